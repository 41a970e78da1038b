"""FETI: Dirichlet-preconditioned conjugate gradients on the dual problem, the bounds enforced on the whole
Krylov subspace, with the natural coarse space of the floating blocks (TFETI)."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ddsolve.dd.dual import DualProblem, Outcome, Progress, Rounds, no_convergence, projected_gradient
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
        """y moved onto Gᵀy = e by a least-squares change on the ``free`` rows."""
        if not self.G.shape[1]:
            return y
        G = self.G[free]
        step = np.zeros_like(y)
        step[free] = G @ np.linalg.lstsq(G.T @ G, self.e - self.G.T @ y, rcond=None)[0]
        return y + step

    def inside(self, y: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """y moved onto Gᵀy = e within the bounds: corrected on the rows strictly inside them, and where the
        correction pushes a row past a bound, that row held at the bound and the others corrected again."""
        y = np.clip(y, lower, upper)
        while True:
            moved = self.feasible(y, (y > lower) & (y < upper))
            y = np.clip(moved, lower, upper)
            if np.array_equal(y, moved):
                return y

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


def nearest_within(f: np.ndarray, rows: np.ndarray, low: np.ndarray,
                   high: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The c nearest f with low ≤ rows·c ≤ high, and the masks of the rows that hold it at their lower and
    upper bounds: a least-distance problem, solved as Lawson and Hanson's nonnegative least squares
    (the minimal |x| with E x ≥ h from the u ≥ 0 nearest [Eᵀ; hᵀ]u = (0, …, 0, 1))."""
    from scipy.optimize import nnls  # here, on rank 0: importing it costs every rank start-up time
    norms = np.linalg.norm(rows, axis=1)
    sides = [(1.0, low, np.isfinite(low) & (norms > 0)), (-1.0, high, np.isfinite(high) & (norms > 0))]
    E = np.vstack([side * rows[keep] / norms[keep, None] for side, _, keep in sides])
    h = np.concatenate([side * (bound[keep] - rows[keep] @ f) / norms[keep] for side, bound, keep in sides])
    at_low, at_high = np.zeros(len(low), dtype=bool), np.zeros(len(low), dtype=bool)
    if not np.any(h > 0):  # f is within
        return f.copy(), at_low, at_high
    size = float(np.abs(h).max())
    M = np.vstack([E.T, h / size])
    u, _ = nnls(M, np.eye(len(f) + 1)[-1])
    r = M @ u
    c = f - size * r[:-1] / (r[-1] - 1.0)
    count = int(sides[0][2].sum())
    at_low[sides[0][2]], at_high[sides[1][2]] = u[:count] > 0, u[count:] > 0
    return c, at_low, at_high


#: a direction whose A-norm² is less than this share of its own before orthogonalization adds nothing
INDEPENDENT = 1e-14


