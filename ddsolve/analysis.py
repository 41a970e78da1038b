"""Numbers about results: error of one result against another, and the constraints' residuals."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import assembly, scene as scenes
from .errors import DDSolveError
from .interface import BLOCKS
from .result import Result


def elasticities(result: Result) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Layer -> (D, c) of the result's scene (see :func:`ddsolve.materials.elasticity`)."""
    scene = scenes.loads(result.scene)
    return {layer: assembly.elasticity(scene, layer) for layer in scenes.LAYERS}


def block_energies(result: Result, difference: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """‖x_b‖²_K per block (of ``result − difference`` when given: fields on the result's nodes, per
    block), with the result's materials."""
    laws = elasticities(result)
    out = []
    for spec in BLOCKS:
        half = result.half(spec.name)
        field = result.solution[spec.name]
        if difference is not None:
            field = field - difference[spec.name]
        out.append(assembly.energy(half.points, half.cells, laws[spec.layer][0], field))
    return np.array(out)


@dataclass(frozen=True)
class Comparison:
    energy_error: float  # sqrt(Σ‖a_b − b_b‖²) / sqrt(Σ‖b_b‖²), energy norms over the four blocks
    max_difference: float  # max nodal |a − b|
    max_displacement: float  # max nodal |b|


def same_meshes(a: Result, b: Result) -> bool:
    """Whether two results are on the same meshes (nodes and cells of both halves)."""
    return all(half_a.points.shape == half_b.points.shape and np.array_equal(half_a.cells, half_b.cells)
               and np.abs(half_a.points - half_b.points).max() <= 1e-12
               for half_a, half_b in ((a.lower, b.lower), (a.upper, b.upper)))


def compare(a: Result, b: Result) -> Comparison:
    """Error of ``a`` against ``b`` (the reference).  On different meshes (a coarse solution against a
    fine one), ``a`` is first evaluated at ``b``'s nodes with its own shape functions."""
    fields = {s.name: a.solution[s.name] for s in BLOCKS}
    if not same_meshes(a, b):
        fields = {s.name: interpolate(a.half(s.name), a.solution[s.name], b.half(s.name).points) for s in BLOCKS}
    reference = block_energies(b).sum()
    error = block_energies(b, difference=fields).sum()
    largest = max(np.abs(b.solution[s.name]).max() for s in BLOCKS)
    difference = max(np.abs(fields[s.name] - b.solution[s.name]).max() for s in BLOCKS)
    if reference > 0:
        relative = np.sqrt(error / reference)
    else:  # a zero reference (no load): exact agreement or an infinite relative error
        relative = 0.0 if error == 0 else np.inf
    return Comparison(float(relative), float(difference), float(largest))


@dataclass(frozen=True)
class Constraints:
    penetration: float  # max (u⁻ − u⁺)·ν over crack nodes, / max|u|
    gluing_gap: float  # max |gluing constraint| over Σ, / max|u|
    complementarity: float  # max |μᶜ [u]·ν| / (max|μᶜ| max|u|)
    min_mu_c: float  # smallest contact multiplier (≥ 0 when dual feasible)
    max_displacement: float


def constraints(result: Result) -> Constraints:
    """Residuals of the interface conditions of a result."""
    s = result.solution
    u_minus, u_plus, v_minus, v_plus = (s[name][result.interface_nodes(name)]
                                        for name in ("u_minus", "u_plus", "v_minus", "v_plus"))
    crack = result.crack
    largest = max(np.abs(s[spec.name]).max() for spec in BLOCKS)
    scale = largest if largest > 0 else 1.0
    jump = normal_jump(result)
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
    """Evaluate the field ``values`` (n, c) of ``half`` at ``points`` (q, 2) inside that half with the
    element's own shape functions (P1, or isoparametric P2: the reference coordinates of a point are
    found by Newton's method from those in the straight triangle of its corners)."""
    from matplotlib.tri import Triangulation

    corners = half.corners
    triangulation = Triangulation(half.points[:, 0], half.points[:, 1], corners)
    cell = triangulation.get_trifinder()(points[:, 0], points[:, 1])
    if np.any(cell < 0):
        raise DDSolveError(f"{int(np.sum(cell < 0))} points lie outside the {half.name} mesh")
    p = half.points[corners[cell]]  # (q, 3, 2)
    d1, d2, d = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], points - p[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    xi = np.column_stack([(d[:, 0] * d2[:, 1] - d[:, 1] * d2[:, 0]) / det,
                          (d1[:, 0] * d[:, 1] - d1[:, 1] * d[:, 0]) / det])
    nodes = half.points[half.cells[cell]]  # (q, k, 2)
    k = half.cells.shape[1]
    for _ in range(8 if k == 6 else 0):  # Newton on x(ξ) = points
        shapes, gradients = assembly.shape_functions(k, xi)
        residual = np.einsum("qk,qkd->qd", shapes, nodes) - points
        jacobian = np.einsum("qkd,qke->qde", nodes, gradients)
        xi = xi - np.linalg.solve(jacobian, residual[..., None])[..., 0]
    shapes, _ = assembly.shape_functions(k, xi)
    return np.einsum("qk,qkc->qc", shapes, values[half.cells[cell]])


def energy_error(energy: float, exact: float) -> float:
    """Relative energy-norm error sqrt((Π(u_h) − Π(u)) / (−Π(u))) of a conforming solution with total
    potential energy Π(u_h) = ``energy`` against the exact Π(u) = ``exact`` (‖u − u_h‖²_E = 2(Π(u_h) − Π(u))
    for the linear problem, ‖u‖²_E = −2Π(u)); 0 if ``energy`` is below ``exact``."""
    return float(np.sqrt(max(energy - exact, 0.0) / -exact))


def layer_stresses(result: Result) -> dict[str, np.ndarray]:
    """Per-cell von Mises stress of each block."""
    laws = elasticities(result)
    return {spec.name: assembly.von_mises(result.half(spec.name).points, result.half(spec.name).cells,
                                          *laws[spec.layer], result.solution[spec.name])
            for spec in BLOCKS}


def normal_jump(result: Result) -> np.ndarray:
    """[u]·ν = (u⁺ − u⁻)·ν of layer 1 at the k multiplier nodes (negative: overlap)."""
    jump = result.solution["u_plus"][result.interface_nodes("u_plus")] - \
        result.solution["u_minus"][result.interface_nodes("u_minus")]
    return np.einsum("kd,kd->k", jump, result.normals)
