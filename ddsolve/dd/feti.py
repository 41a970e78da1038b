"""FETI: Dirichlet-preconditioned conjugate gradients on the dual problem, the bounds enforced on the whole
Krylov subspace, with the natural coarse space of the floating blocks (TFETI)."""
from __future__ import annotations

import itertools
from typing import Callable

import numpy as np

from ddsolve.dd.dual import DualProblem, Outcome, Progress, Rounds, no_convergence, projected_gradient
from ddsolve.dd.interface import Interface
from ddsolve.problem.scene import Solver


class Preconditioner:
    """M⁻¹ = B_D S B_Dᵀ ≈ A⁻¹, FETI's preconditioner for A = B K⁻¹ Bᵀ (B = W^½ C).

    Dirichlet's: S = diag(S_b) applied by one Dirichlet solve per block (a round, never a Schur complement
    matrix); lumped (``lumped``): S_b replaced by K_b,ΣΣ, the block's stiffness on its trace, which rank 0
    holds (no round, no Dirichlet factorization; more iterations).  B_D = (B Δ Bᵀ)⁻¹ B Δ with Δ_b = 1/diag(K_b)
    on the traces (stiffness scaling: the stiffer block takes the larger share of a jump), so that
    B B_Dᵀ = I.  B Δ Bᵀ couples only the multipliers of one trace entry (at most three), so its inverse is a
    batch of 3×3 inverses.
    """

    def __init__(self, rounds: Rounds, interface: Interface, sqrt_w: np.ndarray, lumped: bool = False):
        self.stiffness = rounds.lumped if lumped else rounds.dirichlet
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
        forces = self.stiffness(traces.T).T
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


