"""The domain-decomposition solve: scene -> meshes -> blocks on ranks -> multiplier method -> result.

Rank 0 reads the scene; the leaders of u⁻ and u⁺ mesh a half each (or rank 0 reads the whole mesh);
each rank receives only the half its blocks live on, and Σ (:func:`local_mesh`); every rank assembles
and factors the blocks (or the rows of a block) it owns; rank 0 runs the multiplier method while the
other ranks serve rounds of block solves (:func:`serve`); then the solve is finished
(:mod:`ddsolve.parallel.finish`): the ranks write their parts of the result together (``OnRanks``,
parallel HDF5), or rank 0 gathers the block solutions (and the upper half) and writes the result
(``Gathered``).  :func:`solve` reads :func:`prepare` -> :func:`run_method` -> finish.  Every phase of the
launch is timed, with its CPU time and peak memory (:class:`Phases`); the result file has them in
``/timings`` and ``/memory``.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from ddsolve.dd import dual, final_check, kernels, registry
from ddsolve.dd.interface import Interface, for_mesh
from ddsolve.errors import DDSolveError, DivergedError, NotConvergedError, SceneError
from ddsolve.fem import assembly, supports
from ddsolve.mesh import pieces
from ddsolve.mesh.mesh import U_MINUS, U_PLUS, Mesh, blocks as block_list
from ddsolve.mesh.pieces import Piece
from ddsolve.parallel import finish, launch
from ddsolve.parallel.blocks import Block
from ddsolve.parallel.distribution import LocalMesh, half_bytes, local_mesh, whole, whole_mesh_checks
from ddsolve.parallel.exchange import Exchange, collective
from ddsolve.parallel.launch import supported, usable
from ddsolve.parallel.phases import Phases, launch_age, memory_record
from ddsolve.parallel.rounds import BlockServer, drive, kernel_traces
from ddsolve.post.result import Result
from ddsolve.problem.scene import Scene

STAGES = ("Setup", "Factorization", "Rounds", "Update", "Output")



def run_method(scene: Scene, setup: "Setup", server: BlockServer, progress):
    """The scene's multiplier method on rank 0, then the final round; (outcome, rounds, failure)."""
    interface = setup.interface

    def work(rounds):  # the multipliers, then the displacements for λ, checked
        method = scene.solver.method
        return final_check.checked_solve(method, rounds, interface, scene.solver, dual.Progress(method, out=progress))

    outcome, rounds, failure = drive(setup, server, work)
    if outcome is not None and outcome.state is not None:  # rank 0: the state its multipliers solve (a bond's damage)
        setup.interface = outcome.state
    if failure is None and outcome is not None:
        if outcome.diverged:
            failure = DivergedError(outcome.message)
        elif not outcome.converged:
            failure = NotConvergedError(outcome.message)
    return outcome, rounds, failure


def whole_mesh_bytes(local: LocalMesh, exchange: Exchange) -> int:
    """Bytes of the whole mesh's arrays (both halves and Σ), counted by the leaders of u⁻ and u⁺ (known from the
    sizes when they hold pieces)."""
    if local.whole_bytes:
        return sum(local.whole_bytes.values()) + local.sigma_bytes
    own = sum(half_bytes(local.half(side)) for b, side in ((U_MINUS, -1), (U_PLUS, 1))
              if exchange.comm.rank == exchange.leader(b))
    return exchange.comm.allreduce(own) + local.sigma_bytes


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
    pieces: dict[int, Piece]  # local block -> this rank's piece of its half (its rows' nodes and cells)
    whole_mesh_bytes: int  # of both halves and Σ (:func:`whole_mesh_bytes`)

    @property
    def timings(self) -> dict:
        return self.phases.wall

    @property
    def trace_stiffness(self) -> None:
        """Not gathered: the plane driver's feti takes Dirichlet's preconditioner."""
        return None

    def trace_entries(self) -> None:
        """Every block holds the whole trace (Σ's)."""
        return None

    def kernel_traces(self) -> list[np.ndarray] | None:
        """The traces of the blocks' kernels (:func:`ddsolve.parallel.rounds.kernel_traces`)."""
        return kernel_traces(self.mesh)

    def destroy(self) -> None:
        for block in self.blocks:
            block.destroy()
        self.exchange.free()



def hold_blocks(phases: Phases, blocks: list[Block], factored: bool = True) -> None:
    """Account what ``blocks`` hold now (:meth:`Block.held_bytes`) in ``phases``."""
    held = [block.held_bytes(factored) for block in blocks]
    for what in ("matrices", "factors", "schur complements"):
        phases.hold(what, sum(kinds[what] for kinds in held))


