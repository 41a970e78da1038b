"""The monolithic reference: the same discrete problem as one system, solved exactly.

All nodal equalities are imposed by giving tied degrees of freedom one unknown (u⁻ = u⁺ on glued
vertices, u± = v± everywhere on Σ).  At a crack vertex under non-penetration the lower face's normal
displacement is the upper face's plus the jump j = [u]·ν, an unknown of its own, so that the glued system
K x = f holds every crack face free.  It is factored once by MUMPS (KSP prefix ``reference_``), which
returns with the factors the Schur complement S_j of K on the jumps.  With y = W^½ μᶜ, non-penetration
is the small dense dual problem of the crack

    min ½ yᵀ A y − bᵀ y over y ≥ 0,   A = W^½ S_j⁻¹ W^½,   b = W^½ j⁰

(j⁰ the jumps of the unconstrained solution x⁰ = K⁻¹ f; no bound p), solved by the primal-dual active set
method :func:`ddsolve.dd.schur.box_qp` from the unconstrained solution's penetrations (the vertices whose
faces overlap in x⁰ start closed): whatever the active set, its steps cost dense solves of the crack's
size and no sparse work.  One more solve with the contact forces −W μᶜ on the jumps gives the
displacements, refined while its jumps differ from the model's (:data:`REFINEMENT_TOLERANCE`).  The jumps
are eliminated last inside the sparse factorization, so the layers' bending never enters S_j⁻¹, as it
would in the flexibility of the two faces' separate displacements.

With the elastic bond (``[interface] law = "elastic"``, :mod:`ddsolve.dd.cohesive`) the bonded vertices' faces
are not tied: each has its own unknowns, joined by a spring w/c per row (c the row's compliance, w its lumped
weight), the primal form of the dual's gap = c λ.  The bilinear law is refused (its damage is a nonlinear problem).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ddsolve.dd import constraints
from ddsolve.dd.interface import Interface, for_mesh
from ddsolve.dd.schur import box_qp
from ddsolve.errors import SolverError
from ddsolve.fem import assembly, supports
from ddsolve.fem.assembly import BlockSystem, coo_to_csr
from ddsolve.mesh import mesh as meshes
from ddsolve.mesh.mesh import U_MINUS, U_PLUS, Mesh
from ddsolve.parallel.blocks import Block
from ddsolve.parallel.distribution import whole_mesh_checks
from ddsolve.parallel.launch import provenance
from ddsolve.parallel.phases import Phases
from ddsolve.post import analysis, estimate, fracture, reactions
from ddsolve.post.result import Result
from ddsolve.problem.scene import Scene

#: The phases of the solve, each with its wall and CPU seconds in the result's timings.
PHASES = ("merge", "factorization", "solve")
#: The solve with the contact forces is refined while its jumps differ from the dense model's by more than this,
#: relative to the displacement scale (the ENF of issue 39: 2e-12 before a refinement, 3e-16 after).
REFINEMENT_TOLERANCE = 1e-14
MAX_REFINEMENTS = 3


@dataclass(frozen=True, eq=False)
class Joint:
    """One interface Σ of the structure: its multipliers (``interface``, over its own blocks), the structure's
    block of each of its blocks (``blocks``) and their trace dofs in those blocks' systems (``dofs``)."""

    interface: Interface
    blocks: tuple[int, ...]
    dofs: tuple[np.ndarray, ...]


def joint_of(systems: list[BlockSystem], interface: Interface) -> Joint:
    """The one interface of a structure whose blocks are ``interface.blocks``, assembled as ``systems``."""
    return Joint(interface, tuple(range(len(systems))), tuple(system.trace_dofs for system in systems))


def numbering(systems: list[BlockSystem], interface: Interface, closed: np.ndarray) -> list[np.ndarray]:
    """Global unknown of every block dof; tied dofs share one.  ``closed``: crack vertices in contact."""
    return joint_numbering([system.size for system in systems], [joint_of(systems, interface)], [closed])


def joint_numbering(sizes: list[int], joints: list[Joint], closed: list[np.ndarray]) -> list[np.ndarray]:
    """Global unknown of every dof of blocks of ``sizes`` dofs: the traces of each of ``joints`` first (tied
    dofs sharing one; ``closed``: each joint's crack vertices in contact), then the blocks' other dofs."""
    numbers = [np.full(size, -1, dtype=np.int64) for size in sizes]
    following = 0
    for joint, shut in zip(joints, closed):
        traces = joint_traces(joint.interface, shut)
        for block, dofs, trace in zip(joint.blocks, joint.dofs, traces):
            numbers[block][dofs] = following + trace
        following += int(traces.max(initial=-1)) + 1
    for number in numbers:
        own = number < 0
        number[own] = following + np.arange(own.sum())
        following += int(own.sum())
    return numbers


