"""The meshes of the two halves and the interface Σ between them: the one thing geometry produces.

A :class:`Mesh` holds the lower half Ω₋ and the upper half Ω₊ (:class:`HalfMesh`: nodes, P1 or P2
triangles, named boundary edges) and :class:`SigmaLine`, the Σ nodes in order along Σ with their
normals, lumped weights and roles (crack, crack tip, clamped).  Whether the halves came from the
built-in box, a gmsh script or a mesh file, nothing downstream can tell.

Conventions: arrays follow meshio (row-major ``points (n, 2)`` float64, ``cells (m, 3)`` or
``(m, 6)`` int64 counter-clockwise, P2 nodes in meshio's order v0 v1 v2 m01 m12 m20).  Boundary edges
are ``(e, 2)`` or, for P2, ``(e, 3)`` = (a, b, midpoint), oriented counter-clockwise around their
half.  Σ runs so that ν, the outward normal of the lower half, is its tangent turned left.
No PETSc, MPI or gmsh here.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ddsolve.errors import MeshError
from ddsolve.problem.schema import LAYERS, REGIONS
from ddsolve.mesh.element import (CELL_EDGES, EDGE_RULE, crowded_edges, edge_keys, edge_points, edge_shapes,
                                  outer_edges)

#: Boundary names with a meaning: Σ (cracks included), the cracks, and Γ_D (both layers clamped).
SIGMA, CRACK, CLAMPED = "sigma", "crack", "clamped"
#: A middle region's Σ above it and its cracks (its ``sigma`` is the Σ below it), with several interfaces.
SIGMA_ABOVE, CRACK_ABOVE = "sigma_above", "crack_above"
#: Relative tolerance for coordinates that must coincide (Σ nodes of the two halves).
TOL = 1e-10



@dataclass(frozen=True, eq=False)
class HalfMesh:
    """One half: ``side`` −1 (lower, Ω₋) or +1 (upper, Ω₊); ``sigma`` its Σ nodes in Σ order.

    ``named_points``: the geometry's named points (gmsh physical points), name -> coordinates ``(k, 2)``,
    the same in both halves; each is a vertex of the half(s) whose boundary it lies on
    (:func:`point_nodes` finds it by its coordinates, which refinement and distribution keep)."""

    points: np.ndarray
    cells: np.ndarray
    side: int
    sigma: np.ndarray
    boundaries: dict[str, np.ndarray] = field(default_factory=dict)
    named_points: dict[str, np.ndarray] = field(default_factory=dict)
    #: With several interfaces: the region's name (``region1`` ...) and a middle region's nodes on the Σ above it,
    #: in Σ order (its ``sigma``, ``side`` +1, are those of the Σ below it).
    region: str = ""
    sigma_above: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @property
    def name(self) -> str:
        """Its region of Ω (:data:`ddsolve.problem.schema.REGIONS`, or its own with several interfaces), which
        selects the layers' materials there."""
        return self.region or region_of(self.side)

    @property
    def degree(self) -> int:
        return 1 if self.cells.shape[1] == 3 else 2

    @property
    def corners(self) -> np.ndarray:
        """The triangles' vertices ``(m, 3)`` (the cells themselves for P1)."""
        return self.cells[:, :3]

    @cached_property
    def vertex_count(self) -> int:
        """Triangle vertices (P2 midpoints not counted)."""
        return len(np.unique(self.corners))

    def edges(self, name: str) -> np.ndarray:
        """The boundary edges named ``name`` (empty if this half has none)."""
        return self.boundaries.get(name, np.zeros((0, self.degree + 1), dtype=np.int64))

    def nodes(self, name: str) -> np.ndarray:
        """Sorted indices of the nodes on the boundary edges named ``name``."""
        return np.unique(self.edges(name))

    def clamped(self) -> np.ndarray:
        """Indices of the nodes on Γ_D."""
        return self.nodes(CLAMPED)

    def areas(self) -> np.ndarray:
        """Signed areas of the triangles' corners (positive for counter-clockwise cells)."""
        return signed_areas(self.points, self.corners)

    @cached_property
    def boundary_edges(self) -> np.ndarray:
        """Every edge used by exactly one cell, oriented counter-clockwise (with its midpoint for P2)."""
        return outer_edges(self.cells)

    @cached_property
    def shape(self) -> Shape:
        """The shortest triangle side and the smallest angle."""
        return shape_of(self.points, self.corners)


