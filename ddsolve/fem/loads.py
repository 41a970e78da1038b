"""The loads of a block as dof vectors, one description per kind that assembly, reactions, G and the checks
all use: a traction or pressure on a named boundary (a :class:`~ddsolve.problem.scene.Load`: its vector on
a half, :func:`load_vector`), and a layer's temperature change (:class:`ThermalLoad`: its load vector, energy
and eigenstrains).  Which of a scene's loads act on a half: :func:`layer_loads`, :func:`thermal_of`."""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ddsolve.errors import SceneError
from ddsolve.fem.elements import element_dofs, strain_operator
from ddsolve.mesh.element import (TRIANGLE_RULES, edge_points, edge_shapes, element_geometry, gauss_interval,
                                  shape_functions)
from ddsolve.mesh.mesh import HalfMesh
from ddsolve.problem import materials
from ddsolve.problem.expressions import Expression
from ddsolve.problem.scene import Load, Scene


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


def thermal_load(points: np.ndarray, cells: np.ndarray, D: np.ndarray, eigenstrain: np.ndarray,
                 temperature: Expression) -> np.ndarray:
    """∫ Bᵀ D ε₀ over ``cells`` as a dof vector ``(2n,)`` (x, y), ε₀ = ``eigenstrain`` × ΔT(x, y)."""
    xi, weights = TRIANGLE_RULES[6]  # exact to degree 4
    det, gradients = element_geometry(points, cells, xi)
    change = cell_temperatures(points, cells, temperature, xi)
    force = np.einsum("mq,q,mqja,j->ma", det * change, weights, strain_operator(gradients), D @ eigenstrain)
    return np.bincount(element_dofs(cells).ravel(), force.ravel(), minlength=2 * len(points))


def thermal_energy(points: np.ndarray, cells: np.ndarray, D: np.ndarray, eigenstrain: np.ndarray,
                   temperature: Expression) -> float:
    """½ ∫ ε₀ᵀ D ε₀ over ``cells``, ε₀ = ``eigenstrain`` × ΔT(x, y), with the quadrature of :func:`thermal_load`."""
    xi, weights = TRIANGLE_RULES[6]
    det, _ = element_geometry(points, cells, xi)
    change = cell_temperatures(points, cells, temperature, xi)
    return 0.5 * float(np.einsum("mq,q->", det * change ** 2, weights)) * float(eigenstrain @ D @ eigenstrain)


def cell_temperatures(points: np.ndarray, cells: np.ndarray, temperature: Expression, xi: np.ndarray) -> np.ndarray:
    """ΔT ``(m, q)`` at the reference points ``xi`` of every cell; a SceneError if it is not finite."""
    shapes, _ = shape_functions(cells.shape[1], xi)
    position = np.einsum("qk,mkd->mqd", shapes, points[cells])
    change = np.broadcast_to(np.asarray(temperature(position[..., 0], position[..., 1]), dtype=np.float64),
                             position.shape[:2])
    if not np.all(np.isfinite(change)):
        x, y = position[tuple(np.argwhere(~np.isfinite(change))[0])]
        raise SceneError(f"temperature: the temperature change is not finite at (x, y) = ({x:.6g}, {y:.6g})")
    return change


class ThermalLoad(NamedTuple):
    """A layer's temperature change ΔT acting through its eigenstrain per unit ΔT: ε₀ = ``eigenstrain`` × ΔT."""

    eigenstrain: np.ndarray
    temperature: Expression

    def vector(self, points: np.ndarray, cells: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Its load ∫ Bᵀ D ε₀ over ``cells`` (:func:`thermal_load`)."""
        return thermal_load(points, cells, D, *self)

    def energy(self, points: np.ndarray, cells: np.ndarray, D: np.ndarray) -> float:
        """½ ∫ ε₀ᵀ D ε₀ over ``cells`` (:func:`thermal_energy`)."""
        return thermal_energy(points, cells, D, *self)

    def changes(self, points: np.ndarray, cells: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """ΔT ``(m, q)`` at the reference points ``xi`` of every cell (:func:`cell_temperatures`)."""
        return cell_temperatures(points, cells, self.temperature, xi)

    def eigenstrains(self, points: np.ndarray, cells: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """ε₀ ``(m, q, 3)`` at the reference points ``xi`` of every cell."""
        return self.changes(points, cells, xi)[..., None] * self.eigenstrain


def thermal_of(scene: Scene, layer: str, region: str) -> ThermalLoad | None:
    """The thermal load of ``layer`` in ``region`` (the layer's temperature change through the region's
    material), or None when it has no temperature change or expansion there."""
    if layer not in scene.temperature:
        return None
    strain, _ = materials.thermal_strain(scene.material(layer, region), scene.model)
    return ThermalLoad(strain, scene.temperature[layer]) if np.any(strain != 0.0) else None


def load_vector(half: HalfMesh, load: Load) -> np.ndarray:
    """The consistent nodal vector ``(2n,)`` of a traction or pressure on its boundary of ``half``."""
    return boundary_load(half.points, half.edges(load.boundary), load)


def layer_loads(scene: Scene, layer: str, half: HalfMesh) -> list[Load]:
    """The scene's loads on ``layer`` whose boundary this half has."""
    return [load for (name, _), load in scene.loads.items() if name == layer and load.boundary in half.boundaries]
