"""Geometry: from a scene to a :class:`~ddsolve.mesh.Mesh`, by gmsh or from a file.

Three sources give the same thing:

- the built-in **box** ``geometry.box`` cut by Σ at ``geometry.sigma``, with cracks as x intervals
  on Σ and clamped sides; each half is meshed by gmsh on its own (so two ranks can mesh at once),
  with matching Σ nodes from the same transfinite curves.  Boundary names: ``bottom``, ``top``,
  ``left``, ``right``, ``sigma``, ``crack``, ``clamped``;
- a gmsh **.geo** script or **.msh** file with physical groups ``lower`` and ``upper`` (surfaces) and
  ``sigma``, ``clamped``, optionally ``crack`` and any other names (curves), see docs/geometry.md;
- any other **mesh file** meshio reads (or a .msh without those groups): triangles of the box, split
  into halves at Σ, boundaries named by the box's sides.

gmsh is imported only here, and only when a mesh is made.
"""
from __future__ import annotations

import contextlib
import io
import math
import multiprocessing
import os
import signal
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, TypeVar

import numpy as np

from .errors import MeshError, SceneError
from .launch import end_with_parent
from .mesh import CLAMPED, CRACK, SIGMA, TOL, HalfMesh, Mesh, elevate, make_half, make_mesh, merge_repeats, oriented
from .scene import SIDES, Geometry, MeshOptions, Scene, readable

#: Grading of the paper's mesh family: h(d) = h_Σ + (h_far − h_Σ)(d/H)^GRADING_EXPONENT at distance d
#: from Σ (H: the larger half height), h_far = FAR_FACTOR·perimeter/M.  Fitted so that the five meshes
#: of the paper's Table 1 have its vertex and triangle counts (±5 %).
GRADING_EXPONENT = 0.8
FAR_FACTOR = 1.2
T = TypeVar("T")
#: Physical groups a gmsh geometry must have.
REQUIRED_GROUPS = {2: ("lower", "upper"), 1: (SIGMA, CLAMPED)}
#: gmsh element types: triangle, 6-node triangle, line, 3-node line.
_TRIANGLE, _TRIANGLE6, _LINE, _LINE3 = 2, 9, 1, 8


def build(scene: Scene, background: SizeMap | None = None) -> Mesh:
    """The scene's mesh, from whichever source it names (sized by ``background`` if given); always checked."""
    options = scene.mesh
    if options.kind == "box":
        return pair(scene, *(generate_half(scene, side, background) for side in (-1, 1)))
    if options.kind == "geo" or (options.file.suffix.lower() == ".msh" and _has_halves(options.file)):
        return from_gmsh(scene, background)
    return read_box_file(scene)


def origin(scene: Scene) -> str:
    """How to name the scene's mesh in messages."""
    return str(scene.mesh.file) if scene.mesh.file is not None else "generated mesh"


def check_loads(scene: Scene, mesh: Mesh) -> None:
    """Every load names a boundary of the mesh that is not clamped (else a one-line SceneError)."""
    names = mesh.boundary_names()
    for (_, name), load in scene.loads.items():
        if name not in names:
            raise SceneError(f"{load.key}: no boundary named {name!r} in {mesh.origin} "
                             f"(boundaries: {', '.join(n for n in names if n != CLAMPED)})")
        if name == CLAMPED or all(_edge_set(half, name) <= _edge_set(half, CLAMPED) for half in mesh.halves):
            raise SceneError(f"{load.key}: boundary {name!r} is clamped (Γ_D), where no load can act")
        if all(np.isin(half.nodes(name), half.clamped()).all() for half in mesh.halves):
            raise SceneError(f"{load.key}: on this mesh every node of boundary {name!r} is clamped, so the load "
                             "would act on nothing (a mesh coarser than the geometry): use smaller elements "
                             "(mesh.size, or mesh.sigma_vertices and mesh.boundary_vertices) or mesh.degree = 2")


def _edge_set(half: HalfMesh, name: str) -> set[tuple[int, int]]:
    return set(map(tuple, np.sort(half.edges(name)[:, :2], axis=1).tolist()))


def pair(scene: Scene, lower: HalfMesh, upper: HalfMesh) -> Mesh:
    """The mesh of two halves made separately (box geometry)."""
    return make_mesh(lower, upper, origin(scene))


# --- the built-in box -----------------------------------------------------------------------------
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


def generate_half(scene: Scene, side: int, background: SizeMap | None = None) -> HalfMesh:
    """One half of the box meshed by gmsh (:func:`_mesh_half`) in a child process (:func:`apart`)."""
    return apart(_mesh_half, scene, side, background)


