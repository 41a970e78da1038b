"""What every multiplier method shares: its handle on the blocks, its outcome, its progress lines and the
dual problem.  The methods (:mod:`~ddsolve.dd.registry` lists them) run on rank 0.

A method sees the blocks only through a :class:`Rounds` object: each call is one round of block
solves on all ranks (``solve``) or one collection of the blocks' Schur complements on Σ.
Loads, traces and multipliers are related by :class:`~ddsolve.dd.interface.Interface`:
x_b(λ) = K_b⁻¹(f_b + ℓ_b(λ)) with ℓ(λ) = −Cᵀ W λ, and the constraint gap is C t.

The fast methods solve the dual problem in the W-scaled variable y = W^½ λ,

    minimize ½ yᵀ A y − bᵀ y  subject to  lower ≤ y ≤ upper,
    A = W^½ C K⁻¹ Cᵀ W^½,  b = W^½ C K⁻¹ f,  gradient A y − b = −W^½ gap(x(λ)),

(with a compliant bond, :mod:`ddsolve.dd.cohesive`, A gains the diagonal c of its rows: gap = c λ), where the
scaling makes A's spectrum that of the Uzawa iteration operator C K⁻¹ Cᵀ W (so 2/λmax(A)
is Uzawa's stable bound on θ) and ‖A y − b‖ the L²(Σ) norm of the constraint violation.  Their
stopping rule ``kkt`` is the norm of the projected gradient (violated equalities, penetration,
and contact forces on open crack faces) relative to its value for λ = 0, the uncoupled blocks (or to
the gap the data would make, where the uncoupled blocks' gap is round-off: :func:`gap_scale`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from ddsolve.dd.constraints import DATA_FLOOR
from ddsolve.dd.interface import Interface
from ddsolve.problem.scene import Solver


class Rounds(Protocol):
    """Rank 0's handle on the blocks."""

    count: int  # rounds of block solves so far
    residuals: np.ndarray  # (blocks,) the blocks' relative residuals ‖K x − b‖ in the last full solve
    largest: float  # the largest nodal displacement |x| in the last full solve
    floating: list[int]  # the blocks whose stiffness is singular (held only through Σ)
    kernel_traces: list[np.ndarray]  # per block the traces (2k, m_b) of its kernel R_b (m_b = 0: invertible)

    def solve(self, loads: np.ndarray, full: bool, held: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Solve every block with trace loads ``(blocks, 2k)`` (plus the body load if ``full``).

        Returns the traces ``(blocks, 2k)`` and the energies x_bᵀ K_b x_b ``(blocks,)`` of the solutions.
        With ``full`` the blocks keep their solutions for output.  A floating block applies a generalized
        inverse K_b⁺ (``feti``); in a full solve with ``held`` traces ``(blocks, 2k)`` it takes its trace from
        them instead and solves its interior, x_I = K_II⁻¹(f_I − K_IΣ t_b).
        """

    def solve_many(self, loads: list[np.ndarray]) -> list[np.ndarray]:
        """Per block the traces ``(2k, m_b)`` of its solves with its trace loads ``(2k, m_b)``, no body load, in one
        round (a multi-column solve per block; K_b⁺ for a floating block)."""

    def schur_complements(self) -> np.ndarray:
        """The blocks' Schur complements on their traces, S_b = (E K_b⁻¹ Eᵀ)⁻¹, ``(blocks, 2k, 2k)``."""

    def dirichlet(self, traces: np.ndarray) -> np.ndarray:
        """S_b t_b for trace displacements ``(blocks, 2k)``: one Dirichlet solve per block (``feti``)."""

    def lumped(self, traces: np.ndarray) -> np.ndarray:
        """K_b,ΣΣ t_b for trace displacements ``(blocks, 2k)``: the blocks' stiffness on their traces, held on rank 0
        (``feti``'s lumped preconditioner; no round)."""

    def trace_diagonals(self) -> np.ndarray:
        """The diagonals of the blocks' stiffness matrices at their traces, ``(blocks, 2k)``."""

    def condensed_loads(self, schur_complements: np.ndarray) -> np.ndarray:
        """The body loads condensed on the traces, g_b = f_Σ − K_ΣI K_II⁻¹ f_I ``(blocks, 2k)`` (S_b t⁰_b for
        an invertible block, with ``schur_complements`` S_b)."""

    def kernel_work(self) -> list[np.ndarray]:
        """Per block R_bᵀ f_b ``(m_b,)``: the work of its body loads in its rigid motions."""


@dataclass
class Outcome:
    lam: np.ndarray
    converged: bool
    iterations: int
    history: list[float] = field(default_factory=list)  # the stopping criterion, one per iteration
    active_set_changes: list[int] = field(default_factory=list)  # per iteration, for active-set methods
    message: str = ""
    diverged: bool = False  # stopped because the iteration blew up (nothing is written)
    details: dict = field(default_factory=dict)  # method-specific numbers for the result file
    # (traces of a full solve, whether the check failed) -> a better λ, or None when it cannot be bettered
    refine: Callable[[np.ndarray, bool], np.ndarray | None] | None = None
    held: np.ndarray | None = None  # (blocks, 2k) the traces floating blocks take in the final solve
    state: Interface | None = None  # the interface the multipliers solve where it differs (a bond's damage)


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


def no_convergence(name: str, solver: Solver, history: list[float]) -> str:
    """The message of method ``name`` when it used all its iterations."""
    last = history[-1] if history else float("nan")
    return (f"{name}: no convergence in {solver.max_iterations} iterations "
            f"(criterion {last:.3e}, tol {solver.tol:g})")


def projected_gradient(y: np.ndarray, gradient: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Gradient with the components that push against an active bound removed."""
    out = gradient.copy()
    out[(y <= lower) & (gradient > 0)] = 0.0
    out[(y >= upper) & (gradient < 0)] = 0.0
    return out


def gap_scale(interface: Interface, gap: np.ndarray) -> float:
    """What the ``kkt`` stopping rule measures the projected gradient against: ‖W^½ gap‖ of the uncoupled
    blocks, or, where that is round-off (their data cancels on Σ), the norm of a gap of DATA_FLOOR × the
    data's displacement on every row (the final check's floor, :func:`~ddsolve.dd.constraints.displacement_scale`)."""
    floor = DATA_FLOOR * interface.data * np.sqrt(interface.row_weights.sum())
    return max(float(np.linalg.norm(np.sqrt(interface.row_weights) * gap)), float(floor))


def kkt_criterion(y, gradient, lower, upper, scale: float) -> float:
    """‖projected gradient‖ / ‖gradient at λ = 0‖ (0 when both vanish: nothing to couple)."""
    norm = float(np.linalg.norm(projected_gradient(y, gradient, lower, upper)))
    if scale == 0.0:
        return 0.0 if norm == 0.0 else np.inf
    return norm / scale


class DualProblem:
    """The W-scaled dual QP (see the module docstring); ``apply`` costs one round of block solves."""

    def __init__(self, rounds: Rounds, interface: Interface, solver: Solver, initial: np.ndarray | None = None):
        self.rounds, self.interface, self.solver = rounds, interface, solver
        self.sqrt_w = np.sqrt(interface.row_weights)
        if initial is None:
            initial, _ = rounds.solve(interface.loads(np.zeros(interface.size)), full=True)
        self.initial_traces = initial  # of the uncoupled blocks (λ = 0), or a model of them when given
        self.b = self.sqrt_w * interface.gap(initial)
        lower, upper = interface.bounds(solver.p)
        self.lower, self.upper = lower * self.sqrt_w, upper * self.sqrt_w
        self.scale = gap_scale(interface, interface.gap(initial))
        self.compliance = interface.compliance  # a bond's rows: gap = c λ, the diagonal c added to A

    def apply(self, y: np.ndarray) -> np.ndarray:
        traces, _ = self.rounds.solve(self.interface.loads(y / self.sqrt_w), full=False)
        return -self.sqrt_w * self.interface.gap(traces) + self.compliance * y

    def apply_many(self, Y: np.ndarray) -> np.ndarray:
        """A Y for the columns of ``Y`` ``(size, m)``, in one round."""
        pieces = self.interface.column_loads(Y / self.sqrt_w[:, None])
        traces = self.rounds.solve_many([loads for _, loads in pieces])
        gap = self.interface.column_gap([(taken, trace) for (taken, _), trace in zip(pieces, traces)], Y.shape[1])
        return -self.sqrt_w[:, None] * gap + self.compliance[:, None] * Y

    def criterion(self, y: np.ndarray, gradient: np.ndarray) -> float:
        return kkt_criterion(y, gradient, self.lower, self.upper, self.scale)

    def project(self, y: np.ndarray) -> np.ndarray:
        return np.clip(y, self.lower, self.upper)

    def start(self, lam: np.ndarray | None) -> np.ndarray:
        """The feasible y of the multipliers ``lam`` (0 for None)."""
        return np.zeros(self.interface.size) if lam is None else self.project(self.sqrt_w * lam)

    def multipliers(self, y: np.ndarray) -> np.ndarray:
        return y / self.sqrt_w


def largest_eigenvalue(apply: Callable[[np.ndarray], np.ndarray], size: int, iterations: int = 12,
                       tolerance: float = 1e-3) -> float:
    """Power iteration (Rayleigh quotients) for λmax of an SPD operator; ``apply`` may cost a round each."""
    v = np.random.default_rng(12345).standard_normal(size)
    v /= np.linalg.norm(v)
    estimate = 0.0
    for _ in range(iterations):
        w = apply(v)
        previous, estimate = estimate, float(v @ w)
        v = w / np.linalg.norm(w)
        if abs(estimate - previous) <= tolerance * estimate:
            break
    return estimate


def iterate(name: str, problem: DualProblem, progress: Progress, steps) -> Outcome:
    """Drive a generator of (y, criterion) pairs until the tolerance or max_iterations."""
    solver = problem.solver
    outcome = Outcome(np.zeros(problem.interface.size), converged=False, iterations=0)
    y = np.zeros(problem.interface.size)
    for iteration, (y, criterion) in enumerate(steps):  # iteration 0: the starting point
        if iteration > 0:
            outcome.history.append(criterion)
            outcome.iterations = iteration
            progress(iteration, criterion)
        if not np.isfinite(criterion):
            outcome.message = f"{name} broke down at iteration {iteration} (non-finite criterion)"
            outcome.diverged = True
            break
        if criterion < solver.tol:
            outcome.converged = True
            break
        if iteration >= solver.max_iterations:
            outcome.message = no_convergence(name, solver, outcome.history)
            break
    progress(outcome.iterations, outcome.history[-1] if outcome.history else 0.0, final=True)
    outcome.lam = problem.multipliers(y)
    return outcome
