"""Triangle meshes of the two halves Ω₋ = (−1,1)×(−1,0) and Ω₊ = (−1,1)×(0,1).

Both halves share their vertices on Σ = (−1,1)×{0}; crack tips are vertices.  Arrays follow meshio:
``points`` is row-major ``(n, 2)`` float64, ``cells`` is ``(m, 3)`` int64, counter-clockwise.
No PETSc or MPI here.
"""
from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from .errors import MeshError

#: Coordinates closer than this to x = ±1, y = 0, ±1 are snapped onto the line.
TOL = 1e-10


@dataclass(frozen=True)
class HalfMesh:
    """One half of the square; ``side`` is -1 (lower, y ≤ 0) or +1 (upper, y ≥ 0)."""

    points: np.ndarray
    cells: np.ndarray
    side: int

    @property
    def name(self) -> str:
        return "lower" if self.side < 0 else "upper"

    def sigma(self) -> np.ndarray:
        """Indices of the vertices on Σ (y = 0), sorted by x; endpoints included."""
        on = np.flatnonzero(self.points[:, 1] == 0.0)
        return on[np.argsort(self.points[on, 0], kind="stable")]

    def clamped(self) -> np.ndarray:
        """Indices of the vertices on Γ_D (x = ±1)."""
        return np.flatnonzero(np.abs(self.points[:, 0]) == 1.0)

    def _edge_keys(self) -> tuple[np.ndarray, np.ndarray]:
        """Every cell edge as (vertex pair, integer key smaller·n + larger), 3 per cell."""
        pairs = self.cells[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        return pairs, pairs.min(axis=1) * len(self.points) + pairs.max(axis=1)

    @cached_property
    def _boundary_edges(self) -> np.ndarray:
        pairs, keys = self._edge_keys()
        _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
        return pairs[counts[inverse] == 1]

    def boundary_edges(self) -> np.ndarray:
        """Edges used by exactly one triangle, oriented counter-clockwise around the half."""
        return self._boundary_edges

    def edges_on_line(self, y: float) -> np.ndarray:
        """Boundary edges lying on the horizontal line at height ``y``."""
        edges = self.boundary_edges()
        return edges[np.all(self.points[edges, 1] == y, axis=1)]

    def areas(self) -> np.ndarray:
        """Signed triangle areas (positive for counter-clockwise cells)."""
        p = self.points[self.cells]
        d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])


@dataclass(frozen=True)
class MeshStats:
    """Per-half numbers as in the paper's Table 1.

    The paper does not define its h; ``h_min``, ``h_max`` are the smallest and largest circumdiameter
    (2R) of a triangle, which matches all twenty of its values within 18 % on our meshes of its
    five (P, M) (the longest edge: within 23 %).
    """

    h_min: float
    h_max: float
    vertices: int
    triangles: int


def statistics(half: HalfMesh) -> MeshStats:
    p = half.points[half.cells]
    edges = np.linalg.norm(p - p[:, [1, 2, 0]], axis=2)
    circumdiameters = edges.prod(axis=1) / (2.0 * np.abs(half.areas()))
    return MeshStats(float(circumdiameters.min()), float(circumdiameters.max()), len(half.points), len(half.cells))


def snap(points: np.ndarray) -> np.ndarray:
    """Put coordinates within TOL of the square's lines and of Σ exactly on them."""
    points = np.array(points, dtype=np.float64)
    for value in (-1.0, 0.0, 1.0):
        points[np.abs(points - value) <= TOL] = value
    return points


def _compact(points: np.ndarray, cells: np.ndarray, side: int) -> HalfMesh:
    """Keep only the vertices the cells use, numbered by x (then y).

    Consecutive vertices then form vertical slabs, so a block distributed by contiguous row
    ranges gives each rank a compact piece of the half with a short boundary.
    """
    used = np.unique(cells)
    used = used[np.lexsort((points[used, 1], points[used, 0]))]
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    return HalfMesh(points[used], renumber[cells], side)


def split(points: np.ndarray, cells: np.ndarray, origin: str) -> tuple[HalfMesh, HalfMesh]:
    """Split a triangulation of the square into its halves by the side of Σ each cell lies on."""
    y = points[cells, 1]
    crossing = np.any(y < 0, axis=1) & np.any(y > 0, axis=1)
    if crossing.any():
        raise MeshError(f"{origin}: {crossing.sum()} triangles cross Σ (y = 0); Σ must be made of mesh edges")
    lower = np.any(y < 0, axis=1)
    flat = ~lower & ~np.any(y > 0, axis=1)
    if flat.any():
        raise MeshError(f"{origin}: {flat.sum()} degenerate triangles lie on Σ")
    return _compact(points, cells[lower], -1), _compact(points, cells[~lower], +1)


