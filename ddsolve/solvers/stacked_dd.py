"""The domain decomposition of a structure of several interfaces (``geometry.sigma = [y1, y2, ...]``).

The blocks are the layers × regions of :func:`ddsolve.solvers.stacked.block_names`, one per rank, several per rank
or several ranks per block (:class:`~ddsolve.parallel.exchange.Exchange`).  The structure's trace is the
interfaces' traces concatenated, bottom to top; a block holds the entries of the Σ below and the Σ above it
(its *positions*), and its own trace is its dofs there, in that order.  The rounds send and return the structure's
trace (:class:`~ddsolve.parallel.rounds.BlockServer` with ``positions``), so the multiplier methods work on the
one :class:`~ddsolve.dd.interface.Interface` of every interface (:meth:`Interface.joined`) as they do on one Σ.
The mesh is built once on rank 0 and broadcast; each rank assembles only its blocks (or its rows of one); rank 0
gathers the blocks' displacements and finishes the same :class:`~ddsolve.solvers.stacked.StackResult` as the
monolithic reference (:func:`ddsolve.solvers.stacked.stack_result`).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ddsolve.dd import kernels, registry
from ddsolve.dd.interface import Interface
from ddsolve.errors import DDSolveError, SceneError
from ddsolve.fem import assembly, supports
from ddsolve.io import hdf5
from ddsolve.mesh import geometry, stack
from ddsolve.mesh.mesh import BlockSpec, Mesh
from ddsolve.parallel.blocks import Block
from ddsolve.parallel.exchange import Exchange, collective
from ddsolve.parallel.launch import supported, usable
from ddsolve.parallel.rounds import BlockServer
from ddsolve.problem.scene import Scene
from ddsolve.solvers import driver, stacked
from ddsolve.solvers.reference import Joint
from ddsolve.solvers.stacked import StackResult


@dataclass
class StackSetup:
    """What every rank holds after assembly and factorization (as :class:`ddsolve.solvers.driver.Setup` does for
    one interface): the whole mesh, its joints and views, this rank's factored blocks, each local block's positions
    in the structure's trace, and the interface of every interface (rank 0 runs the method on it)."""

    scene: Scene  # with the method resolved
    mesh: Mesh
    joints: list[Joint]
    seen: list[tuple[Scene, Mesh]]
    exchange: Exchange
    blocks: list[Block]
    positions: dict[int, np.ndarray]
    interface: Interface
    stages: dict
    timings: dict[str, float]

    @property
    def trace_stiffness(self) -> None:
        """Not gathered: this driver's feti takes Dirichlet's preconditioner."""
        return None

    def trace_entries(self) -> list[np.ndarray]:
        """Each block's entries of the structure's trace."""
        return trace_layout(self.joints, self.exchange.n_blocks)[0]

    def kernel_traces(self) -> None:
        """No block floats (:func:`prepare` refuses it)."""
        return None

    def destroy(self) -> None:
        for block in self.blocks:
            block.destroy()
        self.exchange.free()


def method_of(scene: Scene, floating: list[str]) -> Scene:
    """The scene with ``auto`` resolved (``schur``, the exact solve); in one line, what this solve does not take:
    a bond, friction, adaptivity, a method that needs blocks whose supports hold them alone (``floating``: those
    held only through Σ, for every method: their kernels are not built here)."""
    if scene.friction is not None:
        raise SceneError(f"{scene.friction.key}: friction on the cracks of several interfaces is not solved yet")
    if scene.bond is not None:
        raise SceneError("interface.law: a bond on several interfaces is not solved yet")
    if scene.mesh.target_error is not None:
        raise SceneError("mesh.target_error: adaptive refinement of a structure of several interfaces is not done yet")
    if floating:
        raise SceneError(f"geometry.clamped: blocks {', '.join(floating)} of the structure of several interfaces are "
                         "held only through Σ (floating), which its domain decomposition does not solve yet: support "
                         "every region, or use ddsolve reference")
    method = scene.solver.method if scene.solver.method in registry.METHODS else "schur"
    return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=method))


def floating_blocks(mesh: Mesh, names: list[tuple[str, str, int]], fixed: list[np.ndarray]) -> list[str]:
    """The blocks whose own prescribed dofs ``fixed`` leave them a rigid motion."""
    _, rows = stacked.support_rows(mesh, names, fixed)
    return [name for (name, _, _), block_rows in zip(names, rows) if kernels.null_space(block_rows, 3).shape[1]]


