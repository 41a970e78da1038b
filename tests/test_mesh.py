"""Mesh files, checks and statistics."""
import meshio
import numpy as np
import pytest

from ddsolve import mesh
from ddsolve.errors import MeshError

from conftest import structured_square


def write(tmp_path, points, cells, name="m.vtu"):
    path = tmp_path / name
    meshio.write(path, meshio.Mesh(points, [("triangle", cells)]))
    return path


def test_read_splits_the_square_into_matching_halves(mesh_file):
    lower, upper = mesh.read(mesh_file)
    mesh.check(lower, upper, (-0.5, 0.5))
    assert np.all(lower.points[:, 1] <= 0) and np.all(upper.points[:, 1] >= 0)
    assert np.array_equal(lower.points[lower.sigma()], upper.points[upper.sigma()])
    assert len(lower.cells) == len(upper.cells) == 64
    assert np.all(lower.areas() > 0) and np.all(upper.areas() > 0)
    stats = mesh.statistics(lower)
    assert (stats.vertices, stats.triangles) == (45, 64)
    assert 0.25 < stats.h_min < stats.h_max < 0.25 * 2 ** 0.5 * 1.3  # circumdiameters
    assert mesh.boundary_vertex_count(lower, upper) == 32


def test_clockwise_files_are_accepted(tmp_path):
    points, cells = structured_square(4, 2)
    lower, upper = mesh.read(write(tmp_path, points, cells[:, ::-1]))
    mesh.check(lower, upper, (-0.5, 0.5))


@pytest.mark.parametrize("damage, message", [
    ("invert", "inverted or degenerate triangles"),
    ("degenerate", "inverted or degenerate triangles"),
    ("cross", "triangles cross Σ"),
    ("shrink", "no clamped boundary"),
    ("hole", "boundary edges inside the square"),
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
    with pytest.raises(MeshError, match=message):
        lower, upper = mesh.read(write(tmp_path, points, cells))
        mesh.check(lower, upper, (-0.5, 0.5))


def test_crack_tips_must_be_vertices_and_sigma_must_match(mesh_file):
    lower, upper = mesh.read(mesh_file)
    with pytest.raises(MeshError, match="crack tip x = 0.3 is not a Σ vertex"):
        mesh.check(lower, upper, (-0.5, 0.3))
    moved = upper.points.copy()
    moved[upper.sigma()[3], 0] += 0.01
    with pytest.raises(MeshError, match="Σ vertices of the two halves do not match"):
        mesh.check(lower, mesh.HalfMesh(moved, upper.cells, +1), (-0.5, 0.5))


def test_unreadable_files(tmp_path):
    with pytest.raises(MeshError, match="mesh file not found"):
        mesh.read(tmp_path / "missing.msh")
    garbage = tmp_path / "garbage.msh"
    garbage.write_text("this is not a mesh\n")
    with pytest.raises(MeshError, match="cannot read mesh"):
        mesh.read(garbage)
