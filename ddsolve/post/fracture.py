"""Will the crack grow?  The energy release rate G at every crack tip, by the domain (G-θ) integral.

G at a tip is −dΠ/da: how fast the total potential energy Π falls as that tip moves along Σ, away
from its crack (Griffith: the crack grows where G ≥ G_c).  Move the points of both halves by tθ,
with θ = φ(r) t(x): t the unit tangent of Σ pointing away from the crack (for a curved Σ, the tangent
at the nearest point of Σ, interpolated between the Σ nodes, so that θ is tangent to Σ on Σ),
φ = 1 for r ≤ inner, 0 for r ≥ outer, linear between, r the distance to the tip; the same θ in both
layers and both halves.  Without body forces and with no load where θ ≠ 0, the derivative of the
minimal energy at t = 0 is

    G = Σ over the four blocks ∫ [σ_ij u_i,k θ_k,j − ½ σ_ij ε_ij θ_k,k] dΩ  −  Σ_k λ_k (u⁻_k − u⁺_k)·ν̇_k.

The gluing constraints (u⁻ = u⁺ off the cracks, u± = v± on Σ) compare displacements at the same Σ
node, which θ moves as one, so they contribute nothing.  Non-penetration (u⁻ − u⁺)·ν_k ≤ 0 depends on
the node's normal: a node moving by θ_k·τ_k along a curved Σ sees its normal turn, ν̇_k =
(dν/ds)(θ_k·τ_k), and the last sum (λ_k = w_k μᶜ_k, the nodal contact force) accounts for that; it is
zero on a straight Σ and wherever the faces do not touch.

With friction on the crack faces (``contact.friction``, ``contact.slip_bound``) G is −dΠ/da less the rate of
frictional dissipation: the friction tractions μ_t are taken as loads on the faces inside θ's support, which adds
the face term −Σ_k μ_t,k s_k ẇ_k (s the slip, w_k the node's weight; :func:`friction_terms`).

Discretely this is exact: θ is interpolated with the element's own basis (P1 or P2 nodes) and
integrated with the element quadrature, so G is the derivative of the discrete energy Π_h with
respect to moving the mesh nodes by θ (tests/test_fracture.py checks it against finite differences).

The radii come from the geometry: ``outer`` is half the distance from the tip to the nearest other
tip, point of the outer boundary (loaded, free or clamped) or kink of Σ, ``inner`` half of ``outer``;
the scene's ``[fracture] inner, outer`` override them.

G splits into opening and sliding (:func:`mode_split`): by the domain integral of the parts of the fields
symmetric and antisymmetric about Σ where the θ disc is mirror-symmetric, else by virtual crack closure of
the tip's gluing forces (docs/fracture.md, "Modes I and II"); between regions of different materials (an
interface crack) by K from the interaction integral and the phase ψ at a reference length
(:mod:`ddsolve.post.interface_crack`).  No PETSc or MPI here.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ddsolve.errors import SceneError
from ddsolve.fem import assembly
from ddsolve.mesh import element
from ddsolve.mesh.mesh import SIGMA, HalfMesh, Mesh, SigmaLine, blocks as block_list, partner
from ddsolve.post import interface_crack
from ddsolve.post.result import Fracture, OnSigma
from ddsolve.post.toughness import judge
from ddsolve.problem.materials import Bimaterial
from ddsolve.problem.scene import Scene

#: Σ turns by more than this between two edges at a kink (a smooth curve turns by h·κ per edge).
KINK_DEGREES = 10.0
#: Default radii: outer = OUTER_FRACTION × the distance to the nearest obstacle, inner = INNER_FRACTION × outer.
OUTER_FRACTION = 0.5
INNER_FRACTION = 0.5
#: Σ is straight when its normals agree to this.
STRAIGHT = 1e-10


@dataclass(frozen=True)
class Tip:
    """A crack tip: its Σ node, crack (runs of crack nodes counted along Σ), extension direction and radii.

    ``clearance`` is the distance to the nearest ``obstacle`` θ must avoid; ``spacing`` the mean length
    of the Σ edges at the tip.
    """

    node: int
    crack: int
    point: np.ndarray
    direction: np.ndarray
    inner: float
    outer: float
    clearance: float
    obstacle: str
    spacing: float

    @property
    def elements(self) -> float:
        """Σ edges within the inner radius (a few or more for an accurate G)."""
        return self.inner / self.spacing

    def describe(self) -> str:
        return f"({self.point[0]:.6g}, {self.point[1]:.6g})"



# --- tips and radii -----------------------------------------------------------------------------
def find_tips(mesh: Mesh, inner: float | None = None, outer: float | None = None) -> list[Tip]:
    """Every crack tip of ``mesh`` with its extension direction and θ radii (given ones checked)."""
    sigma = mesh.sigma
    tangents = sigma.frames[:, 0]
    found = []  # (node, crack, sign of the extension along Σ's direction of travel)
    for crack, (first, last) in enumerate(sigma.pieces(sigma.crack)):
        for node, sign in ((first - 1, -1.0), (last + 1, 1.0)):
            if 0 <= node < len(sigma.points) and sigma.tip[node]:
                found.append((node, crack, sign))
    if not found:
        return []
    points = sigma.points[[node for node, _, _ in found]]
    segments = _outer_boundary(mesh)
    kinks = _kinks(sigma)
    corners = np.flatnonzero(sigma.corner)
    tips = []
    for i, (node, crack, sign) in enumerate(found):
        point = points[i]
        obstacles = [(float(_segment_distance(point, segments).min(initial=np.inf)), "the outer boundary")]
        for other in np.delete(points, i, axis=0):
            obstacles.append((float(np.linalg.norm(other - point)),
                              f"the crack tip at ({other[0]:.6g}, {other[1]:.6g})"))
        for kink in kinks:
            obstacles.append((float(np.linalg.norm(kink - point)), f"the kink of Σ at ({kink[0]:.6g}, {kink[1]:.6g})"))
        clearance, obstacle = min(obstacles)
        where = f"the crack tip at ({point[0]:.6g}, {point[1]:.6g})"
        if outer is not None and outer >= clearance:
            raise SceneError(f"fracture.outer = {outer:g}: the θ disc around {where} reaches {obstacle} "
                             f"(at distance {clearance:.4g}); θ must vanish there")
        radius = outer if outer is not None else OUTER_FRACTION * clearance
        small = inner if inner is not None else INNER_FRACTION * radius
        if small >= radius:
            raise SceneError(f"fracture.inner = {small:g} must be below the outer radius {radius:.4g} at {where}")
        position = int(np.searchsorted(corners, node))
        neighbours = corners[[j for j in (position - 1, position + 1) if 0 <= j < len(corners)]]
        spacing = float(np.mean(np.linalg.norm(sigma.points[neighbours] - point, axis=1)))
        tips.append(Tip(node, crack, point.copy(), sign * tangents[node], float(small), float(radius),
                        clearance, obstacle, spacing))
    return tips


def _outer_boundary(mesh: Mesh) -> np.ndarray:
    """``(s, 2, 2)`` straight pieces of the boundary of both halves without Σ (P2 edges in two pieces)."""
    pieces = []
    for half in mesh.halves:
        edges = half.boundary_edges
        n = len(half.points)
        keys = np.minimum(edges[:, 0], edges[:, 1]) * n + np.maximum(edges[:, 0], edges[:, 1])
        on_sigma = half.edges(SIGMA)
        sigma_keys = np.minimum(on_sigma[:, 0], on_sigma[:, 1]) * n + np.maximum(on_sigma[:, 0], on_sigma[:, 1])
        edges = edges[~np.isin(keys, sigma_keys)]
        chain = [[0, 1]] if edges.shape[1] == 2 else [[0, 2], [2, 1]]
        pieces.extend(half.points[edges[:, pair]] for pair in chain)
    return np.concatenate(pieces) if pieces else np.zeros((0, 2, 2))


def _segment_distance(point: np.ndarray, segments: np.ndarray) -> np.ndarray:
    a, b = segments[:, 0], segments[:, 1]
    d = b - a
    s = np.clip(np.einsum("sd,sd->s", point - a, d) / np.maximum(np.einsum("sd,sd->s", d, d), 1e-300), 0.0, 1.0)
    return np.linalg.norm(a + s[:, None] * d - point, axis=1)


def _kinks(sigma: SigmaLine) -> np.ndarray:
    """Corners where Σ turns by more than KINK_DEGREES between consecutive edges."""
    corners = sigma.points[sigma.corner]
    chords = np.diff(corners, axis=0)
    chords /= np.linalg.norm(chords, axis=1, keepdims=True)
    cosine = np.einsum("sd,sd->s", chords[:-1], chords[1:])
    return corners[1:-1][cosine < np.cos(np.radians(KINK_DEGREES))]


# --- the θ field --------------------------------------------------------------------------------
def theta(tip: Tip, sigma: SigmaLine, points: np.ndarray) -> np.ndarray:
    """θ ``(n, 2)`` at ``points``: φ(r) times the extension direction (along Σ's tangent)."""
    r = np.linalg.norm(points - tip.point, axis=1)
    weight = np.clip((tip.outer - r) / (tip.outer - tip.inner), 0.0, 1.0)
    out = np.zeros_like(points, dtype=np.float64)
    near = np.flatnonzero(weight > 0.0)
    if len(near):
        out[near] = weight[near, None] * _directions(tip, sigma, points[near])
    return out


def _directions(tip: Tip, sigma: SigmaLine, points: np.ndarray) -> np.ndarray:
    """Unit tangents of Σ at the points of Σ nearest to ``points``, oriented like the tip's direction."""
    if np.abs(sigma.normals - sigma.normals[0]).max() <= STRAIGHT:
        return np.broadcast_to(tip.direction, points.shape)
    tangents = sigma.frames[:, 0] * np.sign(sigma.frames[tip.node, 0] @ tip.direction)
    a, b = sigma.points[:-1], sigma.points[1:]
    reach = 2.0 * tip.outer + np.linalg.norm(b - a, axis=1).max()
    keep = np.flatnonzero(np.minimum(np.linalg.norm(a - tip.point, axis=1), np.linalg.norm(b - tip.point, axis=1))
                          <= reach)
    a, d = a[keep], b[keep] - a[keep]
    s = np.clip(np.einsum("nsd,sd->ns", points[:, None, :] - a[None], d) / np.einsum("sd,sd->s", d, d), 0.0, 1.0)
    distance = np.linalg.norm(a[None] + s[..., None] * d[None] - points[:, None, :], axis=2)
    nearest = np.argmin(distance, axis=1)
    s = s[np.arange(len(points)), nearest][:, None]
    direction = (1.0 - s) * tangents[keep[nearest]] + s * tangents[keep[nearest] + 1]
    return direction / np.linalg.norm(direction, axis=1, keepdims=True)


# --- the integrals --------------------------------------------------------------------------------
def volume_terms(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray, fields: list[np.ndarray],
                 thermal: assembly.ThermalLoad | None = None) -> np.ndarray:
    """∫ [σ_ij u_i,k θ_k,j − ½ σ:(ε − ε₀) div θ] + eigenstrain term, over the ``cells`` on ``points`` (a half,
    or the cells a rank owns of it), for each nodal θ ``(n, 2)`` in ``fields``.

    ``u`` ``(n, 2)`` in x, y; σ = D (ε − ε₀) (Voigt, engineering shear), the mechanical stress, with the
    eigenstrain ε₀ = e ΔT of ``thermal`` (e, ΔT) (zero without), so ½ σ:(ε − ε₀) is the in-plane energy density.
    """
    out = np.zeros(len(fields))
    sampled = Sampled.of(points, cells, D, u, fields, thermal)
    if sampled is None:
        return out
    density = 0.5 * np.sum(sampled.stress * sampled.strain, axis=-1)
    momentum = np.matmul(sampled.grad_u.swapaxes(-1, -2), tensor(sampled.stress))  # σ_ij u_i,k as (k, j)
    for i, field in enumerate(fields):
        grad_theta = sampled.gradient(field)  # θ_k,j
        integrand = (momentum * grad_theta).sum(axis=(-1, -2)) - density * (grad_theta[..., 0, 0]
                                                                           + grad_theta[..., 1, 1])
        if thermal is not None:
            integrand = integrand + sampled.eigenstrain(sampled.stress, field, thermal)
        out[i] = float(np.sum(sampled.volume * integrand))
    return out


def interaction_terms(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray, fields: list[np.ndarray],
                      auxiliary: list, thermal: assembly.ThermalLoad | None = None) -> np.ndarray:
    """``(len(fields), 2)``: the interaction integrals of ``u`` with the two auxiliary fields of each θ in
    ``fields`` (``auxiliary``: for each, a function of the quadrature points ``(m, q, 2)`` giving their
    gradients ``(2, m, q, 2, 2)``, :func:`ddsolve.post.interface_crack.global_gradients`), over ``cells`` as
    :func:`volume_terms`: ∫ [σ_ij ũ_i,k + σ̃_ij u_i,k] θ_k,j − σ̃:(ε − ε₀) div θ + σ̃ : ∂ε₀/∂x_k θ_k."""
    out = np.zeros((len(fields), 2))
    sampled = Sampled.of(points, cells, D, u, fields, thermal)
    if sampled is None:
        return out
    for i, (field, gradients) in enumerate(zip(fields, auxiliary)):
        grad_theta = sampled.gradient(field)
        # where ∇θ = 0 only an eigenstrain's gradient term is left: skip those points without one
        near = np.ones(grad_theta.shape[:2], dtype=bool) if thermal is not None else np.any(grad_theta != 0.0,
                                                                                              axis=(-1, -2))
        for k, grad_aux in enumerate(gradients(sampled.points[near])):
            stress = assembly.voigt_strain(grad_aux) @ D.T
            momentum = (np.matmul(grad_aux.swapaxes(-1, -2), tensor(sampled.stress[near]))
                        + np.matmul(sampled.grad_u[near].swapaxes(-1, -2), tensor(stress)))
            integrand = ((momentum * grad_theta[near]).sum(axis=(-1, -2))
                         - np.sum(stress * sampled.strain[near], axis=-1) * (grad_theta[near][..., 0, 0]
                                                                            + grad_theta[near][..., 1, 1]))
            if thermal is not None:
                integrand = integrand + sampled.eigenstrain(stress.reshape(sampled.stress.shape), field,
                                                            thermal)[near]
            out[i, k] = float(np.sum(sampled.volume[near] * integrand))
    return out


def tensor(voigt: np.ndarray) -> np.ndarray:
    """``(..., 2, 2)`` stress tensors from Voigt ``(..., 3)``."""
    return np.stack([np.stack([voigt[..., 0], voigt[..., 2]], -1), np.stack([voigt[..., 2], voigt[..., 1]], -1)], -2)


@dataclass(frozen=True)
class Sampled:
    """A block's field at the quadrature points of the cells where any θ is non-zero: the cells, the reference
    rule, det J × weight ``volume`` ``(m, q)``, the shape gradients, the points ``(m, q, 2)``, u_d,e, the strain
    ε − ε₀ and the stress D (ε − ε₀)."""

    points_of: np.ndarray
    cells: np.ndarray
    xi: np.ndarray
    volume: np.ndarray
    shape_gradients: np.ndarray
    points: np.ndarray
    grad_u: np.ndarray
    strain: np.ndarray
    stress: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray, fields: list[np.ndarray],
           thermal: assembly.ThermalLoad | None) -> Sampled | None:
        support = np.zeros(len(points), dtype=bool)
        for field in fields:
            support |= np.any(field != 0.0, axis=1)
        cells = cells[support[cells].any(axis=1)]
        if len(cells) == 0:
            return None
        xi, weights = element.quadrature(cells.shape[1])
        det, gradients = element.element_geometry(points, cells, xi)
        shapes, _ = element.shape_functions(cells.shape[1], xi)
        grad_u = element.field_gradients(u[cells], gradients)  # u_d,e
        strain = assembly.voigt_strain(grad_u)
        if thermal is not None:
            strain = strain - thermal.eigenstrains(points, cells, xi)
        return cls(points, cells, xi, det * weights, gradients, np.einsum("qk,mkd->mqd", shapes, points[cells]),
                   grad_u, strain, strain @ D.T)

    def gradient(self, field: np.ndarray) -> np.ndarray:
        """θ_k,j ``(m, q, 2, 2)`` of a nodal field."""
        return element.field_gradients(field[self.cells], self.shape_gradients)

    def eigenstrain(self, stress: np.ndarray, field: np.ndarray, thermal: assembly.ThermalLoad) -> np.ndarray:
        """:func:`eigenstrain_term` with ``stress`` ``(m, q, 3)``."""
        return eigenstrain_term(self.points_of, self.cells, self.xi, self.shape_gradients, stress, field, thermal)


