"""What a scene's data drives, before any work: loads, prescribed displacements and temperature changes
sampled densely (finite, not singular: :func:`load_extent`, :func:`field_extent`), moduli and the displacements
they drive within what double precision represents (:func:`check_range`), and the scales of the data
(:func:`modulus`, :func:`data_displacement`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddsolve.errors import SceneError
from ddsolve.fem.fields import elasticity
from ddsolve.fem.loads import HIGH_ORDER_POINTS, thermal_of
from ddsolve.mesh.element import TRIANGLE_RULES, edge_shapes, gauss_interval, shape_functions
from ddsolve.mesh.mesh import SigmaLine
from ddsolve.problem import expressions, materials
from ddsolve.problem.expressions import Expression
from ddsolve.problem.scene import Displacement, Load, Scene


#: A load is checked at LOAD_SAMPLES points of each edge (endpoints included) and at the quadrature points;
#: a part that is not a polynomial is then sampled CLOSING_STEPS times ever closer (4 times each step) to
#: each edge's largest value, to 1e-21 of the edge, below the resolution of doubles at the box's size.
#: Growing by more than GROWTH over GROWTH_STEPS steps (a distance 4^6 times smaller) once the samples are
#: closer than 1e-10 of the edge (FINE_STEP), where a bounded load has long stopped growing, it is singular.
LOAD_SAMPLES = 33
CLOSING_STEPS = 32
FINE_STEP = 14
GROWTH_STEPS = 6
GROWTH = 2.0


def load_extent(points: np.ndarray, edges: np.ndarray, load: Load | Displacement) -> float:
    """The largest |value| of the parts of ``load`` (a load or a prescribed displacement) along ``edges``,
    sampled densely; a SceneError naming the part's key if a value is not finite or grows without bound (a
    singular load, whose integral would depend on the mesh, as would the solution)."""
    largest = 0.0
    if len(edges) == 0:
        return largest
    start = np.concatenate([np.linspace(0.0, 1.0, LOAD_SAMPLES), gauss_interval(HIGH_ORDER_POINTS)[0]])
    offsets = np.linspace(-1.0, 1.0, 9)[:, None]  # 0 among them: each step keeps the best point so far
    noun = load.NOUN
    for component, part in load.parts.items():
        key = f"{load.key}.{component}"

        def sample(at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            values, position = _sampled(points, edges, part, at[..., 0], key, noun)
            return values, position, values

        at = np.broadcast_to(start[:, None], (len(edges), len(start), 1))
        growth = _closing_in(sample, at, lambda center, width: np.clip(center[:, None] + width * offsets, 0.0, 1.0),
                             1.0 / (LOAD_SAMPLES - 1), part.degree is None)
        if growth.unbounded is not None:
            x, y = growth.unbounded
            raise SceneError(f"{key}: the {noun} grows without bound towards (x, y) = ({x:.6g}, {y:.6g}) (to "
                             f"{growth.largest:.3g} and still growing as the samples close in): it is singular "
                             f"on its boundary, so its {'integral' if noun == 'load' else 'nodal values'} and the "
                             "solution would depend on the mesh; move the singularity off the boundary")
        largest = max(largest, growth.largest)
    return largest


@dataclass(frozen=True)
class Growth:
    """What closing in on a field's largest values found: the largest |value| seen, and where the values still
    grow without bound (None: bounded)."""

    largest: float
    unbounded: tuple[float, float] | None


def _closing_in(sample, at: np.ndarray, around, width: float, search: bool) -> Growth:
    """Sample a field at the parameters ``at`` ``(e, q, d)`` of e pieces: ``sample(at)`` -> (|values| ``(e, q)``,
    positions ``(e, q, 2)``, and the steering values ``(e, q)``, by default |values|).  If ``search`` (the field
    is not a polynomial), close in CLOSING_STEPS times on each piece's largest steering value, ``around(center
    (e, d), width)`` giving the next parameters, ``width`` shrinking 4 times a step.  Growing by more than GROWTH
    over GROWTH_STEPS steps once the samples are within 1e-10 of the piece (FINE_STEP), where a bounded field
    has long stopped growing, the field is singular there."""
    values, position, steer = sample(at)
    record = [values.max(axis=1)]
    if not search:
        return Growth(float(np.max(record)), None)
    for _ in range(CLOSING_STEPS):
        center = at[np.arange(len(at)), np.argmax(steer, axis=1)]
        at = around(center, width)
        values, position, steer = sample(at)
        record.append(values.max(axis=1))
        width /= 4.0
    fine = np.array(record[FINE_STEP - GROWTH_STEPS:])
    growing = np.flatnonzero((fine[GROWTH_STEPS:] > GROWTH * fine[:-GROWTH_STEPS]).any(axis=0))
    if not len(growing):
        return Growth(float(np.max(record)), None)
    piece = growing[np.argmax(record[-1][growing])]
    x, y = position[piece, np.argmax(values[piece])]
    return Growth(float(record[-1][piece]), (float(x), float(y)))


def _sampled(points: np.ndarray, edges: np.ndarray, part, at: np.ndarray, key: str, noun: str = "load"
             ) -> tuple[np.ndarray, np.ndarray]:
    """|part| at the parameters ``at`` ``(e, q)`` of each edge, and the positions ``(e, q, 2)``; a SceneError
    naming ``key`` if a value is not finite."""
    shapes, _ = edge_shapes(edges.shape[1], at.ravel())
    position = np.einsum("eqk,ekd->eqd", shapes.reshape(*at.shape, -1), points[edges])
    return _finite(part, position, key, f"the {noun} is not finite at (x, y) = ({{:.6g}}, {{:.6g}}); change the "
                   f"expression or the boundary it acts on")


def _finite(part: Expression, position: np.ndarray, key: str, message: str) -> tuple[np.ndarray, np.ndarray]:
    """(|part| at ``position`` ``(..., 2)``, ``position``); a SceneError ``key: message`` (formatted with the
    first point where the value is not finite) otherwise."""
    values = np.abs(part(position[..., 0], position[..., 1]))
    if not np.all(np.isfinite(values)):
        x, y = position[tuple(np.argwhere(~np.isfinite(values))[0])]
        raise SceneError(f"{key}: " + message.format(x, y))
    return values, position


#: A field over the cells (a temperature change) is sampled at the points of a lattice of this order in each
#: cell and at the quadrature points; where it is not a polynomial, the closing-in search runs in the
#: CANDIDATES cells where it is largest, and for each of its divisors (:func:`ddsolve.problem.expressions.divisors`)
#: in the CANDIDATES cells nearest the divisor's zeros, the only places it can grow without bound.
LATTICE = 4
CANDIDATES = 16
#: Cells sampled at once (bounded memory on large meshes).
SAMPLED_CELLS = 2 ** 14


def field_extent(points: np.ndarray, cells: np.ndarray, field: Expression, key: str) -> float:
    """The largest |field| over ``cells``, sampled densely; a SceneError naming ``key`` if a value is not finite
    or the field grows without bound inside a cell (its integrals, and the solution, would depend on the mesh).
    A field that is not a polynomial is closed in on where it is largest and on the zeros of each of its
    divisors, where it may have a pole hidden by larger values elsewhere."""
    if len(cells) == 0:
        return 0.0
    if field.constant:
        return float(_finite(field, points[cells[:1, :1]], key, _NOT_FINITE)[0].max())
    lattice = np.array([(i, j) for i in range(LATTICE + 1) for j in range(LATTICE + 1 - i)], float) / LATTICE
    start = np.vstack([lattice, TRIANGLE_RULES[6][0]])
    steering = [None, *expressions.divisors(field)] if field.degree is None else [None]
    largest = [np.zeros(len(cells)) for _ in steering]  # per cell: |field|, then −|divisor| (nearest its zero)
    for first in range(0, len(cells), SAMPLED_CELLS):
        chunk = slice(first, first + SAMPLED_CELLS)
        values, position, _ = _cell_sample(points, cells[chunk], field, key)(start)
        largest[0][chunk] = values.max(axis=1)
        for index, divisor in enumerate(steering[1:], 1):
            largest[index][chunk] = -np.abs(divisor(position[..., 0], position[..., 1])).min(axis=1)
    extent = float(largest[0].max())
    offsets = np.stack(np.meshgrid(np.linspace(-1.0, 1.0, 9), np.linspace(-1.0, 1.0, 9)), axis=-1).reshape(-1, 2)
    for steer, ranking in zip(steering if field.degree is None else [], largest):
        chosen = np.argsort(-np.nan_to_num(ranking, nan=np.inf))[:CANDIDATES]
        growth = _closing_in(_cell_sample(points, cells[chosen], field, key, steer),
                             np.broadcast_to(start, (len(chosen), *start.shape)),
                             lambda center, width: _in_triangle(center[:, None] + width * offsets), 1.0 / LATTICE, True)
        if growth.unbounded is not None:
            x, y = growth.unbounded
            raise SceneError(f"{key}: the temperature change grows without bound towards (x, y) = ({x:.6g}, "
                             f"{y:.6g}) (to {growth.largest:.3g} and still growing as the samples close in): it is "
                             "singular inside the layer, so its load and energy, and the solution, would depend on "
                             "the mesh; move the singularity out of the layer")
        extent = max(extent, growth.largest)
    return extent


def _cell_sample(points: np.ndarray, cells: np.ndarray, field: Expression, key: str,
                 steer: Expression | None = None):
    """A sampler for :func:`_closing_in` of |field| in ``cells`` (a SceneError naming ``key`` where it is not
    finite), steered towards its largest values, or towards the zeros of ``steer``."""
    def sample(at: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        position = _cell_positions(points, cells, at)
        values, _ = _finite(field, position, key, _NOT_FINITE)
        if steer is None:
            return values, position, values
        return values, position, -np.nan_to_num(np.abs(steer(position[..., 0], position[..., 1])), nan=np.inf)
    return sample


_NOT_FINITE = "the temperature change is not finite at (x, y) = ({:.6g}, {:.6g}); change the expression"


def _cell_positions(points: np.ndarray, cells: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The points ``(m, q, 2)`` at the reference coordinates ``at`` of each cell: ``(m, q, 2)``, or ``(q, 2)``
    the same in every cell."""
    shapes, _ = shape_functions(cells.shape[1], at.reshape(-1, 2))
    if at.ndim == 2:
        return np.einsum("qk,mkd->mqd", shapes, points[cells])
    return np.einsum("mqk,mkd->mqd", shapes.reshape(*at.shape[:2], -1), points[cells])


