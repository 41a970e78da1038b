"""Critical load factors with a fixed temperature change: per tip the smallest λ ≥ 0 at which G = G_c when
every mechanical load and prescribed displacement is scaled by λ (:meth:`ddsolve.problem.scene.Scene.scaled`)
and the temperature change is kept.

Without a temperature change G(λ) = λ²G(1) and the factor is √(G_c/G(1)) (:func:`ddsolve.post.toughness.
critical_factor`, no extra solve).  With one, the fields are u_T + λu_M while the contact set does not
change, so G, G_I and G_II are quadratics in λ: the solves at λ = 0, 1 and 2 give them, the first root of
G(λ) = G_c(ψ(λ)) of that model is the first guess, and a solve there checks it.  Where the contact set
changes, the root is refined in a bracket [λ_lo, λ_hi] with G < G_c at λ_lo (and every solve below it) and
G ≥ G_c at λ_hi, by the root of the quadratic through the nearest solves, or by bisection when the bracket
does not halve, until |G/G_c − 1| ≤ ``TOLERANCE`` (or, for a G_c far below the G of the temperature
change, to what a solve resolves of G: :func:`resolved`), or until the bracket is narrower than
``RESOLUTION`` × λ (G jumps there, or its noise exceeds TOLERANCE × G_c): its upper end.  A tip with G ≥ G_c at λ = 0 grows under the temperature
change alone: factor 0; a tip that does not reach G_c below ``MAX_FACTOR``: inf.  Every solve gives G at
every tip, so tips share them.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ddsolve.errors import DDSolveError, SolverError
from ddsolve.mesh.mesh import Mesh
from ddsolve.post import toughness
from ddsolve.post.result import RELEASE, Fracture, Result
from ddsolve.problem.scene import Scene
from ddsolve.solvers import driver

#: |G/G_c − 1| at the critical load factor.
TOLERANCE = 1e-8
#: The largest load factor searched: a tip below G_c there does not grow (factor inf).
MAX_FACTOR = 1e6
#: A bracket this narrow (relative to λ) gives the factor: its upper end, the first λ known with G ≥ G_c.
#: There G jumps over G_c (the contact set changes) or the noise of G is above TOLERANCE × G_c (a G_c far
#: below the G of other tips); λ itself is then known to this resolution.
RESOLUTION = 1e-9
#: The most solves the search of one tip may add.
MAX_SOLVES = 40
#: Points of the grid on which the first sign change of a quadratic model is looked for.
GRID = 2000


def needed(scene: Scene) -> bool:
    """Whether the scene's critical load factors need the root solve (a toughness, and a solution not proportional
    to the loads: a temperature change, a Tresca bound)."""
    return toughness.given(scene) and not scene.proportional


def excess(scene: Scene, fracture: Fracture) -> np.ndarray:
    """G/G_c − 1 at every tip of ``fracture`` (−1 where G ≤ 0: the tip is not loaded towards growth)."""
    return _excess(fracture.G, toughness.resistance(scene, fracture))


def _excess(G: np.ndarray, G_c: np.ndarray) -> np.ndarray:
    positive = G > 0
    return np.where(positive, G / np.where(positive, G_c, 1.0) - 1.0, -1.0)


def search(scene: Scene, evaluate: Callable[[float], Fracture], progress: Callable[[str], None] | None = None
           ) -> np.ndarray:
    """The critical load factor of every tip (one process), ``evaluate(λ)`` giving the fracture of the
    solve of ``scene.scaled(λ)``; ``progress`` hears the number of solves and the tips without a root."""
    found: dict[float, Fracture] = {}

    def at(lam: float) -> Fracture:
        if lam not in found:
            found[lam] = evaluate(lam)
        return found[lam]

    for lam in (0.0, 1.0, 2.0):
        at(lam)
    factors = np.array([_tip_factor(scene, tip, found, at) for tip in range(len(found[1.0].G))])
    if progress is not None:
        progress(f"critical load factors with the temperature change kept: {len(found)} solves of the scaled scene")
        for tip in np.flatnonzero(np.isinf(factors)):
            x, y = found[1.0].points[tip]
            progress(f"tip ({x:.6g}, {y:.6g}): G stays below G_c up to λ = {MAX_FACTOR:g}: it does not grow "
                     "under this loading (critical load factor inf)")
    return factors


def _model(scene: Scene, tip: int, points: list[tuple[float, Fracture]]) -> Callable[[np.ndarray], np.ndarray]:
    """G/G_c − 1 of ``tip`` as a function of λ, from the quadratics in λ of G, G_I and G_II through three
    solves ``points`` (the phase angle from G_I and G_II: the laws depend on |ψ| only)."""
    lams = [lam for lam, _ in points]
    fits = {name: _quadratic(lams, [getattr(fracture, name)[tip] for _, fracture in points])
            for name in ("G", "G_I", "G_II")}
    crack = points[0][1].crack[tip]

    def modelled(values: np.ndarray) -> np.ndarray:
        G, G_I, G_II = (fits[name](values) for name in ("G", "G_I", "G_II"))
        phase = np.degrees(np.arctan2(np.sqrt(np.maximum(G_II, 0.0)), np.sqrt(np.maximum(G_I, 0.0))))
        return _excess(G, toughness.law(scene.fracture, np.full(np.shape(values), crack), G, G_II, phase))

    return modelled


def _quadratic(x: list[float], y: list[float]) -> Callable[[np.ndarray], np.ndarray]:
    """The quadratic through three points (x distinct), in Newton's form (divided differences)."""
    first = [(y[1] - y[0]) / (x[1] - x[0]), (y[2] - y[1]) / (x[2] - x[1])]
    second = (first[1] - first[0]) / (x[2] - x[0])
    return lambda values: y[0] + (values - x[0]) * (first[0] + (values - x[1]) * second)


