"""Adaptive refinement to a target error (``mesh.target_error``): solve, estimate, mark, re-mesh, repeat.

Each level is an ordinary domain-decomposition solve (:func:`ddsolve.driver.solve`) with its error
estimate.  While the estimate is above the target, rank 0 marks the cells that carry the largest
indicators (Dörfler marking: the fewest cells whose η_K² add up to ``DORFLER`` of η²), asks for
``REFINE`` × their size and the present size elsewhere, and gmsh meshes the geometry again with that
size field (:class:`ddsolve.geometry.SizeMap`, the previous mesh with sizes at its vertices; with
``mesh.grading`` the graded field still applies where it is finer).  The two halves are meshed from
the same size field, so their Σ nodes match.  What carries over from a level to the next: the scene,
the geometry's size field and the previous mesh (as the background of the next one).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from . import driver, io
from .errors import NotConvergedError
from .exchange import collective
from .geometry import SizeMap
from .interface import BLOCKS
from .mesh import Mesh
from .result import Result
from .scene import Scene

#: Dörfler's bulk parameter θ: the marked cells carry at least this fraction of η².
DORFLER = 0.5
#: Marked cells are meshed again with this fraction of their size.
REFINE = 0.5
#: Levels before giving up.
MAX_LEVELS = 25
#: Unknowns above which the next level is not attempted (memory).
MAX_UNKNOWNS = 4_000_000
#: Columns of the level table (``/levels`` in the result file).
LEVEL_COLUMNS = ("unknowns", "cells", "error_estimate", "energy", "mesh_time", "solve_time", "level_time", "elapsed")


def unknowns(mesh: Mesh) -> int:
    """Displacement unknowns of the four blocks (two per node, each half twice)."""
    return 4 * (len(mesh.lower.points) + len(mesh.upper.points))


def _silent(_line: str) -> None:
    pass


def solve(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print) -> Result | None:
    """Refine until the estimated relative energy-norm error is at most ``scene.mesh.target_error``.

    Prints a line per level on rank 0 (via ``progress``); writes the last level's result with the
    level table.  Returns the result on rank 0 (None elsewhere).  Raises NotConvergedError on every
    rank (after writing the last result) if the target is not reached within ``MAX_LEVELS`` levels or
    ``MAX_UNKNOWNS`` unknowns.
    """
    target = scene.mesh.target_error
    started = time.perf_counter()
    background, rows, result, message = None, [], None, ""
    for level in range(MAX_LEVELS):
        mark = time.perf_counter()
        mesh = driver.build_mesh(scene, comm, background)
        meshing = time.perf_counter() - mark
        result = driver.solve(scene, comm, None, progress=_silent, mesh=mesh)
        decision = None
        if comm.rank == 0:
            estimate = float(result.attrs["error_estimate"])
            rows.append({"unknowns": unknowns(mesh), "cells": len(mesh.lower.cells) + len(mesh.upper.cells),
                         "error_estimate": estimate, "energy": float(result.attrs.get("energy", np.nan)),
                         "mesh_time": meshing, "solve_time": result.wall_time,
                         "level_time": time.perf_counter() - mark, "elapsed": time.perf_counter() - started})
            progress(f"level {level}: {rows[-1]['unknowns']:,} unknowns, estimated error {100 * estimate:.3g} %, "
                     f"{rows[-1]['level_time']:.2f} s (mesh {meshing:.2f} s, solve {result.wall_time:.2f} s)")
            decision = _next(result, target, level)
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
        raise error
    return result


def _next(result: Result, target: float, level: int) -> tuple[bool, SizeMap | None, str]:
    """Rank 0's decision after a level: (stop, the next size map, why the target was not reached)."""
    estimate = float(result.attrs["error_estimate"])
    if estimate <= target:
        return True, None, ""
    if level + 1 == MAX_LEVELS:
        return True, None, (f"mesh.target_error = {target:g} not reached in {MAX_LEVELS} levels "
                            f"(estimated error {estimate:.3g})")
    sizes, growth = refined_sizes(result.mesh, result.indicators)
    if unknowns(result.mesh) * growth > MAX_UNKNOWNS:
        return True, None, (f"mesh.target_error = {target:g} not reached: the next mesh would have about "
                            f"{unknowns(result.mesh) * growth:,.0f} unknowns (estimated error {estimate:.3g}; "
                            "raise mesh.degree or mesh.target_error)")
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
