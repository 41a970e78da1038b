"""Local conforming refinement of a Mesh by newest-vertex bisection, both halves and Σ at once.

The two halves are joined into one triangulation of Ω (:class:`Triangulation`: the vertices, the Σ
vertices once, each cell with its side), so that Σ edges are shared by a lower and an upper cell like
any interior edge and the closure crosses Σ by itself: an edge of Σ bisected in one half is bisected in
the other, and the Σ nodes of the halves match.  A cell ``(v0, v1, v2)`` (counter-clockwise) is split
at the middle m of its refinement edge ``(v1, v2)``, opposite its newest vertex v0, into
``(m, v0, v1)`` and ``(m, v2, v0)``: counter-clockwise, m newest.  Marking an edge marks the
refinement edge of every cell that holds it, until no cell has a marked edge other than its own
refinement edge (the closure); then every cell is bisected once or twice (its children's refinement
edges are its other two edges), which leaves no hanging node.  Every triangle of the result is similar
to one of at most four per initial triangle (Mitchell), so the smallest angle stays bounded; the first
labels are the longest edges (:func:`triangulation`), later ones the order of the cells' vertices,
which :func:`to_mesh` keeps.

Named boundary edges are split with their names; crack tips and every old vertex stay vertices.  New
vertices on boundary and Σ edges are placed by ``project(points (k, 2), names (k,)) -> (k, 2)`` (the
edge's boundary name, ``"sigma"`` for Σ; None: straight middles), P2 meshes are refined on their
vertices and get their midpoints back, old ones kept (on curves as gmsh placed them), new ones on
boundary edges projected.  Pure numpy; no gmsh, PETSc or MPI.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ddsolve.mesh.curves import Projector
from ddsolve.mesh.element import CELL_EDGES, boundary_nodes, edge_keys, outer_edges
from ddsolve.mesh.mesh import CLAMPED, SIGMA, Mesh, elevate, make_half, make_mesh, with_named_points


#: Local vertices of the three edges of a cell, edge j opposite vertex j (edge 0 is the refinement edge).
OPPOSITE = np.array([[1, 2], [2, 0], [0, 1]])

#: A vertex of a half's boundary whose cells' angles there add up to more than this is a re-entrant corner.
REENTRANT_ANGLE = 1.1 * np.pi


@dataclass(frozen=True, eq=False)
class Triangulation:
    """Both halves as one vertex triangulation of Ω.

    ``cells`` ``(m, 3)`` counter-clockwise with the refinement edge opposite the first vertex, ``side``
    ``(m,)`` −1 or +1; ``boundaries`` ``(side, name) -> (e, 2)`` edges counter-clockwise around their
    half; ``names`` the boundary name of each vertex made by bisection ("" inside Ω and for the original
    vertices); ``singular`` the vertices where the solution may be singular (crack tips, the ends of Σ,
    where a clamped boundary meets a free one, re-entrant corners); ``middles`` the original P2 edges
    ``(k, 2)`` and their midpoints ``(k, 2)`` (empty for P1).
    """

    points: np.ndarray
    cells: np.ndarray
    side: np.ndarray
    boundaries: dict[tuple[int, str], np.ndarray]
    names: np.ndarray
    singular: np.ndarray
    middles: tuple[np.ndarray, np.ndarray]
    degree: int
    origin: str
    named_points: dict = field(default_factory=dict)  # the mesh's (HalfMesh.named_points), kept


def triangulation(mesh: Mesh, longest_edge: bool = True) -> Triangulation:
    """Join the halves of ``mesh`` (cells: the lower half's, then the upper half's).  The refinement
    edge of each cell is its longest edge (``longest_edge``, for a mesh that was not made by bisection)
    or the edge opposite its first vertex (a mesh from :func:`to_mesh`)."""
    lower, upper = mesh.lower, mesh.upper
    corner = mesh.sigma.corner
    numbers, parts, start = {}, [], 0
    for half in (lower, upper):
        number = np.full(len(half.points), -1, dtype=np.int64)
        if half is upper:
            number[upper.sigma[corner]] = numbers[-1][lower.sigma[corner]]
        vertices = np.unique(half.corners)
        vertices = vertices[number[vertices] < 0]
        number[vertices] = start + np.arange(len(vertices))
        start += len(vertices)
        parts.append(half.points[vertices])
        numbers[half.side] = number
    points = np.vstack(parts)
    cells = np.vstack([numbers[half.side][half.corners] for half in (lower, upper)])
    if longest_edge:
        ends = points[cells[:, OPPOSITE]]  # (m, 3, 2, 2)
        longest = np.argmax(np.linalg.norm(ends[:, :, 1] - ends[:, :, 0], axis=2), axis=1)
        cells = cells[np.arange(len(cells))[:, None], (longest[:, None] + np.arange(3)) % 3]
    side = np.repeat([-1, 1], [len(lower.cells), len(upper.cells)])
    boundaries = {(half.side, name): numbers[half.side][edges[:, :2]]
                  for half in (lower, upper) for name, edges in half.boundaries.items()}
    middles = (np.zeros((0, 2), dtype=np.int64), np.zeros((0, 2)))
    if mesh.degree == 2:
        p2_edges = [half.cells[:, CELL_EDGES[6]].reshape(-1, 3) for half in (lower, upper)]  # (a, b, midpoint)
        edges = np.vstack([numbers[half.side][found[:, :2]] for half, found in zip((lower, upper), p2_edges)])
        where = np.vstack([half.points[found[:, 2]] for half, found in zip((lower, upper), p2_edges)])
        _, first = np.unique(edge_keys(edges, len(points)), return_index=True)
        middles = (edges[first], where[first])
    tri = Triangulation(points, cells, side, boundaries, np.full(len(points), "", dtype=object),
                        np.zeros(len(points), dtype=bool), middles, mesh.degree, mesh.origin, mesh.named_points)
    return replace(tri, singular=_singular(tri, mesh, numbers[-1][lower.sigma[corner]]))


def _singular(tri: Triangulation, mesh: Mesh, sigma: np.ndarray) -> np.ndarray:
    """The vertices of ``tri`` where the solution may be singular (``sigma``: the Σ vertices in order)."""
    singular = np.zeros(len(tri.points), dtype=bool)
    line = mesh.sigma
    singular[sigma[line.tip[line.corner]]] = True
    singular[sigma[[0, -1]]] = True
    outer = outer_edges(tri.cells)
    clamped = np.vstack([edges for (_, name), edges in tri.boundaries.items() if name == CLAMPED] or
                        [np.zeros((0, 2), dtype=np.int64)])
    on_clamped = np.zeros(len(tri.points), dtype=bool)
    on_clamped[clamped.ravel()] = True
    free = ~np.isin(edge_keys(outer, len(tri.points)), edge_keys(clamped, len(tri.points)))
    on_free = np.zeros(len(tri.points), dtype=bool)
    on_free[outer[free].ravel()] = True
    singular |= on_clamped & on_free
    glued = np.zeros(len(tri.points), dtype=bool)
    glued[sigma[~line.crack[line.corner]]] = True
    glued[sigma[[0, -1]]] = False
    for side in (-1, 1):
        cells = tri.cells[tri.side == side]
        boundary = boundary_nodes(cells, len(tri.points))
        total = np.bincount(cells.ravel(), _angles(tri.points, cells).ravel(), minlength=len(tri.points))
        singular |= boundary & ~glued & (total > REENTRANT_ANGLE)
    return singular


def _angles(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The interior angles ``(m, 3)`` of the triangles at their three vertices."""
    p = points[cells]
    a, b = p[:, [1, 2, 0]] - p, p[:, [2, 0, 1]] - p
    return np.arctan2(np.abs(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]), np.einsum("mkd,mkd->mk", a, b))


