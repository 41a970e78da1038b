"""A 3-D box's halves cut into slabs parallel to Σ (``solver.pieces``): the cut, the ties of the supports across it,
the decomposition of the slabs equal to the monolithic reference with contact active, on 1, 2 and 4 ranks, with
feti's lumped and Dirichlet preconditioners, and the refusals."""
from __future__ import annotations

import numpy as np
import pytest

from ddsolve.errors import SceneError
from ddsolve.problem.scene import loads
from experiments import three_d, three_d_front

#: The 3-D page's partly shut crack (three_d.scene_of) at a mesh that holds two slabs per half (seven element layers).
CLOSURE = three_d.scene_of("partial closure", 0.14, 3)
#: The quarter penny (its bottom its only support in y) in two slabs per half: the slabs off the bottom float.
PENNY = loads(three_d_front.PENNY.format(L=2, size=0.3, grading=0.2)).with_({"solver.pieces": 2})
#: The 3-D page's box held on its top and bottom faces only (the bottom clamped, the top tilted: the crack's left
#: part shut), in two slabs per half: the slabs at Σ float, free of all six motions.
HELD = loads("""
[geometry]
box = [-1, 1, -1, 1, 0, 0.5]
crack = [-0.5, 0.5]
clamped = ["bottom"]
[mesh]
size = 0.14
[materials.layer1]
E = 200.0
nu = 0.28
[displacements.layer1.top]
x = 0.0
y = "0.01 * x"
z = 0.0
[solver]
pieces = 2
""")