def read(path: Path) -> tuple[HalfMesh, HalfMesh]:
    """Read a triangle mesh of the square with meshio (any format it reads; see docs/usage.md)."""
    import meshio

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: mesh file not found")
    chatter = io.StringIO()
    try:
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            mesh = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many kinds (even SystemExit): all mean unreadable
        reason = str(exc) if not isinstance(exc, SystemExit) else chatter.getvalue()
        reason = " ".join(reason.split()) or exc.__class__.__name__
        raise MeshError(f"{path}: cannot read mesh ({reason})") from None
    triangles = [block.data for block in mesh.cells if block.type == "triangle"]
    if not triangles:
        raise MeshError(f"{path}: no triangle cells")
    cells = np.concatenate(triangles).astype(np.int64)
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"{path}: points must have 2 or 3 coordinates")
    if points.shape[1] == 3:
        if np.abs(points[:, 2]).max(initial=0.0) > TOL:
            raise MeshError(f"{path}: the mesh is not planar (z != 0)")
        points = points[:, :2]
    if cells.min() < 0 or cells.max() >= len(points):
        raise MeshError(f"{path}: cells refer to missing points")
    points = snap(points)
    p = points[cells]
    area = (p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0])
    if np.all(area < 0):  # a consistently clockwise file: adopt our orientation
        cells = cells[:, ::-1].copy()
    return split(points, cells, str(path))


def check(lower: HalfMesh, upper: HalfMesh, crack: tuple[float, float] | None, origin: str = "mesh") -> None:
    """Raise MeshError unless the halves form a valid decomposition for this crack."""
    for half in (lower, upper):
        where = f"{origin}: {half.name} half"
        x, y = half.points[:, 0], half.points[:, 1] * half.side
        if np.any(np.abs(x) > 1.0) or np.any(y < 0.0) or np.any(y > 1.0):
            raise MeshError(f"{where}: vertices outside its half of the square")
        area = half.areas()
        scale = np.abs(area).max(initial=0.0)
        if np.any(area <= 1e-12 * scale):
            bad = int(np.sum(area <= 1e-12 * scale))
            raise MeshError(f"{where}: {bad} inverted or degenerate triangles (non-positive area)")
        if len(half.clamped()) < 2:
            raise MeshError(f"{where}: no clamped boundary (x = ±1): the block would be singular")
        edges = half.boundary_edges()
        ends = half.points[edges]
        on_sides = np.all(np.abs(ends[:, :, 0]) == 1.0, axis=1) & (ends[:, 0, 0] == ends[:, 1, 0])
        on_lines = np.all(ends[:, :, 1] == ends[:, :1, 1], axis=1) & np.isin(ends[:, 0, 1], (0.0, half.side))
        if not np.all(on_sides | on_lines):
            raise MeshError(f"{where}: boundary edges inside the square (holes or non-conforming cells)")
        sigma = half.sigma()
        if len(sigma) < 3 or half.points[sigma[0], 0] != -1.0 or half.points[sigma[-1], 0] != 1.0:
            raise MeshError(f"{where}: Σ must run from (-1, 0) to (1, 0) through at least one inner vertex")
        if len(half.edges_on_line(0.0)) != len(sigma) - 1:
            raise MeshError(f"{where}: Σ is not covered by a chain of boundary edges")
    x_lower = lower.points[lower.sigma(), 0]
    x_upper = upper.points[upper.sigma(), 0]
    if len(x_lower) != len(x_upper) or np.abs(x_lower - x_upper).max() > TOL:
        raise MeshError(f"{origin}: Σ vertices of the two halves do not match")
    if crack is not None:
        for tip in crack:
            if np.abs(x_lower - tip).min() > TOL:
                raise MeshError(f"{origin}: crack tip x = {tip} is not a Σ vertex")


#: Grading of generated meshes: h(y) = h_Σ + (h_far − h_Σ)|y|^GRADING_EXPONENT, h_far = FAR_FACTOR·8/M.
#: Fitted so that the five meshes of the paper's Table 1 have its vertex and triangle counts (±5 %).
GRADING_EXPONENT = 0.8
FAR_FACTOR = 1.2


def apportion(total: int, lengths) -> np.ndarray:
    """Split ``total`` segments among pieces in proportion to their lengths (≥ 1 each, exact sum)."""
    lengths = np.asarray(lengths, dtype=float)
    ideal = total * lengths / lengths.sum()
    count = np.maximum(np.floor(ideal).astype(np.int64), 1)
    while count.sum() > total:
        count[int(np.argmax(np.where(count > 1, count - ideal, -np.inf)))] -= 1
    while count.sum() < total:
        count[int(np.argmax(ideal - count))] += 1
    return count