def joint_traces(interface: Interface, closed: np.ndarray) -> np.ndarray:
    """``interface.trace_unknowns(closed)`` with the faces of a bond's sprung rows (compliance c > 0) apart: the
    upper side's entry of each numbered after the others, the spring of :func:`bond_springs` between them."""
    traces = interface.trace_unknowns(closed)
    if interface.bond is None:
        return traces
    entries = interface.trace_index[interface.compliance > 0.0]
    upper = np.array([spec.side > 0 for spec in interface.blocks])
    traces[np.ix_(upper, entries)] = int(traces.max(initial=-1)) + 1 + np.arange(len(entries))
    return traces


def bond_springs(joint: Joint, numbers: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bond's springs as COO entries (rows, columns, values) of the glued system numbered ``numbers``: on
    every row of compliance c > 0 (:attr:`~ddsolve.dd.interface.Interface.compliance`) the stiffness w/c between
    the unknowns of its trace entry on u⁻ and on u⁺, the energy ½ (w/c)(u⁻ − u⁺)², whose force on u⁻ is
    the dual's −W λ with u⁻ − u⁺ = c λ."""
    interface = joint.interface
    rows = np.flatnonzero(interface.compliance > 0.0)
    entries = interface.trace_index[rows]
    lower, upper = (numbers[joint.blocks[block]][joint.dofs[block][entries]] for block in (U_MINUS, U_PLUS))
    stiffness = interface.row_weights[rows] / interface.compliance[rows]
    return (np.concatenate([lower, upper, lower, upper]), np.concatenate([lower, upper, upper, lower]),
            np.concatenate([stiffness, stiffness, -stiffness, -stiffness]))


def jump_numbering(sizes: list[int], joints: list[Joint]) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The numbering with the crack faces' normal displacements tied, and the second unknown of every block
    dof (−1 for none): on the lower face's blocks of each joint (those of its lower half, whose normal
    displacement is the upper face's plus the jump), the jump of its contact row, numbered last, joint by joint
    in row order."""
    contacts = [joint.interface.slices["mu_c"] for joint in joints]
    numbers = joint_numbering(sizes, joints, [np.ones(rows.stop - rows.start, dtype=bool) for rows in contacts])
    following = int(max(n.max(initial=-1) for n in numbers)) + 1
    jumps = [np.full(size, -1, dtype=np.int64) for size in sizes]
    for joint, rows in zip(joints, contacts):
        normal = 2 * joint.interface.vertex[rows] + 1
        for spec, block, dofs in zip(joint.interface.blocks, joint.blocks, joint.dofs):
            if spec.side < 0:
                jumps[block][dofs[normal]] = following + np.arange(len(normal))
        following += len(normal)
    return numbers, jumps


def merged_system(systems: list[BlockSystem], numbers: list[np.ndarray],
                  jumps: list[np.ndarray] | None = None,
                  springs: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = ()) -> BlockSystem:
    """Tᵀ diag(K_b) T and Tᵀ f for the map T that gives block dof i the value of unknown ``numbers[b][i]``,
    plus that of unknown ``jumps[b][i]`` where it is not −1; plus the COO entries ``springs``
    (:func:`bond_springs`)."""
    jumps = jumps if jumps is not None else [np.full(len(n), -1, dtype=np.int64) for n in numbers]
    size = int(max(max(n.max(), j.max()) for n, j in zip(numbers, jumps))) + 1
    rows, cols, values, rhs = [], [], [], np.zeros(size)
    for system, number, jump in zip(systems, numbers, jumps):
        local_rows = np.repeat(np.arange(system.size), np.diff(system.indptr))
        pairs = ((number, number), (jump, number), (number, jump), (jump, jump))
        for row_map, col_map in pairs if (jump >= 0).any() else pairs[:1]:
            kept = (row_map[local_rows] >= 0) & (col_map[system.indices] >= 0)
            rows.append(row_map[local_rows[kept]])
            cols.append(col_map[system.indices[kept]])
            values.append(system.data[kept])
        rhs += np.bincount(number, system.rhs, minlength=size)
        second = jump >= 0
        rhs += np.bincount(jump[second], system.rhs[second], minlength=size)
    for spring_rows, spring_cols, spring_values in springs:
        rows.append(spring_rows)
        cols.append(spring_cols)
        values.append(spring_values)
    indptr, indices, data = coo_to_csr(size, np.concatenate(rows), np.concatenate(cols), np.concatenate(values))
    return BlockSystem("reference", indptr, indices, data, rhs, np.zeros(0, dtype=np.int64), size, block_size=1)


class FaceProblem:
    """The crack's dual problem min ½ yᵀAy − bᵀy over y ≥ 0 (y = W^½ μᶜ) from the Schur complement S_j = L Lᵀ
    on the jumps and the unconstrained jumps j⁰: A = (L⁻¹ W^½)ᵀ(L⁻¹ W^½), b = W^½ j⁰.  Records, per active-set
    step, its largest penetration of an open vertex and tension μᶜ < 0 (unscaled) and how many vertices
    changed state."""

    def __init__(self, stiffness: np.ndarray, unconstrained: np.ndarray, sqrt_w: np.ndarray):
        import scipy.linalg  # here: importing it costs every rank of a DD launch 35 ms of its start-up

        factor = scipy.linalg.cholesky(stiffness, lower=True, check_finite=False)
        forces = scipy.linalg.solve_triangular(factor, np.diag(sqrt_w), lower=True, check_finite=False)
        self.A, self.b, self.sqrt_w = forces.T @ forces, sqrt_w * unconstrained, sqrt_w
        self.violations: list[tuple[float, float]] = []
        self.changes: list[int] = []

    def jumps(self, y: np.ndarray) -> np.ndarray:
        """The jumps the model predicts under the scaled multipliers ``y``."""
        return (self.b - self.A @ y) / self.sqrt_w

    def solve(self, start: np.ndarray | None = None) -> np.ndarray:
        """The solution by :func:`box_qp`, its first active set that of ``start`` (a previous solution: the rows
        it holds at 0 stay open) or, without one, the unconstrained solution's: open where j⁰ ≤ 0, closed where
        the faces penetrate."""
        start = np.maximum(self.b, 0.0) if start is None else start
        return box_qp(self.A, self.b, np.zeros(len(self.b)), np.full(len(self.b), np.inf), observe=self._record,
                      start=start)[0]

    def _record(self, y: np.ndarray, changed: int) -> None:
        self.violations.append((float(np.max(self.jumps(y)[y == 0.0], initial=0.0)),
                                float(np.max(-y / self.sqrt_w, initial=0.0))))
        self.changes.append(changed)

    def refine(self, y: np.ndarray, mismatch: np.ndarray) -> np.ndarray:
        """The solution once the model's jumps are shifted by ``mismatch`` (the solved jumps less the predicted
        ones: iterative refinement), starting from ``y``'s active set."""
        self.b = self.b + self.sqrt_w * mismatch
        return self.solve(start=y)


