"""Fields of a solution: strains, stresses and energies at quadrature points and per cell, and a block's
elastic matrices (its layer's material in its region) under the scene's plane model."""
from __future__ import annotations

import numpy as np

from ddsolve.fem.loads import thermal_of
from ddsolve.mesh.element import TRIANGLE_RULES, element_geometry, field_gradients
from ddsolve.problem import materials
from ddsolve.problem.scene import Scene


def elasticity(scene: Scene, layer: str, region: str) -> tuple[np.ndarray, np.ndarray]:
    """(D, c) of ``layer`` in ``region`` under the scene's plane model (:meth:`Scene.material`,
    :func:`ddsolve.problem.materials.elasticity`)."""
    return materials.elasticity(scene.material(layer, region), scene.model)


def voigt_strain(grad_u: np.ndarray) -> np.ndarray:
    """(εxx, εyy, γxy) ``(..., 3)`` from the displacement gradient ``(..., 2, 2)`` (u_d,e)."""
    return np.stack([grad_u[..., 0, 0], grad_u[..., 1, 1], grad_u[..., 0, 1] + grad_u[..., 1, 0]], axis=-1)


def quadrature_strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray, rule: tuple | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """det J × weight ``(m, q)`` and the strain ``(m, q, 3)`` of the field u ``(n, 2)`` at the points of
    ``rule`` (reference points, weights; the element's by default)."""
    xi, weights = TRIANGLE_RULES[cells.shape[1]] if rule is None else rule
    det, gradients = element_geometry(points, cells, xi)
    return det * weights, voigt_strain(field_gradients(u[cells], gradients))


def quadrature_fields(scene: Scene, layer: str, region: str, points: np.ndarray, cells: np.ndarray, u: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`quadrature_strains` of the field u ``(n, 2)`` of ``layer`` in ``region`` and its ΔT ``(m, q)`` at the
    same points: the element rule's (ΔT zero) without a thermal load, else the rule of :func:`thermal_load` and
    :func:`thermal_energy`."""
    thermal = thermal_of(scene, layer, region)
    if thermal is None:
        volume, strain = quadrature_strains(points, cells, u)
        return volume, strain, np.zeros(volume.shape)
    rule = TRIANGLE_RULES[6]
    return (*quadrature_strains(points, cells, u, rule), thermal.changes(points, cells, rule[0]))


def cell_means(volume: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: area ``(m,)`` and the mean of ``values`` ``(m, q, c)`` given at the rule's points with
    their ``volume`` ``(m, q)`` (det J × weight)."""
    area = volume.sum(axis=1)
    return area, np.einsum("mq,mqi->mi", volume, values) / area[:, None]


def integrated_energies(volume: np.ndarray, strain: np.ndarray, D: np.ndarray) -> np.ndarray:
    """Per cell ∫ εᵀ D ε from the strains ``(m, q, 3)`` at the rule's points with their ``volume``."""
    return np.einsum("mq,mqi->m", volume, (strain @ D) * strain)


def cell_strains(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell: area ``(m,)`` and mean strain (εxx, εyy, γxy) ``(m, 3)`` of the field u ``(n, 2)``."""
    return cell_means(*quadrature_strains(points, cells, u))


def energy(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray) -> float:
    """uᵀ K u = ∫ ε(u)ᵀ D ε(u) for the unconstrained stiffness K of this mesh."""
    return float(cell_energies(points, cells, D, u).sum())


def cell_energies(points: np.ndarray, cells: np.ndarray, D: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per cell ∫ ε(u)ᵀ D ε(u) (twice the strain energy of the cell)."""
    return integrated_energies(*quadrature_strains(points, cells, u), D)


def cell_stresses(D: np.ndarray, c: np.ndarray, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(σxx, σyy, σxy) ``(m, 3)`` and σzz ``(m,)`` from strains ``(m, 3)``."""
    return strain @ D.T, strain @ c


def von_mises(points: np.ndarray, cells: np.ndarray, D: np.ndarray, c: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Per-cell von Mises stress of the mean strain (σzz from the plane model included)."""
    _, strain = cell_strains(points, cells, u)
    return materials.von_mises(*cell_stresses(D, c, strain))
