"""Adaptive refinement to a target error (``mesh.target_error``): solve, estimate, mark, re-mesh, repeat.

Each level is an ordinary domain-decomposition solve (:func:`ddsolve.solvers.driver.solve`) with its error
estimate.  While the estimate is above the target, rank 0 marks the cells that carry the largest
indicators (Dörfler marking: the fewest cells whose η_K² add up to ``DORFLER`` of η²), asks for
``REFINE`` × their size and the present size elsewhere, and gmsh meshes the geometry again with that
size field (:class:`ddsolve.mesh.sizing.SizeMap`, the previous mesh with sizes at its vertices; with
``mesh.grading`` the graded field still applies where it is finer).  The two halves are meshed from
the same size field, so their Σ nodes match.  What carries over from a level to the next: the scene,
the geometry's size field and the previous mesh (as the background of the next one).

What cannot finish is not started: after every level the unknowns the target needs are predicted at
the best rate adaptive meshes reach, error ∝ N^(−degree/2) (:func:`needed_unknowns`); if they exceed
what a level may have on this machine (:func:`largest_level`), the first level refuses the target at
once (nothing written) and a later one stops there; no level is built whose mesh would exceed it.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ddsolve.errors import DDSolveError, NotConvergedError
from ddsolve.io import hdf5 as io
from ddsolve.mesh.mesh import BLOCKS, Mesh
from ddsolve.mesh.sizing import SizeMap
from ddsolve.parallel import distribution
from ddsolve.parallel.exchange import collective
from ddsolve.post.result import Result
from ddsolve.problem.scene import Scene
from ddsolve.solvers import driver

#: Dörfler's bulk parameter θ: the marked cells carry at least this fraction of η².
DORFLER = 0.5
#: Marked cells are meshed again with this fraction of their size.
REFINE = 0.5
#: Levels before giving up.
MAX_LEVELS = 25
#: Unknowns above which the next level is not attempted (memory; fewer if this machine holds fewer,
#: see :func:`largest_level`).
MAX_UNKNOWNS = 4_000_000
#: The target is refused (first level) or given up (later levels) when the predicted unknowns exceed
#: the largest level by this factor: before their asymptotic rate, adaptive meshes converge a little
#: faster (Example 1, P1: N^-0.64 from the first level to the second, N^-0.51 over twelve levels).
PREDICTION_MARGIN = 2.0
#: Columns of the level table (``/levels`` in the result file).
LEVEL_COLUMNS = ("unknowns", "cells", "error_estimate", "energy", "mesh_time", "solve_time", "level_time", "elapsed")


def unknowns(mesh: Mesh) -> int:
    """Displacement unknowns of the four blocks (two per node, each half twice)."""
    return 4 * (len(mesh.lower.points) + len(mesh.upper.points))


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


def solve(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, level=None) -> Result | None:
    """Refine until the estimated relative energy-norm error is at most ``scene.mesh.target_error``.

    ``level(mesh)`` solves one level (on every rank; the result on rank 0): by default the domain
    decomposition (:func:`ddsolve.solvers.driver.solve`); ``reference`` passes the monolithic solve.  Prints a
    line per level on rank 0 (via ``progress``); writes the last level's result with the level table.
    Returns the result on rank 0 (None elsewhere).  Raises DDSolveError on every rank after the first
    level, nothing written, if the target needs more unknowns than a level may have
    (:func:`largest_level`); NotConvergedError on every rank (after writing the last result) if it is
    not reached within ``MAX_LEVELS`` levels or that many unknowns.  The error holds the last result
    as ``result`` on rank 0.
    """
    target = scene.mesh.target_error
    if level is None:
        def level(mesh: Mesh) -> Result | None:
            return driver.solve(scene, comm, None, progress=_silent, mesh=mesh)
    started = time.perf_counter()
    background, rows, result, message = None, [], None, ""
    for number in range(MAX_LEVELS):
        mark = time.perf_counter()
        mesh = distribution.build_mesh(scene, comm, background)
        meshing = time.perf_counter() - mark
        result = level(mesh)
        if comm.rank == 0:
            estimate = float(result.attrs["error_estimate"])
            rows.append({"unknowns": unknowns(mesh), "cells": len(mesh.lower.cells) + len(mesh.upper.cells),
                         "error_estimate": estimate, "energy": float(result.attrs.get("energy", np.nan)),
                         "mesh_time": meshing, "solve_time": result.wall_time,
                         "level_time": time.perf_counter() - mark, "elapsed": time.perf_counter() - started})
            progress(f"level {number}: {rows[-1]['unknowns']:,} unknowns, estimated error {100 * estimate:.3g} %, "
                     f"{rows[-1]['level_time']:.2f} s (mesh {meshing:.2f} s, solve {result.wall_time:.2f} s)")
        decision = collective(comm, lambda: next_level(result, target, number), root_only=True)
        done, background, message = comm.bcast(decision, root=0)
        if done:
            break
    if comm.rank == 0:
        result.levels = {column: np.array([row[column] for row in rows]) for column in LEVEL_COLUMNS}
        result.attrs.update({"target_error": target, "levels": len(rows)})
        result.timings["adaptive"] = time.perf_counter() - started
    if output is not None:
        collective(comm, lambda: io.write(output, result, final=True), root_only=True)
    if message:
        error = NotConvergedError(message)
        error.collective = True
        error.result = result
        raise error
    return result


def next_level(result: Result, target: float, level: int) -> tuple[bool, SizeMap | None, str]:
    """Rank 0's decision after a level: (stop, the next size map, why the target was not reached).
    Raises DDSolveError after the first level if the target is out of reach."""
    estimate = float(result.attrs["error_estimate"])
    if estimate <= target:
        return True, None, ""
    count, degree, limit = unknowns(result.mesh), result.mesh.degree, largest_level(result.ranks)
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
    sizes, growth = refined_sizes(result.mesh, result.indicators)
    if count * growth > limit:
        return True, None, (f"mesh.target_error = {target:g} not reached: the next mesh would have about "
                            f"{count * growth:,.0f} unknowns, more than the {limit:,} a level may have on this "
                            f"machine (estimated error {estimate:.3g}; raise mesh.degree or mesh.target_error)")
    return False, sizes, ""


def refined_sizes(mesh: Mesh, indicators: dict[str, np.ndarray], theta: float = DORFLER,
                  factor: float = REFINE) -> tuple[SizeMap, float]:
    """Dörfler marking on both halves and the size map of the next mesh; also the predicted growth of
    the number of cells.

    A cell's size h_K is the mean length of its (corner) edges and its indicator the sum of the two
    blocks on its half.  A vertex gets the smallest wanted size of its cells where one of them is
    marked, else the mean size of its cells; a Σ vertex the smaller value of the two halves.
    """
    halves = mesh.halves
    squared = [sum(indicators[spec.name] ** 2 for spec in BLOCKS if spec.side == half.side) for half in halves]
    every = np.concatenate(squared)
    order = np.argsort(every)[::-1]
    marked = np.zeros(len(every), dtype=bool)
    count = int(np.searchsorted(np.cumsum(every[order]), theta * every.sum())) + 1
    marked[order[:min(count, len(every))]] = True
    corners, sizes, growth, start = [], [], 0.0, 0
    vertex_sizes = []
    for half in halves:
        cells = half.corners
        p = half.points[cells]
        h = np.linalg.norm(p - p[:, [1, 2, 0]], axis=2).mean(axis=1)
        mine = marked[start:start + len(cells)]
        start += len(cells)
        wanted = np.where(mine, factor * h, h)
        growth += float(np.sum((h / wanted) ** 2))
        n = len(half.points)
        mean = np.bincount(cells.ravel(), np.repeat(h, 3), minlength=n) / np.maximum(
            np.bincount(cells.ravel(), minlength=n), 1)
        smallest = np.full(n, np.inf)
        np.minimum.at(smallest, cells[mine].ravel(), np.repeat(wanted[mine], 3))
        vertex_sizes.append(np.minimum(mean, smallest))
    corner = mesh.sigma.corner
    shared = np.minimum(vertex_sizes[0][mesh.lower.sigma[corner]], vertex_sizes[1][mesh.upper.sigma[corner]])
    vertex_sizes[0][mesh.lower.sigma[corner]] = shared
    vertex_sizes[1][mesh.upper.sigma[corner]] = shared
    for half, size in zip(halves, vertex_sizes):
        corners.append(half.points[half.corners])
        sizes.append(size[half.corners])
    return SizeMap(np.concatenate(corners), np.concatenate(sizes)), growth / len(every)
