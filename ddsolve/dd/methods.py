"""Multiplier methods, run on rank 0.

A method sees the blocks only through a :class:`Rounds` object: each call is one round of block
solves on all ranks (``solve``) or one collection of the blocks' Schur complements on Σ.
Loads, traces and multipliers are related by :class:`~ddsolve.dd.interface.Interface`:
x_b(λ) = K_b⁻¹(f_b + ℓ_b(λ)) with ℓ(λ) = −Cᵀ W λ, and the constraint gap is C t.

The fast methods solve the dual problem in the W-scaled variable y = W^½ λ,

    minimize ½ yᵀ A y − bᵀ y  subject to  lower ≤ y ≤ upper,
    A = W^½ C K⁻¹ Cᵀ W^½,  b = W^½ C K⁻¹ f,  gradient A y − b = −W^½ gap(x(λ)),

where the scaling makes A's spectrum that of the Uzawa iteration operator C K⁻¹ Cᵀ W (so 2/λmax(A)
is Uzawa's stable bound on θ) and ‖A y − b‖ the L²(Σ) norm of the constraint violation.  Their
stopping rule ``kkt`` is the norm of the projected gradient (violated equalities, penetration,
and contact forces on open crack faces) relative to its value for λ = 0, the uncoupled blocks (or to
the gap the data would make, where the uncoupled blocks' gap is round-off: :func:`gap_scale`).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Callable, Protocol

import numpy as np

from ddsolve.dd.constraints import DATA_FLOOR, Constraints, displacement_scale, kkt, kkt_tolerance
from ddsolve.dd.interface import Interface
from ddsolve.errors import SolverError
from ddsolve.problem.scene import Solver


class Rounds(Protocol):
    """Rank 0's handle on the blocks."""

    count: int  # rounds of block solves so far
    residuals: np.ndarray  # (4,) the blocks' relative residuals ‖K x − b‖ in the last full solve
    largest: float  # the largest nodal displacement |x| in the last full solve
    floating: list[int]  # the blocks whose stiffness is singular (held only through Σ)
    kernel_traces: list[np.ndarray]  # per block the traces (2k, m_b) of its kernel R_b (m_b = 0: invertible)

    def solve(self, loads: np.ndarray, full: bool, held: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Solve every block with trace loads ``(4, 2k)`` (plus the body load if ``full``).

        Returns the traces ``(4, 2k)`` and the energies x_bᵀ K_b x_b ``(4,)`` of the solutions.
        With ``full`` the blocks keep their solutions for output.  A floating block applies a generalized
        inverse K_b⁺ (``feti``); in a full solve with ``held`` traces ``(4, 2k)`` it takes its trace from
        them instead and solves its interior, x_I = K_II⁻¹(f_I − K_IΣ t_b).
        """

    def schur_complements(self) -> np.ndarray:
        """The blocks' Schur complements on their traces, S_b = (E K_b⁻¹ Eᵀ)⁻¹, ``(4, 2k, 2k)``."""

    def dirichlet(self, traces: np.ndarray) -> np.ndarray:
        """S_b t_b for trace displacements ``(4, 2k)``: one Dirichlet solve per block (``feti``)."""

    def trace_diagonals(self) -> np.ndarray:
        """The diagonals of the blocks' stiffness matrices at their traces, ``(4, 2k)``."""

    def condensed_loads(self, schur_complements: np.ndarray) -> np.ndarray:
        """The body loads condensed on the traces, g_b = f_Σ − K_ΣI K_II⁻¹ f_I ``(4, 2k)`` (S_b t⁰_b for
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
    held: np.ndarray | None = None  # (4, 2k) the traces floating blocks take in the final solve


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


# --- the paper's Uzawa method ----------------------------------------------------------------
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
        outcome.message = _no_convergence("uzawa", solver, outcome.history)
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


def _no_convergence(name: str, solver: Solver, history: list[float]) -> str:
    last = history[-1] if history else float("nan")
    return (f"{name}: no convergence in {solver.max_iterations} iterations "
            f"(criterion {last:.3e}, tol {solver.tol:g})")


# --- the dual problem shared by the fast methods --------------------------------------------
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

    def apply(self, y: np.ndarray) -> np.ndarray:
        traces, _ = self.rounds.solve(self.interface.loads(y / self.sqrt_w), full=False)
        return -self.sqrt_w * self.interface.gap(traces)

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


def _iterate(name: str, problem: DualProblem, progress: Progress, steps) -> Outcome:
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
            outcome.message = _no_convergence(name, solver, outcome.history)
            break
    progress(outcome.iterations, outcome.history[-1] if outcome.history else 0.0, final=True)
    outcome.lam = problem.multipliers(y)
    return outcome


# --- accelerated projected gradient ----------------------------------------------------------
def fista(rounds: Rounds, interface: Interface, solver: Solver, progress: Progress,
          start: np.ndarray | None = None) -> Outcome:
    """Projected gradient with Nesterov/FISTA momentum and adaptive (gradient) restart.

    The step is 1/L with L = 1.1 λmax(A) from a power iteration (a few rounds); no θ is needed.
    One round per iteration; the criterion is the KKT residual at the gradient-mapping point.
    ``start``: the multipliers to start from (0 by default).
    """
    problem = DualProblem(rounds, interface, solver)
    lipschitz = 1.1 * largest_eigenvalue(problem.apply, interface.size)

    def steps():
        x = problem.start(start)
        y, t = x.copy(), 1.0
        while True:
            gradient = problem.apply(y) - problem.b
            new = problem.project(y - gradient / lipschitz)
            mapping = lipschitz * (y - new)  # the projected gradient when y is feasible
            yield new, (float(np.linalg.norm(mapping)) / problem.scale if problem.scale else 0.0)
            if np.dot(y - new, new - x) > 0.0:  # the momentum points uphill: restart
                t = 1.0
            t_next = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
            y = new + ((t - 1.0) / t_next) * (new - x)
            x, t = new, t_next

    outcome = _iterate("fista", problem, progress, steps())
    outcome.details["lambda_max"] = lipschitz / 1.1
    return outcome


# --- MPRGP ------------------------------------------------------------------------------------
def mprgp(rounds: Rounds, interface: Interface, solver: Solver, progress: Progress,
          start: np.ndarray | None = None, proportioning: float = 1.0) -> Outcome:
    """Dostál's MPRGP for box constraints: conjugate gradients on the free set, expansion steps
    with the fixed step ᾱ = 1.9/λmax(A), proportioning steps that release active constraints.

    One round per CG or proportioning step, two per expansion step.  ``start``: the multipliers to
    start from (0 by default).
    """
    problem = DualProblem(rounds, interface, solver)
    lam_max = largest_eigenvalue(problem.apply, interface.size)
    alpha_bar = 1.9 / (1.05 * lam_max)
    lower, upper = problem.lower, problem.upper

    def free_gradient(y, g):
        return np.where((y > lower) & (y < upper), g, 0.0)

    def chopped_gradient(y, g):
        return np.where(y <= lower, np.minimum(g, 0.0), 0.0) + np.where(y >= upper, np.maximum(g, 0.0), 0.0)

    def reduced_free_gradient(y, g):
        phi = free_gradient(y, g)
        return np.where(phi > 0, np.minimum((y - lower) / alpha_bar, phi), np.maximum((y - upper) / alpha_bar, phi))

    def feasible_step(y, direction):
        """Largest α with lower ≤ y − α·direction ≤ upper."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # infinite bounds: infinite steps
            down = np.where(direction > 0, (y - lower) / direction, np.inf)
            up = np.where(direction < 0, (y - upper) / direction, np.inf)
        return float(min(down.min(initial=np.inf), up.min(initial=np.inf)))

    def steps():
        y = problem.start(start)
        g = problem.apply(y) - problem.b if np.any(y) else -problem.b
        p = free_gradient(y, g)
        while True:
            yield y, problem.criterion(y, g)
            beta = chopped_gradient(y, g)
            phi = free_gradient(y, g)
            if beta @ beta <= proportioning ** 2 * (reduced_free_gradient(y, g) @ phi):
                Ap = problem.apply(p)
                curvature = p @ Ap
                if curvature <= 0.0:  # p = 0: only chopped components left; nothing to minimize freely
                    p = phi
                    continue
                alpha_cg = (g @ p) / curvature
                if alpha_cg <= feasible_step(y, p):  # conjugate gradient step
                    y = y - alpha_cg * p
                    g = g - alpha_cg * Ap
                    p = free_gradient(y, g) - ((free_gradient(y, g) @ Ap) / curvature) * p
                else:  # expansion step
                    alpha_f = feasible_step(y, p)
                    y = y - alpha_f * p
                    g = g - alpha_f * Ap
                    new = problem.project(y - alpha_bar * free_gradient(y, g))
                    g = g + problem.apply(new - y)
                    y = new
                    p = free_gradient(y, g)
            else:  # proportioning step
                Ad = problem.apply(beta)
                alpha = min((g @ beta) / (beta @ Ad), feasible_step(y, beta))
                y = problem.project(y - alpha * beta)
                g = g - alpha * Ad
                p = free_gradient(y, g)

    outcome = _iterate("mprgp", problem, progress, steps())
    outcome.details["lambda_max"] = lam_max
    return outcome


# --- exact dual solve from the interface flexibilities ----------------------------------------
def box_qp(A: np.ndarray, b: np.ndarray, lower: np.ndarray, upper: np.ndarray,
           max_steps: int = 200, observe: Callable[[np.ndarray, int], None] | None = None) -> tuple[np.ndarray, int]:
    """Minimize ½ yᵀAy − bᵀy over lower ≤ y ≤ upper (A dense SPD) by a primal-dual active set method.

    Returns the solution and the number of active-set steps.  Each step solves the free rows
    with the active ones at their bounds; the sets are updated from the signs of the gradient on
    active rows and the bound violations on free rows, until they no longer change.
    ``observe(y, changes)`` is called after each step with its solution and how many rows change set.
    """
    at_lower = np.zeros(len(b), dtype=bool)
    at_upper = np.zeros(len(b), dtype=bool)
    for step in range(1, max_steps + 1):
        y = np.where(at_lower, lower, np.where(at_upper, upper, 0.0))
        free = ~(at_lower | at_upper)
        fixed = ~free
        if free.any():
            rhs = b[free] - A[np.ix_(free, fixed)] @ y[fixed]
            y[free] = np.linalg.solve(A[np.ix_(free, free)], rhs)
        gradient = A @ y - b
        new_lower = (at_lower & (gradient >= 0)) | (free & (y < lower))
        new_upper = (at_upper & (gradient <= 0)) | (free & (y > upper))
        if observe is not None:
            observe(y, int(np.sum(new_lower != at_lower) + np.sum(new_upper != at_upper)))
        if np.array_equal(new_lower, at_lower) and np.array_equal(new_upper, at_upper):
            return y, step
        at_lower, at_upper = new_lower, new_upper
    raise SolverError(f"the active-set QP solver did not settle in {max_steps} steps")


#: At most this many refinement rounds after the final solve (each one a rank-0 solve and a round).
MAX_REFINEMENTS = 3
#: ``schur`` refines when the final solve's traces differ from its prediction by more than this,
#: relative to the largest trace or DATA_FLOOR × the data's displacement, if larger (MUMPS's own Schur
#: complements: about 1e-11 on the slender strip; those inverted from the flexibility of blocks on two ranks:
#: about 1e-8).
PREDICTION_TOLERANCE = 1e-10


def triangular_solve(L: np.ndarray, b: np.ndarray, transpose: bool = False, block: int = 128) -> np.ndarray:
    """L⁻¹ b (or L⁻ᵀ b) for a lower triangular L, by blocks of rows: O(n²) work for one vector."""
    n = len(b)
    x = np.array(b, dtype=np.float64)
    starts = list(range(0, n, block))
    for start in (starts[::-1] if transpose else starts):
        stop = min(start + block, n)
        if transpose:
            x[start:stop] = np.linalg.solve(L[start:stop, start:stop].T, x[start:stop] - L[stop:, start:stop].T @ x[stop:])
        else:
            x[start:stop] = np.linalg.solve(L[start:stop, start:stop], x[start:stop] - L[start:stop, :start] @ x[:start])
    return x


def schur(rounds: Rounds, interface: Interface, solver: Solver, progress: Progress) -> Outcome:
    """Exact solve from the blocks' Schur complements S_b on Σ; three rounds in all (one more for each
    refinement the final solve asks for).

    Rounds: one to collect S_b (from MUMPS with the factorization), one for the uncoupled traces
    t⁰_b; :func:`final_solve` adds the final one.  Rank 0 assembles the interface stiffness
    S = Σ_b P_bᵀ S_b P_b on the tied interface unknowns (every gluing constraint holds exactly),
    with body loads Σ P_bᵀ S_b t⁰_b.  Eliminating it leaves the dual problem on the crack rows only,

        A_c = W^½ B S⁻¹ Bᵀ W^½,  b_c = W^½ B S⁻¹ r,  y_c ≥ 0   (B z: the normal gap u⁻ − u⁺),

    solved exactly by the active-set method; every multiplier then follows from the block residuals
    ℓ_b = S_b (t_b − t⁰_b).  Should that violate a bound ±p, the full dual problem (A from
    G_b = S_b⁻¹) is solved with all bounds.  Whether the result is exact is decided by the final
    solve: when its traces differ from the predicted ones by more than :data:`PREDICTION_TOLERANCE`
    (relative; S_b inverted from a distributed block's flexibility, a slender structure) or its KKT
    check fails, ``refine`` repeats the rank-0 solve with t⁰ shifted by the difference between the
    solved and the predicted traces, cumulatively (iterative refinement: the error of S_b enters squared).
    """
    schur_complements = rounds.schur_complements()
    if rounds.floating:  # no K_b⁻¹ f_b for a floating block: its condensed load g_b, by its interior
        condensed = rounds.condensed_loads(schur_complements)
        least = [np.linalg.lstsq(S_b, g_b, rcond=None)[0] for S_b, g_b in zip(schur_complements, condensed)]
        problem = DualProblem(rounds, interface, solver, initial=np.array(least))  # t⁰ for the criterion's scale
    else:
        problem = DualProblem(rounds, interface, solver)
        condensed = np.einsum("bij,bj->bi", schur_complements, problem.initial_traces)
    started = time.perf_counter()
    unknowns = interface.trace_unknowns()
    size = int(unknowns.max()) + 1
    contact = interface.slices["mu_c"]
    normal = 2 * interface.vertex[contact] + 1
    # The crack faces' normal unknowns go last: the contact forces act on them only, so with
    # S = L Lᵀ, L⁻¹ Bᵀ lives in the last block of L and A_c = (L_cc⁻¹ B_cᵀ)ᵀ(L_cc⁻¹ B_cᵀ).
    faces = np.concatenate([unknowns[0][normal], unknowns[1][normal]])
    last = np.zeros(size, dtype=bool)
    last[faces] = True
    position = np.argsort(last, kind="stable").argsort()
    unknowns, first = position[unknowns], size - len(faces)
    stiffness = np.zeros((size, size))
    for S_b, numbers in zip(schur_complements, unknowns):
        stiffness[np.ix_(numbers, numbers)] += S_b
    sqrt_w = problem.sqrt_w[contact]
    jump = np.zeros((len(faces), len(normal)))  # B_cᵀ W^½: forces of a unit scaled contact multiplier
    jump[unknowns[0][normal] - first, np.arange(len(normal))] += sqrt_w
    jump[unknowns[1][normal] - first, np.arange(len(normal))] -= sqrt_w
    import scipy.linalg  # here, on rank 0: importing it costs every rank 35 ms of its start-up

    try:  # in place: the stiffness's memory (rank 0's largest array with the S_b) becomes L
        L = scipy.linalg.cholesky(stiffness.T, lower=False, overwrite_a=True, check_finite=False).T
    except np.linalg.LinAlgError:
        raise SolverError("schur: the interface stiffness is not positive definite (a structure that can move "
                          "rigidly?)") from None
    del stiffness
    forces = np.linalg.solve(L[first:, first:], jump) if len(faces) else np.zeros((0, 0))  # L_cc⁻¹ B_cᵀ
    dual = forces.T @ forces
    history: list[float] = []
    changes: list[int] = []
    lower_c, upper_c = problem.lower[contact], problem.upper[contact]

    def exact(initial: np.ndarray, condensed: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """The scaled multipliers, their predicted traces and the active-set steps for uncoupled
        traces ``initial`` and condensed loads ``condensed`` = S_b t⁰_b (only these with floating blocks)."""
        body = np.zeros(size)
        for g_b, numbers in zip(condensed, unknowns):
            body[numbers] += g_b
        loaded = triangular_solve(L, body)  # L⁻¹ body

        def contact_step(y_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            """Every scaled multiplier and the traces S⁻¹(body − Bᵀ W^½ y_c) for the contact multipliers ``y_c``."""
            rhs = loaded.copy()
            rhs[first:] -= forces @ y_c
            traces = triangular_solve(L, rhs, transpose=True)[unknowns]
            loads = np.einsum("bij,bj->bi", schur_complements, traces) - condensed  # ℓ_b = S_b t_b − g_b
            y = problem.sqrt_w * interface.multipliers(loads)
            y[contact] = y_c
            return y, traces

        def record(y: np.ndarray, traces: np.ndarray, changed: int) -> None:
            """History of one active-set step: the criterion of its solution projected onto the bounds
            (the last step's is feasible already) and how many constraints changed state."""
            history.append(problem.criterion(y, -problem.sqrt_w * interface.gap(traces)))
            changes.append(changed)

        y_c, steps = box_qp(dual, forces.T @ loaded[first:], lower_c, upper_c,
                            observe=lambda y_c, changed: record(*contact_step(np.clip(y_c, lower_c, upper_c)),
                                                                changed))
        y, traces = contact_step(y_c)
        if np.any(y < problem.lower) or np.any(y > problem.upper):  # a bound ±p is active: all bounds
            if rounds.floating:
                raise SolverError(f"schur: a multiplier bound solver.p = {solver.p:g} is active, and its exact solve "
                                  "needs every block invertible, which floating blocks are not: use solver.method = "
                                  "\"feti\" or a larger solver.p")
            flexibilities = np.linalg.inv(schur_complements)
            A = interface.dual_matrix(flexibilities) / np.outer(problem.sqrt_w, problem.sqrt_w)
            b = problem.sqrt_w * interface.gap(initial)

            def full_step(y: np.ndarray) -> np.ndarray:
                return initial + np.einsum("bij,bj->bi", flexibilities, interface.loads(y / problem.sqrt_w))

            y, more = box_qp(A, b, problem.lower, problem.upper,
                             observe=lambda y, changed: record(problem.project(y), full_step(problem.project(y)),
                                                               changed))
            steps += more
            traces = full_step(y)
        return y, traces, steps

    uncoupled = problem.initial_traces  # t⁰ of rank 0's model, corrected by each refinement
    y, predicted, steps = exact(uncoupled, condensed)
    progress(steps, history[-1] if history else 0.0, final=True)
    outcome = Outcome(problem.multipliers(y), converged=True, iterations=steps, history=history,
                      active_set_changes=changes,
                      details={"rank0_solve_time": time.perf_counter() - started, "interface_unknowns": size},
                      held=predicted)

    def refine(solved_traces: np.ndarray, required: bool) -> np.ndarray | None:
        nonlocal predicted, uncoupled, condensed
        mismatch = np.abs(solved_traces - predicted).max(initial=0.0)
        size = displacement_scale(interface, float(np.abs(solved_traces).max(initial=0.0)))
        if not required and mismatch <= PREDICTION_TOLERANCE * size:
            return None
        mark = time.perf_counter()
        uncoupled = uncoupled + (solved_traces - predicted)  # the model now agrees with the blocks at this λ
        condensed = condensed + np.einsum("bij,bj->bi", schur_complements, solved_traces - predicted)
        y, predicted, more = exact(uncoupled, condensed)
        outcome.held = predicted
        outcome.iterations += more
        outcome.details["rank0_solve_time"] += time.perf_counter() - mark
        return problem.multipliers(y)

    outcome.refine = refine
    return outcome


# --- the final solve and the convergence claim ---------------------------------------------------
def final_solve(rounds: Rounds, interface: Interface, solver: Solver, outcome: Outcome) -> Constraints:
    """One full round for the method's multipliers (the displacements that are written), then the
    check of their KKT residuals against :func:`~ddsolve.dd.constraints.kkt_tolerance`: a method that
    stopped on its own rule is converged only if they pass.  A method that can refine its
    multipliers (``outcome.refine``) gets another round when they do not, or when it asks for one, up to
    :data:`MAX_REFINEMENTS` times."""
    tolerance = kkt_tolerance(solver)

    def solve() -> tuple[Constraints, np.ndarray, np.ndarray]:
        traces, energies = rounds.solve(interface.loads(outcome.lam), full=True, held=outcome.held)
        return kkt(interface, traces, outcome.lam, solver.p, rounds.residuals, rounds.largest), traces, energies

    residuals, traces, energies = solve()
    for refinement in range(1, MAX_REFINEMENTS + 1) if outcome.refine is not None else ():
        refined = outcome.refine(traces, bool(residuals.violations(tolerance)))
        if refined is None:
            break
        outcome.lam = refined
        residuals, traces, energies = solve()
        outcome.details["refined"] = refinement
    outcome.details["energy"] = rounds.potential_energy(energies)
    outcome.details["kkt_tolerance"] = tolerance
    outcome.details.update({f"kkt_{name}": getattr(residuals, name) for name in Constraints.NAMES})
    violations = residuals.violations(tolerance)
    if violations and outcome.converged:
        outcome.converged = False
        outcome.message = (f"{solver.method}: not converged: the final solution violates {', '.join(violations)} "
                           f"(scale-free tolerance {tolerance:g}); {_remedy(solver, violations)}")
    return residuals


#: The methods whose criterion is relative to the uncoupled blocks' gap and that can start from given
#: multipliers; :func:`checked_solve` lowers their tol when the final check finds their solution short
#: (uzawa's with ``stop = "kkt"`` only: the other rules are not relative to that gap).
WARM_STARTS = ("fista", "mprgp", "feti", "uzawa")
#: At most this many times.
TIGHTENINGS = 2


def checked_solve(method: str, rounds: Rounds, interface: Interface, solver: Solver, progress: Progress) -> Outcome:
    """``method``'s multipliers, the final solve and its check (:func:`final_solve`).

    The criterion of the methods of :data:`WARM_STARTS` is relative to the gap of the uncoupled blocks.
    Where those are far more flexible than the glued structure (a delamination specimen's arms), it is met
    while the final check, relative to the solution's displacements, still fails.  Such a method then goes on
    from its multipliers with its tol lowered by ten times the worst shortfall, at most :data:`TIGHTENINGS`
    times and within ``max_iterations`` in all; the check stays the one ``solver.tol`` asks for."""
    run = METHODS[method]
    outcome = run(rounds, interface, solver, progress)
    if outcome.diverged:
        return outcome
    tolerance, tol = kkt_tolerance(solver), solver.tol
    met = outcome.converged
    residuals = final_solve(rounds, interface, solver, outcome)
    warm = method in WARM_STARTS and (method != "uzawa" or solver.stop == "kkt")
    theta = outcome.details.get("theta", solver.theta)  # uzawa's θ = "auto": found once
    for _ in range(TIGHTENINGS if warm else 0):
        short = {name: getattr(residuals, name) for name in Constraints.NAMES
                 if not getattr(residuals, name) <= tolerance}
        left = solver.max_iterations - outcome.iterations
        if not (met and short) or "equilibrium" in short or not np.all(np.isfinite(list(short.values()))) or left < 1:
            break
        tol /= 10.0 * max(short.values()) / tolerance
        progress.out(f"{method}: the final check found {', '.join(residuals.violations(tolerance))} (tolerance "
                     f"{tolerance:g}): going on with tol {tol:.2e}")
        done = outcome.iterations
        more = run(rounds, interface, replace(solver, tol=tol, max_iterations=left, theta=theta),
                   lambda iteration, criterion, final=False: progress(done + iteration, criterion, final),
                   start=outcome.lam)
        more.iterations += done
        more.history = outcome.history + more.history
        more.active_set_changes = outcome.active_set_changes + more.active_set_changes
        more.details = {**outcome.details, **more.details, "tightened_tol": tol}
        outcome = more
        if outcome.diverged:
            return outcome
        if not outcome.converged:  # all the iterations, to the lowered tol
            outcome.message = _no_convergence(method, replace(solver, tol=tol), outcome.history)
        met = outcome.converged
        residuals = final_solve(rounds, interface, solver, outcome)
    return outcome


def _remedy(solver: Solver, violations: list[str]) -> str:
    """What to change when the final check fails."""
    if any(v.startswith("equilibrium") for v in violations):
        return ("the block solves are inaccurate: check the blocks' PETSc options "
                "(-u_minus_ksp_rtol, -u_minus_pc_type, ...)")
    if solver.method == "uzawa" and solver.stop == "paper":
        return (f"the paper's stopping rule ‖Δx‖/‖x‖² < solver.tol is dimensional and was met after too few "
                f"steps: set solver.stop = \"kkt\" (or a smaller solver.theta than {solver.theta:g})"
                if isinstance(solver.theta, float) else "set solver.stop = \"kkt\"")
    if solver.method == "uzawa":
        return "lower solver.tol or solver.theta"
    if solver.method == "schur":
        return "the interface problem is too ill-conditioned for an exact solve: try solver.method = \"mprgp\""
    return "lower solver.tol"


# --- FETI: Dirichlet-preconditioned dual iterations on an active set ---------------------------
class DirichletPreconditioner:
    """M⁻¹ = B_D S B_Dᵀ ≈ A⁻¹, FETI's Dirichlet preconditioner for A = B K⁻¹ Bᵀ (B = W^½ C).

    S = diag(S_b) is applied by one Dirichlet solve per block (a round, never a Schur complement
    matrix); B_D = (B Δ Bᵀ)⁻¹ B Δ with Δ_b = 1/diag(K_b) on the traces (stiffness scaling: the stiffer
    block takes the larger share of a jump), so that B B_Dᵀ = I.  B Δ Bᵀ couples only the multipliers
    of one trace entry (at most three), so its inverse is a batch of 3×3 inverses.
    """

    def __init__(self, rounds: Rounds, interface: Interface, sqrt_w: np.ndarray):
        self.rounds = rounds
        self.delta = 1.0 / rounds.trace_diagonals().T  # (2k, 4)
        self.index = interface.trace_index
        order = np.argsort(self.index, kind="stable")
        first = np.searchsorted(self.index[order], self.index[order])
        self.slot = np.empty(interface.size, dtype=np.int64)
        self.slot[order] = np.arange(interface.size) - first
        width = int(self.slot.max(initial=0)) + 1
        signs = np.zeros((interface.size, len(interface.couplings)))
        for block, coupling in enumerate(interface.couplings):
            signs[coupling.rows, block] = coupling.sign
        self.B = np.zeros((interface.trace_size, width, len(interface.couplings)))  # per trace entry: rows × blocks
        self.B[self.index, self.slot] = signs * sqrt_w[:, None]
        G = np.einsum("tib,tb,tjb->tij", self.B, self.delta, self.B)
        unused = np.all(self.B == 0.0, axis=2)  # padding rows: identity
        G[unused, :] = 0.0
        G[np.nonzero(unused) + (np.nonzero(unused)[1],)] = 1.0
        self.G_inverse = np.linalg.inv(G)

    def __call__(self, r: np.ndarray) -> np.ndarray:
        R = np.zeros(self.B.shape[:2])
        R[self.index, self.slot] = r
        Z = np.einsum("tij,tj->ti", self.G_inverse, R)
        traces = self.delta * np.einsum("tib,ti->tb", self.B, Z)  # B_Dᵀ r, per block's trace
        forces = self.rounds.dirichlet(traces.T).T
        Y = np.einsum("tij,tjb,tb->ti", self.G_inverse, self.B, self.delta * forces)  # B_D S B_Dᵀ r
        return Y[self.index, self.slot]


class Coarse:
    """FETI's natural coarse space for floating blocks (TFETI): with K_b⁺ a generalized inverse and R_b the
    kernel, block b is solvable when R_bᵀ(f_b − B_bᵀ y) = 0, i.e. Gᵀ y = e with G = B R (a column per rigid
    motion, B = W^½ C) and e = Rᵀ f; then u_b = K_b⁺(f_b − B_bᵀ y) + R_b α_b.  On the rows left free by an
    active set, :meth:`feasible` moves y onto Gᵀ y = e, :meth:`project` applies P = I − G(GᵀG)⁻¹Gᵀ, and
    :meth:`residual` is the gradient less its part in range G (the gap of the u_b), whose coefficients are the
    amplitudes α.  Without floating blocks G has no columns and every map is the identity.
    """

    def __init__(self, rounds: Rounds, interface: Interface, sqrt_w: np.ndarray):
        columns = []
        for block in rounds.floating:
            coupling, kernel = interface.couplings[block], rounds.kernel_traces[block]
            column = np.zeros((interface.size, kernel.shape[1]))
            column[coupling.rows] = (sqrt_w[coupling.rows] * coupling.sign)[:, None] * kernel[coupling.trace]
            columns.append(column)
        self.rounds = rounds
        self.G = np.hstack(columns) if columns else np.zeros((interface.size, 0))
        work = rounds.kernel_work() if columns else []
        self.e = np.concatenate([work[block] for block in rounds.floating]) if columns else np.zeros(0)

    def _amplitudes(self, v: np.ndarray, free: np.ndarray) -> np.ndarray:
        """(G_fᵀG_f)⁻¹ G_fᵀ v with G_f the free rows of G (least squares: a bound may take a row G needs)."""
        G = self.G[free]
        return np.linalg.lstsq(G.T @ G, G.T @ v[free], rcond=None)[0]

    def feasible(self, y: np.ndarray, free: np.ndarray) -> np.ndarray:
        if not self.G.shape[1]:
            return y
        G = self.G[free]
        step = np.zeros_like(y)
        step[free] = G @ np.linalg.lstsq(G.T @ G, self.e - self.G.T @ y, rcond=None)[0]
        return y + step

    def project(self, v: np.ndarray, free: np.ndarray) -> np.ndarray:
        if not self.G.shape[1]:
            return v
        out = v.copy()
        out[free] -= self.G[free] @ self._amplitudes(v, free)
        return out

    def residual(self, g: np.ndarray, free: np.ndarray) -> np.ndarray:
        return g - self.G @ self._amplitudes(g, free) if self.G.shape[1] else g

    def held(self, interface: Interface, lam: np.ndarray, sqrt_w: np.ndarray, free: np.ndarray) -> np.ndarray | None:
        """The traces of u_b = K_b⁺(f_b − B_bᵀ y) + R_b α_b for the multipliers ``lam`` (one round), for the
        final solve (None without floating blocks)."""
        if not self.G.shape[1]:
            return None
        traces, _ = self.rounds.solve(interface.loads(lam), full=True)
        alpha = self._amplitudes(-sqrt_w * interface.gap(traces), free)
        start = 0
        for block in self.rounds.floating:
            kernel = self.rounds.kernel_traces[block]
            traces[block] += kernel @ alpha[start:start + kernel.shape[1]]
            start += kernel.shape[1]
        return traces


def feti(rounds: Rounds, interface: Interface, solver: Solver, progress: Progress,
         start: np.ndarray | None = None) -> Outcome:
    """The dual problem by a primal-dual active set method whose steps are solved by conjugate
    gradients on the free multipliers, preconditioned by FETI's Dirichlet preconditioner.

    Only block solves and products: a CG iteration takes two rounds (the Dirichlet solves of the
    preconditioner, then the solves of A p), so its cost per round is that of ``mprgp``, and the
    preconditioner keeps the iterations nearly independent of the mesh.  Each active-set step fixes
    the multipliers at their bounds where the sets say so and solves for the others; the sets
    change by the signs of the gradient (active rows) and the bound violations (free rows), as in
    ``box_qp``.  Converged: the sets did not change, the multipliers are feasible and the KKT
    criterion (on the free rows: the CG residual) is below ``tol``; the CG of a step stops at
    ``tol`` then, or while the sets still move at 1e-1 of the smaller of its starting residual and the
    natural residual ‖y − P(y − ∇L)‖ of the best step so far (an inexact Newton step whose forcing only
    tightens: relative to its own start it loosened after every change of the sets, which then followed the
    CG's error and never settled on the ENF specimen).  ``start``: the multipliers to start from (the
    least-squares solution of the coarse problem by default).
    """
    problem = DualProblem(rounds, interface, solver)
    precondition = DirichletPreconditioner(rounds, interface, problem.sqrt_w)
    coarse = Coarse(rounds, interface, problem.sqrt_w)  # floating blocks: y on Gᵀy = e, steps projected
    lower, upper, scale = problem.lower, problem.upper, max(problem.scale, np.finfo(float).tiny)
    y = coarse.feasible(problem.start(start), np.ones(interface.size, dtype=bool))  # by default λ₀ = G(GᵀG)⁻¹e
    g = problem.apply(y) - problem.b if np.any(y) else -problem.b  # A y − b
    at_lower, at_upper = (y <= lower) & (g >= 0), (y >= upper) & (g <= 0)
    outcome = Outcome(y, converged=False, iterations=0)
    settled, steps = False, 0
    reached = np.inf  # the smallest natural residual ‖y − P(y − ∇L)‖ at the end of a step so far
    while outcome.iterations < solver.max_iterations:
        steps += 1
        free = ~(at_lower | at_upper)
        target = coarse.feasible(np.where(at_lower, lower, np.where(at_upper, upper, y)), free)
        if np.any(target != y):  # the fixed multipliers go to their bounds
            g = g + problem.apply(target - y)
            y = target
        r = -coarse.project(np.where(free, g, 0.0), free)
        # An inexact step solves to a tenth of the KKT residual already reached, not of its own starting
        # residual: moving a few rows to their bounds makes that jump by orders of magnitude, which would
        # loosen every step after a change back to ~1e-3 and decide the next sets on the CG's error.
        goal = solver.tol * scale if settled else max(solver.tol * scale, 1e-1 * min(np.linalg.norm(r), reached))
        z = coarse.project(np.where(free, precondition(r), 0.0), free) if np.linalg.norm(r) > goal else r
        p, rz = z, r @ z
        while np.linalg.norm(r) > goal and outcome.iterations < solver.max_iterations:
            q = problem.apply(p)
            alpha = rz / (p @ q)
            y, g = y + alpha * p, g + alpha * q
            r = -coarse.project(np.where(free, g, 0.0), free)
            outcome.iterations += 1
            outcome.history.append(problem.criterion(np.clip(y, lower, upper), coarse.residual(g, free)))
            progress(outcome.iterations, outcome.history[-1])
            if not np.isfinite(outcome.history[-1]):
                outcome.message, outcome.diverged = f"feti broke down at iteration {outcome.iterations}", True
                outcome.lam = problem.multipliers(y)
                return outcome
            if np.linalg.norm(r) <= goal:
                break
            z = coarse.project(np.where(free, precondition(r), 0.0), free)
            rz, previous = r @ z, rz
            p = z + (rz / previous) * p
        gradient = coarse.residual(g, free)  # the Lagrangian's: g less its part carried by the rigid motions
        reached = min(reached, float(np.linalg.norm(y - np.clip(y - gradient, lower, upper))))
        new_lower = (at_lower & (gradient >= 0)) | (free & (y < lower))
        new_upper = (at_upper & (gradient <= 0)) | (free & (y > upper))
        if np.array_equal(new_lower, at_lower) and np.array_equal(new_upper, at_upper):
            criterion = problem.criterion(y, gradient)
            if settled and criterion < solver.tol:
                outcome.converged = True
                break
            settled = True
        else:
            settled = False
        at_lower, at_upper = new_lower, new_upper
    if not outcome.converged:
        outcome.message = _no_convergence("feti", solver, outcome.history)
    progress(outcome.iterations, outcome.history[-1] if outcome.history else 0.0, final=True)
    outcome.lam = problem.multipliers(y)
    outcome.details["active_set_steps"] = steps
    outcome.held = coarse.held(interface, outcome.lam, problem.sqrt_w, ~(at_lower | at_upper))
    return outcome


# --- the default: schur or feti ------------------------------------------------------------------
#: Per-block costs (seconds, n = block unknowns, c = columns, m = multiplier rounds) fitted by
#: ``./run scaling`` on one rank (docs/scaling.md): the interface matrix of a distributed block by
#: multi-column solves c·(n·2kΣ)^p; one block solve; a plain factorization; rank 0's dense solve of
#: ``schur`` on nΣ ≈ 3P interface unknowns; the CG iterations of ``feti`` (about constant in P).
COST_LAWS = {"columns": (1.16e-08, 1.09), "solve": (1.18e-07, 1.10), "factor": (3.46e-08, 1.49),
             "rank0": (4.14e-09, 2.40)}
FETI_ROUNDS = 60


def predicted_costs(ranks_per_block: int, unknowns: int, sigma_vertices: int) -> dict[str, float]:
    """Seconds of what ``schur`` and ``feti`` do beyond the factorization both need, with each block
    on ``ranks_per_block`` ranks (block work shared ideally among them, as in the cost model)."""
    law = {key: (lambda x, a=a, p=p: a * x ** p) for key, (a, p) in COST_LAWS.items()}
    trace = 2 * sigma_vertices
    share = 1.0 / ranks_per_block
    schur = law["rank0"](3 * sigma_vertices)
    if ranks_per_block > 1:  # no Schur complement from a distributed factorization: 2kΣ columns of solves
        schur += share * law["columns"](unknowns * trace)
    feti = share * (law["factor"](unknowns) + FETI_ROUNDS * law["solve"](unknowns))  # + the Dirichlet problem
    return {"schur": schur, "feti": feti}


def choose(ranks_per_block: int, unknowns: int, sigma_vertices: int) -> str:
    """The default method: ``schur`` for whole blocks (exact in three rounds, its Schur complements come
    with the factorization), else whichever :func:`predicted_costs` finds cheaper."""
    if ranks_per_block == 1:
        return "schur"
    costs = predicted_costs(ranks_per_block, unknowns, sigma_vertices)
    return min(costs, key=costs.get)


METHODS: dict[str, Callable[..., Outcome]] = {"schur": schur, "mprgp": mprgp, "fista": fista, "uzawa": uzawa,
                                              "feti": feti}
