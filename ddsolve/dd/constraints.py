"""The constraints on Σ and their KKT residuals: the scale-free check behind every «converged»."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddsolve.dd.interface import Interface
from ddsolve.mesh.mesh import U_MINUS, U_PLUS
from ddsolve.problem import scene as scenes

#: The smallest tolerance of the final check: residuals at round-off level (with room for the
#: conditioning of fine or strongly graded meshes) always pass.
KKT_FLOOR = 1e-9


#: The final check allows this multiple of a scale-free stopping tolerance (kkt, relative).
KKT_FACTOR = 100.0


#: The tolerance of the final check for the paper's dimensional stopping rule, which has no
#: scale-free meaning of its own.
KKT_PAPER = 1e-5


def kkt_tolerance(solver: scenes.Solver | None) -> float:
    """The scale-free tolerance every residual of :class:`Constraints` must meet for a result to be
    called converged: round-off level for exact solves (``solver`` None: the reference), else
    KKT_FACTOR × the stopping tolerance (KKT_PAPER for the paper's rule), never below KKT_FLOOR."""
    if solver is None:
        return KKT_FLOOR
    if solver.stop == "paper":
        return KKT_PAPER
    return max(KKT_FLOOR, KKT_FACTOR * solver.tol)


@dataclass(frozen=True)
class Constraints:
    """The KKT residuals of a result, each scale-free (0 for an exact solution)."""

    penetration: float  # max (u⁻ − u⁺)·ν > 0 over every crack node under non-penetration (prescribed too), / U
    gluing_gap: float  # max |gluing gap| over Σ (but the gap a multiplier at its bound ±p allows) and max slip of
    # crack faces held by friction below its bound g (or slipping against μ_t where |μ_t| = g), / U
    complementarity: float  # max |μᶜ [u]·ν| (but where μᶜ = p) / (max|λ| U)
    multiplier_bounds: float  # max violation of 0 ≤ μᶜ ≤ p, |μ| ≤ p, |μ_t| ≤ g (a pull on closed crack faces,
    # friction beyond its bound: Coulomb's g = μ max(μᶜ, 0) of the same multipliers), / max|λ|
    equilibrium: float  # max over blocks of ‖K x − f − ℓ(λ)‖∞ / (‖K‖∞‖x‖∞ + ‖f‖∞ + ‖ℓ(λ)‖∞)
    min_mu_c: float  # smallest contact multiplier (≥ 0 when dual feasible)
    max_displacement: float  # max nodal |u|
    displacement_scale: float = 0.0  # U: max|u|, or DATA_FLOOR × the data's displacement where larger

    NAMES = ("penetration", "gluing_gap", "complementarity", "multiplier_bounds", "equilibrium")

    def violations(self, tolerance: float) -> list[str]:
        """``name value`` of every residual above ``tolerance`` (or not a number), worst first."""
        values = {name: getattr(self, name) for name in self.NAMES}
        bad = [(name, value) for name, value in values.items() if not value <= tolerance]
        bad.sort(key=lambda item: -item[1] if np.isfinite(item[1]) else -np.inf)
        return [f"{name.replace('_', ' ')} {value:.2e}" for name, value in bad]

    def summary(self) -> str:
        labels = {"penetration": "max penetration", "gluing_gap": "max gluing gap",
                  "equilibrium": "equilibrium residual"}
        return "   ".join(f"{labels.get(name, name.replace('_', ' '))} {getattr(self, name):.3e}" for name in self.NAMES)


#: The smallest traction scale of the KKT check, as a fraction of the stress scale modulus × U / |Σ|:
#: below it multipliers are round-off (a structure that expands freely carries no stress at all).
STRESS_FLOOR = 1e-6


#: The smallest displacement scale U of the KKT check and of the stopping rules, as a fraction of the
#: displacement the data would make (:attr:`~ddsolve.dd.interface.Interface.data`).  Where the solution is
#: (near) zero but the data is not (a heated plate clamped all round: u ≡ 0, the stress −EαΔT/(1 − 2ν)), its
#: displacements and gaps are both round-off of the data's size, and their ratio means nothing.  The built-in
#: scenes' max|u| is 0.2 to 270 times the data's displacement, so this floor never decides their checks.
DATA_FLOOR = 1e-2


def displacement_scale(interface: Interface, largest: float) -> float:
    """U, what the KKT check measures displacements against: the largest nodal displacement, or
    DATA_FLOOR × the displacement the data would make where that is larger."""
    return max(largest, DATA_FLOOR * interface.data)


def traction_scale(interface: Interface, lam: np.ndarray, size: float) -> float:
    """What the KKT check measures multipliers (tractions on Σ) against: the largest of them, or, when the
    structure carries (almost) no stress and they are all round-off, STRESS_FLOOR × the stress displacements
    of the scale ``size`` would make (modulus × size / Σ's length)."""
    length = float(interface.weights.sum())
    return max(float(np.abs(lam).max(initial=0.0)),
               STRESS_FLOOR * interface.modulus * size / length if length > 0 else 0.0)


def scale_free_ratio(value: float, scale: float) -> float:
    """value / scale, 0 when the value is 0 (nothing to compare), NaN-propagating."""
    if value == 0.0:
        return 0.0
    return value / scale if scale > 0.0 else np.inf


#: A friction multiplier within this fraction of the traction scale of its bound g is at the bound (Coulomb's g
#: of the final multipliers differs from the last fixed-point iterate's by the iteration's tolerance).
FRICTION_SLACK = 1e-6


def kkt(interface: Interface, traces: np.ndarray, lam: np.ndarray, p: float | None, equilibrium: np.ndarray,
        largest: float) -> Constraints:
    """The KKT residuals from the blocks' traces ``(blocks, 2k)`` (local frames) under the multipliers
    ``lam`` (bound ``p``), their equilibrium residuals and the largest nodal displacement; displacements
    are measured against :func:`displacement_scale`.  Friction (μ_t): |μ_t| ≤ g, the slip (u⁻ − u⁺)·τ zero where
    |μ_t| < g and of μ_t's sign where |μ_t| = g (Coulomb: g = μ max(μᶜ, 0) of ``lam``).  A compliant bond's rows
    measure gap − c λ (:attr:`~ddsolve.dd.interface.Interface.compliance`)."""
    gap = interface.gap(traces) - interface.compliance * lam
    lower, upper = interface.with_slip(interface.slip_bounds(lam)).bounds(p)
    size = displacement_scale(interface, largest)
    traction = traction_scale(interface, lam, size)
    base = 1e-9 * np.abs(upper[np.isfinite(upper)]).max(initial=0.0)
    slack = np.full(len(lam), base)
    slack[interface.is_friction] = max(base, FRICTION_SLACK * traction)
    at_lower, at_upper = lam <= lower + slack, lam >= upper - slack
    violated = np.where(at_upper, np.maximum(-gap, 0.0), np.where(at_lower, np.maximum(gap, 0.0), np.abs(gap)))
    violated[at_lower & at_upper] = 0.0  # a friction row without contact pressure (Coulomb's g = 0): free
    contact = interface.is_contact
    mu_c = lam[contact]
    bounds = float(np.maximum(lower - lam, lam - upper).max(initial=0.0))
    finite = bool(np.all(np.isfinite(traces)) and np.all(np.isfinite(lam)) and np.isfinite(largest))
    nan = float("nan")
    held = traces[U_MINUS, interface.prescribed_contact] - traces[U_PLUS, interface.prescribed_contact]
    penetration = max(float(np.where(at_upper, 0.0, np.maximum(gap, 0.0))[contact].max(initial=0.0)),
                      float(held.max(initial=0.0)))  # every crack node, its rows dropped or not
    return Constraints(
        penetration=scale_free_ratio(penetration, size) if finite else nan,
        gluing_gap=scale_free_ratio(float(violated[~contact].max(initial=0.0)), size) if finite else nan,
        complementarity=scale_free_ratio(float(np.abs(np.where(at_upper, 0.0, lam * gap)[contact]).max(initial=0.0)),
                                         traction * size) if finite else nan,
        multiplier_bounds=scale_free_ratio(max(bounds, 0.0), traction) if finite else nan,
        equilibrium=float(np.max(equilibrium, initial=0.0)),
        min_mu_c=float(mu_c.min(initial=0.0)),
        max_displacement=float(largest),
        displacement_scale=float(size),
    )
