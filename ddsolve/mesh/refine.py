"""Uniform refinement of a coarse mesh: every coarse triangle cut into a lattice of n² triangles.

A coarse half refined by ``levels`` levels becomes, for P1, the lattice with n = 2^levels on every
coarse triangle; for P2, the lattice with n = 2^(levels+1) whose 2×2 groups are the 6-node triangles
(meshio's order v0 v1 v2 m01 m12 m20, counter-clockwise like the coarse cell).

The fine nodes are numbered from the coarse mesh alone (:class:`Lattice`), so that any rank can make
the fine points and cells of any range of coarse cells, and the pieces of several ranks fit together
by placement, without renumbering.  The coarse cells are taken in order along the longer side of
the half's bounding box; each coarse vertex and edge belongs to the first cell that uses it; the
fine nodes are numbered cell by cell, each cell's block holding its own coarse vertices, then the
n − 1 inner lattice nodes of its own edges (each edge from its lower to its higher vertex, edges in
the order of their vertices), then its inner lattice nodes.  A range of coarse cells therefore owns
a contiguous range of fine nodes, and the numbering of the fine half runs along its longer side as
:func:`~ddsolve.mesh.mesh.make_half`'s does (compact row ranges when a block is distributed).

New nodes on named boundary edges and on Σ are placed by ``project(points, names)`` (``names``: the
boundary name of the coarse edge each point lies on, ``"sigma"`` on Σ; None: straight edges); inner
nodes follow their cell's edges (the edges' displacements blended into the cell), so a cell on a
curved boundary bends with it.  Crack tips, being coarse vertices, stay vertices; both halves
refine their Σ edges alike, so their Σ nodes match.  No gmsh or MPI here.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ddsolve.errors import MeshError
from ddsolve.mesh.curves import Projector
from ddsolve.mesh.element import CELL_EDGES
from ddsolve.mesh.mesh import (CLAMPED, CRACK, SIGMA, HalfMesh, Mesh, Shape, check_resolution, check_sigma_match,
                               known, sigma_line)


#: Boundary names that only tag edges of other parts: a node is projected on its part's curve.
_TAGS = (CLAMPED, CRACK)

#: Coarse cells whose inner points :meth:`Lattice.points_of` places at once.
_CELL_CHUNK = 1024


def lattice_triangles(n: int, degree: int) -> np.ndarray:
    """The triangles of the lattice ``(i, j)``, i + j ≤ n, of one cell as ``(n², 3)`` (P1) or
    ``((n/2)², 6)`` (P2) rows of lattice positions (numbered row by row: j, then i), counter-clockwise."""
    side = n if degree == 1 else n // 2
    step = 1 if degree == 1 else 2
    i, j = (a.ravel() for a in np.meshgrid(np.arange(side), np.arange(side), indexing="ij"))
    up, down = i + j <= side - 1, i + j <= side - 2

    def at(di, dj, keep):
        return lattice_index(n, step * i[keep] + di, step * j[keep] + dj)

    if degree == 1:
        upward = np.column_stack([at(0, 0, up), at(1, 0, up), at(0, 1, up)])
        downward = np.column_stack([at(1, 0, down), at(1, 1, down), at(0, 1, down)])
    else:
        upward = np.column_stack([at(0, 0, up), at(2, 0, up), at(0, 2, up), at(1, 0, up), at(1, 1, up),
                                  at(0, 1, up)])
        downward = np.column_stack([at(2, 0, down), at(2, 2, down), at(0, 2, down), at(2, 1, down),
                                    at(1, 2, down), at(1, 1, down)])
    return np.vstack([upward, downward])


def lattice_index(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Position of lattice point (i, j) in the row-by-row order (rows j = 0..n of n + 1 − j points)."""
    return j * (n + 1) - j * (j - 1) // 2 + i