def local_systems(scene: Scene, mesh: LocalMesh, exchange: Exchange, block_pieces: dict[int, Piece]
                  ) -> list[assembly.BlockSystem]:
    """Assemble this rank's blocks, or its rows of the one it shares on its piece of the half (:func:`cut_pieces`);
    blocks of one half share its sparsity pattern."""
    if exchange.groups[0].size == 1:
        return assembly.block_systems(scene, mesh, exchange.local_blocks, None, mesh.sigma_supports)
    index = exchange.local_blocks[0]
    piece = block_pieces[index]
    rows = (2 * piece.owned_nodes.start, 2 * piece.owned_nodes.stop)
    on_piece = replace(mesh, halves={block_list(scene.geometry.layers)[index].side: piece.half})
    return [assembly.renumbered(system, piece.nodes, piece.rows) for system in
            assembly.block_systems(scene, on_piece, [index], rows, mesh.sigma_supports)]


def make_blocks(scene: Scene, mesh: LocalMesh, exchange: Exchange, package: str,
                block_pieces: dict[int, Piece]) -> list[Block]:
    """This rank's blocks as PETSc objects; no assembled array outlives its PETSc matrix."""
    systems = local_systems(scene, mesh, exchange, block_pieces)
    blocks = []
    while systems:
        blocks.append(Block(systems.pop(0), comm=PETSc.Comm(exchange.groups[len(blocks)]), factor_package=package))
    return blocks


def reload(setup: "Setup", scene: Scene) -> None:
    """Give the factored blocks of ``setup`` the loads of ``scene`` (same mesh, materials, method, and the
    same prescribed entries: new prescribed values, as a scaled scene has, need both halves on every rank,
    as a setup made from a whole mesh has)."""
    local = setup.mesh
    if scene.displacements != setup.scene.displacements:  # the Σ entries' values follow the scene's
        if len(local.halves) < 2:
            error = DDSolveError("reload: new prescribed displacement values need the whole mesh on every rank")
            error.collective = True
            raise error
        whole_mesh = Mesh(local.half(-1), local.half(1), local.sigma, local.origin)
        setup.mesh = replace(local, sigma_supports=supports.sigma_supports(scene, whole_mesh))
    systems = collective(setup.exchange.comm, lambda: local_systems(scene, setup.mesh, setup.exchange, setup.pieces))
    for block, system in zip(setup.blocks, systems):
        block.system = replace(block.system, rhs=system.rhs, energy_offset=system.energy_offset)  # both the data's
    setup.interface = interface_of(scene, setup.mesh, setup.exchange.comm)  # the new data's displacement
    setup.phases = Phases()
    setup.phases.end("assembly")
    setup.phases.skip("factorization")


def interface_of(scene: Scene, local: LocalMesh, comm: MPI.Comm) -> Interface:
    """The scene's interface on every rank (collective): the displacement its data would make is the
    largest over the ranks' halves or pieces (:func:`ddsolve.fem.assembly.data_displacement`)."""
    data = comm.allreduce(assembly.data_displacement(scene, local.halves.values(), local.sigma), op=MPI.MAX)
    return for_mesh(local.sigma, scene.nonpenetration, local.sigma_supports.fixed, assembly.modulus(scene), data,
                    scene.friction, block_list(scene.geometry.layers), scene.bond)


