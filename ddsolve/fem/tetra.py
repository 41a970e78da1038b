"""Linear elasticity on P1 and P2 tetrahedra (straight edges), vectorized: three displacement components per node (dof 3 i + c),
strains in Voigt order (xx, yy, zz, yz, xz, xy; engineering shears), an isotropic or transversely isotropic law
per half, a temperature change's eigenstrain, tractions and pressures on a half's sides, clamped and prescribed
components (rollers: one component) on its sides, and a half's system with its prescribed dofs decoupled
(:func:`half_system`), as the plane blocks have them."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse

from ddsolve.errors import SceneError
from ddsolve.fem import ranges
from ddsolve.fem.assembly import BlockSystem
from ddsolve.mesh.element import TRIANGLE_RULES, shape_functions
from ddsolve.mesh.solid import SIDE_PLANES, TETRA_EDGES, SolidHalf, SolidMesh
from ddsolve.problem import expressions, materials
from ddsolve.problem.expressions import Expression
from ddsolve.problem.scene import Load, Scene

#: The reference gradients of the barycentric coordinates 1 − ξ − η − ζ, ξ, η, ζ (the P1 shape functions).
REFERENCE_GRADIENTS = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
_A, _B = 0.5854101966249685, 0.1381966011250105
#: Quadrature on the reference tetrahedron (volume 1/6) per element: exact for K of P1 (1 point) and P2 (degree 2).
TETRA_RULES = {4: (np.full((1, 3), 0.25), np.array([1.0 / 6.0])),
               10: (np.array([[_B, _B, _B], [_A, _B, _B], [_B, _A, _B], [_B, _B, _A]]), np.full(4, 1.0 / 24.0))}
#: Which displacement component each component name of a load or support sets.
AXES = {"x": 0, "y": 1, "z": 2}


def isotropic(material: materials.Isotropic) -> np.ndarray:
    """The 6 × 6 elastic matrix of an isotropic material in Voigt order (engineering shears)."""
    E, nu = material.E, material.nu
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    D = np.zeros((6, 6))
    D[:3, :3] = lam
    D[np.arange(3), np.arange(3)] += 2 * mu
    D[np.arange(3, 6), np.arange(3, 6)] = mu
    return D


def elastic_matrix(material: materials.Isotropic | materials.Orthotropic) -> np.ndarray:
    """The 6 × 6 elastic matrix of a half's material: :func:`isotropic`, or transversely isotropic about its fibre
    (:func:`ddsolve.problem.materials.solid_stiffness`)."""
    if isinstance(material, materials.Isotropic):
        return isotropic(material)
    return materials.solid_stiffness(material)


def largest_modulus(material: materials.Isotropic | materials.Orthotropic) -> float:
    """The largest Young's modulus of a half's material: E, or a ply's larger of E1 and E2."""
    if isinstance(material, materials.Isotropic):
        return material.E
    return max(material.E1, material.E2)