def _in_triangle(at: np.ndarray) -> np.ndarray:
    """Reference coordinates ``(..., 2)`` moved into the reference triangle (s, t ≥ 0, s + t ≤ 1)."""
    at = np.maximum(at, 0.0)
    total = at.sum(axis=-1, keepdims=True)
    return np.where(total > 1.0, at / np.maximum(total, 1.0), at)


def modulus(scene: Scene) -> float:
    """The largest entry of the blocks' elastic matrices: the scale of the stress a strain makes."""
    return max(float(np.abs(elasticity(scene, layer, region)[0]).max()) for layer in scene.layers
               for region in scene.geometry.region_names)


def data_displacement(scene: Scene, halves, sigma: SigmaLine) -> float:
    """The displacement the scene's data would make, whatever the supports make of it: the largest of the
    prescribed values and of Σ's length × the largest strain of the data (an eigenstrain |ε₀|, a traction
    / the layer's largest modulus), at the nodes of ``halves`` (whole halves or pieces of them: the largest
    over the pieces is the whole's).  The scale of the KKT check where the solution itself is (near) zero
    (a heated plate clamped all round); 0 for a scene without data.  Values that are not finite are left
    out (assembly refuses them).  A scale, not a range check: the values at the nodes, where
    :func:`driven_displacements` samples densely once, before any work, to refuse data out of range."""
    def largest(expression: Expression | None, points: np.ndarray) -> float:
        if expression is None or not len(points):
            return 0.0
        values = np.abs(expression(points[:, 0], points[:, 1]))
        return float(values[np.isfinite(values)].max(initial=0.0))

    prescribed, strain = 0.0, 0.0
    for half in halves:
        for layer in scene.layers:
            stiffness = float(np.abs(elasticity(scene, layer, half.name)[0]).max())
            thermal = thermal_of(scene, layer, half.name)
            if thermal is not None:
                strain = max(strain, float(np.abs(thermal.eigenstrain).max())
                             * largest(thermal.temperature, half.points))
            for (name, boundary), load in scene.loads.items():
                at = half.points[np.unique(half.edges(boundary))] if name == layer else half.points[:0]
                strain = max(strain, *(largest(getattr(load, part), at) / stiffness for part in load.COMPONENTS))
            for (name, boundary), displacement in scene.displacements.items():
                at = half.points[np.unique(half.edges(boundary))] if name == layer else half.points[:0]
                prescribed = max(prescribed, *(largest(getattr(displacement, part), at)
                                               for part in displacement.COMPONENTS))
    return max(prescribed, strain * float(sigma.weights.sum()))


