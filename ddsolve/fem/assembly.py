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

The element operators are in :mod:`~ddsolve.fem.elements`, the load vectors in :mod:`~ddsolve.fem.loads`,
the fields of a solution in :mod:`~ddsolve.fem.fields` and the checks of the data's ranges in
:mod:`~ddsolve.fem.ranges`; this module, the stage's face, re-exports them.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ddsolve.fem import supports
from ddsolve.fem.elements import (coo_to_csr, element_dofs, element_stiffness, rotate_elements, rotate_vector,
                                  stiffness, strain_operator, to_global)
from ddsolve.fem.fields import (cell_energies, cell_means, cell_strains, cell_stresses, elasticity, energy,
                                integrated_energies, quadrature_fields, quadrature_strains, voigt_strain, von_mises)
from ddsolve.fem.loads import (HIGH_ORDER_POINTS, ThermalLoad, boundary_load, cell_temperatures, layer_loads,
                               load_vector, thermal_energy, thermal_load, thermal_of)
from ddsolve.fem.ranges import (CANDIDATES, CLOSING_STEPS, DISPLACEMENT_RANGE, ENERGY_RANGE, FINE_STEP, GROWTH,
                                GROWTH_STEPS, LATTICE, LOAD_SAMPLES, SAMPLED_CELLS, STIFFNESS_RANGE, Growth,
                                check_range, data_displacement, driven_displacements, field_extent, load_extent,
                                modulus)
from ddsolve.mesh.mesh import HalfMesh, blocks, Mesh, SigmaLine, index_type
from ddsolve.problem.scene import Load, Scene


#: The fem stage's face: the block systems here and the names of its other modules, as before they were split.
__all__ = ["BlockSystem", "ELEMENT_ENTRIES", "Pattern", "block_system", "block_systems", "csr_matvec", "pattern",
           "renumbered", "rigid_body_modes", "row_ranges", "trace_nodes",
           "coo_to_csr", "element_dofs", "element_stiffness", "rotate_elements", "rotate_vector", "stiffness",
           "strain_operator", "to_global",
           "cell_energies", "cell_means", "cell_strains", "cell_stresses", "elasticity", "energy",
           "integrated_energies", "quadrature_fields", "quadrature_strains", "voigt_strain", "von_mises",
           "HIGH_ORDER_POINTS", "ThermalLoad", "boundary_load", "cell_temperatures", "layer_loads", "load_vector",
           "thermal_energy", "thermal_load", "thermal_of",
           "CANDIDATES", "CLOSING_STEPS", "DISPLACEMENT_RANGE", "ENERGY_RANGE", "FINE_STEP", "GROWTH", "GROWTH_STEPS",
           "LATTICE", "LOAD_SAMPLES", "SAMPLED_CELLS", "STIFFNESS_RANGE", "Growth", "check_range",
           "data_displacement", "driven_displacements", "field_extent", "load_extent", "modulus"]


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


def trace_entries(system: BlockSystem, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The entries of K_ΣΣ in the system's rows (row, column, value), numbered by ``positions``: the place of each
    trace dof in the structure's trace."""
    place = np.full(system.size, -1, dtype=np.int64)
    place[system.trace_dofs] = positions
    rows = np.repeat(np.arange(len(system.rhs)) + system.first, np.diff(system.indptr))
    kept = (place[rows] >= 0) & (place[system.indices] >= 0)
    return place[rows[kept]], place[system.indices[kept]], system.data[kept]


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
                 thermal: ThermalLoad | None = None) -> BlockSystem:
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
        rhs += load_vector(half, load)
    offset = 0.0
    if thermal is not None:
        rhs += thermal.vector(half.points, structure.cells, D)
        owned = (structure.cells[:, 0] >= first // 2) & (structure.cells[:, 0] < last // 2)  # each cell once
        offset += thermal.energy(half.points, structure.cells[owned], D)
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


def rigid_body_modes(points: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
    """``(3, 2n)``: the translations in x and y and the rotation about ``centre`` (default: the centroid)."""
    centred = points - (points.mean(axis=0) if centre is None else centre)
    modes = np.zeros((3, len(points), 2))
    modes[0, :, 0] = 1.0
    modes[1, :, 1] = 1.0
    modes[2, :, 0], modes[2, :, 1] = -centred[:, 1], centred[:, 0]
    return modes.reshape(3, -1)


def block_systems(scene: Scene, mesh: Mesh, which: list[int] | None = None,
                  rows: tuple[int, int] | None = None, table: supports.SigmaSupports | None = None
                  ) -> list[BlockSystem]:
    """Assemble the scene's blocks (:func:`ddsolve.mesh.mesh.blocks`) with indices in ``which`` (all by default),
    or their ``rows``;
    ``table``: the Σ supports (:func:`ddsolve.fem.supports.sigma_supports`; made from ``mesh``, which
    must then be whole, if not given)."""
    systems, patterns = [], {}
    if table is None:
        table = supports.sigma_supports(scene, mesh)
    specs = blocks(scene.geometry.layers)
    for index in range(len(specs)) if which is None else which:
        spec = specs[index]
        half = mesh.half(spec.side)
        D, _ = elasticity(scene, spec.layer, spec.region)
        if spec.side not in patterns:
            patterns[spec.side] = pattern(half, rows)
        prescribed = supports.block_supports(scene, half, mesh.sigma, spec.layer, index, table)
        systems.append(block_system(spec.name, half, mesh.sigma, D, layer_loads(scene, spec.layer, half), rows,
                                    patterns[spec.side], prescribed, thermal_of(scene, spec.layer, spec.region)))
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