def tetra_shapes(nodes: int, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values ``(q, k)`` and reference gradients ``(q, k, 3)`` of the P1 (k = 4) or P2 (k = 10, mid-edge nodes in
    :data:`ddsolve.mesh.solid.TETRA_EDGES` order) shape functions at the reference points ``xi (q, 3)``."""
    L = np.column_stack([1.0 - xi.sum(axis=1), xi])  # barycentric (q, 4)
    dL = np.broadcast_to(REFERENCE_GRADIENTS, (len(xi), 4, 3))
    if nodes == 4:
        return L, dL.copy()
    i, j = TETRA_EDGES.T
    values = np.column_stack([L * (2 * L - 1), 4 * L[:, i] * L[:, j]])
    grads = np.concatenate([(4 * L - 1)[..., None] * dL,
                            4 * (L[:, j, None] * dL[:, i] + L[:, i, None] * dL[:, j])], axis=1)
    return values, grads


def gradients(points: np.ndarray, cells: np.ndarray, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The shape functions' gradients ``(m, q, k, 3)`` at the reference points ``xi`` of every tetrahedron (straight
    edges: an affine map from its vertices) and its Jacobian's determinant ``(m,)``, six times its volume."""
    corners = points[cells[:, :4]]
    jacobians = np.einsum("kd,mkj->mjd", REFERENCE_GRADIENTS, corners)  # J[m, j, d] = ∂x_j/∂ξ_d
    inverse = np.linalg.inv(jacobians)  # ∂ξ_d/∂x_j at [m, d, j]
    _, reference = tetra_shapes(cells.shape[1], xi)
    return np.einsum("qkd,mdj->mqkj", reference, inverse), np.abs(np.linalg.det(jacobians))


def strain_operator(grads: np.ndarray) -> np.ndarray:
    """B ``(..., 6, 3 k)``: the Voigt strains from the ``3 k`` dofs (node-major) of gradients ``(..., k, 3)``."""
    B = np.zeros((*grads.shape[:-2], 6, grads.shape[-2], 3))
    for axis in range(3):
        B[..., axis, :, axis] = grads[..., axis]
    for row, (i, j) in zip(range(3, 6), ((1, 2), (0, 2), (0, 1))):
        B[..., row, :, i] = grads[..., j]
        B[..., row, :, j] = grads[..., i]
    return B.reshape(*grads.shape[:-2], 6, 3 * grads.shape[-2])


def element_dofs(cells: np.ndarray) -> np.ndarray:
    """The dofs of every cell's nodes, node-major ``(m, 3 k)``."""
    return (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 3 * cells.shape[1])


def stiffness(points: np.ndarray, cells: np.ndarray, D: np.ndarray) -> scipy.sparse.csr_matrix:
    """K = Σ_e ∫_e Bᵀ D B over the P1 or P2 tetrahedra (one elastic matrix ``D`` for all), by :data:`TETRA_RULES`."""
    xi, w = TETRA_RULES[cells.shape[1]]
    grads, dets = gradients(points, cells, xi)
    B = strain_operator(grads)  # (m, q, 6, n)
    weighted = (dets[:, None] * w)[:, :, None, None] * B
    local = np.matmul(np.swapaxes(weighted, -1, -2), D @ B).sum(axis=1)  # Σ_q w_q |J| Bᵀ D B
    dofs = element_dofs(cells)
    n = dofs.shape[1]
    rows = np.repeat(dofs, n, axis=1).ravel()
    cols = np.tile(dofs, (1, n)).ravel()
    size = 3 * len(points)
    return scipy.sparse.csr_matrix((local.ravel(), (rows, cols)), shape=(size, size))


def strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray, xi: np.ndarray | None = None) -> np.ndarray:
    """The Voigt strains ``(m, q, 6)`` of the displacements ``u`` (3 per node) at the reference points ``xi`` of
    every tetrahedron (by default its centroid)."""
    B = strain_operator(gradients(points, cells, np.full((1, 3), 0.25) if xi is None else xi)[0])
    return np.einsum("mqij,mj->mqi", B, u[element_dofs(cells)])


#: The quadrature of thermal loads and energies (degree 2): exact for a linear ΔT on P1 and P2 tetrahedra.
THERMAL_RULE = TETRA_RULES[10]


def thermal_load(points: np.ndarray, cells: np.ndarray, D: np.ndarray, eigenstrain: np.ndarray,
                 temperature: Expression) -> tuple[np.ndarray, float]:
    """∫ Bᵀ D ε₀ over the tetrahedra as a dof vector, and ½ ∫ ε₀ᵀ D ε₀ (so that Π = ½ ∫ (ε − ε₀)ᵀ D (ε − ε₀) − the
    loads' work), ε₀ = ``eigenstrain`` × ΔT(x, y, z), by :data:`THERMAL_RULE`."""
    xi, w = THERMAL_RULE
    grads, dets = gradients(points, cells, xi)
    corners = np.einsum("qk,mkd->mqd", tetra_shapes(4, xi)[0], points[cells[:, :4]])  # straight edges
    change = _evaluated(temperature, corners.reshape(-1, 3), "temperature.layer1").reshape(len(cells), len(w))
    weighted = dets[:, None] * w * change
    force = np.einsum("mq,mqja,j->ma", weighted, strain_operator(grads), D @ eigenstrain)
    vector = np.bincount(element_dofs(cells).ravel(), force.ravel(), minlength=3 * len(points))
    return vector, 0.5 * float((weighted * change).sum()) * float(eigenstrain @ D @ eigenstrain)


