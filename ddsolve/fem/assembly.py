"""Vectorized plane elasticity with P1 or P2 (isoparametric) triangles: stiffness, boundary loads,
strains, stresses and energies.

No Python loop over cells: element matrices as ``(m, 2k, 2k)`` arrays (k = 3 or 6 nodes), a slice of cells
at a time, summed into CSR through a precomputed pattern (:class:`Pattern`, one per half: the two blocks of
a half share it, only their values differ; it holds each node pair's entry and expands a slice's entries
to their dofs when they are summed).  Degrees of
freedom are interleaved, node ``v`` owning ``2v`` (x) and ``2v + 1`` (y), so the matrices have block
size 2.  At the Σ nodes that carry multipliers the two dofs are instead the components in the node's
(tangent, normal) frame (:attr:`~ddsolve.mesh.mesh.SigmaLine.frames`), so that every interface condition
acts on single dofs; :func:`to_global` turns a solution back.  No PETSc or MPI here.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ddsolve.errors import SceneError
from ddsolve.fem import supports
from ddsolve.mesh.element import (TRIANGLE_RULES, edge_points, edge_shapes, element_geometry, field_gradients,
                                  gauss_interval, shape_functions)
from ddsolve.mesh.mesh import BLOCKS, HalfMesh, Mesh, SigmaLine, index_type
from ddsolve.problem import expressions, materials
from ddsolve.problem.expressions import Expression
from ddsolve.problem.scene import LAYERS, Displacement, Load, Scene


def strain_operator(gradients: np.ndarray) -> np.ndarray:
    """B ``(..., 3, 2k)`` mapping element dofs to (εxx, εyy, γxy), from gradients ``(..., k, 2)``."""
    k = gradients.shape[-2]
    B = np.zeros(gradients.shape[:-2] + (3, 2 * k))
    B[..., 0, 0::2] = gradients[..., 0]
    B[..., 1, 1::2] = gradients[..., 1]
    B[..., 2, 0::2] = gradients[..., 1]
    B[..., 2, 1::2] = gradients[..., 0]
    return B


def element_dofs(cells: np.ndarray) -> np.ndarray:
    """``(m, 2c)`` dofs of each row of c nodes, in the order (v0x, v0y, v1x, v1y, ...)."""
    return np.stack([2 * cells, 2 * cells + 1], axis=2).reshape(len(cells), 2 * cells.shape[1])


def element_stiffness(points: np.ndarray, cells: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``(m, 2k, 2k)`` element stiffness matrices ∫ Bᵀ D B."""
    xi, weights = TRIANGLE_RULES[cells.shape[1]]
    det, gradients = element_geometry(points, cells, xi)
    out = np.zeros((len(cells), 2 * cells.shape[1], 2 * cells.shape[1]))
    for q, weight in enumerate(weights):
        B = strain_operator(gradients[:, q]) * np.sqrt(weight * det[:, q])[:, None, None]
        out += np.matmul(B.transpose(0, 2, 1), np.matmul(D, B))
    return out


