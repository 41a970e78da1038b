"""The reference cells: the triangle (P1, P2) and its edges: topology, shape functions and
quadrature rules, shared by the meshes (edge geometry, Σ weights) and the assembly."""
from __future__ import annotations

import numpy as np


def gauss_interval(points: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre rule on [0, 1]: (abscissae, weights)."""
    s, w = np.polynomial.legendre.leggauss(points)
    return 0.5 * (s + 1.0), 0.5 * w


#: The rule for lengths and lumped weights along edges (exact for straight P2 edges).
EDGE_RULE = gauss_interval(4)


#: Local (a, b, midpoint) node positions of the three edges of a P1 or P2 triangle.
CELL_EDGES = {3: np.array([[0, 1], [1, 2], [2, 0]]), 6: np.array([[0, 1, 3], [1, 2, 4], [2, 0, 5]])}


def cell_edges(cells: np.ndarray) -> np.ndarray:
    """Every cell edge once per cell, ``(3m, 2|3)`` oriented with the cell (with its midpoint for P2)."""
    return cells[:, CELL_EDGES[cells.shape[1]]].reshape(-1, 2 if cells.shape[1] == 3 else 3)


def _used_once(keys: np.ndarray) -> np.ndarray:
    """The values that occur once in the sorted ``keys``."""
    repeated = keys[1:] == keys[:-1]
    once = np.ones(len(keys), dtype=bool)
    once[1:] &= ~repeated
    once[:-1] &= ~repeated
    return keys[once]


def outer_edge_positions(cells: np.ndarray) -> np.ndarray:
    """Where the edges that one cell alone uses stand in :func:`cell_edges` (position p: edge p % 3 of cell
    p // 3): one sort of the edges' keys and a search of each edge among the few used once (no per-edge
    counts: 3× faster than np.unique's)."""
    keys = edge_keys(cell_edges(cells), int(cells.max(initial=0)) + 1)
    once = _used_once(np.sort(keys))
    if not len(once):
        return np.zeros(0, dtype=np.int64)
    at = np.minimum(np.searchsorted(once, keys), len(once) - 1)
    return np.flatnonzero(once[at] == keys)


def outer_edges(cells: np.ndarray) -> np.ndarray:
    """The cell edges ``(e, 2|3)`` that one cell alone uses, oriented with it."""
    return cell_edges(cells)[outer_edge_positions(cells)]


def crowded_edges(corners: np.ndarray) -> int:
    """How many edges more than two triangles of ``corners`` use (overlapping cells)."""
    keys = np.sort(edge_keys(cell_edges(corners), int(corners.max(initial=0)) + 1))
    return len(np.unique(keys[2:][keys[2:] == keys[:-2]]))


def boundary_nodes(corners: np.ndarray, n: int) -> np.ndarray:
    """Whether each of ``n`` nodes ends an edge that one triangle of ``corners`` alone uses."""
    once = _used_once(np.sort(edge_keys(cell_edges(corners), n)))
    boundary = np.zeros(n, dtype=bool)
    boundary[once // n] = boundary[once % n] = True
    return boundary


def edge_keys(edges: np.ndarray, n: int) -> np.ndarray:
    """An integer per undirected edge (its end nodes), for matching."""
    return np.minimum(edges[:, 0], edges[:, 1]).astype(np.int64) * n + np.maximum(edges[:, 0], edges[:, 1])


def edge_points(points: np.ndarray, edges: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``(e, q, 2)`` and tangents dx/ds ``(e, q, 2)`` at parameters ``s`` ``(q,)`` in [0, 1]."""
    shapes, derivatives = edge_shapes(edges.shape[1], s)
    nodes = points[edges]  # (e, k, 2)
    return np.einsum("qk,ekd->eqd", shapes, nodes), np.einsum("qk,ekd->eqd", derivatives, nodes)


def edge_shapes(nodes: int, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lagrange shape functions on an edge (a, b[, midpoint]) and their s-derivatives, ``(q, k)``."""
    s = np.asarray(s, dtype=float)
    if nodes == 2:
        return np.column_stack([1.0 - s, s]), np.column_stack([-np.ones_like(s), np.ones_like(s)])
    shapes = np.column_stack([(1.0 - s) * (1.0 - 2.0 * s), s * (2.0 * s - 1.0), 4.0 * s * (1.0 - s)])
    derivatives = np.column_stack([4.0 * s - 3.0, 4.0 * s - 1.0, 4.0 - 8.0 * s])
    return shapes, derivatives



# --- the reference triangle -----------------------------------------------------------------------
#: Quadrature on the reference triangle (ξ, η ≥ 0, ξ + η ≤ 1): points and weights summing to ½.
#: P1 uses the centroid (gradients are constant); P2 the 6-point rule of degree 4 (Dunavant), exact
#: for straight P2 stiffness and accurate for curved (isoparametric) cells.
_A, _B = 0.445948490915965, 0.091576213509771


TRIANGLE_RULES = {
    3: (np.array([[1.0 / 3.0, 1.0 / 3.0]]), np.array([0.5])),
    6: (np.array([[_A, _A], [1 - 2 * _A, _A], [_A, 1 - 2 * _A], [_B, _B], [1 - 2 * _B, _B], [_B, 1 - 2 * _B]]),
        0.5 * np.array([0.223381589678011] * 3 + [0.109951743655322] * 3)),
}


def quadrature(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """The element rule of P1 (``nodes`` = 3) or P2 (6) cells: reference points ``(q, 2)``, weights ``(q,)``."""
    return TRIANGLE_RULES[nodes]


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
    """At reference points ``xi``: det J ``(m, q)`` and physical gradients ``(m, q, k, 2)`` (read-only views
    for P1 cells, whose map is affine)."""
    if cells.shape[1] == 3:  # straight P1 cells: one Jacobian per cell, the same at every point
        det, gradients = _affine_geometry(points, cells)
        return (np.broadcast_to(det[:, None], (len(cells), len(xi))),
                np.broadcast_to(gradients[:, None], (len(cells), len(xi), 3, 2)))
    _, reference = shape_functions(cells.shape[1], xi)
    nodes = points[cells]  # (m, k, 2)
    jacobian = np.matmul(nodes.transpose(0, 2, 1)[:, None], reference)  # (m, q, d, e) = dx_d/dξ_e
    det = jacobian[..., 0, 0] * jacobian[..., 1, 1] - jacobian[..., 0, 1] * jacobian[..., 1, 0]
    inverse = np.empty_like(jacobian)  # (m, q, e, d) = dξ_e/dx_d
    inverse[..., 0, 0], inverse[..., 1, 1] = jacobian[..., 1, 1], jacobian[..., 0, 0]
    inverse[..., 0, 1], inverse[..., 1, 0] = -jacobian[..., 0, 1], -jacobian[..., 1, 0]
    inverse /= det[..., None, None]
    return det, np.matmul(reference, inverse)  # (m, q, k, d)


def _affine_geometry(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """det J ``(m,)`` and the gradients ``(m, 3, 2)`` of the P1 basis, elementwise from the edge vectors
    (the reference gradients are (−1, −1), (1, 0), (0, 1)): no batched 2×2 products."""
    origin = points[cells[:, 0]]
    first, second = points[cells[:, 1]] - origin, points[cells[:, 2]] - origin  # the columns of J
    det = first[:, 0] * second[:, 1] - second[:, 0] * first[:, 1]
    gradients = np.empty((len(cells), 3, 2))
    gradients[:, 1, 0], gradients[:, 1, 1] = second[:, 1] / det, -second[:, 0] / det  # the rows of J⁻¹
    gradients[:, 2, 0], gradients[:, 2, 1] = -first[:, 1] / det, first[:, 0] / det
    gradients[:, 0] = -(gradients[:, 1] + gradients[:, 2])
    return det, gradients


def field_gradients(values: np.ndarray, gradients: np.ndarray) -> np.ndarray:
    """``(m, q, c, 2)``: ∂v_c/∂x_d at the points of :func:`element_geometry`'s physical ``gradients``
    ``(m, q, k, 2)`` for the nodal values ``(m, k, c)`` of each cell (a read-only view, the same at every
    point, when the gradients are: P1 cells)."""
    if gradients.shape[1] > 1 and gradients.strides[1] == 0:
        at_one = np.matmul(values.transpose(0, 2, 1)[:, None], gradients[:, :1])
        return np.broadcast_to(at_one, (len(at_one), gradients.shape[1]) + at_one.shape[2:])
    return np.matmul(values.transpose(0, 2, 1)[:, None], gradients)