def rigid_modes(points: np.ndarray, centre: np.ndarray | None = None) -> np.ndarray:
    """The six rigid-body motions ``(6, 3 n)``: three translations, three rotations about ``centre`` (the
    centroid unless given)."""
    r = points - (points.mean(axis=0) if centre is None else centre)
    modes = np.zeros((6, len(points), 3))
    modes[np.arange(3), :, np.arange(3)] = 1.0
    for k, axis in enumerate(np.eye(3)):
        modes[3 + k] = np.cross(axis, r)
    return modes.reshape(6, -1)


def face_load(points: np.ndarray, triangles: np.ndarray, traction) -> np.ndarray:
    """∫ t·φ over the (3- or 6-node) triangles for a traction ``traction(points (q, 3)) -> (q, 3)``, by a degree-4
    rule: exact for tractions linear on P2 triangles, cubic on P1."""
    xi, w = TRIANGLE_RULES[6]
    shapes, _ = shape_functions(triangles.shape[1], xi)  # (q, 3) or (q, 6): straight-sided triangles
    a, b, c = (points[triangles[:, k]] for k in range(3))
    areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    at = np.einsum("qk,tkd->tqd", shapes, points[triangles])  # (t, q, 3)
    values = traction(at.reshape(-1, 3)).reshape(len(triangles), len(w), 3)
    nodal = np.einsum("tqd,q,qk,t->tkd", values, 2.0 * w, shapes, areas)  # the rule's weights sum to ½
    return np.bincount(element_dofs(triangles).ravel(), nodal.ravel(), minlength=3 * len(points))


def side_traction(load: Load, side: str):
    """The traction of ``load`` on the box side ``side`` at points ``(q, 3)``: its x, y, z components, or
    −pressure × the side's outward normal; each an expression in x, y and z."""
    if load.pressure is None:
        return lambda at: np.stack([np.zeros(len(at)) if getattr(load, name) is None else
                                    _evaluated(getattr(load, name), at, load.key) for name in AXES], axis=1)
    axis, end = SIDE_PLANES[side]
    outward = np.zeros(3)
    outward[axis] = 1.0 if end else -1.0
    return lambda at: -_evaluated(load.pressure, at, load.key)[:, None] * outward


