"""The paper's method: the projected Uzawa iteration, with its stopping rules on the blocks' energies."""
from __future__ import annotations

import numpy as np

from ddsolve.dd.constraints import DATA_FLOOR
from ddsolve.dd.dual import (DualProblem, Outcome, Progress, Rounds, gap_scale, kkt_criterion, largest_eigenvalue,
                             no_convergence)
from ddsolve.dd.interface import Interface
from ddsolve.problem.scene import Solver


def block_criterion(rule: str, step_energy: np.ndarray, energy: np.ndarray, floor: float = 0.0) -> float:
    """Stopping-rule value from the energies ‖xᵏ − xᵏ⁻¹‖² and ‖xᵏ‖² of the four blocks.

    ``paper``: max ‖Δx‖ / ‖x‖² (as printed in the paper); ``relative``: max ‖Δx‖ / ‖x‖.
    ‖x‖² is taken no smaller than ``floor`` (the energy the data's displacement would have, so that a solution
    that is zero, with data that is not, can stop: :func:`energy_floor`).  A block with ‖x‖ = 0 (and no
    floor) contributes 0 if it did not move and ∞ otherwise.
    """
    step = np.sqrt(np.maximum(step_energy, 0.0))
    energy = np.maximum(energy, floor)
    size = np.maximum(energy, 0.0) if rule == "paper" else np.sqrt(np.maximum(energy, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(step == 0.0, 0.0, step / size)
    return float(np.max(ratio))


def energy_floor(interface: Interface) -> float:
    """‖x‖² = xᵀ K x of a block whose displacements are DATA_FLOOR × the data's (the layers' modulus × their
    square: ∫ εᵀ D ε over a domain of size L with ε ~ u / L), below which :func:`block_criterion` does not
    measure a block (0 without data)."""
    return interface.modulus * (DATA_FLOOR * interface.data) ** 2


#: θ = AUTO_STEP / λmax for ``theta = "auto"``: below the stable bound 2/λmax with room for the
#: power iteration's underestimate of λmax.
AUTO_STEP = 1.7
#: Divergence: the multiplier step grew this much above its smallest size so far.  (The paper's rule
#: cannot see divergence: ‖x‖² grows faster than ‖Δx‖, so ‖Δx‖/‖x‖² falls while the iteration explodes.)
DIVERGENCE_GROWTH = 1e6


def uzawa(rounds: Rounds, interface: Interface, solver: Solver, progress: Progress,
          start: np.ndarray | None = None) -> Outcome:
    """The paper's projected Uzawa iteration λ ← P(λ + θ·gap), one round of block solves each.

    Blocks are solved for the load increments, so ‖xᵏ − xᵏ⁻¹‖ is computed from the increment
    itself (no cancellation) and ‖xᵏ‖² is updated from traces: ‖x + Δx‖² = ‖x‖² + 2 t·Δℓ + ‖Δx‖².
    With ``stop = "kkt"`` the criterion is the dual one of the fast methods.  ``start``: the multipliers
    to start from (0 by default; one more round then, for the uncoupled blocks' gap).
    """
    lower, upper = interface.bounds(solver.p)
    theta = solver.theta
    details = {}
    if theta == "auto":  # 2/λmax of C K⁻¹ Cᵀ W bounds the stable steps; power iteration underestimates λmax
        details["lambda_max"] = largest_eigenvalue(DualProblem(rounds, interface, solver).apply, interface.size)
        theta = AUTO_STEP / details["lambda_max"]
        details["theta"] = theta
    lam = np.zeros(interface.size)
    traces, energy = rounds.solve(interface.loads(lam), full=True)
    sqrt_w = np.sqrt(interface.row_weights)
    scale = gap_scale(interface, interface.gap(traces))
    if start is not None:
        lam = np.clip(start, lower, upper)
        traces, energy = rounds.solve(interface.loads(lam), full=True)
    outcome = Outcome(lam, converged=False, iterations=0, details=details)
    steps: list[float] = []
    smallest_step = np.inf
    for iteration in range(1, solver.max_iterations + 1):
        new = np.clip(lam + theta * interface.gap(traces), lower, upper)
        increment = interface.loads(new - lam)
        steps.append(float(np.linalg.norm(sqrt_w * (new - lam))))
        lam = new
        delta, step_energy = rounds.solve(increment, full=False)
        energy = energy + 2.0 * np.sum(traces * increment, axis=1) + step_energy
        traces = traces + delta
        if solver.stop == "kkt":
            gradient = -sqrt_w * interface.gap(traces)
            criterion = kkt_criterion(sqrt_w * lam, gradient, sqrt_w * lower, sqrt_w * upper, scale)
        else:
            criterion = block_criterion(solver.stop, step_energy, energy, energy_floor(interface))
        outcome.history.append(criterion)
        outcome.iterations = iteration
        progress(iteration, criterion)
        smallest_step = min(smallest_step, steps[-1])
        if not np.isfinite(criterion) or steps[-1] > DIVERGENCE_GROWTH * smallest_step:
            outcome.message = _divergence_message(iteration, theta, steps)
            outcome.diverged = True
            break
        if criterion < solver.tol:
            outcome.converged = True
            break
    else:
        outcome.message = no_convergence("uzawa", solver, outcome.history)
    progress(outcome.iterations, outcome.history[-1] if outcome.history else 0.0, final=True)
    outcome.lam = lam
    return outcome


def _divergence_message(iteration: int, theta: float, steps: list[float]) -> str:
    """Explain a divergence, estimating λmax of the iteration operator from the step growth.

    Near divergence the multiplier steps are dominated by the top eigenvector of C K⁻¹ Cᵀ W,
    which the iteration multiplies by |1 − θ λmax| = ρ per step, so 2/λmax ≈ 2θ / (1 + ρ).
    """
    recent = np.array(steps[-10:])
    recent = recent[recent > 0]
    message = f"uzawa diverged at iteration {iteration}"
    if len(recent) >= 2:
        rate = float(np.exp(np.mean(np.diff(np.log(recent)))))
        if rate > 1.0:
            bound = 2.0 * theta / (1.0 + rate)
            message += (f": theta = {theta:g} is above the stable bound 2/lambda_max ~ {bound:.3g} "
                        f"(estimated from the growth rate {rate:.3g} per iteration)")
    return message


def resumes(solver: Solver) -> bool:
    """Whether uzawa can go on from its multipliers to a lower tol: with ``stop = "kkt"`` only (the other rules
    are not relative to the uncoupled blocks' gap)."""
    return solver.stop == "kkt"


def remedy(solver: Solver) -> str:
    """What to change when uzawa's final check fails (with accurate block solves)."""
    if solver.stop == "paper":
        return (f"the paper's stopping rule ‖Δx‖/‖x‖² < solver.tol is dimensional and was met after too few "
                f"steps: set solver.stop = \"kkt\" (or a smaller solver.theta than {solver.theta:g})"
                if isinstance(solver.theta, float) else "set solver.stop = \"kkt\"")
    return "lower solver.tol or solver.theta"