def _mesh_half(scene: Scene, side: int, background: SizeMap | None = None) -> HalfMesh:
    """Unstructured triangulation of one half of the box (side −1: lower, +1: upper) with gmsh.

    With (P, M): Σ gets P vertices (ends and crack tips included), uniform on each Σ piece; the outer
    boundary gets M vertices in proportion to length; inside, the size grows from the Σ spacing to
    ``FAR_FACTOR`` × the boundary spacing (the paper's family).  With ``mesh.size`` h: every curve is
    divided into pieces of about h and the size is h throughout.  With ``mesh.grading`` or a
    ``background`` size map (adaptive refinement), the size field alone (:func:`set_size_field`)
    sizes every curve and the inside.  One thread, deterministic: a half is the same whether it is
    meshed alone in a process or after the other one, and the Σ vertices of both halves come from the
    same curves meshed with the same size field.
    """
    import gmsh  # imported here: importing gmsh changes the SIGINT handler until finalize

    options = scene.mesh
    shift = local_origin(scene.geometry.box)  # gmsh meshes the box about a nearby origin
    geometry = translated(scene.geometry, -shift)
    if background is not None:
        background = SizeMap(background.corners - shift, background.sizes)
    x0, x1, y0, y1 = geometry.box
    ys = geometry.sigma
    cracks = [tip for piece in geometry.cracks for tip in piece if x0 < tip < x1]
    sigma_x = sorted({x0, *cracks, x1})
    width, below, above = x1 - x0, ys - y0, y1 - ys
    lengths = [width, width, below, below, above, above]  # bottom, top, the four half-sides
    if options.size is None:
        P, M = options.sigma_vertices, options.boundary_vertices
        h_sigma = width / (P - 1)
        slope = FAR_FACTOR * 2.0 * (width + below + above) / M - h_sigma
        counts = [*apportion(P - 1, np.diff(sigma_x)), *apportion(M, lengths)]
        size_field = (f"{h_sigma:.17f} {'+' if slope >= 0 else '-'} {abs(slope):.17f} * "
                      f"({_distance_to_sigma(ys, max(below, above))})^{GRADING_EXPONENT:.17f}")
    else:
        h = options.size
        counts = [max(1, math.ceil(length / h - 1e-9)) for length in [*np.diff(sigma_x), *lengths]]
        size_field = f"{h:.17f}"
    gmsh.initialize([], readConfigFiles=False)
    try:
        _quiet_deterministic(gmsh)
        geo = gmsh.model.geo
        on_sigma = [geo.addPoint(x, ys, 0.0) for x in sigma_x]
        sigma = [geo.addLine(a, b) for a, b in zip(on_sigma[:-1], on_sigma[1:])]
        corners = [geo.addPoint(x, y, 0.0) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
        bottom, top = geo.addLine(corners[0], corners[1]), geo.addLine(corners[2], corners[3])
        edges = [geo.addLine(corners[1], on_sigma[-1]), geo.addLine(on_sigma[0], corners[0]),
                 geo.addLine(on_sigma[-1], corners[2]), geo.addLine(corners[3], on_sigma[0])]
        if side < 0:
            surface = geo.addPlaneSurface([geo.addCurveLoop([bottom, edges[0], *[-c for c in sigma[::-1]], edges[1]])])
        else:
            surface = geo.addPlaneSurface([geo.addCurveLoop([*sigma, edges[2], top, edges[3]])])
        geo.synchronize()
        if options.grading is None and background is None:
            for curve, count in zip([*sigma, bottom, top, *edges], counts):
                gmsh.model.mesh.setTransfiniteCurve(curve, int(count) + 1)
            field = gmsh.model.mesh.field.add("MathEval")
            gmsh.model.mesh.field.setString(field, "F", size_field)
            gmsh.model.mesh.field.setAsBackgroundMesh(field)
        else:
            set_size_field(gmsh, options, box_singular_points(geometry), _box_length(geometry), background)
        gmsh.model.mesh.generate(2)
        tags, coordinates, _ = gmsh.model.mesh.getNodes()
        points = np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)[:, :2]
        position = _positions(tags)
        _, nodes = gmsh.model.mesh.getElementsByType(_TRIANGLE, surface)
        cells = position[np.asarray(nodes, dtype=np.int64).reshape(-1, 3)]
    finally:
        gmsh.finalize()
    half = _box_half(points, cells, side, geometry, options.degree, origin(scene))
    return replace(half, points=half.points + shift)


def local_origin(box) -> np.ndarray:
    """The point about which the box is meshed: the multiple of a power of two (at least 64 box sizes)
    nearest the box's centre.  It is (0, 0) for a box near the origin; for a box far away, coordinates
    relative to it are exact (a box at x = 1e9 is meshed as one at x = 0: gmsh fails on the former)."""
    x0, x1, y0, y1 = box
    unit = 2.0 ** math.ceil(math.log2(64.0 * max(x1 - x0, y1 - y0)))
    return np.array([round(0.5 * (x0 + x1) / unit) * unit, round(0.5 * (y0 + y1) / unit) * unit])


def translated(geometry: Geometry, offset: np.ndarray) -> Geometry:
    """The box geometry moved by ``offset`` (dx, dy)."""
    dx, dy = (float(v) for v in offset)
    x0, x1, y0, y1 = geometry.box
    return replace(geometry, box=(x0 + dx, x1 + dx, y0 + dy, y1 + dy), sigma=geometry.sigma + dy,
                   cracks=tuple((a + dx, b + dx) for a, b in geometry.cracks))


def estimated_vertices(scene: Scene) -> float | None:
    """About how many vertices :func:`generate_half` makes for both halves of the box (the paper's
    family integrated over its size field, or a uniform ``mesh.size``; P2 nodes counted as vertices of
    the halved size); None for geometries from files."""
    options = scene.mesh
    if options.kind != "box":
        return None
    x0, x1, y0, y1 = scene.geometry.box
    width, below, above = x1 - x0, scene.geometry.sigma - y0, y1 - scene.geometry.sigma
    if options.size is not None:
        count = 2.0 / math.sqrt(3.0) * width * (below + above) / options.size ** 2
    else:
        h_sigma = width / (options.sigma_vertices - 1)
        slope = FAR_FACTOR * 2.0 * (width + below + above) / options.boundary_vertices - h_sigma
        count = 0.0
        for height in (below, above):
            distance = np.linspace(0.0, height, 401)
            size = h_sigma + slope * (distance / max(below, above)) ** GRADING_EXPONENT
            density = 2.0 / (math.sqrt(3.0) * size ** 2)
            count += width * float(np.sum(0.5 * (density[1:] + density[:-1]) * np.diff(distance)))
    return count * options.degree ** 2


