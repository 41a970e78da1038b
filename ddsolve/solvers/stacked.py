"""The monolithic reference of a structure of several interfaces (``geometry.sigma = [y1, y2, ...]``).

Regions r = 0..R-1 bottom to top, interfaces i = 0..R-2 (Σ_i between regions i and i+1); the blocks are the
layers × regions, layer by layer, the lowest region first (u1, u2, .., then v1, v2, ..).  Interface i is seen as
the two-region structure of regions i and i+1 (:func:`views`): its mesh, its scene (the two regions' materials
as ``lower`` and ``upper``, its one Σ and its cracks) and its :class:`~ddsolve.dd.interface.Interface` over
that structure's blocks, with the supports its ties spread (:func:`ddsolve.fem.supports.sigma_supports`).  The
glued system ties every interface at once (:func:`ddsolve.solvers.reference.solve_joints`: a middle region's
blocks carry both their Σ lines, and the cracks' jumps of all interfaces make one dual problem).

Each interface's view is returned as a :class:`~ddsolve.post.result.Result` of its own (its two regions' blocks,
its multipliers, its KKT check) with G at its tips: θ's disc keeps clear of the view's outer boundary, which
holds the other Σ lines, so the domain integral over the view's blocks is the whole structure's.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ddsolve.dd import constraints, kernels
from ddsolve.dd.constraints import Constraints
from ddsolve.dd.interface import for_mesh
from ddsolve.errors import SceneError
from ddsolve.fem import assembly, supports
from ddsolve.fem.assembly import BlockSystem
from ddsolve.mesh import geometry
from ddsolve.mesh.mesh import BlockSpec, Mesh, blocks, facing_above
from ddsolve.post import analysis, fracture, toughness
from ddsolve.post.result import Result
from ddsolve.post.stack import StackResult, block_names, crack_counts, crack_slices, view_scene
from ddsolve.problem.scene import Scene, Solver
from ddsolve.solvers.reference import PHASES, Joint, contact_violation, refuse_friction, solve_joints


def views(scene: Scene, mesh: Mesh) -> list[tuple[Scene, Mesh]]:
    """Every interface, bottom to top, as a structure of two regions: its scene (:func:`view_scene`) and its mesh
    (the region below facing it as the lower half, the region above as the upper half)."""
    regions = mesh.regions
    counts = crack_counts(mesh)
    toughness.check_cracks(scene, sum(counts))
    return [(view_scene(scene, index, cracks),
             Mesh(regions[index] if index == 0 else facing_above(regions[index]), regions[index + 1], line,
                  mesh.origin))
            for index, (line, cracks) in enumerate(zip(mesh.sigmas, crack_slices(counts)))]


def straight_lines(mesh: Mesh) -> None:
    """The blocks' dofs are (x, y) on every Σ only where each Σ runs along x: refuse any other in one line."""
    if any(not np.array_equal(line.frames, np.broadcast_to(np.eye(2), line.frames.shape)) for line in mesh.sigmas):
        raise SceneError(f"{mesh.origin}: several interfaces are solved where every Σ is a line along x "
                         "(the box), not here")


def assemble(scene: Scene, mesh: Mesh) -> tuple[list[BlockSystem], list[Joint], list[tuple[Scene, Mesh]]]:
    """The structure's block systems (:func:`block_names`) with the supports each interface's ties spread, the
    interfaces as joints of those blocks, and the interfaces' views."""
    joints, seen, held = joined(scene, mesh)
    names = block_names(scene.geometry.layers, len(mesh.regions))
    systems = [block_system(scene, mesh, names[block], prescribed) for block, prescribed in enumerate(held)]
    return systems, joints, seen


