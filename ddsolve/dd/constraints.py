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

    penetration: float  # max (u⁻ − u⁺)·ν > 0 over every crack node under non-penetration (prescribed too), / max|u|
    gluing_gap: float  # max |gluing gap| over Σ (but the gap a multiplier at its bound ±p allows), / max|u|
    complementarity: float  # max |μᶜ [u]·ν| (but where μᶜ = p) / (max|λ| max|u|)
    multiplier_bounds: float  # max violation of 0 ≤ μᶜ ≤ p, |μ| ≤ p (a pull on closed crack faces), / max|λ|
    equilibrium: float  # max over blocks of ‖K x − f − ℓ(λ)‖∞ / (‖K‖∞‖x‖∞ + ‖f + ℓ(λ)‖∞)
    min_mu_c: float  # smallest contact multiplier (≥ 0 when dual feasible)
    max_displacement: float  # max nodal |u|

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


#: The smallest traction scale of the KKT check, as a fraction of the stress scale modulus × max|u| / |Σ|:
#: below it multipliers are round-off (a structure that expands freely carries no stress at all).
STRESS_FLOOR = 1e-6


def scale_free_ratio(value: float, scale: float) -> float:
    """value / scale, 0 when the value is 0 (nothing to compare), NaN-propagating."""
    if value == 0.0:
        return 0.0
    return value / scale if scale > 0.0 else np.inf


def kkt(interface: Interface, traces: np.ndarray, lam: np.ndarray, p: float | None, equilibrium: np.ndarray,
        largest: float) -> Constraints:
    """The KKT residuals from the blocks' traces ``(4, 2k)`` (local frames) under the multipliers
    ``lam`` (bound ``p``), their equilibrium residuals and the largest nodal displacement."""
    gap = interface.gap(traces)
    lower, upper = interface.bounds(p)
    # Multipliers are tractions on Σ: measured against the largest of them, or, when the structure carries
    # (almost) no stress and they are all round-off, against STRESS_FLOOR × the stress its displacements
    # would make (modulus × max|u| / Σ's length).
    length = float(interface.weights.sum())
    traction = max(float(np.abs(lam).max(initial=0.0)),
                   STRESS_FLOOR * interface.modulus * largest / length if length > 0 else 0.0)
    slack = 1e-9 * np.abs(upper[np.isfinite(upper)]).max(initial=0.0)
    at_lower, at_upper = lam <= lower + slack, lam >= upper - slack
    violated = np.where(at_upper, np.maximum(-gap, 0.0), np.where(at_lower, np.maximum(gap, 0.0), np.abs(gap)))
    contact = interface.is_contact
    mu_c = lam[contact]
    bounds = float(np.maximum(lower - lam, lam - upper).max(initial=0.0))
    finite = bool(np.all(np.isfinite(traces)) and np.all(np.isfinite(lam)) and np.isfinite(largest))
    nan = float("nan")
    held = traces[U_MINUS, interface.prescribed_contact] - traces[U_PLUS, interface.prescribed_contact]
    penetration = max(float(np.where(at_upper, 0.0, np.maximum(gap, 0.0))[contact].max(initial=0.0)),
                      float(held.max(initial=0.0)))  # every crack node, its rows dropped or not
    return Constraints(
        penetration=scale_free_ratio(penetration, largest) if finite else nan,
        gluing_gap=scale_free_ratio(float(violated[~contact].max(initial=0.0)), largest) if finite else nan,
        complementarity=scale_free_ratio(float(np.abs(np.where(at_upper, 0.0, lam * gap)[contact]).max(initial=0.0)),
                                         traction * largest) if finite else nan,
        multiplier_bounds=scale_free_ratio(max(bounds, 0.0), traction) if finite else nan,
        equilibrium=float(np.max(equilibrium, initial=0.0)),
        min_mu_c=float(mu_c.min(initial=0.0)),
        max_displacement=float(largest),
    )