def eigenstrain_term(points: np.ndarray, cells: np.ndarray, xi: np.ndarray, gradients: np.ndarray, stress: np.ndarray,
                     field: np.ndarray, thermal: assembly.ThermalLoad) -> np.ndarray:
    """σ : (∂ε₀/∂x_k) θ_k at the quadrature points ``(m, q)``: the part of −dΠ/da an eigenstrain that varies
    in space adds (Shih, Moran and Nakamura 1986, eq. 13: J = ∫ [σ_ij u_i,1 − W δ_1j] q_,j dA +
    ∫ σ_ij ∂ε₀_ij/∂x_1 q dA, with W the energy of ε − ε₀).  ε₀ = e ΔT; ∇ΔT from ΔT interpolated at the nodes."""
    eigenstrain, temperature = thermal
    nodal = np.asarray(temperature(points[cells][..., 0], points[cells][..., 1]), dtype=np.float64)
    grad_change = np.einsum("mk,mqkd->mqd", np.broadcast_to(nodal, cells.shape), gradients)
    shapes, _ = element.shape_functions(cells.shape[1], xi)
    theta_q = np.einsum("qk,mkd->mqd", shapes, field[cells])
    return (stress @ eigenstrain) * np.einsum("mqd,mqd->mq", grad_change, theta_q)


