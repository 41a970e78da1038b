"""The domain-decomposition solve: scene -> meshes -> blocks on ranks -> multiplier method -> result.

Rank 0 reads the scene; two ranks mesh a half each; every rank assembles and factors the blocks (or
the rows of a block) it owns; rank 0 runs the multiplier method while the other ranks serve rounds of
block solves (:func:`serve`); rank 0 gathers the block solutions and writes the result.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import assembly, estimate, geometry, io, methods
from .blocks import Block
from .errors import DDSolveError, DivergedError, NotConvergedError, SolverError
from .exchange import Exchange, collective
from .interface import BLOCKS, Interface, for_mesh
from .mesh import Mesh
from .result import Result
from .scene import Scene

STOP, SOLVE_LOAD, SOLVE_FULL, SCHUR, REPORT_ERROR = range(5)


def result_width(command: int, trace_size: int) -> int:
    """Values per block a round returns (before the status flag): a Schur complement, or the trace,
    the energy xᵀ K x and the work of the body loads."""
    return trace_size ** 2 if command == SCHUR else trace_size + 2


class BlockServer:
    """The blocks this rank works on and what a round does with them."""

    def __init__(self, blocks: list[Block], exchange: Exchange):
        self.blocks, self.exchange = blocks, exchange
        self.solutions: dict[int, np.ndarray] = {}  # led blocks' solutions from the last full solve
        self.error = ""

    def run(self, command: int, loads: list[np.ndarray] | None, width: int) -> np.ndarray:
        """One round on the local blocks: the rows of the led blocks, each ending with a status flag."""
        rows, failed = {}, False
        try:
            for i, (index, block) in enumerate(zip(self.exchange.local_blocks, self.blocks)):
                if command == SCHUR:
                    value = block.schur_complement()
                else:
                    value = self._solve(index, block, loads[i], full=command == SOLVE_FULL)
                if block.is_leader:
                    rows[index] = value
        except DDSolveError as exc:
            self.error, failed = str(exc), True
        # Every rank of a block learns whether one of them failed (PETSc errors are collective anyway).
        for group in self.exchange.groups:
            if group.size > 1:
                failed = group.allreduce(failed, op=MPI.LOR)
        out = np.full((len(self.exchange.led_blocks), width + 1), np.nan)
        out[:, -1] = float(failed)
        if not failed:
            for i, index in enumerate(self.exchange.led_blocks):
                out[i, :-1] = rows[index].ravel()
        return out

    def _solve(self, index: int, block: Block, load: np.ndarray, full: bool) -> np.ndarray | None:
        x = block.solve(load, body=full)
        trace, energies = block.trace(x), block.energies()
        if full:
            whole = block.gather(x)
            if block.is_leader:
                self.solutions[index] = whole
        return np.concatenate([trace, energies]) if block.is_leader else None


class ParallelRounds:
    """Rank 0's implementation of :class:`~ddsolve.methods.Rounds` over an :class:`Exchange`.

    Between rounds rank 0 is updating multipliers: that time is logged in the PETSc stage
    ``Update``, the rounds themselves in ``Rounds``.
    """

    def __init__(self, exchange: Exchange, server: BlockServer, trace_size: int, stages: dict):
        self.exchange, self.server, self.trace_size, self.stages = exchange, server, trace_size, stages
        self.count = 0
        self.elapsed = 0.0  # seconds inside rounds
        self.work = np.zeros(len(BLOCKS))  # work of the body loads in the last solve

    def _round(self, command: int, loads: np.ndarray | None) -> np.ndarray:
        self.stages["Update"].pop()
        self.stages["Rounds"].push()
        started = time.perf_counter()
        self.exchange.command(command)
        local = None
        if loads is not None:
            local = self.exchange.scatter(loads, self.trace_size)
        width = result_width(command, self.trace_size)
        results = self.exchange.gather(self.server.run(command, local, width), width + 1)
        self.count += 1
        if np.any(results[:, -1] != 0.0):
            self.exchange.command(REPORT_ERROR)
            messages = self.exchange.comm.gather(self.server.error, root=0)
            raise SolverError(next(m for m in messages if m))
        self.elapsed += time.perf_counter() - started
        self.stages["Rounds"].pop()
        self.stages["Update"].push()
        return results[:, :-1]

    def solve(self, loads: np.ndarray, full: bool) -> tuple[np.ndarray, np.ndarray]:
        results = self._round(SOLVE_FULL if full else SOLVE_LOAD, loads)
        self.work = results[:, -1]
        return results[:, :-2], results[:, -2]

    def potential_energy(self, energies: np.ndarray) -> float:
        """Π = Σ_b ½ x_bᵀ K_b x_b − f_bᵀ x_b of the last full solve, whose energies are given."""
        return float(0.5 * energies.sum() - self.work.sum())

    def schur_complements(self) -> np.ndarray:
        return self._round(SCHUR, None).reshape(-1, self.trace_size, self.trace_size)

    def stop(self) -> None:
        self.exchange.command(STOP)


def serve(exchange: Exchange, server: BlockServer, trace_size: int, stages: dict) -> None:
    """Worker loop: answer rank 0's rounds until it says STOP."""
    stages["Rounds"].push()
    while True:
        command = exchange.command()
        if command == STOP:
            break
        if command == REPORT_ERROR:
            exchange.comm.gather(server.error, root=0)
            continue
        local = exchange.scatter(None, trace_size) if command in (SOLVE_LOAD, SOLVE_FULL) else None
        width = result_width(command, trace_size)
        exchange.gather(server.run(command, local, width), width + 1)
    stages["Rounds"].pop()


