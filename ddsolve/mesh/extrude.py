"""The mesh of a prismatic 3-D box (``mesh.extrude = N``): the plane mesh of its x-y section, made by the plane
mesher (:func:`ddsolve.mesh.geometry.build`, with ``mesh.size`` and the grading towards the crack tips), extruded
in N uniform layers along z.

Every prism (a section triangle times a layer) is split into three tetrahedra by the global vertex numbering: on
each quadrilateral face the diagonal starts at the face's lowest-numbered vertex, so that the two prisms sharing a
face split it alike, and Σ's quadrilaterals (the extrusion of Σ's segments, whose vertices both halves share) are
split the same way from either half.  :func:`ddsolve.mesh.solid.build` assembles the tetrahedra (halves, Σ, crack
front, P2 elevation) as it does gmsh's.  The P1 (P2) space holds every z-independent field of the section's P1 (P2)
space, and the crack front is a straight line of nodes at every layer.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ddsolve.mesh import geometry as plane_geometry
from ddsolve.mesh.mesh import Mesh
from ddsolve.problem.scene import Scene


def tetrahedra(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The P1 tetrahedra of a 3-D box scene whose cracks span the depth: the section's plane P1 mesh, its two
    halves merged on Σ, extruded in ``mesh.extrude`` layers; the nodes ``(n, 3)``, the tetrahedra ``(m, 4)`` and
    whether each lies in the upper half (as :func:`ddsolve.mesh.solid.build` takes gmsh's)."""
    box = scene.geometry.box
    points, triangles, upper = section(plane_geometry.build(section_scene(scene)))
    layers = np.linspace(box[4], box[5], scene.mesh.extrude + 1)
    return (*extruded(points, triangles, layers), np.tile(upper, 3 * (len(layers) - 1)))


def section_scene(scene: Scene) -> Scene:
    """The plane scene of the section: the box's x-y rectangle, the cracks' x intervals, the same mesh keys at
    degree 1 (the 3-D mesh is elevated after extrusion)."""
    geometry = scene.geometry
    flat = replace(geometry, box=geometry.box[:4], cracks=tuple(crack[:2] for crack in geometry.cracks))
    return replace(scene, geometry=flat, mesh=replace(scene.mesh, degree=1, extrude=None), displacements={}, loads={})


def section(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The section's vertices ``(n, 2)`` and triangles ``(m, 3)`` in one numbering, the lower half's first and
    the upper half's Σ vertices those of the lower half, and whether each triangle lies in the upper half."""
    lower, upper = mesh.lower, mesh.upper
    own = np.ones(len(upper.points), dtype=bool)
    own[upper.sigma] = False
    number = np.empty(len(upper.points), dtype=np.int64)
    number[own] = len(lower.points) + np.arange(int(own.sum()))
    number[upper.sigma] = lower.sigma
    points = np.vstack([lower.points, upper.points[own]])
    triangles = np.vstack([lower.cells[:, :3], number[upper.cells[:, :3]]])
    return points, triangles, np.repeat([False, True], [len(lower.cells), len(upper.cells)])


def extruded(points: np.ndarray, triangles: np.ndarray, layers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The section extruded through the z values ``layers``: vertex i at layer k is ``k n + i``; each prism's
    three tetrahedra (a0 b0 c0 c1), (a0 b0 b1 c1), (a0 a1 b1 c1) for its triangle's vertices a < b < c, all the
    first tetrahedra of every layer, then the second, then the third (the triangles' order within each)."""
    n = len(points)
    solid_points = np.column_stack([np.tile(points, (len(layers), 1)), np.repeat(layers, n)])
    a, b, c = np.sort(triangles, axis=1).T
    below = n * np.arange(len(layers) - 1)[:, None]  # (layers - 1, 1): the bottom of each layer
    above = below + n
    split = [(a + below, b + below, c + below, c + above), (a + below, b + below, b + above, c + above),
             (a + below, a + above, b + above, c + above)]
    return solid_points, np.concatenate([np.stack([v.ravel() for v in tetrahedron], axis=1) for tetrahedron in split])
