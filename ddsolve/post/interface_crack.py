"""An interface crack between different isotropic materials: the oscillation index ε, the complex stress
intensity K = K₁ + iK₂ by the interaction integral, and the phase ψ at a reference length.

Near the tip of a crack on the interface of material 1 (above, in the tip's frame: x along the extension,
y turned 90° counter-clockwise from it) and material 2 (below), the tractions ahead are (Rice 1988)

    σ_yy + iσ_xy = K r^{iε} / √(2πr),   ε = (1/2π) ln[(κ₁/μ₁ + 1/μ₂)/(κ₂/μ₂ + 1/μ₁)],

κ = 3 − 4ν (plane strain) or (3 − ν)/(1 + ν) (plane stress), and G = |K|²/(E* cosh²πε), 2/E* = 1/Ē₁ + 1/Ē₂.
The interaction integral of the solution with the auxiliary tip field of K = 1 and of K = i
(:func:`tip_field`: Matos, Moran and Shih 1989) gives 2K₁/(E* cosh²πε) and 2K₂/(E* cosh²πε); the domain
form is G's (ddsolve.post.fracture) with the cross terms.  The phase at a reference length l is
ψ = arg(K l^{iε}), and G splits there into G_I = G cos²ψ and G_II = G sin²ψ: for ε = 0 the classical
split.  The structure's two layers are tied along Σ: where each layer's pair is one pair times a factor,
they carry the same near-tip field and K is that of one sheet of the summed stiffness
(:func:`ddsolve.problem.materials.interface_pair`).  No PETSc or MPI here.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from ddsolve.fem import assembly
from ddsolve.mesh.mesh import SigmaLine
from ddsolve.problem import materials
from ddsolve.problem.materials import Bimaterial
from ddsolve.problem.scene import Scene
from ddsolve.problem.schema import REGIONS

#: The complex step of the auxiliary field's derivatives (exact to rounding for any small step).
STEP = 1e-30


def oscillation(pair: Bimaterial, upper_first: bool = True) -> float:
    """ε with material 1 the upper region (``upper_first``) or the lower one."""
    (mu_1, kappa_1), (mu_2, kappa_2) = (pair.upper, pair.lower) if upper_first else (pair.lower, pair.upper)
    return math.log((kappa_1 / mu_1 + 1.0 / mu_2) / (kappa_2 / mu_2 + 1.0 / mu_1)) / (2.0 * math.pi)


def modulus(pair: Bimaterial) -> float:
    """E*: 2/E* = 1/Ē₁ + 1/Ē₂, Ē = 8μ/(κ + 1)."""
    return 16.0 / sum((kappa + 1.0) / mu for mu, kappa in (pair.lower, pair.upper))


def release(K: np.ndarray, epsilon: float, pair: Bimaterial) -> np.ndarray:
    """G = |K|²/(E* cosh²πε) of the complex K."""
    return np.abs(K) ** 2 / (modulus(pair) * math.cosh(math.pi * epsilon) ** 2)


def tip_field(x: np.ndarray, y: np.ndarray, shear: float, kappa: float, epsilon: float, side: int
              ) -> tuple[np.ndarray, np.ndarray]:
    """The displacements ``(2, ...)`` in the tip's frame of the tip fields of K = 1 and K = i at (x, y), in the
    material (μ = ``shear``, κ) above (``side`` 1, y > 0) or below (−1) the interface.  Real or complex
    arguments (the complex step of :func:`tip_gradients`)."""
    r = np.sqrt(x * x + y * y)
    with np.errstate(divide="ignore", invalid="ignore"):  # tan(θ/2) = y/(r + x) = (r − x)/y: the better one
        angle = 2.0 * np.where(np.real(x) >= 0.0, np.arctan(y / (r + x)), np.arctan((r - x) / y))
    delta = np.exp(epsilon * (angle - side * math.pi))
    minus, plus = kappa * delta - 1.0 / delta, kappa * delta + 1.0 / delta
    rho = epsilon * np.log(r)
    beta = (0.5 * np.cos(rho) + epsilon * np.sin(rho)) / (0.25 + epsilon ** 2)
    beta_bar = (0.5 * np.sin(rho) - epsilon * np.cos(rho)) / (0.25 + epsilon ** 2)
    cosine, sine = np.cos(0.5 * angle), np.sin(0.5 * angle)
    d = beta * minus * cosine + beta_bar * plus * sine
    c = beta_bar * minus * cosine - beta * plus * sine
    phase, swing = rho + 0.5 * angle, 2.0 * delta * np.sin(angle)
    factor = np.sqrt(r) / (4.0 * shear * math.cosh(math.pi * epsilon) * math.sqrt(2.0 * math.pi))
    return (factor * np.stack([d + swing * np.sin(phase), -c - swing * np.cos(phase)]),
            factor * np.stack([-c + swing * np.cos(phase), -d + swing * np.sin(phase)]))


def tip_gradients(x: np.ndarray, y: np.ndarray, shear: float, kappa: float, epsilon: float, side: int
                  ) -> np.ndarray:
    """``(2, ..., 2, 2)``: u_i,j of the tip fields of K = 1 and K = i (:func:`tip_field`), by the complex step."""
    x, y = np.asarray(x, dtype=np.complex128), np.asarray(y, dtype=np.complex128)
    along = tip_field(x + 1j * STEP, y, shear, kappa, epsilon, side)
    across = tip_field(x, y + 1j * STEP, shear, kappa, epsilon, side)
    return np.stack([np.moveaxis(np.stack([np.imag(a), np.imag(b)], axis=-1), 0, -2) / STEP
                     for a, b in zip(along, across)])


def global_gradients(points: np.ndarray, tip: np.ndarray, direction: np.ndarray, material: tuple[float, float],
                     epsilon: float, side: int) -> np.ndarray:
    """``(2, ..., 2, 2)``: u_i,j in x, y of the tip fields of K = 1 and K = i at ``points`` ``(..., 2)`` for the
    tip at ``tip`` extending along ``direction``, in the ``material`` (μ, κ) on the ``side`` of the tip
    frame's y (1: material 1, −1: material 2) of an interface of index ``epsilon``."""
    frame = np.array([direction, [-direction[1], direction[0]]])  # rows: the tip frame's x and y
    local = (points - tip) @ frame.T
    return frame.T @ tip_gradients(local[..., 0], local[..., 1], *material, epsilon, side) @ frame


