"""Uniform refinement of a coarse mesh (ddsolve.mesh.refine): geometry kept, numbering shared by the
ranks, energies decreasing with the levels, and the parallel path against one rank."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import MATERIALS, ddsolve, structured_mesh

from ddsolve.errors import SceneError
from ddsolve.fem import assembly
from ddsolve.io import hdf5
from ddsolve.mesh import geometry, refine
from ddsolve.mesh.element import outer_edges
from ddsolve.mesh.mesh import CLAMPED, CRACK, SIGMA, edge_lengths, make_mesh, shape_of, statistics
from ddsolve.problem import scene
from ddsolve.problem.scene import Geometry
from ddsolve.solvers import reference

#: The paper's square with its crack (tips at x = ±0.5 are vertices of the structured mesh).
CRACKED = Geometry()


@pytest.fixture(scope="module")
def coarse():
    return structured_mesh(8, 4, shear=0.3, geometry=CRACKED)


@pytest.mark.parametrize("degree", [1, 2])
@pytest.mark.parametrize("levels", [0, 1, 2])
def test_refinement_keeps_area_boundaries_orientation_angles_and_the_crack_tips(coarse, degree, levels):
    fine = refine.refine(coarse, levels, degree)
    n = 2 ** levels
    for old, new in zip(coarse.halves, fine.halves):
        assert new.degree == degree
        assert len(new.cells) == n * n * len(old.cells)
        assert np.all(new.areas() > 0)  # every fine cell counter-clockwise
        assert new.areas().sum() == pytest.approx(old.areas().sum(), rel=1e-13)
        assert set(new.boundaries) == set(old.boundaries)
        for name, edges in old.boundaries.items():
            assert len(new.edges(name)) == n * len(edges)
            assert edge_lengths(new.points, new.edges(name)).sum() == pytest.approx(
                edge_lengths(old.points, edges).sum(), rel=1e-13)
        assert statistics(new).min_angle == pytest.approx(statistics(old).min_angle, rel=1e-10)
    corners = fine.sigma.points[fine.sigma.corner]
    assert len(corners) == n * (int(coarse.sigma.corner.sum()) - 1) + 1
    np.testing.assert_allclose(fine.lower.points[fine.lower.sigma], fine.upper.points[fine.upper.sigma], atol=1e-15)
    np.testing.assert_allclose(fine.sigma.points[fine.sigma.tip], coarse.sigma.points[coarse.sigma.tip], atol=1e-15)
    assert fine.sigma.crack.sum() == (n * degree) * (coarse.sigma.crack.sum() + 1) - 1  # crack nodes between tips


def test_the_refined_mesh_passes_every_check_of_a_mesh_and_gives_the_same_sigma(coarse):
    fine = refine.refine(coarse, 2, 2)
    checked = make_mesh(fine.lower, fine.upper, "refined")  # all of make_mesh's checks
    for name in ("points", "normals", "weights", "crack", "tip", "clamped", "corner"):
        np.testing.assert_allclose(getattr(checked.sigma, name), getattr(fine.sigma, name), atol=1e-14)


def test_p2_cells_have_meshio_node_order(coarse):
    fine = refine.refine(coarse, 1, 2)
    for half in fine.halves:
        p = half.points[half.cells]
        for middle, (a, b) in zip((3, 4, 5), ((0, 1), (1, 2), (2, 0))):
            np.testing.assert_allclose(p[:, middle], 0.5 * (p[:, a] + p[:, b]), atol=1e-14)
        for name, edges in half.boundaries.items():
            np.testing.assert_allclose(half.points[edges[:, 2]], 0.5 * (half.points[edges[:, 0]]
                                                                       + half.points[edges[:, 1]]), atol=1e-14)


@pytest.mark.parametrize("degree", [1, 2])
def test_pieces_of_any_number_of_parts_assemble_into_the_same_mesh(coarse, degree):
    grid = refine.Lattice(coarse.lower, 2, degree)
    whole_points = grid.fine_points(0, grid.cell_count)
    whole_cells = grid.fine_cells(0, grid.cell_count)
    for parts in (1, 2, 4, 7):
        bounds = refine.shares(grid, parts)
        points = np.full_like(whole_points, np.nan)
        cells = []
        for first, stop in zip(bounds[:-1], bounds[1:]):  # each part placed where the numbering says
            points[grid.node_offsets[first]:grid.node_offsets[stop]] = grid.fine_points(first, stop)
            cells.append(grid.fine_cells(first, stop))
        np.testing.assert_array_equal(points, whole_points)
        np.testing.assert_array_equal(np.concatenate(cells), whole_cells)
    # every node once, every node used, the same node from all its cells
    assert np.array_equal(np.unique(whole_cells), np.arange(grid.node_count))
    assert len(np.unique(np.round(whole_points, 12), axis=0)) == grid.node_count


@pytest.mark.parametrize("degree, levels", [(1, 1), (1, 2), (1, 3), (2, 1), (2, 2)])
def test_a_piece_made_from_the_coarse_half_is_the_piece_cut_from_the_fine_one(degree, levels):
    """pieces.of_lattice (what a rank of a shared block makes alone) equals pieces.cut of the whole refined half:
    the same nodes, points, cells in the same order, skeleton and owned cells, for every rank of 2 and 3; the
    coarse half's skeleton of the fine half is the whole one's; the fine cells are in the order of their
    smallest node."""
    from ddsolve.mesh import curves, pieces
    from ddsolve.mesh.mesh import skeleton

    chosen = scene.load("partial-closure", ["mesh.sigma_vertices=25", "mesh.boundary_vertices=36"])
    project = curves.projector(chosen)
    for coarse_half in geometry.build_coarse(chosen).halves:
        grid = refine.Lattice(coarse_half, levels, degree)
        half = refine.refine_half(coarse_half, levels, degree, project)
        smallest = half.cells.min(axis=1)
        assert np.all(np.diff(smallest) >= 0)
        n = len(half.points)
        for parts in (2, 3):
            bounds = np.linspace(0, n, parts + 1).round().astype(int)
            for first, stop in zip(bounds[:-1], bounds[1:]):
                cut, made = pieces.cut(half, first, stop), pieces.of_lattice(grid, first, stop, project)
                made = dataclasses.replace(made, cell_first=int(np.count_nonzero(smallest < first)))
                for name in ("nodes", "outer_edges", "outline"):
                    np.testing.assert_array_equal(getattr(made, name), getattr(cut, name))
                for name in ("owned", "first", "stop", "cell_first", "rows", "cell_rows"):
                    assert getattr(made, name) == getattr(cut, name)
                np.testing.assert_array_equal(made.half.points, cut.half.points)
                np.testing.assert_array_equal(made.half.cells, cut.half.cells)
                np.testing.assert_array_equal(made.half.sigma, cut.half.sigma)
                assert made.half.boundaries.keys() == cut.half.boundaries.keys()
                for name, edges in cut.half.boundaries.items():
                    np.testing.assert_array_equal(made.half.boundaries[name], edges)
        whole, bare = skeleton(half), grid.skeleton(half.shape, project)
        for name in ("points", "sigma", "boundary_edges"):
            np.testing.assert_array_equal(getattr(bare, name), getattr(whole, name))


@pytest.mark.parametrize("parts", [2, 4, 8])
def test_the_ranks_of_a_half_share_the_fine_nodes_evenly(coarse, parts):
    grid = refine.Lattice(refine.refine_half(coarse.lower, 2), 2, 1)  # 128 coarse cells
    nodes = np.diff(grid.node_offsets[refine.shares(grid, parts)])
    largest_cell = np.diff(grid.node_offsets).max()
    assert nodes.sum() == grid.node_count and nodes.max() <= grid.node_count / parts + largest_cell
    idle = np.diff(grid.node_offsets[refine.shares(grid, parts, idle_first=True)])  # the first has other work
    assert idle[0] == 0 and idle.sum() == grid.node_count
    assert idle[1:].max() <= grid.node_count / (parts - 1) + largest_cell


@pytest.mark.parametrize("degree", [1, 2])
@pytest.mark.parametrize("levels", [1, 2])
def test_the_refined_half_knows_its_outer_edges_and_the_pieces_its_shape(coarse, degree, levels):
    grid = refine.Lattice(coarse.lower, levels, degree)
    half = refine.refine_half(coarse.lower, levels, degree)
    counted = outer_edges(half.cells)  # every edge one cell uses, oriented with it
    assert len(half.boundary_edges) == len(counted)
    np.testing.assert_array_equal(np.unique(half.boundary_edges, axis=0), np.unique(counted, axis=0))
    whole = shape_of(half.points, half.corners)
    bounds = refine.shares(grid, 3)
    pieces = [shape_of(half.points, grid.fine_cells(first, stop)[:, :3]) for first, stop in zip(bounds[:-1], bounds[1:])]
    assert pieces[0] & pieces[1] & pieces[2] == whole
    sides = np.linalg.norm(half.points[half.corners] - half.points[np.roll(half.corners, -1, axis=1)], axis=2)
    assert whole.shortest_side == pytest.approx(sides.min(), rel=1e-14)
    assert whole.smallest_angle == pytest.approx(statistics(half).min_angle, rel=1e-14)
    assert 0 < whole.smallest_angle < 60


def test_a_projection_puts_the_new_boundary_nodes_on_their_curve_and_bends_the_cells(coarse):
    bump = 0.05

    def project(points, names):
        assert points.shape == (len(names), 2) and set(names) <= {"top", "bottom", "left", "right", SIGMA}
        moved = points.copy()
        top = names == "top"
        moved[top, 1] = 1.0 + bump * np.sin(4 * np.pi * points[top, 0])
        return moved

    fine = refine.refine(coarse, 2, 1, project)
    upper = fine.upper
    on_top = np.unique(upper.edges("top"))
    np.testing.assert_allclose(upper.points[on_top, 1], 1.0 + bump * np.sin(4 * np.pi * upper.points[on_top, 0]),
                               atol=1e-14)
    assert np.all(upper.areas() > 0)
    straight = refine.refine(coarse, 2, 1)
    moved = np.flatnonzero(np.any(upper.points != straight.upper.points, axis=1))
    assert len(np.setdiff1d(moved, on_top)) > 0  # inner nodes of the cells on top bend with them
    np.testing.assert_array_equal(fine.lower.points, straight.lower.points)


def patch_error(half) -> float:
    """Largest error of the FE solution with a field of the element's space prescribed on the boundary."""
    rows, cols, values = assembly.stiffness(half.points, half.cells, np.diag([2.0, 2.0, 1.0]))
    K = np.zeros((2 * len(half.points), 2 * len(half.points)))
    np.add.at(K, (rows, cols), values)
    x, y = half.points.T
    exact = np.column_stack([0.01 + 0.002 * x - 0.003 * y, -0.02 + 0.004 * x + 0.001 * y])
    if half.degree == 2:
        exact += 0.005 * np.column_stack([x * x - y * y, -2.0 * x * y])
    exact = exact.ravel()
    fixed = assembly.element_dofs(np.unique(half.boundary_edges)[:, None]).ravel()
    free = np.setdiff1d(np.arange(len(exact)), fixed)
    u = exact.copy()
    u[free] = np.linalg.solve(K[np.ix_(free, free)], -K[np.ix_(free, fixed)] @ exact[fixed])
    return float(np.abs(u - exact).max())