#: Stiffnesses (the largest entry of a layer's elastic matrix) whose element matrices stay normal
#: double-precision numbers on any sensible mesh.
STIFFNESS_RANGE = (1e-280, 1e280)


#: Displacements whose squares (norms, energies) stay far inside double precision.
DISPLACEMENT_RANGE = (1e-100, 1e100)


#: Energies (stiffness × displacement², the scale of the blocks' forces × displacements) that stay normal
#: double-precision numbers with room for the sums over a mesh.
ENERGY_RANGE = (1e-290, 1e290)


def check_range(scene: Scene, mesh) -> None:
    """Refuse moduli, loads, prescribed displacements and thermal eigenstrains a double-precision solve cannot
    represent, naming their keys.

    Each block's stiffness is the largest entry of its elastic matrix (its layer's material in its region); the
    structure's displacements (the layers are glued) are of the order of the largest of what drives them
    (:func:`driven_displacements`): (largest traction on a block) × (size of the mesh) / its stiffness, the
    largest prescribed value, (largest eigenstrain αΔT) × (size of the mesh).  Blocks are scaled to order one
    (:class:`ddsolve.parallel.blocks.Block`), so only the ranges matter: stiffnesses within STIFFNESS_RANGE, displacements within DISPLACEMENT_RANGE (their
    squares must not overflow) and the energy stiffness × displacement² within ENERGY_RANGE.  A load, a
    displacement or a temperature change that is not finite or singular is refused first (:func:`load_extent`,
    :func:`field_extent`).
    """
    size = float(np.ptp(np.vstack([half.points for half in mesh.halves]), axis=0).max())
    driven, stiffest = [], (0.0, "")
    for layer, region in ((layer, region) for layer in scene.layers for region in scene.geometry.region_names):
        material = scene.material(layer, region)
        key = scene.material_key(layer, region) + (".E" if isinstance(material, materials.Isotropic) else "")
        with np.errstate(all="ignore"):
            D, _ = materials.elasticity(material, scene.model)
        stiffness = checked_stiffness(float(np.abs(D).max()), key)
        driven += driven_displacements(scene, mesh, (layer, region), size, key, stiffness)
        stiffest = max(stiffest, (stiffness, key))
    refuse_driven(driven, stiffest)


