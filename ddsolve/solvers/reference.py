"""The monolithic reference: the same discrete problem as one system, solved exactly.

All nodal equalities are imposed by giving tied degrees of freedom one unknown (u⁻ = u⁺ on glued
vertices, u± = v± everywhere on Σ); non-penetration on crack vertices is handled by a primal-dual
active set method: an active vertex ties the normal displacements of the two crack faces, an
inactive one leaves them free; the contact multiplier μᶜ comes from the block residuals.  Each
active-set step is one sparse Cholesky factorization (KSP prefix ``reference_``).
"""
from __future__ import annotations

import time

import numpy as np

from ddsolve.dd import constraints
from ddsolve.dd.interface import Interface, for_mesh
from ddsolve.errors import SolverError
from ddsolve.fem import assembly
from ddsolve.fem.assembly import BlockSystem, coo_to_csr
from ddsolve.mesh import mesh as meshes
from ddsolve.mesh.mesh import Mesh
from ddsolve.parallel.blocks import Block
from ddsolve.parallel.distribution import whole_mesh_checks
from ddsolve.parallel.launch import provenance
from ddsolve.post import analysis, estimate, fracture, reactions
from ddsolve.post.result import Result
from ddsolve.problem.scene import Scene

MAX_ACTIVE_SET_STEPS = 100


def contact_violation(penetration: np.ndarray, mu_c: np.ndarray, closed: np.ndarray, scale_u: float,
                      scale_mu: float) -> float:
    """The active-set step's stopping criterion: the largest penetration of an open crack vertex
    relative to the displacement scale ``scale_u``, or tension μᶜ < 0 on a closed one relative to the traction
    scale ``scale_mu`` (those of the KKT check, :mod:`ddsolve.dd.constraints`; 0 when nothing is violated).
    The active set changes while it exceeds 1e-12."""
    def relative(values: np.ndarray, scale: float) -> float:
        largest = float(np.max(values, initial=0.0))
        return largest / scale if largest > 0.0 else 0.0

    return max(relative(penetration[~closed], scale_u), relative(-mu_c[closed], scale_mu))


def numbering(systems: list[BlockSystem], interface: Interface, closed: np.ndarray) -> list[np.ndarray]:
    """Global unknown of every block dof; tied dofs share one.  ``closed``: crack vertices in contact."""
    traces = interface.trace_unknowns(closed)
    following = traces.max(initial=-1) + 1
    numbers = []
    for system, trace in zip(systems, traces):
        number = np.full(system.size, -1, dtype=np.int64)
        number[system.trace_dofs] = trace
        own = number < 0
        number[own] = following + np.arange(own.sum())
        following += own.sum()
        numbers.append(number)
    return numbers


def merged_system(systems: list[BlockSystem], numbers: list[np.ndarray]) -> BlockSystem:
    """Pᵀ diag(K_b) P and Pᵀ f for the numbering P."""
    size = int(max(n.max() for n in numbers)) + 1
    rows, cols, values, rhs = [], [], [], np.zeros(size)
    for system, number in zip(systems, numbers):
        local_rows = np.repeat(np.arange(system.size), np.diff(system.indptr))
        rows.append(number[local_rows])
        cols.append(number[system.indices])
        values.append(system.data)
        rhs += np.bincount(number, system.rhs, minlength=size)
    indptr, indices, data = coo_to_csr(size, np.concatenate(rows), np.concatenate(cols), np.concatenate(values))
    return BlockSystem("reference", indptr, indices, data, rhs, np.zeros(0, dtype=np.int64), size, block_size=1)