@pytest.mark.parametrize("degree", [1, 2])
def test_patch_test_on_the_refined_mesh(degree):
    fine = refine.refine(structured_mesh(4, 2, shear=0.3), 1, degree)
    assert patch_error(fine.lower) < 1e-12


@pytest.mark.solve
def test_energy_decreases_with_the_levels():
    small = scene.load("partial-closure", ["mesh.sigma_vertices=9", "mesh.boundary_vertices=12"])
    coarse = geometry.build(small)
    energies = [reference.solve_monolithic(small, refine.refine(coarse, levels)).energy for levels in (0, 1, 2)]
    assert energies[0] > energies[1] > energies[2]


def refined(*overrides: str):
    return geometry.refinement(scene.load("partial-closure", list(overrides)))


def test_the_automatic_choice_keeps_the_paper_meshes_and_refines_the_large_ones():
    for P, M in ((13, 16), (25, 32), (50, 64), (100, 128), (200, 256), (400, 512)):  # Table 1 and P = 400
        _, levels = refined(f"mesh.sigma_vertices={P}", f"mesh.boundary_vertices={M}")
        assert levels == 0
    coarse, levels = refined("mesh.sigma_vertices=801", "mesh.boundary_vertices=1024")
    assert levels >= 1 and 2 ** levels * (coarse.mesh.sigma_vertices - 1) + 1 == 801
    assert geometry.estimated_vertices(coarse) <= geometry.COARSE_VERTICES
    assert geometry.coarse_segments(coarse, 0) >= geometry.COARSE_SEGMENTS
    assert refined("mesh.sigma_vertices=801", "mesh.boundary_vertices=1024", "mesh.refine=0")[1] == 0
    coarse, levels = refined("mesh.sigma_vertices=800", "mesh.boundary_vertices=1024", "mesh.refine=2")
    assert (levels, coarse.mesh.sigma_vertices, coarse.mesh.boundary_vertices, coarse.mesh.degree) == (2, 201, 256, 1)
    coarse, levels = refined("mesh.size=0.005")
    assert levels >= 1 and coarse.mesh.size == pytest.approx(0.005 * 2 ** levels)
    assert refined("mesh.size=0.05")[1] == 0


