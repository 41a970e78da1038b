"""A rank's piece of a half whose rows (nodes) are shared out in contiguous ranges.

The rank of a distributed block that owns the nodes ``first:stop`` of a half owns the cells whose
smallest node lies in the range: a contiguous range of them, since a half's cells are in the order of
their smallest node (:func:`~ddsolve.mesh.mesh.make_half`, :meth:`~ddsolve.mesh.refine.Lattice.half`).  It
works on those cells, the other cells of its nodes, and ``rings`` layers of neighbours around them all
(cells that share a node): two rings are what the error estimate's recovery needs at the nodes of the
owned cells; every owned node has all its cells, so the forces there (the reactions) are whole.  The
piece is a :class:`~ddsolve.mesh.mesh.HalfMesh` of its own, renumbered locally in the half's order (its
owned nodes are one contiguous range), that also keeps the half's skeleton: every Σ node, the nodes of
every named boundary and of the outer boundary, with no cells of their own where they lie outside the
piece — what the supports, the loads and Σ's traces read of a half is the same on it.  It is cut from the
whole half (:func:`cut`) or, for a refined half, made from the coarse one (:func:`of_lattice`).  No MPI
here.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ddsolve.mesh.curves import Projector
from ddsolve.mesh.mesh import HalfMesh, index_type
from ddsolve.mesh.refine import Lattice

#: Fine cells :func:`of_lattice` makes at once.
CHUNK_CELLS = 1 << 16


@dataclass(frozen=True, eq=False)
class Piece:
    """The piece ``half`` (local numbers; its cells the half's cells ``cell_first:cell_stop`` that it owns, then
    the others it needs) on the half's nodes ``nodes`` (global numbers, ascending) of a rank that owns
    the nodes ``first:stop`` of ``rows``; ``outer_edges``: the half's boundary edges among the piece's cells
    (local)."""

    half: HalfMesh
    nodes: np.ndarray
    owned: int
    outer_edges: np.ndarray
    first: int
    stop: int
    cell_first: int
    rows: int  # the half's nodes
    cell_rows: int  # the half's cells
    outline: np.ndarray  # the local numbers of the half's outer boundary nodes (its skeleton keeps them all)

    @property
    def points(self) -> np.ndarray:
        return self.half.points

    @property
    def cells(self) -> np.ndarray:
        return self.half.cells

    @property
    def cell_stop(self) -> int:
        return self.cell_first + self.owned

    @property
    def owned_nodes(self) -> slice:
        """The local numbers of the owned nodes ``first:stop``."""
        start = int(np.searchsorted(self.nodes, self.first))
        return slice(start, start + self.stop - self.first)

    @property
    def owned_cells(self) -> np.ndarray:
        """The owned cells in local numbers."""
        return self.half.cells[:self.owned]

    @cached_property
    def owned_half(self) -> HalfMesh:
        """The piece with its owned cells only (its nodes all kept): what the ranks of a block sum over."""
        return self.half if self.owned == len(self.half.cells) else dataclasses.replace(self.half,
                                                                                       cells=self.owned_cells)

    def local_dofs(self) -> np.ndarray:
        """The global dofs (x, y) of the piece's nodes, in local order."""
        return np.column_stack([2 * self.nodes, 2 * self.nodes + 1]).ravel()


def cell_range(half: HalfMesh, first: int, stop: int) -> tuple[int, int]:
    """The cells owned with the nodes ``first:stop`` (see the module)."""
    smallest = half.cells.min(axis=1)
    return int(np.count_nonzero(smallest < first)), int(np.count_nonzero(smallest < stop))


def cut(half: HalfMesh, first: int, stop: int, rings: int = 2) -> Piece:
    """The piece of the rank owning the nodes ``first:stop`` of ``half`` (the whole half if that is all of them)."""
    n = len(half.points)
    if first == 0 and stop == n:
        return Piece(half, np.arange(n, dtype=index_type(2 * n)), len(half.cells), half.boundary_edges, 0, n, 0, n,
                     len(half.cells), np.unique(half.boundary_edges))
    cell_first, cell_stop = cell_range(half, first, stop)
    mine = np.zeros(n, dtype=bool)
    mine[first:stop] = True
    taken = mine[half.cells].any(axis=1)  # the owned cells and the other cells of the owned nodes
    for _ in range(rings):
        reached = np.zeros(n, dtype=bool)
        reached[half.cells[taken]] = True
        taken |= reached[half.cells].any(axis=1)
    taken[cell_first:cell_stop] = False
    cell_ids = np.concatenate([np.arange(cell_first, cell_stop), np.flatnonzero(taken)])
    in_cells = np.zeros(n, dtype=bool)
    in_cells[half.cells[cell_ids]] = True
    edges = half.boundary_edges
    kept = in_cells.copy()
    for skeleton in (edges, half.sigma, *half.boundaries.values()):
        kept[skeleton] = True
    nodes = np.flatnonzero(kept)
    local = np.full(n, -1, dtype=np.int64)
    local[nodes] = np.arange(len(nodes))
    piece = HalfMesh(half.points[nodes], local[half.cells[cell_ids]], half.side, local[half.sigma],
                     {name: local[named] for name, named in half.boundaries.items()}, half.named_points)
    outer = local[edges[in_cells[edges].all(axis=1)]]
    return Piece(piece, nodes.astype(index_type(2 * n)), cell_stop - cell_first, outer, first, stop, cell_first, n,
                 len(half.cells), local[np.unique(edges)])