def prepare(scene: Scene, comm: MPI.Comm, mesh: Mesh | None = None, phases: Phases | None = None,
            keep_halves: bool = True) -> Setup:
    """Build (or take) the mesh, assemble and factor every rank's blocks.  Not ``keep_halves`` (a solve whose
    ranks write the result together): from assembly on, a rank holds only its pieces of its halves
    (:mod:`ddsolve.mesh.pieces`; all a gathered result, a reload or a critical-factor search would need the
    halves whole)."""
    specs = block_list(scene.geometry.layers)
    if not supported(comm.size, len(specs)):
        one_layer = " (geometry.layers = 1: blocks u_minus and u_plus)" if len(specs) == 2 else ""
        error = DDSolveError(f"unsupported number of ranks {comm.size}: use {usable(len(specs))}{one_layer}")
        error.collective = True  # every rank sees the same size
        raise error
    phases = phases if phases is not None else Phases()
    stages = {name: PETSc.Log.Stage(name) for name in STAGES}

    stages["Setup"].push()
    exchange = Exchange(comm, len(specs))
    if mesh is not None:
        tips, table, block_kernels = comm.bcast(collective(comm, lambda: whole_mesh_checks(scene, mesh),
                                                           root_only=True), root=0)
        local = whole(mesh, tips, table, block_kernels)
    else:
        local = local_mesh(scene, comm, exchange, phases, whole_halves=keep_halves)
    scene = resolve(scene, comm.size, local)
    method = registry.METHODS[scene.solver.method]
    phases.hold("mesh", local.nbytes)
    floating = local.kernels.floating
    if floating and not method.floating:
        error = SceneError(f"solver.method = {method.name}: blocks {local.kernels.names()} are floating (held only "
                           f"through Σ, their stiffness singular), which {method.name} cannot solve: use "
                           f"{' or '.join(registry.floating_methods())}")
        error.collective = True  # every rank knows the supports
        raise error
    block_pieces = cut_pieces(local, exchange, specs)
    kernel_rows = {index: floating_kernel(scene, local, index, block_pieces[index],
                                          fixed=method.floating == registry.GENERALIZED_INVERSE)
                   for index in exchange.local_blocks if index in floating}
    whole_bytes = whole_mesh_bytes(local, exchange)
    if not keep_halves:
        local = replace(local, halves={specs[index].side: piece.half for index, piece in block_pieces.items()})
    phases.hold("mesh", local.nbytes + pieces.extra_bytes(block_pieces.values(), local.halves.values()))
    phases.end("distribution")  # the pieces cut, and the halves dropped: assembly holds what it works on
    blocks = collective(comm, lambda: make_blocks(scene, local, exchange, method.factorization, block_pieces))
    interface = interface_of(scene, local, comm)
    hold_blocks(phases, blocks, factored=False)
    stages["Setup"].pop()
    phases.end("assembly")

    stages["Factorization"].push()
    def factor():
        for index, block in zip(exchange.local_blocks, blocks):
            if index in floating:
                block.make_floating(*kernel_rows[index])
            block.factor(schur=method.schur_complements, out_of_core=scene.solver.out_of_core)
            if method.dirichlet or block.floating:
                block.factor_dirichlet(out_of_core=scene.solver.out_of_core)

    collective(comm, factor)
    hold_blocks(phases, blocks)
    stages["Factorization"].pop()
    phases.end("factorization")
    return Setup(local, exchange, blocks, interface, stages, phases, scene, block_pieces, whole_bytes)


def cut_pieces(local: LocalMesh, exchange: Exchange, specs: tuple) -> dict[int, Piece]:
    """This rank's piece of the half of each of its blocks: the nodes of its rows (:mod:`ddsolve.mesh.pieces`;
    a block's rows are shared out as :func:`ddsolve.fem.assembly.row_ranges` says), made with the mesh or cut now."""
    if local.pieces:
        return {index: local.pieces[specs[index].side] for index in exchange.local_blocks}
    out = {}
    for index, group in zip(exchange.local_blocks, exchange.groups):
        half = local.half(specs[index].side)
        first, last = assembly.row_ranges(len(half.points), group.size)[group.rank]
        out[index] = pieces.cut(half, first // 2, last // 2)
    return out


def floating_kernel(scene: Scene, mesh: LocalMesh, index: int, piece: Piece, fixed: bool
                    ) -> tuple[np.ndarray, np.ndarray | None]:
    """A floating block's kernel at its rows here (the nodes ``piece`` owns) and, with ``fixed``, the dofs fixed
    for FETI's K⁺: m dofs of the half's outer boundary, off the trace and the prescribed dofs, where the kernel
    is independent (chosen from the skeleton every piece keeps, the same on every rank of the block)."""
    spec, half = block_list(scene.geometry.layers)[index], piece.half
    vectors = kernels.kernel_vectors(half, mesh.sigma, mesh.kernels.kernels[index], mesh.kernels.frame)
    chosen = None
    if fixed:
        prescribed, _ = supports.block_supports(scene, half, mesh.sigma, spec.layer, index, mesh.sigma_supports)
        excluded = prescribed.ravel().copy()
        excluded[assembly.element_dofs(assembly.trace_nodes(half, mesh.sigma)[:, None]).ravel()] = True
        dofs = assembly.element_dofs(piece.outline[:, None]).ravel()
        picked = dofs[kernels.fixing_dofs(vectors[:, dofs], np.flatnonzero(excluded[dofs]))]
        chosen = 2 * piece.nodes[picked // 2].astype(np.int64) + picked % 2
    owned = piece.owned_nodes
    return vectors[:, 2 * owned.start:2 * owned.stop], chosen


def resolve(scene: Scene, ranks: int, mesh: LocalMesh) -> Scene:
    """The scene with ``auto`` replaced by the method :func:`ddsolve.dd.registry.choose` picks."""
    if scene.solver.method in registry.METHODS:
        return scene
    if scene.bond is not None:  # a bond's problem is solved on rank 0, with the blocks' Schur complements
        return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method="schur"))
    sigma = mesh.sigma
    crack_rows = int(sigma.crack[sigma.multiplier_nodes].sum()) if scene.nonpenetration else 0
    method = registry.choose(ranks, 2 * max(mesh.nodes.values()), len(sigma.multiplier_nodes), crack_rows,
                             len(block_list(scene.geometry.layers)))
    return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=method))


