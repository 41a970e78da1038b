"""The domain-decomposition solve: scene -> meshes -> blocks on ranks -> multiplier method -> result.

Rank 0 reads the scene and builds the meshes; every rank assembles and factors the blocks it owns;
rank 0 runs the multiplier method while the other ranks serve rounds of block solves
(:func:`serve`); rank 0 gathers the block solutions and writes the result.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import assembly, io, mesh, methods
from .blocks import Block
from .errors import DDSolveError, DivergedError, NotConvergedError, SolverError
from .exchange import Exchange, collective
from .interface import BLOCKS, Interface
from .scene import Scene

STOP, SOLVE_LOAD, SOLVE_FULL, SCHUR, REPORT_ERROR = range(5)
SUPPORTED_RANKS = (1, 2, 4)


class BlockServer:
    """The blocks this rank owns and what a round does with them."""

    def __init__(self, blocks: list[Block]):
        self.blocks = blocks
        self.solutions: list[np.ndarray] = [np.zeros(0)] * len(blocks)
        self.error = ""

    def run(self, command: int, loads: np.ndarray | None) -> np.ndarray:
        """One round on the local blocks; each result row ends with a status flag (0 ok, 1 failed)."""
        try:
            if command == SCHUR:
                rows = [block.schur_complement().ravel() for block in self.blocks]
            else:
                rows = [self._solve(i, load, command == SOLVE_FULL) for i, load in enumerate(loads)]
            return np.array([np.append(row, 0.0) for row in rows])
        except DDSolveError as exc:
            self.error = str(exc)
            width = (loads.shape[1] + 1) if loads is not None else len(self.blocks[0].trace_dofs) ** 2
            failed = np.full((len(self.blocks), width + 1), np.nan)
            failed[:, -1] = 1.0
            return failed

    def _solve(self, i: int, load: np.ndarray, full: bool) -> np.ndarray:
        block = self.blocks[i]
        x = block.solve(load, body=full)
        energy = float(np.dot(x, block.rhs.getArray(readonly=True)))
        if full:
            self.solutions[i] = x.copy()
        return np.append(x[block.trace_dofs], energy)


class ParallelRounds:
    """Rank 0's implementation of :class:`~ddsolve.methods.Rounds` over an :class:`Exchange`.

    Between rounds rank 0 is updating multipliers: that time is logged in the PETSc stage
    ``Update``, the rounds themselves in ``Rounds``.
    """

    def __init__(self, exchange: Exchange, server: BlockServer, trace_size: int, stages: dict):
        self.exchange, self.server, self.trace_size, self.stages = exchange, server, trace_size, stages
        self.count = 0
        self.elapsed = 0.0  # seconds inside rounds

    def _round(self, command: int, loads: np.ndarray | None) -> np.ndarray:
        self.stages["Update"].pop()
        self.stages["Rounds"].push()
        started = time.perf_counter()
        self.exchange.command(command)
        local = None
        if loads is not None:
            local = self.exchange.scatter(loads, self.trace_size)
        results = self.exchange.gather(self.server.run(command, local))
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
        return results[:, :-1], results[:, -1]

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
        exchange.gather(server.run(command, local))
    stages["Rounds"].pop()


#: Default block factorization per method.  The iterative methods make one solve per round with one
#: factorization, where PETSc's own Cholesky is about 3x faster than MUMPS; ``schur`` needs MUMPS for
#: the Schur complements (``./run bench factor`` measures both).
FACTOR_PACKAGE = {"uzawa": "petsc", "fista": "petsc", "mprgp": "petsc", "schur": "mumps"}
STAGES = ("Setup", "Factorization", "Rounds", "Update", "Output")


def run_method(scene: Scene, exchange: Exchange, server: BlockServer, interface: Interface, stages: dict,
               progress) -> tuple[methods.Outcome | None, ParallelRounds | None, DDSolveError | None]:
    """Rank 0 runs the multiplier method (then the final round); the others serve rounds."""
    if not exchange.is_root:
        serve(exchange, server, interface.trace_size, stages)
        return None, None, None
    rounds = ParallelRounds(exchange, server, interface.trace_size, stages)
    outcome, failure = None, None
    stages["Update"].push()
    try:
        method = scene.solver.method
        outcome = methods.METHODS[method](rounds, interface, scene.solver, methods.Progress(method, out=progress))
        if not outcome.diverged:
            rounds.solve(interface.loads(outcome.lam), full=True)  # the displacements for λ
    except DDSolveError as exc:
        failure = exc
    else:
        if outcome.diverged:
            failure = DivergedError(outcome.message)
        elif not outcome.converged:
            failure = NotConvergedError(outcome.message)
    finally:
        stages["Update"].pop()
    rounds.stop()
    return outcome, rounds, failure


def peak_memory_mb() -> float:
    """This process's peak resident memory so far, in MB."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


