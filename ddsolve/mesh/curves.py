"""New boundary vertices onto the geometry's curves: the projector of :mod:`ddsolve.mesh.bisection` for
a gmsh geometry.

A ``.geo`` scene's geometry is opened in a gmsh session (in a child process, :func:`~ddsolve.mesh.gmsh_io.apart`)
without meshing, and each point goes to the closest point of the curves of its physical group, the
nearest curve winning: straight lines by an orthogonal projection here (gmsh's closest point on a
line is only good to about 1e-8), other curves by ``gmsh.model.getClosestPoint``, all points of a
curve at once.  The box and mesh files have no curves to follow: no projector.
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from ddsolve.mesh.bisection import Projector
from ddsolve.mesh.gmsh_io import apart, open_file, physical_groups, session
from ddsolve.problem.scene import Scene


def projector(scene: Scene) -> Projector | None:
    """The projector onto the curves of the scene's ``.geo`` geometry; None for the box and mesh files."""
    if scene.mesh.kind != "geo":
        return None
    return functools.partial(project_onto_geometry, scene.mesh.file)


def project_onto_geometry(path: Path, points: np.ndarray, names: np.ndarray) -> np.ndarray:
    """``points`` ``(k, 2)`` moved to the nearest point of the curves of the physical group ``names``
    ``(k,)`` of the gmsh geometry ``path`` (a point whose group has no curves stays)."""
    return apart(_project, Path(path), np.asarray(points, dtype=float), np.asarray(names, dtype=str))


def _project(path: Path, points: np.ndarray, names: np.ndarray) -> np.ndarray:
    moved = points.copy()
    with session() as gmsh:
        open_file(gmsh, path)
        groups = physical_groups(gmsh, str(path))
        for name in np.unique(names):
            rows = np.flatnonzero(names == name)
            nearest, distance = points[rows].copy(), np.full(len(rows), np.inf)
            for curve in groups.get((1, str(name)), []):
                closest = _closest(gmsh, curve, points[rows])
                gap = np.linalg.norm(closest - points[rows], axis=1)
                better = gap < distance
                nearest[better], distance[better] = closest[better], gap[better]
            moved[rows] = nearest
    return moved


def _closest(gmsh, curve: int, points: np.ndarray) -> np.ndarray:
    """The closest points ``(k, 2)`` of the geometry curve ``curve`` to ``points``."""
    if gmsh.model.getType(1, curve) == "Line":
        ends = [np.asarray(gmsh.model.getValue(0, tag, []), dtype=float)[:2]
                for _, tag in gmsh.model.getBoundary([(1, curve)], oriented=False)]
        start, direction = ends[0], ends[-1] - ends[0]
        t = np.clip((points - start) @ direction / (direction @ direction), 0.0, 1.0)
        return start + t[:, None] * direction
    xyz = np.column_stack([points, np.zeros(len(points))]).ravel()
    closest, _ = gmsh.model.getClosestPoint(1, curve, xyz)
    return np.asarray(closest, dtype=float).reshape(-1, 3)[:, :2]