def bound(scene: Scene, comm: MPI.Comm, mesh: Mesh | None = None, iterations: int = 300) -> float:
    """λmax of the dual operator C K⁻¹ Cᵀ W by power iteration (one round each); 2/λmax bounds Uzawa's θ."""
    setup = prepare(scene, comm, mesh)
    try:
        def work(rounds):
            problem = dual.DualProblem(rounds, setup.interface, scene.solver)
            return dual.largest_eigenvalue(problem.apply, setup.interface.size, iterations, tolerance=1e-9)

        estimate, _, failure = drive(setup, BlockServer(setup.blocks, setup.exchange), work)
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            failure.collective = True
            raise failure
        return comm.bcast(estimate, root=0)
    finally:
        setup.destroy()


def solve_decomposed(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, mesh: Mesh | None = None,
          setup: Setup | None = None, gather: bool = True, factors: np.ndarray | None = None,
          refined_next: Callable[[Result], bool] | None = None) -> Result | None:
    """Run the domain decomposition for ``scene`` on ``comm``; write ``output``.

    Not ``gather`` (the command line), with ``output`` on more than one rank and h5py built with MPI:
    every rank writes its part of the result set (:class:`ddsolve.parallel.finish.OnRanks`) and rank 0's
    result holds only the Σ data, the scalars and G (``mesh`` None, ``solution`` empty); else rank 0 gathers
    the whole result and writes it (:class:`ddsolve.parallel.finish.Gathered`).

    Returns the result on rank 0 (None elsewhere).  A run that reaches max_iterations writes its
    result with converged = false and then raises NotConvergedError on every rank (the error holds
    the result as ``result``).  ``mesh`` (on every rank) skips building it; ``setup`` (from
    :func:`prepare`, loads from :func:`reload`) skips assembly and factorization and is kept.
    ``factors`` (rank 0): the critical load factors of the tips where a root solve found them (a scene with
    a temperature change, :func:`ddsolve.solvers.critical.factors`); else √(G_c/G) or NaN
    (:func:`ddsolve.post.toughness.judge`).  ``refined_next`` (rank 0, gathered results): given the result
    with its estimate and indicators, whether it is only a step to a finer mesh (an adaptive level); then G,
    its modes and the reactions are not computed (``fracture`` stays None, ``reactions`` empty).
    """
    own = setup is None
    finishing = finish.chosen(output, gather, comm)
    if own:
        setup = prepare(scene, comm, mesh, Phases(launch_age() if mesh is None else 0.0), keep_halves=finishing.whole)
    else:
        # the method the setup was made for (``auto`` resolved), the scene's other solver settings
        scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=setup.scene.solver.method))
        setup.scene = scene
    phases, exchange, stages = setup.phases, setup.exchange, setup.stages

    try:
        piece_dofs = {index: piece.local_dofs() for index, piece in setup.pieces.items()}
        server = BlockServer(setup.blocks, exchange, piece_dofs, gather=finishing.whole)
        outcome, rounds, failure = run_method(setup.scene, setup, server, progress)
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            failure.collective = True
        mine = end_method(setup, server, rounds, free=own)
        if failure is not None and not isinstance(failure, NotConvergedError):
            raise failure

        finisher = finishing(setup, server, outcome.lam if exchange.is_root else None, output)
        phases.end("estimate")
        stages["Output"].push()
        finisher.collect()
        mine["held_bytes"] = finisher.held_bytes
        phases.hold("mesh", finisher.mesh_bytes)
        phases.hold("solutions", finisher.held_bytes - finisher.mesh_bytes)
        result = finisher.result(outcome_record(setup, outcome, rounds, comm) if exchange.is_root else None,
                                 factors, refined_next)
        phases.end("output")  # G, its modes, the reactions and the files' contents included
        withdrawn = comm.bcast(result.claim() if exchange.is_root else None, root=0)
        if withdrawn and failure is None:  # written with converged = false, then raised on every rank
            failure = NotConvergedError(withdrawn)
            failure.collective = True
        memory = comm.gather((mine, phases), root=0)
        if exchange.is_root:
            record_timings(result, setup, rounds, memory)
        if output is not None:
            written = finisher.write(result)
            if result is not None:  # the launch's last phase, for whoever reports it
                result.timings["write"] = written
        stages["Output"].pop()
        if failure is not None:  # not converged: the result is written with converged = false
            failure.result = result
            raise failure
        return result
    finally:
        if own:
            setup.destroy()