@dataclass
class GluedSolution:
    """The glued problem solved: every block's displacements, the scaled contact multipliers y = W^½ μᶜ, the
    crack's dual problem (None without contact rows), the sparse solves and the refinements among them,
    whether MUMPS kept the factors on disk, and the wall and CPU seconds of :data:`PHASES`."""

    out_of_core: bool
    fields: list[np.ndarray] = field(default_factory=list)
    y: np.ndarray = field(default_factory=lambda: np.zeros(0))
    face: FaceProblem | None = None
    solves: int = 1
    refinements: int = 0
    timings: dict[str, float] = field(default_factory=dict)


def solve_glued(systems: list[BlockSystem], interface: Interface, out_of_core: bool = False) -> GluedSolution:
    """One factorization of the glued system (with S_j on the jumps when there is contact), the unconstrained
    solve, then with contact the crack's dual problem and the solve with its forces (see the module)."""
    return solve_joints(systems, [joint_of(systems, interface)], out_of_core)


def solve_joints(systems: list[BlockSystem], joints: list[Joint], out_of_core: bool = False) -> GluedSolution:
    """:func:`solve_glued` for blocks glued on the interfaces ``joints``: their cracks' jumps together in one
    dual problem (y joint by joint)."""
    phases = Phases()
    numbers, jumps = jump_numbering([system.size for system in systems], joints)
    sqrt_w = np.sqrt(np.concatenate([joint.interface.row_weights[joint.interface.slices["mu_c"]]
                                     for joint in joints]))
    merged = merged_system(systems, numbers, jumps,
                           [bond_springs(joint, numbers) for joint in joints if joint.interface.bond is not None])
    phases.end("merge")
    x, solved = solve_merged(merged, sqrt_w, lambda largest: constraints.displacement_scale(joints[0].interface,
                                                                                             largest),
                             out_of_core, phases)
    solved.fields = [x[number] + np.where(jump >= 0, x[jump], 0.0) for number, jump in zip(numbers, jumps)]
    phases.end("solve")
    solved.timings = {**{name: phases.wall[name] for name in PHASES},
                      **{f"{name}_cpu": phases.cpu[name] for name in PHASES}}
    return solved


