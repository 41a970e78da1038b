"""Numbers about results: error of one result against another, and the constraints' residuals."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import assembly, scene as scenes
from .errors import DDSolveError
from .interface import BLOCKS
from .result import Result


def block_energies(result: Result, difference: Result | None = None) -> np.ndarray:
    """‖x_b‖²_K per block (of ``result − difference`` when given), with the result's materials."""
    materials = scenes.loads(result.scene).materials
    out = []
    for spec in BLOCKS:
        half = result.half(spec.name)
        field = result.solution[spec.name]
        if difference is not None:
            field = field - difference.solution[spec.name]
        out.append(assembly.energy(half.points, half.cells, materials[spec.layer], field))
    return np.array(out)


@dataclass(frozen=True)
class Comparison:
    energy_error: float  # sqrt(Σ‖a_b − b_b‖²) / sqrt(Σ‖b_b‖²), energy norms over the four blocks
    max_difference: float  # max nodal |a − b|
    max_displacement: float  # max nodal |b|


def compare(a: Result, b: Result) -> Comparison:
    """Error of ``a`` against ``b`` (the reference); both must be on the same meshes."""
    for half_a, half_b in ((a.lower, b.lower), (a.upper, b.upper)):
        if half_a.points.shape != half_b.points.shape or not np.array_equal(half_a.cells, half_b.cells) \
                or np.abs(half_a.points - half_b.points).max() > 1e-12:
            raise DDSolveError(f"the results are on different meshes ({half_a.name} halves differ)")
    reference = block_energies(b).sum()
    error = block_energies(b, difference=a).sum()
    largest = max(np.abs(b.solution[s.name]).max() for s in BLOCKS)
    difference = max(np.abs(a.solution[s.name] - b.solution[s.name]).max() for s in BLOCKS)
    if reference > 0:
        relative = np.sqrt(error / reference)
    else:  # a zero reference (no load): exact agreement or an infinite relative error
        relative = 0.0 if error == 0 else np.inf
    return Comparison(float(relative), float(difference), float(largest))


@dataclass(frozen=True)
class Constraints:
    penetration: float  # max (u⁻ − u⁺)·ν over crack vertices, / max|u|
    gluing_gap: float  # max |gluing constraint| over Σ, / max|u|
    complementarity: float  # max |μᶜ [u]·ν| / (max|μᶜ| max|u|)
    min_mu_c: float  # smallest contact multiplier (≥ 0 when dual feasible)
    max_displacement: float


def constraints(result: Result) -> Constraints:
    """Residuals of the interface conditions of a result."""
    s = result.solution
    lower, upper = result.lower.sigma()[1:-1], result.upper.sigma()[1:-1]
    u_minus, u_plus = s["u_minus"][lower], s["u_plus"][upper]
    v_minus, v_plus = s["v_minus"][lower], s["v_plus"][upper]
    crack = result.crack
    largest = max(np.abs(s[spec.name]).max() for spec in BLOCKS)
    scale = largest if largest > 0 else 1.0
    jump = u_plus[:, 1] - u_minus[:, 1]
    gaps = [np.abs(u_minus - v_minus).ravel(), np.abs(u_plus - v_plus).ravel(),
            np.abs(u_minus - u_plus)[~crack].ravel()]
    mu_c = result.multipliers["mu_c"][crack]
    mu_scale = np.abs(mu_c).max(initial=0.0) or 1.0
    return Constraints(
        penetration=float(np.maximum(-jump[crack], 0.0).max(initial=0.0) / scale),
        gluing_gap=float(max(g.max(initial=0.0) for g in gaps) / scale),
        complementarity=float(np.abs(mu_c * jump[crack]).max(initial=0.0) / (mu_scale * scale)),
        min_mu_c=float(mu_c.min(initial=0.0)),
        max_displacement=float(largest),
    )


def interpolate(half, values: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Evaluate the P1 field ``values`` (n, c) of ``half`` at ``points`` (q, 2) inside that half."""
    from matplotlib.tri import Triangulation

    triangulation = Triangulation(half.points[:, 0], half.points[:, 1], half.cells)
    cell = triangulation.get_trifinder()(points[:, 0], points[:, 1])
    if np.any(cell < 0):
        raise DDSolveError(f"{int(np.sum(cell < 0))} points lie outside the {half.name} mesh")
    corners = half.points[half.cells[cell]]  # (q, 3, 2)
    d1, d2, d = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], points - corners[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    l1 = (d[:, 0] * d2[:, 1] - d[:, 1] * d2[:, 0]) / det
    l2 = (d1[:, 0] * d[:, 1] - d1[:, 1] * d[:, 0]) / det
    weights = np.column_stack([1.0 - l1 - l2, l1, l2])
    return np.einsum("qk,qkc->qc", weights, values[half.cells[cell]])


def discretization_error(coarse: Result, fine: Result) -> float:
    """Relative energy-norm distance between a coarse solution and a fine one, on the fine mesh."""
    materials = scenes.loads(fine.scene).materials
    error = reference = 0.0
    for spec in BLOCKS:
        half = fine.half(spec.name)
        field = fine.solution[spec.name]
        coarse_field = interpolate(coarse.half(spec.name), coarse.solution[spec.name], half.points)
        error += assembly.energy(half.points, half.cells, materials[spec.layer], field - coarse_field)
        reference += assembly.energy(half.points, half.cells, materials[spec.layer], field)
    return float(np.sqrt(error / reference))


def layer_stresses(result: Result) -> dict[str, np.ndarray]:
    """Per-cell von Mises stress of each block."""
    materials = scenes.loads(result.scene).materials
    return {spec.name: assembly.von_mises(result.half(spec.name).points, result.half(spec.name).cells,
                                          materials[spec.layer], result.solution[spec.name])
            for spec in BLOCKS}


def normal_jump(result: Result) -> np.ndarray:
    """[u]·ν = u⁺_y − u⁻_y of layer 1 at the inner Σ vertices (negative: overlap)."""
    lower, upper = result.lower.sigma()[1:-1], result.upper.sigma()[1:-1]
    return result.solution["u_plus"][upper, 1] - result.solution["u_minus"][lower, 1]
