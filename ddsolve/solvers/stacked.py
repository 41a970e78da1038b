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

import numpy as np

from ddsolve.dd import constraints, kernels
from ddsolve.dd.interface import for_mesh
from ddsolve.errors import SceneError
from ddsolve.fem import assembly, supports
from ddsolve.fem.assembly import BlockSystem
from ddsolve.mesh import geometry
from ddsolve.mesh.mesh import BlockSpec, Mesh, blocks, facing_above
from ddsolve.post import analysis, fracture, toughness
from ddsolve.post.result import Fracture, Result
from ddsolve.problem.schema import LAYERS, REGIONS
from ddsolve.problem.scene import Scene
from ddsolve.solvers.reference import PHASES, Joint, contact_violation, refuse_friction, solve_joints


@dataclass
class StackResult:
    """The reference's solution of several interfaces: the blocks' displacements ``(n, 2)`` by name (u1, u2, ..
    bottom to top, then v1, ..), the potential energy, and each interface's view (:func:`views`) solved, with G
    at its tips."""

    scene: Scene
    mesh: Mesh
    solution: dict[str, np.ndarray]
    energy: float
    interfaces: list[Result]
    fracture: Fracture
    converged: bool
    message: str
    iterations: int
    timings: dict[str, float]

    @property
    def wall_time(self) -> float:
        return self.timings["total"]


def block_names(layers: int, count: int) -> list[tuple[str, str, int]]:
    """(name, layer, region index) of the blocks of ``layers`` layers on ``count`` regions, layer by layer, the
    lowest region first."""
    return [(f"{letter}{region + 1}", layer, region) for layer, letter in zip(LAYERS[:layers], "uv")
            for region in range(count)]


def view_scene(scene: Scene, interface: int, cracks: slice) -> Scene:
    """The scene of interface ``interface`` alone: its Σ and cracks, its two regions' materials as those of
    ``lower`` and ``upper``, its ``cracks`` of a toughness given per crack."""
    shape, options = scene.geometry, scene.fracture
    names = shape.region_names[interface:interface + 2]
    toughness = options.toughness[cracks] if isinstance(options.toughness, tuple) else options.toughness
    return dataclasses.replace(
        scene, geometry=dataclasses.replace(shape, sigma=shape.sigmas[interface],
                                            cracks=shape.crack_lists[interface], above=()),
        fracture=dataclasses.replace(options, toughness=toughness),
        regions={(layer, region): scene.material(layer, name) for layer in scene.layers
                 for region, name in zip(REGIONS, names)})


def views(scene: Scene, mesh: Mesh) -> list[tuple[Scene, Mesh]]:
    """Every interface, bottom to top, as a structure of two regions: its scene (:func:`view_scene`) and its mesh
    (the region below facing it as the lower half, the region above as the upper half)."""
    regions = mesh.regions
    counts = crack_counts(mesh)
    toughness.check_cracks(scene, sum(counts))
    first = np.concatenate([[0], np.cumsum(counts)]).astype(int)
    return [(view_scene(scene, index, slice(first[index], first[index + 1])),
             Mesh(regions[index] if index == 0 else facing_above(regions[index]), regions[index + 1], line,
                  mesh.origin))
            for index, line in enumerate(mesh.sigmas)]


def crack_counts(mesh: Mesh) -> list[int]:
    """The number of cracks on each interface, bottom to top."""
    return [len(line.pieces(line.crack)) for line in mesh.sigmas]


def straight_lines(mesh: Mesh) -> None:
    """The blocks' dofs are (x, y) on every Σ only where each Σ runs along x: refuse any other in one line."""
    if any(not np.array_equal(line.frames, np.broadcast_to(np.eye(2), line.frames.shape)) for line in mesh.sigmas):
        raise SceneError(f"{mesh.origin}: several interfaces are solved where every Σ is a line along x "
                         "(the box), not here")


def assemble(scene: Scene, mesh: Mesh) -> tuple[list[BlockSystem], list[Joint], list[tuple[Scene, Mesh]]]:
    """The structure's block systems (:func:`block_names`) with the supports each interface's ties spread, the
    interfaces as joints of those blocks, and the interfaces' views."""
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
    systems, held_fixed = [], []
    for (name, layer, region), held in zip(names, ties):
        half, line = mesh.regions[region], mesh.sigmas[max(region - 1, 0)]
        fixed, values = supports.own_supports(scene, half, line, layer)
        for at, tied, tied_values in held:
            fixed[at], values[at] = tied, tied_values
        held_fixed.append(fixed)
        systems.append(assembly.block_system(name, half, line, assembly.elasticity(scene, layer, half.name)[0],
                                             assembly.layer_loads(scene, layer, half), prescribed=(fixed, values),
                                             thermal=assembly.thermal_of(scene, layer, half.name)))
    check_supported(mesh, names, held_fixed, joints)
    return systems, joints, seen


