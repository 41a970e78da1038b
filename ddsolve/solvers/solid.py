"""The monolithic reference of a 3-D box (``geometry.box = [x0, x1, y0, y1, z0, z1]``): the two halves glued on Σ
off the cracks, the crack faces free or under non-penetration along Σ's normal, solved exactly.

The plane reference's machinery with three dofs per node (:mod:`ddsolve.solvers.reference`): a glued Σ vertex's
dofs are one unknown for both halves; at a crack vertex under non-penetration the lower face's normal
displacement is the upper face's plus the jump j = u⁻·ν − u⁺·ν (ν = +y), an unknown of its own numbered last;
MUMPS factors the merged system once with the Schur complement on the jumps, and the crack's small dense dual
problem (:class:`~ddsolve.solvers.reference.FaceProblem`) gives the contact pressures.  The final check: the
merged system's residual, no penetration, no tension, complementarity.  A box of several interfaces: its regions
glued on every Σ alike, each Σ's jumps numbered after the Σ below's, G along each Σ's fronts from its view
(:meth:`ddsolve.post.solid.SolidResult.interface`).
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ddsolve.dd import constraints
from ddsolve.errors import DDSolveError
from ddsolve.fem import tetra
from ddsolve.fem.assembly import csr_matvec
from ddsolve.io import solid as solid_files
from ddsolve.mesh import solid as solid_meshes
from ddsolve.mesh.solid import SolidMesh
from ddsolve.parallel.phases import Phases
from ddsolve.post import front
from ddsolve.post.solid import SolidResult
from ddsolve.problem.scene import Scene
from ddsolve.solvers import solid_lines
from ddsolve.solvers.reference import PHASES, merged_system, solve_merged

#: Σ's normal ν (the lower half's outward normal) as a component: y.
NORMAL = 1


def numbering(mesh: SolidMesh, contact: bool) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """The unknown of every dof of each region (a glued Σ vertex's dofs shared by the regions below and above it;
    under ``contact`` a crack vertex's normal dofs share the upper face's), the jump unknown of each dof (−1 for
    none; numbered last, Σ after Σ in Σ order) and each Σ's crack vertices that carry a jump."""
    offsets = np.cumsum([0] + [region.dofs for region in mesh.regions])
    numbers = [offset + np.arange(region.dofs) for offset, region in zip(offsets, mesh.regions)]
    jumping, borders = [], []
    for k, surface in enumerate(mesh.sigmas):
        below, above = (tetra.element_dofs(nodes[:, None]) for nodes in mesh.border(k))  # (s, 3) each
        glued = ~surface.cracked
        numbers[k + 1][above[glued]] = numbers[k][below[glued]]
        jumping.append(np.flatnonzero(surface.cracked) if contact else np.zeros(0, dtype=np.int64))
        numbers[k][below[jumping[-1], NORMAL]] = numbers[k + 1][above[jumping[-1], NORMAL]]
        borders.append(below)
    _, compact = np.unique(np.concatenate(numbers), return_inverse=True)
    numbers = np.split(compact.astype(np.int64), offsets[1:-1])
    jumps = [np.full(region.dofs, -1, dtype=np.int64) for region in mesh.regions]
    first = int(compact.max()) + 1
    for k, (below, vertices) in enumerate(zip(borders, jumping)):
        jumps[k][below[vertices, NORMAL]] = first + np.arange(len(vertices))
        first += len(vertices)
    return numbers, jumps, jumping


def solve_solid(scene: Scene, mesh: SolidMesh) -> SolidResult:
    """The scene's discrete problem on ``mesh`` solved exactly, with its final check (data a double-precision
    solve cannot represent refused first, :func:`ddsolve.fem.tetra.check_range`)."""
    phases = Phases()
    tetra.check_range(scene, mesh)
    systems = [tetra.half_system(scene, region) for region in mesh.regions]
    blocks = [system.decoupled(region.name) for system, region in zip(systems, mesh.regions)]
    numbers, jumps, jumping = numbering(mesh, scene.nonpenetration)
    sqrt_w = np.sqrt(np.concatenate([surface.weights[vertices] for surface, vertices in zip(mesh.sigmas, jumping)]))
    merged = merged_system(blocks, numbers, jumps)
    phases.end("merge")
    x, solved = solve_merged(merged, sqrt_w, lambda largest: largest, scene.solver.out_of_core, phases)
    fields = [x[number] + np.where(jump >= 0, x[jump], 0.0) for number, jump in zip(numbers, jumps)]
    phases.end("solve")
    pressures = [np.zeros(len(surface.points)) for surface in mesh.sigmas]
    if solved.face is not None:
        for pressure, vertices, y in zip(pressures, jumping, np.split(solved.y / sqrt_w,
                                                                      np.cumsum([len(v) for v in jumping])[:-1])):
            pressure[vertices] = y
    contact_load = np.zeros(merged.size)
    contact_load[merged.size - len(sqrt_w):] = -sqrt_w * solved.y
    residual = csr_matvec(merged, x) - merged.rhs - contact_load
    result = SolidResult(scene, mesh, tuple(u.reshape(-1, 3) for u in fields), tuple(pressures),
                         energy=sum(system.energy(u) for system, u in zip(systems, fields)),
                         steps=len(solved.face.changes) if solved.face else 1, solves=solved.solves, converged=True,
                         timings={name: phases.wall[name] for name in PHASES})
    _final_check(result, float(np.abs(residual).max()) / max(float(np.abs(merged.rhs).max()),
                                                             float(np.abs(contact_load).max()), 1e-300))
    return result


