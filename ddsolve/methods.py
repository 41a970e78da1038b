"""Multiplier methods, run on rank 0.

A method sees the blocks only through a :class:`Rounds` object: each call is one round of block
solves on all ranks (``solve``) or one collection of interface flexibilities (``flexibility``).
Loads, traces and multipliers are related by :class:`~ddsolve.interface.Interface`:
x_b(λ) = K_b⁻¹(f_b + E ℓ_b(λ)) with ℓ(λ) = −Cᵀ W λ, and the gap is C t.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from .interface import Interface
from .scene import Solver


class Rounds(Protocol):
    """Rank 0's handle on the blocks."""

    count: int  # rounds of block solves so far

    def solve(self, loads: np.ndarray, full: bool) -> tuple[np.ndarray, np.ndarray]:
        """Solve every block with trace loads ``(4, 2k)`` (plus the body load if ``full``).

        Returns the traces ``(4, 2k)`` and the energies x_bᵀ K_b x_b ``(4,)`` of the solutions.
        With ``full`` the blocks keep their solutions for output.
        """

    def flexibility(self) -> np.ndarray:
        """The blocks' interface flexibilities E^T K_b⁻¹ E, ``(4, 2k, 2k)``."""


@dataclass
class Outcome:
    lam: np.ndarray
    converged: bool
    iterations: int
    history: list[float] = field(default_factory=list)
    message: str = ""
    update_time: float = 0.0  # rank-0 time spent in the multiplier update


class Progress:
    """Rank-0 progress lines (iteration, criterion, elapsed) at most every ``interval`` seconds."""

    def __init__(self, label: str, interval: float = 2.0, out: Callable[[str], None] = print):
        self.label, self.interval, self.out = label, interval, out
        self.start = self.last = time.perf_counter()

    def __call__(self, iteration: int, criterion: float, final: bool = False) -> None:
        now = time.perf_counter()
        if final or now - self.last >= self.interval:
            self.out(f"{self.label}: iteration {iteration:6d}  criterion {criterion:.3e}  "
                     f"elapsed {now - self.start:7.1f} s")
            self.last = now


def block_criterion(rule: str, step_energy: np.ndarray, energy: np.ndarray) -> float:
    """Stopping-rule value from the energies ‖xᵏ − xᵏ⁻¹‖² and ‖xᵏ‖² of the four blocks.

    ``paper``: max ‖Δx‖ / ‖x‖² (as printed in the paper); ``relative``: max ‖Δx‖ / ‖x‖.
    A block with x = 0 contributes 0 if it did not move and ∞ otherwise.
    """
    step = np.sqrt(np.maximum(step_energy, 0.0))
    size = np.maximum(energy, 0.0) if rule == "paper" else np.sqrt(np.maximum(energy, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(step == 0.0, 0.0, step / size)
    return float(np.max(ratio))


#: Divergence: the multiplier step grew this much above its smallest size so far.  (The paper's rule
#: cannot see divergence: ‖x‖² grows faster than ‖Δx‖, so ‖Δx‖/‖x‖² falls while the iteration explodes.)
DIVERGENCE_GROWTH = 1e6


def uzawa(rounds: Rounds, interface: Interface, solver: Solver, progress: Progress) -> Outcome:
    """The paper's projected Uzawa iteration λ ← P(λ + θ·gap), one round of block solves each.

    Blocks are solved for the load increments, so ‖xᵏ − xᵏ⁻¹‖ is computed from the increment
    itself (no cancellation) and ‖xᵏ‖² is updated from traces: ‖x + Δx‖² = ‖x‖² + 2 t·Δℓ + ‖Δx‖².
    """
    lower, upper = interface.bounds(solver.p)
    lam = np.zeros(interface.size)
    traces, energy = rounds.solve(interface.loads(lam), full=True)
    outcome = Outcome(lam, converged=False, iterations=0)
    steps: list[float] = []
    smallest_step = np.inf
    for iteration in range(1, solver.max_iterations + 1):
        started = time.perf_counter()
        new = np.clip(lam + solver.theta * interface.gap(traces), lower, upper)
        increment = interface.loads(new - lam)
        steps.append(float(np.sqrt(np.sum(interface.row_weights * (new - lam) ** 2))))
        lam = new
        outcome.update_time += time.perf_counter() - started
        delta, step_energy = rounds.solve(increment, full=False)
        energy = energy + 2.0 * np.sum(traces * increment, axis=1) + step_energy
        traces = traces + delta
        criterion = block_criterion(solver.stop, step_energy, energy)
        outcome.history.append(criterion)
        outcome.iterations = iteration
        progress(iteration, criterion)
        smallest_step = min(smallest_step, steps[-1])
        if not np.isfinite(criterion) or steps[-1] > DIVERGENCE_GROWTH * smallest_step:
            outcome.message = _divergence_message(iteration, solver.theta, steps)
            break
        if criterion < solver.tol:
            outcome.converged = True
            break
    else:
        outcome.message = (f"uzawa: no convergence in {solver.max_iterations} iterations "
                           f"(criterion {outcome.history[-1]:.3e}, tol {solver.tol:g})")
    progress(outcome.iterations, outcome.history[-1] if outcome.history else 0.0, final=True)
    outcome.lam = lam
    return outcome


def _divergence_message(iteration: int, theta: float, steps: list[float]) -> str:
    """Explain a divergence, estimating λmax of the iteration operator from the step growth.

    Near divergence the multiplier steps are dominated by the top eigenvector of B K⁻¹ Bᵀ W,
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