def _first_root(model: Callable[[np.ndarray], np.ndarray], grid: np.ndarray) -> float | None:
    """The first λ of ``grid``'s range where ``model`` turns from negative to non-negative, by bisection
    between the grid points around it; None if it stays negative (or is NaN)."""
    values = model(grid)
    turns = np.flatnonzero((values[:-1] < 0) & (values[1:] >= 0))
    if turns.size == 0:
        return None
    lo, hi = grid[turns[0]], grid[turns[0] + 1]
    for _ in range(200):
        middle = 0.5 * (lo + hi)
        if not lo < middle < hi:
            break
        lo, hi = (middle, hi) if model(np.array([middle]))[0] < 0 else (lo, middle)
    return float(hi)


def resolved(scene: Scene, found: dict[float, Fracture], lam: float, tip: int) -> bool:
    """Whether the solve at ``lam`` puts G at ``tip`` at G_c: |G/G_c − 1| ≤ ``TOLERANCE``, or, where G_c is
    far below the tip's G of the temperature change alone (λ = 0) or at ``lam``, |G − G_c| within the part
    of them a solve does not resolve (:data:`ddsolve.post.result.RELEASE`, what a result calls G ≈ 0): the
    root is not sought below the noise of G, which would never settle it."""
    G_c = float(toughness.resistance(scene, found[lam])[tip])
    G = float(found[lam].G[tip])
    scale = max(abs(float(found[0.0].G[tip])), abs(G))
    return G > 0 and abs(G - G_c) <= max(TOLERANCE * G_c, RELEASE * scale)


