"""The domain-decomposition solve: scene -> meshes -> blocks on ranks -> multiplier method -> result.

Rank 0 reads the scene; the leaders of u⁻ and u⁺ mesh a half each (or rank 0 reads the whole mesh);
each rank receives only the half its blocks live on, and Σ (:func:`local_mesh`); every rank assembles
and factors the blocks (or the rows of a block) it owns; rank 0 runs the multiplier method while the
other ranks serve rounds of block solves (:func:`serve`); rank 0 gathers the block solutions (and the
upper half) and writes the result.  Every phase of the launch is timed, with its CPU time and peak
memory (:class:`Phases`); the result file has them in ``/timings`` and ``/memory``.
"""
from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from . import assembly, estimate, fracture, geometry, io, methods
from .blocks import Block
from .errors import DDSolveError, DivergedError, NotConvergedError, SolverError
from .exchange import Exchange, collective
from .interface import BLOCKS, U_PLUS, Interface, for_mesh
from .launch import supported
from .mesh import HalfMesh, Mesh, SigmaLine
from .result import Result
from .scene import Scene, check_range

STOP, SOLVE_LOAD, SOLVE_FULL, SCHUR, REPORT_ERROR, DIRICHLET, DIAGONAL = range(7)
#: Commands whose round sends a trace vector to every block.
WITH_LOADS = (SOLVE_LOAD, SOLVE_FULL, DIRICHLET)


def result_width(command: int, trace_size: int) -> int:
    """Values per block a round returns (before the status flag): a Schur complement, or the trace,
    the energy xᵀ K x, the work of the body loads, and (full solves) the relative residual and the
    largest nodal |x|."""
    return trace_size ** 2 if command == SCHUR else trace_size + 4


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
                elif command in (DIRICHLET, DIAGONAL):
                    trace = block.dirichlet(loads[i]) if command == DIRICHLET else block.trace_diagonal()
                    value = np.concatenate([trace, np.zeros(width - len(trace))]) if block.is_leader else None
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
        checks = np.zeros(2)
        if full:
            checks = np.array([block.residual(), block.largest_displacement(x)])
            whole = block.gather(x)
            if block.is_leader:
                self.solutions[index] = whole
        return np.concatenate([trace, energies, checks]) if block.is_leader else None


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
        self.residuals = np.zeros(len(BLOCKS))  # relative residuals of the last full solve
        self.largest = 0.0  # largest nodal displacement in the last full solve

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
        trace = self.trace_size
        self.work = results[:, trace + 1]
        if full:
            self.residuals, self.largest = results[:, trace + 2], float(results[:, trace + 3].max())
        return results[:, :trace], results[:, trace]

    def potential_energy(self, energies: np.ndarray) -> float:
        """Π = Σ_b ½ x_bᵀ K_b x_b − f_bᵀ x_b of the last full solve, whose energies are given."""
        return float(0.5 * energies.sum() - self.work.sum())

    def schur_complements(self) -> np.ndarray:
        return self._round(SCHUR, None).reshape(-1, self.trace_size, self.trace_size)

    def dirichlet(self, traces: np.ndarray) -> np.ndarray:
        return self._round(DIRICHLET, traces)[:, :self.trace_size]

    def trace_diagonals(self) -> np.ndarray:
        return self._round(DIAGONAL, None)[:, :self.trace_size]

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
        local = exchange.scatter(None, trace_size) if command in WITH_LOADS else None
        width = result_width(command, trace_size)
        exchange.gather(server.run(command, local, width), width + 1)
    stages["Rounds"].pop()


#: Default block factorization per method.  The iterative methods make one solve per round with one
#: factorization, where PETSc's own Cholesky is about 3x faster than MUMPS; ``schur`` needs MUMPS for
#: the Schur complements (``./run bench factor`` measures both).
FACTOR_PACKAGE = {"uzawa": "petsc", "fista": "petsc", "mprgp": "petsc", "schur": "mumps", "feti": "mumps"}
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
            methods.final_solve(rounds, interface, scene.solver, outcome)  # the displacements for λ, checked
        return outcome

    outcome, rounds, failure = drive(setup, server, work)
    if failure is None and outcome is not None:
        if outcome.diverged:
            failure = DivergedError(outcome.message)
        elif not outcome.converged:
            failure = NotConvergedError(outcome.message)
    return outcome, rounds, failure