def block_terms(scene, sigma: SigmaLine, tips: list[Tip], parts: dict[int, tuple]) -> np.ndarray:
    """Sum of the volume terms for every tip over ``parts``: block index -> (points, cells, u), cells of the
    block's half (all, or those a rank owns) and the displacements ``(n, 2)`` (x, y) at the points; ``(2t,)``:
    each tip's with its θ, then with its :func:`halved` one; between different materials with a pair
    (:func:`ddsolve.post.interface_crack.interface_pair`) ``(4t,)``: then each tip's interaction integrals
    with the tip fields of K = 1 and K = i (NaN where Σ is not straight in the disc)."""
    contours = tips + [halved(tip) for tip in tips]
    pair = interface_crack.interface_pair(scene)
    crack = isinstance(pair, Bimaterial)
    out = np.zeros(len(contours) + (2 * len(tips) if crack else 0))
    if not tips:
        return out
    for index, (points, cells, u) in parts.items():
        spec = block_list(scene.geometry.layers)[index]
        D = assembly.elasticity(scene, spec.layer, spec.region)[0]
        thermal = assembly.thermal_of(scene, spec.layer, spec.region)
        fields = [theta(tip, sigma, points) for tip in contours]
        out[:len(contours)] += volume_terms(points, cells, D, u, fields, thermal)
        if crack:
            auxiliary = [interface_crack.tip_fields(tip, sigma, pair, spec.side) for tip in tips]
            out[len(contours):] += interaction_terms(points, cells, D, u, fields[:len(tips)], auxiliary,
                                                     thermal).ravel()
    if crack:
        straight = np.repeat([straight_near(tip, sigma) for tip in tips], 2)
        out[len(contours):] = np.where(straight, out[len(contours):], np.nan)
    return out