def index_type(largest: int):
    """int32 when every index fits (half the memory; what PETSc uses unless built for 64-bit), else int64."""
    return np.int32 if largest < 2 ** 31 - 1 else np.int64


def known(half: HalfMesh, **values) -> HalfMesh:
    """``half`` with the values of cached properties (``boundary_edges``, ``shape``) that its maker knows
    already (a refinement, from the coarse mesh or from pieces); they travel with it when it is sent."""
    for name, value in values.items():
        if not isinstance(getattr(HalfMesh, name, None), cached_property):
            raise AttributeError(f"HalfMesh has no cached property {name!r}")
        half.__dict__[name] = value
    return half


def skeleton(half: HalfMesh) -> HalfMesh:
    """The half's boundary alone: the nodes of its outer edges, named boundaries and Σ (in their order,
    renumbered), no cells, its outer edges and shape known.  All that pairing and checking the whole
    mesh read of a half (Σ, the boundaries, the extent, the supports' nodes) is the same on it."""
    kept = np.unique(np.concatenate([half.boundary_edges.ravel(), half.sigma,
                                     *(edges.ravel() for edges in half.boundaries.values())]))
    number = np.full(len(half.points), -1, dtype=np.int64)
    number[kept] = np.arange(len(kept))
    bare = HalfMesh(half.points[kept], np.zeros((0, half.cells.shape[1]), dtype=half.cells.dtype), half.side,
                    number[half.sigma], {name: number[edges] for name, edges in half.boundaries.items()},
                    half.named_points)
    return known(bare, boundary_edges=number[half.boundary_edges], shape=half.shape)


@dataclass(frozen=True)
class Shape:
    """What the checks and the records need of a mesh's triangles (:func:`shape_of`)."""

    shortest_side: float
    smallest_angle: float  # degrees

    def __and__(self, other: Shape) -> Shape:
        """The shape of two sets of triangles together."""
        return Shape(min(self.shortest_side, other.shortest_side), min(self.smallest_angle, other.smallest_angle))


#: Triangles measured at once by :func:`shape_of` (its temporaries stay a few tens of MB).
SHAPE_CHUNK = 1 << 18


def shape_of(points: np.ndarray, corners: np.ndarray) -> Shape:
    """The shortest side and the smallest angle of the triangles ``corners`` (a slice at a time)."""
    shortest, smallest = np.inf, 180.0
    for start in range(0, len(corners), SHAPE_CHUNK):
        sides, lengths = _sides(points, corners[start:start + SHAPE_CHUNK])
        shortest = min(shortest, float(lengths.min()))
        smallest = min(smallest, _smallest_angle(sides, lengths))
    return Shape(shortest, smallest)


@dataclass(frozen=True, eq=False)
class SigmaLine:
    """The Σ nodes in order (endpoints included) and what each one is.

    ``weights`` are the lumped integrals ∫Σ φ_k ds; ``normals`` point out of the lower half;
    ``crack`` marks nodes whose faces are not glued (inside a crack, or a crack's end on a free
    boundary); ``tip`` marks crack tips (glued, between a crack and a glued part); ``clamped`` marks
    nodes on Γ_D, which carry no multiplier; ``corner`` is False for P2 midpoints.
    """

    points: np.ndarray
    normals: np.ndarray
    weights: np.ndarray
    crack: np.ndarray
    tip: np.ndarray
    clamped: np.ndarray
    corner: np.ndarray

    @property
    def multiplier_nodes(self) -> np.ndarray:
        """Positions (along Σ) of the nodes that carry multipliers: those not clamped."""
        return np.flatnonzero(~self.clamped)

    @property
    def frames(self) -> np.ndarray:
        """``(s, 2, 2)``: rows τ (tangent) and ν (normal) at each node; trace components in this frame."""
        nu = self.normals
        tangent = np.column_stack([nu[:, 1], -nu[:, 0]])
        return np.stack([tangent, nu], axis=1)

    @cached_property
    def arclength(self) -> np.ndarray:
        """Distance along Σ from its first node (chords between consecutive nodes)."""
        return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(self.points, axis=0), axis=1))])

    def pieces(self, mask: np.ndarray) -> list[tuple[int, int]]:
        """Maximal runs ``[first, last]`` (inclusive) of consecutive nodes where ``mask`` holds."""
        padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
        starts = np.flatnonzero(np.diff(padded) == 1)
        stops = np.flatnonzero(np.diff(padded) == -1) - 1
        return list(zip(starts.tolist(), stops.tolist()))


