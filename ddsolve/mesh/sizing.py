"""Size fields: meshes graded towards the singular points (crack tips, corners, re-entrant corners)."""
from __future__ import annotations

import numpy as np

from ddsolve.mesh.mesh import CLAMPED, CRACK, SIGMA, TOL
from ddsolve.problem.scene import Geometry, MeshOptions

# --- size fields: grading towards singular points -------------------------------------------------
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


def box_length(geometry: Geometry) -> float:
    """The shorter side of the box."""
    x0, x1, y0, y1 = geometry.box
    return float(min(x1 - x0, y1 - y0))


def model_singular_points(gmsh, groups: dict[tuple[int, str], list[int]]) -> np.ndarray:
    """``(k, 2)``: the singular points of a gmsh geometry with physical groups.

    A point is singular where a crack curve ends on anything else (a crack tip, or a crack reaching
    the outer boundary), where Σ meets the outer boundary, where a clamped curve meets a free one
    (the boundary condition changes), where a half has a re-entrant corner (interior angle > π)
    that is not inside the glued part of Σ (there the material continues into the other half), and at
    the physical points (point supports).
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
    for (dim, _), points in groups.items():  # physical points: point supports (point forces)
        singular += [gmsh.model.getValue(0, point, [])[:2] for point in points if dim == 0]
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


def set_size_field(gmsh, options: MeshOptions, singular: np.ndarray, length: float) -> None:
    """Make the background mesh size of the current gmsh model: :func:`graded_size` around each
    singular point (``options.grading`` = μ), at most ``options.size``; nothing else (points, boundaries,
    curvature) sizes the mesh."""
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


def node_positions(tags) -> np.ndarray:
    """Index of each gmsh node tag in the order ``getNodes`` returned them."""
    tags = np.asarray(tags, dtype=np.int64)
    position = np.full(int(tags.max(initial=0)) + 1, -1, dtype=np.int64)
    position[tags] = np.arange(len(tags))
    return position