def halved(tip: Tip) -> Tip:
    """The tip with the second θ contour: radii (inner/2, inner).  The exact G does not depend on the
    contour; the two discrete ones differ by the discretization error, G's noise level (:func:`finish`)."""
    return dataclasses.replace(tip, inner=0.5 * tip.inner, outer=tip.inner)


def contact_terms(tips: list[Tip], on: OnSigma) -> np.ndarray:
    """Σ_k λ_k (u⁻_k − u⁺_k)·ν̇_k per tip: the work of the contact forces on the turning normals."""
    out = np.zeros(len(tips))
    sigma = on.sigma
    mu = on.multipliers["mu_c"]
    if not tips or not np.any(mu != 0.0) or np.abs(sigma.normals - sigma.normals[0]).max() <= STRAIGHT:
        return out
    nodes = sigma.multiplier_nodes
    turning = np.gradient(sigma.normals, sigma.arclength, axis=0)[nodes]  # dν/ds
    gap = on.gap
    force = sigma.weights[nodes] * mu
    tangents = sigma.frames[nodes, 0]
    for i, tip in enumerate(tips):
        speed = np.einsum("kd,kd->k", theta(tip, sigma, sigma.points[nodes]), tangents)  # ds/dt of each node
        out[i] = float(np.sum(force * speed * np.einsum("kd,kd->k", gap, turning)))
    return out


def friction_terms(tips: list[Tip], on: OnSigma) -> np.ndarray:
    """Σ_k μ_t,k s_k dw_k/dt per tip: the rate at which the friction tractions μ_t, taken as loads on the crack
    faces, change the potential energy as θ moves the Σ nodes (s = (u⁻ − u⁺)·τ the slip, w_k = ∫ φ_k ds its
    node's weight); zero without friction.  G = −dΠ/da less the frictional dissipation is the volume terms less
    this: the continuous −∫ μ_t s dθ_s/ds ds = ∫ μ_t θ_s ds/ds ds, the domain integral's face term of a loaded crack."""
    out = np.zeros(len(tips))
    mu = on.multipliers.get("mu_t")
    if mu is None or not tips or not np.any(mu != 0.0):
        return out
    sigma = on.sigma
    nodes = sigma.multiplier_nodes
    work = np.zeros(len(sigma.points))
    work[nodes] = mu * np.einsum("kd,kd->k", on.gap, sigma.frames[nodes, 0])
    for i, tip in enumerate(tips):
        out[i] = float(work @ weight_rates(sigma, theta(tip, sigma, sigma.points)))
    return out