@pytest.mark.unit
def test_slabs_partition_a_half_and_share_only_their_cuts():
    """Three slabs of each half: every tetrahedron and side triangle in one slab, Σ's nodes in the first only, a
    node in at most two neighbouring slabs, each cut's two nodes at one point, its weights the cut's area (at least
    the box's section, the cut being jagged); too many slabs for the mesh: None; a cut vertex's prescribed z on the
    back face is prescribed in both slabs."""
    from ddsolve.mesh import slabs, solid
    from ddsolve.solvers import solid_dd

    mesh = solid.build(CLOSURE)
    for half in mesh.halves:
        cut = slabs.slabs(half, CLOSURE.geometry.sigma, 3)
        assert cut is not None
        pieces, cuts = cut
        assert sum(len(slab.piece.tetrahedra) for slab in pieces) == len(half.tetrahedra)
        for side, triangles in half.faces.items():
            assert sum(len(slab.piece.faces[side]) for slab in pieces) == len(triangles)
        assert np.array_equal(pieces[0].nodes[pieces[0].piece.sigma_nodes], half.sigma_nodes)
        assert all(len(slab.piece.sigma_nodes) == 0 for slab in pieces[1:])
        count = np.zeros(len(half.points), dtype=int)
        for slab in pieces:
            count[slab.nodes] += 1
        assert count.min() == 1 and count.max() == 2
        assert not np.intersect1d(pieces[0].nodes, pieces[2].nodes).size
        for j, between in enumerate(cuts):
            near, far = pieces[j], pieces[j + 1]
            assert np.allclose(near.piece.points[between.nodes[0]], between.points)
            assert np.allclose(far.piece.points[between.nodes[1]], between.points)
            assert len(between.points) == np.count_nonzero(np.isin(near.nodes, far.nodes))
            assert 1.0 <= between.weights.sum() < 2.0 and between.weights.min() > 0  # the section is 2 × ½
        assert slabs.slabs(half, CLOSURE.geometry.sigma, 12) is None
    parts = solid_dd.decomposition(CLOSURE, mesh, 3)
    lower, lower_below = parts.slabs[0], parts.slabs[2]
    glued = parts.joints[1]  # the lower half's first cut: (slab 1, slab 0)
    assert glued.blocks == (2, 0)
    for block, dofs in zip(glued.blocks, glued.dofs):
        z_back = dofs[2::3][np.isclose(parts.slabs[block].piece.points[dofs[2::3] // 3, 2], three_d.DEPTH)]
        assert z_back.size and np.all(np.isin(z_back, parts.supports[block][0]))
    assert lower.piece.name == lower_below.piece.name == "lower"


@pytest.mark.unit
def test_slabs_and_the_lumped_preconditioner_are_refused_where_they_do_not_apply():
    """A plane scene refuses solver.pieces and the lumped preconditioner; slabs too many for the mesh are refused
    naming solver.pieces, floating slabs with a method that cannot solve them naming solver.method."""
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid_dd

    plane = three_d.scene_of("partial closure", 0.2, 2)
    with pytest.raises(SceneError, match="solver.pieces: cuts the halves of a 3-D box"):
        plane.with_({"solver.pieces": 2})
    with pytest.raises(SceneError, match="solver.preconditioner = lumped: .* a plane scene's feti takes dirichlet"):
        plane.with_({"solver.preconditioner": "lumped"})
    mesh = solid.build(CLOSURE)
    with pytest.raises(SceneError, match=r"^solver.pieces = 9: this mesh's halves do not hold 9 slabs each"):
        solid_dd.pieces_of(CLOSURE.with_({"solver.pieces": 9}), mesh, 1)
    held = HELD.with_({"solver.method": "mprgp"})
    held_mesh = solid.build(held)
    parts = solid_dd.pieces_of(held, held_mesh, 1)
    kernels = solid_dd.kernels_of(parts)
    with pytest.raises(SceneError, match=r"^solver.method = mprgp: block u_minus, u_plus of the 3-D box is floating"):
        solid_dd.method_of(held, parts, kernels)


@pytest.mark.unit
def test_a_box_takes_any_rank_count_up_to_its_blocks_or_a_multiple():
    """A 3-D box's blocks go on any rank count up to theirs (some ranks holding one more) or a multiple, where a plane
    structure's take divisors and multiples only; ``-n`` is checked by that rule before mpiexec, auto's slab counts
    together; the cost model charges the busiest rank: four blocks on 3 ranks cost as on 2."""
    from ddsolve.dd import solid_costs
    from ddsolve.errors import UsageError
    from ddsolve.parallel import launch
    from ddsolve.solvers import checks

    assert [size for size in range(1, 17) if launch.supported(size, 8, uneven=True)] == [*range(1, 9), 16]
    assert [size for size in range(1, 17) if launch.supported(size, 8)] == [1, 2, 4, 8, 16]
    assert launch.usable(3, uneven=True) == "1, 2 or a multiple of 3"
    assert launch.usable(8, uneven=True) == "1 to 7 or a multiple of 8" and launch.usable(4) == "1, 2 or a multiple of 4"
    for ranks in (3, 5, 7, 8, 10):
        checks.check_ranks(ranks, CLOSURE)
    with pytest.raises(UsageError, match=r"^-n 9: unsupported number of ranks: use 1 to 8 or a multiple of 2 \(the "
                                         r"3-D box's halves in 1, 2 or 4 slabs each\)$"):
        checks.check_ranks(9, CLOSURE)
    with pytest.raises(UsageError, match=r"^-n 3: .* use 1 or a multiple of 2 \(the 3-D box's halves in 1 slab each"):
        checks.check_ranks(3, CLOSURE.with_({"solver.pieces": 1}))
    box = solid_costs.Box(300_000, 3_000, 0, 1)
    for candidate in solid_costs.candidates([2], schur_fits=False):
        assert solid_costs.predicted_seconds(box, candidate, 3) == solid_costs.predicted_seconds(box, candidate, 2)


@pytest.mark.unit
def test_slabs_held_only_through_their_neighbours_float_and_auto_keeps_them():
    """The penny's slabs off its bottom keep the translation in y, the slabs at Σ of a box held on its top and
    bottom all six motions, kept as the slabs asked for (auto's method on them: feti); ``auto`` keeps the halves
    whole for the methods that cannot solve floating blocks (the box's halves do not float)."""
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid_dd

    penny_mesh = solid.build(PENNY)
    parts = solid_dd.pieces_of(PENNY, penny_mesh, 1)
    held = solid_dd.kernels_of(parts)
    assert parts.count == 2 and held.floating == [0, 1, 3] and held.names() == "u_minus, u_plus, u_plus_1"
    assert [kernel.shape[1] for kernel in held.kernels] == [1, 1, 0, 1]
    mesh = solid.build(HELD)
    parts = solid_dd.decomposition(HELD, mesh, 2)
    held = solid_dd.kernels_of(parts)
    assert parts.count == 2 and held.floating == [0, 1]
    assert all(held.kernels[block].shape[1] == 6 for block in held.floating)
    assert solid_dd.method_of(HELD, parts, held).solver.method == "feti"  # auto on slabs
    for method in ("mprgp", "fista"):  # auto keeps the halves whole, which do not float
        scene = HELD.with_({"solver.pieces": "auto", "solver.method": method})
        parts = solid_dd.pieces_of(scene, mesh, 2)
        held = solid_dd.kernels_of(parts)
        assert parts.count == 1 and held.floating == [], method


@pytest.mark.solve
def test_the_slabs_decomposition_equals_the_reference_with_contact_active():
    """Two slabs per half (four blocks, three joints): feti with the lumped preconditioner and with
    Dirichlet's, schur and mprgp give the reference's solution to 1e-8 in energy norm at solver.tol 1e-10, with the
    same crack vertices shut; the lumped preconditioner takes one round per iteration."""
    from mpi4py import MPI

    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver, solid_dd
    from ddsolve.solvers.solid import energy_error

    reference = solid_solver.solve_solid(CLOSURE, solid.build(CLOSURE))
    assert reference.closed > 0
    for method, preconditioner in (("feti", "lumped"), ("feti", "dirichlet"), ("schur", "auto"), ("mprgp", "auto")):
        scene = CLOSURE.with_({"solver.method": method, "solver.pieces": 2, "solver.tol": 1e-10,
                               "solver.preconditioner": preconditioner})
        result = solid_dd.solve(scene, MPI.COMM_SELF, None, progress=lambda _line: None)
        assert result.converged and result.closed == reference.closed, (method, preconditioner)
        assert energy_error(result, reference) < 1e-8, (method, preconditioner)
        if method == "feti":
            lumped = result.scene.solver.preconditioner == "lumped"
            assert lumped == (preconditioner == "lumped")
            assert result.solves <= result.steps + 4 if lumped else result.solves > 2 * result.steps


@pytest.mark.solve
def test_floating_slabs_equal_the_reference():
    """The penny in two slabs per half (three of its four slabs floating in y) by feti (the lumped preconditioner)
    and schur, and the box held on its top and bottom in two slabs per half (its slabs at Σ free of six motions,
    contact active) by feti: the reference's solution to 1e-8 in energy norm at solver.tol 1e-11, G along the
    penny's front the reference's."""
    from mpi4py import MPI

    from ddsolve.mesh import solid
    from ddsolve.post import front
    from ddsolve.solvers import solid as solid_solver, solid_dd
    from ddsolve.solvers.solid import energy_error

    for scene, methods in ((PENNY, ("feti", "schur")), (HELD, ("feti",))):
        mesh = solid.build(scene)
        reference = solid_solver.solve_solid(scene, mesh)
        assert (reference.closed > 0) == (scene is HELD)
        for method in methods:
            result = solid_dd.solve(scene.with_({"solver.method": method, "solver.tol": 1e-11}), MPI.COMM_SELF, None,
                                    progress=lambda _line: None, mesh=mesh)
            assert result.converged and result.closed == reference.closed and result.scene.solver.pieces == 2
            assert energy_error(result, reference) < 1e-8, method
            if scene is PENNY:
                G = front.release(reference).G
                assert np.abs(result.fracture.G - G).max() < 1e-6 * np.abs(G).max(), method


@pytest.mark.mpi
def test_the_slabs_on_2_3_and_4_ranks_equal_the_reference(tmp_path):
    """ddsolve solve -n 2, -n 3 and -n 4 with two slabs per half (four blocks: two a rank; two on rank 0 and one on
    each other; one a rank), the partly shut crack on 2 and 3 and the penny's floating slabs on 4, hold the
    reference's solution to 1e-8 in energy norm; 5 ranks are refused naming the slabs' rule."""
    from conftest import ddsolve

    from ddsolve.io import solid as solid_files
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver

    for ranks, scene, tol in ((2, CLOSURE, 1e-10), (3, CLOSURE, 1e-10), (4, PENNY, 1e-11)):
        path = tmp_path / f"{ranks}.toml"
        path.write_text(scene.text)
        reference = solid_solver.solve_solid(scene, solid.build(scene))
        solved = ddsolve("solve", str(path), "-o", str(tmp_path / f"{ranks}.h5"), "--set", "solver.pieces=2",
                         "--set", f"solver.tol={tol:g}", ranks=ranks)
        assert "feti (3-D):" in solved.stdout and f"on {ranks} ranks" in solved.stdout
        assert solid_solver.energy_error(solid_files.read(tmp_path / f"{ranks}.h5"), reference) < 1e-8
    refused = ddsolve("solve", str(tmp_path / "2.toml"), "-n", "5", "--set", "solver.pieces=2", "-o",
                      str(tmp_path / "5.h5"), check=False)
    assert refused.returncode == 2 and refused.stderr.strip() == (
        "ddsolve: error: -n 5: unsupported number of ranks: use 1, 2, 3 or a multiple of 4 (the 3-D box's halves in "
        "2 slabs each)")
