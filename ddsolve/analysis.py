"""Numbers about results: error of one result against another, and the constraints' residuals."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import assembly, materials, scene as scenes
from .errors import DDSolveError
from .interface import BLOCKS
from .result import Result


def elasticities(result: Result) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Layer -> (D, c) of the result's scene (see :func:`ddsolve.materials.elasticity`)."""
    scene = scenes.loads(result.scene)
    return {layer: assembly.elasticity(scene, layer) for layer in scenes.LAYERS}


def block_energies(result: Result, difference: Result | None = None) -> np.ndarray:
    """‖x_b‖²_K per block (of ``result − difference`` when given), with the result's materials."""
    laws = elasticities(result)
    out = []
    for spec in BLOCKS:
        half = result.half(spec.name)
        field = result.solution[spec.name]
        if difference is not None:
            field = field - difference.solution[spec.name]
        out.append(assembly.energy(half.points, half.cells, laws[spec.layer][0], field))
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
    """Evaluate the field ``values`` (n, c) of ``half`` at ``points`` (q, 2) inside that half, linearly
    on each triangle's corners (exact for P1 fields)."""
    from matplotlib.tri import Triangulation

    corners = half.corners
    triangulation = Triangulation(half.points[:, 0], half.points[:, 1], corners)
    cell = triangulation.get_trifinder()(points[:, 0], points[:, 1])
    if np.any(cell < 0):
        raise DDSolveError(f"{int(np.sum(cell < 0))} points lie outside the {half.name} mesh")
    p = half.points[corners[cell]]  # (q, 3, 2)
    d1, d2, d = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], points - p[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    l1 = (d[:, 0] * d2[:, 1] - d[:, 1] * d2[:, 0]) / det
    l2 = (d1[:, 0] * d[:, 1] - d1[:, 1] * d[:, 0]) / det
    weights = np.column_stack([1.0 - l1 - l2, l1, l2])
    return np.einsum("qk,qkc->qc", weights, values[corners[cell]])


def discretization_error(coarse: Result, fine: Result) -> float:
    """Relative energy-norm distance between a coarse solution and a fine one, on the fine mesh."""
    laws = elasticities(fine)
    error = reference = 0.0
    for spec in BLOCKS:
        half = fine.half(spec.name)
        field = fine.solution[spec.name]
        coarse_field = interpolate(coarse.half(spec.name), coarse.solution[spec.name], half.points)
        error += assembly.energy(half.points, half.cells, laws[spec.layer][0], field - coarse_field)
        reference += assembly.energy(half.points, half.cells, laws[spec.layer][0], field)
    return float(np.sqrt(error / reference))


@dataclass(frozen=True)
class CellFields:
    """Per-cell fields of one block from each cell's mean strain; Voigt order (xx, yy, xy)."""

    strain: np.ndarray  # (m, 3) εxx, εyy, γxy = 2 εxy
    strain_zz: np.ndarray  # (m,) 0 in plane strain; from σzz = 0 in plane stress (NaN if the law is not known)
    stress: np.ndarray  # (m, 3) σxx, σyy, σxy
    stress_zz: np.ndarray  # (m,) from the plane model (0 in plane stress)
    von_mises: np.ndarray  # (m,)
    energy_density: np.ndarray  # (m,) strain energy per unit area: ½ ∫ ε·σ over the cell / its area


def cell_fields(result: Result) -> dict[str, CellFields]:
    """Block name -> its per-cell strains, stresses, von Mises stress and energy density."""
    scene = scenes.loads(result.scene)
    out = {}
    for spec in BLOCKS:
        half, u = result.half(spec.name), result.solution[spec.name]
        D, c = assembly.elasticity(scene, spec.layer)
        out_of_plane = materials.out_of_plane_strain(scene.materials[spec.layer], scene.model)
        area, strain = assembly.cell_strains(half.points, half.cells, u)
        stress, stress_zz = assembly.cell_stresses(D, c, strain)
        strain_zz = strain @ out_of_plane if out_of_plane is not None else np.full(len(strain), np.nan)
        out[spec.name] = CellFields(
            strain=strain, strain_zz=strain_zz, stress=stress, stress_zz=stress_zz,
            von_mises=materials.von_mises(stress, stress_zz),
            energy_density=0.5 * assembly.cell_energies(half.points, half.cells, D, u) / area)
    return out


def layer_stresses(result: Result) -> dict[str, np.ndarray]:
    """Per-cell von Mises stress of each block."""
    return {name: fields.von_mises for name, fields in cell_fields(result).items()}


def normal_jump(result: Result) -> np.ndarray:
    """[u]·ν = (u⁺ − u⁻)·ν of layer 1 at the k multiplier nodes (negative: overlap)."""
    jump = result.solution["u_plus"][result.interface_nodes("u_plus")] - \
        result.solution["u_minus"][result.interface_nodes("u_minus")]
    return np.einsum("kd,kd->k", jump, result.normals)


def sigma_is_graph(result: Result) -> bool:
    """Whether Σ is a graph over x (x increases along it): Σ quantities are then plotted against x."""
    points = result.interface_points
    return len(points) < 2 or bool(np.all(np.diff(points[:, 0]) > 0))


def along_sigma(result: Result) -> tuple[np.ndarray, str]:
    """The coordinate to plot Σ quantities against: x if Σ is a graph over x, else the arc length."""
    if sigma_is_graph(result):
        return result.interface_points[:, 0], "x on Σ"
    return result.mesh.sigma.arclength[result.multiplier_nodes], "arc length along Σ"


def contact_zones(result: Result, tolerance: float = 1e-9) -> list[tuple[int, int]]:
    """Runs ``[first, last]`` of multiplier nodes where the crack faces touch: crack nodes whose opening
    [u]·ν is at most ``tolerance`` × max |u|.  (Not μᶜ > 0: a multiplier recovered from residuals, as
    the reference's, is round-off where the faces are apart.)"""
    largest = max(np.abs(u).max(initial=0.0) for u in result.solution.values())
    touching = result.crack & (normal_jump(result) <= tolerance * largest)
    return result.mesh.sigma.pieces(touching)