def solve_merged(merged: BlockSystem, sqrt_w: np.ndarray, scale_of: Callable[[float], float], out_of_core: bool,
                 phases: Phases) -> tuple[np.ndarray, GluedSolution]:
    """The merged system whose last ``len(sqrt_w)`` unknowns are the crack's jumps (W^½ their weights') factored
    once (phase ``factorization``, with S_j on the jumps), solved unconstrained, then with contact the crack's
    dual problem and the solve with its forces (:func:`contact_solve`; ``scale_of``: the displacement scale of a
    largest displacement).  The solution and the record of the solve (its ``fields`` left to the caller)."""
    block = Block(dataclasses.replace(merged, trace_dofs=merged.size - len(sqrt_w) + np.arange(len(sqrt_w))))
    try:
        block.factor(schur=len(sqrt_w) > 0, out_of_core=out_of_core)
        phases.end("factorization")
        x = block.solve(np.zeros(len(sqrt_w)), body=True).copy()
        solved = GluedSolution(block.out_of_core())
        if len(sqrt_w):
            solved.face = FaceProblem(block.schur_complement(), x[block.trace_dofs], sqrt_w)
            x = contact_solve(block, x, scale_of, solved)
    finally:
        block.destroy()
    return x, solved


def contact_solve(block: Block, unconstrained: np.ndarray, scale_of: Callable[[float], float],
                  solved: GluedSolution) -> np.ndarray:
    """The glued solution under contact from the ``unconstrained`` one: ``solved.face`` solved, then the solve
    with the contact forces −W μᶜ on the jumps, refined while its jumps differ from the model's by more than
    :data:`REFINEMENT_TOLERANCE` (relative to ``scale_of`` the largest displacement: the KKT check's displacement
    scale), at most :data:`MAX_REFINEMENTS` times."""
    face = solved.face
    solved.y = face.solve()
    x = unconstrained
    while solved.y.any():
        x = block.solve(-face.sqrt_w * solved.y, body=True).copy()
        solved.solves += 1
        mismatch = x[block.trace_dofs] - face.jumps(solved.y)
        scale = scale_of(float(np.abs(x).max()))
        if np.abs(mismatch).max() <= REFINEMENT_TOLERANCE * scale or solved.refinements == MAX_REFINEMENTS:
            return x
        solved.y = face.refine(solved.y, mismatch)
        solved.refinements += 1
    return unconstrained


def contact_violation(penetration: float, tension: float, scale_u: float, scale_mu: float) -> float:
    """An active-set step's violation of the contact conditions: its largest penetration of an open crack
    vertex relative to the displacement scale ``scale_u``, or tension μᶜ < 0 on a closed one relative to the
    traction scale ``scale_mu`` (those of the KKT check, :mod:`ddsolve.dd.constraints`; 0 when nothing is
    violated)."""
    return max(constraints.scale_free_ratio(penetration, scale_u), constraints.scale_free_ratio(tension, scale_mu))


def refuse_friction(scene: Scene) -> None:
    """The reference solves non-penetration in the faces' normal jump only: friction is refused in one line."""
    if scene.friction is not None:
        raise SolverError(f"reference: {scene.friction.key} is not solved by the monolithic reference (its contact is "
                          "the crack faces' normal jump only): solve the scene with a multiplier method (solver.method)")


