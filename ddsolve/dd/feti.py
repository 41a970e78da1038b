"""FETI: Dirichlet-preconditioned dual iterations on an active set, with the natural coarse space of the
floating blocks (TFETI)."""
from __future__ import annotations

import numpy as np

from ddsolve.dd.dual import DualProblem, Outcome, Progress, Rounds, no_convergence
from ddsolve.dd.interface import Interface
from ddsolve.problem.scene import Solver


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
        outcome.message = no_convergence("feti", solver, outcome.history)
    progress(outcome.iterations, outcome.history[-1] if outcome.history else 0.0, final=True)
    outcome.lam = problem.multipliers(y)
    outcome.details["active_set_steps"] = steps
    outcome.held = coarse.held(interface, outcome.lam, problem.sqrt_w, ~(at_lower | at_upper))
    return outcome