@dataclass
class Setup:
    """What every rank holds after assembly and factorization."""

    lower: mesh.HalfMesh
    upper: mesh.HalfMesh
    exchange: Exchange
    blocks: list[Block]
    interface: Interface
    stages: dict
    timings: dict

    def destroy(self) -> None:
        for block in self.blocks:
            block.destroy()


def prepare(scene: Scene, comm: MPI.Comm, meshes: tuple[mesh.HalfMesh, mesh.HalfMesh] | None = None) -> Setup:
    """Build (or take) the meshes on rank 0, assemble and factor every rank's blocks."""
    if comm.size not in SUPPORTED_RANKS:
        error = DDSolveError(f"unsupported number of ranks {comm.size}: use 1, 2 or 4")
        error.collective = True  # every rank sees the same size
        raise error
    timings: dict[str, float] = {}
    stages = {name: PETSc.Log.Stage(name) for name in STAGES}
    method = scene.solver.method

    mark = time.perf_counter()
    stages["Setup"].push()
    if meshes is None:
        meshes = comm.bcast(collective(comm, lambda: mesh.build(scene), root_only=True), root=0)
    lower, upper = meshes
    exchange = Exchange(comm, len(BLOCKS))
    blocks = collective(comm, lambda: [
        Block(system, factor_package=FACTOR_PACKAGE[method])
        for system in assembly.block_systems(scene, lower, upper, exchange.local_blocks)])
    interface = Interface(lower.points[lower.sigma(), 0], scene.crack, scene.contact)
    stages["Setup"].pop()
    timings["setup"] = time.perf_counter() - mark

    mark = time.perf_counter()
    stages["Factorization"].push()
    collective(comm, lambda: [block.factor(schur=method == "schur") for block in blocks])
    comm.Barrier()
    stages["Factorization"].pop()
    timings["factorization"] = time.perf_counter() - mark
    return Setup(lower, upper, exchange, blocks, interface, stages, timings)


def bound(scene: Scene, comm: MPI.Comm, meshes=None, iterations: int = 300) -> float:
    """λmax of the dual operator C K⁻¹ Cᵀ W by power iteration (one round each); 2/λmax bounds Uzawa's θ."""
    setup = prepare(scene, comm, meshes)
    server = BlockServer(setup.blocks)
    estimate = None
    if setup.exchange.is_root:
        rounds = ParallelRounds(setup.exchange, server, setup.interface.trace_size, setup.stages)
        setup.stages["Update"].push()
        problem = methods.DualProblem(rounds, setup.interface, scene.solver)
        estimate = methods.largest_eigenvalue(problem.apply, setup.interface.size, iterations, tolerance=1e-9)
        setup.stages["Update"].pop()
        rounds.stop()
    else:
        serve(setup.exchange, server, setup.interface.trace_size, setup.stages)
    setup.destroy()
    return comm.bcast(estimate, root=0)


def solve(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, meshes=None) -> io.Result | None:
    """Run the domain decomposition for ``scene`` on ``comm``; write ``output`` on rank 0.

    Returns the result on rank 0 (None elsewhere).  A run that reaches max_iterations writes its
    result with converged = false and then raises NotConvergedError on every rank.  ``meshes``
    (on every rank) skips building them.
    """
    setup = prepare(scene, comm, meshes)
    lower, upper, exchange, blocks, interface, stages, timings = (
        setup.lower, setup.upper, setup.exchange, setup.blocks, setup.interface, setup.stages, setup.timings)
    method = scene.solver.method

    try:
        mark = time.perf_counter()
        server = BlockServer(blocks)
        outcome, rounds, failure = run_method(scene, exchange, server, interface, stages, progress)
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            failure.collective = True
        timings["iterations"] = time.perf_counter() - mark
        if failure is not None and not isinstance(failure, NotConvergedError):
            raise failure

        mark = time.perf_counter()
        stages["Output"].push()
        sizes = [2 * len((lower if spec.side < 0 else upper).points) for spec in BLOCKS]
        solutions = exchange.gather_varying(server.solutions, sizes)
        memory = comm.gather(peak_memory_mb(), root=0)
        result = None
        if exchange.is_root:
            timings["update"] = timings["iterations"] - rounds.elapsed
            result = io.Result(
                scene=scene.text, method=method, converged=outcome.converged, iterations=outcome.iterations,
                solves=rounds.count, wall_time=timings["factorization"] + timings["iterations"], ranks=comm.size,
                lower=lower, upper=upper, solution={spec.name: x.reshape(-1, 2) for spec, x in zip(BLOCKS, solutions)},
                interface_x=interface.x, crack=interface.crack, multipliers=interface.split(outcome.lam),
                history=np.array(outcome.history), timings=timings, message=outcome.message,
                attrs={**io.provenance(), "stop": scene.solver.stop, "tol": scene.solver.tol,
                       "peak_memory_mb": memory, **outcome.details},
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