#: Default block factorization per method.  The iterative methods make one solve per round with one
#: factorization, where PETSc's own Cholesky is about 3x faster than MUMPS; ``schur`` needs MUMPS for
#: the Schur complements (``./run bench factor`` measures both).
FACTOR_PACKAGE = {"uzawa": "petsc", "fista": "petsc", "mprgp": "petsc", "schur": "mumps"}
STAGES = ("Setup", "Factorization", "Rounds", "Update", "Output")


def drive(setup: "Setup", server: BlockServer, work) -> tuple[object, ParallelRounds | None, DDSolveError | None]:
    """Rank 0 runs ``work(rounds)`` (its time between rounds is the Update stage) while the other
    ranks serve rounds; rank 0 always sends STOP, so an error there cannot leave the others waiting.
    Returns (value, rounds, error) on rank 0 and (None, None, None) elsewhere."""
    exchange, stages = setup.exchange, setup.stages
    if not exchange.is_root:
        serve(exchange, server, setup.interface.trace_size, stages)
        return None, None, None
    rounds = ParallelRounds(exchange, server, setup.interface.trace_size, stages)
    value, failure = None, None
    stages["Update"].push()
    try:
        value = work(rounds)
    except DDSolveError as exc:
        failure = exc
    finally:
        stages["Update"].pop()
    rounds.stop()
    return value, rounds, failure


def run_method(scene: Scene, setup: "Setup", server: BlockServer, progress):
    """The scene's multiplier method on rank 0, then the final round; (outcome, rounds, failure)."""
    interface = setup.interface

    def work(rounds):
        method = scene.solver.method
        outcome = methods.METHODS[method](rounds, interface, scene.solver, methods.Progress(method, out=progress))
        if not outcome.diverged:
            _, energies = rounds.solve(interface.loads(outcome.lam), full=True)  # the displacements for λ
            outcome.details["energy"] = rounds.potential_energy(energies)
        return outcome

    outcome, rounds, failure = drive(setup, server, work)
    if failure is None and outcome is not None:
        if outcome.diverged:
            failure = DivergedError(outcome.message)
        elif not outcome.converged:
            failure = NotConvergedError(outcome.message)
    return outcome, rounds, failure


