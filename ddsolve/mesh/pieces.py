"""A rank's piece of a half whose rows (nodes) are shared out in contiguous ranges.

The rank of a distributed block that owns the nodes ``first:stop`` of a half owns a contiguous range of
its cells: as many as have their smallest node below ``stop``, less those below ``first`` — the cells
whose smallest node lies in the range when the cells are in the order of their smallest node, as
:func:`~ddsolve.mesh.mesh.make_half` makes them.  In any order every cell has one owner; a refined half's
cells come coarse cell by coarse cell, nearly that order (P = 800: 99.6 % of a rank's cells have their
smallest node among its nodes, the others lie next to them).  It works on
those cells, the other cells of its nodes, and ``rings`` layers of neighbours around them all (cells that
share a node): two rings are what the error estimate's recovery needs at the nodes of the owned cells;
every owned node has all its cells, so the forces there (the reactions) are whole.  The piece is a
:class:`~ddsolve.mesh.mesh.HalfMesh` of its own, renumbered locally in the half's order (its owned nodes
are one contiguous range), that also keeps the half's skeleton: every Σ node and the nodes of every
named boundary, with no cells of their own where they lie outside the piece — what the supports, the
loads and Σ's traces read of a half is the same on it.  No MPI here.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ddsolve.mesh.mesh import HalfMesh, index_type


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
                     len(half.cells))
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
    kept = in_cells.copy()
    kept[half.sigma] = True
    for edges in half.boundaries.values():
        kept[edges] = True
    nodes = np.flatnonzero(kept)
    local = np.full(n, -1, dtype=np.int64)
    local[nodes] = np.arange(len(nodes))
    edges = half.boundary_edges
    piece = HalfMesh(half.points[nodes], local[half.cells[cell_ids]], half.side, local[half.sigma],
                     {name: local[named] for name, named in half.boundaries.items()})
    outer = local[edges[in_cells[edges].all(axis=1)]]
    return Piece(piece, nodes.astype(index_type(2 * n)), cell_stop - cell_first, outer, first, stop, cell_first, n,
                 len(half.cells))


def extra_bytes(pieces, halves) -> int:
    """Bytes of the pieces' arrays that are not their halves' own (none for a piece that is a whole half)."""
    own = {id(a) for half in halves for a in (half.points, half.cells, half.sigma, half.__dict__.get("boundary_edges"),
                                               *half.boundaries.values())}
    arrays = {id(a): a.nbytes for piece in pieces
              for a in (piece.nodes, piece.outer_edges, piece.half.points, piece.half.cells,
                        piece.half.sigma, *piece.half.boundaries.values()) if id(a) not in own}
    return sum(arrays.values())