def intensity(terms: np.ndarray, epsilon: float, pair: Bimaterial) -> complex:
    """K from the interaction integrals (M₁, M₂) with the tip fields of K = 1 and K = i."""
    scale = 0.5 * modulus(pair) * math.cosh(math.pi * epsilon) ** 2
    return complex(scale * terms[0], scale * terms[1])


def phase(K: complex, epsilon: float, length: float) -> float:
    """ψ = arg(K l^{iε}) in degrees at the reference length l."""
    return math.degrees(np.angle(K * length ** (1j * epsilon)))


# --- the tips of a scene -------------------------------------------------------------------------
def interface_pair(scene: Scene) -> Bimaterial | str | None:
    """The effective isotropic pair below and above Σ where the regions of a layer have different elastic laws
    (:func:`ddsolve.problem.materials.interface_pair`), or why there is none; None where every layer has one
    law on both sides (the mirror or closure split)."""
    if not scene.dissimilar_layers(thermal=False):
        return None
    laws = {region: [assembly.elasticity(scene, layer, region)[0] for layer in scene.layers] for region in REGIONS}
    return materials.interface_pair(laws["lower"], laws["upper"])


def tip_frame(tip, sigma: SigmaLine) -> int:
    """1 where the tip's frame's y (its extension turned 90° counter-clockwise) points into the upper region,
    else −1 (``tip``: a :class:`ddsolve.post.fracture.Tip`)."""
    return 1 if sigma.normals[tip.node] @ np.array([-tip.direction[1], tip.direction[0]]) > 0.0 else -1


def tip_epsilon(tip, sigma: SigmaLine, pair: Bimaterial) -> float:
    """ε at the tip, material 1 on the side of its frame's y."""
    return oscillation(pair, upper_first=tip_frame(tip, sigma) > 0)


def tip_fields(tip, sigma: SigmaLine, pair: Bimaterial, side: int):
    """The gradients of the tip fields of K = 1 and K = i in the region on ``side`` of Σ (−1 below), as a function
    of the quadrature points (:func:`ddsolve.post.fracture.interaction_terms`)."""
    frame_side = side * tip_frame(tip, sigma)
    material = pair.lower if side < 0 else pair.upper
    return functools.partial(global_gradients, tip=tip.point, direction=tip.direction,
                             material=material, epsilon=tip_epsilon(tip, sigma, pair), side=frame_side)


def reference_length(scene: Scene) -> float:
    """The length l of the phase ψ = arg(K l^{iε}): ``fracture.reference_length``, else 1 (ψ = arg K)."""
    given = scene.fracture.reference_length
    return 1.0 if given is None else float(given)


def interface_split(tips: list, G: np.ndarray, interaction: np.ndarray, sigma: SigmaLine, scene: Scene,
                    closed: np.ndarray) -> dict[str, np.ndarray]:
    """G's split at the tips of an interface crack between different materials from the interaction integrals
    ``(t, 2)`` (:func:`ddsolve.post.fracture.block_terms`): ε, K = K₁ + iK₂ ``(t, 2)``, ψ = arg(K l^{iε})
    (degrees) at the scene's :func:`reference_length` and G_I = G cos²ψ, G_II = G sin²ψ (docs/fracture.md).
    A ``closed`` tip (its faces touch at the crack node nearest it) slides only: G_I = 0, ψ = ±90°."""
    pair, length = interface_pair(scene), reference_length(scene)
    count = len(tips)
    out = {"G_I": np.full(count, np.nan), "G_II": np.full(count, np.nan), "phase": np.full(count, np.nan),
           "symmetric": np.zeros(count, dtype=bool), "epsilon": np.full(count, np.nan),
           "K": np.full((count, 2), np.nan)}
    for i, tip in enumerate(tips):
        epsilon = tip_epsilon(tip, sigma, pair)
        out["epsilon"][i] = epsilon
        if not np.all(np.isfinite(interaction[i])):
            continue
        K = intensity(interaction[i], epsilon, pair)
        out["K"][i] = K.real, K.imag
        psi = phase(K, epsilon, length)
        if closed[i]:
            psi = math.copysign(90.0, psi)
        out["phase"][i] = psi
        out["G_I"][i] = 0.0 if closed[i] else G[i] * math.cos(math.radians(psi)) ** 2
        out["G_II"][i] = G[i] if closed[i] else G[i] * math.sin(math.radians(psi)) ** 2
    return out