def boundary_load(points: np.ndarray, triangles: np.ndarray, load: Load, side: str, box: bool) -> np.ndarray:
    """The load vector of ``load`` on the ``triangles`` of the boundary ``side``: on a ``box``'s side its traction
    (:func:`side_traction`); on a 3-D file's surface its components, or its pressure along each triangle's outward
    normal (the triangles are oriented outward)."""
    if box or load.pressure is None:
        return face_load(points, triangles, side_traction(load, side))
    a, b, c = (points[triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    outward = np.repeat(normals, len(TRIANGLE_RULES[6][1]), axis=0)  # at face_load's points, triangle by triangle
    return face_load(points, triangles, lambda at: -_evaluated(load.pressure, at, load.key)[:, None] * outward)


def _evaluated(expression: Expression, at: np.ndarray, key: str) -> np.ndarray:
    """``expression`` at the points ``at`` ``(q, 3)``, finite, else refused naming ``key``."""
    values = np.broadcast_to(expression(at[:, 0], at[:, 1], at[:, 2]), (len(at),)).astype(float)
    if not np.all(np.isfinite(values)):
        where = at[np.argmin(np.isfinite(values))]
        raise SceneError(f"{key}: not finite at (x, y, z) = ({where[0]:.6g}, {where[1]:.6g}, {where[2]:.6g})")
    return values


def prescribed(scene: Scene, half: SolidHalf) -> tuple[np.ndarray, np.ndarray]:
    """The dofs the scene prescribes in ``half`` and their values: every component on the clamped sides, and the
    given components (x, y, z, or normal: along the side's axis) of ``displacements.layer1.SIDE``."""
    values = np.full(half.dofs, np.nan)
    for side in scene.geometry.clamped:
        values[element_dofs(half.faces[side]).ravel()] = 0.0
    for (_, side), displacement in scene.displacements.items():
        nodes = np.unique(half.faces[side])
        parts = {AXES[name]: part for name, part in displacement.parts.items() if name in AXES}
        if displacement.normal is not None:  # along the outward normal: +axis at the range's upper end
            axis, end = SIDE_PLANES[side]
            parts = {axis: displacement.normal if end else expressions.scaled(displacement.normal, -1.0)}
        for axis, part in parts.items():
            values[3 * nodes + axis] = _evaluated(part, half.points[nodes], displacement.key)
    dofs = np.flatnonzero(~np.isnan(values))
    return dofs, values[dofs]


@dataclass(frozen=True, eq=False)
class HalfSystem:
    """A half's stiffness ``K`` and load ``f`` as assembled, its prescribed ``dofs`` and their ``values``, and the
    thermal ``offset`` ½ ∫ ε₀ᵀ D ε₀ of its energy."""

    K: scipy.sparse.csr_matrix
    f: np.ndarray
    dofs: np.ndarray
    values: np.ndarray
    offset: float = 0.0

    def energy(self, u: np.ndarray) -> float:
        """Π = ½ uᵀ K u − fᵀ u + offset: the strain energy of ε − ε₀ less the work of the loads."""
        return float(0.5 * u @ (self.K @ u) - self.f @ u) + self.offset

    def decoupled(self, name: str) -> BlockSystem:
        """The system with the prescribed dofs decoupled: their rows and columns empty but the diagonal, whose
        equation gives the prescribed value; the other rows lifted by K's columns times the values."""
        lifted = self.f - self.K[:, self.dofs] @ self.values
        keep = np.ones(self.K.shape[0])
        keep[self.dofs] = 0.0
        mask = scipy.sparse.diags(keep)
        diagonal = self.K.diagonal()
        K = (mask @ self.K @ mask + scipy.sparse.diags(1.0 - keep) @ scipy.sparse.diags(diagonal)).tocsr()
        K.sort_indices()
        lifted[self.dofs] = diagonal[self.dofs] * self.values
        return BlockSystem(name, K.indptr.astype(np.int64), K.indices.astype(np.int64), K.data, lifted,
                           np.zeros(0, dtype=np.int64), K.shape[0], block_size=3)


def half_system(scene: Scene, half: SolidHalf, supports: tuple[np.ndarray, np.ndarray] | None = None) -> HalfSystem:
    """The half's stiffness (its region's material of ``layer1``), the loads on its sides, its temperature change
    (``temperature.layer1``) and its supports (``supports``: these prescribed dofs and values instead of
    :func:`prescribed`'s)."""
    material = scene.material("layer1", half.name)
    D = elastic_matrix(material)
    K = stiffness(half.points, half.tetrahedra, D)
    f = np.zeros(half.dofs)
    for (_, side), load in scene.loads.items():
        f += boundary_load(half.points, half.faces[side], load, side, not scene.geometry.solid_file)
    offset = 0.0
    if "layer1" in scene.temperature:
        thermal, offset = thermal_load(half.points, half.tetrahedra, D, materials.solid_expansion(material),
                                       scene.temperature["layer1"])
        f += thermal
    dofs, values = prescribed(scene, half) if supports is None else supports
    return HalfSystem(K, f, dofs, values, offset)


def check_range(scene: Scene, mesh: SolidMesh) -> SolidMesh:
    """``mesh``, once the moduli, loads, prescribed values and temperature change of each of its regions are within
    what a double-precision solve represents (the plane's rule, :func:`ddsolve.fem.ranges.check_range`, at the
    regions' nodes); else refused in one line naming their keys, before any assembly."""
    size = float(np.ptp(np.vstack([half.points for half in mesh.regions]), axis=0).max())
    driven, stiffest = [], (0.0, "")
    for half in mesh.regions:
        material = scene.material("layer1", half.name)
        key = scene.material_key("layer1", half.name) + (".E" if isinstance(material, materials.Isotropic) else "")
        with np.errstate(all="ignore"):
            stiffness = ranges.checked_stiffness(float(np.abs(elastic_matrix(material)).max()), key)
        for (_, side), item in [*scene.loads.items(), *scene.displacements.items()]:
            at = half.points[np.unique(half.faces[side])]
            value = max((float(np.abs(_evaluated(part, at, item.key)).max(initial=0.0))
                         for part in item.parts.values()), default=0.0)
            if value:
                driven.append(ranges.driven_by(item, value, size, key, stiffness))
        if "layer1" in scene.temperature:
            change = float(np.abs(_evaluated(scene.temperature["layer1"], half.points, "temperature.layer1")).max())
            with np.errstate(all="ignore"):
                eigenstrain = materials.solid_expansion(material)
            if change:
                driven.append(ranges.heated(scene, ("layer1", half.name), eigenstrain, change, size))
        stiffest = max(stiffest, (stiffness, key))
    ranges.refuse_driven(driven, stiffest)
    return mesh