def gather_estimate(scene: Scene, mesh: LocalMesh, exchange: Exchange, server: BlockServer
                    ) -> dict[str, np.ndarray] | None:
    """Each block's leader computes its error indicators from the last full solve; rank 0 gets them
    (block name -> ``(2, cells)``, see :func:`ddsolve.estimate.block_indicators`), None elsewhere."""
    local = [estimate.block_part(scene, mesh, index, server.solutions[index]).ravel()
             for index in exchange.led_blocks]
    parts = exchange.gather_varying(local, [2 * mesh.cells[spec.side] for spec in BLOCKS])
    return None if parts is None else {spec.name: part.reshape(2, -1) for spec, part in zip(BLOCKS, parts)}


def peak_memory_mb() -> float:
    """This process's peak resident memory so far, in MB."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


#: Environment variable with the wall-clock time (time.time()) at which ``ddsolve solve -n`` started mpiexec.
LAUNCHED = "DDSOLVE_LAUNCHED"
#: The phases of a launch, in order; their sum is the whole launch (``total``).
PHASES = ("startup", "meshing", "distribution", "assembly", "factorization", "iterations", "estimate", "output",
          "write")


def launch_age() -> float:
    """Seconds since the launch began: since ``ddsolve solve -n`` started mpiexec, else since this
    process started (Linux), else 0."""
    launched = os.environ.get(LAUNCHED)
    if launched:
        try:
            return max(0.0, time.time() - float(launched))
        except ValueError:
            pass
    try:
        with open("/proc/self/stat") as stat, open("/proc/uptime") as uptime:
            started = int(stat.read().rsplit(")", 1)[1].split()[19]) / os.sysconf("SC_CLK_TCK")
            return max(0.0, float(uptime.read().split()[0]) - started)
    except (OSError, ValueError, IndexError):
        return 0.0


def cpu_seconds() -> float:
    """CPU seconds of this process and of its children that ended (gmsh meshes in one)."""
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


class Phases:
    """Wall seconds (this rank's clock), CPU seconds and peak memory at the end of each phase."""

    def __init__(self, startup: float = 0.0):
        self.wall = {"startup": startup}
        self.cpu = {"startup": cpu_seconds()}
        self.peak = {"startup": peak_memory_mb()}
        self._wall, self._cpu = time.perf_counter(), cpu_seconds()

    def end(self, name: str) -> None:
        wall, cpu = time.perf_counter(), cpu_seconds()
        self.wall[name] = self.wall.get(name, 0.0) + wall - self._wall
        self.cpu[name] = self.cpu.get(name, 0.0) + cpu - self._cpu
        self.peak[name] = peak_memory_mb()
        self._wall, self._cpu = wall, cpu

    def skip(self, name: str) -> None:
        """Record phase ``name`` as not done (zero seconds), e.g. a factorization reused."""
        self.wall.setdefault(name, 0.0)
        self.cpu.setdefault(name, 0.0)
        self.peak[name] = peak_memory_mb()


@dataclass(frozen=True, eq=False)
class LocalMesh:
    """What a rank holds of the mesh: the halves its blocks live on, Σ, and the size of both halves."""

    halves: dict[int, HalfMesh]
    sigma: SigmaLine
    nodes: dict[int, int]  # side -> nodes of that half (both sides)
    cells: dict[int, int]  # side -> cells of that half (both sides)
    origin: str
    tips: list = dataclasses.field(default_factory=list)  # the crack tips (fracture.Tip)

    def half(self, side: int) -> HalfMesh:
        return self.halves[side]

    @property
    def nbytes(self) -> int:
        """Bytes of the mesh arrays held here (halves and Σ)."""
        arrays = [getattr(self.sigma, name) for name in ("points", "normals", "weights", "crack", "tip", "clamped",
                                                          "corner")]
        for half in self.halves.values():
            arrays += [half.points, half.cells, half.sigma, *half.boundaries.values()]
        return int(sum(a.nbytes for a in arrays))


def whole(mesh: Mesh, tips: list | None = None) -> LocalMesh:
    """The whole mesh as a rank holding both halves sees it."""
    halves = {-1: mesh.lower, 1: mesh.upper}
    return LocalMesh(halves, mesh.sigma, {side: len(half.points) for side, half in halves.items()},
                     {side: len(half.cells) for side, half in halves.items()}, mesh.origin, tips or [])


@dataclass
class Setup:
    """What every rank holds after assembly and factorization."""

    mesh: LocalMesh
    exchange: Exchange
    blocks: list[Block]
    interface: Interface
    stages: dict
    phases: Phases
    scene: Scene  # with the method resolved

    @property
    def timings(self) -> dict:
        return self.phases.wall

    def destroy(self) -> None:
        for block in self.blocks:
            block.destroy()
        self.exchange.free()


def build_mesh(scene: Scene, comm: MPI.Comm, background: geometry.SizeMap | None = None) -> Mesh:
    """The scene's whole mesh on every rank (sized by ``background``, the same on every rank, if given),
    for experiments and adaptive levels that need it everywhere."""
    exchange = Exchange(comm, len(BLOCKS))
    try:
        mine = local_mesh(scene, comm, exchange, keep_whole=True, background=background)
    finally:
        exchange.free()
    halves = {side: comm.bcast(mine.halves.get(side) if comm.rank == 0 else None, root=0) for side in (-1, 1)}
    return Mesh(halves[-1], halves[1], mine.sigma, mine.origin)


def local_mesh(scene: Scene, comm: MPI.Comm, exchange: Exchange, phases: Phases | None = None,
               keep_whole: bool = False, background: geometry.SizeMap | None = None) -> LocalMesh:
    """Each rank gets the half its blocks live on (both with one rank), Σ, and the crack tips
    (the mesh sized by ``background``, if given).

    A box is meshed by the leaders of u⁻ (rank 0, lower half) and u⁺ (upper half) at once, else
    rank 0 makes the whole mesh.  Rank 0 pairs the halves (checks, Σ, the loads' boundaries), then
    each half goes to the ranks that need it by a broadcast among them.  Rank 0 keeps the upper half
    only with one rank (or ``keep_whole``); it gets it back for output (:func:`gather_upper`).
    """
    rank = comm.rank
    upper_maker = exchange.leader(U_PLUS)
    split = scene.mesh.kind == "box" and comm.size > 1
    if split:
        side = -1 if rank == 0 else 1 if rank == upper_maker else 0
        made = collective(comm, lambda: geometry.generate_half(scene, side, background) if side else None)
        if rank == upper_maker:
            comm.send(made, dest=0)
        halves = {-1: made, 1: comm.recv(source=upper_maker)} if rank == 0 else {side: made} if side else {}
        paired = collective(comm, lambda: geometry.pair(scene, halves[-1], halves[1]), root_only=True)
    else:
        paired = collective(comm, lambda: geometry.build(scene, background), root_only=True)
        halves = {-1: paired.lower, 1: paired.upper} if rank == 0 else {}
    tips = collective(comm, lambda: whole_mesh_checks(scene, paired), root_only=True)
    if phases is not None:
        phases.end("meshing")
    sigma, nodes, cells, tips = comm.bcast((paired.sigma, {s: len(h.points) for s, h in halves.items()},
                                            {s: len(h.cells) for s, h in halves.items()}, tips)
                                           if rank == 0 else None, root=0)
    needed = sorted({BLOCKS[b].side for b in exchange.local_blocks})
    if comm.size > 1:
        if not split and upper_maker != 0:  # rank 0 made both halves: the upper one goes to u⁺'s leader
            if rank == 0:
                comm.send(halves[1], dest=upper_maker)
            elif rank == upper_maker:
                halves[1] = comm.recv(source=0)
        group = comm.Split(color=int(needed[0] > 0), key=rank)  # the ranks of one half; its maker is the first
        halves = {needed[0]: group.bcast(halves.get(needed[0]), root=0),
                  **({1: halves[1]} if keep_whole and rank == 0 else {})}
        group.Free()
    if phases is not None:
        phases.end("distribution")
    return LocalMesh(halves, sigma, nodes, cells, geometry.origin(scene), tips)


def whole_mesh_checks(scene: Scene, mesh: Mesh) -> list[fracture.Tip]:
    """What needs the whole mesh (rank 0, before it is distributed): the loads' boundaries, the range of
    the moduli and loads, and the crack tips with their θ radii (which keep clear of the outer boundary)."""
    geometry.check_loads(scene, mesh)
    check_range(scene, mesh)
    return fracture.find_tips(mesh, scene.fracture.inner, scene.fracture.outer)


def gather_upper(mesh: LocalMesh, exchange: Exchange) -> Mesh | None:
    """The whole mesh on rank 0 for output: the upper half comes from u⁺'s leader (None elsewhere)."""
    source = exchange.leader(U_PLUS)
    upper = mesh.halves.get(1)
    if source != 0:
        if exchange.comm.rank == source:
            exchange.comm.send(upper, dest=0)
        elif exchange.is_root:
            upper = exchange.comm.recv(source=source)
    return Mesh(mesh.half(-1), upper, mesh.sigma, mesh.origin) if exchange.is_root else None


def local_systems(scene: Scene, mesh: LocalMesh | Mesh, exchange: Exchange) -> list[assembly.BlockSystem]:
    """Assemble this rank's blocks (or its rows of the one it shares); blocks of one half share its
    sparsity pattern."""
    group = exchange.groups[0]
    rows = None
    if group.size > 1:
        half = mesh.half(BLOCKS[exchange.local_blocks[0]].side)
        rows = assembly.row_ranges(len(half.points), group.size)[group.rank]
    return assembly.block_systems(scene, mesh, exchange.local_blocks, rows)


def make_blocks(scene: Scene, mesh: LocalMesh | Mesh, exchange: Exchange, package: str) -> list[Block]:
    """This rank's blocks as PETSc objects; no assembled array outlives its PETSc matrix."""
    systems = local_systems(scene, mesh, exchange)
    blocks = []
    while systems:
        blocks.append(Block(systems.pop(0), comm=PETSc.Comm(exchange.groups[len(blocks)]), factor_package=package))
    return blocks


def reload(setup: "Setup", scene: Scene) -> None:
    """Give the factored blocks of ``setup`` the loads of ``scene`` (same mesh, materials, method)."""
    systems = collective(setup.exchange.comm, lambda: local_systems(scene, setup.mesh, setup.exchange))
    for block, system in zip(setup.blocks, systems):
        block.system = replace(block.system, rhs=system.rhs)
    setup.phases = Phases()
    setup.phases.end("assembly")
    setup.phases.skip("factorization")


def prepare(scene: Scene, comm: MPI.Comm, mesh: Mesh | None = None, phases: Phases | None = None) -> Setup:
    """Build (or take) the mesh, assemble and factor every rank's blocks."""
    if not supported(comm.size):
        error = DDSolveError(f"unsupported number of ranks {comm.size}: use 1, 2 or a multiple of 4")
        error.collective = True  # every rank sees the same size
        raise error
    phases = phases if phases is not None else Phases()
    stages = {name: PETSc.Log.Stage(name) for name in STAGES}

    stages["Setup"].push()
    exchange = Exchange(comm, len(BLOCKS))
    if mesh is not None:
        tips = comm.bcast(collective(comm, lambda: whole_mesh_checks(scene, mesh), root_only=True), root=0)
        local = whole(mesh, tips)
    else:
        local = local_mesh(scene, comm, exchange, phases)
    scene = resolve(scene, comm.size, local)
    method = scene.solver.method
    blocks = collective(comm, lambda: make_blocks(scene, local, exchange, FACTOR_PACKAGE[method]))
    interface = for_mesh(local.sigma, scene.nonpenetration)
    stages["Setup"].pop()
    phases.end("assembly")

    stages["Factorization"].push()
    def factor():
        for block in blocks:
            block.factor(schur=method == "schur")
            if method == "feti":
                block.factor_dirichlet()

    collective(comm, factor)
    stages["Factorization"].pop()
    phases.end("factorization")
    return Setup(local, exchange, blocks, interface, stages, phases, scene)


def resolve(scene: Scene, ranks: int, mesh: LocalMesh) -> Scene:
    """The scene with ``auto`` replaced by the method :func:`ddsolve.methods.choose` picks."""
    if scene.solver.method != "auto":
        return scene
    per_block = max(1, ranks // len(BLOCKS))
    method = methods.choose(per_block, 2 * max(mesh.nodes.values()), int(mesh.sigma.corner.sum()))
    return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=method))


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


