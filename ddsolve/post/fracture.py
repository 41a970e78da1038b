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

Discretely this is exact: θ is interpolated with the element's own basis (P1 or P2 nodes) and
integrated with the element quadrature, so G is the derivative of the discrete energy Π_h with
respect to moving the mesh nodes by θ (tests/test_fracture.py checks it against finite differences).

The radii come from the geometry: ``outer`` is half the distance from the tip to the nearest other
tip, point of the outer boundary (loaded, free or clamped) or kink of Σ, ``inner`` half of ``outer``;
the scene's ``[fracture] inner, outer`` override them.  No PETSc or MPI here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddsolve.errors import SceneError
from ddsolve.fem import assembly
from ddsolve.mesh import element
from ddsolve.mesh.mesh import BLOCKS, SIGMA, HalfMesh, Mesh, SigmaLine
from ddsolve.post.result import Fracture, OnSigma

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
def volume_terms(half: HalfMesh, D: np.ndarray, u: np.ndarray, fields: list[np.ndarray],
                 thermal: tuple[np.ndarray, object] | None = None) -> np.ndarray:
    """∫ [σ_ij u_i,k θ_k,j − ½ σ:(ε − ε₀) div θ] + eigenstrain term, over ``half``, for each nodal θ
    ``(n, 2)`` in ``fields``.

    ``u`` ``(n, 2)`` in x, y; σ = D (ε − ε₀) (Voigt, engineering shear), the mechanical stress, with the
    eigenstrain ε₀ = e ΔT of ``thermal`` (e, ΔT) (zero without), so ½ σ:(ε − ε₀) is the in-plane energy density.
    """
    out = np.zeros(len(fields))
    support = np.zeros(len(half.points), dtype=bool)
    for field in fields:
        support |= np.any(field != 0.0, axis=1)
    cells = half.cells[support[half.cells].any(axis=1)]
    if len(cells) == 0:
        return out
    xi, weights = element.quadrature(cells.shape[1])
    det, gradients = element.element_geometry(half.points, cells, xi)
    grad_u = np.einsum("mkd,mqke->mqde", u[cells], gradients)  # u_d,e
    strain = np.stack([grad_u[..., 0, 0], grad_u[..., 1, 1], grad_u[..., 0, 1] + grad_u[..., 1, 0]], axis=-1)
    if thermal is not None:
        strain = strain - assembly.cell_temperatures(half.points, cells, thermal[1], xi)[..., None] * thermal[0]
    s = strain @ D.T
    stress = np.stack([np.stack([s[..., 0], s[..., 2]], -1), np.stack([s[..., 2], s[..., 1]], -1)], -2)
    density = 0.5 * np.sum(s * strain, axis=-1)
    momentum = np.einsum("mqij,mqik->mqkj", stress, grad_u)  # σ_ij u_i,k
    volume = det * weights
    for i, field in enumerate(fields):
        grad_theta = np.einsum("mkd,mqke->mqde", field[cells], gradients)  # θ_k,j
        integrand = np.einsum("mqkj,mqkj->mq", momentum, grad_theta) - density * (grad_theta[..., 0, 0]
                                                                                   + grad_theta[..., 1, 1])
        if thermal is not None:
            integrand = integrand + eigenstrain_term(half, cells, xi, gradients, s, field, thermal)
        out[i] = float(np.sum(volume * integrand))
    return out