def _distance_to_sigma(ys: float, height: float) -> str:
    """gmsh MathEval text for |y − ys| / height (written out so the paper's square gives Fabs(y))."""
    shifted = "y" if ys == 0.0 else f"(y {'-' if ys > 0 else '+'} {abs(ys):.17f})"
    return f"Fabs({shifted})" if height == 1.0 else f"Fabs({shifted}) / {height:.17f}"


def _quiet_deterministic(gmsh) -> None:
    for name, value in {"General.Terminal": 0, "General.Verbosity": 0, "General.NumThreads": 1,
                        "Mesh.MaxNumThreads2D": 1, "Mesh.Algorithm": 5, "Mesh.MeshSizeFromPoints": 0,
                        "Mesh.MeshSizeExtendFromBoundary": 0, "Mesh.MeshSizeFromCurvature": 0}.items():
        gmsh.option.setNumber(name, value)


# --- size fields: grading towards singular points, and background sizes for adaptive refinement -----
#: Radius R of the graded zone around a singular point, as a fraction of the shorter side of the
#: geometry's bounding box (the error per unknown changes by a few % between 0.07 and 0.2).
GRADING_RADIUS = 0.14
#: The smallest mesh size asked of gmsh, as a fraction of the geometry's length, per source.  gmsh 4.8
#: leaves flat triangles of three Σ nodes, or aborts, when asked for much smaller triangles: measured
#: robust down to 2e-7 on the box's straight lines and 1e-5 on gmsh geometries with curved Σ (not 3e-6).
#: The floor costs accuracy only at tips with a large stress intensity and targets near 0.1 % or below.
SMALLEST = {"box": 2e-7, "geo": 1e-5}
#: gmsh's Mesh.RandomFactor (points are perturbed by this times the model size): gmsh's default, 1e-9,
#: folds the smallest graded triangles; 1e-13 makes gmsh abort on the box.
RANDOM_FACTOR = 1e-11
#: Interior angles above π(1 + this) are re-entrant corners.
REENTRANT = 1e-6


@dataclass(frozen=True)
class SizeMap:
    """A mesh-size field given on triangles covering the geometry (adaptive refinement): the corners
    ``(t, 3, 2)`` and the wanted mesh size at each ``(t, 3)``, linear in between."""

    corners: np.ndarray
    sizes: np.ndarray


def graded_size(distance: np.ndarray, size: float, mu: float, length: float, smallest: float = 0.0) -> np.ndarray:
    """h(r) = H ((r + r₀)/R)^(1−μ), at most H: the size at distance r from a singular point of a
    geometry whose shorter side is ``length`` (R = ``GRADING_RADIUS`` × length; r₀ from
    :func:`grading_offset`)."""
    radius = GRADING_RADIUS * length
    offset = grading_offset(size, mu, length, smallest)
    return np.minimum(size, size * ((np.asarray(distance) + offset) / radius) ** (1.0 - mu))


def grading_offset(size: float, mu: float, length: float, smallest: float = 0.0) -> float:
    """r₀ = R (H/R)^(1/μ), which makes h(0) = r₀ (the smallest triangle at the point is as large as the
    distance at which it is needed), but at least ``smallest`` × length, and large enough that h(0) is
    too (a small μ asks for h(0) far below r₀); R when H ≥ R (no grading)."""
    radius = GRADING_RADIUS * length
    if size >= radius:
        return radius
    floor = smallest * length
    return max(radius * (size / radius) ** (1.0 / mu), floor, radius * (floor / size) ** (1.0 / (1.0 - mu)))


def box_singular_points(geometry: Geometry) -> np.ndarray:
    """``(k, 2)``: where the solution in the box is singular: crack tips and crack ends, the ends of Σ
    (Σ meets the outer boundary), and the corners where a clamped side meets a free one."""
    x0, x1, y0, y1 = geometry.box
    ys = geometry.sigma
    points = {(x0, ys), (x1, ys), *((x, ys) for piece in geometry.cracks for x in piece)}
    corners = {("bottom", "left"): (x0, y0), ("bottom", "right"): (x1, y0),
               ("top", "right"): (x1, y1), ("top", "left"): (x0, y1)}
    for sides, corner in corners.items():
        if sum(side in geometry.clamped for side in sides) == 1:
            points.add(corner)
    return np.array(sorted(points), dtype=np.float64)


def _box_length(geometry: Geometry) -> float:
    """The shorter side of the box."""
    x0, x1, y0, y1 = geometry.box
    return float(min(x1 - x0, y1 - y0))


def model_singular_points(gmsh, groups: dict[tuple[int, str], list[int]]) -> np.ndarray:
    """``(k, 2)``: the singular points of a gmsh geometry with physical groups.

    A point is singular where a crack curve ends on anything else (a crack tip, or a crack reaching
    the outer boundary), where Σ meets the outer boundary, where a clamped curve meets a free one
    (the boundary condition changes), and where a half has a re-entrant corner (interior angle > π)
    that is not inside the glued part of Σ (there the material continues into the other half).
    """
    crack, sigma, clamped = (set(groups.get((1, name), [])) for name in (CRACK, SIGMA, CLAMPED))
    halves = set(groups[(2, "lower")]) | set(groups[(2, "upper")])

    def role(curve: int) -> str | None:
        if curve in crack:
            return "crack"
        if curve in sigma:
            return "glued"
        surfaces = set(gmsh.model.getAdjacencies(1, curve)[0]) & halves
        if len(surfaces) != 1:
            return None  # not on the boundary of a half
        return "clamped" if curve in clamped else "free"

    singular = []
    for _, point in gmsh.model.getEntities(0):
        roles = {role(int(curve)) for curve in gmsh.model.getAdjacencies(0, point)[0]} - {None}
        outer = roles & {"clamped", "free"}
        if ("crack" in roles and len(roles) > 1) or (roles & {"crack", "glued"} and outer) \
                or outer == {"clamped", "free"} \
                or ("glued" not in roles and roles and _reentrant(gmsh, point, halves)):
            singular.append(gmsh.model.getValue(0, point, [])[:2])
    return np.array(singular, dtype=np.float64).reshape(-1, 2)