class Subspace:
    """The iterate y = y₀ + V c over an A-orthonormal basis V of the directions so far, with A V kept: the
    minimizer of the dual energy ½|c|² + cᵀVᵀ(A y₀ − b) over the bounds is the point of the bounds' polytope
    in c nearest −Vᵀ(A y₀ − b) (:func:`nearest_within`), and costs no round.  Without bounds this is
    conjugate gradients.  Every direction must satisfy Gᵀv = 0 (``on_constraint`` removes the round-off)."""

    def __init__(self, problem: DualProblem, y: np.ndarray, g: np.ndarray, capacity: int,
                 on_constraint: Callable[[np.ndarray], np.ndarray]):
        self.problem, self.capacity, self.on_constraint = problem, capacity, on_constraint
        self.bounded = np.isfinite(problem.lower) | np.isfinite(problem.upper)
        self.restarts = 0
        self.rebase(y, g)

    def rebase(self, y: np.ndarray, g: np.ndarray) -> None:
        self.y0, self.g0 = y, g
        self.V, self.AV = np.zeros((len(y), 0)), np.zeros((len(y), 0))

    def add(self, z: np.ndarray) -> bool:
        """Appends direction z, A-orthogonalized (one round); False when it adds nothing new."""
        if self.V.shape[1] >= self.capacity:
            self.rebase(*self.point())
            self.restarts += 1
        known = 0.0  # |A-components of z along V|²
        for _ in range(2):
            h = self.AV.T @ z
            z, known = z - self.V @ h, known + float(h @ h)
        z = self.on_constraint(z)  # off Gᵀz = 0 by round-off, it would grow with every direction built on it
        q = self.problem.apply(z)
        norm = float(z @ q)
        if not norm > INDEPENDENT * (norm + known):
            return False
        self.V = np.column_stack([self.V, z / np.sqrt(norm)])
        self.AV = np.column_stack([self.AV, q / np.sqrt(norm)])
        return True

    def minimizer(self, constrained: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The minimizer y over the subspace within the bounds of the ``constrained`` rows, and A y − b."""
        lower, upper, b = self.problem.lower, self.problem.upper, constrained
        c, at_low, at_high = nearest_within(
            -self.V.T @ self.g0, self.V[b], lower[b] - self.y0[b], upper[b] - self.y0[b])
        y, g = self.y0 + self.V @ c, self.g0 + self.AV @ c
        held = y[b]
        held[at_low], held[at_high] = lower[b][at_low], upper[b][at_high]  # exactly, not to round-off
        y[b] = held
        return y, g

    def point(self) -> tuple[np.ndarray, np.ndarray]:
        """The minimizer y over the subspace within all bounds, and A y − b."""
        y, g = self.minimizer(self.bounded)
        return np.clip(y, self.problem.lower, self.problem.upper), g


def released(projected: np.ndarray, free: np.ndarray) -> np.ndarray:
    """The rows at a bound that the next direction may move off it: those whose projected gradient pulls
    them off at least as hard as the largest free gradient (at least the one pulled hardest).  Releasing
    every row pulled at all let the delamination specimens' crack faces, all pressed together before the
    first step, move apart and then be held again one by one."""
    pulled = ~free & (projected != 0.0)
    if pulled.any():
        bar = min(np.abs(projected[pulled]).max(), np.abs(projected[free]).max(initial=0.0))
        pulled &= np.abs(projected) >= bar
    return pulled


def inward(coarse: Coarse, v: np.ndarray, y: np.ndarray, face: np.ndarray, lower: np.ndarray,
           upper: np.ndarray) -> np.ndarray:
    """v on the ``face`` rows and on Gᵀv = 0, without the rows at a bound that it would push past it."""
    while True:
        v = coarse.project(np.where(face, v, 0.0), face)
        outward = face & (((y <= lower) & (v < 0)) | ((y >= upper) & (v > 0)))
        if not outward.any():
            return v
        face = face & ~outward


def feti(rounds: Rounds, interface: Interface, solver: Solver, progress: Progress,
         start: np.ndarray | None = None) -> Outcome:
    """The dual problem by conjugate gradients on a growing subspace, preconditioned by FETI's Dirichlet
    preconditioner on the free multipliers, with the bounds enforced on the whole subspace.

    Each iteration adds one direction: the preconditioned projected gradient on the free rows and on the
    rows at a bound pulled off it hardest (:func:`released`), projected by the coarse space of the
    floating blocks.  The iterate is the minimizer over the span of all directions so far within the
    bounds (a dense least-distance problem of the basis' size on rank 0), so the Krylov space survives
    every change of the active set.  Where the minimizer with only the held rows bounded leaves the
    bounds, an expansion step adds its projection onto them as a direction: the rows it crosses are held
    together, not one per iteration.  An iteration takes two rounds (the Dirichlet solves, then A z), an
    expansion one more.  Converged: the KKT criterion (the projected gradient of the Lagrangian) is below
    ``tol``.  ``start``: the multipliers to start from (0 by default: the crack faces free), moved onto
    the bounds and the coarse constraint Gᵀy = e.
    """
    problem = DualProblem(rounds, interface, solver)
    precondition = DirichletPreconditioner(rounds, interface, problem.sqrt_w)
    coarse = Coarse(rounds, interface, problem.sqrt_w)
    outcome, free = minimize(problem, coarse, precondition, progress, start)
    outcome.held = coarse.held(interface, outcome.lam, problem.sqrt_w, free)
    return outcome


def minimize(problem: DualProblem, coarse: Coarse, precondition: Callable[[np.ndarray], np.ndarray],
             progress: Progress, start: np.ndarray | None = None, capacity: int = 400) -> tuple[Outcome, np.ndarray]:
    """:func:`feti`'s iterations; returns the outcome and the free rows of its multipliers."""
    solver, lower, upper = problem.solver, problem.lower, problem.upper
    y = coarse.inside(problem.start(start), lower, upper)
    g = problem.apply(y) - problem.b if np.any(y) else -problem.b
    space = Subspace(problem, y, g, capacity, lambda v: coarse.project(v, v != 0.0))
    outcome = Outcome(y, converged=False, iterations=0)
    expansions = 0
    while True:
        free = (y > lower) & (y < upper)
        gradient = coarse.residual(g, free)  # the Lagrangian's: g less its part carried by the rigid motions
        criterion = problem.criterion(y, gradient)
        if outcome.iterations:
            outcome.history.append(criterion)
            progress(outcome.iterations, criterion)
        if not criterion >= solver.tol or outcome.iterations >= solver.max_iterations:
            break
        projected = projected_gradient(y, gradient, lower, upper)
        face = free | released(projected, free)
        if not (space.add(inward(coarse, precondition(-projected), y, face, lower, upper))
                or space.add(inward(coarse, -projected, y, face, lower, upper))):
            outcome.message = (f"feti: no new direction at iteration {outcome.iterations} "
                               f"(criterion {criterion:.3e}, tol {solver.tol:g})")
            break
        unheld, _ = space.minimizer(space.bounded & ~free)
        if np.any(unheld < lower) or np.any(unheld > upper):
            space.add(coarse.inside(unheld, lower, upper) - unheld)
            expansions += 1
        y, g = space.point()
        outcome.iterations += 1
        outcome.active_set_changes.append(int(np.count_nonzero(free != ((y > lower) & (y < upper)))))
    outcome.converged = criterion < solver.tol
    if not np.isfinite(criterion):
        outcome.message, outcome.diverged = f"feti broke down at iteration {outcome.iterations}", True
    elif not outcome.converged and not outcome.message:
        outcome.message = no_convergence("feti", solver, outcome.history)
    progress(outcome.iterations, outcome.history[-1] if outcome.history else 0.0, final=True)
    outcome.lam = problem.multipliers(y)
    outcome.details.update(expansions=expansions, restarts=space.restarts, held_rows=int(np.count_nonzero(~free)),
                           set_changes=int(sum(outcome.active_set_changes)))
    return outcome, free
