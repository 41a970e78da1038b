"""Adaptive re-meshing of a 3-D box to a target error (``mesh.target_error``): solve, estimate, mesh again with gmsh
at the sizes the estimate asks for, solve, until the estimated relative energy-norm error is at most the target.

Every level is an ordinary solve: the monolithic reference (:func:`ddsolve.solvers.solid.solve_solid`) or the domain
decomposition (:func:`ddsolve.solvers.solid_dd.solve`) on rank 0's mesh; rank 0 estimates
(:mod:`ddsolve.post.solid_estimate`), plans the sizes (:func:`planned`) and meshes the box again
(:func:`ddsolve.mesh.solid.build` with a :class:`~ddsolve.mesh.solid_sizing.SizeField`).  The reference and the
DD refine the same way from the same estimate, so both end on the same mesh (gmsh is deterministic) and their
solutions there agree to the solvers' precision.

The sizes aim at the target in one step: on a tetrahedron K of mean edge h_K and volume V_K of a mesh of degree p
the error density is taken as smooth, η_K² = c_K h_K^(2p) V_K; over a size field h(x) the error is ∫ c h^(2p) and
the tetrahedra ∝ ∫ h⁻³, so the fewest tetrahedra for η² = η_T² have h = A c^(−1/(2p+3)) with
A^(2p) = η_T² / ∫ c^(3/(2p+3)); η_T aims at the target ÷ :data:`SAFETY`.  A vertex takes the smallest size of its
tetrahedra, a size stays between ``mesh.size`` and h_K / :data:`MAX_REFINEMENT`.  At the crack front the solution
is not smooth: a tetrahedron with a vertex on the front holds η_K² ∝ h_K² (the r^½ field), so its front vertices
take h_K √(ε / η_K²), ε = ρ A^(2p+3) the share of every tetrahedron when the error is equidistributed (ρ the median
V_K / h_K³); gmsh grades from there to the smooth sizes.  (The front's tetrahedra asked for the smooth model's
sizes, a level under-refined the front and the next one went on: on the extruded scene 3 levels and 39,987
unknowns at 8.40 % true error for a target of 8 %, against 2 levels and 59,142 unknowns at 7.99 % now.)
"""
from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ddsolve.errors import DDSolveError, NotConvergedError
from ddsolve.io import solid as solid_files
from ddsolve.mesh import solid as solid_meshes
from ddsolve.mesh.solid import TETRA_EDGES, SolidMesh, signed_volumes
from ddsolve.mesh.solid_sizing import SizeField
from ddsolve.parallel.exchange import collective
from ddsolve.post import solid_estimate
from ddsolve.post.estimate import Estimate
from ddsolve.post.solid import SolidResult
from ddsolve.problem.scene import Scene
from ddsolve.solvers.adapt import SAFETY, largest_level

#: Levels (solves) before giving up.
MAX_LEVELS = 6
#: A level's mean edge is divided by at most this much at once (the estimate is a model).
MAX_REFINEMENT = 8.0
#: No element size below this fraction of the box's largest side (gmsh's 3-D mesher stays robust above it).
SMALLEST = 1e-4
#: Sizes are rounded to this step of their logarithm (0.1 %): solutions that differ by rounding (the reference's and
#: the DD's, or the DD's on other ranks) give the same sizes, so gmsh meshes the same nodes and both end on one mesh.
SIZE_STEP = 1e-3
#: 3-D unknowns a level may have at most: a sparse factor of a 3-D body fills in far more than a plane one's.
MAX_UNKNOWNS = 600_000