@dataclass(frozen=True, eq=False)
class Mesh:
    """Both halves and Σ; ``origin`` names the source in messages.  With several interfaces, ``lower`` and
    ``upper`` are the two lowest regions and ``sigma`` the Σ between them; ``above`` holds each further interface,
    bottom to top, as its Σ and the region above it."""

    lower: HalfMesh
    upper: HalfMesh
    sigma: SigmaLine
    origin: str = "mesh"
    above: tuple[tuple[SigmaLine, HalfMesh], ...] = ()

    @property
    def halves(self) -> tuple[HalfMesh, HalfMesh]:
        return self.lower, self.upper

    @property
    def regions(self) -> tuple[HalfMesh, ...]:
        """Every region of Ω, bottom to top (the two halves with one interface)."""
        return (self.lower, self.upper, *(region for _, region in self.above))

    @property
    def sigmas(self) -> tuple[SigmaLine, ...]:
        """Every interface's Σ, bottom to top."""
        return (self.sigma, *(line for line, _ in self.above))

    def half(self, side: int) -> HalfMesh:
        return self.lower if side < 0 else self.upper

    @property
    def degree(self) -> int:
        return self.lower.degree

    def boundary_names(self) -> list[str]:
        """Names of the boundary parts loads may refer to (Σ and the cracks excluded)."""
        names = set().union(*(region.boundaries for region in self.regions))
        return sorted(names - {SIGMA, CRACK, SIGMA_ABOVE, CRACK_ABOVE})

    @property
    def named_points(self) -> dict[str, np.ndarray]:
        """The geometry's named points (both halves hold them), name -> coordinates ``(k, 2)``."""
        return self.lower.named_points


def with_named_points(mesh: Mesh, named_points: dict[str, np.ndarray]) -> Mesh:
    """``mesh`` with both halves holding ``named_points`` (a mesh remade from another keeps its points)."""
    if not named_points:
        return mesh
    lower, upper = (replace(half, named_points=named_points) for half in mesh.halves)
    return replace(mesh, lower=lower, upper=upper)


def point_nodes(points: np.ndarray, point) -> np.ndarray:
    """The indices of ``points`` (a half's nodes) at ``point`` (x, y), within TOL of their extent."""
    point = np.asarray(point, dtype=np.float64)
    if len(points) == 0:
        return np.zeros(0, dtype=np.int64)
    scale = max(float(np.ptp(points, axis=0).max()), 1e-300)
    return np.flatnonzero(np.abs(points - point).max(axis=1) <= TOL * scale)


# --- geometry helpers -------------------------------------------------------------------------
def signed_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    p = points[triangles]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])