def weight_rates(sigma: SigmaLine, field: np.ndarray) -> np.ndarray:
    """d/dt of the Σ nodes' weights w_k = ∫ φ_k ds (:func:`ddsolve.mesh.mesh.sigma_line`) as the nodes move by
    t × ``field`` ``(s, 2)``."""
    step = 1 if sigma.corner.all() else 2
    count = len(sigma.points)
    edges = np.column_stack([np.arange(0, count - 1, step), np.arange(step, count, step)]
                            + ([np.arange(1, count, step)] if step == 2 else []))
    s, w = element.EDGE_RULE
    shapes, derivatives = element.edge_shapes(edges.shape[1], s)
    tangents = np.einsum("qk,ekd->eqd", derivatives, sigma.points[edges])
    rates = np.einsum("qk,ekd->eqd", derivatives, field[edges])
    speed = np.einsum("eqd,eqd->eq", tangents, rates) / np.linalg.norm(tangents, axis=2)  # d|dx/ds|/dt
    return np.bincount(edges.ravel(), np.einsum("eq,q,qk->ek", speed, w, shapes).ravel(), minlength=count)


def sigma_terms(tips: list[Tip], on: OnSigma) -> np.ndarray:
    """The Σ terms G subtracts from the volume terms: the contact forces' on the turning normals
    (:func:`contact_terms`) and the friction's (:func:`friction_terms`)."""
    return contact_terms(tips, on) + friction_terms(tips, on)


