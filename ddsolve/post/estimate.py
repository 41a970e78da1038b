"""A posteriori error estimate: Zienkiewicz–Zhu recovery per block, plus the contact term on the crack.

For each block the strain of the solution, discontinuous between cells, is recovered into a continuous
field ε* of the same element space by superconvergent patch recovery (SPR): around every vertex a
polynomial of the element degree is fitted by least squares to the strains at the superconvergent
points of the cells of the vertex's patch (the centroid for P1, the 3-point Gauss points for P2), and
nodes take the value of the patches they belong to.  The indicator of a cell K is

    η_K² = ∫_K (ε* − ε_h)ᵀ D (ε* − ε_h),

the energy of the difference.  Recovery never crosses Σ: each block is recovered on its own half, so
the jumps of the stress across Σ that the gluing forces and the crack cause are kept, not smeared.
The discrete contact conditions hold at the nodes only; between nodes the contact pressure and the
opening of the crack may both be positive.  That complementarity defect, 2 |∫_E μᶜ_h [u_h]·ν ds| per
crack edge E, is added to the cells of u⁻ and u⁺ along E (half each).  The total is

    η² = Σ_K η_K²,      relative estimate = η / sqrt(‖u_h‖²_E + η²),

an estimate of ‖u − u_h‖_E / ‖u‖_E (‖u‖² = ‖u_h‖² + ‖u − u_h‖² for the Galerkin solution of the linear
problem).  Everything is vectorized over cells; no PETSc or MPI here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddsolve.fem.assembly import elasticity, voigt_strain
from ddsolve.mesh.element import (CELL_EDGES, boundary_nodes, edge_keys, edge_points, edge_shapes, element_geometry,
                                  field_gradients, gauss_interval, shape_functions)
from ddsolve.mesh.mesh import CRACK, HalfMesh, Mesh, SigmaLine, blocks
from ddsolve.problem.scene import Scene

#: Sampling points of the recovery per element (reference coordinates): where the strain of the
#: element is most accurate.
_SAMPLES = {3: np.array([[1.0 / 3.0, 1.0 / 3.0]]),
            6: np.array([[1.0 / 6.0, 1.0 / 6.0], [2.0 / 3.0, 1.0 / 6.0], [1.0 / 6.0, 2.0 / 3.0]])}
#: Quadrature for the indicators: degree 2 for P1 (ε* linear), degree 4 for P2 (ε* quadratic).
_A, _B = 0.445948490915965, 0.091576213509771
TRIANGLE_RULES = {
    3: (_SAMPLES[6], np.full(3, 1.0 / 6.0)),
    6: (np.array([[_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A], [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]]),
        0.5 * np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)),
}
#: Local nodes of a cell that take their value from the patch of each corner: the corner itself and,
#: for P2, the midpoints of the two edges at it.
_OWN = {3: np.array([[0], [1], [2]]), 6: np.array([[0, 3, 5], [1, 3, 4], [2, 4, 5]])}
#: A patch fit is used when every Cholesky pivot of its normal matrix exceeds this fraction of its
#: largest diagonal entry (coordinates are scaled to the patch, so the entries are of order one).
_CONDITION = 1e-8


def _monomials(local: np.ndarray, degree: int) -> np.ndarray:
    """``(..., b)``: 1, x, y (and x², xy, y² for degree 2) at local coordinates ``(..., 2)``."""
    x, y = local[..., 0], local[..., 1]
    terms = [np.ones_like(x), x, y]
    if degree == 2:
        terms += [x * x, x * y, y * y]
    return np.stack(terms, axis=-1)


def _strains_at(points: np.ndarray, cells: np.ndarray, u: np.ndarray, xi: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At reference points ``xi``: positions ``(m, q, 2)``, det J ``(m, q)``, strains ``(m, q, 3)``."""
    values, _ = shape_functions(cells.shape[1], xi)  # (q, k)
    det, gradients = element_geometry(points, cells, xi)
    return np.matmul(values, points[cells]), det, voigt_strain(field_gradients(u[cells], gradients))