def edge_lengths(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    s, w = EDGE_RULE
    _, tangents = edge_points(points, edges, s)
    return np.linalg.norm(tangents, axis=2) @ w


# --- building a half ----------------------------------------------------------------------------
def merge_repeats(cells: np.ndarray, groups: np.ndarray | int) -> np.ndarray:
    """The elements of a file that lists an element once per physical group it is in (gmsh's MSH 2.2
    does), each once: it carries every group.

    ``groups`` is, per row, the physical group that listed it; or an int k when the rows are the
    elements of one gmsh entity in k groups (gmsh keeps every copy, so the j-th copy of an element is
    the j-th group's).  A copy of an element in a group that has not listed it yet is dropped; a copy
    listed again by the same group stays, for :func:`oriented` and :func:`make_half` to refuse.
    """
    cells = np.asarray(cells, dtype=np.int64)
    if len(cells) == 0:
        return cells
    _, element = np.unique(np.sort(cells, axis=1), axis=0, return_inverse=True)
    element = element.reshape(-1)
    index = np.arange(len(cells))
    if np.ndim(groups) == 0:
        order = np.argsort(element, kind="stable")
        starts = np.flatnonzero(np.diff(element[order], prepend=-1))
        copy = np.empty(len(cells), dtype=np.int64)
        copy[order] = index - np.repeat(starts, np.diff(np.append(starts, len(cells))))
        groups = np.minimum(copy, max(int(groups), 1) - 1)
    first = np.full(int(element.max()) + 1, len(cells))
    np.minimum.at(first, element, index)
    _, pair_first, pair = np.unique(np.column_stack([element, np.asarray(groups, dtype=np.int64)]), axis=0,
                                    return_index=True, return_inverse=True)
    keep = (index == first[element]) | (index != pair_first[pair.reshape(-1)])
    return cells[keep]


def make_half(points: np.ndarray, cells: np.ndarray, side: int, boundaries: dict[str, np.ndarray],
              origin: str) -> tuple[HalfMesh, np.ndarray]:
    """A checked half from raw nodes, cells and named boundary edges (any orientation).

    Cells are made counter-clockwise (a file that is clockwise throughout is flipped; mixed
    orientation is an error); nodes the cells do not use are dropped and the rest numbered along the
    longer side of the bounding box, so that contiguous row ranges of a distributed block are compact
    slabs, and the cells in the order of their smallest node, so that the cells of such a range are a
    contiguous range too (:mod:`ddsolve.mesh.pieces`).  Returns the half and the new number of every old
    node (−1: dropped).
    """
    where = f"{origin}: {'lower' if side < 0 else 'upper'} half"
    points = np.asarray(points, dtype=np.float64)
    cells = oriented(points, cells, where)
    used = np.unique(cells)
    extent = points[used].max(axis=0) - points[used].min(axis=0)
    major = 0 if extent[0] >= extent[1] else 1
    used = used[np.lexsort((points[used, 1 - major], points[used, major]))]
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    cells = renumber[cells]
    cells = cells[np.argsort(cells.min(axis=1), kind="stable")]
    points = points[used]
    _check_distinct(points, where)
    outer = outer_edges(cells)
    keys = edge_keys(outer, len(points))
    order = np.argsort(keys)
    named = {}
    for name, raw in boundaries.items():
        raw = renumber[np.asarray(raw, dtype=np.int64).reshape(len(raw), -1)] if len(raw) else np.zeros((0, 2), np.int64)
        if len(raw) == 0:
            continue
        if np.any(raw < 0):
            raise MeshError(f"{where}: boundary {name!r} has nodes that no triangle uses")
        wanted = edge_keys(raw, len(points))
        if len(np.unique(wanted)) < len(wanted):
            raise MeshError(f"{where}: boundary {name!r} lists {len(wanted) - len(np.unique(wanted))} edges more "
                            "than once")
        position = np.searchsorted(keys[order], wanted)
        found = (position < len(keys)) & (keys[order][np.minimum(position, len(keys) - 1)] == wanted)
        if not found.all():
            raise MeshError(f"{where}: boundary {name!r} has {int((~found).sum())} edges that are not on "
                            "the boundary of the half")
        named[name] = outer[order[position]]
    sigma = _chain(named.get(SIGMA, np.zeros((0, cells.shape[1] // 3 + 1), np.int64)), side, where)
    return HalfMesh(points, cells, side, sigma, named), renumber


def oriented(points: np.ndarray, cells: np.ndarray, where: str) -> np.ndarray:
    """The cells, counter-clockwise; raise MeshError for bad nodes, inverted, degenerate, repeated or
    overlapping cells.  A file that is clockwise throughout is flipped; mixed orientation is an error."""
    cells = np.asarray(cells, dtype=np.int64)
    if len(cells) == 0:
        raise MeshError(f"{where}: no triangles")
    if not np.all(np.isfinite(points)):
        raise MeshError(f"{where}: non-finite node coordinates")
    area = signed_areas(points, cells[:, :3])
    scale = np.abs(area).max()
    if np.all(area < 0):
        cells = cells[:, [1, 0, 2, 3, 5, 4] if cells.shape[1] == 6 else [1, 0, 2]]
        area = -area
    if np.any(area <= 1e-12 * scale):
        raise MeshError(f"{where}: {int(np.sum(area <= 1e-12 * scale))} inverted or degenerate triangles "
                        "(non-positive area)")
    _check_cover(points, cells, where)
    return cells


def _check_distinct(points: np.ndarray, where: str) -> None:
    """Reject nodes of the triangles at the position of another (to 1e-12 of the half's size): a mesh not
    merged there, whose triangles meet without sharing the node, is not connected across it (a crack
    lies on Σ, between the halves, never inside one).  ``points`` are sorted along an axis, then the
    other (:func:`make_half`), so a repeated position is a repeated row."""
    close = np.abs(np.diff(points, axis=0)) <= 1e-12 * np.ptp(points, axis=0).max()
    repeated = int(np.count_nonzero(close.all(axis=1)))
    if repeated:
        raise MeshError(f"{where}: nodes of its triangles where another node is: {repeated} (a mesh not merged "
                        "there, its triangles not connected; gmsh's Coherence merges them)")


def _check_cover(points: np.ndarray, cells: np.ndarray, where: str) -> None:
    """Reject repeated cells and cells that overlap (an edge in three cells, or more area than the
    boundary encloses)."""
    corners = np.sort(cells[:, :3], axis=1)
    if len(np.unique(corners, axis=0)) < len(corners):
        repeated = len(corners) - len(np.unique(corners, axis=0))
        raise MeshError(f"{where}: {repeated} triangles are listed more than once")
    crowded = crowded_edges(cells[:, :3])
    if crowded:
        raise MeshError(f"{where}: {crowded} edges are shared by more than two triangles (overlapping cells)")
    outer = outer_edges(cells[:, :3])
    corner = points[cells[0, 0]]  # about a point of the mesh: exact however far it is from (0, 0)
    a, b = points[outer[:, 0]] - corner, points[outer[:, 1]] - corner
    enclosed = 0.5 * np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    total = signed_areas(points, cells[:, :3]).sum()
    if abs(total - enclosed) > 1e-9 * abs(total):
        raise MeshError(f"{where}: the triangles cover {total:.6g} but their boundary encloses {enclosed:.6g} "
                        "(overlapping cells)")


def _chain(edges: np.ndarray, side: int, where: str) -> np.ndarray:
    """Σ nodes in Σ order from a half's Σ edges (oriented counter-clockwise around that half)."""
    if len(edges) == 0:
        return np.zeros(0, dtype=np.int64)
    following = dict(zip(edges[:, 0].tolist(), range(len(edges))))
    starts = set(edges[:, 0].tolist()) - set(edges[:, 1].tolist())
    if len(following) != len(edges) or len(starts) != 1:
        kind = "a closed curve" if not starts else "not one simple curve"
        raise MeshError(f"{where}: Σ is {kind}; it must run from the outer boundary to the outer boundary")
    node, path = starts.pop(), []
    for _ in range(len(edges)):
        edge = edges[following[node]]
        path.append(edge[0])
        if len(edge) == 3:
            path.append(edge[2])
        node = edge[1]
        if node not in following:
            break
    path.append(node)
    if len(path) != len(edges) * (len(edges[0]) - 1) + 1:
        raise MeshError(f"{where}: Σ is not one connected curve")
    path = np.array(path, dtype=np.int64)
    return path[::-1].copy() if side < 0 else path  # the lower half runs against Σ


# --- Σ --------------------------------------------------------------------------------------------
def make_mesh(lower: HalfMesh, upper: HalfMesh, origin: str, exact_normals: np.ndarray | None = None) -> Mesh:
    """Pair the halves along Σ and describe Σ; raise MeshError unless they form a valid decomposition.

    ``exact_normals`` ``(s, 2)`` (NaN where unknown), in Σ order, replace the averaged edge normals.
    """
    for half in (lower, upper):
        where = f"{origin}: {half.name} half"
        if len(half.sigma) == 0:
            raise MeshError(f"{where}: no Σ edges (a boundary part named {SIGMA!r} shared with the other half)")
        crack_edges = half.edges(CRACK)
        if len(crack_edges) and not np.isin(edge_keys(crack_edges, len(half.points)),
                                            edge_keys(half.edges(SIGMA), len(half.points))).all():
            raise MeshError(f"{where}: a crack is not on Σ (every {CRACK!r} edge must be a {SIGMA!r} edge)")
        if half.degree != lower.degree:
            raise MeshError(f"{origin}: the halves have different element degrees")
    scale = max(np.ptp(half.points, axis=0).max() for half in (lower, upper))
    check_resolution(lower, upper, origin)
    check_sigma_match(lower, upper, scale, origin)
    _check_only_sigma_is_shared(lower, upper, scale, origin)
    sigma = sigma_line(lower, upper, exact_normals)
    if np.any(sigma.crack & sigma.clamped):
        first = sigma.points[np.flatnonzero(sigma.crack & sigma.clamped)[0]]
        raise MeshError(f"{origin}: a crack reaches the clamped boundary at ({first[0]:.6g}, {first[1]:.6g}); "
                        "the crack must stay off Γ_D")
    return Mesh(lower, upper, sigma, origin)


def region_half(points: np.ndarray, cells: np.ndarray, region: str, bottom: bool,
                boundaries: dict[str, np.ndarray], origin: str) -> HalfMesh:
    """A checked region of a structure of several interfaces (:func:`make_half`): the ``bottom`` region is the
    lower half of the Σ above it (side −1); any other is the upper half of the Σ below it (side +1) and, if its
    boundaries name one (:data:`SIGMA_ABOVE`), keeps its nodes on the Σ above it in ``sigma_above``."""
    where = f"{origin}: {region}"
    half, _ = make_half(points, cells, -1 if bottom else 1, boundaries, where)
    return replace(half, region=region, sigma_above=_chain(half.edges(SIGMA_ABOVE), -1, where))


def facing_above(region: HalfMesh) -> HalfMesh:
    """A middle region as the lower half of the Σ above it: that Σ and its cracks named :data:`SIGMA` and
    :data:`CRACK` (the Σ below it left unnamed)."""
    named = {name: edges for name, edges in region.boundaries.items() if name not in (SIGMA, CRACK)}
    renamed = {SIGMA_ABOVE: SIGMA, CRACK_ABOVE: CRACK}
    return replace(region, side=-1, sigma=region.sigma_above,
                   boundaries={renamed.get(name, name): edges for name, edges in named.items()})


def make_stack(regions: tuple[HalfMesh, ...], origin: str) -> Mesh:
    """The mesh of several interfaces from its regions bottom to top (:func:`region_half`): each pair of
    neighbours paired along its Σ and checked as :func:`make_mesh` checks two halves."""
    lines = [make_mesh(below if k == 0 else facing_above(below), above, origin).sigma
             for k, (below, above) in enumerate(zip(regions[:-1], regions[1:]))]
    return Mesh(regions[0], regions[1], lines[0], origin, tuple(zip(lines[1:], regions[2:])))


def check_sigma_match(lower: HalfMesh, upper: HalfMesh, scale: float, origin: str) -> None:
    """The two halves' Σ nodes coincide, in order (within TOL × ``scale``)."""
    a, b = lower.points[lower.sigma], upper.points[upper.sigma]
    if len(a) != len(b) or np.abs(a - b).max() > TOL * scale:
        raise MeshError(f"{origin}: the Σ nodes of the two halves do not match ({len(a)} and {len(b)} nodes)")


#: The largest rounding of a node's coordinates (the spacing of doubles at the largest coordinate) that
#: a mesh allows, relative to its shortest edge: the element matrices are then exact to this order.
RESOLUTION = 1e-5


def check_resolution(lower: HalfMesh, upper: HalfMesh, origin: str) -> None:
    """Refuse a mesh whose coordinates are so large, against its smallest triangles, that double
    precision cannot place its nodes (a small geometry far from (0, 0))."""
    largest = max(float(np.abs(half.points).max()) for half in (lower, upper))
    shortest = min(half.shape.shortest_side for half in (lower, upper))
    rounding = float(np.spacing(largest))
    if not rounding <= RESOLUTION * shortest:
        raise MeshError(f"{origin}: coordinates as large as {largest:.3g} are placed to {rounding:.2g} in double "
                        f"precision, {rounding / shortest:.2g} of the shortest edge {shortest:.3g} (at most "
                        f"{RESOLUTION:g}): move the geometry towards x = y = 0 (geometry.box, or the file's "
                        f"coordinates, and the loads' x and y with it) or use elements of at least "
                        f"{rounding / RESOLUTION:.2g}")


def _check_only_sigma_is_shared(lower: HalfMesh, upper: HalfMesh, scale: float, origin: str) -> None:
    """The halves may touch along Σ only (else Σ does not split Ω)."""
    def midpoints(half: HalfMesh) -> set[tuple[int, int]]:
        edges = half.boundary_edges
        sigma_keys = set(edge_keys(half.edges(SIGMA), len(half.points)).tolist())
        keep = ~np.isin(edge_keys(edges, len(half.points)), list(sigma_keys))
        mid = 0.5 * (half.points[edges[keep, 0]] + half.points[edges[keep, 1]]) - corner
        return set(map(tuple, np.round(mid / (1e-8 * scale)).astype(np.int64).tolist()))

    corner = lower.points.min(axis=0)

    shared = midpoints(lower) & midpoints(upper)
    if shared:
        raise MeshError(f"{origin}: the halves touch along {len(shared)} edges that are not Σ: Σ must split Ω "
                        f"into the lower and the upper half (is part of Σ missing from {SIGMA!r}?)")


def sigma_line(lower: HalfMesh, upper: HalfMesh, exact_normals: np.ndarray | None = None) -> SigmaLine:
    """Σ of two paired halves: its nodes in order, normals (``exact_normals`` where given), weights, roles."""
    degree = lower.degree
    step = degree  # nodes per Σ edge, beyond its first
    order = lower.sigma
    points = lower.points[order]
    edges = np.column_stack([order[:-1:step], order[step::step]] + ([order[1::step]] if degree == 2 else []))
    s, w = EDGE_RULE
    shapes, _ = edge_shapes(edges.shape[1], s)
    _, tangents = edge_points(lower.points, edges, s)
    speed = np.linalg.norm(tangents, axis=2)  # (e, q)
    local = np.einsum("eq,q,qk->ek", speed, w, shapes)  # ∫ φ_k ds per edge and edge node
    positions = np.column_stack([np.arange(0, len(order) - 1, step), np.arange(step, len(order), step)]
                                + ([np.arange(1, len(order), step)] if degree == 2 else []))
    weights = np.bincount(positions.ravel(), local.ravel(), minlength=len(order))
    # Normals: the unit tangents at each node's edge ends (and P2 middles), averaged with the edge
    # lengths as weights, turned left (Σ runs so that ν, out of the lower half, is on its left).
    _, end_tangents = edge_points(lower.points, edges, np.array([0.0, 1.0, 0.5][:edges.shape[1]]))
    direction = end_tangents / np.linalg.norm(end_tangents, axis=2, keepdims=True)
    summed = np.zeros((len(order), 2))
    np.add.at(summed, positions.ravel(), (direction * (speed @ w)[:, None, None]).reshape(-1, 2))
    normals = np.column_stack([-summed[:, 1], summed[:, 0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    if exact_normals is not None:
        known = np.all(np.isfinite(exact_normals), axis=1)
        aligned = exact_normals * np.sign(np.sum(exact_normals * normals, axis=1))[:, None]
        normals[known] = aligned[known] / np.linalg.norm(aligned[known], axis=1, keepdims=True)
    crack_keys = set(edge_keys(lower.edges(CRACK), len(lower.points)).tolist())
    on_crack = np.isin(edge_keys(edges, len(lower.points)), list(crack_keys))
    crack_count = np.bincount(positions[:, :2].ravel(), np.repeat(on_crack, 2), minlength=len(order))
    edge_count = np.bincount(positions[:, :2].ravel(), minlength=len(order))
    if degree == 2:  # a midpoint belongs to its edge only
        crack_count[1::2] = on_crack
        edge_count[1::2] = 1
    crack = (crack_count == edge_count) & (crack_count > 0)
    tip = (crack_count > 0) & ~crack
    clamped = np.isin(order, lower.clamped()) | np.isin(upper.sigma, upper.clamped())
    corner = np.ones(len(order), dtype=bool)
    if degree == 2:
        corner[1::2] = False
    return SigmaLine(points, normals, weights, crack, tip, clamped, corner)


# --- P2 from P1, statistics ---------------------------------------------------------------------
def elevate(points: np.ndarray, cells: np.ndarray, boundaries: dict[str, np.ndarray]
            ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """P1 → P2 with straight edges: a new node at the middle of every edge (raw, unchecked arrays)."""
    edges = cells[:, CELL_EDGES[3]].reshape(-1, 2)
    keys = edge_keys(edges, len(points))
    unique, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    middles = 0.5 * (points[edges[first, 0]] + points[edges[first, 1]])
    numbers = len(points) + np.arange(len(unique))
    cells6 = np.column_stack([cells, numbers[inverse].reshape(-1, 3)])
    named = {}
    for name, raw in boundaries.items():
        raw = np.asarray(raw, dtype=np.int64).reshape(-1, 2)
        position = np.searchsorted(unique, edge_keys(raw, len(points)))
        if len(raw) and (np.any(position >= len(unique)) or np.any(unique[np.minimum(position, len(unique) - 1)]
                                                                     != edge_keys(raw, len(points)))):
            raise MeshError(f"boundary {name!r} has edges that are not triangle edges")
        named[name] = np.column_stack([raw, numbers[position]])
    return np.vstack([points, middles]), cells6, named


@dataclass(frozen=True)
class MeshStats:
    """Per-half numbers as in the paper's Table 1.

    The paper does not define its h; ``h_min``, ``h_max`` are the smallest and largest circumdiameter
    (2R) of a triangle, which matches all twenty of its values within 18 % on our meshes of its
    five (P, M) (the longest edge: within 23 %).  ``min_angle`` is the smallest angle in degrees.
    """

    h_min: float
    h_max: float
    vertices: int
    triangles: int
    min_angle: float


def statistics(half: HalfMesh) -> MeshStats:
    sides, edges = _sides(half.points, half.corners)
    circumdiameters = edges.prod(axis=1) / (2.0 * np.abs(half.areas()))
    return MeshStats(float(circumdiameters.min()), float(circumdiameters.max()), half.vertex_count,
                     len(half.cells), _smallest_angle(sides, edges))


def _sides(points: np.ndarray, corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles' side vectors ``(m, 3, 2)`` (from each corner to the next) and their lengths."""
    p = points[corners]
    sides = np.empty_like(p)
    sides[:, :2] = p[:, 1:] - p[:, :2]
    sides[:, 2] = p[:, 0] - p[:, 2]
    return sides, np.sqrt(sides[..., 0] ** 2 + sides[..., 1] ** 2)


def _smallest_angle(sides: np.ndarray, edges: np.ndarray) -> float:
    """The smallest interior angle of the triangles (degrees): that of the largest cosine."""
    cosines = -np.einsum("mkd,mkd->mk", sides, sides[:, [2, 0, 1]]) / (edges * edges[:, [2, 0, 1]])
    return float(np.degrees(np.arccos(np.clip(cosines.max(initial=-1.0), -1.0, 1.0))))


def boundary_vertex_count(mesh: Mesh) -> int:
    """M: triangle vertices on ∂Ω (the boundary of the regions without the Σ lines), shared ones counted once."""
    coordinates = []
    for half in mesh.regions:
        edges = half.boundary_edges[:, :2]
        inner = np.vstack([half.edges(SIGMA)[:, :2], half.edges(SIGMA_ABOVE)[:, :2]])
        sigma = np.isin(edge_keys(edges, len(half.points)), edge_keys(inner, len(half.points)))
        coordinates.append(half.points[np.unique(edges[~sigma])].round(12))
    return len(np.unique(np.vstack(coordinates), axis=0))


def quality(mesh: Mesh) -> dict:
    """What a result records of its mesh: the smallest angle (degrees), the vertices on Σ and on ∂Ω."""
    return {"min_angle": min(half.shape.smallest_angle for half in mesh.regions),
            "sigma_vertices": int(mesh.sigma.corner.sum()), "boundary_vertices": boundary_vertex_count(mesh)}


def region_of(side: int) -> str:
    """The region of Ω of a half: ``lower`` (side −1) or ``upper`` (+1)."""
    return REGIONS[0] if side < 0 else REGIONS[1]


@dataclass(frozen=True)
class BlockSpec:
    name: str
    layer: str
    side: int  # -1: lower half, +1: upper half

    @property
    def region(self) -> str:
        """The block's region of Ω: with its layer, it selects the block's material."""
        return region_of(self.side)


def blocks(layers: int = 2) -> tuple[BlockSpec, ...]:
    """The blocks of a structure of ``layers`` layers (1 or 2): each layer on each region of Ω, layer by layer,
    the lower region first: u⁻, u⁺ (layer1), then v⁻, v⁺ (layer2).  Layer1's blocks come first in any
    structure, so :data:`U_MINUS` and :data:`U_PLUS` index them; :data:`V_MINUS` and :data:`V_PLUS` exist with
    two layers only."""
    if layers not in (1, 2):
        raise ValueError(f"a structure has 1 or 2 layers, not {layers}")
    return tuple(BlockSpec(f"{letter}_{word}", layer, side) for layer, letter in zip(LAYERS[:layers], "uv")
                 for side, word in ((-1, "minus"), (+1, "plus")))


U_MINUS, U_PLUS, V_MINUS, V_PLUS = range(4)


def partner(block: int, specs: tuple[BlockSpec, ...]) -> int:
    """The block of the same layer on the other half (in the block list ``specs``)."""
    spec = specs[block]
    return next(i for i, other in enumerate(specs) if other.layer == spec.layer and other.side == -spec.side)


def glued_layers(specs: tuple[BlockSpec, ...]) -> list[tuple[int, int]]:
    """The pairs of blocks that one region's layers glue together on Σ: (layer1's block, another layer's
    block of the same region), the lower region first; none in a one-layer structure."""
    return [(first, other) for first, spec in enumerate(specs) if spec.layer == LAYERS[0]
            for other, below in enumerate(specs) if below.side == spec.side and below.layer != LAYERS[0]]