def test_too_many_levels_for_the_geometry_are_refused():
    with pytest.raises(SceneError, match=r"mesh.refine = 5: the coarse mesh would have fewer than 2 segments"):
        refined("mesh.sigma_vertices=41", "mesh.boundary_vertices=64", "mesh.refine=5")
    with pytest.raises(SceneError, match="mesh.refine"):
        scene.load("partial-closure", ["mesh.refine=-1"])


def test_a_refined_mesh_file_is_its_mesh_refined(mesh_file):
    plain = geometry.build(scene.load("partial-closure", [f'mesh.file="{mesh_file}"']))
    fine = geometry.build(scene.load("partial-closure", [f'mesh.file="{mesh_file}"', "mesh.refine=1"]))
    assert len(fine.lower.cells) == 4 * len(plain.lower.cells)
    assert set(fine.lower.boundaries) == set(plain.lower.boundaries) >= {SIGMA, CRACK, CLAMPED}


@pytest.mark.mpi
@pytest.mark.slow
def test_p801_refined_gives_the_same_energy_on_1_2_and_4_ranks(tmp_path):
    options = ["--set", "mesh.sigma_vertices=801", "--set", "mesh.boundary_vertices=1024"]
    energies = {}
    for ranks in (1, 2, 4):
        output = tmp_path / f"r{ranks}.h5"
        ddsolve("solve", "partial-closure", *options, "-o", str(output), ranks=ranks, timeout=600)
        energies[ranks] = hdf5.read(output).energy
    assert energies[2] == pytest.approx(energies[1], rel=1e-10)
    assert energies[4] == pytest.approx(energies[1], rel=1e-10)


