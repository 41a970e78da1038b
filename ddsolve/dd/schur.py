"""The exact method (``schur``): the dual problem solved on rank 0 from the blocks' Schur complements on Σ,
by a primal-dual active set method, refined from the final solve when it asks."""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ddsolve.dd import cohesive
from ddsolve.dd.constraints import displacement_scale
from ddsolve.dd.dual import DualProblem, Outcome, Progress, Rounds
from ddsolve.dd.friction import MAX_FIXED_POINT, no_fixed_point, relative_change, settled
from ddsolve.dd.interface import Interface
from ddsolve.errors import SolverError
from ddsolve.problem.scene import Solver


def box_qp(A: np.ndarray, b: np.ndarray, lower: np.ndarray, upper: np.ndarray, max_steps: int = 200,
           observe: Callable[[np.ndarray, int], None] | None = None, start: np.ndarray | None = None
           ) -> tuple[np.ndarray, int]:
    """Minimize ½ yᵀAy − bᵀy over lower ≤ y ≤ upper (A dense SPD) by a primal-dual active set method.

    Returns the solution and the number of active-set steps.  Each step solves for the free rows with
    the active ones at their bounds; the sets are updated from the signs of the gradient on active rows
    and the bound violations on free rows, until they no longer change.  The first step starts from the
    rows ``start`` (a previous solution) holds at a bound, or from none: the unconstrained minimizer,
    whose violations make the second step's set.  A step costs the factorization of the smaller of the
    two sets' blocks: A_ff directly, or, once the active set is the smaller, H_aa of H = A⁻¹ (factored
    once): y = H(b + Eₐμ) with H_aa μ = y_a − (Hb)_a.  ``observe(y, changes)`` is called after each
    step with its solution and how many rows change set.
    """
    import scipy.linalg  # on rank 0 only (see ExactDual)

    if start is None:
        at_lower = np.zeros(len(b), dtype=bool)
        at_upper = np.zeros(len(b), dtype=bool)
    else:
        at_lower, at_upper = start <= lower, start >= upper
    inverse = loaded = None  # H = A⁻¹ and H b, made at the first step whose active set is the smaller
    for step in range(1, max_steps + 1):
        y = np.where(at_lower, lower, np.where(at_upper, upper, 0.0))
        free = ~(at_lower | at_upper)
        fixed = ~free
        if inverse is None and 0 < fixed.sum() < free.sum():
            factor = scipy.linalg.cho_factor(A, check_finite=False)
            inverse = scipy.linalg.cho_solve(factor, np.eye(len(b)), check_finite=False)
            loaded = scipy.linalg.cho_solve(factor, b, check_finite=False)
        if inverse is not None and fixed.sum() < free.sum():
            y_fixed = y[fixed]
            if fixed.any():
                mu = np.linalg.solve(inverse[np.ix_(fixed, fixed)], y_fixed - loaded[fixed])
                y = loaded + inverse[:, fixed] @ mu
            else:
                y = loaded.copy()
            y[fixed] = y_fixed
        elif free.any():
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