def check_supported(mesh: Mesh, names: list[tuple[str, str, int]], fixed: list[np.ndarray], joints: list[Joint]
                    ) -> None:
    """Refuse, naming the free motion, a structure whose blocks' prescribed dofs ``fixed`` ``(n, 2)`` (x, y) and
    the gluing of every interface leave a rigid motion (:mod:`ddsolve.dd.kernels`)."""
    frame = kernels.frame_of(np.vstack([region.points for region in mesh.regions]))
    rows = []
    for (_, _, region), held in zip(names, fixed):
        points = mesh.regions[region].points
        directions = kernels.prescribed_directions(held, np.broadcast_to(np.eye(2), (len(points), 2, 2)))
        rows.append(kernels.constraint_rows(frame.modes(points), np.zeros(0, dtype=np.int64), directions))
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
    largest = analysis.largest_displacement(u.reshape(-1, 2) for u in fields)
    forces = [assembly.csr_matvec(s, u) - s.rhs for s, u in zip(systems, fields)]  # the interfaces' loads
    contact_rows = np.cumsum([0] + [j.interface.slices["mu_c"].stop - j.interface.slices["mu_c"].start
                                    for j in joints])
    interface_loads, lams = [[] for _ in systems], []
    for joint, first, stop in zip(joints, contact_rows[:-1], contact_rows[1:]):
        interface = joint.interface
        lam = interface.multipliers(np.array([forces[b][dofs] for b, dofs in zip(joint.blocks, joint.dofs)]))
        contact = interface.slices["mu_c"]
        lam[contact] = solved.y[first:stop] / np.sqrt(interface.row_weights[contact])
        lams.append(lam)
        for b, dofs, load in zip(joint.blocks, joint.dofs, interface.loads(lam)):
            interface_loads[b].append((dofs, load))
    residuals = [analysis.block_residual(dataclasses.replace(s, trace_dofs=np.concatenate([d for d, _ in held])),
                                         u, np.concatenate([load for _, load in held]))
                 for s, u, held in zip(systems, fields, interface_loads)]
    steps, changes = (solved.face.violations, solved.face.changes) if solved.face else ([(0.0, 0.0)], [0])
    energy = sum(0.5 * u @ assembly.csr_matvec(s, u) - s.rhs @ u + s.energy_offset for s, u in zip(systems, fields))
    total = sum(solved.timings[name] for name in PHASES)
    results = [interface_result((part, view), joint, lam, fields, residuals, largest, steps, changes,
                                solved.solves)
               for (part, view), joint, lam in zip(seen, joints, lams)]
    violated = [f"interface {n + 1}: {r.message}" for n, r in enumerate(results) if r.message]
    joined = fracture.of_interfaces([r.fracture for r in results], crack_counts(mesh))
    names = block_names(scene.geometry.layers, len(mesh.regions))
    return StackResult(scene, mesh, {name: u.reshape(-1, 2) for (name, _, _), u in zip(names, fields)}, float(energy),
                       results, joined, not violated, "reference: " + "; ".join(violated) if violated else "",
                       len(steps), {**solved.timings, "total": total})


def interface_result(seen: tuple[Scene, Mesh], joint: Joint, lam: np.ndarray, fields: list[np.ndarray],
                     residuals: list[float], largest: float, steps: list, changes: list, solves: int) -> Result:
    """One interface's view as a result: its blocks' displacements and multipliers, its KKT check (the blocks'
    equilibrium residuals under both their interfaces' loads) and G at its tips."""
    part, view = seen
    interface = joint.interface
    traces = np.array([fields[b][dofs] for b, dofs in zip(joint.blocks, joint.dofs)])
    checked = constraints.kkt(interface, traces, lam, None, np.array([residuals[b] for b in joint.blocks]), largest)
    violations = checked.violations(constraints.kkt_tolerance(None))
    scale_u = constraints.displacement_scale(interface, largest)
    scale_mu = constraints.traction_scale(interface, lam, scale_u)
    result = Result.from_blocks(
        part, "reference", view, [fields[b] for b in joint.blocks], interface, lam, converged=not violations,
        iterations=len(steps), solves=solves, wall_time=0.0, ranks=1,
        history=np.array([contact_violation(*step, scale_u, scale_mu) for step in steps]),
        active_set_changes=np.array(changes, dtype=np.int64),
        message=f"the solution violates {', '.join(violations)}" if violations else "",
        attrs={"kkt_tolerance": constraints.kkt_tolerance(None),
               **{f"kkt_{name}": getattr(checked, name) for name in constraints.Constraints.NAMES}})
    result.fracture = fracture.of_result(result, fracture.find_tips(view, part.fracture.inner, part.fracture.outer))
    return result