def solve_monolithic(scene: Scene, mesh: Mesh, factors: np.ndarray | None = None) -> Result:
    """Solve the scene's discrete problem exactly; return it in the result schema (``factors``: the tips'
    critical load factors where a root solve found them, see :func:`ddsolve.post.toughness.judge`)."""
    tips, table, _ = whole_mesh_checks(scene, mesh)  # the solver's checks: a structure that can move is refused
    systems = assembly.block_systems(scene, mesh, table=table)
    started = time.perf_counter()  # the solve phase: merging, factorizations, active-set steps
    interface = for_mesh(mesh.sigma, scene.nonpenetration, table.fixed, assembly.modulus(scene),
                         assembly.data_displacement(scene, mesh.halves, mesh.sigma))
    contact_rows = interface.slices["mu_c"]
    closed = np.zeros(contact_rows.stop - contact_rows.start, dtype=bool)
    history, changes = [], []
    factorization = 0.0
    for step in range(1, MAX_ACTIVE_SET_STEPS + 1):
        numbers = numbering(systems, interface, closed)
        block = Block(merged_system(systems, numbers))
        mark = time.perf_counter()
        block.factor(out_of_core=scene.solver.out_of_core)
        factorization += time.perf_counter() - mark
        x = block.solve(np.zeros(0), body=True).copy()
        out_of_core = block.out_of_core()  # what MUMPS did (a PETSc option may override the scene)
        block.destroy()
        fields = [x[number] for number in numbers]
        loads = np.array([assembly.csr_matvec(s, u)[s.trace_dofs] - s.rhs[s.trace_dofs]
                          for s, u in zip(systems, fields)])
        lam = interface.multipliers(loads)
        traces = np.array([u[s.trace_dofs] for s, u in zip(systems, fields)])
        penetration = interface.gap(traces)[contact_rows]
        mu_c = lam[contact_rows]
        scale_u = constraints.displacement_scale(interface, float(np.abs(x).max(initial=0.0)))
        scale_mu = constraints.traction_scale(interface, lam, scale_u)
        stays = closed & (mu_c >= -1e-12 * scale_mu)
        enters = ~closed & (penetration > 1e-12 * scale_u)
        changed = closed != (stays | enters)
        history.append(contact_violation(penetration, mu_c, closed, scale_u, scale_mu))
        changes.append(int(changed.sum()))
        if not changed.any():
            break
        closed = stays | enters
    else:
        raise SolverError(f"reference: the active set did not settle in {MAX_ACTIVE_SET_STEPS} steps")
    elapsed = time.perf_counter() - started
    lam[contact_rows][~closed] = 0.0  # open rows carry no pressure: exactly, not the residuals' round-off
    energy = sum(0.5 * u @ assembly.csr_matvec(s, u) - s.rhs @ u + s.energy_offset
                 for s, u in zip(systems, fields))
    checked = constraints.kkt(interface, traces, lam, None,
                           np.array([analysis.block_residual(s, u, load)
                                     for s, u, load in zip(systems, fields, interface.loads(lam))]),
                           analysis.largest_displacement(u.reshape(-1, 2) for u in fields))
    violations = checked.violations(constraints.kkt_tolerance(None))
    message = (f"reference: the solution violates {', '.join(violations)} (scale-free tolerance "
               f"{constraints.kkt_tolerance(None):g}): the problem is too ill-conditioned for double precision"
               if violations else "")
    result = Result.from_blocks(
        scene, "reference", mesh, fields, interface, lam, converged=not violations, iterations=step,
        solves=step, wall_time=elapsed, ranks=1, history=np.array(history),
        active_set_changes=np.array(changes, dtype=np.int64),
        timings={"factorization": factorization, "total": elapsed}, message=message,
        attrs={**provenance(), **meshes.quality(mesh), "closed_vertices": int(closed.sum()), "energy": float(energy),
               "factors_out_of_core": out_of_core,
               "kkt_tolerance": constraints.kkt_tolerance(None),
               **{f"kkt_{name}": getattr(checked, name) for name in constraints.Constraints.NAMES}})
    estimated = estimate.of_scene(scene, mesh, result.solution, result.multipliers["mu_c"])
    result.attrs["error_estimate"], result.indicators = estimated.relative, estimated.indicators
    result.fracture = fracture.of_result(result, tips, factors)
    result.reactions = reactions.reactions(scene, mesh, result.solution, table)
    result.claim()
    return result