def _reentrant(gmsh, point: int, surfaces: set[int]) -> bool:
    """Whether one of ``surfaces`` has an interior angle above π at the geometry point ``point``."""
    where = np.asarray(gmsh.model.getValue(0, point, []), dtype=float)[:2]
    for surface in surfaces:
        boundary = gmsh.model.getBoundary([(2, surface)], combined=False, oriented=True)
        curves = [(abs(tag), 1.0 if tag > 0 else -1.0) for _, tag in boundary]
        ends = {}
        area = 0.0
        for curve, sign in curves:
            low, high = (float(v[0]) for v in gmsh.model.getParametrizationBounds(1, curve))
            s, w = np.polynomial.legendre.leggauss(16)
            t = low + 0.5 * (s + 1.0) * (high - low)
            xyz = np.asarray(gmsh.model.getValue(1, curve, t), dtype=float).reshape(-1, 3)
            dxyz = np.asarray(gmsh.model.getDerivative(1, curve, t), dtype=float).reshape(-1, 3)
            area += sign * 0.5 * (high - low) * np.sum(w * xyz[:, 0] * dxyz[:, 1])  # ∮ x dy
            start, end = (np.asarray(gmsh.model.getValue(1, curve, [v]), dtype=float)[:2] for v in (low, high))
            start_tangent, end_tangent = (sign * np.asarray(gmsh.model.getDerivative(1, curve, [v]), dtype=float)[:2]
                                          for v in (low, high))
            if sign < 0:
                start, end, start_tangent, end_tangent = end, start, end_tangent, start_tangent
            scale = np.linalg.norm(start - end) + np.linalg.norm(start) + 1.0
            if np.linalg.norm(end - where) <= TOL * scale:
                ends["in"] = end_tangent
            if np.linalg.norm(start - where) <= TOL * scale:
                ends["out"] = start_tangent
        if len(ends) != 2:
            continue
        incoming, outgoing = ends["in"], ends["out"]
        turning = np.arctan2(incoming[0] * outgoing[1] - incoming[1] * outgoing[0], incoming @ outgoing)
        interior = np.pi - turning if area > 0 else np.pi + turning  # material on the left when area > 0
        if interior > np.pi * (1.0 + REENTRANT):
            return True
    return False


def _point_tags(gmsh, points: np.ndarray) -> list[int]:
    """The tags of the geometry points at ``points`` (every singular point is one)."""
    tags = [tag for _, tag in gmsh.model.getEntities(0)]
    where = np.array([gmsh.model.getValue(0, tag, [])[:2] for tag in tags]).reshape(-1, 2)
    scale = np.ptp(where, axis=0).max(initial=0.0) + 1.0
    return [tags[int(np.argmin(np.linalg.norm(where - point, axis=1)))] for point in points
            if np.linalg.norm(where - point, axis=1).min() <= TOL * scale]


def set_size_field(gmsh, options: MeshOptions, singular: np.ndarray, length: float,
                   background: SizeMap | None) -> None:
    """Make the background mesh size of the current gmsh model: :func:`graded_size` around each
    singular point when ``options.grading`` (μ) is set, the ``background`` sizes when given, the
    smaller of the two where both are; nothing else (points, boundaries, curvature) sizes the mesh."""
    fields = []
    if options.grading is not None and len(singular):
        size, mu, radius = options.size, options.grading, GRADING_RADIUS * length
        offset = grading_offset(size, mu, length, SMALLEST[options.kind])
        distance = gmsh.model.mesh.field.add("Distance")
        gmsh.model.mesh.field.setNumbers(distance, "PointsList", _point_tags(gmsh, singular))
        field = gmsh.model.mesh.field.add("MathEval")
        gmsh.model.mesh.field.setString(field, "F", f"{size:.17g} * ((F{distance} + {offset:.17g}) / "
                                                    f"{radius:.17g})^{1.0 - mu:.17g}")
        fields.append(field)
    if options.grading is not None:
        field = gmsh.model.mesh.field.add("MathEval")
        gmsh.model.mesh.field.setString(field, "F", f"{options.size:.17g}")
        fields.append(field)
    if background is not None:
        view = gmsh.view.add("sizes")
        corners, sizes = background.corners, np.maximum(background.sizes, SMALLEST[options.kind] * length)
        data = np.concatenate([corners[:, :, 0], corners[:, :, 1], np.zeros((len(corners), 3)), sizes], axis=1)
        gmsh.view.addListData(view, "ST", len(corners), data.ravel())
        field = gmsh.model.mesh.field.add("PostView")
        gmsh.model.mesh.field.setNumber(field, "ViewTag", view)
        fields.append(field)
    if len(fields) > 1:
        field = gmsh.model.mesh.field.add("Min")
        gmsh.model.mesh.field.setNumbers(field, "FieldsList", fields)
    gmsh.model.mesh.field.setAsBackgroundMesh(field)
    for name in ("Mesh.MeshSizeFromPoints", "Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromCurvature"):
        gmsh.option.setNumber(name, 0)
    # Frontal-Delaunay and small random perturbations: with the defaults (Delaunay, 1e-9) gmsh leaves
    # flat or folded triangles at graded tips.
    gmsh.option.setNumber("Mesh.Algorithm", 6)
    gmsh.option.setNumber("Mesh.RandomFactor", RANDOM_FACTOR)


def _positions(tags) -> np.ndarray:
    """Index of each gmsh node tag in the order ``getNodes`` returned them."""
    tags = np.asarray(tags, dtype=np.int64)
    position = np.full(int(tags.max(initial=0)) + 1, -1, dtype=np.int64)
    position[tags] = np.arange(len(tags))
    return position


