"""G along the crack fronts of a 3-D box, by the domain (G-θ) integral with θ localised along the front.

A front is a chain of Σ vertices (:attr:`ddsolve.mesh.solid.SigmaSurface.front`) with, at every node, the tangent t,
the in-plane normal n (in Σ, away from the crack: the direction of growth) and ν = +y, (n, ν, t) right-handed.
Front node k has θ_k(x) = φ_k(s) c(r) n(s): φ_k the hat of node k along the arc length s of the point of the front
nearest x, of half-width the inner radius (at least one front edge: hats one edge wide let the P1 field's error at
the element scale scatter G from node to node by tens of per cent), r the distance to it, c = 1 for r ≤ inner, 0
for r ≥ outer, linear between, n(s) interpolated between the nodes; θ is made tangent to every side of the box it
touches.  Without body forces and
with no load where θ ≠ 0 (the radii keep it off the loaded and clamped sides), the release of energy is

    J(θ) = Σ over both halves ∫ [σ_ij u_i,k θ_k,j − W θ_k,k] dV = Σ_a θ(a)·F_a,
    F_a = Σ_e |e| (∇uᵀσ − W I)_e ∇N_a,

F the nodal configurational forces (P1: σ and ∇u constant per tetrahedron), and G_k = J(θ_k) / ∫ φ_k ds, G per
unit length of front at node k (the mean of G(s) weighted by the hat).  J(θ) is the derivative of the discrete
energy as the nodes move by θ (tests/test_front.py checks it by finite differences).  Σ is flat, so
non-penetration adds no term (its normal does not turn).  Under a temperature change (``temperature.layer1``) σ and
W are those of ε − ε₀, ε₀ = ε₀′ ΔT, and F gains the eigenstrain's term Σ_e |e| σ:ε₀′ ∇ΔT λ_a (the plane code's,
:func:`ddsolve.post.fracture.eigenstrain_term`).

Modes: where the materials above and below Σ are the same and the reflection about Σ leaves their law unchanged
(isotropic, or a ply whose fibre lies in Σ), the fields split into the part symmetric about Σ
(u + R u′)/2 (R = diag(1, −1, 1), u′ the other half's field at the mirror image, located in its tetrahedra) and
the antisymmetric part; G_I is J of the symmetric part, and the antisymmetric one is split in the front's frame:
its component along t (tearing) gives G_III, the rest (sliding along n and the normal component) G_II.  The
cross terms vanish for the near-front fields; G_I + G_II + G_III = G up to them (and to the interpolation at the
images).  An eigenstrain that is its own mirror image about Σ goes with the symmetric part (mode I); between different
materials, or under one that is not, the modes are not split (NaN).  No PETSc or MPI here.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ddsolve.fem import tetra
from ddsolve.mesh.solid import SIDE_PLANES, SolidHalf, SolidMesh
from ddsolve.problem import materials

#: Default radii as in the plane: outer = OUTER_FRACTION × the clearance, inner = INNER_FRACTION × outer.
OUTER_FRACTION = 0.5
INNER_FRACTION = 0.5
#: The hats' half-width along the front as a multiple of the inner radius (at least the longest front edge).
WIDTH_FRACTION = 1.0
#: A front turning by more than this at a node has a corner there (a rectangle's), not a curvature.
CORNER_DEGREES = 30.0
#: Σ's normal ν and the reflection about Σ.
NU = np.array([0.0, 1.0, 0.0])
REFLECTION = np.diag([1.0, -1.0, 1.0])
#: The reflection's signs on Voigt stresses (xx, yy, zz, yz, xz, xy): a law it leaves unchanged is split into modes.
REFLECTED_VOIGT = np.array([1.0, 1.0, 1.0, -1.0, 1.0, -1.0])


@dataclass(frozen=True)
class Front:
    """One chain of front nodes in order: their Σ vertices, points, tangents t, normals n (the growth direction),
    arc length, θ's radii and the half-width of its hats along the front."""

    nodes: np.ndarray
    points: np.ndarray
    tangents: np.ndarray
    normals: np.ndarray
    arclength: np.ndarray
    closed: bool
    inner: float
    outer: float
    width: float

    @property
    def lengths(self) -> np.ndarray:
        """∫ φ_k ds of every node's hat along the front: the half-width, less the parts beyond an open chain's
        ends."""
        out = np.full(len(self.points), self.width)
        if not self.closed:
            for distance in (self.arclength, self.arclength[-1] - self.arclength):
                out -= np.clip(self.width - distance, 0.0, None) ** 2 / (2.0 * self.width)
        return out

    @property
    def closure(self) -> float:
        """The length of the edge from the last node back to the first (0 for an open chain)."""
        return float(np.linalg.norm(self.points[0] - self.points[-1])) if self.closed else 0.0

    def integrate(self, s: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Σ_a φ_k(s_a) values_a ``(k,)`` for every node k: φ_k(s) = 1 − |s − s_k|/width, at least 0 (around a
        closed chain, the shorter way), over the points at arc length ``s``."""
        order = np.argsort(s)
        s, values = s[order], values[order]
        if self.closed:
            total = self.arclength[-1] + self.closure
            s, values = np.concatenate([s - total, s, s + total]), np.tile(values, 3)
        low = np.searchsorted(s, self.arclength - self.width)
        high = np.searchsorted(s, self.arclength + self.width)
        out = np.empty(len(self.points))
        for k, (first, last) in enumerate(zip(low, high)):
            hat = np.clip(1.0 - np.abs(s[first:last] - self.arclength[k]) / self.width, 0.0, None)
            out[k] = hat @ values[first:last]
        return out

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For every point: the segment of the front nearest it, the position along it (0 to 1) and the
        distance."""
        ends = np.column_stack([np.arange(len(self.points)), np.roll(np.arange(len(self.points)), -1)])
        ends = ends if self.closed else ends[:-1]
        a, d = self.points[ends[:, 0]], self.points[ends[:, 1]] - self.points[ends[:, 0]]
        best = np.full(len(points), np.inf)
        segment, along = np.zeros(len(points), dtype=np.int64), np.zeros(len(points))
        for j in range(len(ends)):  # one segment at a time: memory linear in the points
            t = np.clip((points - a[j]) @ d[j] / (d[j] @ d[j]), 0.0, 1.0)
            distance = np.linalg.norm(a[j] + t[:, None] * d[j] - points, axis=1)
            closer = distance < best
            best[closer], segment[closer], along[closer] = distance[closer], j, t[closer]
        return ends[segment], along, best

    def locate(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """At ``points``: the arc length s of the nearest point of the front, the radial cut-off c(r), and the
        normal n(s) and tangent t(s) there (interpolated between the nodes); θ_k = φ_k(s) c(r) n(s)."""
        ends, along, distance = self.nearest(points)
        cut = np.clip((self.outer - distance) / (self.outer - self.inner), 0.0, 1.0)
        start = self.arclength[ends[:, 0]]
        edge = np.where(ends[:, 1] > ends[:, 0], self.arclength[ends[:, 1]] - start, self.closure)
        normals, tangents = (_unit((1.0 - along)[:, None] * field[ends[:, 0]] + along[:, None] * field[ends[:, 1]])
                             for field in (self.normals, self.tangents))
        return start + along * edge, cut, normals, tangents


def _unit(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.maximum(np.linalg.norm(vectors, axis=1, keepdims=True), 1e-300)


def fronts(mesh: SolidMesh, box: tuple[float, ...], inner: float | None = None, outer: float | None = None,
           width: float | None = None) -> list[Front]:
    """The chains of Σ's front edges, each oriented so that n = ν × t points away from its crack, with θ's radii
    (given, else from the clearance: the distance to the box's sides the front does not end on and to the other
    fronts)."""
    sigma = mesh.sigma
    chains = [(_oriented(sigma, chain, closed), closed) for chain, closed in _chains(sigma.front)]
    out = []
    for index, (chain, closed) in enumerate(chains):
        points = sigma.points[chain]
        tangents = _tangents(points, closed, box)
        others = [sigma.points[other] for j, (other, _) in enumerate(chains) if j != index]
        clearance = _clearance(points, closed, box, others)
        big = outer if outer is not None else OUTER_FRACTION * clearance
        small = inner if inner is not None else INNER_FRACTION * big
        arclength = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
        spacing = float(np.diff(arclength).max(initial=0.0))
        out.append(Front(chain, points, tangents, np.cross(NU, tangents), arclength, closed, float(small),
                         float(big), max(spacing, width if width is not None else WIDTH_FRACTION * small)))
    return out


def _chains(edges: np.ndarray) -> list[tuple[np.ndarray, bool]]:
    """The edges as chains of vertices in order, and whether each closes on itself."""
    neighbours: dict[int, list[int]] = {}
    for a, b in edges.tolist():
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    left = set(neighbours)
    chains = []
    while left:
        ends = [v for v in left if len(neighbours[v]) == 1]
        chain = [min(ends) if ends else min(left)]
        left.discard(chain[0])
        while True:
            following = [v for v in neighbours[chain[-1]] if v in left]
            if not following:
                break
            chain.append(following[0])
            left.discard(following[0])
        closed = not ends and len(chain) > 2
        chains.append((np.array(chain, dtype=np.int64), closed))
    return chains


def _oriented(sigma, chain: np.ndarray, closed: bool) -> np.ndarray:
    """The chain in the order whose n = ν × t points away from the cracked vertices next to it."""
    points = sigma.points[chain]
    tangents = _tangents(points, closed, None)
    triangles = sigma.triangles[np.isin(sigma.triangles, chain).any(axis=1)]
    cracked = np.unique(triangles[sigma.cracked[triangles]])
    if not len(cracked):
        return chain
    # each cracked neighbour against the nearest chain node's normal
    nearest = np.argmin(np.linalg.norm(sigma.points[cracked][:, None] - points[None], axis=2), axis=1)
    side = np.einsum("kd,kd->k", sigma.points[cracked] - points[nearest], np.cross(NU, tangents)[nearest])
    return chain if side.sum() < 0 else chain[::-1]


def _tangents(points: np.ndarray, closed: bool, box: tuple[float, ...] | None) -> np.ndarray:
    """Unit tangents at the chain's nodes (central differences; at an end on a side of the box, the side's
    normal: θ must be tangent to the side)."""
    if closed:
        tangents = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    else:
        tangents = np.gradient(points, axis=0) if len(points) > 1 else np.array([[0.0, 0.0, 1.0]])
    tangents = _unit(tangents)
    if box is not None and not closed:
        for end in (0, -1):
            for axis in (0, 2):
                if np.isclose(points[end, axis], box[2 * axis]) or np.isclose(points[end, axis], box[2 * axis + 1]):
                    normal = np.eye(3)[axis]
                    tangents[end] = normal * np.sign(tangents[end] @ normal)
    return tangents


def _curvature(points: np.ndarray, closed: bool) -> float:
    """The smallest radius of curvature of the chain (edge length over turning angle), corners (turning by more
    than CORNER_DEGREES) left out; infinite for a straight chain."""
    ring = np.concatenate([points[-1:], points, points[:1]]) if closed else points
    chords = np.diff(ring, axis=0)
    lengths = np.linalg.norm(chords, axis=1)
    cosine = np.einsum("sd,sd->s", chords[:-1], chords[1:]) / (lengths[:-1] * lengths[1:])
    turning = np.arccos(np.clip(cosine, -1.0, 1.0))
    smooth = (turning > 1e-9) & (turning <= np.radians(CORNER_DEGREES))
    radii = 0.5 * (lengths[:-1] + lengths[1:])[smooth] / turning[smooth]
    return float(radii.min(initial=np.inf))


def _clearance(points: np.ndarray, closed: bool, box: tuple[float, ...], others: list[np.ndarray]) -> float:
    """The distance from the front to the box's sides it does not end on and to the other fronts, and its
    smallest radius of curvature (θ's normals must not cross inside the tube)."""
    distances = [np.abs(points[:, 1] - box[2]).min(), np.abs(points[:, 1] - box[3]).min(), _curvature(points, closed)]
    for axis in (0, 2):
        for value in box[2 * axis:2 * axis + 2]:
            gaps = np.abs(points[:, axis] - value)
            if gaps.min() > 1e-9 * (box[1] - box[0]):
                distances.append(gaps.min())
    for other in others:
        distances.append(np.linalg.norm(points[:, None] - other[None], axis=2).min())
    return float(min(distances))


#: A half's temperature change: its eigenstrain per unit ΔT ``(6,)`` (Voigt, engineering shears) and ΔT(x, y, z).
Thermal = tuple[np.ndarray, Callable]


def thermal_of(scene, half: SolidHalf) -> Thermal | None:
    """The half's eigenstrain per unit ΔT and ``temperature.layer1`` (None without a temperature change)."""
    if "layer1" not in scene.temperature:
        return None
    return materials.solid_expansion(scene.material("layer1", half.name)), scene.temperature["layer1"]


def forces(half: SolidHalf, D: np.ndarray, u: np.ndarray, cells: np.ndarray,
           thermal: Thermal | None = None) -> np.ndarray:
    """The configurational forces F ``(n, 3)`` at the half's vertices from the tetrahedra ``cells`` (indices, P1
    or P2) and the displacements ``u`` ``(n, 3)``: F_a = Σ_e Σ_q w_q |J| [(∇uᵀσ − W I) ∇λ_a + σ:ε₀′ ∇ΔT λ_a](x_q),
    λ_a the vertices' barycentric coordinates (θ moves the vertices: each tetrahedron's affine map), σ = D (ε − ε₀)
    and W = ½ σ:(ε − ε₀) with the eigenstrain ε₀ = ε₀′ ΔT of ``thermal`` (none without); the last term is the
    eigenstrain's (Shih, Moran and Nakamura 1986), ∇ΔT from ΔT interpolated at the nodes.  The stiffness's rule,
    or the thermal load's (degree 2) under a temperature change."""
    tetrahedra = half.tetrahedra[cells]
    xi, weights = tetra.TETRA_RULES[tetrahedra.shape[1]] if thermal is None else tetra.THERMAL_RULE
    grads, dets = tetra.gradients(half.points, tetrahedra, xi)  # (m, q, k, 3)
    grad_u = np.einsum("mkd,mqkj->mqdj", u[tetrahedra], grads)  # u_d,j
    strain = np.einsum("mqij,mj->mqi", tetra.strain_operator(grads), u[tetrahedra].reshape(len(cells), -1))
    barycentric = tetra.tetra_shapes(4, xi)[0]  # λ_a at the rule's points (q, 4)
    if thermal is not None:
        eigenstrain, temperature = thermal
        at = np.einsum("qa,mad->mqd", barycentric, half.points[tetrahedra[:, :4]])  # straight edges
        strain = strain - _temperature(temperature, at)[..., None] * eigenstrain
    stress = strain @ D.T
    sigma = stress[..., [[0, 5, 4], [5, 1, 3], [4, 3, 2]]]
    density = 0.5 * np.einsum("mqi,mqi->mq", stress, strain)
    tensor = np.einsum("mqik,mqij->mqkj", grad_u, sigma) - density[..., None, None] * np.eye(3)  # σ_ij u_i,k
    vertex = tetra.gradients(half.points, tetrahedra[:, :4], xi[:1])[0][:, 0]  # ∇λ_a (m, 4, 3)
    volume = dets[:, None] * weights
    nodal = np.einsum("mq,mqkj,maj->mak", volume, tensor, vertex)
    if thermal is not None:
        grad_change = np.einsum("mk,mqkd->mqd", _temperature(temperature, half.points[tetrahedra]), grads)
        nodal += np.einsum("mq,mq,mqd,qa->mad", volume, stress @ eigenstrain, grad_change, barycentric)
    out = np.zeros((len(half.points), 3))
    np.add.at(out, tetrahedra[:, :4].ravel(), nodal.reshape(-1, 3))
    return out


def _temperature(temperature: Callable, at: np.ndarray) -> np.ndarray:
    """ΔT at the points ``at`` ``(..., 3)``, in their shape."""
    return np.broadcast_to(temperature(at[..., 0], at[..., 1], at[..., 2]), at.shape[:-1]).astype(float)


def tangential(points: np.ndarray, box: tuple[float, ...], field: np.ndarray) -> np.ndarray:
    """``field`` ``(n, 3)`` at ``points`` with its component normal to every side of the box removed on it."""
    out = field.copy()
    tolerance = 1e-9 * max(np.ptp(np.reshape(box, (3, 2)), axis=1))
    for axis, end in SIDE_PLANES.values():
        out[np.abs(points[:, axis] - box[2 * axis + end]) <= tolerance, axis] = 0.0
    return out


@dataclass(frozen=True)
class Support:
    """A half's part within reach of a front's θ: its vertices, the tetrahedra touching them, and at the vertices
    the arc length s, the cut-off c(r) and θ's direction (n(s) made tangent to the box's sides): θ_k = φ_k(s) c(r)
    direction; the tetrahedra's nodes (with P2's mid-edge ones: the fields the integral reads) and t(s) at them."""

    front: Front
    nodes: np.ndarray
    cells: np.ndarray
    s: np.ndarray
    cut: np.ndarray
    directions: np.ndarray
    every: np.ndarray
    tangents: np.ndarray

    @classmethod
    def of(cls, front: Front, half: SolidHalf, box: tuple[float, ...]) -> Support:
        reach = front.outer + np.linalg.norm(np.ptp(front.points, axis=0))
        near = np.flatnonzero(np.linalg.norm(half.points - front.points.mean(axis=0), axis=1) <= reach)
        touched = near[front.nearest(half.points[near])[2] < front.outer]
        cells = np.flatnonzero(np.isin(half.tetrahedra[:, :4], touched).any(axis=1))
        nodes = np.unique(half.tetrahedra[cells, :4])
        s, cut, normals, _ = front.locate(half.points[nodes])
        every = np.unique(half.tetrahedra[cells])
        return cls(front, nodes, cells, s, cut, tangential(half.points[nodes], box, normals), every,
                   front.locate(half.points[every])[3])

    def theta(self, k: int) -> np.ndarray:
        """θ_k at the nodes ``(q, 3)``."""
        gap = np.abs(self.s - self.front.arclength[k])
        if self.front.closed:
            gap = np.minimum(gap, self.front.arclength[-1] + self.front.closure - gap)
        return (np.clip(1.0 - gap / self.front.width, 0.0, None) * self.cut)[:, None] * self.directions

    def release(self, half: SolidHalf, D: np.ndarray, u: np.ndarray, thermal: Thermal | None = None) -> np.ndarray:
        """J(θ_k) ``(k,)`` on this half for the displacements ``u`` ``(n, 3)`` (and the eigenstrain of ``thermal``):
        Σ_a φ_k(s_a) c_a direction_a·F_a."""
        force = forces(half, D, u, self.cells, thermal)[self.nodes]
        return self.front.integrate(self.s, self.cut * np.einsum("qd,qd->q", self.directions, force))


def mirrored(half: SolidHalf, other: SolidHalf, u_other: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """R u′(x′) ``(q, 3)``: the ``other`` half's field at the mirror images about Σ of ``half``'s ``nodes``
    (Σ's height: the Σ vertices'), reflected; each image located in the other half's tetrahedra."""
    from scipy.spatial import cKDTree

    height = half.points[half.sigma_nodes[0], 1]
    images = half.points[nodes] * [1.0, -1.0, 1.0] + [0.0, 2.0 * height, 0.0]
    corners = other.points[other.tetrahedra[:, :4]]
    inverse = np.linalg.inv(np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1)))
    found = np.full(len(images), -1, dtype=np.int64)
    coordinates = np.zeros((len(images), 4))
    best = np.full(len(images), -np.inf)
    tree = cKDTree(corners.mean(axis=1))
    for candidates in tree.query(images, k=min(24, len(corners)))[1].T:  # the nearest centroids first
        local = np.einsum("qij,qj->qi", inverse[candidates], images - corners[candidates, 0])
        weights = np.column_stack([1.0 - local.sum(axis=1), local])
        worst = weights.min(axis=1)
        better = worst > best
        best[better], found[better], coordinates[better] = worst[better], candidates[better], weights[better]
    shapes = tetra.tetra_shapes(other.tetrahedra.shape[1], coordinates[:, 1:])[0]  # P1 or P2 at the images
    return np.einsum("qa,qad->qd", shapes, u_other[other.tetrahedra[found]]) @ REFLECTION


@dataclass(frozen=True)
class FrontRelease:
    """G along the fronts: one row per front node (``front``: which chain), its point, tangent t and normal n
    ``(n, 3)``, arc length along its chain, G, G_I, G_II, G_III per unit length, the phase angles ψ =
    atan2(K_II, K_I) and φ = atan2(K_III, √(K_I² + K_II²)) in degrees (signs from the jumps behind the node), and
    θ's radii of its chain."""

    front: np.ndarray
    points: np.ndarray
    tangents: np.ndarray
    normals: np.ndarray
    arclength: np.ndarray
    G: np.ndarray
    G_I: np.ndarray
    G_II: np.ndarray
    G_III: np.ndarray
    phase: np.ndarray
    phase_III: np.ndarray
    inner: np.ndarray
    outer: np.ndarray


def release(result, inner: float | None = None, outer: float | None = None,
            width: float | None = None) -> FrontRelease:
    """G and its modes at every front node of a 3-D result (:class:`ddsolve.post.solid.SolidResult`); θ's radii
    and hats' half-width: given, else the scene's ``fracture.inner`` and ``outer``, else automatic."""
    scene, mesh = result.scene, result.mesh
    inner = inner if inner is not None else scene.fracture.inner
    outer = outer if outer is not None else scene.fracture.outer
    laws = [tetra.elastic_matrix(scene.material("layer1", half.name)) for half in mesh.halves]
    thermals = [thermal_of(scene, half) for half in mesh.halves]
    flip = np.diag(REFLECTED_VOIGT)
    same = (np.allclose(laws[0], laws[1], rtol=1e-12, atol=0.0)
            and np.allclose(flip @ laws[0] @ flip, laws[0], rtol=1e-12, atol=0.0) and _mirrored_heat(mesh, thermals))
    box = mesh.box if scene.geometry.solid_file else scene.geometry.box  # a file's body: its bounds
    rows = []
    for front in fronts(mesh, box, inner, outer, width):
        parts = np.zeros((4, len(front.points)))  # G, G_I, G_II, G_III
        for k, (half, D, u, thermal) in enumerate(zip(mesh.halves, laws, result.fields, thermals)):
            support = Support.of(front, half, box)
            parts[0] += support.release(half, D, u, thermal)
            if same:
                parts[1:] += _mode_parts(support, half, mesh.halves[1 - k], D, u, result.fields[1 - k], thermal)
        G, G_I, G_II, G_III = parts / front.lengths
        if not same:
            G_I = G_II = G_III = np.full(len(G), np.nan)
        rows.append((front, G, G_I, G_II, G_III))
    return _table(rows, result)


def _mirrored_heat(mesh: SolidMesh, thermals: list[Thermal | None]) -> bool:
    """Whether the eigenstrain is its own mirror image about Σ: none, or the same reflection-invariant eigenstrain
    per unit ΔT in both halves and ΔT equal at every lower vertex and its image (then it is all in the symmetric
    part of the fields, mode I)."""
    if thermals[0] is None:
        return True
    (lower, temperature), (upper, _) = thermals
    if not (np.allclose(lower, upper, rtol=1e-12, atol=0.0) and np.allclose(lower * REFLECTED_VOIGT, lower)):
        return False
    half = mesh.halves[0]
    height = half.points[half.sigma_nodes[0], 1]
    change = _temperature(temperature, half.points)
    image = _temperature(temperature, half.points * [1.0, -1.0, 1.0] + [0.0, 2.0 * height, 0.0])
    return bool(np.allclose(change, image, rtol=1e-12, atol=1e-12 * float(np.abs(change).max(initial=0.0))))


def _mode_parts(support: Support, half: SolidHalf, other: SolidHalf, D: np.ndarray, u: np.ndarray,
                u_other: np.ndarray, thermal: Thermal | None = None) -> np.ndarray:
    """J(θ_k) ``(3, k)`` of the symmetric part (with the eigenstrain of ``thermal``, its own mirror image), the
    antisymmetric part less its tearing, and the tearing."""
    nodes = support.every
    image = mirrored(half, other, u_other, nodes)
    symmetric, antisymmetric = (np.zeros_like(u) for _ in range(2))
    symmetric[nodes] = 0.5 * (u[nodes] + image)
    antisymmetric[nodes] = 0.5 * (u[nodes] - image)
    tearing = np.zeros_like(u)
    along = np.einsum("qd,qd->q", antisymmetric[nodes], support.tangents)
    tearing[nodes] = along[:, None] * support.tangents
    return np.array([support.release(half, D, field, heat)
                     for field, heat in ((symmetric, thermal), (antisymmetric - tearing, None), (tearing, None))])


def _table(rows: list, result) -> FrontRelease:
    """The chains' rows joined, with the phase angles from the jumps behind each node."""
    if not rows:
        empty = np.zeros((0, 3))
        return FrontRelease(np.zeros(0, dtype=np.int64), empty, empty, empty, *(np.zeros(0) for _ in range(9)))
    joined = [np.concatenate(parts) for parts in zip(*[row[1:] for row in rows])]
    G, G_I, G_II, G_III = joined
    signs = np.concatenate([_behind(front, result) for front, *_ in rows])
    K = np.sqrt(np.maximum(np.stack([G_I, G_II, G_III]), 0.0)) * signs.T
    phase = np.degrees(np.arctan2(K[1], K[0]))
    phase_III = np.degrees(np.arctan2(K[2], np.hypot(K[0], K[1])))
    return FrontRelease(
        front=np.concatenate([np.full(len(front.points), i, dtype=np.int64) for i, (front, *_) in enumerate(rows)]),
        points=np.concatenate([front.points for front, *_ in rows]),
        tangents=np.concatenate([front.tangents for front, *_ in rows]),
        normals=np.concatenate([front.normals for front, *_ in rows]),
        arclength=np.concatenate([front.arclength for front, *_ in rows]), G=G, G_I=G_I, G_II=G_II, G_III=G_III,
        phase=phase, phase_III=phase_III,
        inner=np.concatenate([np.full(len(front.points), front.inner) for front, *_ in rows]),
        outer=np.concatenate([np.full(len(front.points), front.outer) for front, *_ in rows]))


def _behind(front: Front, result) -> np.ndarray:
    """``(k, 3)``: the signs of the opening (along ν), the sliding (along n) and the tearing (along t) of the
    crack vertices within ``inner`` behind every front node (+1 where none)."""
    sigma = result.mesh.sigma
    cracked = np.flatnonzero(sigma.cracked)
    opening = result.opening[cracked]
    out = np.ones((len(front.points), 3))
    for k, (point, t, n) in enumerate(zip(front.points, front.tangents, front.normals)):
        near = np.linalg.norm(sigma.points[cracked] - point, axis=1) <= front.inner
        if near.any():
            jump = opening[near].sum(axis=0) @ np.column_stack([NU, n, t])
            out[k] = np.where(jump < 0.0, -1.0, 1.0)
    return out


def joined(releases: list[FrontRelease]) -> FrontRelease:
    """The rows of several releases (of several interfaces) in one table, their chains numbered on."""
    starts = np.cumsum([0] + [int(release.front.max(initial=-1)) + 1 for release in releases])
    return FrontRelease(**{name: np.concatenate([getattr(release, name) + (start if name == "front" else 0)
                                                 for release, start in zip(releases, starts)])
                           for name in (field.name for field in dataclasses.fields(FrontRelease))})
