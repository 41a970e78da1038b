"""Cracks anywhere along Σ on an existing mesh: read them as arc-length intervals, set them, and the
arc lengths where a growing tip must stop.

A crack is an interval (a, b) of arc length along Σ (:attr:`~ddsolve.mesh.mesh.SigmaLine.arclength`,
from Σ's first node); a = 0 or b = Σ's length is a crack open to that end of Σ.  :func:`with_cracks`
keeps the nodes and cells of a mesh and moves the few nodes around each new tip so that the tip is a Σ
vertex exactly at its arc length: the nearest Σ vertex goes there, its neighbours (both halves, P2
midpoints included) follow a smooth field that fades out within about RADIUS_EDGES Σ edges, and
nodes on every other boundary stay.  Growth along Σ then changes a handful of nodes per step, not the
mesh.  No PETSc, MPI or gmsh here.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from ddsolve.errors import MeshError
from ddsolve.mesh.element import CELL_EDGES, edge_keys
from ddsolve.mesh.mesh import CRACK, SIGMA, TOL, HalfMesh, Mesh, SigmaLine, make_mesh, signed_areas

#: A tip's move fades to zero at this many Σ edges (the mean of the two at its vertex) from the vertex.
RADIUS_EDGES = 2.0
#: Rounds of placing the Σ nodes so that each tip's arc length on the new Σ is the one asked (one on a
#: straight Σ; on a curved Σ the moved nodes cut Σ's corners, shifting the arc length a little).
PLACEMENT_ROUNDS = 8


def intervals(mesh: Mesh) -> list[tuple[float, float]]:
    """The mesh's cracks as arc-length intervals along Σ, in Σ order (0 or Σ's length at an open end)."""
    s = mesh.sigma.arclength
    step = mesh.degree
    return [(float(s[first * step]), float(s[(last + 1) * step]))
            for first, last in mesh.sigma.pieces(_crack_edges(mesh))]


def with_cracks(mesh: Mesh, cracks: Sequence[tuple[float, float]]) -> Mesh:
    """The mesh with the same nodes and cells whose cracks are exactly ``cracks`` (arc-length intervals
    along Σ, sorted and disjoint; 0 or Σ's length ``mesh.sigma.arclength[-1]`` at an open end).

    Every end strictly inside Σ becomes a tip at exactly that arc length of the new Σ: the nearest Σ
    vertex (not a P2 midpoint) moves there, and every node within about RADIUS_EDGES Σ edges of it moves
    by the smooth field (1 − (r/R)²)² times the vertex's move (R shrunk to keep clear of other boundaries
    and other tips); P2 midpoints move by the mean of their edge's corners, so straight edges stay
    straight.  Σ nodes move along Σ, the same in both halves: on a curved Σ they stay on the polyline of
    Σ's nodes (the chords between the original nodes, the P2 midpoints among them), so cut its corners
    slightly; the normals are the original ones interpolated along Σ.  Apply it to the original mesh at
    every step (not to its own output) so that moves do not accumulate.

    Raises MeshError (one line naming the interval) for intervals unsorted, overlapping or outside Σ, a
    crack or a glued piece between two cracks shorter than a Σ edge, two tips on one vertex, a tip on a
    clamped Σ node or within half an edge of an end of Σ, a crack over a clamped node, or a move that
    would invert a triangle.
    """
    sigma = mesh.sigma
    s = sigma.arclength
    length = float(s[-1])
    ends = _checked(cracks, length)
    fixed = [_fixed_nodes(half) for half in mesh.halves]
    held = sigma.clamped | np.isin(mesh.lower.sigma, fixed[0]) | np.isin(mesh.upper.sigma, fixed[1])
    corners = np.flatnonzero(sigma.corner)
    inside = (ends > 0.0) & (ends < length)
    targets = ends[inside]
    owner = np.nonzero(inside)[0]  # the crack of each tip
    vertices = corners[np.abs(s[corners][None, :] - targets[:, None]).argmin(axis=1)]
    spacing = _edge_at(s[corners], targets)
    _check_tips(ends, owner, targets, vertices, spacing, held, sigma)

    anchors = sigma.points[vertices]
    obstacles = np.vstack([half.points[nodes] for half, nodes in zip(mesh.halves, fixed)])
    radii = RADIUS_EDGES * _mean_spacing(s[corners], s[vertices])
    radii = np.minimum(radii, _nearest(anchors, obstacles))
    if len(anchors) > 1:
        apart = np.linalg.norm(anchors[:, None] - anchors[None], axis=2)
        np.fill_diagonal(apart, np.inf)
        radii = np.minimum(radii, apart.min(axis=1))
    sigma_weights = _weights(sigma.points, anchors, radii)
    new_s, new_points = _placed(sigma, sigma_weights, targets - s[vertices], vertices, targets)
    _check_clamped(ends, new_s, sigma, length)
    moves = new_points[vertices] - anchors

    halves = []
    for half in mesh.halves:
        weights = _weights(half.points, anchors, radii)
        points = half.points + weights @ moves
        points[half.sigma] = new_points
        if half.degree == 2:
            edges = half.cells[:, CELL_EDGES[6]].reshape(-1, 3)
            shift = points - half.points
            points[edges[:, 2]] = half.points[edges[:, 2]] + 0.5 * (shift[edges[:, 0]] + shift[edges[:, 1]])
            points[half.sigma] = new_points
        _check_areas(half, points, weights, ends, owner)
        halves.append(replace(half, points=points, boundaries=_boundaries(half, new_s, ends)))
    normals = np.column_stack([np.interp(new_s, s, sigma.normals[:, k]) for k in range(2)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return make_mesh(*halves, mesh.origin, exact_normals=normals)


def stops(mesh: Mesh, held: np.ndarray | None = None) -> np.ndarray:
    """Sorted arc lengths a growing tip must not pass: Σ's ends and the first and last node of every run of
    clamped Σ nodes, and of ``held`` (a mask over the Σ nodes, e.g. those with prescribed displacements:
    the scene's supports are not known to the mesh; :func:`ddsolve.fem.supports.sigma_supports` has them)."""
    sigma = mesh.sigma
    mask = sigma.clamped if held is None else sigma.clamped | np.asarray(held, dtype=bool)
    runs = np.array(sigma.pieces(mask), dtype=np.int64).reshape(-1)
    return np.unique(np.concatenate([[0.0, sigma.arclength[-1]], sigma.arclength[runs]]))


# --- what the cracks are ----------------------------------------------------------------------------
def _crack_edges(mesh: Mesh) -> np.ndarray:
    """Per Σ edge, in Σ order: whether it is a crack edge."""
    lower, step = mesh.lower, mesh.degree
    order = lower.sigma
    edges = np.column_stack([order[:-1:step], order[step::step]])
    n = len(lower.points)
    return np.isin(edge_keys(edges, n), edge_keys(lower.edges(CRACK), n))


def _name(ends: np.ndarray, crack: int) -> str:
    return f"crack ({ends[crack, 0]:.9g}, {ends[crack, 1]:.9g})"


def _checked(cracks: Sequence[tuple[float, float]], length: float) -> np.ndarray:
    """``(c, 2)`` interval ends, checked; ends within TOL × length of an end of Σ put on it."""
    ends = np.asarray(cracks, dtype=np.float64).reshape(-1, 2) if len(cracks) else np.zeros((0, 2))
    for crack, (a, b) in enumerate(ends):
        if not (np.isfinite(a) and np.isfinite(b) and a < b):
            raise MeshError(f"crack ({a:.9g}, {b:.9g}): an interval needs finite ends, start < end")
        if a < -TOL * length or b > length * (1.0 + TOL):
            raise MeshError(f"{_name(ends, crack)}: outside Σ, whose arc length runs from 0 to {length:.9g}")
        if crack and a <= ends[crack - 1, 1]:
            raise MeshError(f"{_name(ends, crack)}: overlaps or touches {_name(ends, crack - 1)} (intervals sorted "
                            "and disjoint; merge them)")
    ends[np.abs(ends) <= TOL * length] = 0.0
    ends[np.abs(ends - length) <= TOL * length] = length
    return ends


def _check_tips(ends: np.ndarray, owner: np.ndarray, targets: np.ndarray, vertices: np.ndarray,
                spacing: np.ndarray, held: np.ndarray, sigma: SigmaLine) -> None:
    """Refuse tips on held Σ nodes, pieces shorter than a Σ edge, two tips on one vertex."""
    for tip, vertex in enumerate(vertices):
        if held[vertex]:
            x, y = sigma.points[vertex]
            what = "clamped Σ node" if sigma.clamped[vertex] else "Σ node on the outer boundary (an end of Σ)"
            raise MeshError(f"{_name(ends, owner[tip])}: its tip at s = {targets[tip]:.9g} falls on the {what} at "
                            f"({x:.6g}, {y:.6g}); keep tips at least half a Σ edge off it")
    for tip in range(len(targets) - 1):
        short = targets[tip + 1] - targets[tip] < min(spacing[tip], spacing[tip + 1])
        if short or vertices[tip] == vertices[tip + 1]:
            first, second = owner[tip], owner[tip + 1]
            piece = (_name(ends, first) if first == second
                     else f"the glued piece between {_name(ends, first)} and {_name(ends, second)}")
            reason = "is shorter than a Σ edge there" if short else "has both ends on one Σ vertex"
            raise MeshError(f"{piece} {reason} ({spacing[tip]:.3g}){'' if first == second else ': merge them'}")


def _check_clamped(ends: np.ndarray, along: np.ndarray, sigma: SigmaLine, length: float) -> None:
    """Refuse a crack over a clamped Σ node (its open end included)."""
    for crack, (a, b) in enumerate(ends):
        inside = ((along > a) | (a == 0.0)) & ((along < b) | (b == length)) & (along >= a) & (along <= b)
        if np.any(inside & sigma.clamped):
            x, y = sigma.points[np.flatnonzero(inside & sigma.clamped)[0]]
            raise MeshError(f"{_name(ends, crack)}: reaches the clamped Σ node at ({x:.6g}, {y:.6g}); the crack "
                            "must stay off Γ_D")


def _fixed_nodes(half: HalfMesh) -> np.ndarray:
    """Nodes that must not move: on the half's boundary off Σ, or on a named boundary other than Σ, cracks."""
    n = len(half.points)
    outer = half.boundary_edges
    off_sigma = outer[~np.isin(edge_keys(outer, n), edge_keys(half.edges(SIGMA), n))]
    named = [edges.reshape(-1) for name, edges in half.boundaries.items() if name not in (SIGMA, CRACK)]
    return np.unique(np.concatenate([off_sigma.reshape(-1), *named]))


def _edge_at(corner_s: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The length of the Σ edge (corner to corner) holding each arc length ``s``."""
    right = np.clip(np.searchsorted(corner_s, s), 1, len(corner_s) - 1)
    return corner_s[right] - corner_s[right - 1]


def _mean_spacing(corner_s: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The mean length of the Σ edges on either side of the corners at arc lengths ``s``."""
    position = np.searchsorted(corner_s, s)
    before = corner_s[position] - corner_s[np.maximum(position - 1, 0)]
    after = corner_s[np.minimum(position + 1, len(corner_s) - 1)] - corner_s[position]
    return 0.5 * (before + after)


def _nearest(points: np.ndarray, others: np.ndarray) -> np.ndarray:
    """The distance from each of ``points`` to the nearest of ``others``."""
    if len(others) == 0:
        return np.full(len(points), np.inf)
    return np.sqrt(np.min(((points[:, None] - others[None]) ** 2).sum(axis=2), axis=1, initial=np.inf))


# --- moving the nodes ---------------------------------------------------------------------------------
def _weights(points: np.ndarray, anchors: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """``(n, tips)``: the smooth field (1 − (r/R)²)² of each tip at ``points`` (zero beyond R)."""
    rho = np.linalg.norm(points[:, None] - anchors[None], axis=2) / radii[None]
    return np.where(rho < 1.0, (1.0 - rho ** 2) ** 2, 0.0)


def _placed(sigma: SigmaLine, weights: np.ndarray, delta: np.ndarray, vertices: np.ndarray,
            targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Σ nodes moved along Σ: the arc length (along the original Σ) of each node shifted by the
    weighted tips' shifts (a P2 midpoint by the mean of its corners'), placed on the polyline of the
    original nodes, the tips' shifts corrected until each tip's arc length on the new Σ is its target.
    Returns the new nodes' positions along the original Σ and their points."""
    s = sigma.arclength
    for _ in range(PLACEMENT_ROUNDS):
        shift = weights @ delta
        if not sigma.corner.all():  # P2: a midpoint shifts by the mean of its corners' shifts
            shift[1::2] = 0.5 * (shift[:-1:2] + shift[2::2])
        along = s + shift
        points = np.column_stack([np.interp(along, s, sigma.points[:, k]) for k in range(2)])
        reached = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])[vertices]
        error = targets - reached
        if np.all(np.abs(error) <= 4.0 * np.spacing(s[-1]) * np.sqrt(len(s))):
            break
        delta = delta + error
    return along, points


def _check_areas(half: HalfMesh, points: np.ndarray, weights: np.ndarray, ends: np.ndarray, owner: np.ndarray) -> None:
    """Refuse moved nodes that invert (or flatten) a triangle, naming the cracks whose tips moved them."""
    area = signed_areas(points, half.corners)
    bad = area <= 1e-12 * np.abs(area).max()
    if bad.any():
        movers = np.unique(owner[np.any(weights[half.corners[bad].ravel()] > 0.0, axis=0)])
        names = " and ".join(_name(ends, crack) for crack in movers)
        raise MeshError(f"{names}: moving its tips onto Σ vertices inverts {int(bad.sum())} triangles of the {half.name} "
                        "half (a tip too close to another boundary: move it along Σ or refine there)")


def _boundaries(half: HalfMesh, along: np.ndarray, ends: np.ndarray) -> dict[str, np.ndarray]:
    """The half's named boundaries with the crack edges: the Σ edges whose middle lies inside a crack."""
    position = np.full(len(half.points), -1, dtype=np.int64)
    position[half.sigma] = np.arange(len(half.sigma))
    edges = half.edges(SIGMA)
    middle = 0.5 * (along[position[edges[:, 0]]] + along[position[edges[:, 1]]])
    crack = np.searchsorted(ends[:, 0], middle) - 1
    on_crack = (crack >= 0) & (middle < ends[np.maximum(crack, 0), 1]) if len(ends) else np.zeros(len(edges), bool)
    named = {name: edges for name, edges in half.boundaries.items() if name != CRACK}
    if on_crack.any():
        named[CRACK] = edges[on_crack]
    return named