def snap(points: np.ndarray, geometry: Geometry) -> np.ndarray:
    """Coordinates within TOL (relative) of the box's lines or of Σ put exactly on them."""
    x0, x1, y0, y1 = geometry.box
    scale = max(x1 - x0, y1 - y0)
    points = np.array(points, dtype=np.float64)
    for column, values in ((0, (x0, x1)), (1, (y0, geometry.sigma, y1))):
        for value in values:
            near = np.abs(points[:, column] - value) <= TOL * scale
            points[near, column] = value
    return points


def _box_half(points: np.ndarray, cells: np.ndarray, side: int, geometry: Geometry, degree: int,
              where: str) -> HalfMesh:
    """A half of the box from P1 triangles: boundaries named by the sides they lie on."""
    points = snap(points, geometry)
    cells = oriented(points, cells, f"{where}: {'lower' if side < 0 else 'upper'} half")
    boundaries = box_boundaries(points, cells, geometry, where)
    if degree == 2:
        points, cells, boundaries = elevate(points, cells, boundaries)
    half, _ = make_half(points, cells, side, boundaries, where)
    return half


def box_boundaries(points: np.ndarray, cells: np.ndarray, geometry: Geometry, where: str) -> dict[str, np.ndarray]:
    """Boundary edges of one half of the box by name: the sides, Σ, the cracks on Σ, Γ_D."""
    x0, x1, y0, y1 = geometry.box
    pairs = cells[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    keys = np.minimum(pairs[:, 0], pairs[:, 1]) * len(points) + np.maximum(pairs[:, 0], pairs[:, 1])
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    outer = pairs[counts[inverse] == 1]
    ends = points[outer]
    lines = {"bottom": (1, y0), "top": (1, y1), "left": (0, x0), "right": (0, x1), SIGMA: (1, geometry.sigma)}
    named = {name: outer[np.all(ends[:, :, column] == value, axis=1)] for name, (column, value) in lines.items()}
    covered = sum(len(edges) for edges in named.values())
    if covered != len(outer):
        raise MeshError(f"{where}: {len(outer) - covered} boundary edges lie inside the box (holes or "
                        "non-conforming cells)")
    sigma_x = points[named[SIGMA], 0]
    scale = x1 - x0
    on_crack = np.zeros(len(sigma_x), dtype=bool)
    for a, b in geometry.cracks:
        for tip in (a, b):
            if x0 < tip < x1 and np.abs(sigma_x - tip).min(initial=np.inf) > TOL * scale:
                raise MeshError(f"{where}: crack tip x = {tip:g} is not a Σ vertex")
        on_crack |= np.all((sigma_x >= a - TOL * scale) & (sigma_x <= b + TOL * scale), axis=1)
    named[CRACK] = named[SIGMA][on_crack]
    named[CLAMPED] = np.concatenate([named[name] for name in geometry.clamped]) if geometry.clamped \
        else np.zeros((0, 2), dtype=np.int64)
    return {name: edges for name, edges in named.items() if len(edges)}


# --- gmsh in a child process -------------------------------------------------------------------
def apart(work: Callable[..., T], *args) -> T:
    """``work(*args)`` in a forked child process; its value or exception comes back through a pipe.

    gmsh does not return to Python while it meshes (a minute for a large mesh), so in this process a
    signal handler would run only after it; here the parent waits in short steps, and on SIGTERM or
    Ctrl-C it kills the child and goes on with its own clean exit.  (The child touches no MPI.)  The
    child never outlives this process, however it ends (SIGKILL included): see :func:`_child`.
    """
    context = multiprocessing.get_context("fork")
    receiver, sender = context.Pipe(duplex=False)
    child = context.Process(target=_child, args=(os.getpid(), sender, work, args), daemon=True)
    # An interrupt inside fork's hooks (logging's lock release) would be printed as "Exception ignored":
    # it waits, blocked, until the child exists, and then reaches this process's handler as usual.
    interrupts = {signal.SIGINT, signal.SIGTERM}
    signal.pthread_sigmask(signal.SIG_BLOCK, interrupts)
    try:
        child.start()
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, interrupts)
    sender.close()
    try:
        while not receiver.poll(0.05):
            if not child.is_alive() and not receiver.poll(0.05):
                break
        try:
            ok, value = receiver.recv()
        except EOFError:  # the child ended without an answer (gmsh aborted it)
            child.join()
            raise MeshError(f"gmsh stopped without a mesh (it aborted, exit status {child.exitcode}): change the element "
                            "sizes (mesh.size, mesh.grading, the sizes of a .geo) or the geometry") from None
    finally:
        receiver.close()
        if child.is_alive():
            child.kill()
        child.join()
    if not ok:
        raise value
    return value


def _child(parent: int, sender, work, args) -> None:
    # The kernel kills this process when its parent ends; SIGINT and SIGTERM end it at once (gmsh does
    # not return to Python for them), and they no longer wake the parent's watchdog through the
    # inherited wakeup fd: the parent, which gets them too, cleans up and kills this child itself.
    end_with_parent(parent)
    signal.set_wakeup_fd(-1)
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})  # blocked across the fork
    quiet = os.open(os.devnull, os.O_WRONLY)  # gmsh writes its aborts to standard error: the parent reports
    os.dup2(quiet, 2)
    os.close(quiet)
    try:
        outcome = (True, work(*args))
    except BaseException as exc:  # every error goes back to the parent, which raises it
        outcome = (False, exc)
    sender.send(outcome)
    sender.close()