def joined(scene: Scene, mesh: Mesh
           ) -> tuple[list[Joint], list[tuple[Scene, Mesh]], list[tuple[np.ndarray, np.ndarray]]]:
    """The interfaces as joints of the structure's blocks (:func:`block_names`), their views, and each block's
    prescribed dofs and values ``(n, 2)``: its own supports and those each interface's ties spread; refuses a
    structure that can move rigidly (:func:`check_supported`)."""
    straight_lines(mesh)
    seen = views(scene, mesh)
    names = block_names(scene.geometry.layers, len(mesh.regions))
    index = {(layer, region): b for b, (_, layer, region) in enumerate(names)}
    specs = blocks(scene.geometry.layers)
    tables = [supports.sigma_supports(part, view) for part, view in seen]
    joints, ties = [], [[] for _ in names]  # ties: per block, (Σ nodes of its half, their fixed and values)
    for number, ((part, view), table) in enumerate(zip(seen, tables)):
        line = view.sigma
        interface = for_mesh(line, scene.nonpenetration, table.fixed, assembly.modulus(scene),
                             assembly.data_displacement(scene, mesh.regions, line), specs=specs)
        members, dofs = [], []
        for view_block, spec in enumerate(specs):
            block = index[(spec.layer, number + (spec.side > 0))]
            at = view.half(spec.side).sigma[line.multiplier_nodes]
            members.append(block)
            dofs.append((2 * at[:, None] + np.arange(2)).ravel())
            ties[block].append((at, table.fixed[view_block].reshape(-1, 2),
                                table.values[view_block].reshape(-1, 2)))
        joints.append(Joint(interface, tuple(members), tuple(dofs)))
    held = []
    for (_, layer, region), tied in zip(names, ties):
        fixed, values = supports.own_supports(scene, mesh.regions[region], mesh.sigmas[max(region - 1, 0)], layer)
        for at, tied_fixed, tied_values in tied:
            fixed[at], values[at] = tied_fixed, tied_values
        held.append((fixed, values))
    check_supported(mesh, names, [fixed for fixed, _ in held], joints)
    return joints, seen, held


def block_system(scene: Scene, mesh: Mesh, block: tuple[str, str, int], prescribed: tuple[np.ndarray, np.ndarray],
                 rows: tuple[int, int] | None = None) -> BlockSystem:
    """The system of ``block`` (name, layer, region index) with its ``prescribed`` dofs and values (its ``rows``
    only, where given)."""
    name, layer, region = block
    half, line = mesh.regions[region], mesh.sigmas[max(region - 1, 0)]
    return assembly.block_system(name, half, line, assembly.elasticity(scene, layer, half.name)[0],
                                 assembly.layer_loads(scene, layer, half), rows, prescribed=prescribed,
                                 thermal=assembly.thermal_of(scene, layer, half.name))


def support_rows(mesh: Mesh, names: list[tuple[str, str, int]], fixed: list[np.ndarray]
                 ) -> tuple[kernels.Frame, list[np.ndarray]]:
    """The structure's frame and each block's constraint rows ``(c, 3)`` (:func:`ddsolve.dd.kernels.constraint_rows`)
    from its prescribed dofs ``fixed`` ``(n, 2)`` (x, y)."""
    frame = kernels.frame_of(np.vstack([region.points for region in mesh.regions]))
    rows = []
    for (_, _, region), held in zip(names, fixed):
        points = mesh.regions[region].points
        directions = kernels.prescribed_directions(held, np.broadcast_to(np.eye(2), (len(points), 2, 2)))
        rows.append(kernels.constraint_rows(frame.modes(points), np.zeros(0, dtype=np.int64), directions))
    return frame, rows