def bisect(tri: Triangulation, marked: np.ndarray) -> tuple[Triangulation, np.ndarray, np.ndarray]:
    """Bisect the ``marked`` cells ``(m,)`` bool (and, for conformity, their neighbours as needed).

    Returns the refined triangulation, the cell of ``tri`` each new cell comes from, and how many
    times it was bisected (0, 1 or 2).  New vertices are the straight middles of their edges (for an
    original P2 edge: its midpoint); :func:`to_mesh` projects those on boundaries.
    """
    n = len(tri.points)
    active, keys, inverse, flagged = _closure(tri.cells, n, np.asarray(marked, dtype=bool))
    ends = np.column_stack([keys[flagged] // n, keys[flagged] % n])
    points = 0.5 * (tri.points[ends[:, 0]] + tri.points[ends[:, 1]])
    number = np.full(len(keys), -1, dtype=np.int64)
    number[flagged] = n + np.arange(len(ends))
    old, middle = tri.middles
    where = _lookup(keys, edge_keys(old, n))
    known = where >= 0
    known[known] = flagged[where[known]]
    points[number[where[known]] - n] = middle[known]
    middles = number[inverse]  # (a, 3): the new vertex on each edge of each active cell, or −1
    cells = tri.cells[active]
    split = middles[:, 0] >= 0
    kept = ~active
    kept[active] = ~split
    children, parents = [tri.cells[kept]], [np.flatnonzero(kept)]
    splits = [np.zeros(int(kept.sum()), dtype=np.int64)]
    index = np.flatnonzero(active)[split]
    c, m = cells[split], middles[split]
    for child, mid in ((np.column_stack([m[:, 0], c[:, 0], c[:, 1]]), m[:, 2]),
                       (np.column_stack([m[:, 0], c[:, 2], c[:, 0]]), m[:, 1])):
        again = mid >= 0
        children += [child[~again], np.column_stack([mid[again], child[again, 0], child[again, 1]]),
                     np.column_stack([mid[again], child[again, 2], child[again, 0]])]
        parents += [index[~again], index[again], index[again]]
        twice = np.full(int(again.sum()), 2, dtype=np.int64)
        splits += [np.ones(int((~again).sum()), dtype=np.int64), twice, twice]
    parent = np.concatenate(parents)
    order = np.argsort(parent, kind="stable")
    names = np.concatenate([tri.names, np.full(len(ends), "", dtype=object)])
    boundaries = {}
    for (side, name), edges in sorted(tri.boundaries.items(), key=lambda item: item[0][1] == SIGMA):
        where = _lookup(keys, edge_keys(edges, n))
        mid = np.where(where >= 0, number[where], -1)
        cut = mid >= 0
        names[mid[cut]] = name
        boundaries[(side, name)] = np.vstack([edges[~cut], np.column_stack([edges[cut, 0], mid[cut]]),
                                              np.column_stack([mid[cut], edges[cut, 1]])])
    refined = replace(tri, points=np.vstack([tri.points, points]), cells=np.concatenate(children)[order],
                      side=tri.side[parent[order]], boundaries=boundaries, names=names,
                      singular=np.concatenate([tri.singular, np.zeros(len(ends), dtype=bool)]))
    return refined, parent[order], np.concatenate(splits)[order]


#: Rings of neighbours around the marked cells in which the closure is looked for first (doubled while
#: it reaches the edge of that region).
CLOSURE_RINGS = 3


def _closure(cells: np.ndarray, n: int, marked: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The edges to bisect: the refinement edges of the marked cells, and of every cell with an edge to
    bisect, until there is none more.  Looked for among the cells near the marked ones only (the
    closure of newest-vertex bisection stays close): returns those cells (``(m,)`` bool), their edges'
    keys, each cell's three edges ``(a, 3)`` (edge j opposite vertex j) and which edges to bisect."""
    rings = CLOSURE_RINGS
    while True:
        active, near = marked.copy(), np.zeros(n, dtype=bool)
        for _ in range(rings):
            near[cells[active].ravel()] = True
            active = near[cells].any(axis=1)
        keys, inverse, counts = np.unique(edge_keys(cells[active][:, OPPOSITE].reshape(-1, 2), n),
                                          return_inverse=True, return_counts=True)
        inverse = inverse.reshape(-1, 3)
        flagged = np.zeros(len(keys), dtype=bool)
        flagged[inverse[marked[active], 0]] = True
        while True:
            pending = flagged[inverse].any(axis=1) & ~flagged[inverse[:, 0]]
            if not pending.any():
                break
            flagged[inverse[pending, 0]] = True
        rim = keys[flagged & (counts == 1)]  # bisected edges on the region's outline: the region may be too small
        if active.all() or not len(rim):
            return active, keys, inverse, flagged
        on_rim = np.zeros(n, dtype=bool)
        on_rim[np.concatenate([rim // n, rim % n])] = True
        outside = cells[~active & (on_rim[cells].sum(axis=1) >= 2)]
        if not np.isin(edge_keys(outside[:, OPPOSITE].reshape(-1, 2), n), rim).any():
            return active, keys, inverse, flagged
        rings *= 2


def _lookup(keys: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """The position of each of ``wanted`` in the sorted ``keys``, −1 where it is not there."""
    if len(keys) == 0:
        return np.full(len(wanted), -1, dtype=np.int64)
    position = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
    return np.where(keys[position] == wanted, position, -1)


def to_mesh(tri: Triangulation, project: Projector | None = None) -> Mesh:
    """The checked Mesh of ``tri`` (P2: midpoints back, the original ones kept); new vertices and
    midpoints on named boundary edges placed by ``project`` (None: straight middles)."""
    points = tri.points.copy()
    moved = np.flatnonzero(tri.names != "")
    if project is not None and len(moved):
        points[moved] = project(points[moved], tri.names[moved].astype(str))
    cells, boundaries = tri.cells, tri.boundaries
    if tri.degree == 2:
        points, cells, boundaries = elevate(points, cells, boundaries)
        n = len(tri.points)
        edges = cells[:, CELL_EDGES[6]].reshape(-1, 3)
        keys, first = np.unique(edge_keys(edges[:, :2], n), return_index=True)
        old, middle = tri.middles
        position = np.searchsorted(keys, edge_keys(old, n))
        kept = (position < len(keys)) & (keys[np.minimum(position, len(keys) - 1)] == edge_keys(old, n))
        points[edges[first[position[kept]], 2]] = middle[kept]
        if project is not None:
            fixed = np.zeros(len(points), dtype=bool)
            fixed[edges[first[position[kept]], 2]] = True
            names = np.full(len(points), "", dtype=object)
            for (_, name), named in sorted(boundaries.items(), key=lambda item: item[0][1] == SIGMA):
                names[named[:, 2]] = name
            moved = np.flatnonzero((names != "") & ~fixed)
            if len(moved):
                points[moved] = project(points[moved], names[moved].astype(str))
    halves = []
    for side in (-1, 1):
        mine = {name: edges for (where, name), edges in boundaries.items() if where == side}
        halves.append(make_half(points, cells[tri.side == side], side, mine, tri.origin)[0])
    return with_named_points(make_mesh(*halves, tri.origin), tri.named_points)


def refine(mesh: Mesh, marked: np.ndarray, project: Projector | None = None, longest_edge: bool = True) -> Mesh:
    """``mesh`` with its ``marked`` cells (lower half's, then upper half's) bisected once, and the
    closure (:func:`bisect`); ``longest_edge`` as in :func:`triangulation`."""
    refined, _, _ = bisect(triangulation(mesh, longest_edge), marked)
    return to_mesh(refined, project)