def eigenstrain_term(half: HalfMesh, cells: np.ndarray, xi: np.ndarray, gradients: np.ndarray, stress: np.ndarray,
                     field: np.ndarray, thermal: tuple[np.ndarray, object]) -> np.ndarray:
    """σ : (∂ε₀/∂x_k) θ_k at the quadrature points ``(m, q)``: the part of −dΠ/da an eigenstrain that varies
    in space adds (Shih, Moran and Nakamura 1986, eq. 13: J = ∫ [σ_ij u_i,1 − W δ_1j] q_,j dA +
    ∫ σ_ij ∂ε₀_ij/∂x_1 q dA, with W the energy of ε − ε₀).  ε₀ = e ΔT; ∇ΔT from ΔT interpolated at the nodes."""
    eigenstrain, temperature = thermal
    nodal = np.asarray(temperature(half.points[cells][..., 0], half.points[cells][..., 1]), dtype=np.float64)
    grad_change = np.einsum("mk,mqkd->mqd", np.broadcast_to(nodal, cells.shape), gradients)
    shapes, _ = element.shape_functions(cells.shape[1], xi)
    theta_q = np.einsum("qk,mkd->mqd", shapes, field[cells])
    return (stress @ eigenstrain) * np.einsum("mqd,mqd->mq", grad_change, theta_q)


def block_terms(scene, mesh: Mesh, tips: list[Tip], solutions: dict[int, np.ndarray]) -> np.ndarray:
    """Sum of the volume terms of the blocks in ``solutions`` (block index -> solution as solved: flat,
    Σ dofs of multiplier nodes in their local frames) for every tip."""
    out = np.zeros(len(tips))
    if not tips:
        return out
    frames = mesh.sigma.frames[mesh.sigma.multiplier_nodes]
    for index, x in solutions.items():
        spec = BLOCKS[index]
        half = mesh.half(spec.side)
        u = assembly.to_global(np.asarray(x), assembly.trace_nodes(half, mesh.sigma), frames)
        D, _ = assembly.elasticity(scene, spec.layer)
        out += volume_terms(half, D, u, [theta(tip, mesh.sigma, half.points) for tip in tips],
                            assembly.thermal_of(scene, spec.layer))
    return out


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


def finish(tips: list[Tip], volume: np.ndarray, on: OnSigma) -> Fracture:
    """G = volume terms − contact terms, and the contact zones, from the Σ data ``on`` of a result
    (:attr:`ddsolve.post.result.Result.on_sigma`)."""
    from ddsolve.post.analysis import contact_zones

    contact = contact_terms(tips, on)
    sigma = on.sigma
    crack_of = np.full(len(sigma.points), -1)
    for index, (first, last) in enumerate(sigma.pieces(sigma.crack)):
        crack_of[first:last + 1] = index
    nodes = sigma.multiplier_nodes
    runs = np.array(contact_zones(on), dtype=np.int64).reshape(-1, 2)
    arc = sigma.arclength[nodes]
    return Fracture(
        points=np.array([tip.point for tip in tips]).reshape(-1, 2),
        directions=np.array([tip.direction for tip in tips]).reshape(-1, 2),
        crack=np.array([tip.crack for tip in tips], dtype=np.int64),
        inner=np.array([tip.inner for tip in tips]), outer=np.array([tip.outer for tip in tips]),
        spacing=np.array([tip.spacing for tip in tips]), G=np.asarray(volume, dtype=np.float64) - contact, contact=contact,
        zones=arc[runs].reshape(-1, 2), zone_crack=crack_of[nodes[runs[:, 0]]] if len(runs) else np.zeros(0, np.int64),
    )


def of_result(result, tips: list[Tip]) -> Fracture:
    """G at ``tips`` from a result's four blocks (one process)."""
    scene = result.parsed_scene
    volume = np.zeros(len(tips))
    for spec in BLOCKS:
        half = result.half(spec.name)
        D, _ = assembly.elasticity(scene, spec.layer)
        fields = [theta(tip, result.mesh.sigma, half.points) for tip in tips]
        volume += volume_terms(half, D, result.solution[spec.name], fields, assembly.thermal_of(scene, spec.layer))
    return finish(tips, volume, result.on_sigma)


def evaluate(result, inner: float | None = None, outer: float | None = None) -> Fracture:
    """G at every tip of a result (any source, one process); radii: given, else the scene's, else automatic."""
    options = result.parsed_scene.fracture
    tips = find_tips(result.mesh, inner if inner is not None else options.inner,
                     outer if outer is not None else options.outer)
    return of_result(result, tips)