def gather_estimate(scene: Scene, mesh: Mesh, exchange: Exchange, server: BlockServer
                    ) -> dict[str, np.ndarray] | None:
    """Each block's leader computes its error indicators from the last full solve; rank 0 gets them
    (block name -> ``(2, cells)``, see :func:`ddsolve.estimate.block_indicators`), None elsewhere."""
    local = [estimate.block_part(scene, mesh, index, server.solutions[index]).ravel()
             for index in exchange.led_blocks]
    parts = exchange.gather_varying(local, [2 * len(mesh.half(spec.side).cells) for spec in BLOCKS])
    return None if parts is None else {spec.name: part.reshape(2, -1) for spec, part in zip(BLOCKS, parts)}


def peak_memory_mb() -> float:
    """This process's peak resident memory so far, in MB."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


@dataclass
class Setup:
    """What every rank holds after assembly and factorization."""

    mesh: Mesh
    exchange: Exchange
    blocks: list[Block]
    interface: Interface
    stages: dict
    timings: dict

    def destroy(self) -> None:
        for block in self.blocks:
            block.destroy()
        self.exchange.free()


def supported(size: int) -> bool:
    """1, 2 or 4 ranks (whole blocks per rank), or a multiple of 4 (each block on size/4 ranks)."""
    return size in (1, 2) or size % len(BLOCKS) == 0


def build_mesh(scene: Scene, comm: MPI.Comm, background: geometry.SizeMap | None = None) -> Mesh:
    """The scene's mesh on every rank (sized by ``background``, the same on every rank, if given); with 2
    ranks or more the two halves of a box are meshed at once."""
    if scene.mesh.kind != "box" or comm.size == 1:
        built = comm.bcast(collective(comm, lambda: geometry.build(scene, background), root_only=True), root=0)
    else:
        side = {0: -1, 1: 1}.get(comm.rank)
        mine = collective(comm, lambda: geometry.generate_half(scene, side, background) if side else None)
        lower, upper = comm.bcast(mine, root=0), comm.bcast(mine, root=1)
        paired = collective(comm, lambda: geometry.pair(scene, lower, upper), root_only=True)
        sigma = comm.bcast(paired.sigma if comm.rank == 0 else None, root=0)
        built = Mesh(lower, upper, sigma, geometry.origin(scene))
    collective(comm, lambda: geometry.check_loads(scene, built), root_only=True)
    return built


def make_blocks(scene: Scene, mesh: Mesh, exchange: Exchange, package: str) -> list[Block]:
    """Assemble this rank's blocks (or its rows of them) and wrap them in PETSc objects."""
    blocks = []
    for index, group in zip(exchange.local_blocks, exchange.groups):
        half = mesh.half(BLOCKS[index].side)
        rows = assembly.row_ranges(len(half.points), group.size)[group.rank] if group.size > 1 else None
        system = assembly.block_systems(scene, mesh, [index], rows)[0]
        blocks.append(Block(system, comm=PETSc.Comm(group), factor_package=package))
    return blocks


def prepare(scene: Scene, comm: MPI.Comm, mesh: Mesh | None = None) -> Setup:
    """Build (or take) the mesh, assemble and factor every rank's blocks."""
    if not supported(comm.size):
        error = DDSolveError(f"unsupported number of ranks {comm.size}: use 1, 2 or a multiple of 4")
        error.collective = True  # every rank sees the same size
        raise error
    timings: dict[str, float] = {}
    stages = {name: PETSc.Log.Stage(name) for name in STAGES}
    method = scene.solver.method

    mark = time.perf_counter()
    stages["Setup"].push()
    mesh = mesh if mesh is not None else build_mesh(scene, comm)
    exchange = Exchange(comm, len(BLOCKS))
    blocks = collective(comm, lambda: make_blocks(scene, mesh, exchange, FACTOR_PACKAGE[method]))
    interface = for_mesh(mesh.sigma, scene.nonpenetration)
    stages["Setup"].pop()
    timings["setup"] = time.perf_counter() - mark

    mark = time.perf_counter()
    stages["Factorization"].push()
    collective(comm, lambda: [block.factor(schur=method == "schur") for block in blocks])
    comm.Barrier()
    stages["Factorization"].pop()
    timings["factorization"] = time.perf_counter() - mark
    return Setup(mesh, exchange, blocks, interface, stages, timings)


