"""Extruded 3-D meshes (``mesh.extrude``): the section's plane mesh extruded in layers is conforming (every
interior face between two tetrahedra, Σ's triangles the same from both halves), of positive volumes, with a
straight front of nodes; its P2 space holds the plane P2 solution of the same section mesh exactly."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.spatial

from ddsolve.errors import SceneError
from ddsolve.fem import tetra
from ddsolve.mesh import solid
from ddsolve.mesh.solid import TETRA_FACES
from ddsolve.problem.scene import loads

#: The box [-1, 1]² × [0, 0.5] cut at y = 0, the crack (−½, ½) through the depth, extruded in layers.
SOLID = """
[geometry]
box = [-1, 1, -1, 1, 0, 0.5]
crack = {crack}
[mesh]
size = 0.5
extrude = {layers}
[materials.layer1]
E = 200.0
nu = 0.3
[loads.layer1.top]
y = [0.1]
"""


def face_counts(tetrahedra: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every distinct triangle of the tetrahedra (sorted vertices) and how many tetrahedra it bounds."""
    return np.unique(np.sort(tetrahedra[:, TETRA_FACES].reshape(-1, 3), axis=1), axis=0, return_counts=True)


@pytest.mark.unit
@pytest.mark.parametrize("degree", [1, 2])
def test_extruded_mesh_conforms_with_positive_volumes_and_a_straight_front(degree):
    scene = loads(SOLID.format(crack="[-0.5, 0.5]", layers=3)).with_({"mesh.degree": degree, "mesh.grading": True})
    mesh = solid.build(scene)
    assert mesh.degree == degree
    sigma_faces = []
    for half in mesh.halves:
        corners = half.tetrahedra[:, :4]
        volumes = solid.signed_volumes(half.points, corners)
        assert volumes.min() > 0 and np.isclose(volumes.sum(), 2 * 1 * 0.5)
        faces, counts = face_counts(corners)
        assert counts.max() == 2  # an interior face between exactly two tetrahedra
        centres = half.points[faces[counts == 1]].mean(axis=1)
        on_side = np.isclose(np.abs(centres[:, :2]), 1.0).any(axis=1) | np.isclose(centres[:, 2], 0.0) \
            | np.isclose(centres[:, 2], 0.5) | np.isclose(centres[:, 1], 0.0)
        assert on_side.all()  # the rest is the box's sides and Σ
        sigma_of = np.full(len(half.points), -1)
        sigma_of[half.sigma_nodes] = np.arange(len(half.sigma_nodes))
        sigma_faces.append(np.unique(np.sort(sigma_of[half.faces["sigma"][:, :3]], axis=1), axis=0))
    assert np.array_equal(*sigma_faces)  # Σ's triangles, from either half, the same
    surface = mesh.sigma
    assert np.allclose(surface.points[:, 1], 0.0) and np.array_equal(*(half.points[half.sigma_nodes]
                                                                       for half in mesh.halves))
    front = surface.points[np.unique(surface.front)]
    assert np.allclose(np.abs(front[:, 0]), 0.5)  # two straight lines x = ±½ of vertices, one at every layer
    assert np.allclose(np.unique(np.round(front[:, 2], 12)), np.linspace(0.0, 0.5, 4))


@pytest.mark.unit
def test_extrusion_is_refused_where_it_cannot_apply():
    with pytest.raises(SceneError, match=r"geometry.crack: a crack that does not span the depth .* mesh.extrude"):
        loads(SOLID.format(crack="[-0.5, 0.5, 0.1, 0.3]", layers=2))
    with pytest.raises(SceneError, match=r"mesh.extrude: extrudes a plane section"):
        loads(SOLID.format(crack="[-0.5, 0.5]", layers=2).replace(", 0, 0.5]", "]\nlayers = 1"))
    with pytest.raises(SceneError, match=r"mesh.extrude"):
        loads(SOLID.format(crack="[-0.5, 0.5]", layers=0))


def extended(plane_result, half: solid.SolidHalf) -> np.ndarray:
    """The plane solution on the half of the same name as a z-independent 3-D field (u_z = 0) at its nodes."""
    region = plane_result.mesh.lower if half.name == "lower" else plane_result.mesh.upper
    values = plane_result.solution["u_minus" if half.name == "lower" else "u_plus"]
    distance, nearest = scipy.spatial.cKDTree(region.points).query(half.points[:, :2])
    assert distance.max() < 1e-12  # every 3-D node stands above a node of the plane P2 mesh
    return np.column_stack([values[nearest], np.zeros(len(half.points))]).ravel()


@pytest.mark.solve
@pytest.mark.parametrize("case", ["opening", "partial closure"])
def test_p2_extrusion_holds_the_plane_p2_solution_exactly(case):
    """Rollers on the z faces: the plane P2 solution of the same section mesh, extended in z, is a field of the
    extruded P2 space; its 3-D energy is the depth times the plane energy to rounding, and the 3-D solve, a
    minimum over a larger space, lies at or below it (per unit depth: within a few per cent here)."""
    from experiments import three_d
    from ddsolve.mesh import geometry
    from ddsolve.solvers import reference, solid as solid_reference

    scene = three_d.scene_of(case, 0.5, 3).with_({"mesh.extrude": 1, "mesh.degree": 2})
    flat = three_d.scene_of(case, 0.5, 2).with_({"mesh.degree": 2})
    mesh = solid.build(scene)
    plane = reference.solve_monolithic(flat, geometry.build(flat))
    systems = [tetra.half_system(scene, half) for half in mesh.halves]
    held = sum(system.energy(extended(plane, half)) for system, half in zip(systems, mesh.halves))
    assert held / three_d.DEPTH == pytest.approx(plane.energy, rel=1e-10)
    result = solid_reference.solve_solid(scene, mesh)
    assert result.converged and (result.closed > 0) == (case == "partial closure")
    assert plane.energy * 1.05 < result.energy / three_d.DEPTH <= plane.energy * (1 - 1e-12)