@dataclass(frozen=True, eq=False)
class Lattice:
    """The fine numbering of ``coarse`` refined ``levels`` times to element ``degree`` (see the module)."""

    coarse: HalfMesh
    levels: int
    degree: int

    @cached_property
    def n(self) -> int:
        """Lattice points per coarse edge, minus one."""
        return 2 ** self.levels * self.degree

    @cached_property
    def _topology(self) -> dict[str, np.ndarray]:
        corners = self.coarse.corners
        vertices, local = np.unique(corners, return_inverse=True)  # coarse points that are vertices
        local = local.reshape(-1, 3)
        centroid = self.coarse.points[corners].mean(axis=1)
        major = int(np.argmax(np.ptp(self.coarse.points[vertices], axis=0)))
        order = np.lexsort((centroid[:, 1 - major], centroid[:, major]))
        local = local[order]
        pairs = local[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        low, high = pairs.min(axis=1), pairs.max(axis=1)
        edges, cell_edge = np.unique(np.column_stack([low, high]), axis=0, return_inverse=True)
        cells = np.arange(len(local))
        vertex_owner = np.full(len(vertices), len(local))
        np.minimum.at(vertex_owner, local, cells[:, None].repeat(3, axis=1))
        edge_owner = np.full(len(edges), len(local))
        np.minimum.at(edge_owner, cell_edge.reshape(-1), np.repeat(cells, 3))
        inner = (self.n - 1) * (self.n - 2) // 2
        owned_vertices = np.bincount(vertex_owner, minlength=len(local))
        owned_edges = np.bincount(edge_owner, minlength=len(local))
        sizes = owned_vertices + owned_edges * (self.n - 1) + inner
        offsets = np.concatenate([[0], np.cumsum(sizes)])
        vertex_id = offsets[vertex_owner] + _rank_within(vertex_owner)
        edge_first = offsets[edge_owner] + owned_vertices[edge_owner] + _rank_within(edge_owner) * (self.n - 1)
        return {"vertices": vertices, "cells": local, "edges": edges,
                "cell_edges": cell_edge.reshape(-1, 3), "forward": (pairs[:, 0] < pairs[:, 1]).reshape(-1, 3),
                "offsets": offsets, "vertex_id": vertex_id, "edge_first": edge_first,
                "vertex_owner": vertex_owner, "edge_owner": edge_owner, "owned_vertices": owned_vertices,
                "inner_first": offsets[1:] - inner}

    @property
    def cell_count(self) -> int:
        """Coarse cells."""
        return len(self.coarse.cells)

    @property
    def node_offsets(self) -> np.ndarray:
        """``(cells + 1,)``: coarse cell c owns the fine nodes ``offsets[c]:offsets[c + 1]``."""
        return self._topology["offsets"]

    @property
    def cells_per_cell(self) -> int:
        """Fine cells per coarse cell: coarse cell c has the fine cells ``c·k:(c + 1)·k``."""
        return (self.n // self.degree) ** 2

    @property
    def node_count(self) -> int:
        return int(self.node_offsets[-1])

    @cached_property
    def _template(self) -> dict[str, np.ndarray]:
        n = self.n
        j, i = (a.ravel() for a in np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij"))
        keep = i + j <= n
        i, j = i[keep], j[keep]  # row by row, as lattice_index counts
        corner = np.select([(i == 0) & (j == 0), i == n, j == n], [0, 1, 2], -1)
        edge = np.select([corner >= 0, j == 0, i + j == n, i == 0], [-1, 0, 1, 2], -1)
        step = np.select([edge == 0, edge == 1, edge == 2], [i, j, n - j], 0)
        inner = (corner < 0) & (edge < 0)
        inner_index = np.cumsum(inner) - 1
        return {"i": i, "j": j, "corner": corner, "edge": edge, "step": step, "inner": inner,
                "inner_index": inner_index, "triangles": lattice_triangles(n, self.degree)}

    def node_ids(self, cells: np.ndarray) -> np.ndarray:
        """``(cells, lattice points)``: the fine number of every lattice point of coarse ``cells``."""
        top, shape = self._topology, self._template
        ids = np.empty((len(cells), len(shape["i"])), dtype=np.int64)
        for local in range(3):
            at = shape["corner"] == local
            ids[:, at] = top["vertex_id"][top["cells"][cells, local]][:, None]
            at = shape["edge"] == local
            forward = top["forward"][cells, local][:, None]
            steps = np.where(forward, shape["step"][at][None, :], self.n - shape["step"][at][None, :])
            ids[:, at] = top["edge_first"][top["cell_edges"][cells, local]][:, None] + steps - 1
        ids[:, shape["inner"]] = top["inner_first"][cells][:, None] + shape["inner_index"][shape["inner"]][None, :]
        return ids

    def fine_cells(self, first: int, stop: int) -> np.ndarray:
        """The fine cells of coarse cells ``first:stop`` (``cells_per_cell`` rows per coarse cell)."""
        return self.cells_of(np.arange(first, stop))

    def cells_of(self, cells: np.ndarray) -> np.ndarray:
        """The fine cells of coarse ``cells`` (``cells_per_cell`` rows per coarse cell, in lattice order)."""
        return self.node_ids(cells)[:, self._template["triangles"]].reshape(-1, 3 * self.degree)

    def points_of(self, nodes: np.ndarray, project: Projector | None = None) -> np.ndarray:
        """The points of the fine ``nodes`` (any numbers, in any order), placed as :meth:`fine_points` places them."""
        top, n, shape = self._topology, self.n, self._template
        nodes = np.asarray(nodes, dtype=np.int64)
        owner = np.searchsorted(self.node_offsets, nodes, side="right") - 1
        out = np.empty((len(nodes), 2))
        vertex = nodes - self.node_offsets[owner] < top["owned_vertices"][owner]
        inner = nodes >= top["inner_first"][owner]
        edge = ~vertex & ~inner
        by_number = np.argsort(top["vertex_id"])
        out[vertex] = self.coarse.points[top["vertices"][by_number[np.searchsorted(top["vertex_id"], nodes[vertex],
                                                                                   sorter=by_number)]]]
        by_first = np.argsort(top["edge_first"])
        edges = by_first[np.searchsorted(top["edge_first"], nodes[edge], side="right", sorter=by_first) - 1]
        unique_edges, which = np.unique(edges, return_inverse=True)
        out[edge] = self._edge_nodes(unique_edges, project)[which, nodes[edge] - top["edge_first"][edges]]
        cells, at = np.unique(owner[inner], return_inverse=True)
        weights = np.column_stack([n - shape["i"] - shape["j"], shape["i"], shape["j"]])[shape["inner"]] / n
        position = nodes[inner] - top["inner_first"][owner[inner]]
        placed = np.empty((int(inner.sum()), 2))
        for start in range(0, len(cells), _CELL_CHUNK):  # the inner points of a chunk of cells at a time
            chunk = cells[start:start + _CELL_CHUNK]
            rows = np.flatnonzero((at >= start) & (at < start + len(chunk)))
            chunk_points = np.einsum("qk,ckd->cqd", weights, self.coarse.points[top["vertices"][top["cells"][chunk]]])
            if project is not None:
                chunk_points += self._bend(chunk, weights, project)
            placed[rows] = chunk_points[at[rows] - start, position[rows]]
        out[inner] = placed
        return out

    def fine_points(self, first: int, stop: int, project: Projector | None = None) -> np.ndarray:
        """The fine nodes coarse cells ``first:stop`` own, in their fine order
        (``node_offsets[first]:node_offsets[stop]``)."""
        return self.points_of(np.arange(self.node_offsets[first], self.node_offsets[stop]), project)

    def _edge_nodes(self, edges: np.ndarray, project: Projector | None) -> np.ndarray:
        """``(e, n − 1, 2)``: the inner lattice nodes of coarse ``edges``, from the lower vertex to the
        higher, on their boundary's curve when ``project`` is given."""
        top, n = self._topology, self.n
        coarse = self.coarse.points[top["vertices"]]
        a, b = coarse[top["edges"][edges, 0]], coarse[top["edges"][edges, 1]]
        t = np.arange(1, n) / n
        nodes = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
        if project is None or len(edges) == 0:
            return nodes
        names = self.edge_names[edges]
        moved = names != ""
        if moved.any():
            flat = nodes[moved].reshape(-1, 2)
            placed = np.asarray(project(flat, np.repeat(names[moved], n - 1)), dtype=np.float64)
            if placed.shape != flat.shape or not np.all(np.isfinite(placed)):
                raise MeshError(f"{self.coarse.name} half: the boundary projection returned {placed.shape} "
                                f"values for {flat.shape} points (or non-finite ones)")
            nodes[moved] = placed.reshape(-1, n - 1, 2)
        return nodes

    def _bend(self, cells: np.ndarray, weights: np.ndarray, project: Projector) -> np.ndarray:
        """``(c, q, 2)``: how far the inner nodes (barycentric ``weights``) of ``cells`` move with their
        cells' projected edges: each edge's displacement, taken where the line from the opposite vertex
        meets it and interpolated between its lattice nodes, weighted by 1 − the opposite weight."""
        top, n = self._topology, self.n
        shift = np.zeros((len(cells), len(weights), 2))
        bent = self.edge_names[top["cell_edges"][cells]] != ""  # (c, 3)
        if not bent.any():
            return shift
        for local, (start, end) in enumerate(CELL_EDGES[3]):
            rows = np.flatnonzero(bent[:, local])
            if len(rows) == 0:
                continue
            edges = top["cell_edges"][cells[rows], local]
            straight = self._edge_nodes(edges, None)
            moved = self._edge_nodes(edges, project) - straight  # (r, n − 1, 2), lower → higher vertex
            moved = np.concatenate([np.zeros((len(rows), 1, 2)), moved, np.zeros((len(rows), 1, 2))], axis=1)
            opposite = 3 - start - end
            along = weights[:, end] / np.maximum(weights[:, start] + weights[:, end], 1e-300)  # from start
            along = np.where(top["forward"][cells[rows], local][:, None], along[None, :], 1.0 - along[None, :])
            position = along * n
            below = np.minimum(np.floor(position).astype(np.int64), n - 1)
            fraction = (position - below)[..., None]
            row = np.arange(len(rows))[:, None]
            value = (1.0 - fraction) * moved[row, below] + fraction * moved[row, below + 1]
            shift[rows] += (1.0 - weights[:, opposite])[None, :, None] * value
        return shift

    @cached_property
    def edge_names(self) -> np.ndarray:
        """Per coarse edge, the boundary it lies on (``"sigma"`` for Σ, a part's name rather than a
        tag such as ``clamped``; ``""`` inside the half)."""
        top = self._topology
        names = np.full(len(top["edges"]), "", dtype=object)
        ranked = sorted(self.coarse.boundaries, key=lambda name: (name == SIGMA, name not in _TAGS, name))
        for name in ranked:
            names[self._coarse_edges(self.coarse.edges(name))[0]] = name
        return names.astype(str)

    def _coarse_edges(self, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The coarse edge numbers of boundary ``edges`` (rows a, b[, mid] of coarse points) and whether
        each runs from the lower vertex to the higher."""
        top = self._topology
        local = np.searchsorted(top["vertices"], edges[:, :2])
        low, high = local.min(axis=1), local.max(axis=1)
        keys = top["edges"][:, 0] * len(top["vertices"]) + top["edges"][:, 1]
        return np.searchsorted(keys, low * len(top["vertices"]) + high), local[:, 0] < local[:, 1]

    def _chains(self, edges: np.ndarray) -> np.ndarray:
        """``(e, n + 1)``: the fine nodes along each coarse boundary edge (a, b[, mid]) from a to b."""
        top, n = self._topology, self.n
        numbers, forward = self._coarse_edges(edges)
        steps = np.where(forward[:, None], np.arange(1, n)[None, :], n - np.arange(1, n)[None, :])
        local = np.searchsorted(top["vertices"], edges[:, :2])
        inner = top["edge_first"][numbers][:, None] + steps - 1
        return np.column_stack([top["vertex_id"][local[:, 0]], inner, top["vertex_id"][local[:, 1]]])

    def fine_edges(self, edges: np.ndarray) -> np.ndarray:
        """The fine edges of coarse boundary ``edges``, each cut into 2^levels, in its direction."""
        chain = self._chains(edges)
        if self.degree == 1:
            return np.stack([chain[:, :-1], chain[:, 1:]], axis=2).reshape(-1, 2)
        return np.stack([chain[:, :-1:2], chain[:, 2::2], chain[:, 1::2]], axis=2).reshape(-1, 3)

    def boundaries(self) -> dict[str, np.ndarray]:
        """The named boundary edges of the fine half."""
        return {name: self.fine_edges(edges) for name, edges in self.coarse.boundaries.items()}

    def sigma(self) -> np.ndarray:
        """The fine Σ nodes in the coarse half's Σ order."""
        order = self.coarse.sigma[::self.coarse.degree]  # the coarse Σ vertices
        if len(order) < 2:
            return np.zeros(0, dtype=np.int64)
        chain = self._chains(np.column_stack([order[:-1], order[1:]]))
        return np.concatenate([chain[:, :-1].ravel(), chain[-1:, -1]])

    def outer_edges(self) -> np.ndarray:
        """The fine half's boundary edges (the coarse half's, cut)."""
        return self.fine_edges(self.coarse.boundary_edges)

    def half(self, points: np.ndarray, cells: np.ndarray, shape: Shape | None = None) -> HalfMesh:
        """The fine half from its assembled points and cells (every coarse cell's pieces placed, in lattice order),
        its cells put in the order of their smallest node (:func:`cell_order`); its outer edges are the coarse
        half's cut, and ``shape`` (:func:`~ddsolve.mesh.mesh.shape_of` of all its cells, from the pieces'
        shapes) is kept."""
        half = HalfMesh(points, cells[cell_order(cells)], self.coarse.side, self.sigma(), self.boundaries(),
                        self.coarse.named_points)
        return known(half, boundary_edges=self.outer_edges(), **({"shape": shape} if shape is not None else {}))

    def skeleton(self, shape: Shape, project: Projector | None = None) -> HalfMesh:
        """:func:`~ddsolve.mesh.mesh.skeleton` of the fine half, made from the coarse half alone (``shape``: the
        fine half's)."""
        outer, sigma, boundaries = self.outer_edges(), self.sigma(), self.boundaries()
        kept = np.unique(np.concatenate([outer.ravel(), sigma, *(edges.ravel() for edges in boundaries.values())]))
        bare = HalfMesh(self.points_of(kept, project), np.zeros((0, 3 * self.degree), dtype=np.int64),
                        self.coarse.side, np.searchsorted(kept, sigma),
                        {name: np.searchsorted(kept, edges) for name, edges in boundaries.items()},
                        self.coarse.named_points)
        return known(bare, boundary_edges=np.searchsorted(kept, outer), shape=shape)

    def owners(self, first: int, stop: int) -> np.ndarray:
        """The coarse cells that own the fine nodes ``first:stop`` (a range of them)."""
        offsets = self.node_offsets
        return np.arange(np.searchsorted(offsets, first, side="right") - 1,
                         np.searchsorted(offsets, stop - 1, side="right"))

    def node_span(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The smallest and the largest fine node of each coarse cell of ``cells`` (without making its fine cells)."""
        top, offsets = self._topology, self.node_offsets
        vertices = top["vertex_id"][top["cells"][cells]]
        edges = top["edge_first"][top["cell_edges"][cells]]
        low, high = np.minimum(vertices.min(axis=1), edges.min(axis=1)), np.maximum(vertices.max(axis=1),
                                                                                    edges.max(axis=1) + self.n - 2)
        own = offsets[cells + 1] > offsets[cells]  # the cell owns nodes of its own
        return (np.where(own, np.minimum(low, offsets[cells]), low),
                np.where(own, np.maximum(high, offsets[cells + 1] - 1), high))

    def around(self, cells: np.ndarray, rings: int) -> np.ndarray:
        """The coarse ``cells`` with ``rings`` layers of their neighbours (cells that share a vertex), ascending."""
        corners = self._topology["cells"]
        taken = np.zeros(len(corners), dtype=bool)
        taken[cells] = True
        for _ in range(rings):
            reached = np.zeros(len(self._topology["vertices"]), dtype=bool)
            reached[corners[taken]] = True
            taken |= reached[corners].any(axis=1)
        return np.flatnonzero(taken)


def cell_order(cells: np.ndarray) -> np.ndarray:
    """The order of a refined half's cells (given in lattice order): by their smallest node, as
    :func:`~ddsolve.mesh.mesh.make_half` orders a half's, ties in lattice order."""
    return np.argsort(cells.min(axis=1), kind="stable")


def _rank_within(groups: np.ndarray) -> np.ndarray:
    """For each element, how many elements before it (in index order) share its group."""
    order = np.argsort(groups, kind="stable")
    sorted_groups = groups[order]
    starts = np.flatnonzero(np.r_[True, sorted_groups[1:] != sorted_groups[:-1]])
    counts = np.diff(np.r_[starts, len(groups)])
    rank = np.empty(len(groups), dtype=np.int64)
    rank[order] = np.arange(len(groups)) - np.repeat(starts, counts)
    return rank


def refine_half(coarse: HalfMesh, levels: int, degree: int | None = None, project: Projector | None = None
                ) -> HalfMesh:
    """``coarse`` refined ``levels`` times to element ``degree`` (the coarse one by default), in one process."""
    grid = Lattice(coarse, levels, degree or coarse.degree)
    points = grid.fine_points(0, grid.cell_count, project)
    return grid.half(points, grid.fine_cells(0, grid.cell_count))


def refine(mesh: Mesh, levels: int, degree: int | None = None, project: Projector | None = None) -> Mesh:
    """Both halves of ``mesh`` (a checked mesh, from :func:`~ddsolve.mesh.mesh.make_mesh`) refined
    ``levels`` times (element ``degree``, the mesh's by default) and paired (:func:`pair_refined`)."""
    return pair_refined(mesh, *(refine_half(half, levels, degree, project) for half in mesh.halves))


def pair_refined(coarse: Mesh, lower: HalfMesh, upper: HalfMesh) -> Mesh:
    """The mesh of the refined halves of ``coarse``.  What :func:`~ddsolve.mesh.mesh.make_mesh` checked on
    the coarse mesh (boundaries, clamped parts, cracks on Σ, Σ the only contact) holds for its refinement by
    construction; the fine nodes' positions are checked again (Σ nodes matching, resolution)."""
    scale = max(np.ptp(half.points, axis=0).max() for half in (lower, upper))
    check_resolution(lower, upper, coarse.origin)
    check_sigma_match(lower, upper, scale, coarse.origin)
    return Mesh(lower, upper, sigma_line(lower, upper), coarse.origin)


def shares(grid: Lattice, parts: int, idle_first: bool = False) -> np.ndarray:
    """``(parts + 1,)`` coarse cell bounds giving each of ``parts`` processes about the same fine nodes;
    with ``idle_first`` the first process none (it has other work) and the others about the same."""
    if idle_first and parts > 1:
        return np.concatenate([[0], shares(grid, parts - 1)])
    offsets = grid.node_offsets
    targets = np.linspace(0, offsets[-1], parts + 1)
    bounds = np.searchsorted(offsets, targets)
    bounds[0], bounds[-1] = 0, grid.cell_count
    return np.maximum.accumulate(bounds)