def check_supported(mesh: Mesh, names: list[tuple[str, str, int]], fixed: list[np.ndarray], joints: list[Joint]
                    ) -> None:
    """Refuse, naming the free motion, a structure whose blocks' prescribed dofs ``fixed`` ``(n, 2)`` (x, y) and
    the gluing of every interface leave a rigid motion (:mod:`ddsolve.dd.kernels`)."""
    frame, rows = support_rows(mesh, names, fixed)
    gluing = []
    for joint, line in zip(joints, mesh.sigmas):
        of_view = kernels.gluing_rows(joint.interface, kernels.trace_modes(line, frame))
        spread = np.zeros((len(of_view), 3 * len(names)))
        for view_block, block in enumerate(joint.blocks):
            spread[:, 3 * block:3 * block + 3] += of_view[:, 3 * view_block:3 * view_block + 3]
        gluing.append(spread)
    kernels.refuse_motion(kernels.free_motions(rows, np.vstack(gluing)), frame,
                          tuple(BlockSpec(name, layer, 0) for name, layer, _ in names))


def solve_stack(scene: Scene, mesh: Mesh) -> StackResult:
    """Solve the scene of several interfaces exactly on ``mesh`` (:func:`ddsolve.mesh.stack.build_any`); each
    interface's view checked (KKT) and with G at its tips."""
    refuse_friction(scene)
    geometry.check_loads(scene, mesh)
    supports.check(scene, mesh)
    systems, joints, seen = assemble(scene, mesh)
    solved = solve_joints(systems, joints, out_of_core=scene.solver.out_of_core)
    fields = solved.fields
    forces = [assembly.csr_matvec(s, u) - s.rhs for s, u in zip(systems, fields)]  # the interfaces' loads
    contact_rows = np.cumsum([0] + [j.interface.slices["mu_c"].stop - j.interface.slices["mu_c"].start
                                    for j in joints])
    lams = []
    for joint, first, stop in zip(joints, contact_rows[:-1], contact_rows[1:]):
        interface = joint.interface
        lam = interface.multipliers(np.array([forces[b][dofs] for b, dofs in zip(joint.blocks, joint.dofs)]))
        contact = interface.slices["mu_c"]
        lam[contact] = solved.y[first:stop] / np.sqrt(interface.row_weights[contact])
        lams.append(lam)
    residuals = structure_residuals(systems, joints, fields, lams)
    steps, changes = (solved.face.violations, solved.face.changes) if solved.face else ([(0.0, 0.0)], [0])
    energy = sum(0.5 * u @ assembly.csr_matvec(s, u) - s.rhs @ u + s.energy_offset for s, u in zip(systems, fields))
    total = sum(solved.timings[name] for name in PHASES)
    run = Run("reference", 1, len(steps), solved.solves, np.array(changes, dtype=np.int64),
              lambda scale_u, scale_mu: np.array([contact_violation(*step, scale_u, scale_mu) for step in steps]),
              {**solved.timings, "total": total})
    return stack_result(scene, mesh, seen, joints, fields, lams, residuals, float(energy), run)


@dataclass
class Run:
    """How a structure of several interfaces was solved: the method, the ranks, its iterations, block solves,
    active-set changes, its history (given the KKT check's displacement and traction scales) and timings."""

    method: str
    ranks: int
    iterations: int
    solves: int
    changes: np.ndarray
    history: Callable[[float, float], np.ndarray]
    timings: dict[str, float]
    solver: Solver | None = None  # the KKT check's tolerance and bound p (None: the reference's)


def stack_result(scene: Scene, mesh: Mesh, seen: list[tuple[Scene, Mesh]], joints: list[Joint],
                 fields: list[np.ndarray], lams: list[np.ndarray], residuals: list[float], energy: float, run: Run
                 ) -> StackResult:
    """The solution of several interfaces as a :class:`StackResult`: the blocks' displacements ``fields`` (flat,
    :func:`block_names`), each joint's multipliers ``lams`` and the blocks' equilibrium residuals under both their
    interfaces' loads; each interface's view checked and with G at its tips (:func:`interface_result`)."""
    largest = analysis.largest_displacement(u.reshape(-1, 2) for u in fields)
    results = [interface_result(view, joint, lam, fields, residuals, largest, run)
               for view, joint, lam in zip(seen, joints, lams)]
    violated = [f"interface {n + 1}: {r.message}" for n, r in enumerate(results) if r.message]
    joined_fracture = fracture.of_interfaces([r.fracture for r in results], crack_counts(mesh))
    names = block_names(scene.geometry.layers, len(mesh.regions))
    return StackResult(scene, mesh, {name: u.reshape(-1, 2) for (name, _, _), u in zip(names, fields)}, energy,
                       results, joined_fracture, not violated,
                       f"{run.method}: " + "; ".join(violated) if violated else "", run.iterations, run.timings)