def checked_stiffness(stiffness: float, key: str) -> float:
    """``stiffness``, the largest entry of the elastic matrix ``key``, if within STIFFNESS_RANGE; else refused."""
    low, high = STIFFNESS_RANGE
    if not low <= stiffness <= high:
        raise SceneError(f"{key}: the elastic matrix has entries of {stiffness:.3g}, outside the range a "
                         f"double-precision solve represents ({low:g} to {high:g}): change the unit of stress")
    return stiffness


def refuse_driven(driven: list[tuple[float, str, str]], stiffest: tuple[float, str]) -> None:
    """Refuse the largest of the ``driven`` displacements (order, cause, message) outside DISPLACEMENT_RANGE, or
    with the ``stiffest`` elastic matrix (largest entry, key) energies outside ENERGY_RANGE."""
    if not driven:
        return
    displacement, cause, message = max(driven, key=lambda item: item[0])
    if not DISPLACEMENT_RANGE[0] <= displacement <= DISPLACEMENT_RANGE[1]:
        raise SceneError(message)
    stiffness, key = stiffest
    energy = stiffness * displacement * displacement  # also the force scale K g squared over K
    low, high = ENERGY_RANGE
    if not low <= energy <= high:
        raise SceneError(f"{key}: the elastic matrix (largest entry {stiffness:.3g}) with displacements of order "
                         f"{displacement:.1g} ({cause} drives them) gives energies of order {energy:.1g}, outside "
                         f"the range a double-precision solve represents ({low:g} to {high:g}): change the units "
                         "of the moduli and of what drives the displacements")


