"""A posteriori error estimate of a 3-D solve (P1 or P2 tetrahedra): Zienkiewicz–Zhu recovery per half.

The plane estimate (:mod:`ddsolve.post.estimate`) one dimension up: in each half the strain of the solution,
discontinuous between tetrahedra, is recovered into a continuous field ε* of the same element space by
superconvergent patch recovery: around every vertex a polynomial of the element degree in (x, y, z) is fitted by
least squares to the six strains at the sampling points of the tetrahedra of its patch (the centroid for P1, the
four points of the degree-2 rule for P2).  A vertex takes its own patch's value, a P2 mid-edge node the mean of its
two ends' patches; a node whose own patches are unusable (on the half's boundary, or too few points) the mean of
the usable interior patches of its tetrahedra's vertices.  The indicator of a tetrahedron K is

    η_K² = ∫_K (ε* − ε_h)ᵀ D (ε* − ε_h),

and the estimate η / sqrt(‖u_h‖²_E + η²) with η² = Σ η_K² over both halves.  Recovery never crosses Σ: each half
is recovered on its own, keeping the jumps of the stress the crack and the gluing forces make.  Everything is
vectorized over tetrahedra, a chunk at a time; no PETSc or MPI here.  The crack adds the plane estimate's contact
term: between the crack's nodes the contact pressure and the opening can both be positive, and 2 |∫_T μᶜ_h [u_h]·ν|
per Σ triangle T goes half to the tetrahedron on each side.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse

from ddsolve.fem import tetra
from ddsolve.mesh.element import TRIANGLE_RULES, shape_functions
from ddsolve.mesh.solid import TETRA_EDGES, TETRA_FACES, boundary_faces, signed_volumes
from ddsolve.post.estimate import Estimate, _solve_spd, rounding_energy

#: Tetrahedra whose temporaries are held at once: the recovery's (a few points each), the indicators' (up to 64
#: quadrature points each); a few tens of MB either way.
CHUNK, QUADRATURE_CHUNK = 2 ** 13, 2 ** 10
#: The points of each element where its strain is sampled for the recovery (reference coordinates).
SAMPLES = {4: tetra.TETRA_RULES[4][0], 10: tetra.TETRA_RULES[10][0]}


def _chunks(count: int, size: int = CHUNK):
    """Consecutive slices of ``range(count)`` of at most ``size`` items."""
    return (slice(start, min(start + size, count)) for start in range(0, count, size))


def strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """The Voigt strains ``(m, q, 6)`` (xx, yy, zz, yz, xz, xy; engineering shears) of ``u`` ``(n, 3)`` at the
    reference points ``xi`` of every tetrahedron."""
    grads, _ = tetra.gradients(points, cells, xi)  # (m, q, k, 3)
    G = np.einsum("mqkj,mkd->mqdj", grads, u[cells])  # ∂u_d/∂x_j
    return np.stack([G[..., 0, 0], G[..., 1, 1], G[..., 2, 2], G[..., 1, 2] + G[..., 2, 1],
                     G[..., 0, 2] + G[..., 2, 0], G[..., 0, 1] + G[..., 1, 0]], axis=-1)


def monomials(local: np.ndarray, degree: int) -> np.ndarray:
    """``(..., b)``: 1, x, y, z (and the six products of two for degree 2) at local coordinates ``(..., 3)``."""
    x, y, z = local[..., 0], local[..., 1], local[..., 2]
    terms = [np.ones_like(x), x, y, z]
    if degree == 2:
        terms += [x * x, x * y, x * z, y * y, y * z, z * z]
    return np.stack(terms, axis=-1)


def collapsed_rule(points_per_axis: int) -> tuple[np.ndarray, np.ndarray]:
    """A quadrature on the reference tetrahedron from Gauss–Legendre on the cube collapsed onto it (Duffy): exact
    for polynomials of degree 2 ``points_per_axis`` − 3; points ``(q, 3)``, weights summing to 1/6."""
    nodes, weights = np.polynomial.legendre.leggauss(points_per_axis)
    t, w = 0.5 * (nodes + 1.0), 0.5 * weights
    u, v, s = (a.ravel() for a in np.meshgrid(t, t, t, indexing="ij"))
    wu, wv, ws = (a.ravel() for a in np.meshgrid(w, w, w, indexing="ij"))
    xi = np.column_stack([u, v * (1.0 - u), s * (1.0 - u) * (1.0 - v)])
    return xi, wu * wv * ws * (1.0 - u) ** 2 * (1.0 - v)


def _degree(cells: np.ndarray) -> int:
    return 1 if cells.shape[1] == 4 else 2


def _patch_scale(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Per vertex the root mean square of the longest edge of its tetrahedra: the patch's coordinates scale."""
    corners = cells[:, :4]
    ends = points[corners[:, TETRA_EDGES]]  # (m, 6, 2, 3)
    longest = np.linalg.norm(ends[:, :, 1] - ends[:, :, 0], axis=2).max(axis=1)
    sums = np.bincount(corners.ravel(), np.repeat(longest ** 2, 4), minlength=len(points))
    count = np.bincount(corners.ravel(), minlength=len(points))
    return np.sqrt(sums / np.maximum(count, 1))


