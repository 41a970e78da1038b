"""Mesh files, the box geometry, checks and statistics."""
import meshio
import numpy as np
import pytest
from conftest import MATERIALS, structured_square

from ddsolve.errors import MeshError
from ddsolve.mesh import geometry, gmsh_io, mesh
from ddsolve.problem import scene

SCENE = """
[mesh]
file = "{file}"
degree = {degree}
""" + MATERIALS


def write(tmp_path, points, cells, name="m.vtu"):
    path = tmp_path / name
    meshio.write(path, meshio.Mesh(points, [("triangle", cells)]))
    return path


def build(path, degree=1, overrides=()):
    return geometry.build(scene.loads(SCENE.format(file=path, degree=degree), list(overrides)))


def test_read_splits_the_square_into_matching_halves(mesh_file):
    m = build(mesh_file)
    lower, upper = m.lower, m.upper
    assert np.all(lower.points[:, 1] <= 0) and np.all(upper.points[:, 1] >= 0)
    assert np.array_equal(lower.points[lower.sigma], upper.points[upper.sigma])
    assert len(lower.cells) == len(upper.cells) == 64
    assert np.all(lower.areas() > 0) and np.all(upper.areas() > 0)
    stats = mesh.statistics(lower)
    assert (stats.vertices, stats.triangles) == (45, 64)
    assert 0.25 < stats.h_min < stats.h_max < 0.25 * 2 ** 0.5 * 1.3  # circumdiameters
    assert mesh.boundary_vertex_count(m) == 32
    assert sorted(lower.boundaries) == ["bottom", "clamped", "crack", "left", "right", "sigma"]
    assert np.array_equal(np.flatnonzero(m.sigma.crack), [3, 4, 5]) and np.array_equal(np.flatnonzero(m.sigma.tip), [2, 6])


def test_p2_adds_a_node_on_every_edge(mesh_file):
    m = build(mesh_file, degree=2)
    assert m.degree == 2 and m.lower.cells.shape == (64, 6)
    boundary = len(m.lower.boundary_edges)  # 8 bottom, 4 + 4 sides, 8 on Σ
    assert boundary == 24 and len(m.lower.points) == 45 + (3 * 64 + boundary) // 2  # a node per edge
    assert len(m.sigma.points) == 17 and np.array_equal(m.sigma.corner, np.arange(17) % 2 == 0)
    assert m.sigma.weights.sum() == pytest.approx(2.0)
    middle = m.lower.points[m.lower.cells[:, 3]]
    assert np.allclose(middle, 0.5 * (m.lower.points[m.lower.cells[:, 0]] + m.lower.points[m.lower.cells[:, 1]]))


def test_clockwise_files_are_accepted(tmp_path):
    points, cells = structured_square(4, 2)
    build(write(tmp_path, points, cells[:, ::-1]))


@pytest.mark.parametrize("damage, message", [
    ("invert", "inverted or degenerate triangles"),
    ("degenerate", "inverted or degenerate triangles"),
    ("cross", "triangles cross Σ"),
    ("shrink", "boundary edges lie inside the box"),
    ("hole", "boundary edges lie inside the box"),
    ("repeated", "2 triangles are listed more than once"),
    ("overlap", "overlapping cells"),
])
def test_bad_meshes_are_rejected(tmp_path, damage, message):
    points, cells = structured_square(4, 2)
    if damage == "invert":
        cells[3] = cells[3, ::-1]
    elif damage == "degenerate":
        points = np.vstack([points, [0.1, -0.5]])
        cells = np.vstack([cells, [[len(points) - 1, len(points) - 1, 0]]])
    elif damage == "cross":
        cells = np.vstack([cells, [[0, len(points) - 1, 1]]])
    elif damage == "shrink":
        points[:, 0] *= 0.9
    elif damage == "hole":
        cells = np.delete(cells, 5, axis=0)
    elif damage == "repeated":
        cells = np.vstack([cells, cells[:2]])
    elif damage == "overlap":  # a cell over two others, same corners order as a valid one
        lower = np.flatnonzero(np.all(points[cells, 1] <= 0, axis=1))
        cells = np.vstack([cells, [[cells[lower[0], 0], cells[lower[1], 1], cells[lower[0], 2]]]])
    with pytest.raises(MeshError, match=message):
        build(write(tmp_path, points, cells))


