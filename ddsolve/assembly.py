"""Vectorized P1 plane-strain elasticity: stiffness, traction loads, stresses, energies.

All elements are processed at once (no Python loop over cells): element matrices as one
``(m, 6, 6)`` array, scattered to COO triplets, summed into CSR.  Degrees of freedom are
interleaved, vertex ``v`` owning ``2v`` (x) and ``2v + 1`` (y), so the matrices have block size 2.
No PETSc or MPI here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .interface import BLOCKS
from .mesh import HalfMesh
from .scene import Material, Scene, Traction


def lame(material: Material) -> tuple[float, float]:
    """Plane-strain Lamé constants (μ, λ) from Young's modulus and Poisson's ratio."""
    mu = material.E / (2.0 * (1.0 + material.nu))
    return mu, 2.0 * material.nu * mu / (1.0 - 2.0 * material.nu)


def elasticity_matrix(material: Material) -> np.ndarray:
    """D with σ = D ε for (εxx, εyy, γxy), plane strain."""
    mu, lam = lame(material)
    return np.array([[lam + 2 * mu, lam, 0.0], [lam, lam + 2 * mu, 0.0], [0.0, 0.0, mu]])


def strain_operator(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: area ``(m,)`` and B ``(m, 3, 6)`` mapping element dofs to (εxx, εyy, γxy)."""
    p = points[cells]
    x, y = p[..., 0], p[..., 1]
    b = y[:, [1, 2, 0]] - y[:, [2, 0, 1]]  # ∂φ_i/∂x · 2A
    c = x[:, [2, 0, 1]] - x[:, [1, 2, 0]]  # ∂φ_i/∂y · 2A
    twice_area = x[:, 0] * b[:, 0] + x[:, 1] * b[:, 1] + x[:, 2] * b[:, 2]
    B = np.zeros((len(cells), 3, 6))
    B[:, 0, 0::2] = b
    B[:, 1, 1::2] = c
    B[:, 2, 0::2] = c
    B[:, 2, 1::2] = b
    return 0.5 * twice_area, B / twice_area[:, None, None]


def element_dofs(cells: np.ndarray) -> np.ndarray:
    """``(m, 2c)`` dofs of each row of c vertices, in the order (v0x, v0y, v1x, v1y, ...)."""
    return np.stack([2 * cells, 2 * cells + 1], axis=2).reshape(len(cells), -1)


def element_stiffness(points: np.ndarray, cells: np.ndarray, material: Material) -> np.ndarray:
    """``(m, 6, 6)`` element stiffness matrices A Bᵀ D B."""
    area, B = strain_operator(points, cells)
    return area[:, None, None] * np.einsum("mki,kl,mlj->mij", B, elasticity_matrix(material), B)


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


def stiffness(points: np.ndarray, cells: np.ndarray, material: Material):
    """Unconstrained stiffness as COO triplets (rows, cols, values), duplicates not yet summed."""
    dofs = element_dofs(cells)
    rows = np.broadcast_to(dofs[:, :, None], (len(cells), 6, 6)).ravel()
    cols = np.broadcast_to(dofs[:, None, :], (len(cells), 6, 6)).ravel()
    return rows, cols, element_stiffness(points, cells, material).ravel()