def finish(tips: list[Tip], volume: np.ndarray, on: OnSigma, split: dict[str, np.ndarray] | None, scene: Scene,
           factors: np.ndarray | None = None) -> Fracture:
    """G = volume terms − Σ terms (:func:`sigma_terms`), and the contact zones (without the ``scene``'s non-penetration: the
    zones where the faces overlap), from the Σ data ``on`` of a result
    (:attr:`ddsolve.post.result.Result.on_sigma`); ``split``: G's split into modes I and II
    (:func:`mode_split`), or none (``volume`` with the interaction integrals of :func:`block_terms`: the
    interface crack's, :func:`ddsolve.post.interface_crack.interface_split`), its ψ left undefined (NaN)
    where G is no release rate
    (:meth:`~ddsolve.post.result.Fracture.released`); the scene's toughness and the critical load factors
    (``factors`` where a root solve found them: :func:`ddsolve.post.toughness.judge`)."""
    from ddsolve.post.analysis import contact_zones, overlap_zones

    contact = sigma_terms(tips, on)
    if split is not None:  # the friction acts along the faces: its term is sliding's (mode II)
        split = {**split, "G_II": split["G_II"] - friction_terms(tips, on)}
    sigma = on.sigma
    crack_of = np.full(len(sigma.points), -1)
    for index, (first, last) in enumerate(sigma.pieces(sigma.crack)):
        crack_of[first:last + 1] = index
    nodes = sigma.multiplier_nodes
    arc = sigma.arclength[nodes]

    def located(runs: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
        """Runs of multiplier nodes as arc length ``(z, 2)`` and the crack of each ``(z,)``."""
        runs = np.array(runs, dtype=np.int64).reshape(-1, 2)
        return arc[runs].reshape(-1, 2), crack_of[nodes[runs[:, 0]]].astype(np.int64)

    zones, zone_crack = located(contact_zones(on) if scene.nonpenetration else [])
    overlaps, overlap_crack = located([] if scene.nonpenetration else overlap_zones(on))
    volume = np.asarray(volume, dtype=np.float64)
    interaction = volume[2 * len(tips):] if tips and len(volume) == 4 * len(tips) else None
    G, noise = release_and_noise(tips, volume if interaction is None else volume[:2 * len(tips)], contact, on)
    if interaction is not None:
        closed = [_behind(tip, on, scene.nonpenetration)[2] for tip in tips]
        split = interface_crack.interface_split(tips, G, interaction.reshape(-1, 2), sigma, scene, np.array(closed))
    out = Fracture(
        points=np.array([tip.point for tip in tips]).reshape(-1, 2),
        directions=np.array([tip.direction for tip in tips]).reshape(-1, 2),
        crack=np.array([tip.crack for tip in tips], dtype=np.int64),
        inner=np.array([tip.inner for tip in tips]), outer=np.array([tip.outer for tip in tips]),
        spacing=np.array([tip.spacing for tip in tips]), G=G, contact=contact, zones=zones, zone_crack=zone_crack,
        overlaps=overlaps, overlap_crack=overlap_crack, noise=noise, **(split or {}),
        reference_length=interface_crack.reference_length(scene),
    )
    out.phase = np.where(out.released(), out.phase, np.nan)
    return judge(out, scene, factors)


def release_and_noise(tips: list[Tip], volume: np.ndarray, contact: np.ndarray, on: OnSigma
                      ) -> tuple[np.ndarray, np.ndarray]:
    """G at each tip and its noise level: |G − G'|, G' the domain integral on the :func:`halved` contour
    (``volume`` ``(2t,)`` from :func:`block_terms`), at least −G (the exact G is never negative: G = −dΠ/da
    releases a constraint) and the rounding of the integral; NaN without the second contour."""
    count = len(tips)
    G = volume[:count] - contact
    if len(volume) != 2 * count:
        return G, np.full(count, np.nan)
    other = volume[count:] - sigma_terms([halved(tip) for tip in tips], on)
    rounding = ROUNDING * np.maximum(np.abs(G), np.abs(other))
    return G, np.maximum.reduce([np.abs(G - other), -G, rounding]) if count else np.zeros(0)


#: The rounding of a domain integral relative to its value (its terms cancel to about this).
ROUNDING = 1e-12


def of_interfaces(fractures: list[Fracture], cracks: list[int]) -> Fracture:
    """The tips and contact zones of several interfaces as one :class:`Fracture`: ``fractures`` and the number of
    ``cracks`` of each interface, bottom to top; the cracks numbered interface by interface, each tip's
    ``interface`` (1 the lowest) and each crack's (``crack_interface``) recorded."""
    first = np.concatenate([[0], np.cumsum(cracks)[:-1]]).astype(np.int64)
    renumbered = ("crack", "zone_crack", "overlap_crack")
    joined = {}
    for field_ in dataclasses.fields(Fracture):
        name = field_.name
        if name in ("reference_length", "interface", "crack_interface"):
            continue
        parts = [getattr(f, name) + (offset if name in renumbered else 0) for f, offset in zip(fractures, first)]
        joined[name] = np.concatenate(parts)
    joined["interface"] = np.concatenate([np.full(len(f.G), number + 1, dtype=np.int64)
                                          for number, f in enumerate(fractures)])
    joined["crack_interface"] = np.repeat(np.arange(1, len(cracks) + 1), cracks).astype(np.int64)
    return Fracture(**joined, reference_length=fractures[0].reference_length)


def of_result(result, tips: list[Tip], factors: np.ndarray | None = None) -> Fracture:
    """G at ``tips`` from a result's blocks (one process), with the toughness and the critical load
    factors (``factors``: see :func:`finish`)."""
    volume = block_terms(result.scene, result.mesh.sigma, tips, {
        index: (result.half(spec.name).points, result.half(spec.name).cells, result.solution[spec.name])
        for index, spec in enumerate(result.blocks)})
    return finish(tips, volume, result.on_sigma, mode_split(tips, result), result.scene, factors)


def evaluate(result, inner: float | None = None, outer: float | None = None) -> Fracture:
    """G at every tip of a result (any source, one process); radii: given, else the scene's, else automatic."""
    options = result.scene.fracture
    tips = find_tips(result.mesh, inner if inner is not None else options.inner,
                     outer if outer is not None else options.outer)
    return of_result(result, tips)


# --- modes I and II -------------------------------------------------------------------------------
#: A reflection about Σ leaves a layer's law unchanged when it reproduces D to this (relative).
MIRROR = 1e-10


def mode_split(tips: list[Tip], result) -> dict[str, np.ndarray] | None:
    """G_I, G_II, the phase angle (degrees), ``symmetric`` (how each tip was split) and ε = 0 at every tip; None
    where the regions below and above Σ have different elastic laws (an interface crack: :func:`finish` splits
    it by :func:`ddsolve.post.interface_crack.interface_split` where it has a pair, else not at all,
    :func:`split_note`).

    Where the θ disc is mirror-symmetric about Σ (Σ straight there, both layers' laws unchanged by the
    reflection: always for isotropic layers) the fields split into a part symmetric about Σ (opening,
    mode I) and an antisymmetric one (sliding, mode II), and the domain integral of each part is its G
    (:func:`mirror_split`); elsewhere the virtual crack closure of the tip's gluing forces μᵍ on the jumps
    behind it (:func:`closure_split`).  A tip whose faces touch at the first crack node behind it
    (non-penetration holds there) has G_I = 0.  ψ = atan2(s_II √G_II, s_I √G_I), s_I the sign of the
    opening and s_II that of the sliding behind the tip in its frame (x along the extension, y turned
    90° counter-clockwise from it): atan(√(G_II/G_I)) signed like K_II/K_I.  :func:`finish` leaves ψ
    undefined (NaN) at a tip whose G is no release rate: there G_I and G_II are noise, and so is their angle.
    """
    if result.scene.dissimilar_layers(thermal=False):
        return None
    result = disc_result(result, tips)
    return split_modes(tips, [mirror_split(tip, result) for tip in tips], result.on_sigma,
                       result.scene.nonpenetration, result.mesh.degree)


def split_modes(tips: list[Tip], mirrored: list[tuple[float, float] | None], on: OnSigma, nonpenetration: bool,
                degree: int) -> dict[str, np.ndarray]:
    """:func:`mode_split` from each tip's :func:`mirror_split` (None where the disc is not mirror-symmetric:
    virtual crack closure) and Σ's data ``on``."""
    count = len(tips)
    out = {"G_I": np.full(count, np.nan), "G_II": np.full(count, np.nan), "phase": np.full(count, np.nan),
           "symmetric": np.zeros(count, dtype=bool), "epsilon": np.zeros(count)}
    for i, tip in enumerate(tips):
        out["symmetric"][i] = mirrored[i] is not None
        G_I, G_II = mirrored[i] if mirrored[i] is not None else closure_split(tip, on, degree)
        opening, sliding, closed = _behind(tip, on, nonpenetration)
        if closed:
            G_I = 0.0
        out["G_I"][i], out["G_II"][i] = G_I, G_II
        K_I = math.sqrt(max(G_I, 0.0)) * (-1.0 if opening < 0.0 else 1.0) + 0.0  # + 0.0: no −0.0 (atan2 → 180°)
        K_II = math.sqrt(max(G_II, 0.0)) * (-1.0 if sliding < 0.0 else 1.0) + 0.0
        out["phase"][i] = math.degrees(math.atan2(K_II, K_I))
    return out


def mirror_split(tip: Tip, result) -> tuple[float, float] | None:
    """(G_I, G_II): the domain integral of the parts of the four blocks' fields symmetric and antisymmetric
    about Σ's line at the tip, or None where the disc is not mirror-symmetric.

    Block (layer, side) at a node x takes the mirror image R u(x′) of the same layer's block on the other
    side at x′ = x reflected about Σ (R the reflection; the other half's field interpolated with its own
    shape functions); u_I = (u + R u(x′))/2, u_II = (u − R u(x′))/2.  θ is symmetric, so the cross term of
    the quadratic integral is odd and vanishes up to the interpolation: G_I + G_II = G.
    """
    sigma, scene = result.mesh.sigma, result.scene
    if not mirrorable(tip, sigma, scene):
        return None
    from ddsolve.errors import DDSolveError
    from ddsolve.post.analysis import interpolate

    parts = np.zeros(2)
    for half, other in ((result.lower, result.upper), (result.upper, result.lower)):
        field, nodes, images = mirror_nodes(tip, sigma, half)
        specs = result.blocks
        blocks = [spec for spec in specs if result.half(spec.name) is half]
        partners = [specs[partner(specs.index(spec), specs)] for spec in blocks]
        try:
            mirrored = interpolate(other, np.hstack([result.solution[p.name] for p in partners]), images)
        except DDSolveError:  # the mirror image of the disc leaves the other half
            return None
        for j, spec in enumerate(blocks):
            block = spec.layer, spec.region
            terms = mirror_terms(tip, sigma, half, assembly.elasticity(scene, *block)[0], result.solution[spec.name],
                                 (field, nodes, images), mirrored[:, 2 * j:2 * j + 2],
                                 assembly.thermal_of(scene, *block))
            if terms is None:
                return None
            parts += terms
    return float(parts[0]), float(parts[1])


def mirrorable(tip: Tip, sigma: SigmaLine, scene: Scene) -> bool:
    """Whether the tip's θ disc can be split by mirror symmetry: Σ straight there, every block's law unchanged
    by the reflection about it, and each layer's material the same in both regions (thermal strain too)."""
    laws = [assembly.elasticity(scene, spec.layer, spec.region)[0] for spec in block_list(scene.geometry.layers)]
    return (straight_near(tip, sigma) and all(mirrored_law(D, reflection(tip, sigma)) for D in laws)
            and not scene.dissimilar_layers())


def split_note(scene: Scene) -> str | None:
    """Why G is not split into modes I and II, or None where it is: layers whose regions below and above Σ have
    different elastic laws with no effective isotropic pair (orthotropic regions, or layers whose pairs are not
    proportional: :func:`ddsolve.post.interface_crack.interface_pair`), where an interface crack's G is not
    split."""
    pair = interface_crack.interface_pair(scene)
    if not isinstance(pair, str):
        return None
    layers = scene.dissimilar_layers(thermal=False)
    return (f"G is not split into modes I and II: {' and '.join(layers)} {'has' if len(layers) == 1 else 'have'} "
            f"different elastic laws below and above Σ and {pair}, where the split of an interface crack's G is "
            "not defined (docs/fracture.md)")


def reflection(tip: Tip, sigma: SigmaLine) -> np.ndarray:
    """``(2, 2)``: the reflection about Σ's line at the tip."""
    normal = sigma.normals[tip.node]
    return np.eye(2) - 2.0 * np.outer(normal, normal)


def mirror_nodes(tip: Tip, sigma: SigmaLine, half: HalfMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """θ on ``half`` ``(n, 2)``, the nodes of the cells it touches and their mirror images about Σ's line at
    the tip: where the other side's field is read."""
    field = theta(tip, sigma, half.points)
    nodes = np.unique(half.cells[np.any(field != 0.0, axis=1)[half.cells].any(axis=1)])
    normal = sigma.normals[tip.node]
    images = half.points[nodes] - 2.0 * ((half.points[nodes] - tip.point) @ normal)[:, None] * normal
    return field, nodes, images


def mirror_terms(tip: Tip, sigma: SigmaLine, half: HalfMesh, D: np.ndarray, u: np.ndarray,
                 disc: tuple[np.ndarray, np.ndarray, np.ndarray], opposite: np.ndarray,
                 thermal: assembly.ThermalLoad | None = None) -> np.ndarray | None:
    """One block's share of :func:`mirror_split` ``(2,)``: the domain integrals of (u ± R u′)/2 on its ``half``,
    u′ the same layer's field on the other side at the images (``opposite`` ``(q, 2)``, x and y) of the nodes of
    ``disc`` (:func:`mirror_nodes`); None when the block's eigenstrain is not its own mirror image."""
    field, nodes, images = disc
    if thermal is not None and not mirrored_temperature(thermal, half.points[nodes], images):
        return None
    image = opposite @ reflection(tip, sigma)
    parts = np.zeros(2)
    for k, sign in enumerate((1.0, -1.0)):
        part = np.zeros_like(u)
        part[nodes] = 0.5 * (u[nodes] + sign * image)
        # a temperature symmetric about Σ strains the symmetric part only: its eigenstrain is mode I's
        parts[k] = volume_terms(half.points, half.cells, D, part, [field], thermal if k == 0 else None)[0]
    return parts


def closure_split(tip: Tip, on: OnSigma, degree: int) -> tuple[float, float]:
    """(G_I, G_II) by the virtual crack closure technique from the tip's gluing forces.

    Advancing the tip by one element releases u⁻ = u⁺ at the tip node (and, for P2, at the midpoint ahead):
    the forces w_k μᵍ_k that hold the upper half to the lower one (μ⁻ and μ⁺ act within one half and stay),
    whose work on the jumps [u] = u⁺ − u⁻ they close is the energy released.  The jumps are taken at the
    nodes as far behind the tip (P1: the vertex behind with the tip's force; P2: the vertex behind with the
    tip's force and the midpoint behind with the midpoint's), components in the tip's (τ, ν) frame (ν gives
    G_I, τ gives G_II), and for unequal elements ahead (a₁) and behind (a₂) with the jump scaled as √r:
    G = −Σ F·[u] / (2√(a₁a₂)).  NaN where the nodes do not exist (a tip one element from the crack's end).
    """
    sigma = on.sigma
    step = 1 if tip.direction @ sigma.frames[tip.node, 0] > 0 else -1
    span = 2 if degree == 2 else 1
    nodes = tip.node + step * np.arange(-span, span + 1)  # behind ... tip ... ahead
    multiplier = np.searchsorted(sigma.multiplier_nodes, nodes.clip(0, len(sigma.points) - 1))
    valid = (nodes >= 0) & (nodes < len(sigma.points)) & (multiplier < len(sigma.multiplier_nodes))
    if not valid.all() or np.any(sigma.multiplier_nodes[multiplier] != nodes):
        return math.nan, math.nan
    frame = sigma.frames[tip.node]
    force = (sigma.weights[nodes, None] * on.multipliers["mu_g"][multiplier]) @ frame.T
    jump = (on.traces["u_plus"][nodes] - on.traces["u_minus"][nodes]) @ frame.T
    ahead = np.linalg.norm(sigma.points[nodes[-1]] - tip.point)
    behind = np.linalg.norm(sigma.points[nodes[0]] - tip.point)
    work = -np.sum(force[span:2 * span] * jump[:span], axis=0)  # the tip's force on the farthest jump behind
    tangential, normal = work / (2.0 * math.sqrt(ahead * behind))
    return float(normal), float(tangential)


def straight_near(tip: Tip, sigma: SigmaLine) -> bool:
    """Σ is the straight line through the tip within the θ disc (and one edge beyond)."""
    reach = tip.outer + np.linalg.norm(np.diff(sigma.points, axis=0), axis=1).max()
    near = np.linalg.norm(sigma.points - tip.point, axis=1) <= reach
    normal = sigma.normals[tip.node]
    off = np.abs((sigma.points[near] - tip.point) @ normal)
    return bool(off.max() <= STRAIGHT * reach and np.abs(sigma.normals[near] - normal).max() <= STRAIGHT)


def mirrored_temperature(thermal: assembly.ThermalLoad, points: np.ndarray, images: np.ndarray) -> bool:
    """Whether a layer's eigenstrain e ΔT is its own mirror image: no shear in e, ΔT equal at ``points``
    and their ``images``."""
    strain, temperature = thermal
    here, there = temperature(points[:, 0], points[:, 1]), temperature(images[:, 0], images[:, 1])
    return bool(abs(strain[2]) <= MIRROR * np.abs(strain).max()
                and np.abs(here - there).max(initial=0.0) <= MIRROR * np.abs(here).max(initial=0.0))


def disc_part(half: HalfMesh, tips: list[Tip]) -> tuple[HalfMesh, np.ndarray]:
    """What the split into modes reads of ``half``: the cells whose bounding box reaches into a tip's θ
    disc widened by twice the size of the disc's cells (which hold the disc's nodes and, Σ being straight
    there, their mirror images) and every Σ node; with the indices of the nodes kept (in order)."""
    corners = half.points[half.cells]
    low, high = corners.min(axis=1), corners.max(axis=1)
    near = np.zeros(len(half.cells), dtype=bool)
    for tip in tips:
        gap = np.hypot(*np.maximum(np.maximum(low - tip.point, tip.point - high), 0.0).T)
        # the disc's cells reach beyond it by their size: their nodes' images lie within that reach
        reach = tip.outer + float(np.max(high[gap <= tip.outer] - low[gap <= tip.outer], initial=0.0))
        near |= gap <= 2.0 * reach - tip.outer
    kept = np.union1d(np.unique(half.cells[near]), half.sigma)
    position = np.full(len(half.points), -1, dtype=np.int64)
    position[kept] = np.arange(len(kept))
    return HalfMesh(half.points[kept], position[half.cells[near]], half.side, position[half.sigma]), kept


def disc_result(result, tips: list[Tip]):
    """``result`` on the :func:`disc_part` of each half: all the split into modes reads."""
    parts = {half.side: disc_part(half, tips) for half in result.mesh.halves}
    mesh = Mesh(parts[-1][0], parts[1][0], result.mesh.sigma, result.mesh.origin)
    solution = {spec.name: result.solution[spec.name][parts[spec.side][1]] for spec in result.blocks}
    return dataclasses.replace(result, mesh=mesh, solution=solution, held=None)


def mirrored_law(D: np.ndarray, reflection: np.ndarray) -> bool:
    """Whether the in-plane law D (Voigt, engineering shear) is unchanged by the ``reflection``."""
    basis = np.array([[[1.0, 0.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, 1.0]], [[0.0, 0.5], [0.5, 0.0]]])
    turned = reflection @ basis @ reflection.T
    T = np.stack([turned[:, 0, 0], turned[:, 1, 1], 2.0 * turned[:, 0, 1]])  # columns: the images of the basis
    return bool(np.abs(T.T @ D @ T - D).max() <= MIRROR * np.abs(D).max())


def _behind(tip: Tip, on: OnSigma, nonpenetration: bool) -> tuple[float, float, bool]:
    """Opening and sliding summed over the tip's crack nodes within ``inner`` (sliding along the extension,
    signed as K_II), and whether the faces touch (a contact zone, with non-penetration) at the crack node
    nearest the tip."""
    from ddsolve.post.analysis import contact_zones

    sigma = on.sigma
    multiplier = sigma.multiplier_nodes
    distance = np.linalg.norm(sigma.points[multiplier] - tip.point, axis=1)
    crack = sigma.crack[multiplier] & (distance <= tip.inner)
    if not crack.any():
        return 0.0, 0.0, False
    jump = -on.gap
    normal = sigma.normals[tip.node]
    upward = np.sign(normal @ np.array([-tip.direction[1], tip.direction[0]]))  # ν is the tip frame's ±y
    nearest = np.flatnonzero(crack)[np.argmin(distance[crack])]
    closed = nonpenetration and any(first <= nearest <= last for first, last in contact_zones(on))
    return float(np.sum(jump[crack] @ normal)), float(upward * np.sum(jump[crack] @ tip.direction)), bool(closed)