def _final_check(result: SolidResult, residual: float) -> None:
    """The merged system's relative residual, the largest penetration (relative to the largest displacement),
    tension (none by construction) and complementarity (pressure × opening × weight against the energy scale):
    each within the KKT tolerance, else the result is not converged, with a message naming them."""
    views = [result.interface(k) for k in range(len(result.pressures))]
    openings = [view.normal_opening for view in views]
    largest = max(float(np.abs(u).max()) for u in result.fields)
    cracked = [view.mesh.sigma.cracked if result.scene.nonpenetration else np.zeros(len(opening), dtype=bool)
               for view, opening in zip(views, openings)]
    work = sum(float(np.abs(view.pressure * opening * view.mesh.sigma.weights).sum())
               for view, opening in zip(views, openings))
    scale = max(abs(result.energy), 1e-300)
    result.checks = {"residual": residual,
                     "penetration": max(float(np.max(-opening[on], initial=0.0))
                                        for opening, on in zip(openings, cracked)) / max(largest, 1e-300),
                     "tension": max(float(np.max(-view.pressure, initial=0.0)) for view in views) + 0.0,  # not -0.0
                     "complementarity": work / scale}
    tolerance = constraints.kkt_tolerance(None)
    violated = [name for name, value in result.checks.items() if value > tolerance]
    result.converged = not violated
    result.message = (f"reference: the 3-D solution violates {', '.join(violated)} (tolerance {tolerance:g})"
                      if violated else "")


def energy_error(result: SolidResult, reference: SolidResult) -> float:
    """‖u − u_ref‖_a / ‖u_ref‖_a over both halves, on the reference's mesh (the same as the result's, else
    refused in one line) with the reference scene's materials."""
    same = len(result.mesh.regions) == len(reference.mesh.regions) and all(
        mine.points.shape == theirs.points.shape and np.array_equal(mine.points, theirs.points)
        for mine, theirs in zip(result.mesh.regions, reference.mesh.regions))
    if not same:
        raise DDSolveError("the 3-D results lie on different meshes: compare results of one mesh (geometry.box, "
                           "mesh.size, mesh.grading)")
    error = norm = 0.0
    for half, u, v in zip(reference.mesh.regions, result.fields, reference.fields):
        material = reference.scene.material("layer1", half.name)
        K = tetra.stiffness(half.points, half.tetrahedra, tetra.elastic_matrix(material))
        difference = (u - v).ravel()
        error += difference @ (K @ difference)
        norm += v.ravel() @ (K @ v.ravel())
    return float(np.sqrt(error / norm)) if norm > 0 else (0.0 if error == 0 else float("inf"))


def comparison(result: SolidResult, reference: SolidResult) -> tuple[float, float, float]:
    """:func:`energy_error`, the largest nodal difference and the reference's largest nodal displacement."""
    error = energy_error(result, reference)  # first: it refuses results on different meshes
    difference = max(float(np.abs(u - v).max()) for u, v in zip(result.fields, reference.fields))
    return error, difference, max(float(np.abs(u).max()) for u in reference.fields)


def with_fracture(result: SolidResult, progress: Callable[[str], None] | None = None) -> None:
    """G along ``result``'s crack fronts (:func:`ddsolve.post.front.release`) in its ``fracture``, timed as its phase
    ``fracture`` (with the eigenstrain's term under a temperature change), and a ``progress`` line."""
    if any(len(surface.front) for surface in result.mesh.sigmas):
        phases = Phases()
        result.fracture, result.fracture_interface = fracture_of(result)
        phases.end("fracture")
        result.timings["fracture"] = phases.wall["fracture"]
        if progress is not None:
            progress(solid_lines.front_line(result.fracture, phases.wall["fracture"]))


def fracture_of(result: SolidResult) -> tuple[front.FrontRelease, np.ndarray | None]:
    """G along every front (:func:`ddsolve.post.front.release`): of one Σ its own; of several, each interface's
    view's rows joined, their chains numbered on, and the interface of each row (1 the lowest)."""
    if len(result.pressures) == 1:
        return front.release(result), None
    releases = [front.release(result.interface(k)) for k in range(len(result.pressures))]
    return front.joined(releases), np.concatenate([np.full(len(release.G), k + 1, dtype=np.int64)
                                                   for k, release in enumerate(releases)])


def reference(scene: Scene, output: Path | None = None, progress: Callable[[str], None] | None = None) -> SolidResult:
    """A 3-D scene meshed and solved by the monolithic reference, G along its crack fronts
    (:func:`ddsolve.post.front.release`), ``output`` and its VTU files written; ``progress`` lines after each
    stage."""
    phases = Phases()
    mesh = solid_meshes.build(scene)
    phases.end("meshing")
    if progress is not None:
        progress(solid_lines.mesh_line(mesh, phases.wall["meshing"]))
    result = solve_solid(scene, mesh)
    phases.end("solve")
    result.timings["meshing"] = phases.wall["meshing"]
    if progress is not None:
        progress(solid_lines.factored_line("the merged system", result.timings)
                 + f", solved in {result.timings['solve']:.1f} s ({result.steps} active-set steps)")
    with_fracture(result, progress)
    if output is not None:
        solid_files.write(output, result)
    return result


def reference_on(scene: Scene, mesh: SolidMesh) -> SolidResult:
    """The monolithic reference on ``mesh`` with G along its crack fronts."""
    result = solve_solid(scene, mesh)
    with_fracture(result)
    return result
