"""Vectorized plane elasticity with P1 or P2 (isoparametric) triangles: stiffness, boundary loads,
strains, stresses and energies.

All elements are processed at once (no Python loop over cells): element matrices as one
``(m, 2k, 2k)`` array (k = 3 or 6 nodes), scattered to COO triplets, summed into CSR.  Degrees of
freedom are interleaved, node ``v`` owning ``2v`` (x) and ``2v + 1`` (y), so the matrices have block
size 2.  At the Σ nodes that carry multipliers the two dofs are instead the components in the node's
(tangent, normal) frame (:attr:`~ddsolve.mesh.SigmaLine.frames`), so that every interface condition
acts on single dofs; :func:`to_global` turns a solution back.  No PETSc or MPI here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import materials
from .errors import SceneError
from .interface import BLOCKS
from .mesh import HalfMesh, Mesh, SigmaLine, edge_points, edge_shapes, gauss_interval
from .scene import Load, Scene

# --- the reference triangle -----------------------------------------------------------------------
#: Quadrature on the reference triangle (ξ, η ≥ 0, ξ + η ≤ 1): points and weights summing to ½.
#: P1 uses the centroid (gradients are constant); P2 the 6-point rule of degree 4 (Dunavant), exact
#: for straight P2 stiffness and accurate for curved (isoparametric) cells.
_A, _B = 0.445948490915965, 0.091576213509771
_RULES = {
    3: (np.array([[1.0 / 3.0, 1.0 / 3.0]]), np.array([0.5])),
    6: (np.array([[_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A], [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]]),
        0.5 * np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)),
}


def quadrature(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """The element rule of P1 (``nodes`` = 3) or P2 (6) cells: reference points ``(q, 2)``, weights ``(q,)``."""
    return _RULES[nodes]


def shape_functions(nodes: int, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values ``(q, k)`` and reference gradients ``(q, k, 2)`` of the P1 (k = 3) or P2 (k = 6) basis."""
    s, t = xi[:, 0], xi[:, 1]
    r = 1.0 - s - t
    if nodes == 3:
        values = np.column_stack([r, s, t])
        gradients = np.broadcast_to(np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]), (len(xi), 3, 2)).copy()
        return values, gradients
    values = np.column_stack([r * (2 * r - 1), s * (2 * s - 1), t * (2 * t - 1), 4 * r * s, 4 * s * t, 4 * t * r])
    ds = np.column_stack([1 - 4 * r, 4 * s - 1, 0 * s, 4 * (r - s), 4 * t, -4 * t])
    dt = np.column_stack([1 - 4 * r, 0 * s, 4 * t - 1, -4 * s, 4 * s, 4 * (r - t)])
    return values, np.stack([ds, dt], axis=2)