def least_squares(S: np.ndarray, g: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """The least-squares solution of least norm of S t = g for a symmetric positive semidefinite S whose
    null space is spanned by the columns of ``kernel`` (none: S invertible), by one Cholesky factorization:
    with Z an orthonormal basis of the kernel, t = (S + s Z Zᵀ)⁻¹ (g − Z Zᵀ g) is orthogonal to Z and
    solves S t = g − Z Zᵀ g (s: S's largest diagonal entry, which keeps the shifted matrix's scale).  Rows of S
    that are zero (a block's S on a structure's trace, off the entries it holds) are left out: t is zero there."""
    import scipy.linalg  # here, on rank 0 (see ExactDual)

    held = np.flatnonzero(np.diag(S) != 0.0)  # S is semidefinite: a zero diagonal entry is a zero row
    S, kernel = S[np.ix_(held, held)], kernel[held]
    Z = np.linalg.qr(kernel)[0] if kernel.shape[1] else kernel
    shift = float(np.abs(np.diag(S)).max(initial=1.0))
    projected = g[held] - Z @ (Z.T @ g[held])
    t = np.zeros_like(g)
    t[held] = scipy.linalg.cho_solve(scipy.linalg.cho_factor(S + shift * Z @ Z.T, check_finite=False), projected,
                                     check_finite=False)
    return t


def schur(rounds: Rounds, interface: Interface, solver: Solver, progress: Progress) -> Outcome:
    """Exact solve from the blocks' Schur complements S_b on Σ; three rounds in all (one more for each
    refinement the final solve asks for).

    Rounds: one to collect S_b (from MUMPS with the factorization), one for the uncoupled traces
    t⁰_b; :func:`~ddsolve.dd.final_check.final_solve` adds the final one.  Rank 0 assembles the interface stiffness
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
        least = [least_squares(S_b, g_b, kernel) for S_b, g_b, kernel in
                 zip(schur_complements, condensed, rounds.kernel_traces)]
        problem = DualProblem(rounds, interface, solver, initial=np.array(least))  # t⁰ for the criterion's scale
    else:
        problem = DualProblem(rounds, interface, solver)
        condensed = np.einsum("bij,bj->bi", schur_complements, problem.initial_traces)
    started = time.perf_counter()
    exact = ExactDual(problem, schur_complements, floating=bool(rounds.floating))
    uncoupled = problem.initial_traces  # t⁰ of rank 0's model, corrected by each refinement
    y, predicted, steps = exact.solve(uncoupled, condensed)
    progress(steps, exact.history[-1] if exact.history else 0.0, final=True)
    outcome = Outcome(problem.multipliers(y), converged=True, iterations=steps, history=exact.history,
                      active_set_changes=exact.changes,
                      details={"rank0_solve_time": time.perf_counter() - started, "interface_unknowns": exact.size,
                               "active_set_steps": exact.steps, "active_set_time": exact.step_time},
                      held=predicted)
    record_interface_law(outcome, exact)

    def refine(solved_traces: np.ndarray, required: bool) -> np.ndarray | None:
        nonlocal predicted, uncoupled, condensed
        mismatch = np.abs(solved_traces - predicted).max(initial=0.0)
        size = displacement_scale(interface, float(np.abs(solved_traces).max(initial=0.0)))
        if not required and mismatch <= PREDICTION_TOLERANCE * size:
            return None
        mark = time.perf_counter()
        uncoupled = uncoupled + (solved_traces - predicted)  # the model now agrees with the blocks at this λ
        condensed = condensed + np.einsum("bij,bj->bi", schur_complements, solved_traces - predicted)
        y, predicted, more = exact.solve(uncoupled, condensed)
        outcome.held = predicted
        outcome.iterations += more
        outcome.details["rank0_solve_time"] += time.perf_counter() - mark
        outcome.details.update(active_set_steps=exact.steps, active_set_time=exact.step_time)
        record_interface_law(outcome, exact)
        return problem.multipliers(y)

    outcome.refine = refine
    return outcome


def record_interface_law(outcome: Outcome, exact: ExactDual) -> None:
    """What the interface's law made of rank 0's last solve, in ``outcome``: the bond's state and its linear
    problems, Coulomb's Tresca problems, and a fixed point that did not settle (not converged, with its message,
    as the iterative methods report it)."""
    outcome.state = exact.state
    if exact.interface.bond is not None:
        outcome.details["bond_solves"] = exact.bond_solves
    if exact.coulomb_iterations:
        outcome.details["coulomb_iterations"] = exact.coulomb_iterations
    if exact.unsettled is not None:
        outcome.converged, outcome.message = False, exact.unsettled


class ExactDual:
    """Rank 0's exact solve for :func:`schur`: the interface stiffness S = Σ_b P_bᵀ S_b P_b assembled on the tied
    interface unknowns and factored, S = L Lᵀ, then the dual problem on the crack rows solved by :func:`box_qp`
    (on every row when a bound ±p is active).  Every active-set step is recorded in ``history`` and ``changes``."""

    def __init__(self, problem: DualProblem, schur_complements: np.ndarray, floating: bool):
        interface = problem.interface
        self.problem, self.interface, self.schur_complements, self.floating = problem, interface, schur_complements, floating
        unknowns = interface.trace_unknowns()
        size = int(unknowns.max()) + 1
        # the crack rows: contact (normal), then friction (tangential) where the scene has it
        contact = np.concatenate([np.arange(interface.size)[interface.slices["mu_c"]],
                                  np.flatnonzero(interface.is_friction)])
        normal = interface.trace_index[contact]  # the faces' entries the crack rows act on
        # The crack faces' unknowns the crack rows act on go last: the contact forces act on them only, so with
        # S = L Lᵀ, L⁻¹ Bᵀ lives in the last block of L and A_c = (L_cc⁻¹ B_cᵀ)ᵀ(L_cc⁻¹ B_cᵀ).
        minuend, subtrahend = interface.row_blocks[contact].T  # each crack row's lower and upper face
        faces = np.concatenate([unknowns[minuend, normal], unknowns[subtrahend, normal]])
        last = np.zeros(size, dtype=bool)
        last[faces] = True
        position = np.argsort(last, kind="stable").argsort()
        unknowns, first = position[unknowns], size - len(faces)
        stiffness = np.zeros((size, size))
        for S_b, numbers in zip(schur_complements, unknowns):
            stiffness[np.ix_(numbers, numbers)] += S_b
        sqrt_w = problem.sqrt_w[contact]
        jump = np.zeros((len(faces), len(normal)))  # B_cᵀ W^½: forces of a unit scaled contact multiplier
        jump[unknowns[minuend, normal] - first, np.arange(len(normal))] += sqrt_w
        jump[unknowns[subtrahend, normal] - first, np.arange(len(normal))] -= sqrt_w
        import scipy.linalg  # here, on rank 0: importing it costs every rank 35 ms of its start-up

        try:  # in place: the stiffness's memory (rank 0's largest array with the S_b) becomes L
            self.L = scipy.linalg.cholesky(stiffness.T, lower=False, overwrite_a=True, check_finite=False).T
        except np.linalg.LinAlgError:
            raise SolverError("schur: the interface stiffness is not positive definite (a structure that can move "
                              "rigidly?)") from None
        del stiffness
        self.forces = np.linalg.solve(self.L[first:, first:], jump) if len(faces) else np.zeros((0, 0))  # L_cc⁻¹ B_cᵀ
        self.dual = self.forces.T @ self.forces
        self.unknowns, self.size, self.first, self.contact = unknowns, size, first, contact
        self.lower_c, self.upper_c = problem.lower[contact], problem.upper[contact]
        self.coulomb_iterations = 0  # Tresca problems of the last Coulomb fixed point
        self.unsettled: str | None = None  # why the last Coulomb fixed point did not settle
        self.history: list[float] = []
        self.changes: list[int] = []
        self.last_c: np.ndarray | None = None  # the last contact multipliers: the next solve starts from their set
        self.last: np.ndarray | None = None  # ... and the last multipliers with every bound
        self.steps, self.step_time = 0, 0.0  # active-set steps so far and their seconds (with their traces)
        self.springs: SpringDual | None = None  # a bond's interface stiffness, made at its first solve
        self.state: Interface | None = None  # the bond's last state (its damage), :meth:`bonded`
        self.bond_solves = 0  # the linear problems of the bond's last fixed point

    def solve(self, initial: np.ndarray, condensed: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """The scaled multipliers, their predicted traces and the active-set steps for uncoupled
        traces ``initial`` and condensed loads ``condensed`` = S_b t⁰_b (only these with floating blocks)."""
        problem, lower_c, upper_c = self.problem, self.lower_c, self.upper_c
        if self.interface.bond is not None:
            mark = time.perf_counter()
            y, traces, steps = self.bonded(initial, condensed)
            self.steps += steps
            self.step_time += time.perf_counter() - mark
            return y, traces, steps
        body = np.zeros(self.size)
        for g_b, numbers in zip(condensed, self.unknowns):
            body[numbers] += g_b
        loaded = triangular_solve(self.L, body)  # L⁻¹ body
        mark = time.perf_counter()
        y_c, steps = box_qp(self.dual, self.forces.T @ loaded[self.first:], lower_c, upper_c, start=self.last_c,
                            observe=lambda y_c, changed: self.record(
                                *self.contact_step(loaded, condensed, np.clip(y_c, lower_c, upper_c)), changed))
        if self.interface.coulomb and self.interface.friction:
            y_c, steps = self.fixed_point(loaded, condensed, y_c, steps)
        self.last_c = y_c
        y, traces = self.contact_step(loaded, condensed, y_c)
        if np.any(y < problem.lower) or np.any(y > problem.upper):  # a bound ±p is active: all bounds
            y, traces, more = self.all_bounds(initial)
            steps += more
        self.steps += steps
        self.step_time += time.perf_counter() - mark
        return y, traces, steps

    def fixed_point(self, loaded: np.ndarray, condensed: np.ndarray, y_c: np.ndarray, steps: int
                    ) -> tuple[np.ndarray, int]:
        """Coulomb's friction (:mod:`ddsolve.dd.friction`) on rank 0: Tresca problems on the crack rows with
        g = μ max(μᶜ, 0) of the last, each started from its active set, until g settles; the crack rows' scaled
        multipliers and the active-set steps in all.  The bounds of the friction rows become the last g."""
        problem, interface = self.problem, self.interface
        friction_rows = interface.is_friction[self.contact]
        sqrt_w = problem.sqrt_w[self.contact][friction_rows]
        cap = (np.inf if problem.solver.p is None else problem.solver.p) * sqrt_w
        lam = np.zeros(interface.size)
        slip = self.upper_c[friction_rows] / sqrt_w  # the bounds y_c was solved with
        self.unsettled = None
        for iteration in range(1, MAX_FIXED_POINT + 1):
            lam[self.contact] = y_c / problem.sqrt_w[self.contact]
            new = interface.slip_bounds(lam)
            if settled(slip, new, problem.solver.tol):
                break
            change, slip = relative_change(slip, new), new
            self.upper_c[friction_rows] = np.minimum(slip * sqrt_w, cap)
            self.lower_c[friction_rows] = -self.upper_c[friction_rows]
            y_c, more = box_qp(self.dual, self.forces.T @ loaded[self.first:], self.lower_c, self.upper_c, start=y_c,
                               observe=lambda y, changed: self.record(
                                   *self.contact_step(loaded, condensed, np.clip(y, self.lower_c, self.upper_c)),
                                   changed))
            steps += more
        else:
            self.unsettled = no_fixed_point("schur", change)
        problem.lower[self.contact], problem.upper[self.contact] = self.lower_c, self.upper_c
        self.coulomb_iterations = iteration
        return y_c, steps

    def bonded(self, initial: np.ndarray, condensed: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """A bond's problem on rank 0 by Newton's method on the interface stiffness (:class:`SpringDual`), with no
        block solve: the scaled multipliers, their traces and the active-set steps in all."""
        if self.springs is None:
            self.springs = SpringDual(self.problem, self.schur_complements)
        y, traces, steps, self.state, self.bond_solves = self.springs.newton(condensed)
        return y, traces, steps

    def contact_step(self, loaded: np.ndarray, condensed: np.ndarray, y_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every scaled multiplier and the traces S⁻¹(body − Bᵀ W^½ y_c) for the contact multipliers ``y_c``
        (``loaded`` = L⁻¹ body)."""
        rhs = loaded.copy()
        rhs[self.first:] -= self.forces @ y_c
        traces = triangular_solve(self.L, rhs, transpose=True)[self.unknowns]
        traces[self.interface.faces == 0] = 0.0  # entries a block does not hold (several interfaces)
        loads = np.einsum("bij,bj->bi", self.schur_complements, traces) - condensed  # ℓ_b = S_b t_b − g_b
        y = self.problem.sqrt_w * self.interface.multipliers(loads)
        y[self.contact] = y_c
        return y, traces

    def record(self, y: np.ndarray, traces: np.ndarray, changed: int) -> None:
        """History of one active-set step: the criterion of its solution projected onto the bounds
        (the last step's is feasible already) and how many constraints changed state."""
        self.history.append(self.problem.criterion(y, -self.problem.sqrt_w * self.interface.gap(traces)))
        self.changes.append(changed)

    def all_bounds(self, initial: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """The full dual problem (A from G_b = S_b⁻¹) with every bound, for uncoupled traces ``initial``: the
        scaled multipliers, their traces and the active-set steps."""
        problem, interface = self.problem, self.interface
        if self.floating:
            raise SolverError(f"schur: a multiplier bound solver.p = {problem.solver.p:g} is active, and its exact "
                              "solve needs every block invertible, which floating blocks are not: use solver.method = "
                              "\"feti\" or a larger solver.p")
        flexibilities = np.zeros_like(self.schur_complements)  # G_b = S_b⁻¹ on the entries block b holds
        for G_b, S_b, held in zip(flexibilities, self.schur_complements, interface.faces != 0):
            G_b[np.ix_(held, held)] = np.linalg.inv(S_b[np.ix_(held, held)])
        A = interface.dual_matrix(flexibilities) / np.outer(problem.sqrt_w, problem.sqrt_w)
        b = problem.sqrt_w * interface.gap(initial)

        def full_step(y: np.ndarray) -> np.ndarray:
            return initial + np.einsum("bij,bj->bi", flexibilities, interface.loads(y / problem.sqrt_w))

        y, more = box_qp(A, b, problem.lower, problem.upper, start=self.last,
                         observe=lambda y, changed: self.record(problem.project(y), full_step(problem.project(y)),
                                                                changed))
        self.last = y
        return y, full_step(y), more


#: Newton's method on a bond has converged when no jump changes by more than this times the strength's elastic
#: opening σ_c/k (the elastic law: the largest jump's).
NEWTON_TOLERANCE = 1e-10
#: At most this many Newton steps per load step (per attempt).
MAX_NEWTON = 60
#: The secant iteration a failed Newton attempt falls back to: at most this many solves, converged when no
#: traction changes by more than this times the strength.
FALLBACK_SOLVES, FALLBACK_TOLERANCE = 2000, 1e-4


class SpringDual:
    """``schur``'s solve of a bond on rank 0: the interface stiffness on the faces' unknowns (each layer's lower
    face u⁻ = v⁻ tied, and its upper face u⁺ = v⁺), S = Σ_b P_bᵀ S_b P_b, with the bond's law between the faces
    of each bonded vertex, linearized (:func:`ddsolve.dd.cohesive.response`: springs w K_t and a prestress) and
    solved by Newton's method; the crack's rows (contact, friction) by :func:`box_qp` on their dual
    A_c = J M⁻¹ Jᵀ of each linearized stiffness M, as :class:`ExactDual` does."""

    def __init__(self, problem: DualProblem, schur_complements: np.ndarray):
        interface = problem.interface
        self.problem, self.interface, self.schur_complements = problem, interface, schur_complements
        lower = np.arange(interface.trace_size)
        self.half = interface.trace_size
        self.unknowns = np.array([lower if spec.side < 0 else lower + self.half for spec in interface.blocks])
        size = 2 * self.half
        self.base = np.zeros((size, size))
        for S_b, numbers in zip(schur_complements, self.unknowns):
            self.base[np.ix_(numbers, numbers)] += S_b
        self.crack = np.flatnonzero(interface.is_contact | interface.is_friction)
        entries = interface.trace_index[self.crack]
        self.faces = np.zeros((size, len(self.crack)))  # J: the faces' forces of a unit scaled crack multiplier
        self.faces[entries, np.arange(len(self.crack))] = problem.sqrt_w[self.crack]
        self.faces[entries + self.half, np.arange(len(self.crack))] = -problem.sqrt_w[self.crack]
        rows = np.arange(interface.size)[interface.slices["mu_g"]]
        self.vertices = np.unique(interface.vertex[rows])  # the bonded vertices, and their rows per component
        self.rows = np.full((len(self.vertices), 2), -1)
        self.rows[np.searchsorted(self.vertices, interface.vertex[rows]), interface.component[rows]] = rows
        self.last: np.ndarray | None = None  # the crack rows' last multipliers: the next solve starts from their set
        self.traces: np.ndarray | None = None  # the last load step's traces: Newton's start

    def gaps(self, traces: np.ndarray) -> np.ndarray:
        """``(m, 2)``: u⁻ − u⁺ of the bonded vertices (0 in a component without a row)."""
        entries = 2 * self.vertices[:, None] + np.arange(2)
        out = traces[0][entries] - traces[1][entries]
        return np.where(self.rows >= 0, out, 0.0)

    def newton(self, condensed: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, Interface, int]:
        """The bond's problem for the condensed loads ``condensed`` = S_b t⁰_b from the history's damage: the scaled
        multipliers, their traces, the active-set steps, the final state (damage, pressed rows) and the linear
        problems solved (each a dense factorization of the interface stiffness).  Newton's method from the last
        step's traces; where it fails (a vertex that breaks unloads its neighbours at once: the kinks of the law),
        the monotone secant iteration (:meth:`secant`) and Newton's method again from there."""
        interface, bond = self.interface, self.interface.bond
        history = interface.damage[self.vertices]
        y, traces, steps, solves = self.iterate(history, condensed, self.traces)
        if y is None:
            start, more_steps, more = self.secant(history, condensed, traces)
            y, traces, steps, solves = self.iterate(history, condensed, start)
            steps, solves = steps + more_steps, solves + more + MAX_NEWTON
        if y is None:
            raise SolverError(f"schur: Newton's method on the bond found no solution in {MAX_NEWTON} steps, after "
                              "the secant iteration too")
        law = cohesive.response(bond, history, self.gaps(traces))
        present = self.rows >= 0
        y[self.rows[present]] = (self.problem.sqrt_w[self.rows[present]] * law.traction[present])
        damage, pressed = interface.damage.copy(), interface.pressed.copy()
        damage[self.vertices], pressed[self.vertices] = law.damage, law.pressed
        self.traces = traces
        return y, traces, steps, interface.with_damage(damage, pressed), solves

    def iterate(self, history: np.ndarray, condensed: np.ndarray, traces: np.ndarray | None
                ) -> tuple[np.ndarray | None, np.ndarray, int, int]:
        """Newton's method from ``traces`` (None: the undeformed faces): the scaled multipliers (None if it did not
        converge in :data:`MAX_NEWTON` steps), the traces, the active-set steps and the Newton steps."""
        bond, steps = self.interface.bond, 0
        for solves in range(1, MAX_NEWTON + 1):
            gap = np.zeros((len(self.vertices), 2)) if traces is None else self.gaps(traces)
            law = cohesive.response(bond, history, gap)
            prestress = law.traction - np.einsum("mij,mj->mi", law.tangent, gap)
            try:
                y, traces, more = self.linear(law.tangent, prestress, condensed)
            except np.linalg.LinAlgError:  # a softening tangent made the crack rows' dual indefinite: Newton fails
                return None, traces, steps, MAX_NEWTON
            steps += more
            change = np.abs(self.gaps(traces) - gap).max(initial=0.0)
            reach = bond.strength / bond.stiffness if bond.strength else np.abs(self.gaps(traces)).max(initial=0.0)
            if change <= NEWTON_TOLERANCE * reach:
                return y, traces, steps, solves
        return None, traces, steps, MAX_NEWTON

    def secant(self, history: np.ndarray, condensed: np.ndarray, traces: np.ndarray
               ) -> tuple[np.ndarray, int, int]:
        """The monotone secant iteration from the ``history``: solve with the springs k(1 − d), raise d to the
        damage of the new jumps, never lowering it, until no traction changes by more than
        :data:`FALLBACK_TOLERANCE` σ_c: an increasing bounded sequence, which converges.  The traces, the active-set
        steps and the solves."""
        bond, damage, steps = self.interface.bond, history.copy(), 0
        traces = None
        for solves in range(1, FALLBACK_SOLVES + 1):
            gap = np.zeros((len(self.vertices), 2)) if traces is None else self.gaps(traces)
            raised = np.maximum(damage, cohesive.response(bond, damage, gap).damage)
            effective = np.hypot(np.maximum(-gap[:, 1], 0.0), gap[:, 0])
            if traces is not None and (np.abs(raised - damage) * effective).max(initial=0.0) * bond.stiffness \
                    <= FALLBACK_TOLERANCE * bond.strength:
                break
            damage = raised
            law = cohesive.response(bond, damage, gap)  # no growth beyond ``damage``: the secant springs
            _, traces, more = self.linear(law.tangent, np.zeros_like(gap), condensed)
            steps += more
        return traces, steps, solves

    def linear(self, tangent: np.ndarray, prestress: np.ndarray, condensed: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, int]:
        """The linearized problem: the bonded rows' multipliers K_t (u⁻ − u⁺) + prestress (``tangent`` ``(m, 2, 2)``,
        ``prestress`` ``(m, 2)``); its scaled multipliers, traces and active-set steps."""
        import scipy.linalg  # on rank 0 only (see ExactDual)

        matrix, body = self.base.copy(), np.zeros(len(self.base))
        for g_b, numbers in zip(condensed, self.unknowns):
            body[numbers] += g_b
        weights = self.interface.weights[self.vertices]
        lower = 2 * self.vertices[:, None] + np.arange(2)  # the vertices' entries on the lower and upper faces
        upper = lower + self.half
        for i in range(2):
            held = self.rows[:, i] >= 0
            np.subtract.at(body, lower[held, i], weights[held] * prestress[held, i])
            np.add.at(body, upper[held, i], weights[held] * prestress[held, i])
            for j in range(2):
                both = held & (self.rows[:, j] >= 0)
                spring = weights[both] * tangent[both, i, j]
                for a, b, sign in ((lower, lower, 1.0), (upper, upper, 1.0), (lower, upper, -1.0), (upper, lower, -1.0)):
                    np.add.at(matrix, (a[both, i], b[both, j]), sign * spring)
        factor = scipy.linalg.lu_factor(matrix, check_finite=False)
        free = scipy.linalg.lu_solve(factor, body, check_finite=False)
        steps, y_c = 0, np.zeros(len(self.crack))
        if len(self.crack):
            flexible = scipy.linalg.lu_solve(factor, self.faces, check_finite=False)
            bounds = self.interface.bounds(None)
            lower_c, upper_c = (bound[self.crack] * self.problem.sqrt_w[self.crack] for bound in bounds)
            y_c, steps = box_qp(self.faces.T @ flexible, self.faces.T @ free, lower_c, upper_c, start=self.last)
            self.last = y_c
            free = free - flexible @ y_c
        traces = free[self.unknowns]
        loads = np.einsum("bij,bj->bi", self.schur_complements, traces) - condensed  # ℓ_b = S_b t_b − g_b
        y = self.problem.sqrt_w * self.interface.multipliers(loads)
        y[self.crack] = y_c
        return y, traces, steps


def remedy(solver: Solver) -> str:
    """What to change when schur's final check fails (with accurate block solves)."""
    return "the interface problem is too ill-conditioned for an exact solve: try solver.method = \"mprgp\""
