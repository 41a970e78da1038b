"""Linear elasticity on P1 tetrahedra, vectorized: three displacement components per node (dof 3 i + c),
strains in Voigt order (xx, yy, zz, yz, xz, xy; engineering shears), an isotropic law per half, tractions and
pressures on a half's sides, clamped and prescribed components (rollers: one component) on its sides, and a
half's system with its prescribed dofs decoupled (:func:`half_system`), as the plane blocks have them."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse

from ddsolve.errors import SceneError
from ddsolve.fem.assembly import BlockSystem
from ddsolve.mesh.element import TRIANGLE_RULES, shape_functions
from ddsolve.mesh.solid import SIDE_PLANES, SolidHalf
from ddsolve.problem import expressions, materials
from ddsolve.problem.expressions import Expression
from ddsolve.problem.scene import Load, Scene

#: The reference gradients of the four P1 shape functions 1 − ξ − η − ζ, ξ, η, ζ.
REFERENCE_GRADIENTS = np.array([[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
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


def gradients(points: np.ndarray, tetrahedra: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The shape functions' gradients ``(m, 4, 3)`` on every tetrahedron and their volumes ``(m,)``."""
    corners = points[tetrahedra]
    jacobians = np.einsum("kd,mkj->mjd", REFERENCE_GRADIENTS, corners)  # J[m, j, d] = ∂x_j/∂ξ_d
    inverse = np.linalg.inv(jacobians)  # ∂ξ_d/∂x_j at [m, d, j]
    return np.einsum("kd,mdj->mkj", REFERENCE_GRADIENTS, inverse), np.abs(np.linalg.det(jacobians)) / 6.0


def strain_operator(grads: np.ndarray) -> np.ndarray:
    """B ``(m, 6, 12)``: the Voigt strains of a tetrahedron from its 12 dofs (node-major)."""
    B = np.zeros((len(grads), 6, 4, 3))
    for axis in range(3):
        B[:, axis, :, axis] = grads[:, :, axis]
    for row, (i, j) in zip(range(3, 6), ((1, 2), (0, 2), (0, 1))):
        B[:, row, :, i] = grads[:, :, j]
        B[:, row, :, j] = grads[:, :, i]
    return B.reshape(len(grads), 6, 12)


def element_dofs(cells: np.ndarray) -> np.ndarray:
    """The dofs of every cell's nodes, node-major ``(m, 3 k)``."""
    return (3 * cells[:, :, None] + np.arange(3)).reshape(len(cells), 3 * cells.shape[1])


def stiffness(points: np.ndarray, tetrahedra: np.ndarray, D: np.ndarray) -> scipy.sparse.csr_matrix:
    """K = Σ_e |e| Bᵀ D B over the tetrahedra (one elastic matrix ``D`` for all)."""
    grads, volumes = gradients(points, tetrahedra)
    B = strain_operator(grads)
    local = volumes[:, None, None] * (B.transpose(0, 2, 1) @ (D @ B))  # batched products: einsum's 4 operands crawl
    dofs = element_dofs(tetrahedra)
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    size = 3 * len(points)
    return scipy.sparse.csr_matrix((local.ravel(), (rows, cols)), shape=(size, size))


def strains(points: np.ndarray, tetrahedra: np.ndarray, u: np.ndarray) -> np.ndarray:
    """The Voigt strains ``(m, 6)`` of the displacements ``u`` (3 per node) on every tetrahedron."""
    B = strain_operator(gradients(points, tetrahedra)[0])
    return np.einsum("mij,mj->mi", B, u[element_dofs(tetrahedra)])


def rigid_modes(points: np.ndarray) -> np.ndarray:
    """The six rigid-body motions ``(6, 3 n)``: three translations, three rotations about the centroid."""
    r = points - points.mean(axis=0)
    modes = np.zeros((6, len(points), 3))
    modes[np.arange(3), :, np.arange(3)] = 1.0
    for k, axis in enumerate(np.eye(3)):
        modes[3 + k] = np.cross(axis, r)
    return modes.reshape(6, -1)


def face_load(points: np.ndarray, triangles: np.ndarray, traction) -> np.ndarray:
    """∫ t·φ over the triangles for a traction ``traction(x, y, z) -> (q, 3)`` at points, by a degree-4 rule."""
    xi, w = TRIANGLE_RULES[6]
    shapes, _ = shape_functions(3, xi)  # (q, 3)
    a, b, c = (points[triangles[:, k]] for k in range(3))
    areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    at = np.einsum("qk,tkd->tqd", shapes, points[triangles])  # (t, q, 3)
    values = traction(at.reshape(-1, 3)).reshape(len(triangles), len(w), 3)
    nodal = np.einsum("tqd,q,qk,t->tkd", values, 2.0 * w, shapes, areas)  # the rule's weights sum to ½
    return np.bincount(element_dofs(triangles).ravel(), nodal.ravel(), minlength=3 * len(points))


def side_traction(load: Load, side: str):
    """The traction of ``load`` on the box side ``side`` at points ``(q, 3)``: its x, y, z components, or
    −pressure × the side's outward normal; each an expression in x, y and z."""
    axis, end = SIDE_PLANES[side]
    outward = np.zeros(3)
    outward[axis] = 1.0 if end else -1.0

    def traction(at: np.ndarray) -> np.ndarray:
        if load.pressure is not None:
            values = -_evaluated(load.pressure, at, load.key)[:, None] * outward
        else:
            values = np.stack([np.zeros(len(at)) if getattr(load, name) is None else
                               _evaluated(getattr(load, name), at, load.key) for name in AXES], axis=1)
        return values
    return traction


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
    """A half's stiffness ``K`` and load ``f`` as assembled, its prescribed ``dofs`` and their ``values``."""

    K: scipy.sparse.csr_matrix
    f: np.ndarray
    dofs: np.ndarray
    values: np.ndarray

    def energy(self, u: np.ndarray) -> float:
        """Π = ½ uᵀ K u − fᵀ u: the strain energy less the work of the loads."""
        return float(0.5 * u @ (self.K @ u) - self.f @ u)

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


def half_system(scene: Scene, half: SolidHalf) -> HalfSystem:
    """The half's stiffness (its region's material of ``layer1``), the loads on its sides and its supports."""
    material = scene.material("layer1", half.name)
    K = stiffness(half.points, half.tetrahedra, isotropic(material))
    f = np.zeros(half.dofs)
    for (_, side), load in scene.loads.items():
        f += face_load(half.points, half.faces[side], side_traction(load, side))
    dofs, values = prescribed(scene, half)
    return HalfSystem(K, f, dofs, values)