def structure_residuals(systems: list[BlockSystem], joints: list[Joint], fields: list[np.ndarray],
                        lams: list[np.ndarray]) -> list[float]:
    """Each block's equilibrium residual (:func:`ddsolve.post.analysis.block_residual`) under the loads of every
    interface it is on (the multipliers ``lams`` of each joint)."""
    held = [[] for _ in systems]  # per block: (its dofs on an interface, that interface's load)
    for joint, lam in zip(joints, lams):
        for b, dofs, load in zip(joint.blocks, joint.dofs, joint.interface.loads(lam)):
            held[b].append((dofs, load))
    return [analysis.block_residual(dataclasses.replace(s, trace_dofs=np.concatenate([d for d, _ in loads])),
                                    u, np.concatenate([load for _, load in loads]))
            for s, u, loads in zip(systems, fields, held)]


def check(stacked: StackResult) -> list[Constraints]:
    """The KKT residuals of each interface of a result of several interfaces (one read back): the blocks
    assembled again, each block's equilibrium under the loads of every interface it is on."""
    scene, mesh = stacked.scene, stacked.mesh
    systems, joints, _ = assemble(scene, mesh)
    fields = [stacked.solution[name].reshape(-1) for name, _, _ in block_names(scene.geometry.layers,
                                                                               len(mesh.regions))]
    lams = [analysis.multiplier_vector(joint.interface, view.multipliers, view.mesh.sigma.frames[view.multiplier_nodes])
            for joint, view in zip(joints, stacked.interfaces)]
    residuals = structure_residuals(systems, joints, fields, lams)
    return [analysis.constraints(view, np.array([residuals[b] for b in joint.blocks]))
            for joint, view in zip(joints, stacked.interfaces)]


def interface_result(seen: tuple[Scene, Mesh], joint: Joint, lam: np.ndarray, fields: list[np.ndarray],
                     residuals: list[float], largest: float, run: Run) -> Result:
    """One interface's view as a result: its blocks' displacements and multipliers, its KKT check (the blocks'
    equilibrium residuals under both their interfaces' loads) and G at its tips."""
    part, view = seen
    interface = joint.interface
    traces = np.array([fields[b][dofs] for b, dofs in zip(joint.blocks, joint.dofs)])
    solver, tolerance = run.solver, constraints.kkt_tolerance(run.solver)
    checked = constraints.kkt(interface, traces, lam, None if solver is None else solver.p,
                              np.array([residuals[b] for b in joint.blocks]), largest)
    violations = checked.violations(tolerance)
    scale_u = constraints.displacement_scale(interface, largest)
    scale_mu = constraints.traction_scale(interface, lam, scale_u)
    result = Result.from_blocks(
        part, run.method, view, [fields[b] for b in joint.blocks], interface, lam, converged=not violations,
        iterations=run.iterations, solves=run.solves, wall_time=0.0, ranks=run.ranks,
        history=run.history(scale_u, scale_mu), active_set_changes=run.changes,
        message=f"the solution violates {', '.join(violations)}" if violations else "",
        attrs={"kkt_tolerance": tolerance,
               **{f"kkt_{name}": getattr(checked, name) for name in constraints.Constraints.NAMES}})
    result.fracture = fracture.of_result(result, fracture.find_tips(view, part.fracture.inner, part.fracture.outer))
    return result