def element_geometry(points: np.ndarray, cells: np.ndarray, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At reference points ``xi``: det J ``(m, q)`` and physical gradients ``(m, q, k, 2)``."""
    _, reference = shape_functions(cells.shape[1], xi)
    nodes = points[cells]  # (m, k, 2)
    jacobian = np.einsum("mkd,qke->mqde", nodes, reference)  # dx_d/dξ_e
    det = jacobian[..., 0, 0] * jacobian[..., 1, 1] - jacobian[..., 0, 1] * jacobian[..., 1, 0]
    inverse = np.stack([np.stack([jacobian[..., 1, 1], -jacobian[..., 0, 1]], -1),
                        np.stack([-jacobian[..., 1, 0], jacobian[..., 0, 0]], -1)], -2) / det[..., None, None]
    return det, np.einsum("qke,mqed->mqkd", reference, inverse)


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
    return np.stack([2 * cells, 2 * cells + 1], axis=2).reshape(len(cells), -1)


def element_stiffness(points: np.ndarray, cells: np.ndarray, D: np.ndarray) -> np.ndarray:
    """``(m, 2k, 2k)`` element stiffness matrices ∫ Bᵀ D B."""
    xi, weights = _RULES[cells.shape[1]]
    det, gradients = element_geometry(points, cells, xi)
    out = np.zeros((len(cells), 2 * cells.shape[1], 2 * cells.shape[1]))
    for q, weight in enumerate(weights):
        B = strain_operator(gradients[:, q])
        out += (weight * det[:, q])[:, None, None] * np.einsum("mki,kl,mlj->mij", B, D, B)
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
def rotate_coo(rows: np.ndarray, cols: np.ndarray, values: np.ndarray, nodes: np.ndarray, frames: np.ndarray,
               n_nodes: int):
    """Triplets of R K Rᵀ, R rotating the dofs of ``nodes`` into ``frames`` ``(len(nodes), 2, 2)``."""
    frame_of = np.full(n_nodes, -1, dtype=np.int64)
    frame_of[nodes] = np.arange(len(nodes))
    for axis in (0, 1):
        index = (rows, cols)[axis]
        frame = frame_of[index // 2]
        hit = frame >= 0
        if not hit.any():
            continue
        component = index[hit] % 2
        base = index[hit] - component
        R = frames[frame[hit]]  # (h, 2, 2): new component b = Σ_a R[b, a] old a
        new_index = np.concatenate([base, base + 1])
        new_values = np.concatenate([R[np.arange(len(R)), 0, component], R[np.arange(len(R)), 1, component]])
        new_values = new_values * np.concatenate([values[hit], values[hit]])
        other = np.concatenate([(cols, rows)[axis][hit]] * 2)
        rows_, cols_ = (new_index, other) if axis == 0 else (other, new_index)
        rows = np.concatenate([rows[~hit], rows_])
        cols = np.concatenate([cols[~hit], cols_])
        values = np.concatenate([values[~hit], new_values])
    return rows, cols, values


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


# --- block systems ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BlockSystem:
    """One block's linear system K x = rhs (+ interface loads on ``trace_dofs``), or the rows
    ``first … first + len(rhs) − 1`` of it when the block is distributed.

    Clamped dofs are decoupled: their rows and columns are empty except for the diagonal entry, and
    their right-hand side is zero.  ``indptr``, ``indices``, ``data`` are the CSR arrays of the local
    rows with global columns.  ``trace_dofs`` are the dofs of the multiplier nodes, in Σ order, in
    their local frames; ``modes`` are the rigid-body motions of the local rows (for algebraic multigrid).
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


def row_ranges(nodes: int, parts: int) -> list[tuple[int, int]]:
    """Split a block's dofs into ``parts`` contiguous ranges of whole nodes (as PETSc would)."""
    bounds = np.linspace(0, nodes, parts + 1).round().astype(int)
    return [(2 * a, 2 * b) for a, b in zip(bounds[:-1], bounds[1:])]


def trace_nodes(half: HalfMesh, sigma: SigmaLine) -> np.ndarray:
    """Nodes of ``half`` that carry the trace: the multiplier nodes, in Σ order."""
    return half.sigma[sigma.multiplier_nodes]


def block_system(name: str, half: HalfMesh, sigma: SigmaLine, D: np.ndarray, loads: list[Load],
                 rows: tuple[int, int] | None = None) -> BlockSystem:
    """Assemble a block (or its ``rows``): stiffness with clamped dofs decoupled, the loads on the
    half's named boundaries, Σ dofs in local frames."""
    n = 2 * len(half.points)
    first, last = rows if rows is not None else (0, n)
    owned = np.zeros(len(half.points), dtype=bool)
    owned[first // 2:last // 2] = True
    cells = half.cells[owned[half.cells].any(axis=1)]  # the cells that contribute to these rows
    rows_, cols, values = stiffness(half.points, cells, D)
    nodes = trace_nodes(half, sigma)
    frames = sigma.frames[sigma.multiplier_nodes]
    rotated = not np.allclose(frames, np.eye(2), rtol=0.0, atol=0.0)
    if rotated:
        rows_, cols, values = rotate_coo(rows_, cols, values, nodes, frames, len(half.points))
    clamped = np.zeros(n, dtype=bool)
    clamped[element_dofs(half.clamped()[:, None]).ravel()] = True
    keep = (rows_ >= first) & (rows_ < last) & ~(clamped[rows_] | clamped[cols])
    diagonal = (rows_ == cols) & (rows_ >= first) & (rows_ < last) & clamped[rows_]
    indptr, indices, data = coo_to_csr(last - first, np.concatenate([rows_[keep], rows_[diagonal]]) - first,
                                       np.concatenate([cols[keep], cols[diagonal]]),
                                       np.concatenate([values[keep], values[diagonal]]), columns=n)
    rhs = np.zeros(n)
    for load in loads:
        rhs += boundary_load(half.points, half.edges(load.boundary), load)
    if rotated:
        rhs = rotate_vector(rhs, nodes, frames)
    rhs[clamped] = 0.0
    modes = rigid_body_modes(half.points)
    if rotated:
        modes = np.array([rotate_vector(mode, nodes, frames) for mode in modes])
    return BlockSystem(name, indptr, indices, data, rhs[first:last], element_dofs(nodes[:, None]).ravel(), n,
                       first, modes[:, first:last])


def rigid_body_modes(points: np.ndarray) -> np.ndarray:
    """``(3, 2n)``: the translations in x and y and the rotation about the centroid."""
    centred = points - points.mean(axis=0)
    modes = np.zeros((3, len(points), 2))
    modes[0, :, 0] = 1.0
    modes[1, :, 1] = 1.0
    modes[2, :, 0], modes[2, :, 1] = -centred[:, 1], centred[:, 0]
    return modes.reshape(3, -1)


def elasticity(scene: Scene, layer: str) -> tuple[np.ndarray, np.ndarray]:
    """(D, c) of a layer under the scene's plane model (see :func:`ddsolve.materials.elasticity`)."""
    return materials.elasticity(scene.materials[layer], scene.model)


def layer_loads(scene: Scene, layer: str, half: HalfMesh) -> list[Load]:
    """The scene's loads on ``layer`` whose boundary this half has."""
    return [load for (name, _), load in scene.loads.items() if name == layer and load.boundary in half.boundaries]


def block_systems(scene: Scene, mesh: Mesh, which: list[int] | None = None,
                  rows: tuple[int, int] | None = None) -> list[BlockSystem]:
    """Assemble the scene's blocks with indices in ``which`` (all four by default), or their ``rows``."""
    systems = []
    for index in range(len(BLOCKS)) if which is None else which:
        spec = BLOCKS[index]
        half = mesh.half(spec.side)
        D, _ = elasticity(scene, spec.layer)
        systems.append(block_system(spec.name, half, mesh.sigma, D, layer_loads(scene, spec.layer, half), rows))
    return systems


def csr_matvec(system: BlockSystem, x: np.ndarray) -> np.ndarray:
    """K x for a block system's CSR matrix."""
    rows = np.repeat(np.arange(system.size), np.diff(system.indptr))
    return np.bincount(rows, system.data * x[system.indices], minlength=system.size)


# --- fields of a solution ---------------------------------------------------------------------------
def cell_strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: area ``(m,)`` and mean strain (εxx, εyy, γxy) ``(m, 3)`` of the field u ``(n, 2)``."""
    xi, weights = _RULES[cells.shape[1]]
    det, gradients = element_geometry(points, cells, xi)
    local = u.reshape(-1)[element_dofs(cells)]
    strain = np.einsum("mqij,mj->mqi", strain_operator(gradients), local)
    area = det @ weights
    return area, np.einsum("mq,q,mqi->mi", det, weights, strain) / area[:, None]


def energy(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray) -> float:
    """uᵀ K u = ∫ ε(u)ᵀ D ε(u) for the unconstrained stiffness K of this mesh."""
    return float(cell_energies(points, cells, D, u).sum())


def cell_energies(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per cell ∫ ε(u)ᵀ D ε(u) (twice the strain energy of the cell)."""
    xi, weights = _RULES[cells.shape[1]]
    det, gradients = element_geometry(points, cells, xi)
    strain = np.einsum("mqij,mj->mqi", strain_operator(gradients), u.reshape(-1)[element_dofs(cells)])
    return np.einsum("mq,q,mqi,ij,mqj->m", det, weights, strain, D, strain)


def cell_stresses(D: np.ndarray, c: np.ndarray, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(σxx, σyy, σxy) ``(m, 3)`` and σzz ``(m,)`` from strains ``(m, 3)``."""
    return strain @ D.T, strain @ c


def von_mises(points: np.ndarray, cells: np.ndarray, D: np.ndarray, c: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per-cell von Mises stress of the mean strain (σzz from the plane model included)."""
    _, strain = cell_strains(points, cells, u)
    return materials.von_mises(*cell_stresses(D, c, strain))