def _patch_fits(points: np.ndarray, cells: np.ndarray, u: np.ndarray, scale: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Every vertex's least-squares polynomial ``(n, b, 6)`` in coordinates about it over ``scale``, and which fits
    are well conditioned."""
    degree, n = _degree(cells), len(points)
    b = 4 if degree == 1 else 10
    xi = SAMPLES[cells.shape[1]]
    shapes = tetra.tetra_shapes(4, xi)[0]  # straight edges: positions from the vertices
    normal, moments = np.zeros((n, b * b)), np.zeros((n, b * 6))
    for chunk in _chunks(len(cells)):
        part = cells[chunk]
        where = np.einsum("qk,mkd->mqd", shapes, points[part[:, :4]])  # (c, q, 3)
        strain = strains(points, part, u, xi)  # (c, q, 6)
        vertex = part[:, :4].ravel()
        local = (np.repeat(where, 4, axis=0) - points[vertex][:, None]) / scale[vertex][:, None, None]
        basis = monomials(local, degree)  # (4c, q, b)
        incidence = scipy.sparse.csr_matrix((np.ones(len(vertex)), (vertex, np.arange(len(vertex)))),
                                            shape=(n, len(vertex)))
        normal += incidence @ np.einsum("pqi,pqj->pij", basis, basis).reshape(len(vertex), -1)
        moments += incidence @ np.einsum("pqi,pqd->pid", basis, np.repeat(strain, 4, axis=0)).reshape(len(vertex), -1)
    used = np.flatnonzero(np.bincount(cells[:, :4].ravel(), minlength=n))
    fits = np.zeros((n, b, 6))
    solved, good = _solve_spd(normal[used].reshape(-1, b, b), moments[used].reshape(-1, b, 6))
    fits[used] = solved
    usable = np.zeros(n, dtype=bool)
    usable[used] = good
    return fits, usable


def _means(points: np.ndarray, pairs: np.ndarray, fits: np.ndarray, scale: np.ndarray, use: np.ndarray,
           degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Per node the mean over the (node, vertex) ``pairs`` whose vertex has ``use`` of the vertex's polynomial at
    the node: values ``(n, 6)`` and whether a node got any."""
    pairs = pairs[use[pairs[:, 1]]]
    node, vertex = pairs[:, 0], pairs[:, 1]
    values = np.einsum("pb,pbd->pd", monomials((points[node] - points[vertex]) / scale[vertex][:, None], degree),
                       fits[vertex])
    count = np.bincount(node, minlength=len(points))
    sums = np.stack([np.bincount(node, values[:, d], minlength=len(points)) for d in range(6)], axis=1).astype(float)
    found = count > 0
    sums[found] /= count[found][:, None]
    return sums, found


def _unique_pairs(pairs: np.ndarray) -> np.ndarray:
    return np.unique(pairs, axis=0)


def recovered_strain(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``(n, 6)``: the recovered Voigt strain at every node of a half (``u`` ``(n, 3)``)."""
    degree = _degree(cells)
    scale = _patch_scale(points, cells)
    fits, usable = _patch_fits(points, cells, u, scale)
    outer = np.zeros(len(points), dtype=bool)
    outer[boundary_faces(cells[:, :4])] = True
    interior = usable & ~outer
    corners = np.unique(cells[:, :4])
    own = [np.column_stack([corners, corners])]
    if degree == 2:
        for e, (a, b) in enumerate(TETRA_EDGES):
            own += [cells[:, [4 + e, a]], cells[:, [4 + e, b]]]
    out, found = _means(points, _unique_pairs(np.concatenate(own)), fits, scale, interior, degree)
    missing = ~found
    if missing.any():
        near = cells[missing[cells].any(axis=1)]
        pairs = np.stack(np.broadcast_arrays(near[:, :, None], near[:, None, :4]), axis=-1).reshape(-1, 2)
        pairs = _unique_pairs(pairs)
        for level in (usable, interior):  # the interior patches of its tetrahedra override the boundary ones
            values, got = _means(points, pairs, fits, scale, level, degree)
            take = missing & got
            out[take] = values[take]
    return out


def half_indicators(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``(2, m)``: per tetrahedron η_K² = ∫ (ε* − ε_h)ᵀ D (ε* − ε_h) and ∫ ε_hᵀ D ε_h, for ``u`` ``(n, 3)``."""
    k = cells.shape[1]
    recovered = recovered_strain(points, cells, u)
    xi, w = collapsed_rule(_degree(cells) + 2)  # exact for (ε* − ε_h)² of degree 2 p
    values = tetra.tetra_shapes(k, xi)[0]  # (q, k)
    dets = 6.0 * np.abs(signed_volumes(points, cells[:, :4]))  # straight edges: det J per tetrahedron
    out = np.empty((2, len(cells)))
    for chunk in _chunks(len(cells), QUADRATURE_CHUNK):
        strain = strains(points, cells[chunk], u, xi)  # (c, q, 6)
        difference = np.einsum("qk,ckd->cqd", values, recovered[cells[chunk]]) - strain
        for row, field in enumerate((difference, strain)):
            out[row, chunk] = np.einsum("cqi,ij,cqj,q->c", field, D, field, w) * dets[chunk]
    return out


def contact_indicators(result) -> list[np.ndarray]:
    """Per tetrahedron of the lower and the upper half: half of 2 |∫_T μᶜ_h [u_h]·ν| for its triangles T on Σ, the
    contact pressure and the opening interpolated between the crack's nodes, where the discrete contact conditions
    hold (the plane estimate's contact term, :func:`ddsolve.post.estimate.contact_indicators`)."""
    halves, sigma = result.mesh.halves, result.mesh.sigma
    out = [np.zeros(len(half.tetrahedra)) for half in halves]
    if not np.any(result.pressure):
        return out
    xi, w = TRIANGLE_RULES[6]  # degree 4: exact for the product of two quadratics
    shapes = shape_functions(sigma.triangles.shape[1], xi)[0]  # (q, k)
    a, b, c = (sigma.points[sigma.triangles[:, k]] for k in range(3))
    areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    product = (result.pressure[sigma.triangles] @ shapes.T) * (result.normal_opening[sigma.triangles] @ shapes.T)
    defect = np.abs(product @ w) * 2.0 * areas  # |∫_T μ [u]·ν|: the rule's weights sum to ½
    for cells, half in zip(out, halves):
        np.add.at(cells, _face_owners(half.tetrahedra[:, :4], half.sigma_nodes[sigma.triangles[:, :3]]), defect)
    return out


def _face_owners(tetrahedra: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The tetrahedron each of the boundary ``triangles`` ``(t, 3)`` is a face of."""
    faces = np.sort(tetrahedra[:, TETRA_FACES].reshape(-1, 3), axis=1)
    _, inverse = np.unique(np.vstack([faces, np.sort(triangles, axis=1)]), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    owner = np.full(int(inverse.max()) + 1, -1, dtype=np.int64)
    owner[inverse[:len(faces)]] = np.arange(len(faces)) // 4
    return owner[inverse[len(faces):]]


def of_result(result) -> Estimate:
    """The estimate of a 3-D result (:class:`~ddsolve.post.solid.SolidResult`): indicators η_K per tetrahedron of
    each half (with the contact term, :func:`contact_indicators`), ‖u_h‖²_E, and the rounding level of a
    strain-free field."""
    laws = [tetra.elastic_matrix(result.scene.material("layer1", half.name)) for half in result.mesh.halves]
    parts = [half_indicators(half.points, half.tetrahedra, D, u)
             for half, D, u in zip(result.mesh.halves, laws, result.fields)]
    contact = contact_indicators(result)
    largest = max(float(np.abs(u).max(initial=0.0)) for u in result.fields)
    return Estimate({half.name: np.sqrt(np.maximum(part[0] + extra, 0.0))
                     for half, part, extra in zip(result.mesh.halves, parts, contact)},
                    float(sum(part[1].sum() for part in parts)),
                    rounding_energy(max(float(np.abs(D).max()) for D in laws), largest))
