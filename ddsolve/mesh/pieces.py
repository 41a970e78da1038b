"""A rank's piece of a half whose rows (nodes) are shared out in contiguous ranges.

The rank of a distributed block that owns the nodes ``first:stop`` of a half owns a contiguous range of
its cells: as many as have their smallest node below ``stop``, less those below ``first`` — the cells
whose smallest node lies in the range when the cells are in the order of their smallest node, as
:func:`~ddsolve.mesh.mesh.make_half` makes them (in any order every cell has one owner).  It works on
those cells with ``rings`` layers of their neighbours around them (cells that share a node),
renumbered locally.  Two rings are what the error estimate's recovery needs at the nodes of the owned
cells.  No MPI here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddsolve.mesh.mesh import HalfMesh


@dataclass(frozen=True, eq=False)
class Piece:
    """Cells ``cell_ids`` of a half (the ``owned`` ones first: ``cell_first:cell_stop``) on the nodes ``nodes``
    (global numbers, ascending), of a rank that owns the nodes ``first:stop``; ``cells`` and ``outer_edges``
    (the half's boundary edges among them) in local numbers."""

    nodes: np.ndarray
    points: np.ndarray
    cells: np.ndarray
    cell_ids: np.ndarray
    owned: int
    outer_edges: np.ndarray
    first: int
    stop: int
    cell_first: int

    @property
    def cell_stop(self) -> int:
        return self.cell_first + self.owned

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
        return Piece(np.arange(n), half.points, half.cells, np.arange(len(half.cells)), len(half.cells),
                     half.boundary_edges, 0, n, 0)
    cell_first, cell_stop = cell_range(half, first, stop)
    taken = np.zeros(len(half.cells), dtype=bool)
    taken[cell_first:cell_stop] = True
    for _ in range(rings):
        reached = np.zeros(n, dtype=bool)
        reached[half.cells[taken]] = True
        taken |= reached[half.cells].any(axis=1)
    taken[cell_first:cell_stop] = False
    cell_ids = np.concatenate([np.arange(cell_first, cell_stop), np.flatnonzero(taken)])
    nodes = np.unique(half.cells[cell_ids])
    local = np.full(n, -1, dtype=np.int64)
    local[nodes] = np.arange(len(nodes))
    edges = half.boundary_edges
    inside = (local[edges] >= 0).all(axis=1)
    return Piece(nodes, half.points[nodes], local[half.cells[cell_ids]], cell_ids, cell_stop - cell_first,
                 local[edges[inside]], first, stop, cell_first)


def extra_bytes(pieces, halves) -> int:
    """Bytes of the pieces' arrays that are not their halves' own (none for a piece that is a whole half)."""
    own = {id(a) for half in halves for a in (half.points, half.cells, half.boundary_edges)}
    arrays = {id(a): a.nbytes for piece in pieces for a in (piece.nodes, piece.points, piece.cells, piece.cell_ids,
                                                            piece.outer_edges) if id(a) not in own}
    return sum(arrays.values())