def of_lattice(grid: Lattice, first: int, stop: int, project: Projector | None = None, rings: int = 2,
               share: tuple[int, int] = (0, 1), join: Callable[[np.ndarray], np.ndarray] = lambda part: part,
               mark: Callable[[str, int], None] = lambda name, nbytes: None) -> Piece:
    """The piece :func:`cut` makes of the refined half ``grid`` numbers (:meth:`Lattice.half`, its cells in the
    order of their smallest node), made from the coarse half alone.  The coarse cells around the owned nodes
    whose fine nodes are all owned give all their fine cells; those of the others (a band along the range's
    ends) are made a chunk at a time, ``rings`` + 1 times (the owned nodes' cells, then each ring), and only
    the piece's kept.  Its ``cell_first`` is left 0: it is the number of cells the ranks before own.

    Processes making the same piece can share the work: ``share = (k, parts)`` makes the k-th of ``parts``
    parts of its inner cells and of its points, and ``join`` returns the parts of all, in order, together.
    ``mark(name, nbytes)`` is called at the end of each step, with the bytes of the piece's cells and points
    made so far: ``"meshing"`` after making cells or points, ``"distribution"`` after choosing, joining,
    ordering and numbering them (what :func:`cut` does)."""
    rows, per_cell = grid.node_count, grid.cells_per_cell
    # every cell within rings + 1 fine layers of the owned nodes, the owners' neighbours across a coarse vertex
    patch = grid.around(grid.owners(first, stop), 1 + -(-(rings + 1) // grid.n))
    low, high = grid.node_span(patch)
    inside = (low >= first) & (high < stop)
    band = patch[~inside]
    chunks = np.array_split(band, max(1, len(band) * per_cell // CHUNK_CELLS))
    reached = np.zeros(rows, dtype=bool)
    reached[first:stop] = True
    kept, positions = [], []
    for ring in range(rings + 1):  # the owned nodes reach their cells' nodes, and so on; the cells of the last
        grown = reached.copy()
        for chunk in chunks:
            cells = grid.cells_of(chunk)
            hit = reached[cells].any(axis=1)
            if ring < rings:
                grown[cells[hit]] = True
            else:
                kept.append(cells[hit])
                positions.append(fine_positions(chunk, per_cell)[hit])
        reached = grown
    del reached, grown
    band_bytes = sum(a.nbytes for a in (*kept, *positions))
    mark("distribution", band_bytes)
    inner = grid.cells_of(np.array_split(patch[inside], share[1])[share[0]])
    mark("meshing", band_bytes + inner.nbytes)
    cells = np.concatenate([join(inner), *kept])
    position = np.concatenate([fine_positions(patch[inside], per_cell), *positions])
    del inner, kept, positions
    smallest = cells.min(axis=1)
    owned = (smallest >= first) & (smallest < stop)
    cells = cells[np.lexsort((position, smallest, ~owned))]  # owned first, each part in the half's order
    edges, sigma, boundaries = grid.outer_edges(), grid.sigma(), grid.boundaries()
    used = np.zeros(rows, dtype=bool)
    used[cells] = True
    outer = edges[used[edges].all(axis=1)]
    for skeleton in (edges, sigma, *boundaries.values()):
        used[skeleton] = True
    nodes = np.flatnonzero(used)
    local = np.cumsum(used, dtype=np.int64) - 1
    mark("distribution", cells.nbytes + nodes.nbytes)
    points = grid.points_of(np.array_split(nodes, share[1])[share[0]], project)
    mark("meshing", cells.nbytes + nodes.nbytes + points.nbytes)
    piece = HalfMesh(join(points), local[cells], grid.coarse.side, local[sigma],
                     {name: local[named] for name, named in boundaries.items()}, grid.coarse.named_points)
    return Piece(piece, nodes.astype(index_type(2 * rows)), int(owned.sum()), local[outer], first, stop, 0, rows,
                 grid.cell_count * per_cell, local[np.unique(edges)])


def fine_positions(coarse_cells: np.ndarray, per_cell: int) -> np.ndarray:
    """The places in lattice order of the fine cells of ``coarse_cells``."""
    return (coarse_cells[:, None] * per_cell + np.arange(per_cell)).ravel()


def extra_bytes(pieces, halves) -> int:
    """Bytes of the pieces' arrays that are not their halves' own (none for a piece that is a whole half)."""
    own = {id(a) for half in halves for a in (half.points, half.cells, half.sigma, half.__dict__.get("boundary_edges"),
                                               *half.boundaries.values())}
    arrays = {id(a): a.nbytes for piece in pieces
              for a in (piece.nodes, piece.outer_edges, piece.outline, piece.half.points, piece.half.cells,
                        piece.half.sigma, *piece.half.boundaries.values()) if id(a) not in own}
    return sum(arrays.values())
