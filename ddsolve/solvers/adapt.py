"""Adaptive refinement to a target error (``mesh.target_error``): solve, estimate, refine the mesh, solve.

Level 0 is the scene's mesh (:func:`ddsolve.parallel.distribution.build_mesh`).  While the estimate is
above the target, rank 0 refines the present mesh by newest-vertex bisection
(:mod:`ddsolve.mesh.bisection`, new boundary vertices on the geometry's curves, :mod:`ddsolve.mesh.curves`)
and broadcasts it; every level is an ordinary domain-decomposition solve
(:func:`ddsolve.solvers.driver.solve_decomposed`) with its error estimate.

The marking aims at the target in one step (:func:`plan`): bisecting a cell multiplies its share of η²
by 2^-p for degree p (each child carries 2^-(p+1): η_K² ∝ h_K^(2p+2) where the solution is smooth), and
the child that keeps a singular vertex (crack tips, ends of Σ, clamped meeting free boundary, re-entrant
corners) carries 2^-½ of its parent's (η_K² ∝ h_K for an r^½ singularity).  Cells whose predicted η_K²
is above a threshold τ² are bisected, their children predicted, again, until none is; τ² starts above
every cell's and is lowered in steps until the predicted η² is below (target / ``SAFETY``)², so that
the mesh is refined no further than the target needs.  The result is a mesh with the error
equidistributed, graded towards the singular points, that reaches the target in one refinement as a
rule (two at most).

What cannot finish is not started: after every level the unknowns the target needs are predicted at
the best rate adaptive meshes reach, error ∝ N^(−degree/2) (:func:`needed_unknowns`); if they exceed
what a level may have on this machine (:func:`largest_level`), the first level refuses the target at
once (nothing written) and a later one stops there; no level is solved whose mesh would exceed it.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ddsolve.errors import DDSolveError, NotConvergedError
from ddsolve.io import hdf5
from ddsolve.mesh import bisection, curves
from ddsolve.mesh.mesh import SIGMA, Mesh, signed_areas
from ddsolve.parallel import distribution
from ddsolve.parallel.exchange import collective
from ddsolve.parallel.phases import launch_age
from ddsolve.post import toughness
from ddsolve.post.result import Result
from ddsolve.problem.scene import Scene
from ddsolve.solvers import critical, driver

#: Levels (solves) before giving up; the marking aims at reaching the target within three.
MAX_LEVELS = 5
#: Unknowns above which the next level is not attempted (memory; fewer if this machine holds fewer,
#: see :func:`largest_level`).
MAX_UNKNOWNS = 4_000_000
#: The target is refused (first level) or given up (later levels) when the predicted unknowns exceed
#: the largest level by this factor: before their asymptotic rate, adaptive meshes converge a little
#: faster (Example 1, P1: N^-0.64 from the first level to the second, N^-0.51 over twelve levels).
PREDICTION_MARGIN = 2.0
#: The refined mesh aims at the target divided by this (the prediction is a model).
SAFETY = 1.3
#: The exponent λ of the singular points' r^λ: the child of a bisection that keeps a singular vertex carries
#: 2^-λ of its parent's η_K² (measured: the other child as if the solution were smooth there).
SINGULAR_EXPONENT = 0.5
#: Cells are not marked below this size (square root of the area), relative to the geometry's size: as
#: small as gmsh's graded meshes go (ddsolve.mesh.sizing.SMALLEST), well above rounding.
SMALLEST = 3e-7
#: Bisection sweeps of one refinement at most (a cell at a singular vertex needs two per factor 2 of η_K²).
MAX_SWEEPS = 400
#: Columns of the level table (``/levels`` in the result file).
LEVEL_COLUMNS = ("unknowns", "cells", "error_estimate", "energy", "mesh_time", "solve_time", "level_time", "elapsed")


def unknowns(mesh: Mesh, layers: int = 2) -> int:
    """Displacement unknowns of the blocks of a structure of ``layers`` layers (two per node, each half once per
    layer)."""
    return 2 * layers * (len(mesh.lower.points) + len(mesh.upper.points))


def largest_level(ranks: int) -> int:
    """The most unknowns a level may have on ``ranks`` ranks: MAX_UNKNOWNS, or fewer if this machine's
    memory holds fewer (:func:`ddsolve.cli.nodes_in_memory`; four unknowns per mesh node)."""
    from ddsolve.solvers.checks import nodes_in_memory

    return int(min(MAX_UNKNOWNS, 4 * nodes_in_memory(ranks)))


def needed_unknowns(count: int, estimate: float, target: float, degree: int) -> float:
    """The unknowns a mesh of ``count`` unknowns with estimated error ``estimate`` needs for ``target``
    at the best rate of adaptive meshes, error ∝ N^(−degree/2) (P1: N^-½, P2: N^-1; docs/accuracy.md)."""
    return count * (estimate / target) ** (2.0 / degree)


def _silent(_line: str) -> None:
    pass


def solve_adaptively(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, level=None) -> Result | None:
    """Refine until the estimated relative energy-norm error is at most ``scene.mesh.target_error``.

    ``level(mesh, scene, refined_next)`` solves one level (on every rank; the result on rank 0): by default
    the domain decomposition (:func:`ddsolve.solvers.driver.solve_decomposed`, which asks ``refined_next`` for the
    decision after the level, :class:`NextLevel`, as soon as the estimate is known, and leaves out G, its
    modes and the reactions of a level that is refined next); ``reference`` passes the monolithic solve.  Prints a
    line per level on rank 0 (via ``progress``); writes the last level's result with the level table and, for
    a scene with a toughness and a temperature change, the critical load factors found on the last mesh
    by solves of the scaled scene (by default on blocks factored once, :func:`ddsolve.solvers.critical.factors`;
    else by ``level``, :func:`ddsolve.solvers.critical.roots`), timed as ``critical_factors``.
    Returns the result on rank 0 (None elsewhere).  Raises DDSolveError on every rank after the first
    level, nothing written, if the target needs more unknowns than a level may have
    (:func:`largest_level`); NotConvergedError on every rank (after writing the last result) if it is
    not reached within ``MAX_LEVELS`` levels or that many unknowns.  The error holds the last result
    as ``result`` on rank 0.
    """
    target = scene.mesh.target_error
    decomposed = level is None
    if decomposed:
        def level(mesh: Mesh, solved: Scene, refined_next: Callable[[Result], bool] | None) -> Result | None:
            return driver.solve_decomposed(solved, comm, None, progress=_silent, mesh=mesh, refined_next=refined_next)
    project = curves.projector(scene)
    startup, started = launch_age(), time.perf_counter()
    refined, rows, result, message, refining = None, [], None, "", 0.0
    for number in range(MAX_LEVELS):
        mark = time.perf_counter()
        mesh = distribution.build_mesh(scene, comm) if number == 0 else comm.bcast(refined, root=0)
        meshing = time.perf_counter() - mark + refining
        step = NextLevel(target, number, project)
        result = level(mesh, scene, step.refined_next)
        if comm.rank == 0:
            estimate = float(result.attrs["error_estimate"])
            rows.append({"unknowns": unknowns(mesh, scene.geometry.layers),
                         "cells": len(mesh.lower.cells) + len(mesh.upper.cells),
                         "error_estimate": estimate, "energy": float(result.attrs.get("energy", np.nan)),
                         "mesh_time": meshing, "solve_time": result.wall_time,
                         "level_time": time.perf_counter() - mark + refining - step.seconds,
                         "elapsed": time.perf_counter() - started})
            progress(f"level {number}: {rows[-1]['unknowns']:,} unknowns, estimated error {100 * estimate:.3g} %, "
                     f"{rows[-1]['level_time']:.2f} s (mesh {meshing:.2f} s, solve {result.wall_time:.2f} s)")
        mark = time.perf_counter()
        decision = collective(comm, lambda: step.taken(result), root_only=True)
        done, message = comm.bcast(decision[0::2] if comm.rank == 0 else None, root=0)
        refined = decision[1] if comm.rank == 0 else None
        refining = time.perf_counter() - mark + step.seconds  # the refinement: the next level's meshing
        if done:
            break
    if critical.needed(scene):
        searched = time.perf_counter()
        found = critical.factors(scene, comm, mesh, progress) if decomposed else critical.roots(
            scene, comm, lambda scaled: level(mesh, scaled, None), progress)
        if comm.rank == 0:
            result.timings["critical_factors"] = time.perf_counter() - searched
            if result.fracture is not None:
                toughness.judge(result.fracture, scene, found)
    if comm.rank == 0:
        result.levels = {column: np.array([row[column] for row in rows]) for column in LEVEL_COLUMNS}
        result.attrs.update({"target_error": target, "levels": len(rows)})
        result.timings["adaptive"] = time.perf_counter() - started
        result.timings["startup"] = startup  # the levels' own phases start at 0
    if output is not None:
        written = time.perf_counter()
        collective(comm, lambda: hdf5.write(output, result, final=True), root_only=True)
        if result is not None:
            result.timings["write"] = time.perf_counter() - written
    if message:
        raise NotConvergedError.collective_with(message, result)
    return result


class NextLevel:
    """Rank 0's decision after a level (:func:`next_level`), taken inside the level's solve as soon as its
    estimate and indicators are known (:meth:`refined_next`), so that a level refined next leaves out G,
    its modes and the reactions; or after the solve, for a level that does not ask (:meth:`taken`)."""

    def __init__(self, target: float, level: int, project: bisection.Projector | None):
        self.target, self.level, self.project = target, level, project
        self.decision: tuple | None = None
        self.error: DDSolveError | None = None
        self.seconds = 0.0  # spent deciding inside the solve

    def refined_next(self, result: Result) -> bool:
        """Decide now (rank 0, ``result`` without G yet); whether the level is refined next.  A refusal is
        kept for :meth:`taken` to raise on every rank (the solve goes on as for a last level)."""
        started = time.perf_counter()
        try:
            self.decision = next_level(result, self.target, self.level, self.project)
        except DDSolveError as exc:
            self.error = exc
        self.seconds = time.perf_counter() - started
        return self.decision is not None and not self.decision[0]

    def taken(self, result: Result) -> tuple[bool, Mesh | None, str]:
        """The decision (rank 0): the one taken inside the solve (its refusal raised), else taken now."""
        if self.error is not None:
            raise self.error
        return self.decision if self.decision is not None else next_level(result, self.target, self.level,
                                                                           self.project)


def next_level(result: Result, target: float, level: int, project: bisection.Projector | None = None
               ) -> tuple[bool, Mesh | None, str]:
    """Rank 0's decision after a level: (stop, the next mesh, why the target was not reached).
    Raises DDSolveError after the first level if the target is out of reach."""
    estimate = float(result.attrs["error_estimate"])
    if estimate <= target:
        return True, None, ""
    count, degree, limit = result.unknowns, result.mesh.degree, largest_level(result.ranks)
    needed = needed_unknowns(count, estimate, target, degree)
    if needed > PREDICTION_MARGIN * limit:
        reach = estimate * (PREDICTION_MARGIN * limit / count) ** (-degree / 2.0)
        why = (f"it needs about {needed:.2g} unknowns (estimated error {100 * estimate:.3g} % with {count:,} "
               f"unknowns; at best the error falls as N^-{degree / 2.0:g} with P{degree}), more than {PREDICTION_MARGIN:g} "
               f"times the {limit:,} unknowns a level may have on this machine; the smallest target in reach is "
               f"about {reach:.2g}" + ("" if degree == 2 else " (mesh.degree = 2 reaches smaller ones)"))
        if level == 0:
            raise DDSolveError(f"mesh.target_error = {target:g} refused: {why}")
        return True, None, f"mesh.target_error = {target:g} not reached, and out of reach: {why}"
    if level + 1 == MAX_LEVELS:
        return True, None, (f"mesh.target_error = {target:g} not reached in {MAX_LEVELS} levels "
                            f"(estimated error {estimate:.3g})")
    planned, _ = plan(result.mesh, result.indicators, estimate, target, limit, longest_edge=level == 0)
    if planned_unknowns(planned) > limit:
        return True, None, (f"mesh.target_error = {target:g} not reached: the next mesh would have about "
                            f"{planned_unknowns(planned):,.0f} unknowns, more than the {limit:,} a level may "
                            f"have on this machine (estimated error {estimate:.3g}; raise mesh.degree or "
                            "mesh.target_error)")
    return False, bisection.to_mesh(planned, project), ""


def cell_indicators(mesh: Mesh, indicators: dict[str, np.ndarray]) -> np.ndarray:
    """η_K² per cell, the lower half's cells then the upper half's (the blocks of each half added: a block's name
    ends with its half, ``minus`` or ``plus``)."""
    return np.concatenate([sum(values ** 2 for name, values in indicators.items()
                               if name.endswith("minus") == (half.side < 0)) for half in mesh.halves])


def planned_unknowns(tri: bisection.Triangulation) -> float:
    """The unknowns of the mesh :func:`ddsolve.mesh.bisection.to_mesh` makes of ``tri``: four per node of
    each half, Σ's nodes in both (edges by Euler's formula for a domain without holes, E = V + F − 1)."""
    sigma = len(tri.boundaries[(-1, SIGMA)])
    if tri.degree == 1:
        return 4.0 * (len(tri.points) + sigma + 1)
    return 4.0 * (2 * len(tri.points) + len(tri.cells) - 1 + 2 * sigma + 1)


def plan(mesh: Mesh, indicators: dict[str, np.ndarray], estimate: float, target: float, limit: float,
         longest_edge: bool = True) -> tuple[bisection.Triangulation, float]:
    """The bisected triangulation whose predicted error is at most ``target`` / ``SAFETY`` (see the
    module's docstring), or the first one past ``limit`` unknowns, and its predicted relative error.
    ``estimate`` is the relative error the ``indicators`` (per block) add up to; ``longest_edge`` as in
    :func:`ddsolve.mesh.bisection.triangulation`.

    The threshold τ² starts above every cell's η_K² and is lowered in steps, each refinement carried on
    from the last, until the prediction is below the goal: so the plan stops at (about) the largest τ²
    that reaches it, not below.  A step lowers τ² by (goal / predicted)^((p+1)/p): with the error
    equidistributed, η² ∝ N^-p and τ² ∝ η²/N, so η² ∝ τ^(2p/(p+1))."""
    tri = bisection.triangulation(mesh, longest_edge)
    predicted = cell_indicators(mesh, indicators)
    present = predicted.sum()
    goal = present * (target / (SAFETY * estimate)) ** 2  # the target's η²: η² / estimate² = ‖u‖² + η²
    threshold, power = predicted.max(), (mesh.degree + 1.0) / mesh.degree
    area = signed_areas(tri.points, tri.cells)
    smallest = (SMALLEST * np.ptp(tri.points, axis=0).max()) ** 2
    for _ in range(MAX_SWEEPS):
        refinable = area > smallest
        marked = (predicted > threshold) & refinable
        if not marked.any():
            remaining = predicted[refinable].sum()  # the smallest cells' share is beyond refinement
            if remaining <= goal:
                break
            threshold *= (goal / remaining) ** power
            continue
        tri, parent, splits = bisection.bisect(tri, marked)
        rate = np.where(tri.singular[tri.cells].any(axis=1), SINGULAR_EXPONENT, mesh.degree + 1.0)
        predicted = predicted[parent] * 2.0 ** (-rate * splits)
        area = area[parent] * 2.0 ** -splits
        if planned_unknowns(tri) > limit:
            break
    return tri, estimate * np.sqrt(predicted.sum() / present)