def edge_means(points: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """The mean edge length of every tetrahedron (by its vertices)."""
    ends = points[tetrahedra[:, TETRA_EDGES]]  # (m, 6, 2, 3)
    return np.linalg.norm(ends[:, :, 1] - ends[:, :, 0], axis=2).mean(axis=1)


def planned(mesh: SolidMesh, estimate: Estimate, target: float, ceiling: float, floor: float
            ) -> tuple[SizeField, float]:
    """The size field that aims at ``target`` (see the module's text), and the unknowns it is predicted to give."""
    p = mesh.degree
    aim = target / SAFETY
    wanted = aim ** 2 * estimate.energy / (1.0 - aim ** 2)  # η_T², from η / sqrt(‖u_h‖² + η²) = aim
    corners = [half.tetrahedra[:, :4] for half in mesh.halves]
    h = np.concatenate([edge_means(half.points, c) for half, c in zip(mesh.halves, corners)])
    volumes = np.concatenate([np.abs(signed_volumes(half.points, c)) for half, c in zip(mesh.halves, corners)])
    squared = np.concatenate([estimate.indicators[half.name] ** 2 for half in mesh.halves])
    density = squared / (h ** (2 * p) * volumes)  # c_K
    exponent = 2 * p + 3
    scale = (wanted / max(float(np.sum(density ** (3.0 / exponent) * volumes)), 1e-300)) ** (0.5 / p)
    with np.errstate(divide="ignore"):
        sizes = np.where(density > 0, scale * density ** (-1.0 / exponent), ceiling)
    sizes = np.clip(sizes, np.maximum(floor, h / MAX_REFINEMENT), ceiling)
    offsets = np.cumsum([0] + [len(half.points) for half in mesh.halves])
    tetrahedra = np.concatenate([c + offset for c, offset in zip(corners, offsets)])
    at_vertices = np.full(offsets[-1], ceiling)
    np.minimum.at(at_vertices, tetrahedra.ravel(), np.repeat(sizes, 4))
    # The front: each tetrahedron's share when the error is equidistributed, ε = ρ A^(2p+3) (ρ = V/h³ of the mesh's
    # tetrahedra), from η_K² ∝ h_K² there.
    share = float(np.median(volumes / h ** 3)) * scale ** exponent
    front = np.concatenate([_front_nodes(mesh, half) for half in mesh.halves])[tetrahedra]  # (m, 4)
    singular = np.clip(h * np.sqrt(share / np.maximum(squared, 1e-300)), np.maximum(floor, h / MAX_REFINEMENT),
                       np.minimum(h, ceiling))
    np.minimum.at(at_vertices, tetrahedra[front], np.broadcast_to(singular[:, None], front.shape)[front])
    counted = np.where(front.any(axis=1), np.sqrt(np.minimum(singular, sizes) * sizes), sizes)
    predicted = mesh.unknowns * float(np.sum(volumes / counted ** 3) / np.sum(volumes / h ** 3))
    quantized = np.exp(np.round(np.log(at_vertices) / SIZE_STEP) * SIZE_STEP)
    return SizeField(np.vstack([half.points for half in mesh.halves]), tetrahedra, quantized), predicted


def _front_nodes(mesh: SolidMesh, half) -> np.ndarray:
    """Which nodes of ``half`` lie on a crack front."""
    on_front = np.zeros(len(half.points), dtype=bool)
    on_front[half.sigma_nodes[np.unique(mesh.sigma.front)]] = True
    return on_front


def solve_adaptively(scene: Scene, comm, level: Callable[[SolidMesh | None], SolidResult | None],
                     output: Path | None, progress: Callable[[str], None] = print) -> SolidResult | None:
    """Levels until the estimate is at most ``scene.mesh.target_error``: ``level(mesh)`` solves rank 0's mesh on
    every rank of ``comm`` (the result on rank 0); rank 0 prints a line per level, decides and meshes again.
    ``output`` is the last level's result, with the attributes ``error_estimate``, ``target_error`` and ``levels`` and
    the level table ``/levels/<column>`` (``unknowns``, ``energy``, ``mesh_time``, ``solve_time``,
    ``error_estimate``).  Raises DDSolveError on every rank after the first level, nothing
    written, if the target needs more unknowns than a level may have; NotConvergedError (the last result
    written, and held as ``result``) if it is not reached within :data:`MAX_LEVELS` levels or that many unknowns."""
    started = time.perf_counter()
    mesh = collective(comm, lambda: solid_meshes.build(scene), root_only=True)
    meshing, message, result, rows = time.perf_counter() - started, "", None, []
    for number in range(MAX_LEVELS):
        mark = time.perf_counter()
        result = level(mesh)
        solving = time.perf_counter() - mark
        if comm.rank == 0:
            rows.append({"unknowns": result.mesh.unknowns, "energy": result.energy, "mesh_time": meshing,
                         "solve_time": solving})
        decision = collective(comm, lambda: _next_level(scene, result, number, comm.size, rows[-1], progress),
                              root_only=True)
        done, message = comm.bcast(decision[1:] if comm.rank == 0 else None, root=0)
        mesh, meshing = decision[0] if comm.rank == 0 else None, time.perf_counter() - mark - solving
        if done:
            break
    if comm.rank == 0:
        result.timings["adaptive"] = time.perf_counter() - started
        result.levels = {column: np.array([row[column] for row in rows]) for column in rows[0]}
        result.attrs.update(error_estimate=rows[-1]["error_estimate"], target_error=scene.mesh.target_error,
                            levels=len(rows))
    if output is not None:
        collective(comm, lambda: solid_files.write(output, result), root_only=True)
    if message:
        raise NotConvergedError.collective_with(message, result)
    return result


def _next_level(scene: Scene, result: SolidResult, number: int, ranks: int, row: dict,
                progress: Callable[[str], None]) -> tuple[SolidMesh | None, bool, str]:
    """Rank 0's decision after level ``number``: (the next mesh, stop, why the target was not reached); the
    estimate in the level's ``row``."""
    target = scene.mesh.target_error
    estimate = solid_estimate.of_result(result)
    relative = row["error_estimate"] = estimate.relative
    meshing, solving = row["mesh_time"], row["solve_time"]
    progress(f"level {number}: {result.mesh.unknowns:,} unknowns, estimated error {100 * relative:.3g} %, "
             f"{meshing + solving:.2f} s (mesh {meshing:.2f} s, solve {solving:.2f} s)")
    if relative <= target:
        return None, True, ""
    box = np.reshape(scene.geometry.box, (3, 2))
    sizes, predicted = planned(result.mesh, estimate, target, scene.mesh.size, SMALLEST * float(np.ptp(box, axis=1).max()))
    limit = min(MAX_UNKNOWNS, largest_level(ranks))
    if predicted > limit and number == 0:
        raise DDSolveError(f"mesh.target_error = {target:g}: the estimated error is {100 * relative:.3g} % with "
                           f"{result.mesh.unknowns:,} unknowns, and the target needs about {predicted:,.0f}, above the "
                           f"{limit:,} a 3-D level may have here: give a larger target")
    if predicted > limit or number == MAX_LEVELS - 1:
        return None, True, (f"mesh.target_error = {target:g} not reached: estimated error {100 * relative:.3g} % "
                            f"after {number + 1} levels ({result.mesh.unknowns:,} unknowns)")
    return solid_meshes.build(scene, sizes), False, ""