def _tip_factor(scene: Scene, tip: int, found: dict[float, Fracture], at: Callable[[float], Fracture]) -> float:
    """The critical load factor of one tip, solving at new load factors (``at``) until it is found: the
    root of the quadratic model through the three solves nearest to the bracket (or, before there is one,
    the three largest load factors, else four times the largest), bisection where the bracket does not halve."""
    widths = []
    for _ in range(MAX_SOLVES + 1):
        lams = np.array(sorted(found))
        values = np.array([excess(scene, found[lam])[tip] for lam in lams])
        if np.isnan(values).any():
            return np.nan
        if values[0] >= 0:  # λ = 0: G ≥ G_c under the temperature change alone
            return 0.0
        above = np.flatnonzero(values >= 0)
        close = np.flatnonzero([resolved(scene, found, lam, tip) for lam in lams])
        if close.size and (above.size == 0 or close[0] <= above[0]):
            return float(lams[close[0]])
        if above.size:
            lo, hi = lams[above[0] - 1], lams[above[0]]
            widths.append(hi - lo)
            if hi - lo <= RESOLUTION * hi:  # G jumps over G_c here, or its noise is above TOLERANCE × G_c
                return float(hi)
            nearest = sorted(lams, key=lambda lam: max(lo - lam, lam - hi, 0.0))[:3]
            trial = None
            if len(widths) < 3 or widths[-1] <= 0.5 * widths[-3]:
                trial = _first_root(_model(scene, tip, [(lam, found[lam]) for lam in nearest]),
                                    np.linspace(lo, hi, GRID))
            if trial is None or not lo < trial < hi:
                trial = 0.5 * (lo + hi)
        else:
            lo = lams[-1]
            if lo >= MAX_FACTOR:
                return np.inf
            trial = _first_root(_model(scene, tip, [(lam, found[lam]) for lam in lams[-3:]]),
                                np.geomspace(lo, MAX_FACTOR, GRID))
            trial = min(4.0 * lo if trial is None or trial <= lo else trial, MAX_FACTOR)
        at(float(trial))
    raise SolverError(f"critical load factor: no λ with |G/G_c − 1| ≤ {TOLERANCE:g} at tip {tip} in {MAX_SOLVES} "
                      "solves")


def roots(scene: Scene, comm, solve: Callable[[Scene], Result | None],
          progress: Callable[[str], None] | None = None) -> np.ndarray:
    """:func:`search` on every rank of ``comm``: ``solve(scaled scene)`` runs on every rank with the result on
    rank 0, which decides the load factors and broadcasts them; the factors on every rank.  A failed solve
    raises on every rank (as the solve does); a search that fails on rank 0 raises there and on every rank."""
    outcome = None
    if comm.rank == 0:
        def evaluate(lam: float) -> Fracture:
            comm.bcast(lam, root=0)
            return solve(scene.scaled(lam)).fracture

        try:
            outcome = search(scene, evaluate, progress)
        except DDSolveError as exc:
            if getattr(exc, "collective", False):  # a solve failed: every rank raises it
                raise
            outcome = exc
        comm.bcast(None, root=0)  # the other ranks stop solving
    else:
        while (lam := comm.bcast(None, root=0)) is not None:
            solve(scene.scaled(lam))
    outcome = comm.bcast(outcome, root=0)
    if isinstance(outcome, DDSolveError):
        outcome.collective = True
        raise outcome
    return outcome


def factors(scene: Scene, comm, mesh: Mesh, progress: Callable[[str], None] | None = None,
            setup: driver.Setup | None = None) -> np.ndarray:
    """The critical load factors of ``scene``'s tips on every rank of ``comm`` (rank 0 decides, the result is
    broadcast), each evaluation a domain-decomposition solve of ``scene.scaled(λ)`` on the whole ``mesh``
    (on every rank), the blocks assembled and factored once: here, or given as ``setup`` (from
    :func:`ddsolve.solvers.driver.prepare` with the whole ``mesh``; kept, with the last solve's loads)."""
    own = setup is None
    if own:
        setup = driver.prepare(scene, comm, mesh)
    try:
        def solve(scaled: Scene) -> Result | None:
            driver.reload(setup, scaled)
            return driver.solve_decomposed(scaled, comm, None, progress=_quiet, setup=setup)

        return roots(scene, comm, solve, progress)
    finally:
        if own:
            setup.destroy()


def _quiet(_line: str) -> None:
    pass
