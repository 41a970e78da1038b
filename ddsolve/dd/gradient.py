"""The fast iterative methods on the dual problem: accelerated projected gradient (``fista``) and Dostál's
MPRGP (``mprgp``), one or two rounds of block solves per iteration."""
from __future__ import annotations

import numpy as np

from ddsolve.dd.dual import DualProblem, Outcome, Progress, Rounds, iterate, largest_eigenvalue
from ddsolve.dd.interface import Interface
from ddsolve.problem.scene import Solver


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

    outcome = iterate("fista", problem, progress, steps())
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

    def chopped_gradient(y, g):  # a row whose bounds are equal (friction without pressure) has no way in
        return (np.where((y <= lower) & (y < upper), np.minimum(g, 0.0), 0.0)
                + np.where((y >= upper) & (y > lower), np.maximum(g, 0.0), 0.0))

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

    outcome = iterate("mprgp", problem, progress, steps())
    outcome.details["lambda_max"] = lam_max
    return outcome