def trace_layout(joints: list[Joint], count: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per block of ``count``: its positions in the structure's trace (each interface's entries after those of the
    interfaces below it) and its dofs there, the Σ below first."""
    positions, dofs = [[] for _ in range(count)], [[] for _ in range(count)]
    first = 0
    for joint in joints:
        size = joint.interface.trace_size
        for block, block_dofs in zip(joint.blocks, joint.dofs):
            positions[block].append(first + np.arange(size))
            dofs[block].append(block_dofs)
        first += size
    return [np.concatenate(p) for p in positions], [np.concatenate(d) for d in dofs]


def whole_mesh(scene: Scene, comm: MPI.Comm) -> Mesh:
    """The scene's mesh, built and checked on rank 0, on every rank."""
    def build() -> Mesh:
        mesh = stack.build_any(scene)
        geometry.check_loads(scene, mesh)
        supports.check(scene, mesh)
        return mesh

    return comm.bcast(collective(comm, build, root_only=True), root=0)


def prepare(scene: Scene, comm: MPI.Comm) -> StackSetup:
    """Build the mesh, assemble and factor every rank's blocks (collective: the refusals too)."""
    started = time.perf_counter()
    count = scene.geometry.layers * len(scene.geometry.region_names)
    if not supported(comm.size, count):
        error = DDSolveError(f"unsupported number of ranks {comm.size}: use {usable(count)} (the {count} blocks of "
                             "the structure of several interfaces)")
        error.collective = True  # every rank sees the same size
        raise error
    mesh = whole_mesh(scene, comm)
    joints, seen, held = collective(comm, lambda: stacked.joined(scene, mesh))
    names = stacked.block_names(scene.geometry.layers, len(mesh.regions))
    scene = collective(comm, lambda: method_of(scene, floating_blocks(mesh, names, [f for f, _ in held])))
    method = registry.METHODS[scene.solver.method]
    exchange = Exchange(comm, len(names))
    positions, dofs = trace_layout(joints, len(names))
    stages = {name: PETSc.Log.Stage(name) for name in driver.STAGES}
    timings = {"setup": time.perf_counter() - started}

    def make() -> list[Block]:
        made = []
        for index, group in zip(exchange.local_blocks, exchange.groups):
            rows = None if group.size == 1 else assembly.row_ranges(
                len(mesh.regions[names[index][2]].points), group.size)[group.rank]
            system = stacked.block_system(scene, mesh, names[index], held[index], rows)
            made.append(Block(dataclasses.replace(system, trace_dofs=dofs[index]), comm=PETSc.Comm(group),
                              factor_package=method.factorization))
            made[-1].factor(schur=method.schur_complements, out_of_core=scene.solver.out_of_core)
            if method.dirichlet:
                made[-1].factor_dirichlet(out_of_core=scene.solver.out_of_core)
        return made

    blocks = collective(comm, make)
    timings["factorization"] = time.perf_counter() - started - timings["setup"]
    specs = tuple(BlockSpec(name, layer, 0) for name, layer, _ in names)
    interface = Interface.joined([joint.interface for joint in joints], [joint.blocks for joint in joints], specs)
    return StackSetup(scene, mesh, joints, seen, exchange, blocks,
                      {index: positions[index] for index in exchange.local_blocks}, interface, stages, timings)


def solve(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print) -> StackResult | None:
    """The domain decomposition of the structure of several interfaces ``scene`` on ``comm``; ``output`` written
    (:func:`ddsolve.io.hdf5.write_stack`).  The result on rank 0 (None elsewhere); a method that does not converge
    writes its result with converged = false and raises NotConvergedError on every rank, with the result."""
    started = time.perf_counter()
    setup = prepare(scene, comm)
    try:
        sizes = [2 * len(setup.mesh.regions[region].points)
                 for _, _, region in stacked.block_names(setup.scene.geometry.layers, len(setup.mesh.regions))]
        return driver.gathered_solve(setup, BlockServer(setup.blocks, setup.exchange, positions=setup.positions), sizes,
                                     lambda outcome, rounds, fields: finished(setup, outcome, rounds, fields, comm.size),
                                     hdf5.write_stack, output, started, progress)
    finally:
        setup.destroy()


def finished(setup: StackSetup, outcome, rounds, fields: list[np.ndarray], ranks: int) -> StackResult:
    """Rank 0: the method's ``outcome`` as the reference's record: each interface's multipliers (its rows of the
    structure's), the blocks' residuals and the potential energy of the final round."""
    interface, run = setup.interface, outcome
    lams = [run.lam[rows] for rows in interface.part_rows]
    record = stacked.Run(setup.scene.solver.method, ranks, run.iterations, rounds.count,
                         np.array(run.active_set_changes, dtype=np.int64), lambda *_: np.array(run.history),
                         dict(setup.timings), setup.scene.solver)
    result = stacked.stack_result(setup.scene, setup.mesh, setup.seen, setup.joints, fields, lams,
                                  list(rounds.residuals), float(run.details["energy"]), record)
    if not run.converged:
        result.converged, result.message = False, "; ".join(m for m in (run.message, result.message) if m)
    return result