def bound(scene: Scene, comm: MPI.Comm, mesh: Mesh | None = None, iterations: int = 300) -> float:
    """λmax of the dual operator C K⁻¹ Cᵀ W by power iteration (one round each); 2/λmax bounds Uzawa's θ."""
    setup = prepare(scene, comm, mesh)
    try:
        def work(rounds):
            problem = methods.DualProblem(rounds, setup.interface, scene.solver)
            return methods.largest_eigenvalue(problem.apply, setup.interface.size, iterations, tolerance=1e-9)

        estimate, _, failure = drive(setup, BlockServer(setup.blocks, setup.exchange), work)
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            failure.collective = True
            raise failure
        return comm.bcast(estimate, root=0)
    finally:
        setup.destroy()


def solve(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, mesh: Mesh | None = None
          ) -> Result | None:
    """Run the domain decomposition for ``scene`` on ``comm``; write ``output`` on rank 0.

    Returns the result on rank 0 (None elsewhere).  A run that reaches max_iterations writes its
    result with converged = false and then raises NotConvergedError on every rank.  ``mesh``
    (on every rank) skips building it.
    """
    setup = prepare(scene, comm, mesh)
    mesh, exchange, interface, stages, timings = (setup.mesh, setup.exchange, setup.interface, setup.stages,
                                                  setup.timings)
    method = scene.solver.method

    try:
        mark = time.perf_counter()
        server = BlockServer(setup.blocks, exchange)
        outcome, rounds, failure = run_method(scene, setup, server, progress)
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            failure.collective = True
        timings["iterations"] = time.perf_counter() - mark
        if failure is not None and not isinstance(failure, NotConvergedError):
            raise failure

        mark = time.perf_counter()
        parts = gather_estimate(scene, mesh, exchange, server)
        timings["estimate"] = time.perf_counter() - mark

        mark = time.perf_counter()
        stages["Output"].push()
        sizes = [2 * len(mesh.half(spec.side).points) for spec in BLOCKS]
        solutions = exchange.gather_varying([server.solutions[b] for b in exchange.led_blocks], sizes)
        memory = comm.gather(peak_memory_mb(), root=0)
        result = None
        if exchange.is_root:
            timings["update"] = timings["iterations"] - rounds.elapsed
            frames = mesh.sigma.frames[mesh.sigma.multiplier_nodes]
            solution = {spec.name: assembly.to_global(x, assembly.trace_nodes(mesh.half(spec.side), mesh.sigma),
                                                      frames) for spec, x in zip(BLOCKS, solutions)}
            multipliers = interface.split(outcome.lam, frames)
            estimated = estimate.combine(mesh, parts, solution, multipliers["mu_c"])
            result = Result(
                scene=scene.text, method=method, converged=outcome.converged, iterations=outcome.iterations,
                solves=rounds.count, wall_time=timings["factorization"] + timings["iterations"], ranks=comm.size,
                mesh=mesh, solution=solution, multipliers=multipliers,
                history=np.array(outcome.history), timings=timings, message=outcome.message,
                attrs={**io.provenance(), "stop": scene.solver.stop, "tol": scene.solver.tol,
                       "peak_memory_mb": memory, **outcome.details, "error_estimate": estimated.relative},
                indicators=estimated.indicators,
            )
            timings["output"] = time.perf_counter() - mark  # gathering; io.write adds its own "write" time
        if output is not None:
            collective(comm, lambda: io.write(output, result), root_only=True)
        stages["Output"].pop()
        if failure is not None:  # not converged: the result is written with converged = false
            raise failure
        return result
    finally:
        setup.destroy()
