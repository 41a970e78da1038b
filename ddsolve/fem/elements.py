"""Element-level operators of plane elasticity with P1 or P2 (isoparametric) triangles: the strain operator B,
element dofs and stiffness matrices, COO to CSR, and the rotations into the local (tangent, normal) frames of
the Σ nodes.  No PETSc or MPI here."""
from __future__ import annotations

import numpy as np

from ddsolve.mesh.element import TRIANGLE_RULES, element_geometry


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