def test_a_half_whose_triangles_are_not_merged_at_a_node_is_rejected():
    """Any geometry (not only the box, whose boundary is checked too): a cell at an interior node that uses
    a copy of it is not connected there, though the cells cover the half exactly."""
    points, cells = structured_square(4, 2)
    cells = cells[np.all(points[cells, 1] <= 0, axis=1)]
    mesh.make_half(points, cells, -1, {}, "merged")
    node = int(np.flatnonzero(np.all(np.isclose(points, [-0.5, -0.5]), axis=1))[0])
    points = np.vstack([points, points[node]])
    cell = np.flatnonzero(np.any(cells == node, axis=1))[0]
    cells[cell][cells[cell] == node] = len(points) - 1
    with pytest.raises(MeshError, match="test: lower half: nodes of its triangles where another node is: 1 "):
        mesh.make_half(points, cells, -1, {}, "test")


def test_crack_tips_must_be_vertices_and_sigma_must_match(mesh_file):
    with pytest.raises(MeshError, match="crack tip x = 0.3 is not a Σ vertex"):
        build(mesh_file, overrides=["geometry.crack=[-0.5, 0.3]"])
    m = build(mesh_file)
    moved = m.upper.points.copy()
    moved[m.upper.sigma[3], 0] += 0.01
    shifted = mesh.HalfMesh(moved, m.upper.cells, +1, m.upper.sigma, m.upper.boundaries)
    with pytest.raises(MeshError, match="the Σ nodes of the two halves do not match"):
        mesh.make_mesh(m.lower, shifted, "test")


def test_a_half_without_clamped_boundary_is_a_mesh(mesh_file):
    """Its blocks float (held only through Σ): tests/test_kernels.py and tests/test_floating.py."""
    m = build(mesh_file, overrides=['geometry.clamped=["bottom"]'])
    assert len(m.upper.clamped()) == 0 and len(m.lower.clamped()) > 0 and not m.sigma.clamped.any()


def test_a_crack_reaching_the_clamped_side_is_refused(mesh_file):
    with pytest.raises(MeshError, match=r"a crack reaches the clamped boundary at \(-1, 0\)"):
        build(mesh_file, overrides=["geometry.crack=[-1.0, 0.5]"])
    free = build(mesh_file, overrides=["geometry.crack=[-1.0, 0.5]", 'geometry.clamped=["right"]'])
    assert free.sigma.crack[0] and not free.sigma.clamped[0]  # an edge crack on a free side


def test_unreadable_files(tmp_path):
    with pytest.raises(MeshError, match="mesh file not found"):
        build(tmp_path / "missing.vtu")
    garbage = tmp_path / "garbage.vtu"
    garbage.write_text("this is not a mesh\n")
    with pytest.raises(MeshError, match="cannot read mesh"):
        build(garbage)


@pytest.mark.parametrize("degree", [1, 2])
def test_a_written_msh_reads_back_as_the_same_mesh(tmp_path, mesh_file, degree):
    m = build(mesh_file, degree=degree)
    path = tmp_path / "halves.msh"
    gmsh_io.write_msh(m, path)
    again = build(path, degree=degree)
    for a, b in zip(m.halves, again.halves):
        assert len(a.points) == len(b.points) and len(a.cells) == len(b.cells)
        assert np.allclose(np.sort(a.points, axis=0), np.sort(b.points, axis=0))
        assert sorted(a.boundaries) == sorted(b.boundaries)
    assert np.allclose(m.sigma.points, again.sigma.points) and np.array_equal(m.sigma.crack, again.sigma.crack)
    assert np.allclose(m.sigma.weights, again.sigma.weights)


def _gmsh_imported() -> bool:
    import sys

    return "gmsh" in sys.modules


def test_the_warm_child_imports_gmsh_before_its_work_and_a_later_work_gets_a_child_of_its_own():
    import os

    gmsh_io.warm_up_cpu()
    gmsh_io.warm_up()
    assert gmsh_io.apart(_gmsh_imported)  # the warm child had imported gmsh when the work came
    assert gmsh_io.warm_up_cpu() > 0.0  # and that was start-up work: its CPU seconds are told apart
    first, second = gmsh_io.apart(os.getpid), gmsh_io.apart(os.getpid)
    assert len({first, second, os.getpid()}) == 3
    assert gmsh_io.warm_up_cpu() == 0.0  # children of their own wait for nothing
    gmsh_io.warm_up()
    assert gmsh_io.apart(lambda: 7) == 7  # work that does not pickle: a forked child of its own runs it
    assert gmsh_io.apart(os.getpid) != os.getpid()