def assert_same(a, b) -> None:
    """``a`` and ``b`` equal to the bit: dataclasses field by field, arrays, lists and plain values."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b)
        for field in dataclasses.fields(a):
            assert_same(getattr(a, field.name), getattr(b, field.name))
    elif isinstance(a, np.ndarray):
        np.testing.assert_array_equal(a, b)
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    else:
        assert a == b


#: A strip clamped on its bottom only: the upper half is held by the glue (its blocks float).
FLOATING_STRIP = """
[geometry]
box = [0.0, 4.0, -0.5, 0.5]
cracks = [[1.0, 2.0]]
clamped = ["bottom"]
[mesh]
sigma_vertices = 33
boundary_vertices = 192
refine = 2
[loads.layer1.top]
x = 2e-3
""" + MATERIALS


@pytest.mark.parametrize("name, settings", [
    ("partial-closure", ["mesh.sigma_vertices=49", "mesh.boundary_vertices=64", "mesh.refine=2"]),
    ("partial-closure", ["mesh.sigma_vertices=25", "mesh.boundary_vertices=64", "mesh.refine=1", "mesh.degree=2"]),
    ("arc-bond", ["mesh.refine=1"]),
    ("strip-disbonds", ["mesh.refine=1"]),
    ("floating strip", []),
])
def test_rank_0_checks_the_skeleton_of_the_upper_half_as_it_checks_the_whole(name, settings):
    from ddsolve.mesh import curves
    from ddsolve.mesh import mesh as meshes
    from ddsolve.parallel.distribution import whole_mesh_checks

    chosen = scene.loads(FLOATING_STRIP) if name == "floating strip" else scene.load(name, settings)
    coarse_scene, levels = geometry.refinement(chosen)
    assert levels > 0
    coarse = geometry.build_coarse(coarse_scene)
    lower, upper = (refine.refine_half(half, levels, chosen.mesh.degree, curves.projector(chosen))
                    for half in coarse.halves)
    bare = meshes.skeleton(upper)
    assert len(bare.points) < len(upper.points) / 2 and len(bare.cells) == 0
    whole, checked = (refine.pair_refined(coarse, lower, half) for half in (upper, bare))
    assert_same(checked.sigma, whole.sigma)
    assert meshes.quality(checked) == meshes.quality(whole)
    assert_same(whole_mesh_checks(chosen, checked), whole_mesh_checks(chosen, whole))  # tips, Σ supports, kernels
    if name == "floating strip":
        assert whole_mesh_checks(chosen, checked)[2].floating == [1, 3]


def test_rank_0_pairs_and_checks_gmsh_halves_from_the_skeleton_of_the_upper_one():
    from ddsolve.mesh import mesh as meshes
    from ddsolve.parallel.distribution import whole_mesh_checks

    chosen = scene.load("partial-closure", ["mesh.sigma_vertices=96", "mesh.boundary_vertices=144"])
    lower, upper = (geometry.generate_half(chosen, side) for side in (-1, 1))
    whole, checked = (geometry.pair(chosen, lower, half) for half in (upper, meshes.skeleton(upper)))
    assert_same(checked.sigma, whole.sigma)
    assert meshes.quality(checked) == meshes.quality(whole)
    assert_same(whole_mesh_checks(chosen, checked), whole_mesh_checks(chosen, whole))


@pytest.mark.mpi
@pytest.mark.slow
def test_eight_ranks_mesh_with_a_fraction_of_the_cpu_time_of_two(tmp_path):
    """Meshing as a solve that writes in parallel does it (a coarse gmsh mesh; on 2 ranks each refines its
    half, on 8 each makes its piece of its half, sharing it with the rank of the other layer's block), on a
    mesh whose refinement outweighs gmsh's coarse mesh (P = 1600 from a coarse mesh of P = 51, 5 levels): the
    busiest of 8 ranks (one that made a coarse half, and half its piece's cells and points) spends well under
    the 2-rank run's CPU seconds (0.43 of it measured on 2 cores; choosing, ordering and numbering a piece's
    cells is distribution, as cutting it from a whole half is)."""
    from experiments import report

    records = {ranks: report.launch(ranks, ["scaling-meshing", "1600", "2048", "5"], tmp_path / f"{ranks}.json")
               for ranks in (2, 8)}
    assert records[2]["unknowns"] == records[8]["unknowns"] == 3_057_928  # the same mesh
    assert max(records[8]["meshing_cpu"]) <= 0.75 * max(records[2]["meshing_cpu"])
