"""New boundary vertices onto the geometry's curves: the projector of :mod:`ddsolve.mesh.bisection` for
a gmsh geometry.

A ``.geo`` scene's geometry is opened once, in a gmsh session (in a child process,
:func:`~ddsolve.mesh.gmsh_io.apart`) without meshing, and its curves are described per physical group:
straight lines by their ends and circular arcs by their centre, radius and ends, which numpy then
projects onto exactly (gmsh's closest point on a line is only good to about 1e-8); other curves are
left to ``gmsh.model.getClosestPoint``, in a session of their own at every call.  Each point goes to
the nearest point of the curves of its group, the nearest curve winning.  The box and mesh files have
no curves to follow: no projector.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ddsolve.mesh.gmsh_io import apart, open_file, physical_groups, session
from ddsolve.problem.scene import Scene

#: ``project(points (k, 2), names (k,)) -> (k, 2)``: new boundary vertices onto their curves (``names``: the
#: boundary name, ``sigma`` for Σ, of the edge each point lies on).
Projector = Callable[[np.ndarray, np.ndarray], np.ndarray]


def projector(scene: Scene) -> Projector | None:
    """The projector onto the curves of the scene's ``.geo`` geometry; None for the box and mesh files."""
    return GeometryProjector(scene.mesh.file) if scene.mesh.kind == "geo" else None


@dataclass
class GeometryProjector:
    """``project(points (k, 2), names (k,)) -> (k, 2)`` onto the curves of the physical groups of the gmsh
    geometry ``path`` (a point whose group has no curves stays); the curves are read at the first call."""

    path: Path
    curves: dict[str, list[tuple]] | None = field(default=None, repr=False)

    def __call__(self, points: np.ndarray, names: np.ndarray) -> np.ndarray:
        if self.curves is None:
            self.curves = apart(_describe, Path(self.path))
        points, names = np.asarray(points, dtype=float), np.asarray(names, dtype=str)
        moved = points.copy()
        for name in np.unique(names):
            rows = np.flatnonzero(names == name)
            nearest, distance = points[rows].copy(), np.full(len(rows), np.inf)
            for curve in self.curves.get(str(name), []):
                closest = _closest(curve, points[rows], self.path)
                gap = np.linalg.norm(closest - points[rows], axis=1)
                better = gap < distance
                nearest[better], distance[better] = closest[better], gap[better]
            moved[rows] = nearest
        return moved


def _describe(path: Path) -> dict[str, list[tuple]]:
    """The curves of each physical group: ("line", a, b), ("arc", centre, radius, start, end, middle) or
    ("curve", tag)."""
    described: dict[str, list[tuple]] = {}
    with session() as gmsh:
        open_file(gmsh, path)
        for (dim, name), tags in physical_groups(gmsh, str(path)).items():
            if dim != 1:
                continue
            for tag in tags:
                kind = gmsh.model.getType(1, tag)
                low, high = (float(v[0]) for v in gmsh.model.getParametrizationBounds(1, tag))
                start, middle, end = np.asarray(gmsh.model.getValue(1, tag, [low, 0.5 * (low + high), high]),
                                                dtype=float).reshape(3, 3)[:, :2]
                if kind == "Line":
                    described.setdefault(name, []).append(("line", start, end))
                elif kind == "Circle":
                    centre = _circumcentre(start, middle, end)
                    described.setdefault(name, []).append(("arc", centre, float(np.linalg.norm(start - centre)),
                                                           start, end, middle))
                else:
                    described.setdefault(name, []).append(("curve", int(tag)))
    return described


def _circumcentre(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The centre of the circle through three points."""
    matrix = 2.0 * np.array([b - a, c - a])
    return a + np.linalg.solve(matrix, [np.dot(b - a, b - a), np.dot(c - a, c - a)])


def _closest(curve: tuple, points: np.ndarray, path: Path) -> np.ndarray:
    """The closest points ``(k, 2)`` of one described curve to ``points``."""
    if curve[0] == "line":
        _, start, end = curve
        direction = end - start
        t = np.clip((points - start) @ direction / (direction @ direction), 0.0, 1.0)
        return start + t[:, None] * direction
    if curve[0] == "arc":
        _, centre, radius, start, end, middle = curve
        offset = points - centre
        length = np.linalg.norm(offset, axis=1, keepdims=True)
        on_circle = centre + radius * offset / np.where(length > 0, length, 1.0)
        chord = end - start
        side = np.sign(chord[0] * (middle - start)[1] - chord[1] * (middle - start)[0])
        inside = np.sign(chord[0] * (on_circle - start)[:, 1] - chord[1] * (on_circle - start)[:, 0]) == side
        ends = np.where((np.linalg.norm(points - start, axis=1) <= np.linalg.norm(points - end, axis=1))[:, None],
                        start, end)
        return np.where(inside[:, None], on_circle, ends)
    return apart(_closest_in_gmsh, path, curve[1], points)


def _closest_in_gmsh(path: Path, tag: int, points: np.ndarray) -> np.ndarray:
    with session() as gmsh:
        open_file(gmsh, path)
        xyz = np.column_stack([points, np.zeros(len(points))]).ravel()
        closest, _ = gmsh.model.getClosestPoint(1, tag, xyz)
    return np.asarray(closest, dtype=float).reshape(-1, 3)[:, :2]