def _solve_spd(A: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve many small symmetric positive semidefinite systems ``(p, b, b)`` x = ``(p, b, c)`` at once
    (Cholesky, vectorized over p: numpy's batched solvers pay a LAPACK call per system).  Returns the
    solutions and which systems are well conditioned (every pivot above ``_CONDITION`` × the largest
    diagonal entry); the others get garbage."""
    b = A.shape[1]
    L = np.zeros_like(A)
    floor = _CONDITION * A[:, np.arange(b), np.arange(b)].max(axis=1)
    good = floor > 0
    for j in range(b):
        pivot = A[:, j, j] - np.sum(L[:, j, :j] ** 2, axis=1)
        good &= pivot > floor
        L[:, j, j] = np.sqrt(np.where(good, pivot, 1.0))
        L[:, j + 1:, j] = (A[:, j + 1:, j] - (L[:, j + 1:, :j] @ L[:, j, :j, None])[..., 0]) / L[:, j, j, None]
    y = np.zeros_like(rhs)
    for j in range(b):
        y[:, j] = (rhs[:, j] - (L[:, j, None, :j] @ y[:, :j])[:, 0]) / L[:, j, j, None]
    x = np.zeros_like(rhs)
    for j in reversed(range(b)):
        x[:, j] = (y[:, j] - (L[:, j + 1:, j][:, None, :] @ x[:, j + 1:])[:, 0]) / L[:, j, j, None]
    return x, good


def _energy_density(strain: np.ndarray, D: np.ndarray, det: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per cell ∫ εᵀ D ε from strains ``(m, q, 3)`` at the quadrature points."""
    return (np.sum((strain @ D) * strain, axis=2) * det) @ weights


def recovered_strain(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``(n, 3)``: the SPR-recovered strain (εxx, εyy, γxy) at every node of the block."""
    where, _, strain = _sampled_strains(points, cells, u)
    return _recover(points, cells, where, strain)


#: Cells whose temporaries the estimate holds at once: its memory stays that of a few arrays per node
#: whatever the mesh (all at once, the temporaries took about 1.3 kB per cell).
CHUNK_CELLS = 2 ** 14


def _chunks(count: int, size: int = CHUNK_CELLS):
    """Consecutive slices of ``range(count)`` of at most ``size`` items."""
    return (slice(start, min(start + size, count)) for start in range(0, count, size))


def _add_counts(totals: np.ndarray, nodes: np.ndarray, weights: np.ndarray | None = None) -> None:
    """``totals[..., v] += Σ weights[i]`` over the i with ``nodes[i]`` = v (or the count); ``weights`` ``(i,)``
    or ``(c, i)`` for c rows of ``totals``.  Counted over the range of ``nodes`` only: a chunk of cells of a
    mesh numbered by position touches a narrow range of nodes, and the whole length would cost O(n) per chunk."""
    if not len(nodes):
        return
    low, high = int(nodes.min()), int(nodes.max()) + 1
    shifted = nodes - low
    if weights is None or weights.ndim == 1:
        totals[..., low:high] += np.bincount(shifted, weights, minlength=high - low)
        return
    for row, values in zip(totals, weights):
        row[low:high] += np.bincount(shifted, values, minlength=high - low)


def _sampled_strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions ``(m, s, 2)``, det J ``(m, s)`` and strains ``(m, s, 3)`` at the sampling points of every cell."""
    xi = _SAMPLES[cells.shape[1]]
    where, det, strain = np.empty((len(cells), len(xi), 2)), np.empty((len(cells), len(xi))), np.empty((len(cells), len(xi), 3))
    for chunk in _chunks(len(cells)):
        where[chunk], det[chunk], strain[chunk] = _strains_at(points, cells[chunk], u, xi)
    return where, det, strain


def _recover(points: np.ndarray, cells: np.ndarray, where: np.ndarray, strain: np.ndarray,
             outer_edges: np.ndarray | None = None) -> np.ndarray:
    """SPR from the positions ``(m, s, 2)`` and strains ``(m, s, 3)`` at the sampling points; the
    patch sums are gathered a chunk of cells at a time.  ``outer_edges``: the mesh's boundary edges if
    known (:attr:`~ddsolve.mesh.mesh.HalfMesh.boundary_edges`), else found from the cells."""
    k = cells.shape[1]
    degree = 1 if k == 3 else 2
    b = 3 if degree == 1 else 6
    n = len(points)
    corners = cells[:, :3]
    # The size of each vertex's patch: the root mean square over its cells of the farthest sampling point.
    squares, cells_at = np.zeros(n), np.bincount(corners.ravel(), minlength=n)
    for chunk in _chunks(len(cells)):
        offsets = where[chunk, None, :, :] - points[corners[chunk]][:, :, None, :]  # (c, 3, s, 2)
        _add_counts(squares, corners[chunk].ravel(), (offsets ** 2).sum(axis=3).max(axis=2).ravel())
    scale = np.sqrt(squares / np.maximum(cells_at, 1))
    # The patch normal equations Σ PPᵀ a = Σ P ε, summed per vertex (upper triangle of the symmetric part).
    upper = np.triu_indices(b)
    normal, moments = np.zeros((len(upper[0]), n)), np.zeros((3 * b, n))
    for chunk in _chunks(len(cells)):
        vertex = corners[chunk].ravel()
        cell = np.repeat(np.arange(chunk.start, chunk.stop), 3)
        basis = _monomials((where[cell] - points[vertex][:, None, :]) / scale[vertex][:, None, None], degree)
        # summed over the sampling points, in rows: (b(b+1)/2, 3c) and (3b, 3c)
        pairs = np.einsum("psi,psi->ip", basis[:, :, upper[0]], basis[:, :, upper[1]], order="C")
        products = np.einsum("psi,psd->idp", basis, strain[cell], order="C").reshape(3 * b, len(vertex))
        _add_counts(normal, vertex, pairs)
        _add_counts(moments, vertex, products)
    patches = np.flatnonzero(cells_at)
    A = np.zeros((len(patches), b, b))
    for j, (row, column) in enumerate(zip(*upper)):
        A[:, row, column] = A[:, column, row] = normal[j, patches]
    rhs = moments[:, patches].T.reshape(-1, b, 3)
    del normal, moments
    solved, good = _solve_spd(A, rhs)
    good &= cells_at[patches] >= 3
    coefficients = np.zeros((n, b, 3))
    coefficients[patches[good]] = solved[good]
    usable = np.zeros(n, dtype=bool)
    usable[patches[good]] = True
    if outer_edges is None:
        on_boundary = boundary_nodes(corners, n)
    else:
        on_boundary = np.zeros(n, dtype=bool)
        on_boundary[outer_edges[:, :2]] = True
    interior = usable & ~on_boundary
    # A node takes the mean of the interior patches it is "own" to (its vertex, or a P2 midpoint's two
    # ends); a node without one (at the boundary) the mean of the interior patches of its cells, else
    # of the usable patches of its cells.
    if k == 3:  # a P1 vertex takes its own patch's fit at the vertex: its constant term
        out, found = np.where(interior[:, None], coefficients[:, 0], 0.0), interior.copy()
    else:
        own = _OWN[k]
        out, found = _patch_means(points, cells, lambda c: cells[c][:, own], scale, coefficients, interior, degree)
    missing = ~found
    if missing.any():
        near = np.flatnonzero(missing[cells].any(axis=1))  # the cells with a node still missing
        every = np.broadcast_to(np.arange(k), (3, k))  # every node of the cell, for each corner's patch
        for level in (usable, interior):  # interior patches override boundary ones
            values, count = _patch_means(points, cells[near], lambda c: cells[near[c]][:, every], scale,
                                         coefficients, level, degree)
            take = missing & count
            out[take] = values[take]
    return out


def _patch_means(points: np.ndarray, cells: np.ndarray, nodes, scale: np.ndarray, coefficients: np.ndarray,
                 use: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """The mean, over the corners of ``cells`` whose patch has ``use``, of the corner patch's polynomial
    at the nodes ``nodes(chunk)`` ``(c, 3, r)`` gives for a chunk of cells; ``(n, 3)`` values and ``(n,)``
    whether a node got any."""
    n = len(points)
    count, sums = np.zeros(n, dtype=np.int64), np.zeros((3, n))
    for chunk in _chunks(len(cells)):
        vertex = cells[chunk, :3].ravel()
        at = nodes(chunk).reshape(len(vertex), -1)  # (3c, r)
        chosen = use[vertex]
        vertex, at = vertex[chosen], at[chosen]
        local = (points[at] - points[vertex][:, None, :]) / scale[vertex][:, None, None]
        values = _monomials(local, degree) @ coefficients[vertex]  # (p, r, 3)
        flat = at.ravel()
        _add_counts(count, flat)
        _add_counts(sums, flat, values.reshape(-1, 3).T)
    found = count > 0
    sums[:, found] /= count[found]
    return sums.T.copy(), found


def block_indicators(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray,
                     outer_edges: np.ndarray | None = None) -> np.ndarray:
    """``(2, m)``: per cell η_K² = ∫ (ε* − ε_h)ᵀ D (ε* − ε_h) and ∫ ε_hᵀ D ε_h, for the field u ``(n, 2)``;
    ``outer_edges`` as for :func:`_recover`."""
    k = cells.shape[1]
    where, sampled_det, sampled = _sampled_strains(points, cells, u)
    recovered = _recover(points, cells, where, sampled, outer_edges)
    del where
    xi, weights = TRIANGLE_RULES[k]
    values, _ = shape_functions(k, xi)
    out = np.empty((2, len(cells)))
    for chunk in _chunks(len(cells)):
        if k == 3:  # straight P1 cells: ε_h and det J are the same at every point, the sampled ones (centroid)
            strain = sampled[chunk]
            out[1, chunk] = _energy_density(strain, D, sampled_det[chunk], np.array([weights.sum()]))
            det = np.broadcast_to(sampled_det[chunk], (len(strain), len(xi)))
        else:
            _, det, strain = _strains_at(points, cells[chunk], u, xi)
            out[1, chunk] = _energy_density(strain, D, det, weights)
        difference = np.tensordot(recovered[cells[chunk]], values, axes=([1], [1])).transpose(0, 2, 1) - strain
        out[0, chunk] = _energy_density(difference, D, det, weights)
    return out


def half_indicators(half: HalfMesh, D: np.ndarray, u: np.ndarray) -> np.ndarray:
    """:func:`block_indicators` of the field ``u`` on ``half`` (whose outer edges may be known already)."""
    return block_indicators(half.points, half.cells, D, u, half.boundary_edges)


def contact_indicators(mesh: Mesh, u_minus: np.ndarray, u_plus: np.ndarray, mu_c: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Per cell of the lower and the upper half: half of 2 |∫_E μᶜ_h [u_h]·ν ds| for the crack edges E
    of the cell.  ``mu_c`` ``(k,)`` over the multiplier nodes (0 where there is none)."""
    pressure, jump = contact_on_sigma(mesh.sigma, mu_c, u_minus[mesh.lower.sigma], u_plus[mesh.upper.sigma])
    lower, upper = (half_contact_indicators(half, pressure, jump) for half in mesh.halves)
    return lower, upper


def contact_on_sigma(sigma: SigmaLine, mu_c: np.ndarray, minus: np.ndarray, plus: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """``(s,)`` contact pressure (0 off the multiplier nodes) and normal jump [u]·ν at every Σ node, from
    the displacements ``(s, 2)`` of u⁻ and u⁺ at the Σ nodes."""
    pressure = np.zeros(len(sigma.points))
    pressure[sigma.multiplier_nodes] = mu_c
    return pressure, np.einsum("sd,sd->s", plus - minus, sigma.normals)


def half_contact_indicators(half: HalfMesh, pressure: np.ndarray, jump: np.ndarray) -> np.ndarray:
    """``(m,)``: the contact term of every cell of ``half`` (see :func:`contact_indicators`; of a piece of a
    half, the crack edges of its cells count)."""
    edges = half.edges(CRACK)
    cells = np.zeros(len(half.cells))
    if len(edges) and np.any(pressure):
        position = np.full(len(half.points), -1, dtype=np.int64)
        position[half.sigma] = np.arange(len(half.sigma))
        owner = _edge_cells(half.cells, edges)
        edges, owner = edges[owner >= 0], owner[owner >= 0]
        s, w = gauss_interval(4)
        shapes, _ = edge_shapes(edges.shape[1], s)
        _, tangents = edge_points(half.points, edges, s)
        speed = np.linalg.norm(tangents, axis=2)  # (e, q)
        along = position[edges]
        product = (shapes @ pressure[along].T).T * (shapes @ jump[along].T).T  # (e, q)
        defect = np.abs(np.einsum("eq,eq,q->e", product, speed, w))  # |∫ μ [u]·ν| per edge
        np.add.at(cells, owner, defect)  # ½ of 2|∫ μ [u]·ν|
    return cells


def _edge_cells(cells: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The cell that has each boundary edge (by its end nodes), −1 for an edge of none of ``cells``."""
    if not len(cells):
        return np.full(len(edges), -1, dtype=np.int64)
    pairs = cells[:, CELL_EDGES[cells.shape[1]][:, :2]].reshape(-1, 2)
    n = int(max(cells.max(), edges.max())) + 1
    keys = edge_keys(pairs, n)
    order = np.argsort(keys)
    wanted = edge_keys(edges[:, :2], n)
    at = np.minimum(np.searchsorted(keys[order], wanted), len(keys) - 1)
    found = order[at]
    return np.where(keys[found] == wanted, found // 3, -1)


@dataclass(frozen=True)
class Estimate:
    """Indicators η_K (energy norm, per cell of each block; Σ η_K² = η²) and ‖u_h‖²_E."""

    indicators: dict[str, np.ndarray]
    energy: float  # ‖u_h‖²_E = Σ_b x_bᵀ K_b x_b
    floor: float = 0.0  # the rounding level of ‖u_h‖²_E (:func:`rounding_energy`)

    @property
    def absolute(self) -> float:
        """η."""
        return float(np.sqrt(sum(float(np.sum(v ** 2)) for v in self.indicators.values())))

    @property
    def relative(self) -> float:
        """η / sqrt(‖u_h‖² + η²): the estimated relative energy-norm error."""
        return relative(self.absolute ** 2, self.energy, self.floor)


#: Strains of this fraction of the largest displacement per unit length, or less, are rounding: a field
#: without larger ones is a rigid motion (or none), which every mesh represents exactly.
ROUNDING = 1e-11


def rounding_energy(modulus: float, largest: float) -> float:
    """‖u‖²_E of strains ROUNDING × ``largest`` per unit length under the stiffness ``modulus`` (the largest
    entry of the layers' D): D (ROUNDING |u|)², an energy per unit thickness whatever the domain's size."""
    return modulus * (ROUNDING * largest) ** 2


def relative(squared: float, energy: float, floor: float = 0.0) -> float:
    """η / sqrt(‖u_h‖² + η²) from η² = ``squared`` and ‖u_h‖²_E = ``energy`` (sums over the blocks); 0 when
    both are rounding, at most ``floor`` (:func:`rounding_energy`): nothing is strained, nothing to estimate."""
    total = squared + energy
    return float(np.sqrt(squared / total)) if total > max(floor, 0.0) else 0.0


def block_estimate(part: np.ndarray, contact: np.ndarray | float = 0.0) -> tuple[np.ndarray, float, float]:
    """One block's indicators η_K ``(m,)``, Σ η_K² and ‖u_h‖²_E from its :func:`block_indicators` ``part``
    and its cells' contact terms (u⁻ and u⁺ only); the estimate of the run sums the last two."""
    squared = np.maximum(part[0] + contact, 0.0)
    return np.sqrt(squared), float(squared.sum()), float(part[1].sum())


def combine(mesh: Mesh, parts: dict[str, np.ndarray], solution: dict[str, np.ndarray], mu_c: np.ndarray,
            modulus: float) -> Estimate:
    """The estimate from each block's :func:`block_indicators` and the contact term (rank 0's part);
    ``modulus``: the largest entry of the layers' D (the rounding level, :func:`rounding_energy`)."""
    contact = dict(zip(("u_minus", "u_plus"), contact_indicators(mesh, solution["u_minus"], solution["u_plus"], mu_c)))
    largest = max(float(np.abs(u).max(initial=0.0)) for u in solution.values())
    return Estimate({name: block_estimate(part, contact.get(name, 0.0))[0] for name, part in parts.items()},
                    float(sum(parts[name][1].sum() for name in parts)), rounding_energy(modulus, largest))


def of_scene(scene: Scene, mesh: Mesh, solution: dict[str, np.ndarray], mu_c: np.ndarray) -> Estimate:
    """The whole estimate in one process, for displacements in (x, y)."""
    specs = blocks(scene.geometry.layers)
    laws = {spec.name: elasticity(scene, spec.layer, spec.region)[0] for spec in specs}
    parts = {spec.name: half_indicators(mesh.half(spec.side), laws[spec.name], solution[spec.name])
             for spec in specs}
    return combine(mesh, parts, solution, mu_c, max(float(np.abs(D).max()) for D in laws.values()))