# --- files of the box (any format meshio reads) ---------------------------------------------------
def read_box_file(scene: Scene) -> Mesh:
    """A triangle mesh of the box from a file (any format meshio reads)."""
    points, cells = _read_triangles(scene.mesh.file)
    return split_box(points, cells, scene.geometry, scene.mesh.degree, origin(scene))


def split_box(points: np.ndarray, cells: np.ndarray, geometry: Geometry, degree: int = 1,
              where: str = "mesh") -> Mesh:
    """The mesh of P1 triangles of the box: split at Σ by the side each cell lies on."""
    points = snap(points, geometry)
    y = points[cells, 1] - geometry.sigma
    crossing = np.any(y < 0, axis=1) & np.any(y > 0, axis=1)
    if crossing.any():
        raise MeshError(f"{where}: {crossing.sum()} triangles cross Σ (y = {geometry.sigma:g}); Σ must be made "
                        "of mesh edges")
    lower = np.any(y < 0, axis=1)
    flat = ~lower & ~np.any(y > 0, axis=1)
    if flat.any():
        raise MeshError(f"{where}: {flat.sum()} degenerate triangles lie on Σ")
    halves = [_box_half(points, cells[lower if side < 0 else ~lower], side, geometry, degree, where)
              for side in (-1, 1)]
    return make_mesh(*halves, where)