def generate(sigma_vertices: int, boundary_vertices: int, crack: tuple[float, float] | None,
             side: int) -> HalfMesh:
    """Unstructured graded triangulation of one half (side −1: lower, +1: upper) with gmsh.

    Σ gets P vertices (endpoints and crack tips included), spaced uniformly on each Σ piece; the
    square's boundary gets M vertices (bottom, top and the four half-sides in proportion to length).
    Inside, the size grows from the Σ spacing 2/(P − 1) to 1.2 × the boundary spacing 8/M at y = ±1.
    Each half is meshed on its own (one thread, deterministic): the Σ vertices come from the same
    transfinite curves, so the halves match, and a half is the same whether it is meshed alone in a
    process or after the other one.
    """
    import gmsh  # imported here: importing gmsh changes the SIGINT handler until finalize

    sigma_x = [-1.0, *crack, 1.0] if crack is not None else [-1.0, 1.0]
    h_sigma = 2.0 / (sigma_vertices - 1)
    slope = FAR_FACTOR * 8.0 / boundary_vertices - h_sigma
    gmsh.initialize([], readConfigFiles=False)
    try:
        for name, value in {"General.Terminal": 0, "General.Verbosity": 0, "General.NumThreads": 1,
                            "Mesh.MaxNumThreads2D": 1, "Mesh.Algorithm": 5, "Mesh.MeshSizeFromPoints": 0,
                            "Mesh.MeshSizeExtendFromBoundary": 0, "Mesh.MeshSizeFromCurvature": 0}.items():
            gmsh.option.setNumber(name, value)
        geo = gmsh.model.geo
        on_sigma = [geo.addPoint(x, 0.0, 0.0) for x in sigma_x]
        sigma = [geo.addLine(a, b) for a, b in zip(on_sigma[:-1], on_sigma[1:])]
        corners = [geo.addPoint(x, y, 0.0) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        bottom, top = geo.addLine(corners[0], corners[1]), geo.addLine(corners[2], corners[3])
        edges = [geo.addLine(corners[1], on_sigma[-1]), geo.addLine(on_sigma[0], corners[0]),
                 geo.addLine(on_sigma[-1], corners[2]), geo.addLine(corners[3], on_sigma[0])]
        if side < 0:
            surface = geo.addPlaneSurface([geo.addCurveLoop([bottom, edges[0], *[-c for c in sigma[::-1]], edges[1]])])
        else:
            surface = geo.addPlaneSurface([geo.addCurveLoop([*sigma, edges[2], top, edges[3]])])
        geo.synchronize()
        curves = [*sigma, bottom, top, *edges]
        counts = [*apportion(sigma_vertices - 1, np.diff(sigma_x)),
                  *apportion(boundary_vertices, [2.0, 2.0, 1.0, 1.0, 1.0, 1.0])]
        for curve, count in zip(curves, counts):
            gmsh.model.mesh.setTransfiniteCurve(curve, int(count) + 1)
        field = gmsh.model.mesh.field.add("MathEval")
        # gmsh's expression parser rejects "+ -c" (and aborts the process): write the sign out.
        gmsh.model.mesh.field.setString(field, "F", f"{h_sigma:.17f} {'+' if slope >= 0 else '-'} "
                                                    f"{abs(slope):.17f} * Fabs(y)^{GRADING_EXPONENT:.17f}")
        gmsh.model.mesh.field.setAsBackgroundMesh(field)
        gmsh.model.mesh.generate(2)
        tags, coordinates, _ = gmsh.model.mesh.getNodes()
        tags = np.asarray(tags, dtype=np.int64)
        points = snap(np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)[:, :2])
        position = np.full(int(tags.max()) + 1, -1, dtype=np.int64)
        position[tags] = np.arange(len(tags))
        _, nodes = gmsh.model.mesh.getElementsByType(2, surface)
        half = _compact(points, position[np.asarray(nodes, dtype=np.int64).reshape(-1, 3)], side)
        clockwise = half.areas() < 0
        half.cells[clockwise] = half.cells[clockwise][:, ::-1]
    finally:
        gmsh.finalize()
    return half


def boundary_vertex_count(lower: HalfMesh, upper: HalfMesh) -> int:
    """M: vertices on ∂Ω (the square's sides), the points (±1, 0) counted once."""
    coordinates = set()
    for half in (lower, upper):
        p = half.points
        outer = (np.abs(p[:, 0]) == 1.0) | (np.abs(p[:, 1]) == 1.0)
        coordinates.update(map(tuple, p[outer]))
    return len(coordinates)


def build(scene) -> tuple[HalfMesh, HalfMesh]:
    """The scene's meshes: read from ``mesh.file`` or generated from P and M; always checked."""
    if scene.mesh_file is not None:
        lower, upper = read(scene.mesh_file)
    else:
        lower, upper = (generate(scene.sigma_vertices, scene.boundary_vertices, scene.crack, side) for side in (-1, 1))
    check(lower, upper, scene.crack, origin(scene))
    return lower, upper


def origin(scene) -> str:
    """How to name the scene's mesh in messages."""
    return str(scene.mesh_file) if scene.mesh_file is not None else "generated mesh"