def traction_load(points: np.ndarray, edges: np.ndarray, traction: Traction) -> np.ndarray:
    """Consistent P1 load ∫ t·φ ds over ``edges`` for a polynomial traction t(x), exact Gauss rule."""
    load = np.zeros(2 * len(points))
    degree = max(len(traction.x), len(traction.y), 1) - 1
    s, w = np.polynomial.legendre.leggauss(max(2, (degree + 3) // 2))
    s, w = 0.5 * (s + 1.0), 0.5 * w  # rule on [0, 1]
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    length = np.linalg.norm(b - a, axis=1)
    x = a[:, None, 0] + s[None, :] * (b - a)[:, None, 0]  # (edges, quadrature points)
    shape = np.stack([1.0 - s, s])  # (2, quadrature points)
    for component, coefficients in enumerate((traction.x, traction.y)):
        if not coefficients:
            continue
        t = np.polynomial.polynomial.polyval(x, coefficients)
        nodal = length[:, None] * np.einsum("eq,q,aq->ea", t, w, shape)
        load += np.bincount(2 * edges.ravel() + component, nodal.ravel(), minlength=len(load))
    return load


def strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: area and constant strain (εxx, εyy, γxy) of the P1 field u ``(n, 2)``."""
    area, B = strain_operator(points, cells)
    return area, np.einsum("mij,mj->mi", B, u.reshape(-1)[element_dofs(cells)])


def energy(points: np.ndarray, cells: np.ndarray, material: Material, u: np.ndarray) -> float:
    """uᵀ K u for the unconstrained stiffness K of this mesh and material."""
    area, eps = strains(points, cells, u)
    return float(np.einsum("m,mi,ij,mj->", area, eps, elasticity_matrix(material), eps))


def von_mises(points: np.ndarray, cells: np.ndarray, material: Material, u: np.ndarray) -> np.ndarray:
    """Per-cell von Mises stress, plane strain (σzz = λ (εxx + εyy) included)."""
    _, eps = strains(points, cells, u)
    sxx, syy, sxy = (eps @ elasticity_matrix(material).T).T
    szz = lame(material)[1] * (eps[:, 0] + eps[:, 1])
    return np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2) + 3.0 * sxy ** 2)


@dataclass(frozen=True)
class BlockSystem:
    """One block's linear system K x = rhs (+ interface loads on ``trace_dofs``), or the rows
    ``first … first + len(rhs) − 1`` of it when the block is distributed.

    Clamped dofs (x = ±1) are decoupled: their rows and columns are empty except for a diagonal
    entry of the size of the stiffness diagonal (λ + 2μ), and their right-hand side is zero.
    ``indptr``, ``indices``, ``data`` are the CSR arrays of the local rows with global columns.
    """

    name: str
    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray
    rhs: np.ndarray
    trace_dofs: np.ndarray  # global dofs of the inner Σ vertices (all of them, in trace order)
    size: int  # global number of dofs
    first: int = 0
    coordinates: np.ndarray | None = None  # (local vertices, 2), for the rigid-body near-null space
    block_size: int = 2


def row_ranges(vertices: int, parts: int) -> list[tuple[int, int]]:
    """Split a block's dofs into ``parts`` contiguous ranges of whole vertices (as PETSc would)."""
    bounds = np.linspace(0, vertices, parts + 1).round().astype(int)
    return [(2 * a, 2 * b) for a, b in zip(bounds[:-1], bounds[1:])]


def block_system(name: str, half: HalfMesh, material: Material, traction: Traction | None,
                 rows: tuple[int, int] | None = None) -> BlockSystem:
    """Assemble a block (or its ``rows``): stiffness with clamped dofs decoupled, traction load."""
    n = 2 * len(half.points)
    first, last = rows if rows is not None else (0, n)
    owned = np.zeros(len(half.points), dtype=bool)
    owned[first // 2:last // 2] = True
    cells = half.cells[owned[half.cells].any(axis=1)]  # the cells that contribute to these rows
    rows_, cols, values = stiffness(half.points, cells, material)
    clamped = np.zeros(n, dtype=bool)
    clamped[element_dofs(half.clamped()[:, None]).ravel()] = True
    keep = (rows_ >= first) & (rows_ < last) & ~(clamped[rows_] | clamped[cols])
    fixed = np.flatnonzero(clamped[first:last]) + first
    mu, lam = lame(material)
    indptr, indices, data = coo_to_csr(
        last - first,
        np.concatenate([rows_[keep], fixed]) - first,
        np.concatenate([cols[keep], fixed]),
        np.concatenate([values[keep], np.full(len(fixed), lam + 2.0 * mu)]),
        columns=n,
    )
    rhs = np.zeros(n)
    if traction is not None:
        rhs = traction_load(half.points, half.edges_on_line(float(half.side)), traction)
        rhs[clamped] = 0.0
    inner = half.sigma()[1:-1]
    return BlockSystem(name, indptr, indices, data, rhs[first:last], element_dofs(inner[:, None]).ravel(), n,
                       first, half.points[first // 2:last // 2])


def block_systems(scene: Scene, lower: HalfMesh, upper: HalfMesh, which: list[int] | None = None,
                  rows: tuple[int, int] | None = None) -> list[BlockSystem]:
    """Assemble the scene's blocks with indices in ``which`` (all four by default), or their ``rows``."""
    systems = []
    for index in range(len(BLOCKS)) if which is None else which:
        spec = BLOCKS[index]
        half = lower if spec.side < 0 else upper
        traction = scene.loads.get((spec.layer, "bottom" if spec.side < 0 else "top"))
        systems.append(block_system(spec.name, half, scene.materials[spec.layer], traction, rows))
    return systems


def csr_matvec(system: BlockSystem, x: np.ndarray) -> np.ndarray:
    """K x for a block system's CSR matrix."""
    rows = np.repeat(np.arange(system.size), np.diff(system.indptr))
    return np.bincount(rows, system.data * x[system.indices], minlength=system.size)