def refuse_bond(scene: Scene) -> None:
    """The reference solves the elastic law (``[interface] law = "elastic"``) as springs between the bonded faces:
    a damaging law, or a bond on a structure of several interfaces, is refused in one line."""
    if scene.bond is None or scene.bond.law == "elastic" and not scene.geometry.above:
        return
    why = ("a structure of several interfaces (geometry.sigma) ties its bonded faces" if scene.geometry.above else
           "its damage is a nonlinear problem on Σ; the reference solves interface.law = \"elastic\" only")
    raise SolverError(f"reference: interface.law = \"{scene.bond.law}\" is not solved by the monolithic reference "
                      f"({why}): solve the scene with solver.method = \"schur\", \"mprgp\" or \"fista\"")


def solve_assembled(scene: Scene, mesh: Mesh, systems: list[BlockSystem],
                    table: supports.SigmaSupports | None = None) -> Result:
    """The scene's discrete problem from its assembled ``systems`` (Σ supports ``table``, made from the mesh if
    not given), with the KKT check; timings per phase of :data:`PHASES` (wall and ``_cpu``), ``total`` their sum."""
    refuse_friction(scene)
    refuse_bond(scene)
    table = table if table is not None else supports.sigma_supports(scene, mesh)
    interface = for_mesh(mesh.sigma, scene.nonpenetration, table.fixed, assembly.modulus(scene),
                         assembly.data_displacement(scene, mesh.halves, mesh.sigma),
                         specs=meshes.blocks(scene.geometry.layers), bond=scene.bond)
    solved = solve_glued(systems, interface, out_of_core=scene.solver.out_of_core)
    fields, contact = solved.fields, interface.slices["mu_c"]
    steps, changes = (solved.face.violations, solved.face.changes) if solved.face else ([(0.0, 0.0)], [0])
    lam = interface.multipliers(np.array([assembly.csr_matvec(s, u)[s.trace_dofs] - s.rhs[s.trace_dofs]
                                          for s, u in zip(systems, fields)]))
    lam[contact] = solved.y / np.sqrt(interface.row_weights[contact])  # exactly 0 on open vertices
    traces = np.array([u[s.trace_dofs] for s, u in zip(systems, fields)])
    largest = analysis.largest_displacement(u.reshape(-1, 2) for u in fields)
    checked = constraints.kkt(interface, traces, lam, None,
                              np.array([analysis.block_residual(s, u, load)
                                        for s, u, load in zip(systems, fields, interface.loads(lam))]), largest)
    violations = checked.violations(constraints.kkt_tolerance(None))
    message = (f"reference: the solution violates {', '.join(violations)} (scale-free tolerance "
               f"{constraints.kkt_tolerance(None):g}): the problem is too ill-conditioned for double precision"
               if violations else "")
    scale_u = constraints.displacement_scale(interface, largest)
    scale_mu = constraints.traction_scale(interface, lam, scale_u)
    energy = sum(0.5 * u @ assembly.csr_matvec(s, u) - s.rhs @ u + s.energy_offset for s, u in zip(systems, fields))
    total = sum(solved.timings[name] for name in PHASES)
    return Result.from_blocks(
        scene, "reference", mesh, fields, interface, lam, converged=not violations, iterations=len(steps),
        solves=solved.solves, wall_time=total, ranks=1,
        history=np.array([contact_violation(*step, scale_u, scale_mu) for step in steps]),
        active_set_changes=np.array(changes, dtype=np.int64),
        timings={**solved.timings, "total": total}, message=message,
        attrs={**provenance(), **meshes.quality(mesh), "closed_vertices": int(np.count_nonzero(solved.y)),
               "energy": float(energy), "factors_out_of_core": solved.out_of_core, "refined": solved.refinements,
               "kkt_tolerance": constraints.kkt_tolerance(None),
               **{f"kkt_{name}": getattr(checked, name) for name in constraints.Constraints.NAMES}})


def solve_monolithic(scene: Scene, mesh: Mesh, factors: np.ndarray | None = None) -> Result:
    """Solve the scene's discrete problem exactly; return it in the result schema (``factors``: the tips'
    critical load factors where a root solve found them, see :func:`ddsolve.post.toughness.judge`)."""
    tips, table, _ = whole_mesh_checks(scene, mesh)  # the solver's checks: a structure that can move is refused
    result = solve_assembled(scene, mesh, assembly.block_systems(scene, mesh, table=table), table)
    estimated = estimate.of_scene(scene, mesh, result.solution, result.multipliers["mu_c"])
    result.attrs["error_estimate"], result.indicators = estimated.relative, estimated.indicators
    result.fracture = fracture.of_result(result, tips, factors)
    result.reactions = reactions.reactions(scene, mesh, result.solution, table)
    result.claim()
    return result