def _read_triangles(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(n, 2)`` and triangles of a mesh file meshio reads; every failure is a MeshError."""
    import meshio

    readable(path, "mesh file", MeshError)
    chatter = io.StringIO()
    try:
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            mesh = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many kinds (even SystemExit): all mean unreadable
        reason = str(exc) if not isinstance(exc, SystemExit) else chatter.getvalue()
        reason = " ".join(reason.split()) or exc.__class__.__name__
        raise MeshError(f"{path}: cannot read mesh ({reason})") from None
    physical = mesh.cell_data.get("gmsh:physical", [None] * len(mesh.cells))
    blocks = [(block.data, tags) for block, tags in zip(mesh.cells, physical) if block.type == "triangle"]
    if not blocks:
        raise MeshError(f"{path}: no triangle cells")
    cells = np.concatenate([data for data, _ in blocks]).astype(np.int64)
    # A MSH 2.2 file lists a triangle once per physical group: one triangle (a repeat in one group stays).
    groups = np.concatenate([np.zeros(len(data)) if tags is None else np.ravel(tags) for data, tags in blocks])
    cells = merge_repeats(cells, groups.astype(np.int64))
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"{path}: points must have 2 or 3 coordinates")
    if not np.all(np.isfinite(points)):
        raise MeshError(f"{path}: non-finite point coordinates")
    if points.shape[1] == 3:
        if np.abs(points[:, 2]).max(initial=0.0) > TOL * max(np.ptp(points[:, :2], axis=0).max(), 1e-300):
            raise MeshError(f"{path}: the mesh is not planar (z != 0)")
        points = points[:, :2]
    if cells.min() < 0 or cells.max() >= len(points):
        raise MeshError(f"{path}: cells refer to missing points")
    return points, cells


# --- gmsh geometries with physical groups --------------------------------------------------------
def _has_halves(path: Path) -> bool:
    """Whether a .msh file has the physical surfaces ``lower`` and ``upper`` (else it is a box file)."""
    import gmsh

    readable(path, "mesh file", MeshError)
    gmsh.initialize([], readConfigFiles=False)
    try:
        _quiet(gmsh)
        _open(gmsh, path)
        names = {gmsh.model.getPhysicalName(dim, tag) for dim, tag in gmsh.model.getPhysicalGroups(2)}
    finally:
        gmsh.finalize()
    return {"lower", "upper"} <= names


def _quiet(gmsh) -> None:
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.option.setNumber("General.Verbosity", 0)


def _open(gmsh, path: Path) -> None:
    try:
        gmsh.open(str(path))
    except Exception as exc:  # gmsh raises a bare Exception with its last error
        raise MeshError(f"{path}: gmsh cannot read it ({' '.join(str(exc).split())})") from None


def from_gmsh(scene: Scene, background: SizeMap | None = None) -> Mesh:
    """A .geo meshed or a .msh read by gmsh (:func:`_from_gmsh`) in a child process (:func:`apart`)."""
    return apart(_from_gmsh, scene, background)


def _from_gmsh(scene: Scene, background: SizeMap | None = None) -> Mesh:
    """Mesh a .geo (honouring ``mesh.size``, ``mesh.grading`` and a ``background`` size map) or read a
    .msh, both with physical groups."""
    import gmsh

    path, options = scene.mesh.file, scene.mesh
    where = str(path)
    if scene.geometry.given:
        raise MeshError(f"{where}: geometry.{sorted(scene.geometry.given)[0]} does not apply to a geometry "
                        "with physical groups (they define it)")
    readable(path, "mesh file", MeshError)
    gmsh.initialize([], readConfigFiles=False)
    try:
        _quiet(gmsh)
        if options.kind == "geo":
            gmsh.option.setNumber("General.NumThreads", 1)
            gmsh.option.setNumber("Mesh.MaxNumThreads2D", 1)
        _open(gmsh, path)
        groups = _physical_groups(gmsh, where)
        if options.kind == "geo":
            if options.size is not None:
                gmsh.option.setNumber("Mesh.MeshSizeMax", options.size)
            low, high = np.reshape(gmsh.model.getBoundingBox(-1, -1), (2, 3))
            length = float(np.min((high - low)[:2]))
            _bounded_curves(gmsh, groups, options.degree, length, where)
            if options.grading is not None or background is not None:
                singular = model_singular_points(gmsh, groups) if options.grading is not None else None
                set_size_field(gmsh, options, singular, length, background)
            try:
                gmsh.model.mesh.generate(2)
                if options.degree == 2:
                    gmsh.model.mesh.setOrder(2)
            except Exception as exc:
                raise MeshError(f"{where}: gmsh cannot mesh it ({' '.join(str(exc).split())})") from None
        tags, coordinates, _ = gmsh.model.mesh.getNodes()
        points = np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)
        if np.abs(points[:, 2]).max(initial=0.0) > TOL * max(np.ptp(points[:, :2], axis=0).max(), 1e-300):
            raise MeshError(f"{where}: the geometry is not planar (z != 0)")
        points = points[:, :2]
        position = _positions(tags)
        surfaces = {name: _elements(gmsh, groups[(2, name)], (_TRIANGLE, _TRIANGLE6), position, where)
                    for name in ("lower", "upper")}
        curves = {name: _elements(gmsh, entities, (_LINE, _LINE3), position, where)
                  for (dim, name), entities in groups.items() if dim == 1}
        normals = _curve_normals(gmsh, groups[(1, SIGMA)], position, len(points)) if options.kind == "geo" else None
    finally:
        gmsh.finalize()
    cells = surfaces["lower"]
    if cells.shape[1] == 6 and options.degree == 1:
        raise MeshError(f"{where}: the file has 6-node (P2) triangles: set mesh.degree = 2")
    halves, renumbered = [], []
    for side, name in ((-1, "lower"), (1, "upper")):
        cells = surfaces[name]
        used = np.zeros(len(points), dtype=bool)
        used[cells] = True
        mine = {curve: edges[used[edges].all(axis=1)] for curve, edges in curves.items()}
        half_points = points
        if cells.shape[1] == 3 and options.degree == 2:
            half_points, cells, mine = elevate(points, cells, {k: v[:, :2] for k, v in mine.items()})
        half, renumber = make_half(half_points, cells, side, mine, where)
        halves.append(half)
        renumbered.append(renumber)
    exact = None
    if normals is not None:
        lower = halves[0]
        old = np.full(len(lower.points), -1, dtype=np.int64)
        old[renumbered[0][renumbered[0] >= 0]] = np.flatnonzero(renumbered[0] >= 0)
        exact = normals[old[lower.sigma]]
    return make_mesh(*halves, where, exact_normals=exact)


def _bounded_curves(gmsh, groups: dict[tuple[int, str], list[int]], degree: int, length: float, where: str) -> None:
    """Refuse a .geo whose own sizes (its points' sizes, Mesh.MeshSizeFactor, mesh.size) ask gmsh for more
    than it can do: elements below ``SMALLEST`` × the geometry's length, or a mesh too large to solve in
    this machine's memory.  Its curves are meshed without the factor and with sizes of at least that
    floor (a bounded amount of work), measured, and the mesh cleared; the smallest size asked is the
    shortest edge times the factor, the number of vertices is estimated from the nodes on each surface's
    boundary (divided by the factor).  gmsh itself, asked for too many nodes on a curve, makes one
    element of it without a word, or asks on the terminal whether to go on."""
    from .cli import RANK_MEMORY, VERTEX_MEMORY, _physical_memory

    floor = SMALLEST["geo"] * length
    saved = {name: gmsh.option.getNumber(name) for name in ("Mesh.MeshSizeFactor", "Mesh.MeshSizeMin")}
    factor = saved["Mesh.MeshSizeFactor"]
    gmsh.option.setNumber("Mesh.MeshSizeFactor", 1.0)
    gmsh.option.setNumber("Mesh.MeshSizeMin", max(saved["Mesh.MeshSizeMin"], floor))
    try:
        gmsh.model.mesh.generate(1)
    except Exception as exc:
        raise MeshError(f"{where}: gmsh cannot mesh it ({' '.join(str(exc).split())})") from None
    finally:
        for name, value in saved.items():
            gmsh.option.setNumber(name, value)
    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    points = np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)[_positions(tags)[
        np.asarray(gmsh.model.mesh.getElementsByType(_LINE)[1], dtype=np.int64)]].reshape(-1, 2, 3)
    shortest = factor * float(np.linalg.norm(points[:, 1] - points[:, 0], axis=1).min(initial=math.inf))
    vertices = 0.0
    for surface in groups[(2, "lower")] + groups[(2, "upper")]:
        curves = {abs(tag) for _, tag in gmsh.model.getBoundary([(2, surface)], combined=False)}
        boundary = sum(len(gmsh.model.mesh.getNodes(1, curve, includeBoundary=True)[0]) for curve in curves)
        vertices += VERTICES_PER_BOUNDARY_NODE_SQUARED * (boundary / min(factor, 1.0)) ** 2 * degree ** 2
    gmsh.model.mesh.clear()
    if shortest <= 1.5 * floor:
        raise MeshError(f"{where}: the file asks gmsh for elements of size {min(shortest, floor):.2g} or less (its points' "
                        f"sizes times Mesh.MeshSizeFactor = {factor:g}), below what gmsh meshes reliably "
                        f"({SMALLEST['geo']:g} × the geometry's size {length:.3g}): enlarge them")
    memory = RANK_MEMORY + vertices * VERTEX_MEMORY
    if memory > _physical_memory():
        raise MeshError(f"{where}: its sizes (its points' sizes, Mesh.MeshSizeFactor = {factor:g}, mesh.size) give a "
                        f"mesh of about {vertices:.2g} vertices, which needs about {memory / 1e9:.2g} GB to solve, more "
                        f"than this machine's {_physical_memory() / 1e9:.3g} GB: enlarge them")


#: Vertices of a uniform mesh of a surface per square of the number of nodes on its boundary: 0.072 for a
#: square, 0.092 for a disc (2/√3 vertices per h², boundary length/h nodes).
VERTICES_PER_BOUNDARY_NODE_SQUARED = 0.08


def _physical_groups(gmsh, where: str) -> dict[tuple[int, str], list[int]]:
    """(dim, name) -> entity tags; the required groups must exist."""
    groups: dict[tuple[int, str], list[int]] = {}
    for dim, tag in gmsh.model.getPhysicalGroups():
        name = gmsh.model.getPhysicalName(dim, tag)
        if dim in (1, 2) and name:
            groups.setdefault((dim, name), []).extend(int(e) for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag))
    for dim, names in REQUIRED_GROUPS.items():
        for name in names:
            if (dim, name) not in groups:
                kind = "surface" if dim == 2 else "curve"
                raise MeshError(f"{where}: missing physical {kind} {name!r} (required: surfaces lower, upper; "
                                "curves sigma, clamped; optional: crack and names for loads)")
    return groups


def _elements(gmsh, entities: list[int], types: tuple[int, int], position: np.ndarray, where: str) -> np.ndarray:
    """Node indices of the elements of ``entities`` (of the linear or the quadratic type), each once
    (:func:`~ddsolve.mesh.merge_repeats`: a MSH 2.2 file lists an element once per physical group)."""
    dim = 2 if types[0] == _TRIANGLE else 1
    width = {_TRIANGLE: 3, _TRIANGLE6: 6, _LINE: 2, _LINE3: 3}
    found = {t: [] for t in types}
    for entity in dict.fromkeys(entities):
        element_types, _, node_tags = gmsh.model.mesh.getElements(dim, entity)
        in_groups = len(gmsh.model.getPhysicalGroupsForEntity(dim, entity))
        for kind, nodes in zip(element_types, node_tags):
            if kind in found:
                found[kind].append(merge_repeats(np.asarray(nodes, dtype=np.int64).reshape(-1, width[kind]), in_groups))
            elif dim == 2:
                raise MeshError(f"{where}: the surfaces must hold triangles only (found gmsh element type {kind})")
    kind = types[1] if found[types[1]] else types[0]
    nodes = np.concatenate(found[kind]) if found[kind] else np.zeros((0, width[kind]), dtype=np.int64)
    return position[nodes]


def _curve_normals(gmsh, entities: list[int], position: np.ndarray, count: int) -> np.ndarray:
    """Unit normals of Σ's curves at their nodes from gmsh's parametrization (NaN where unknown).

    Inside a curve the normal is exact; at a point where curves meet it is exact when the curves
    meeting there have the same tangent, and unknown at a kink (the caller averages the edges).
    """
    found: dict[int, list[np.ndarray]] = {}
    for entity in entities:
        tags, coordinates, _ = gmsh.model.mesh.getNodes(1, entity, includeBoundary=True, returnParametricCoord=False)
        if len(tags) == 0:
            continue
        # Parameters recomputed from the coordinates: those stored with the nodes are less accurate.
        parameters = gmsh.model.getParametrization(1, entity, coordinates)
        derivative = np.asarray(gmsh.model.getDerivative(1, entity, parameters), dtype=float).reshape(-1, 3)[:, :2]
        length = np.linalg.norm(derivative, axis=1)
        for tag, d, size in zip(np.asarray(tags, dtype=np.int64), derivative, length):
            if size > 0:
                found.setdefault(int(tag), []).append(np.array([-d[1], d[0]]) / size)
    normals = np.full((count, 2), np.nan)
    for tag, candidates in found.items():
        first = candidates[0]
        if all(abs(abs(first @ other) - 1.0) < 1e-10 for other in candidates):  # one tangent line: no kink
            normals[position[tag]] = first
    return normals


def write_msh(mesh: Mesh, path: Path) -> None:
    """Write ``mesh`` as a gmsh .msh file with the physical groups :func:`from_gmsh` reads.

    The Σ nodes of the two halves become one node each, so the file describes one domain.
    """
    import gmsh

    lower, upper = mesh.lower, mesh.upper
    offset = len(lower.points)
    upper_numbers = offset + np.arange(len(upper.points))
    upper_numbers[upper.sigma] = lower.sigma  # shared Σ nodes
    keep = np.ones(len(upper.points), dtype=bool)
    keep[upper.sigma] = False
    points = np.vstack([lower.points, upper.points[keep]])
    compact = np.cumsum(np.concatenate([np.ones(offset, dtype=bool), keep])) - 1
    numbers = {-1: np.arange(offset), 1: compact[upper_numbers]}
    element = {3: (_TRIANGLE, _LINE), 6: (_TRIANGLE6, _LINE3)}[lower.cells.shape[1]]
    gmsh.initialize([], readConfigFiles=False)
    try:
        _quiet(gmsh)
        gmsh.model.add("ddsolve")
        entity = gmsh.model.addDiscreteEntity(0)
        gmsh.model.mesh.addNodes(0, entity, np.arange(1, len(points) + 1),
                                 np.column_stack([points, np.zeros(len(points))]).ravel())
        next_element = 1
        for half in (lower, upper):
            surface = gmsh.model.addDiscreteEntity(2)
            cells = numbers[half.side][half.cells] + 1
            gmsh.model.mesh.addElementsByType(surface, element[0], np.arange(next_element, next_element + len(cells)),
                                              cells.ravel())
            next_element += len(cells)
            gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [surface]), half.name)
        for name in sorted(set(lower.boundaries) | set(upper.boundaries)):
            halves = (lower,) if name in (SIGMA, CRACK) else (lower, upper)  # Σ edges are shared
            edges = np.concatenate([numbers[half.side][half.edges(name)] for half in halves]) + 1
            curve = gmsh.model.addDiscreteEntity(1)
            gmsh.model.mesh.addElementsByType(curve, element[1], np.arange(next_element, next_element + len(edges)),
                                              edges.ravel())
            next_element += len(edges)
            gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, [curve]), name)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()
