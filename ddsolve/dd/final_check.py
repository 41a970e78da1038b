"""The final solve of a method's multipliers and its KKT check: whether a method converged is decided here,
where a method that fell short is sent on (:func:`checked_solve`, the one entry the driver calls)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ddsolve.dd import cohesive, friction
from ddsolve.dd.constraints import Constraints, kkt, kkt_tolerance
from ddsolve.dd.dual import Outcome, Progress, Rounds, no_convergence
from ddsolve.dd.interface import Interface
from ddsolve.dd.registry import METHODS, compliant_methods
from ddsolve.errors import SolverError
from ddsolve.problem.scene import Solver


#: At most this many refinement rounds after the final solve (each one a rank-0 solve and a round).
MAX_REFINEMENTS = 3


def final_solve(rounds: Rounds, interface: Interface, solver: Solver, outcome: Outcome) -> Constraints:
    """One full round for the method's multipliers (the displacements that are written), then the
    check of their KKT residuals against :func:`~ddsolve.dd.constraints.kkt_tolerance`: a method that
    stopped on its own rule is converged only if they pass.  A method that can refine its
    multipliers (``outcome.refine``) gets another round when they do not, or when it asks for one, up to
    :data:`MAX_REFINEMENTS` times."""
    tolerance = kkt_tolerance(solver)

    def solve() -> tuple[Constraints, np.ndarray, np.ndarray]:  # checked on the state λ solves (a bond's damage)
        state = outcome.state if outcome.state is not None else interface
        traces, energies = rounds.solve(state.loads(outcome.lam), full=True, held=outcome.held)
        return kkt(state, traces, outcome.lam, solver.p, rounds.residuals, rounds.largest), traces, energies

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


#: At most this many times :func:`checked_solve` lowers a method's tol.
TIGHTENINGS = 2


def checked_solve(method: str, rounds: Rounds, interface: Interface, solver: Solver, progress: Progress) -> Outcome:
    """``method``'s multipliers, the final solve and its check (:func:`_checked`); with Coulomb's friction the
    fixed point of Tresca problems (:func:`ddsolve.dd.friction.coulomb`), each checked and started from the last
    multipliers, unless the method iterates it itself on rank 0 (``schur``); with a damaging bond the secant fixed
    point of the damage (:func:`ddsolve.dd.cohesive.secant`) the same way.  A method that cannot take a bond's
    compliance is refused in one line."""
    described = METHODS[method]
    if interface.bond is not None:
        if not described.compliant:
            raise SolverError(f"{method}: interface.law needs a method that takes the bond's compliance on the dual "
                              f"problem: solver.method = {' or '.join(compliant_methods())}")
        if interface.bond.law != "elastic" and not described.fixed_point:
            return cohesive.secant(interface, lambda state, start: _checked(method, rounds, state, solver, progress,
                                                                            start), method)
    if interface.coulomb and interface.friction and not described.fixed_point:
        return friction.coulomb(interface, lambda tresca, start: _checked(method, rounds, tresca, solver, progress,
                                                                           start), solver.tol, method)
    return _checked(method, rounds, interface, solver, progress)


def _checked(method: str, rounds: Rounds, interface: Interface, solver: Solver, progress: Progress,
             start: np.ndarray | None = None) -> Outcome:
    """``method``'s multipliers (from ``start`` where given), the final solve and its check (:func:`final_solve`).

    The criterion of the methods that resume (:attr:`~ddsolve.dd.registry.Method.resumes`) is relative to the gap
    of the uncoupled blocks.
    Where those are far more flexible than the glued structure (a delamination specimen's arms), it is met
    while the final check, relative to the solution's displacements, still fails.  Such a method then goes on
    from its multipliers with its tol lowered by ten times the worst shortfall, at most :data:`TIGHTENINGS`
    times and within ``max_iterations`` in all; the check stays the one ``solver.tol`` asks for."""
    described = METHODS[method]
    run = described.run
    outcome = run(rounds, interface, solver, progress) if start is None else run(rounds, interface, solver,
                                                                                   progress, start=start)
    if outcome.diverged:
        return outcome
    tolerance, tol = kkt_tolerance(solver), solver.tol
    met = outcome.converged
    residuals = final_solve(rounds, interface, solver, outcome)
    warm = described.resumes(solver)
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
            outcome.message = no_convergence(method, replace(solver, tol=tol), outcome.history)
        met = outcome.converged
        residuals = final_solve(rounds, interface, solver, outcome)
    return outcome


def _remedy(solver: Solver, violations: list[str]) -> str:
    """What to change when the final check fails."""
    if any(v.startswith("equilibrium") for v in violations):
        return ("the block solves are inaccurate: check the blocks' PETSc options "
                "(-u_minus_ksp_rtol, -u_minus_pc_type, ...)")
    return METHODS[solver.method].remedy(solver)