def polynomial_directions(interface: Interface, degree: int) -> np.ndarray:
    """Directions ``(size, m)`` of the dual (y = W^½ λ) whose multipliers are the polynomials of degree ≤ ``degree``
    in the nodes' coordinates (:attr:`Interface.points`), joint by joint (the rows between one pair of blocks) and
    component by component, on the rows without bounds (a contact or friction row takes none): the smooth forces
    between the blocks (a stack's bending), which the preconditioned iterations find last.  Each joint's and
    component's columns are orthonormal, its dependent monomials dropped (a plane joint's normal coordinate)."""
    if degree == 0 or interface.points is None:
        return np.zeros((interface.size, 0))
    sqrt_w = np.sqrt(interface.row_weights)
    unbounded = ~(interface.is_contact | interface.is_friction)
    pairs = np.sort(interface.row_blocks, axis=1)
    dim = interface.points.shape[1]
    powers = [p for p in itertools.product(range(degree + 1), repeat=dim) if sum(p) <= degree]
    columns = []
    for pair in np.unique(pairs[unbounded], axis=0):
        joint = unbounded & (pairs == pair).all(axis=1)
        for component in range(interface.components):
            rows = np.flatnonzero(joint & (interface.component == component))
            if not len(rows):
                continue
            at = interface.points[interface.vertex[rows]]
            at = (at - at.mean(axis=0)) / max(float(np.ptp(at, axis=0).max()), np.finfo(float).tiny)
            values = sqrt_w[rows, None] * np.column_stack([np.prod(at ** np.array(p), axis=1) for p in powers])
            basis, singular, _ = np.linalg.svd(values, full_matrices=False)
            kept = basis[:, singular > 1e-8 * singular[0]]
            block = np.zeros((interface.size, kept.shape[1]))
            block[rows] = kept
            columns.append(block)
    return np.hstack(columns) if columns else np.zeros((interface.size, 0))


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
        self.seeds = 0  # the first directions, kept through every rebase (:meth:`seed`)
        self._rows = np.zeros((2, 8, len(y)))  # [V, AV] transposed, a direction a row; grown by doubling
        self.size = 0
        self.rebase(y, g)

    @property
    def V(self) -> np.ndarray:
        return self._rows[0, :self.size].T

    @property
    def AV(self) -> np.ndarray:
        return self._rows[1, :self.size].T

    def rebase(self, y: np.ndarray, g: np.ndarray) -> None:
        """A new subspace from y (gradient g): the seeds only."""
        self.y0, self.g0 = y, g
        self.size = self.seeds
        # the unbounded minimizer: its coefficients −Vᵀg₀ (V is A-orthonormal), y and A y − b, kept as V grows
        self._f = -(self.V.T @ g)
        self._free_y, self._free_g = y + self.V @ self._f, g + self.AV @ self._f

    def _append(self, v: np.ndarray, Av: np.ndarray) -> None:
        """Appends the columns of ``v`` and ``Av`` ``(size, m)`` to V and A V."""
        count = v.shape[1]
        if self.size + count > self._rows.shape[1]:
            grown = np.zeros((2, max(2 * self._rows.shape[1], self.size + count), self._rows.shape[2]))
            grown[:, :self.size] = self._rows[:, :self.size]
            self._rows = grown
        self._rows[0, self.size:self.size + count] = v.T
        self._rows[1, self.size:self.size + count] = Av.T
        self.size += count
        f = -(v.T @ self.g0)
        self._f = np.concatenate([self._f, f])
        self._free_y += v @ f
        self._free_g += Av @ f

    def seed(self, Z: np.ndarray) -> int:
        """Puts the directions ``Z`` ``(size, m)`` (on the constraint) first in the subspace and keeps them through
        every :meth:`rebase`: A Z in one round, A-orthonormalized by the eigenvectors of Zᵀ A Z (the directions A
        barely sees dropped).  Returns the directions kept."""
        AZ = self.problem.apply_many(Z)
        values, vectors = np.linalg.eigh(0.5 * (Z.T @ AZ + AZ.T @ Z))
        kept = values > INDEPENDENT ** 0.5 * values.max(initial=0.0)
        scale = vectors[:, kept] / np.sqrt(values[kept])
        self.seeds = 0
        self.rebase(self.y0, self.g0)
        self._append(Z @ scale, AZ @ scale)
        self.seeds = self.size
        self.capacity += self.seeds
        return self.seeds

    def add(self, z: np.ndarray) -> bool:
        """Appends direction z, A-orthogonalized (one round); False when it adds nothing new."""
        if self.size >= self.capacity:
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
        self._append(z[:, None] / np.sqrt(norm), q[:, None] / np.sqrt(norm))
        return True

    def minimizer(self, constrained: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The minimizer y over the subspace within the bounds of the ``constrained`` rows, and A y − b."""
        lower, upper, b = self.problem.lower, self.problem.upper, constrained
        c, at_low, at_high = nearest_within(self._f, self.V[b], lower[b] - self.y0[b], upper[b] - self.y0[b])
        if not (at_low.any() or at_high.any()):  # no bound holds it: the unbounded minimizer
            return self._free_y.copy(), self._free_g.copy()
        y, g = self.y0 + self.V @ c, self.g0 + self.AV @ c
        held = y[b]
        held[at_low], held[at_high] = lower[b][at_low], upper[b][at_high]  # exactly, not to round-off
        y[b] = held
        return y, g

    def holding(self, held: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The minimizer over the subspace with the ``held`` rows kept at their values in ``y`` and the
        others unbounded (an active-set step), and A y − b."""
        f = self._f
        c = f + np.linalg.lstsq(self.V[held], y[held] - self.y0[held] - self.V[held] @ f, rcond=None)[0]
        new, g = self.y0 + self.V @ c, self.g0 + self.AV @ c
        new[held] = y[held]
        return new, g

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
    preconditioner (or the lumped one, ``solver.preconditioner``) on the free multipliers, with the bounds enforced
    on the whole subspace.

    Each iteration adds one direction: the preconditioned projected gradient on the free rows and on the
    rows at a bound pulled off it hardest (:func:`released`), projected by the coarse space of the
    floating blocks.  The iterate is the minimizer over the span of all directions so far within the
    bounds (a dense least-distance problem of the basis' size on rank 0), so the Krylov space survives
    every change of the active set.  Where the minimizer with only the held rows bounded leaves the
    bounds, an expansion step adds its projection onto them as a direction: the rows it crosses are held
    together, not one per iteration.  An iteration takes two rounds (the Dirichlet solves, then A z; one with
    the lumped preconditioner), an expansion one more.  Where rows are held and released in turn (a long zone of
    crack faces pressed together whose early iterates dip below zero: more reversals than :data:`FLICKER` × the bounded rows),
    the iterations go on as active-set steps on a new subspace (:meth:`Iterations.steps`).  Converged:
    the KKT criterion (the projected gradient of the Lagrangian) is below ``tol``.  ``start``: the
    multipliers to start from (0 by default: the crack faces free), moved onto the bounds and the coarse
    constraint Gᵀy = e.
    """
    problem = DualProblem(rounds, interface, solver)
    precondition = Preconditioner(rounds, interface, problem.sqrt_w, lumped=solver.preconditioner == "lumped")
    coarse = Coarse(rounds, interface, problem.sqrt_w)
    degree = 0 if solver.coarse_degree == "auto" else solver.coarse_degree
    outcome, free = minimize(problem, coarse, precondition, progress, start, polynomial_directions(interface, degree))
    outcome.held = coarse.held(interface, outcome.lam, problem.sqrt_w, free)
    return outcome


#: ``feti`` leaves its bounded iterations for active-set steps once the rows that change set and change
#: back in the next iteration outnumber this share of the bounded rows
FLICKER = 0.5

#: iterations without halving the criterion after which ``feti`` computes its gradient afresh
STAGNATION = 10


class Iterations:
    """:func:`feti`'s iterations: the problem, its preconditioner and coarse space, the subspace of the
    directions so far, the iterate and the outcome."""

    def __init__(self, problem: DualProblem, coarse: Coarse, precondition: Callable[[np.ndarray], np.ndarray],
                 progress: Progress, start: np.ndarray | None, capacity: int = 400):
        self.problem, self.coarse, self.precondition, self.progress = problem, coarse, precondition, progress
        self.lower, self.upper, self.solver = problem.lower, problem.upper, problem.solver
        self.y = coarse.inside(problem.start(start), self.lower, self.upper)
        self.g = problem.apply(self.y) - problem.b if np.any(self.y) else -problem.b
        self.space = Subspace(problem, self.y, self.g, capacity, lambda v: coarse.project(v, v != 0.0))
        self.outcome = Outcome(self.y, converged=False, iterations=0)
        self.expansions = self.reversals = 0
        self.step_iterations: list[int] = []  # the iteration each active-set step started at

    def seed(self, Z: np.ndarray) -> None:
        """The directions ``Z`` put first in the subspace (one round).  The iterate stays where it starts: the
        next direction's minimizer takes them in, and starting at their own minimizer (the bounded rows left where
        it puts them) let the penny's contact rows flicker into the active-set steps (10 iterations without the
        directions, 33 with that start, 11 now)."""
        Z = self.coarse.project(Z, np.ones(len(Z), dtype=bool))  # onto Gᵀz = 0
        self.outcome.details["coarse_directions"] = self.space.seed(Z)

    def free(self) -> np.ndarray:
        return (self.y > self.lower) & (self.y < self.upper)

    def pulled(self, gradient: np.ndarray) -> np.ndarray:
        """The rows at a bound that ``gradient`` pulls off it."""
        return ((self.y <= self.lower) & (gradient < 0)) | ((self.y >= self.upper) & (gradient > 0))

    def held(self) -> np.ndarray:
        """The rows at a bound that the gradient of the Lagrangian keeps there."""
        free = self.free()
        return ~free & ~self.pulled(self.coarse.residual(self.g, free))

    def record(self, criterion: float, changed: np.ndarray) -> None:
        self.outcome.iterations += 1
        self.outcome.history.append(criterion)
        self.outcome.active_set_changes.append(int(np.count_nonzero(changed)))
        self.progress(self.outcome.iterations, criterion)

    def replace_residual(self) -> None:
        """A y − b afresh (one round) and a new subspace from y: the sums g₀ + A V c carry round-off that
        stops the criterion some way above 1e-11 once the basis is long."""
        self.g = self.problem.apply(self.y) - self.problem.b
        self.space.rebase(self.y, self.g)
        self.space.restarts += 1

    def out_of_iterations(self) -> bool:
        return self.outcome.iterations >= self.solver.max_iterations

    def bounded(self) -> bool:
        """Iterations on the whole subspace within the bounds; True when they ended on the flicker rule."""
        lower, upper, space, coarse = self.lower, self.upper, self.space, self.coarse
        previous, started, best, since = np.zeros(len(lower), dtype=bool), False, np.inf, 0
        while True:
            free = self.free()
            gradient = coarse.residual(self.g, free)  # the Lagrangian's: less its part carried by rigid motions
            criterion = self.problem.criterion(self.y, gradient)
            if started:
                self.record(criterion, previous)
            started = True
            if not criterion >= self.solver.tol or self.out_of_iterations():
                self.outcome.converged = criterion < self.solver.tol
                return False
            if self.reversals > FLICKER * np.count_nonzero(space.bounded):
                return True
            if criterion < 0.5 * best:
                best, since = criterion, 0
            elif since >= STAGNATION:
                self.replace_residual()
                best, since = criterion, 0
            since += 1
            projected = projected_gradient(self.y, gradient, lower, upper)
            face = free | released(projected, free)
            if not (space.add(inward(coarse, self.precondition(-projected), self.y, face, lower, upper))
                    or space.add(inward(coarse, -projected, self.y, face, lower, upper))):
                self.outcome.message = (f"feti: no new direction at iteration {self.outcome.iterations} "
                                        f"(criterion {criterion:.3e}, tol {self.solver.tol:g})")
                return False
            unheld, _ = space.minimizer(space.bounded & ~free)
            if np.any(unheld < lower) or np.any(unheld > upper):  # expansion
                space.add(coarse.inside(unheld, lower, upper) - unheld)
                self.expansions += 1
            self.y, self.g = space.point()
            changed = free != self.free()
            self.reversals += int(np.count_nonzero(changed & previous))
            previous = changed

    def steps(self) -> None:
        """Active-set steps on the same subspace: CG on the free rows, the held ones fixed and the others
        unbounded, to a tenth of the smaller of its starting residual and the KKT residual reached (once the
        sets repeat, to ``tol``); then the rows past a bound held, the minimizer within all bounds taken,
        and its rows at a bound held in the next step, until the sets repeat and the criterion meets tol."""
        lower, upper, space, coarse, problem = self.lower, self.upper, self.space, self.coarse, self.problem
        scale = max(problem.scale, np.finfo(float).tiny)
        space.rebase(self.y, self.g)  # the bounded iterations' directions, each a row held and released in turn
        held, reached, settled = self.held(), np.inf, False
        unchanged = np.zeros(len(lower), dtype=bool)
        while not self.out_of_iterations():
            free = ~held
            r = -coarse.project(np.where(free, self.g, 0.0), free)
            if not np.isfinite(r).all():
                return
            self.step_iterations.append(self.outcome.iterations)
            goal = self.solver.tol * scale if settled else max(self.solver.tol * scale,
                                                                 0.1 * min(np.linalg.norm(r), reached))
            while np.linalg.norm(r) > goal and not self.out_of_iterations():
                if not space.add(coarse.project(np.where(free, self.precondition(r), 0.0), free)):
                    self.outcome.message = f"feti: no new direction at iteration {self.outcome.iterations}"
                    return
                self.y, self.g = space.holding(held, self.y)
                r = -coarse.project(np.where(free, self.g, 0.0), free)
                self.record(problem.criterion(np.clip(self.y, lower, upper), coarse.residual(self.g, free)), unchanged)
            gradient = coarse.residual(self.g, free)
            reached = min(reached, float(np.linalg.norm(self.y - np.clip(self.y - gradient, lower, upper))))
            new_held = (held & ~self.pulled(gradient)) | (free & ((self.y < lower) | (self.y > upper)))
            if np.array_equal(new_held, held):
                if settled and problem.criterion(self.y, gradient) < self.solver.tol:
                    self.outcome.converged = True
                    return
                settled = True
                continue
            settled = False
            moved = coarse.feasible(np.where(new_held, np.clip(self.y, lower, upper), self.y), ~new_held)
            if np.any(moved != self.y):
                space.add(moved - self.y)
            self.y, self.g = space.point()
            held = self.held()


def minimize(problem: DualProblem, coarse: Coarse, precondition: Callable[[np.ndarray], np.ndarray],
             progress: Progress, start: np.ndarray | None = None,
             seeds: np.ndarray | None = None) -> tuple[Outcome, np.ndarray]:
    """:func:`feti`'s iterations, their subspace starting from the directions ``seeds`` ``(size, m)`` (kept through
    restarts); returns the outcome and the free rows of its multipliers."""
    run = Iterations(problem, coarse, precondition, progress, start)
    if seeds is not None and seeds.shape[1]:
        run.seed(seeds)
    if run.bounded():
        run.steps()
    outcome = run.outcome
    final = outcome.history[-1] if outcome.history else 0.0
    if not np.isfinite(final):
        outcome.message, outcome.diverged = f"feti broke down at iteration {outcome.iterations}", True
    elif not outcome.converged and not outcome.message:
        outcome.message = no_convergence("feti", problem.solver, outcome.history)
    progress(outcome.iterations, final, final=True)
    outcome.lam = problem.multipliers(run.y)
    free = run.free()
    starts = run.step_iterations + [outcome.iterations]
    outcome.details.update(expansions=run.expansions, restarts=run.space.restarts,
                           bounded_iterations=starts[0], active_set_steps=len(run.step_iterations),
                           step_iterations=np.diff(starts).astype(np.int64), held_rows=int(np.count_nonzero(~free)),
                           set_changes=int(sum(outcome.active_set_changes)))
    return outcome, free