def gathered_solve(setup, server: BlockServer, sizes: list[int], made: Callable, write: Callable,
                   output: Path | None, started: float, progress=print):
    """The method of a setup whose mesh every rank holds (several interfaces, a 3-D box): run it, gather the blocks'
    fields (``sizes`` dofs each) on rank 0, make its result there (``made(outcome, rounds, fields)``) and write it
    (``write(output, result)``).  The result on rank 0 (None elsewhere); a method that does not converge writes its
    result with converged = false and raises NotConvergedError on every rank, with the result."""
    comm = setup.exchange.comm
    outcome, rounds, failure = run_method(setup.scene, setup, server, progress)
    failure = comm.bcast(failure, root=0)
    if failure is not None:
        failure.collective = True
        if not isinstance(failure, NotConvergedError):
            raise failure
    exchange = setup.exchange
    fields = exchange.gather_varying([server.solutions[b] for b in exchange.led_blocks], sizes)
    result = None
    if exchange.is_root:
        setup.timings["total"] = time.perf_counter() - started
        result = made(outcome, rounds, fields)
        if output is not None:
            collective(comm, lambda: write(output, result), root_only=True)
    elif output is not None:
        collective(comm, lambda: None, root_only=True)
    if failure is not None:
        failure.result = result
        raise failure
    return result


def end_method(setup: Setup, server: BlockServer, rounds, free: bool) -> dict:
    """End the phase of the method: account what it held, free the factors with ``free`` (the estimate and the
    output run in the memory they held); this rank's numbers for the memory record."""
    phases = setup.phases
    phases.hold("schur complements", rounds.schur_bytes if rounds is not None else 0)  # rank 0's, during the method
    phases.hold("solutions", server.held_bytes)
    mine = {"mesh_bytes": setup.mesh.nbytes, "unknowns": sum(len(b.system.rhs) for b in setup.blocks),
            "factor_mb": sum(b.factor_megabytes() for b in setup.blocks),
            "out_of_core": any(b.out_of_core() for b in setup.blocks)}
    if free:
        for block in setup.blocks:
            block.destroy()
        hold_blocks(phases, [])
    phases.end("iterations")
    return mine


def outcome_record(setup: Setup, outcome, rounds, comm: MPI.Comm) -> dict:
    """The result's scalars, histories and attributes from the method's ``outcome`` and ``rounds`` (rank 0)."""
    scene, phases = setup.scene, setup.phases
    return dict(
        converged=outcome.converged, iterations=outcome.iterations, solves=rounds.count,
        wall_time=phases.wall["factorization"] + phases.wall["iterations"], ranks=comm.size,
        history=np.array(outcome.history), message=outcome.message,
        active_set_changes=np.array(outcome.active_set_changes, dtype=np.int64),
        attrs={**launch.provenance(), **setup.mesh.quality, "stop": scene.solver.stop, "tol": scene.solver.tol,
               **outcome.details})


def record_timings(result: Result, setup: Setup, rounds, memory: list[tuple[dict, Phases]]) -> None:
    """Rank 0: the launch's timings (wall seconds, and CPU seconds of every rank together) and its memory
    record (``memory``: every rank's numbers and :class:`Phases`) on ``result``."""
    phases, local = setup.phases, setup.mesh
    timings = dict(phases.wall)
    timings["update"] = timings["iterations"] - rounds.elapsed
    timings["setup"] = sum(timings.get(name, 0.0) for name in ("meshing", "distribution", "assembly"))
    for name in phases.cpu:  # CPU seconds of every rank together
        timings[f"{name}_cpu"] = sum(ranked.cpu[name] for _, ranked in memory)
    unknowns = sum(2 * local.nodes[spec.side] for spec in setup.interface.blocks)
    result.timings, result.memory = timings, memory_record(memory, unknowns, setup.whole_mesh_bytes)
    result.attrs["peak_memory_mb"] = [max(ranked.peak.values()) for _, ranked in memory]
    # what MUMPS did (a PETSc option may have overridden solver.out_of_core)
    result.attrs["factors_out_of_core"] = any(ranked["out_of_core"] for ranked, _ in memory)