def solve(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, mesh: Mesh | None = None,
          setup: Setup | None = None) -> Result | None:
    """Run the domain decomposition for ``scene`` on ``comm``; write ``output`` on rank 0.

    Returns the result on rank 0 (None elsewhere).  A run that reaches max_iterations writes its
    result with converged = false and then raises NotConvergedError on every rank (the error holds
    the result as ``result``).  ``mesh`` (on every rank) skips building it; ``setup`` (from
    :func:`prepare`, loads from :func:`reload`) skips assembly and factorization and is kept.
    """
    own = setup is None
    if own:
        setup = prepare(scene, comm, mesh, Phases(launch_age() if mesh is None else 0.0))
    else:
        # the method the setup was made for (``auto`` resolved), the scene's other solver settings
        scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=setup.scene.solver.method))
        setup.scene = scene
    phases = setup.phases
    local, exchange, interface, stages, scene = setup.mesh, setup.exchange, setup.interface, setup.stages, setup.scene
    method = scene.solver.method

    try:
        server = BlockServer(setup.blocks, exchange)
        outcome, rounds, failure = run_method(scene, setup, server, progress)
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            failure.collective = True
        phases.end("iterations")
        if failure is not None and not isinstance(failure, NotConvergedError):
            raise failure

        parts = gather_estimate(scene, local, exchange, server)
        phases.end("estimate")
        stages["Output"].push()
        volume = comm.reduce(fracture.block_terms(scene, local, local.tips, {b: server.solutions[b]
                                                                            for b in exchange.led_blocks}), root=0)
        sizes = [2 * local.nodes[spec.side] for spec in BLOCKS]
        solutions = exchange.gather_varying([server.solutions[b] for b in exchange.led_blocks], sizes)
        mine = {"mesh_bytes": local.nbytes, "unknowns": sum(len(b.system.rhs) for b in setup.blocks),
                "factor_mb": sum(b.factor_megabytes() for b in setup.blocks)}
        mesh = gather_upper(local, exchange)
        phases.end("output")
        memory = comm.gather((mine, phases.peak, phases.cpu), root=0)
        result = None
        if exchange.is_root:
            timings = dict(phases.wall)
            timings["update"] = timings["iterations"] - rounds.elapsed
            timings["setup"] = sum(timings.get(name, 0.0) for name in ("meshing", "distribution", "assembly"))
            for name in phases.cpu:  # CPU seconds of every rank together
                timings[f"{name}_cpu"] = sum(cpu[name] for _, _, cpu in memory)
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
                active_set_changes=np.array(outcome.active_set_changes, dtype=np.int64),
                memory=memory_record(memory, sum(sizes), whole(mesh).nbytes),
                attrs={**io.provenance(), "stop": scene.solver.stop, "tol": scene.solver.tol,
                       "peak_memory_mb": [max(peak.values()) for _, peak, _ in memory], **outcome.details,
                       "error_estimate": estimated.relative},
                indicators=estimated.indicators,
            )
            result.fracture = fracture.finish(local.tips, volume, result)
        if output is not None:
            collective(comm, lambda: io.write(output, result, final=True), root_only=True)
        stages["Output"].pop()
        if failure is not None:  # not converged: the result is written with converged = false
            failure.result = result
            raise failure
        return result
    finally:
        if own:
            setup.destroy()


def memory_record(ranks: list[tuple[dict, dict, dict]], unknowns: int, whole_mesh_bytes: int) -> dict:
    """The result file's ``/memory``: per rank, the peak resident memory (MB) at the end of every phase,
    the unknowns it works on, its mesh arrays and its factors (MUMPS's own count, MB); and per phase the
    largest peak per unknown of a rank (bytes)."""
    record = {"unknowns": unknowns, "whole_mesh_bytes": whole_mesh_bytes}
    for key in ("unknowns", "mesh_bytes", "factor_mb"):
        record[f"rank_{key}"] = np.array([mine[key] for mine, _, _ in ranks])
    for phase in ranks[0][1]:
        peaks = np.array([peak[phase] for _, peak, _ in ranks])
        record[f"peak_mb_{phase}"] = peaks
        record[f"bytes_per_unknown_{phase}"] = float(np.max(peaks * 2 ** 20 / record["rank_unknowns"]))
    return record
