"""Coulomb friction on the crack faces as a fixed point of Tresca problems.

Tresca's friction bounds the tangential multiplier μ_t by a given g: a box, which every bound-constrained method
solves as it is.  Coulomb's bounds it by g = μ μᶜ, the contact pressure of the same solution: the problem is no
longer a QP.  It is solved by successive Tresca problems, g⁰ = 0 (the faces slide freely), gⁱ⁺¹ = μ max(μᶜ(λⁱ), 0)
from the solution λⁱ of the Tresca problem with gⁱ, each solve started from the previous λ where the method
can.  Converged: ‖gⁱ⁺¹ − gⁱ‖ ≤ tol ‖gⁱ⁺¹‖ (``solver.tol``), or both zero (no pressure, no friction), or, for the
iterative methods, the change stalled at the Tresca solves' own accuracy (:func:`stalled`).  The
loading is quasi-static and monotone from the unloaded state, in one step: the friction is the one of the
final state, with no history.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from ddsolve.dd.dual import Outcome
from ddsolve.dd.interface import Interface

#: At most this many Tresca problems per Coulomb problem.
MAX_FIXED_POINT = 50


def relative_change(old: np.ndarray, new: np.ndarray) -> float:
    """‖new − old‖ / ‖new‖ of the slip bounds (0 when both vanish, inf when only ``new`` does)."""
    step, size = float(np.linalg.norm(new - old)), float(np.linalg.norm(new))
    return 0.0 if step == 0.0 else (step / size if size > 0.0 else np.inf)


def settled(old: np.ndarray, new: np.ndarray, tol: float) -> bool:
    """Whether the slip bounds ``new`` are within the relative tolerance ``tol`` of ``old``."""
    return relative_change(old, new) <= tol


def stalled(change: float, previous: float, tol: float) -> bool:
    """Whether the relative change of the slip bounds has stopped falling below √tol: the fixed point's changes
    fall geometrically down to the accuracy of the Tresca solves, which an iterative method meets to about its
    tol (its multipliers, so the bounds μ μᶜ, scatter by up to a few hundred tol from solve to solve); a change no
    smaller than the last one is that floor, and further Tresca problems cannot lower it."""
    return previous <= change <= math.sqrt(tol)


def no_fixed_point(label: str, change: float) -> str:
    """The message of a Coulomb iteration that used all its Tresca problems."""
    return (f"{label}: Coulomb's friction found no fixed point in {MAX_FIXED_POINT} Tresca problems (relative "
            f"change of the slip bound {change:.3e})")


def coulomb(interface: Interface, tresca: Callable[[Interface, np.ndarray | None], Outcome], tol: float,
            label: str) -> Outcome:
    """Coulomb's problem by the fixed point of Tresca problems (module docstring): ``tresca(interface with the
    bounds g, start)`` solves one from the multipliers ``start`` (None: from zero).  The outcome of the last,
    with ``coulomb_iterations`` (the Tresca problems solved) and their iterations summed."""
    slip, start, total, history = np.zeros(len(interface.friction_values)), None, 0, []
    previous = math.inf
    for iteration in range(1, MAX_FIXED_POINT + 1):
        outcome = tresca(interface.with_slip(slip), start)
        total += outcome.iterations
        history += outcome.history
        new = interface.slip_bounds(outcome.lam)
        change = relative_change(slip, new)
        if outcome.diverged or not outcome.converged or change <= tol or stalled(change, previous, tol):
            break
        slip, start, previous = new, outcome.lam, change
    else:
        outcome.converged, outcome.message = False, no_fixed_point(label, change)
    outcome.iterations, outcome.history = total, history
    outcome.details["coulomb_iterations"] = iteration
    return outcome