def driven_displacements(scene: Scene, mesh, block: tuple[str, str], size: float, key: str, stiffness: float
                         ) -> list[tuple[float, str, str]]:
    """The orders of the displacements of the ``block`` (layer, region) (whose elastic matrix ``key`` has the
    largest entry ``stiffness``, on a mesh of ``size``) that each of its loads, prescribed displacements and its
    eigenstrain makes, each with the keys that make it and the message that refuses it outside
    DISPLACEMENT_RANGE; those driven by zero are left out."""
    layer, region = block
    out = []
    for (name, boundary), load in [*scene.loads.items(), *scene.displacements.items()]:
        halves = [half for half in mesh.halves
                  if name == layer and half.name == region and boundary in half.boundaries]
        value = max((load_extent(half.points, half.edges(boundary), load) for half in halves), default=0.0)
        if value == 0.0:
            continue
        out.append(driven_by(load, value, size, key, stiffness))
    with np.errstate(all="ignore"):  # an expansion beyond double precision is refused below, naming its key
        thermal = thermal_of(scene, layer, region)
    if thermal is not None:
        change = max(field_extent(half.points, half.cells, thermal.temperature, f"temperature.{layer}")
                     for half in mesh.halves if half.name == region)
        if change != 0.0:
            out.append(heated(scene, (layer, region), thermal.eigenstrain, change, size))
    return out


#: What a displacement outside DISPLACEMENT_RANGE is.
OUTSIDE = "outside the range a double-precision solve represents ({:g} to {:g})".format(*DISPLACEMENT_RANGE)


def driven_by(item, value: float, size: float, key: str, stiffness: float) -> tuple[float, str, str]:
    """The order of the displacements a load or prescribed displacement ``item`` up to ``value`` makes on a
    block (elastic matrix ``key``, largest entry ``stiffness``) of ``size``, its key and the message refusing it."""
    if isinstance(item, Load):
        moved = value * size / stiffness
        return (moved, item.key, f"{key}: the elastic matrix (largest entry {stiffness:.3g}) with {item.key} up to "
                f"{value:.3g} on a domain of size {size:.3g} gives displacements of order {moved:.1g}, {OUTSIDE}: "
                "change the units of the moduli and the loads")
    return (value, item.key, f"{item.key}: prescribed values up to {value:.3g}, {OUTSIDE}: change the unit of length")


def heated(scene: Scene, block: tuple[str, str], eigenstrain: np.ndarray, change: float, size: float
           ) -> tuple[float, str, str]:
    """The order of the displacements the ``eigenstrain`` per degree times a temperature change up to ``change``
    makes on the ``block`` (layer, region) of ``size``, its keys and the message refusing it."""
    layer, region = block
    strain = float(np.nan_to_num(np.abs(eigenstrain), nan=np.inf).max()) * change
    alpha = "alpha" if isinstance(scene.material(layer, region), materials.Isotropic) else "alpha1, alpha2"
    cause = f"{scene.material_key(layer, region)}.{alpha} with temperature.{layer}"
    return (strain * size, cause, f"{cause} up to {change:.3g} give eigenstrains of order {strain:.1g} and, on a "
            f"domain of size {size:.3g}, displacements of order {strain * size:.1g}, {OUTSIDE}: change the units of "
            "the expansion coefficient and the temperature")