def coo_to_csr(n: int, rows: np.ndarray, cols: np.ndarray, values: np.ndarray, columns: int | None = None):
    """Sum duplicate COO triplets of an n×``columns`` matrix (square by default); return
    (indptr, indices, data) with rows in order."""
    columns = n if columns is None else columns
    key = rows.astype(np.int64) * columns + cols
    order = np.argsort(key)  # duplicates are summed, so their order does not matter
    key = key[order]
    first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    data = np.add.reduceat(values[order], first) if len(first) else np.zeros(0)
    key = key[first]
    indptr = np.searchsorted(key // columns, np.arange(n + 1)).astype(np.int64)
    return indptr, (key % columns).astype(np.int64), data


def stiffness(points: np.ndarray, cells: np.ndarray, D: np.ndarray):
    """Unconstrained stiffness as COO triplets (rows, cols, values), duplicates not yet summed."""
    dofs = element_dofs(cells)
    size = dofs.shape[1]
    rows = np.broadcast_to(dofs[:, :, None], (len(cells), size, size)).ravel()
    cols = np.broadcast_to(dofs[:, None, :], (len(cells), size, size)).ravel()
    return rows, cols, element_stiffness(points, cells, D).ravel()


# --- local frames at the Σ nodes -----------------------------------------------------------------
def rotate_elements(matrices: np.ndarray, cells: np.ndarray, nodes: np.ndarray, frames: np.ndarray,
                    n_nodes: int) -> None:
    """Element matrices ``(m, 2k, 2k)`` of ``cells`` -> R Kₑ Rᵀ in place, R rotating the dofs of
    ``nodes`` into ``frames`` ``(len(nodes), 2, 2)`` (new component b = Σ_a R[b, a] old a)."""
    frame_of = np.full(n_nodes, -1, dtype=np.int64)
    frame_of[nodes] = np.arange(len(nodes))
    touched = np.flatnonzero((frame_of[cells] >= 0).any(axis=1))
    if len(touched) == 0:
        return
    k = cells.shape[1]
    R = np.zeros((len(touched), k, 2, k, 2))
    R[:, np.arange(k), :, np.arange(k), :] = np.eye(2)
    local = frame_of[cells[touched]]  # (t, k)
    which, corner = np.nonzero(local >= 0)
    R[which, corner, :, corner, :] = frames[local[which, corner]]
    R = R.reshape(len(touched), 2 * k, 2 * k)
    matrices[touched] = np.matmul(np.matmul(R, matrices[touched]), R.transpose(0, 2, 1))


def rotate_vector(vector: np.ndarray, nodes: np.ndarray, frames: np.ndarray, transpose: bool = False) -> np.ndarray:
    """A copy of the dof vector with the pairs of ``nodes`` multiplied by their frames (or the transposes)."""
    out = np.array(vector, dtype=np.float64)
    pairs = out.reshape(-1, 2)
    pairs[nodes] = np.einsum("nba,na->nb" if not transpose else "nab,na->nb", frames, pairs[nodes])
    return out


def to_global(values: np.ndarray, nodes: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """Nodal vectors ``(n, 2)`` with the rows of ``nodes`` back from their local frames to (x, y)."""
    return rotate_vector(values.reshape(-1), nodes, frames, transpose=True).reshape(-1, 2)


# --- boundary loads -----------------------------------------------------------------------------------
#: Gauss points per edge for a load that is not a polynomial, or on a curved edge.
HIGH_ORDER_POINTS = 10


def boundary_load(points: np.ndarray, edges: np.ndarray, load: Load) -> np.ndarray:
    """Consistent load ∫ t·φ ds over ``edges`` (oriented counter-clockwise), t the traction vector or
    −pressure × the outward normal; exact for polynomials on straight edges, high order otherwise."""
    out = np.zeros(2 * len(points))
    if len(edges) == 0:
        return out
    parts = [load.pressure] if load.pressure is not None else [load.x, load.y]
    degrees = [part.degree for part in parts if part is not None]
    straight = edges.shape[1] == 2 or np.allclose(
        points[edges[:, 2]], 0.5 * (points[edges[:, 0]] + points[edges[:, 1]]),
        rtol=0.0, atol=1e-12 * np.ptp(points, axis=0).max())
    if straight and None not in degrees:
        count = max((max(degrees, default=0) + edges.shape[1]) // 2 + 1, 2)
    else:
        count = HIGH_ORDER_POINTS
    s, w = gauss_interval(count)
    shapes, _ = edge_shapes(edges.shape[1], s)
    position, tangent = edge_points(points, edges, s)  # (e, q, 2)
    x, y = position[..., 0], position[..., 1]
    if load.pressure is not None:
        outward = np.stack([tangent[..., 1], -tangent[..., 0]], axis=-1)  # |tangent| is the ds factor
        traction = -load.pressure(x, y)[..., None] * outward
    else:
        speed = np.linalg.norm(tangent, axis=2)
        traction = np.stack([(part(x, y) if part is not None else np.zeros_like(x)) * speed
                             for part in (load.x, load.y)], axis=-1)
    if not np.all(np.isfinite(traction)):
        bad = np.argwhere(~np.all(np.isfinite(traction), axis=-1))[0]
        raise SceneError(f"{load.key}: the load is not finite at (x, y) = ({x[tuple(bad)]:.6g}, {y[tuple(bad)]:.6g})")
    nodal = np.einsum("eqc,q,qk->ekc", traction, w, shapes)  # (e, k, 2)
    for component in (0, 1):
        out += np.bincount(2 * edges.ravel() + component, nodal[..., component].ravel(), minlength=len(out))
    return out


#: A load is checked at LOAD_SAMPLES points of each edge (endpoints included) and at the quadrature points;
#: a part that is not a polynomial is then sampled CLOSING_STEPS times ever closer (4 times each step) to
#: each edge's largest value, to 1e-21 of the edge, below the resolution of doubles at the box's size.
#: Growing by more than GROWTH over GROWTH_STEPS steps (a distance 4^6 times smaller) once the samples are
#: closer than 1e-10 of the edge (FINE_STEP), where a bounded load has long stopped growing, it is singular.
LOAD_SAMPLES = 33
CLOSING_STEPS = 32
FINE_STEP = 14
GROWTH_STEPS = 6
GROWTH = 2.0


def load_extent(points: np.ndarray, edges: np.ndarray, load: Load | Displacement) -> float:
    """The largest |value| of the parts of ``load`` (a load or a prescribed displacement) along ``edges``,
    sampled densely; a SceneError naming the part's key if a value is not finite or grows without bound (a
    singular load, whose integral would depend on the mesh, as would the solution)."""
    largest = 0.0
    if len(edges) == 0:
        return largest
    start = np.concatenate([np.linspace(0.0, 1.0, LOAD_SAMPLES), gauss_interval(HIGH_ORDER_POINTS)[0]])
    offsets = np.linspace(-1.0, 1.0, 9)[:, None]  # 0 among them: each step keeps the best point so far
    noun = "displacement" if isinstance(load, Displacement) else "load"
    for component in ("x", "y", "pressure", "normal"):
        part = getattr(load, component, None)
        if part is None:
            continue
        key = f"{load.key}.{component}"

        def sample(at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            values, position = _sampled(points, edges, part, at[..., 0], key, noun)
            return values, position, values

        at = np.broadcast_to(start[:, None], (len(edges), len(start), 1))
        growth = _closing_in(sample, at, lambda center, width: np.clip(center[:, None] + width * offsets, 0.0, 1.0),
                             1.0 / (LOAD_SAMPLES - 1), part.degree is None)
        if growth.unbounded is not None:
            x, y = growth.unbounded
            raise SceneError(f"{key}: the {noun} grows without bound towards (x, y) = ({x:.6g}, {y:.6g}) (to "
                             f"{growth.largest:.3g} and still growing as the samples close in): it is singular "
                             f"on its boundary, so its {'integral' if noun == 'load' else 'nodal values'} and the "
                             "solution would depend on the mesh; move the singularity off the boundary")
        largest = max(largest, growth.largest)
    return largest


@dataclass(frozen=True)
class Growth:
    """What closing in on a field's largest values found: the largest |value| seen, and where the values still
    grow without bound (None: bounded)."""

    largest: float
    unbounded: tuple[float, float] | None


def _closing_in(sample, at: np.ndarray, around, width: float, search: bool) -> Growth:
    """Sample a field at the parameters ``at`` ``(e, q, d)`` of e pieces: ``sample(at)`` -> (|values| ``(e, q)``,
    positions ``(e, q, 2)``, and the steering values ``(e, q)``, by default |values|).  If ``search`` (the field
    is not a polynomial), close in CLOSING_STEPS times on each piece's largest steering value, ``around(center
    (e, d), width)`` giving the next parameters, ``width`` shrinking 4 times a step.  Growing by more than GROWTH
    over GROWTH_STEPS steps once the samples are within 1e-10 of the piece (FINE_STEP), where a bounded field
    has long stopped growing, the field is singular there."""
    values, position, steer = sample(at)
    record = [values.max(axis=1)]
    if not search:
        return Growth(float(np.max(record)), None)
    for _ in range(CLOSING_STEPS):
        center = at[np.arange(len(at)), np.argmax(steer, axis=1)]
        at = around(center, width)
        values, position, steer = sample(at)
        record.append(values.max(axis=1))
        width /= 4.0
    fine = np.array(record[FINE_STEP - GROWTH_STEPS:])
    growing = np.flatnonzero((fine[GROWTH_STEPS:] > GROWTH * fine[:-GROWTH_STEPS]).any(axis=0))
    if not len(growing):
        return Growth(float(np.max(record)), None)
    piece = growing[np.argmax(record[-1][growing])]
    x, y = position[piece, np.argmax(values[piece])]
    return Growth(float(record[-1][piece]), (float(x), float(y)))


def _sampled(points: np.ndarray, edges: np.ndarray, part, at: np.ndarray, key: str, noun: str = "load"
             ) -> tuple[np.ndarray, np.ndarray]:
    """|part| at the parameters ``at`` ``(e, q)`` of each edge, and the positions ``(e, q, 2)``; a SceneError
    naming ``key`` if a value is not finite."""
    shapes, _ = edge_shapes(edges.shape[1], at.ravel())
    position = np.einsum("eqk,ekd->eqd", shapes.reshape(*at.shape, -1), points[edges])
    return _finite(part, position, key, f"the {noun} is not finite at (x, y) = ({{:.6g}}, {{:.6g}}); change the "
                   f"expression or the boundary it acts on")


def _finite(part: Expression, position: np.ndarray, key: str, message: str) -> tuple[np.ndarray, np.ndarray]:
    """(|part| at ``position`` ``(..., 2)``, ``position``); a SceneError ``key: message`` (formatted with the
    first point where the value is not finite) otherwise."""
    values = np.abs(part(position[..., 0], position[..., 1]))
    if not np.all(np.isfinite(values)):
        x, y = position[tuple(np.argwhere(~np.isfinite(values))[0])]
        raise SceneError(f"{key}: " + message.format(x, y))
    return values, position


#: A field over the cells (a temperature change) is sampled at the points of a lattice of this order in each
#: cell and at the quadrature points; where it is not a polynomial, the closing-in search runs in the
#: CANDIDATES cells where it is largest, and for each of its divisors (:func:`ddsolve.problem.expressions.divisors`)
#: in the CANDIDATES cells nearest the divisor's zeros, the only places it can grow without bound.
LATTICE = 4
CANDIDATES = 16
#: Cells sampled at once (bounded memory on large meshes).
SAMPLED_CELLS = 2 ** 14


def field_extent(points: np.ndarray, cells: np.ndarray, field: Expression, key: str) -> float:
    """The largest |field| over ``cells``, sampled densely; a SceneError naming ``key`` if a value is not finite
    or the field grows without bound inside a cell (its integrals, and the solution, would depend on the mesh).
    A field that is not a polynomial is closed in on where it is largest and on the zeros of each of its
    divisors, where it may have a pole hidden by larger values elsewhere."""
    if len(cells) == 0:
        return 0.0
    if field.constant:
        return float(_finite(field, points[cells[:1, :1]], key, _NOT_FINITE)[0].max())
    lattice = np.array([(i, j) for i in range(LATTICE + 1) for j in range(LATTICE + 1 - i)], float) / LATTICE
    start = np.vstack([lattice, TRIANGLE_RULES[6][0]])
    steering = [None, *expressions.divisors(field)] if field.degree is None else [None]
    largest = [np.zeros(len(cells)) for _ in steering]  # per cell: |field|, then −|divisor| (nearest its zero)
    for first in range(0, len(cells), SAMPLED_CELLS):
        chunk = slice(first, first + SAMPLED_CELLS)
        values, position, _ = _cell_sample(points, cells[chunk], field, key)(start)
        largest[0][chunk] = values.max(axis=1)
        for index, divisor in enumerate(steering[1:], 1):
            largest[index][chunk] = -np.abs(divisor(position[..., 0], position[..., 1])).min(axis=1)
    extent = float(largest[0].max())
    offsets = np.stack(np.meshgrid(np.linspace(-1.0, 1.0, 9), np.linspace(-1.0, 1.0, 9)), axis=-1).reshape(-1, 2)
    for steer, ranking in zip(steering if field.degree is None else [], largest):
        chosen = np.argsort(-np.nan_to_num(ranking, nan=np.inf))[:CANDIDATES]
        growth = _closing_in(_cell_sample(points, cells[chosen], field, key, steer),
                             np.broadcast_to(start, (len(chosen), *start.shape)),
                             lambda center, width: _in_triangle(center[:, None] + width * offsets), 1.0 / LATTICE, True)
        if growth.unbounded is not None:
            x, y = growth.unbounded
            raise SceneError(f"{key}: the temperature change grows without bound towards (x, y) = ({x:.6g}, "
                             f"{y:.6g}) (to {growth.largest:.3g} and still growing as the samples close in): it is "
                             "singular inside the layer, so its load and energy, and the solution, would depend on "
                             "the mesh; move the singularity out of the layer")
        extent = max(extent, growth.largest)
    return extent


def _cell_sample(points: np.ndarray, cells: np.ndarray, field: Expression, key: str,
                 steer: Expression | None = None):
    """A sampler for :func:`_closing_in` of |field| in ``cells`` (a SceneError naming ``key`` where it is not
    finite), steered towards its largest values, or towards the zeros of ``steer``."""
    def sample(at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        position = _cell_positions(points, cells, at)
        values, _ = _finite(field, position, key, _NOT_FINITE)
        if steer is None:
            return values, position, values
        return values, position, -np.nan_to_num(np.abs(steer(position[..., 0], position[..., 1])), nan=np.inf)
    return sample


_NOT_FINITE = "the temperature change is not finite at (x, y) = ({:.6g}, {:.6g}); change the expression"


def _cell_positions(points: np.ndarray, cells: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The points ``(m, q, 2)`` at the reference coordinates ``at`` of each cell: ``(m, q, 2)``, or ``(q, 2)``
    the same in every cell."""
    shapes, _ = shape_functions(cells.shape[1], at.reshape(-1, 2))
    if at.ndim == 2:
        return np.einsum("qk,mkd->mqd", shapes, points[cells])
    return np.einsum("mqk,mkd->mqd", shapes.reshape(*at.shape[:2], -1), points[cells])


def _in_triangle(at: np.ndarray) -> np.ndarray:
    """Reference coordinates ``(..., 2)`` moved into the reference triangle (s, t ≥ 0, s + t ≤ 1)."""
    at = np.maximum(at, 0.0)
    total = at.sum(axis=-1, keepdims=True)
    return np.where(total > 1.0, at / np.maximum(total, 1.0), at)


# --- block systems ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BlockSystem:
    """One block's linear system K x = rhs (+ interface loads on ``trace_dofs``), or the rows
    ``first … first + len(rhs) − 1`` of it when the block is distributed.

    Clamped dofs are decoupled: their rows and columns are empty except for the diagonal entry, and
    their right-hand side is zero.  ``indptr``, ``indices``, ``data`` are the CSR arrays of the local
    rows with global columns.  ``trace_dofs`` are the dofs of the multiplier nodes, in Σ order, in
    their local frames; ``modes`` are the rigid-body motions of the local rows (for algebraic multigrid).
    ``energy_offset`` is what Π = ½ a(u, u) − L(u) adds to ½ xᵀKx − xᵀrhs of the decoupled, lifted system
    at its solution (a constant; the local rows' share, so the shares of a distributed block sum to it):
    with g the prescribed values and f the loads, ½ g_P·(K g)_P + ½ Σ K_ii g_i² − f_P·g_P, and with a
    thermal load ½ ∫ ε₀ᵀ D ε₀, so that Π is the mechanical energy ½ ∫ (ε − ε₀)ᵀ D (ε − ε₀) minus the
    work of the tractions.
    """

    name: str
    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray
    rhs: np.ndarray
    trace_dofs: np.ndarray
    size: int  # global number of dofs
    first: int = 0
    modes: np.ndarray | None = None  # (3, local dofs)
    block_size: int = 2
    energy_offset: float = 0.0


def row_ranges(nodes: int, parts: int) -> list[tuple[int, int]]:
    """Split a block's dofs into ``parts`` contiguous ranges of whole nodes (as PETSc would)."""
    bounds = np.linspace(0, nodes, parts + 1).round().astype(int)
    return [(2 * a, 2 * b) for a, b in zip(bounds[:-1], bounds[1:])]


def trace_nodes(half: HalfMesh, sigma: SigmaLine) -> np.ndarray:
    """Nodes of ``half`` that carry the trace: the multiplier nodes, in Σ order."""
    return half.sigma[sigma.multiplier_nodes]


@dataclass(frozen=True, eq=False)
class Pattern:
    """The CSR structure shared by the blocks of one half (or by their rows ``first … last − 1``) and
    where every entry of every element matrix goes in it.

    Clamped dofs are decoupled: the pattern keeps only their node's own 2×2 block (its off-diagonal
    entries stay zero).  ``entries`` ``(m, k, k)`` holds the node entry (a 2×2 block of the CSR) of each
    pair of nodes of ``cells`` (the cells touching the rows), the last one where it is dropped; node
    entry e puts its columns 2c, 2c + 1 at ``opening[0][e]`` in the pair's first dof row and at
    ``opening[1][e]`` in its second (``len(indices)`` for the dropped).  :meth:`positions` expands them for a
    slice of cells.
    """

    indptr: np.ndarray
    indices: np.ndarray
    cells: np.ndarray
    entries: np.ndarray
    opening: tuple[np.ndarray, np.ndarray]
    clamped: np.ndarray
    first: int
    last: int

    def positions(self, cells: slice) -> np.ndarray:
        """``(c, 2k, 2k)``: the CSR index of each element-matrix entry of ``cells`` (a slice of :attr:`cells`),
        ``len(indices)`` or the next for entries that are dropped."""
        entries = self.entries[cells]
        m, k = entries.shape[:2]
        positions = np.empty((m, k, 2, k, 2), dtype=self.indices.dtype)  # (c, α, i, β, j)
        for i, opening in enumerate(self.opening):
            positions[:, :, i, :, 0] = opening[entries]
            positions[:, :, i, :, 1] = positions[:, :, i, :, 0] + 1
        cell, corner = np.nonzero(self.clamped[self.cells[cells]])  # a clamped node keeps its own diagonal only
        positions[cell, corner, 0, corner, 1] = positions[cell, corner, 1, corner, 0] = len(self.indices)
        return positions.reshape(m, 2 * k, 2 * k)

    def add(self, data: np.ndarray, matrices: np.ndarray, cells: slice = slice(None)) -> None:
        """Add the element matrices ``(c, 2k, 2k)`` of ``cells`` (a slice of :attr:`cells`) to the CSR values
        ``data`` by one compiled pass over the range of values they touch."""
        where = self.positions(cells).ravel()
        kept = where < len(data)
        if not kept.any():
            return
        low, high = int(where.min()), int(where.max(where=kept, initial=-1)) + 1
        summed = np.bincount(np.minimum(where, high) - low, matrices.ravel(), minlength=high - low + 1)
        data[low:high] += summed[:high - low]


#: Element-matrix entries computed at once (32 MB of them): assembly's memory does not grow with the mesh.
ELEMENT_ENTRIES = 2 ** 22


def pattern(half: HalfMesh, rows: tuple[int, int] | None = None) -> Pattern:
    """The sparsity pattern of the half's blocks (or their ``rows``) from its node graph: one sort of the
    cells' node pairs gives the graph's edges, which lie in their rows in order (row a: the edges (c, a),
    c < a, by c; the diagonal; the edges (a, c), c > a, by c); expanded to 2×2 dof blocks."""
    n_nodes = len(half.points)
    first, last = rows if rows is not None else (0, 2 * n_nodes)
    first_node, last_node = first // 2, last // 2
    cells = half.cells
    if rows is not None:
        owned = np.zeros(n_nodes, dtype=bool)
        owned[first_node:last_node] = True
        cells = cells[owned[cells].any(axis=1)]
    m, k = cells.shape
    clamped = np.zeros(n_nodes, dtype=bool)
    clamped[half.clamped()] = True
    alpha, beta = np.triu_indices(k, 1)  # the cell's node pairs α < β
    a, b = cells[:, alpha], cells[:, beta]
    keep = ~(clamped[a] | clamped[b])  # a clamped node keeps its own 2×2 block only
    low, high = np.minimum(a, b)[keep].astype(np.int64), np.maximum(a, b)[keep]
    edges, edge_of = np.unique(low * n_nodes + high, return_inverse=True)
    del low, high
    low, high = edges // n_nodes, edges % n_nodes  # sorted by (low, high)
    below, above = np.bincount(high, minlength=n_nodes), np.bincount(low, minlength=n_nodes)
    per_row = (below + 1 + above)[first_node:last_node]  # node entries per row
    row_start = np.zeros(n_nodes + 1, dtype=np.int64)  # node entry of each row's first, rows in range
    row_start[first_node + 1:last_node + 1] = np.cumsum(per_row)
    row_start[last_node + 1:] = row_start[last_node]
    first_above = np.concatenate([[0], np.cumsum(above)])
    by_high = np.argsort(high, kind="stable")  # the entries (high, low) in their rows' order
    first_below = np.concatenate([[0], np.cumsum(below)])
    in_range = lambda r: (r >= first_node) & (r < last_node)  # noqa: E731
    upper = np.where(in_range(low), row_start[low] + below[low] + 1 + np.arange(len(edges)) - first_above[low], -1)
    lower = np.empty(len(edges), dtype=np.int64)
    lower[by_high] = np.arange(len(edges)) - first_below[high[by_high]]
    lower = np.where(in_range(high), row_start[high] + lower, -1)
    count = int(row_start[last_node])  # node entries of the rows
    itype = index_type(max(2 * n_nodes, 4 * count + 2))
    # Node entry e of node row r (from the range's first) has its columns 2c, 2c + 1 in dof row 2r at dof
    # entry 2e + 2·row_start(r) (the row opens at 4·row_start(r)); dof row 2r + 1 holds them 2·per_row(r) later.
    shift = 2 * row_start[first_node:last_node].astype(itype)
    row = np.repeat(np.arange(last_node - first_node, dtype=itype), per_row)
    first_entry = 2 * np.arange(count, dtype=itype) + shift[row]
    second_entry = first_entry + (2 * per_row.astype(itype))[row]
    del row
    column = np.empty(count, dtype=itype)
    mine = upper >= 0
    column[upper[mine]] = high[mine]
    mine = lower >= 0
    column[lower[mine]] = low[mine]
    nodes = np.arange(first_node, last_node)
    column[row_start[nodes] + below[nodes]] = nodes  # the diagonal
    indptr = np.zeros(2 * (last_node - first_node) + 1, dtype=itype)
    indptr[1::2], indptr[2::2] = 2 * shift + 2 * per_row, 2 * shift + 4 * per_row
    indices = np.empty(4 * count, dtype=itype)
    for at in (first_entry, second_entry):
        indices[at], indices[at + 1] = 2 * column, 2 * column + 1
    del column
    # the node entry of every element entry (α, β), or ``count`` (the dropped entries' row of the opening)
    entry = np.empty((m, k, k), dtype=itype)
    local = np.where(in_range(cells), cells, first_node)
    entry[:, np.arange(k), np.arange(k)] = np.where(in_range(cells), row_start[local] + below[local], count)
    del local
    upper, lower = upper[edge_of], lower[edge_of]
    ascending = (a < b)[keep]
    upper[upper < 0], lower[lower < 0] = count, count
    forward = np.full(a.shape, count, dtype=itype)  # entry (α, β), α < β: row a
    backward = np.full(a.shape, count, dtype=itype)  # entry (β, α): row b
    forward[keep] = np.where(ascending, upper, lower)
    backward[keep] = np.where(ascending, lower, upper)
    entry[:, alpha, beta], entry[:, beta, alpha] = forward, backward
    opening = tuple(np.append(at, len(indices)).astype(itype) for at in (first_entry, second_entry))
    return Pattern(indptr, indices, cells, entry, opening, clamped, first, last)


def block_system(name: str, half: HalfMesh, sigma: SigmaLine, D: np.ndarray, loads: list[Load],
                 rows: tuple[int, int] | None = None, shared: Pattern | None = None,
                 prescribed: tuple[np.ndarray, np.ndarray] | None = None,
                 thermal: tuple[np.ndarray, Expression] | None = None) -> BlockSystem:
    """Assemble a block (or its ``rows``): stiffness with prescribed dofs decoupled, the loads on the
    half's named boundaries, Σ dofs in local frames.  ``shared``: the half's :func:`pattern` for
    these rows, when another block of the half has made it.  ``prescribed``: (fixed, values) ``(n, 2)``
    in the dof frames (:func:`ddsolve.fem.supports.block_supports`; default: Γ_D, zero); nonzero values
    are lifted, rhs = f − K g, and a prescribed dof's row reads K_ii x_i = K_ii g_i.  ``thermal``: the
    layer's eigenstrain per unit temperature and the temperature change, whose load ∫ Bᵀ D ε₀ is added.
    Both shift the potential energy by a constant: :attr:`BlockSystem.energy_offset`."""
    n = 2 * len(half.points)
    structure = shared if shared is not None else pattern(half, rows)
    first, last = structure.first, structure.last
    nodes = trace_nodes(half, sigma)
    frames = sigma.frames[sigma.multiplier_nodes]
    rotated = not np.allclose(frames, np.eye(2), rtol=0.0, atol=0.0)
    if prescribed is None:
        fixed = np.zeros((len(half.points), 2), dtype=bool)
        fixed[half.clamped()] = True
        prescribed = (fixed, np.zeros((len(half.points), 2)))
    fixed, values = prescribed[0].reshape(-1), prescribed[1].reshape(-1)
    lifted = bool(np.any(values[fixed] != 0.0))
    data, lift, diagonal = np.zeros(len(structure.indices)), np.zeros(n), np.zeros(n)
    step = max(1, ELEMENT_ENTRIES // (2 * structure.cells.shape[1]) ** 2)
    for start in range(0, len(structure.cells), step):  # element matrices a slice at a time: bounded memory
        cells = slice(start, start + step)
        matrices = element_stiffness(half.points, structure.cells[cells], D)
        if rotated:
            rotate_elements(matrices, structure.cells[cells], nodes, frames, len(half.points))
        dofs = element_dofs(structure.cells[cells])
        if lifted:
            lift += np.bincount(dofs.ravel(), np.einsum("mij,mj->mi", matrices, np.where(fixed[dofs], values[dofs],
                                                                                          0.0)).ravel(), minlength=n)
        each = np.arange(dofs.shape[1])
        own = matrices[:, each, each]
        diagonal += np.bincount(dofs.ravel(), own.ravel(), minlength=n)
        held = fixed[dofs]  # a prescribed dof keeps its diagonal entry only
        matrices[held] = 0.0
        matrices.transpose(0, 2, 1)[held] = 0.0
        matrices[:, each, each] = own
        structure.add(data, matrices, cells)
    del matrices
    rhs = np.zeros(n)
    for load in loads:
        rhs += boundary_load(half.points, half.edges(load.boundary), load)
    offset = 0.0
    if thermal is not None:
        rhs += thermal_load(half.points, structure.cells, D, *thermal)
        owned = (structure.cells[:, 0] >= first // 2) & (structure.cells[:, 0] < last // 2)  # each cell once
        offset += thermal_energy(half.points, structure.cells[owned], D, *thermal)
    if rotated:
        rhs = rotate_vector(rhs, nodes, frames)
    if lifted:
        held = np.flatnonzero(fixed[first:last]) + first
        g = values[held]
        offset += float(g @ (0.5 * lift[held] + 0.5 * diagonal[held] * g - rhs[held]))
    rhs -= lift
    rhs[fixed] = diagonal[fixed] * values[fixed]
    modes = rigid_body_modes(half.points[first // 2:last // 2], centre=half.points.mean(axis=0))
    if rotated:
        mine = (nodes >= first // 2) & (nodes < last // 2)
        modes = np.array([rotate_vector(mode, nodes[mine] - first // 2, frames[mine]) for mode in modes])
    return BlockSystem(name, structure.indptr, structure.indices, data, rhs[first:last],
                       element_dofs(nodes[:, None]).ravel(), n, first, modes, energy_offset=offset)


def thermal_load(points: np.ndarray, cells: np.ndarray, D: np.ndarray, eigenstrain: np.ndarray,
                 temperature: Expression) -> np.ndarray:
    """∫ Bᵀ D ε₀ over ``cells`` as a dof vector ``(2n,)`` (x, y), ε₀ = ``eigenstrain`` × ΔT(x, y)."""
    xi, weights = TRIANGLE_RULES[6]  # exact to degree 4
    det, gradients = element_geometry(points, cells, xi)
    change = cell_temperatures(points, cells, temperature, xi)
    force = np.einsum("mq,q,mqja,j->ma", det * change, weights, strain_operator(gradients), D @ eigenstrain)
    return np.bincount(element_dofs(cells).ravel(), force.ravel(), minlength=2 * len(points))


def thermal_energy(points: np.ndarray, cells: np.ndarray, D: np.ndarray, eigenstrain: np.ndarray,
                   temperature: Expression) -> float:
    """½ ∫ ε₀ᵀ D ε₀ over ``cells``, ε₀ = ``eigenstrain`` × ΔT(x, y), with the quadrature of :func:`thermal_load`."""
    xi, weights = TRIANGLE_RULES[6]
    det, _ = element_geometry(points, cells, xi)
    change = cell_temperatures(points, cells, temperature, xi)
    return 0.5 * float(np.einsum("mq,q->", det * change ** 2, weights)) * float(eigenstrain @ D @ eigenstrain)


def cell_temperatures(points: np.ndarray, cells: np.ndarray, temperature: Expression, xi: np.ndarray) -> np.ndarray:
    """ΔT ``(m, q)`` at the reference points ``xi`` of every cell; a SceneError if it is not finite."""
    shapes, _ = shape_functions(cells.shape[1], xi)
    position = np.einsum("qk,mkd->mqd", shapes, points[cells])
    change = np.broadcast_to(np.asarray(temperature(position[..., 0], position[..., 1]), dtype=np.float64),
                             position.shape[:2])
    if not np.all(np.isfinite(change)):
        x, y = position[tuple(np.argwhere(~np.isfinite(change))[0])]
        raise SceneError(f"temperature: the temperature change is not finite at (x, y) = ({x:.6g}, {y:.6g})")
    return change


def thermal_of(scene: Scene, layer: str) -> tuple[np.ndarray, Expression] | None:
    """(eigenstrain per unit ΔT, ΔT) of a layer, or None when it has no temperature change or expansion."""
    if layer not in scene.temperature:
        return None
    strain, _ = materials.thermal_strain(scene.materials[layer], scene.model)
    return (strain, scene.temperature[layer]) if np.any(strain != 0.0) else None


def rigid_body_modes(points: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
    """``(3, 2n)``: the translations in x and y and the rotation about ``centre`` (default: the centroid)."""
    centred = points - (points.mean(axis=0) if centre is None else centre)
    modes = np.zeros((3, len(points), 2))
    modes[0, :, 0] = 1.0
    modes[1, :, 1] = 1.0
    modes[2, :, 0], modes[2, :, 1] = -centred[:, 1], centred[:, 0]
    return modes.reshape(3, -1)


def modulus(scene: Scene) -> float:
    """The largest entry of the layers' elastic matrices: the scale of the stress a strain makes."""
    return max(float(np.abs(elasticity(scene, layer)[0]).max()) for layer in LAYERS)


def elasticity(scene: Scene, layer: str) -> tuple[np.ndarray, np.ndarray]:
    """(D, c) of a layer under the scene's plane model (see :func:`ddsolve.problem.materials.elasticity`)."""
    return materials.elasticity(scene.materials[layer], scene.model)


def layer_loads(scene: Scene, layer: str, half: HalfMesh) -> list[Load]:
    """The scene's loads on ``layer`` whose boundary this half has."""
    return [load for (name, _), load in scene.loads.items() if name == layer and load.boundary in half.boundaries]


def block_systems(scene: Scene, mesh: Mesh, which: list[int] | None = None,
                  rows: tuple[int, int] | None = None, table: supports.SigmaSupports | None = None
                  ) -> list[BlockSystem]:
    """Assemble the scene's blocks with indices in ``which`` (all four by default), or their ``rows``;
    ``table``: the Σ supports (:func:`ddsolve.fem.supports.sigma_supports`; made from ``mesh``, which
    must then be whole, if not given)."""
    systems, patterns = [], {}
    if table is None:
        table = supports.sigma_supports(scene, mesh)
    for index in range(len(BLOCKS)) if which is None else which:
        spec = BLOCKS[index]
        half = mesh.half(spec.side)
        D, _ = elasticity(scene, spec.layer)
        if spec.side not in patterns:
            patterns[spec.side] = pattern(half, rows)
        prescribed = supports.block_supports(scene, half, mesh.sigma, spec.layer, index, table)
        systems.append(block_system(spec.name, half, mesh.sigma, D, layer_loads(scene, spec.layer, half), rows,
                                    patterns[spec.side], prescribed, thermal_of(scene, spec.layer)))
    return systems


def renumbered(system: BlockSystem, nodes: np.ndarray, count: int) -> BlockSystem:
    """A system assembled on a piece of a half (:mod:`ddsolve.mesh.pieces`) in the numbers of the half: the
    piece's node i is the half's ``nodes[i]`` (ascending, so each row's columns stay in order), the half has
    ``count`` nodes."""
    def dofs(local: np.ndarray) -> np.ndarray:
        return 2 * nodes[local // 2] + local % 2

    return dataclasses.replace(system, indices=dofs(system.indices).astype(index_type(2 * count), copy=False),
                               trace_dofs=dofs(system.trace_dofs), size=2 * count,
                               first=int(dofs(np.array([system.first]))[0]))


def csr_matvec(system: BlockSystem, x: np.ndarray) -> np.ndarray:
    """K x for a block system's CSR matrix."""
    rows = np.repeat(np.arange(system.size), np.diff(system.indptr))
    return np.bincount(rows, system.data * x[system.indices], minlength=system.size)


# --- fields of a solution ---------------------------------------------------------------------------
def voigt_strain(grad_u: np.ndarray) -> np.ndarray:
    """(εxx, εyy, γxy) ``(..., 3)`` from the displacement gradient ``(..., 2, 2)`` (u_d,e)."""
    return np.stack([grad_u[..., 0, 0], grad_u[..., 1, 1], grad_u[..., 0, 1] + grad_u[..., 1, 0]], axis=-1)


def quadrature_strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray, rule: tuple | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """det J × weight ``(m, q)`` and the strain ``(m, q, 3)`` of the field u ``(n, 2)`` at the points of
    ``rule`` (reference points, weights; the element's by default)."""
    xi, weights = TRIANGLE_RULES[cells.shape[1]] if rule is None else rule
    det, gradients = element_geometry(points, cells, xi)
    return det * weights, voigt_strain(field_gradients(u[cells], gradients))


def quadrature_fields(scene: Scene, layer: str, points: np.ndarray, cells: np.ndarray, u: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`quadrature_strains` of ``layer``'s field u ``(n, 2)`` and its ΔT ``(m, q)`` at the same points:
    the element rule's (ΔT zero) without a thermal load, else the rule of :func:`thermal_load` and
    :func:`thermal_energy`."""
    thermal = thermal_of(scene, layer)
    if thermal is None:
        volume, strain = quadrature_strains(points, cells, u)
        return volume, strain, np.zeros(volume.shape)
    rule = TRIANGLE_RULES[6]
    return (*quadrature_strains(points, cells, u, rule), cell_temperatures(points, cells, thermal[1], rule[0]))


def cell_means(volume: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: area ``(m,)`` and the mean of ``values`` ``(m, q, c)`` given at the rule's points with
    their ``volume`` ``(m, q)`` (det J × weight)."""
    area = volume.sum(axis=1)
    return area, np.einsum("mq,mqi->mi", volume, values) / area[:, None]


def integrated_energies(volume: np.ndarray, strain: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Per cell ∫ εᵀ D ε from the strains ``(m, q, 3)`` at the rule's points with their ``volume``."""
    return np.einsum("mq,mqi->m", volume, (strain @ D) * strain)


def cell_strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: area ``(m,)`` and mean strain (εxx, εyy, γxy) ``(m, 3)`` of the field u ``(n, 2)``."""
    return cell_means(*quadrature_strains(points, cells, u))


def energy(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray) -> float:
    """uᵀ K u = ∫ ε(u)ᵀ D ε(u) for the unconstrained stiffness K of this mesh."""
    return float(cell_energies(points, cells, D, u).sum())


def cell_energies(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per cell ∫ ε(u)ᵀ D ε(u) (twice the strain energy of the cell)."""
    return integrated_energies(*quadrature_strains(points, cells, u), D)


def cell_stresses(D: np.ndarray, c: np.ndarray, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(σxx, σyy, σxy) ``(m, 3)`` and σzz ``(m,)`` from strains ``(m, 3)``."""
    return strain @ D.T, strain @ c


def von_mises(points: np.ndarray, cells: np.ndarray, D: np.ndarray, c: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per-cell von Mises stress of the mean strain (σzz from the plane model included)."""
    _, strain = cell_strains(points, cells, u)
    return materials.von_mises(*cell_stresses(D, c, strain))


# ---------------------------------------------------------------------------------------------
#: Stiffnesses (the largest entry of a layer's elastic matrix) whose element matrices stay normal
#: double-precision numbers on any sensible mesh.
STIFFNESS_RANGE = (1e-280, 1e280)


#: Displacements whose squares (norms, energies) stay far inside double precision.
DISPLACEMENT_RANGE = (1e-100, 1e100)


#: Energies (stiffness × displacement², the scale of the blocks' forces × displacements) that stay normal
#: double-precision numbers with room for the sums over a mesh.
ENERGY_RANGE = (1e-290, 1e290)


def check_range(scene: Scene, mesh) -> None:
    """Refuse moduli, loads, prescribed displacements and thermal eigenstrains a double-precision solve cannot
    represent, naming their keys.

    Each layer's stiffness is the largest entry of its elastic matrix; the structure's displacements (the layers
    are glued) are of the order of the largest of what drives them (:func:`driven_displacements`): (largest
    traction on a layer) × (size of the mesh) / its stiffness, the largest prescribed value, (largest eigenstrain
    αΔT) × (size of the mesh).  Blocks are scaled to order one (:class:`ddsolve.parallel.blocks.Block`), so only
    the ranges matter: stiffnesses within STIFFNESS_RANGE, displacements within DISPLACEMENT_RANGE (their
    squares must not overflow) and the energy stiffness × displacement² within ENERGY_RANGE.  A load, a
    displacement or a temperature change that is not finite or singular is refused first (:func:`load_extent`,
    :func:`field_extent`).
    """
    size = float(np.ptp(np.vstack([half.points for half in mesh.halves]), axis=0).max())
    driven, stiffest = [], (0.0, "")
    for layer in LAYERS:
        key = f"materials.{layer}" + (".E" if isinstance(scene.materials[layer], materials.Isotropic) else "")
        with np.errstate(all="ignore"):
            D, _ = materials.elasticity(scene.materials[layer], scene.model)
        stiffness = float(np.abs(D).max())
        low, high = STIFFNESS_RANGE
        if not low <= stiffness <= high:
            raise SceneError(f"{key}: the elastic matrix has entries of {stiffness:.3g}, outside the range a "
                             f"double-precision solve represents ({low:g} to {high:g}): change the unit of stress")
        driven += driven_displacements(scene, mesh, layer, size, key, stiffness)
        stiffest = max(stiffest, (stiffness, key))
    if not driven:
        return
    displacement, cause, message = max(driven, key=lambda item: item[0])
    if not DISPLACEMENT_RANGE[0] <= displacement <= DISPLACEMENT_RANGE[1]:
        raise SceneError(message)
    stiffness, key = stiffest
    energy = stiffness * displacement * displacement  # also the force scale K g squared over K
    low, high = ENERGY_RANGE
    if not low <= energy <= high:
        raise SceneError(f"{key}: the elastic matrix (largest entry {stiffness:.3g}) with displacements of order "
                         f"{displacement:.1g} ({cause} drives them) gives energies of order {energy:.1g}, outside "
                         f"the range a double-precision solve represents ({low:g} to {high:g}): change the units "
                         "of the moduli and of what drives the displacements")


def driven_displacements(scene: Scene, mesh, layer: str, size: float, key: str, stiffness: float
                         ) -> list[tuple[float, str, str]]:
    """The orders of the displacements of ``layer`` (whose elastic matrix ``key`` has the largest entry
    ``stiffness``, on a mesh of ``size``) that each of its loads, prescribed displacements and its eigenstrain
    makes, each with the keys that make it and the message that refuses it outside DISPLACEMENT_RANGE; those
    driven by zero are left out."""
    out = []
    outside = "outside the range a double-precision solve represents ({:g} to {:g})".format(*DISPLACEMENT_RANGE)
    for (name, boundary), load in [*scene.loads.items(), *scene.displacements.items()]:
        halves = [half for half in mesh.halves if name == layer and boundary in half.boundaries]
        value = max((load_extent(half.points, half.edges(boundary), load) for half in halves), default=0.0)
        if value == 0.0:
            continue
        if isinstance(load, Load):
            moved = value * size / stiffness
            out.append((moved, load.key, f"{key}: the elastic matrix (largest entry {stiffness:.3g}) with {load.key} "
                        f"up to {value:.3g} on a domain of size {size:.3g} gives displacements of order {moved:.1g}, "
                        f"{outside}: change the units of the moduli and the loads"))
        else:
            out.append((value, load.key, f"{load.key}: prescribed values up to {value:.3g}, {outside}: change the "
                        "unit of length"))
    with np.errstate(all="ignore"):  # an expansion beyond double precision is refused below, naming its key
        thermal = thermal_of(scene, layer)
    if thermal is not None:
        change = max(field_extent(half.points, half.cells, thermal[1], f"temperature.{layer}") for half in mesh.halves)
        if change != 0.0:
            strain = float(np.nan_to_num(np.abs(thermal[0]), nan=np.inf).max()) * change
            alpha = "alpha" if isinstance(scene.materials[layer], materials.Isotropic) else "alpha1, alpha2"
            cause = f"materials.{layer}.{alpha} with temperature.{layer}"
            out.append((strain * size, cause, f"{cause} up to {change:.3g} give eigenstrains of order {strain:.1g} "
                        f"and, on a domain of size {size:.3g}, displacements of order {strain * size:.1g}, {outside}: "
                        "change the units of the expansion coefficient and the temperature"))
    return out
