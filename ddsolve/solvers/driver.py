"""The domain-decomposition solve: scene -> meshes -> blocks on ranks -> multiplier method -> result.

Rank 0 reads the scene; the leaders of u⁻ and u⁺ mesh a half each (or rank 0 reads the whole mesh);
each rank receives only the half its blocks live on, and Σ (:func:`local_mesh`); every rank assembles
and factors the blocks (or the rows of a block) it owns; rank 0 runs the multiplier method while the
other ranks serve rounds of block solves (:func:`serve`); the ranks write their parts of the result
together (:class:`OnRanks`, parallel HDF5), or rank 0 gathers the block solutions (and the upper half)
and writes the result.  Every phase of the launch is timed, with its CPU time and peak
memory (:class:`Phases`); the result file has them in ``/timings`` and ``/memory``.
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

from ddsolve.dd import kernels, methods
from ddsolve.dd.interface import Interface, for_mesh
from ddsolve.errors import DDSolveError, DivergedError, NotConvergedError, SceneError
from ddsolve.fem import assembly, supports
from ddsolve.io import hdf5
from ddsolve.mesh import pieces
from ddsolve.mesh.mesh import BLOCKS, U_PLUS, Mesh, partner
from ddsolve.mesh.pieces import Piece
from ddsolve.parallel import launch
from ddsolve.parallel.blocks import Block
from ddsolve.parallel.distribution import (LocalMesh, gather_upper, half_bytes, local_mesh, whole,
                                          whole_mesh_checks)
from ddsolve.parallel.exchange import Exchange, collective
from ddsolve.parallel.launch import supported
from ddsolve.parallel.phases import Phases, launch_age, memory_record
from ddsolve.parallel.rounds import BlockServer, drive
from ddsolve.io import viewer
from ddsolve.post import analysis, estimate, fracture, plots, reactions
from ddsolve.post.result import OnSigma, Result
from ddsolve.problem.scene import Scene

#: Default block factorization per method.  The iterative methods make one solve per round with one
#: factorization, where PETSc's own Cholesky is about 3x faster than MUMPS; ``schur`` needs MUMPS for
#: the Schur complements (``./run bench factor`` measures both).
FACTOR_PACKAGE = {"uzawa": "petsc", "fista": "petsc", "mprgp": "petsc", "schur": "mumps", "feti": "mumps"}
STAGES = ("Setup", "Factorization", "Rounds", "Update", "Output")
#: The methods that solve floating blocks (a singular stiffness): ``schur`` by their interiors, ``feti`` by
#: a generalized inverse and the kernels' coarse problem.
FLOATING_METHODS = ("schur", "feti")



def run_method(scene: Scene, setup: "Setup", server: BlockServer, progress):
    """The scene's multiplier method on rank 0, then the final round; (outcome, rounds, failure)."""
    interface = setup.interface

    def work(rounds):  # the multipliers, then the displacements for λ, checked
        method = scene.solver.method
        return methods.checked_solve(method, rounds, interface, scene.solver, methods.Progress(method, out=progress))

    outcome, rounds, failure = drive(setup, server, work)
    if failure is None and outcome is not None:
        if outcome.diverged:
            failure = DivergedError(outcome.message)
        elif not outcome.converged:
            failure = NotConvergedError(outcome.message)
    return outcome, rounds, failure


def piece_displacements(setup: "Setup", server: BlockServer) -> dict[int, np.ndarray]:
    """Local block -> the last full solve at the nodes of this rank's piece of its half, ``(n, 2)`` in x, y."""
    sigma = setup.mesh.sigma
    frames = sigma.frames[sigma.multiplier_nodes]
    out = {}
    for index, piece in setup.pieces.items():  # a piece has every Σ node of its half
        out[index] = assembly.to_global(server.piece_values[index], assembly.trace_nodes(piece.half, sigma), frames)
    return out


def block_indicators(setup: "Setup", displacements: dict[int, np.ndarray], collect: bool = True
                     ) -> dict[int, np.ndarray]:
    """The error indicators ``(2, cells)`` of the last full solve (:func:`ddsolve.post.estimate.block_indicators`):
    every rank of a block computes those of the cells it owns on its piece of the half (:mod:`ddsolve.mesh.pieces`,
    ``displacements`` there: :func:`piece_displacements`); with ``collect`` the block's leader gets the whole
    half's (local block -> indicators, on the leaders), else every rank keeps its own cells'."""
    out = {}
    for index, group in zip(setup.exchange.local_blocks, setup.exchange.groups):
        spec, piece = BLOCKS[index], setup.pieces[index]
        mine = estimate.block_indicators(piece.points, piece.cells, assembly.elasticity(setup.scene, spec.layer)[0],
                                         displacements[index], piece.outer_edges)[:, :piece.owned]
        whole = collect_owned(group, piece, setup.mesh.cells[spec.side], {"indicators": mine.T}) if collect else \
            {"indicators": mine.T}
        if whole is not None:
            out[index] = whole["indicators"].T
    return out


def block_cell_fields(setup: "Setup", displacements: dict[int, np.ndarray]) -> dict[int, analysis.CellFields]:
    """The cell fields of the last full solve on the cells this rank owns (local block -> its
    :class:`~ddsolve.post.analysis.CellFields`)."""
    return {index: analysis.block_cell_fields(setup.scene, BLOCKS[index].layer, piece.points, piece.owned_cells,
                                              displacements[index])
            for index, piece in setup.pieces.items()}


def collect_owned(group: MPI.Comm, piece: Piece, count: int, arrays: dict[str, np.ndarray]
                  ) -> dict[str, np.ndarray] | None:
    """Arrays over the cells each rank of a block owns (first axis) -> over all ``count`` cells of the half,
    on the block's leader (None on the others)."""
    if group.size == 1:
        return arrays
    parts = group.gather((slice(piece.cell_first, piece.cell_stop), arrays), root=0)
    if group.rank != 0:
        return None
    out = {name: np.empty((count,) + values.shape[1:], values.dtype) for name, values in arrays.items()}
    for cells, values in parts:
        for name, array in values.items():
            out[name][cells] = array
    return out


def gather_estimate(mesh: LocalMesh, exchange: Exchange, indicators: dict[int, np.ndarray]
                    ) -> dict[str, np.ndarray] | None:
    """The blocks' error indicators (:func:`block_indicators`) on rank 0 (block name -> ``(2, cells)``),
    None elsewhere."""
    parts = exchange.gather_varying([indicators[index].ravel() for index in exchange.led_blocks],
                                    [2 * mesh.cells[spec.side] for spec in BLOCKS])
    return None if parts is None else {spec.name: part.reshape(2, -1) for spec, part in zip(BLOCKS, parts)}




def whole_mesh_bytes(local: LocalMesh, exchange: Exchange) -> int:
    """Bytes of the whole mesh's arrays (both halves and Σ), counted by the leaders of u⁻ and u⁺ (known from the
    sizes when they hold pieces)."""
    if local.whole_bytes:
        return sum(local.whole_bytes.values()) + local.sigma_bytes
    own = sum(half_bytes(local.half(BLOCKS[b].side)) for b in (0, U_PLUS) if exchange.comm.rank == exchange.leader(b))
    return exchange.comm.allreduce(own) + local.sigma_bytes


class OnRanks:
    """The result as the ranks hold it for a distributed write: every rank its pieces of its blocks' halves
    (:mod:`ddsolve.mesh.pieces`) with the displacements (x, y) there, the indicators and cell fields of the
    cells it owns, and its slabs of the files; rank 0 the Σ data (:class:`OnSigma`) and the estimate, from
    sums over the ranks.  Only Σ-sized arrays and scalars are exchanged."""

    def __init__(self, scene: Scene, local: LocalMesh, exchange: Exchange, block_pieces: dict[int, Piece],
                 interface: Interface, lam: np.ndarray | None, indicators: dict[int, np.ndarray],
                 displacements: dict[int, np.ndarray], solver_bytes: int = 0):
        comm, sigma = exchange.comm, local.sigma
        frames = sigma.frames[sigma.multiplier_nodes]
        self.scene, self.local, self.exchange = scene, local, exchange
        self.pieces, self.displacements = block_pieces, displacements
        self.held_bytes = local.nbytes + solver_bytes + sum(u.nbytes for u in displacements.values())
        # a piece has every Σ node of its half
        traces = exchange.gather_varying([displacements[b][block_pieces[b].half.sigma].ravel()
                                          for b in exchange.led_blocks], [2 * len(sigma.points)] * len(BLOCKS))
        largest = comm.allreduce(max((np.abs(displacements[b][piece.owned_nodes]).max(initial=0.0)
                                      for b, piece in block_pieces.items()), default=0.0), op=MPI.MAX)
        on = OnSigma(sigma, interface.split(lam, frames), {spec.name: trace.reshape(-1, 2) for spec, trace in
                                                           zip(BLOCKS, traces)}, largest) if exchange.is_root else None
        self.on = comm.bcast(on, root=0)
        pressure, jump = estimate.contact_on_sigma(sigma, self.on.multipliers["mu_c"], self.on.traces["u_minus"],
                                                   self.on.traces["u_plus"])
        self.indicators, squared, energy = {}, 0.0, 0.0
        for b, piece in block_pieces.items():
            contact = (estimate.half_contact_indicators(piece.owned_half, pressure, jump)
                       if BLOCKS[b].layer == "layer1" else 0.0)
            self.indicators[b], block_squared, block_energy = estimate.block_estimate(indicators[b], contact)
            squared, energy = squared + block_squared, energy + block_energy
        totals = comm.reduce(np.array([squared, energy]), op=MPI.SUM, root=0)
        self.relative = (estimate.relative(*totals, estimate.rounding_energy(assembly.modulus(scene), largest))
                         if exchange.is_root else None)
        self.reactions = self._reactions()

    def mode_split(self) -> dict[str, np.ndarray] | None:
        """G's split into modes I and II on rank 0.  Every rank integrates its owned cells' share of the mirror
        split (:func:`ddsolve.post.fracture.mirror_terms`) with the other side's field at the mirror images of
        their nodes, which the ranks of the partner block interpolate on the cells they own; rank 0 sums the
        shares and splits the tips whose disc is not mirror-symmetric by crack closure, from Σ's data."""
        local, exchange, comm, scene = self.local, self.exchange, self.exchange.comm, self.scene
        sigma, tips = local.sigma, local.tips
        laws = {spec.layer: assembly.elasticity(scene, spec.layer)[0] for spec in BLOCKS}
        mirrorable = [fracture.mirrorable(tip, sigma, laws.values()) for tip in tips]
        shared = exchange.groups[0].size > 1  # the blocks' ranks own parts of their halves: ask where it may be
        boxes = comm.allgather({b: analysis.owned_box(piece) for b, piece in self.pieces.items()}
                               if shared and any(mirrorable) else {})
        discs, asks = {}, [[] for _ in range(comm.size)]
        for i, tip in enumerate(tips):
            for b, piece in self.pieces.items():
                if mirrorable[i]:
                    discs[i, b] = fracture.mirror_nodes(tip, sigma, piece.owned_half)
                    images = discs[i, b][2]
                    for rank in exchange.ranks(partner(b)) if len(images) else ():  # no disc cells here: no share
                        asked = np.arange(len(images))
                        if shared:
                            low, high = boxes[rank][partner(b)]
                            asked = asked[np.all((images >= low) & (images <= high), axis=1)]
                        asks[rank].append((i, b, asked, images[asked]))
        answers = [[(i, b, asked, *analysis.owned_values_at(self.pieces[partner(b)], self.displacements[partner(b)],
                                                            images)) for i, b, asked, images in received]
                   for received in comm.alltoall(asks)]
        replies: dict[tuple[int, int], list] = {}
        for i, b, *answer in (answer for answered in comm.alltoall(answers) for answer in answered):
            replies.setdefault((i, b), []).append(answer)
        shares, failed = np.zeros((len(tips), 2)), np.zeros(len(tips), dtype=np.int64)
        for (i, b), answered in replies.items():
            spec, values = BLOCKS[b], analysis.nearest_answer(len(discs[i, b][2]), answered)
            terms = None if values is None else fracture.mirror_terms(
                tips[i], sigma, self.pieces[b].owned_half, laws[spec.layer], self.displacements[b], discs[i, b],
                values, assembly.thermal_of(scene, spec.layer))
            if terms is None:  # the images leave the other half, or the eigenstrain is not symmetric
                failed[i] += 1
            else:
                shares[i] += terms
        shares, failed = comm.reduce(shares, op=MPI.SUM, root=0), comm.reduce(failed, op=MPI.SUM, root=0)
        if not exchange.is_root:
            return None
        mirrored = [(float(shares[i, 0]), float(shares[i, 1])) if mirrorable[i] and failed[i] == 0 else None
                    for i in range(len(tips))]
        return fracture.split_modes(tips, mirrored, self.on, scene.nonpenetration, local.half(-1).degree)

    def _reactions(self) -> dict[str, dict[str, np.ndarray]] | None:
        """The reactions on rank 0: every rank the support forces at the nodes it owns, the gluing's ties
        settled on rank 0 from the Σ entries (:func:`ddsolve.post.reactions.reactions` in one process)."""
        scene, local, comm = self.scene, self.local, self.exchange.comm
        sigma = local.sigma
        count = 2 * len(sigma.multiplier_nodes)
        forces, positions, mine = {}, {}, {}
        entries, owning = np.zeros((len(BLOCKS), count)), np.zeros((len(BLOCKS), count), dtype=np.int64)
        for b, piece in self.pieces.items():
            half = piece.half
            forces[b], own = reactions.block_forces(scene, half, sigma, b, self.displacements[b], local.sigma_supports)
            others = np.ones(len(half.points), dtype=bool)
            others[piece.owned_nodes] = False
            forces[b][others] = 0.0  # a node's force comes from the rank that owns it
            positions[b] = half.sigma[sigma.multiplier_nodes]
            mine[b] = ~others[positions[b]]
            entries[b], owning[b] = forces[b][positions[b]].ravel(), own[positions[b]].ravel()
        entries, owning = comm.reduce(entries, op=MPI.SUM, root=0), comm.reduce(owning, op=MPI.SUM, root=0)
        tied = reactions.tie(sigma, list(entries.reshape(len(BLOCKS), -1, 2)),
                             list(owning.reshape(len(BLOCKS), -1, 2) > 0)) if self.exchange.is_root else None
        tied = comm.bcast(tied, root=0)
        parts = []
        for b, piece in self.pieces.items():
            forces[b][positions[b][mine[b]]] = tied[b][mine[b]]
            parts.append((BLOCKS[b].layer, reactions.boundary_sums(scene, piece.half, sigma, BLOCKS[b].layer,
                                                                   forces[b])))
        parts = comm.gather(parts, root=0)
        if not self.exchange.is_root:
            return None
        return reactions.ordered(scene, [part for ranked in parts for part in ranked])

    def files(self, result: Result | None, output: Path, cell_fields: dict[int, analysis.CellFields]
              ) -> tuple[hdf5.Part, viewer.Distributed]:
        """This rank's slabs of the result file and its shares of the viewer files (``result``: rank 0's;
        ``cell_fields``: of the cells it owns, :func:`block_cell_fields`); rank 0 adds the attributes once the
        launch's timings are complete."""
        local, exchange, comm = self.local, self.exchange, self.exchange.comm
        sigma, nodes = local.sigma, local.sigma.multiplier_nodes
        datasets = {}
        for b, piece in self.pieces.items():  # a half's first block writes its mesh, its leader Σ and boundaries
            if b == min(c for c, spec in enumerate(BLOCKS) if spec.side == BLOCKS[b].side):
                datasets.update(hdf5.half_datasets(piece.half, nodes, piece, skeleton=b in exchange.led_blocks))
        held = comm.allgather({BLOCKS[b].side: (piece.nodes[piece.half.sigma],
                                                piece.points[piece.owned_nodes].min(axis=0, initial=np.inf),
                                                piece.points[piece.owned_nodes].max(axis=0, initial=-np.inf))
                               for b, piece in self.pieces.items()})
        halves_sigma, low, high = {}, np.full(2, np.inf), np.full(2, -np.inf)
        for ranked in held:
            for side, (numbers, lowest, highest) in ranked.items():
                halves_sigma[side], low, high = numbers, np.minimum(low, lowest), np.maximum(high, highest)
        shares, tops = {}, {}
        for b, piece in self.pieces.items():
            spec, fields = BLOCKS[b], cell_fields[b]
            u = self.displacements[b][piece.owned_nodes]
            datasets.update(hdf5.block_datasets(spec.name, u, fields.von_mises, self.indicators[b], piece=piece))
            glue = viewer.Glue(halves_sigma[-1], halves_sigma[1], sigma.crack, local.nodes, local.cells,
                               self.on.traces[BLOCKS[partner(b)].name])
            shares[spec.layer] = viewer.layer_share(spec.layer, spec.side, piece.points[piece.owned_nodes], u,
                                                    piece.nodes[piece.owned_cells], fields, glue, self.indicators[b],
                                                    first_node=piece.first, first_cell=piece.cell_first)
            tops[spec.layer] = plots.largest_values(fields.von_mises, sum(local.cells.values()))
        tops = comm.gather(tops, root=0)
        script = ""
        if exchange.is_root:
            datasets.update(hdf5.sigma_datasets(self.on, result.history, result.active_set_changes, result.levels,
                                              result.fracture, result.reactions))
            shares["sigma"] = viewer.sigma_mesh(self.on, local.half(-1).degree)
            ceilings = {layer: plots.stress_ceiling(np.concatenate([top[layer] for top in tops if layer in top]),
                                                    sum(local.cells.values())) for layer in viewer.LAYER_TITLES}
            script = viewer.paraview_script(self.scene.title, output.parent, viewer.viewer_names(output.stem),
                                            ceilings, plots.scale_for(float((high - low).max()), self.on.largest),
                                            plots.one_above_the_other(np.array([low, high])),
                                            analysis.sigma_is_graph(self.on))
        return hdf5.Part(datasets), viewer.Distributed(shares, script)


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
    on_piece = replace(mesh, halves={BLOCKS[index].side: piece.half})
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
        block.system = replace(block.system, rhs=system.rhs)
    setup.interface = interface_of(scene, setup.mesh, setup.exchange.comm)  # the new data's displacement
    setup.phases = Phases()
    setup.phases.end("assembly")
    setup.phases.skip("factorization")


def interface_of(scene: Scene, local: LocalMesh, comm: MPI.Comm) -> Interface:
    """The scene's interface on every rank (collective): the displacement its data would make is the
    largest over the ranks' halves or pieces (:func:`ddsolve.fem.assembly.data_displacement`)."""
    data = comm.allreduce(assembly.data_displacement(scene, local.halves.values(), local.sigma), op=MPI.MAX)
    return for_mesh(local.sigma, scene.nonpenetration, local.sigma_supports.fixed, assembly.modulus(scene), data)


def prepare(scene: Scene, comm: MPI.Comm, mesh: Mesh | None = None, phases: Phases | None = None,
            keep_halves: bool = True) -> Setup:
    """Build (or take) the mesh, assemble and factor every rank's blocks.  Not ``keep_halves`` (a solve whose
    ranks write the result together): from assembly on, a rank holds only its pieces of its halves
    (:mod:`ddsolve.mesh.pieces`; all a gathered result, a reload or a critical-factor search would need the
    halves whole)."""
    if not supported(comm.size):
        error = DDSolveError(f"unsupported number of ranks {comm.size}: use 1, 2 or a multiple of 4")
        error.collective = True  # every rank sees the same size
        raise error
    phases = phases if phases is not None else Phases()
    stages = {name: PETSc.Log.Stage(name) for name in STAGES}

    stages["Setup"].push()
    exchange = Exchange(comm, len(BLOCKS))
    if mesh is not None:
        tips, table, block_kernels = comm.bcast(collective(comm, lambda: whole_mesh_checks(scene, mesh),
                                                           root_only=True), root=0)
        local = whole(mesh, tips, table, block_kernels)
    else:
        local = local_mesh(scene, comm, exchange, phases, whole_halves=keep_halves)
    scene = resolve(scene, comm.size, local)
    method = scene.solver.method
    phases.hold("mesh", local.nbytes)
    floating = local.kernels.floating
    if floating and method not in FLOATING_METHODS:
        error = SceneError(f"solver.method = {method}: blocks {local.kernels.names()} are floating (held only "
                           f"through Σ, their stiffness singular), which {method} cannot solve: use "
                           f"{' or '.join(FLOATING_METHODS)}")
        error.collective = True  # every rank knows the supports
        raise error
    block_pieces = cut_pieces(local, exchange)
    kernel_rows = {index: floating_kernel(scene, local, index, block_pieces[index], fixed=method == "feti")
                   for index in exchange.local_blocks if index in floating}
    whole_bytes = whole_mesh_bytes(local, exchange)
    if not keep_halves:
        local = replace(local, halves={BLOCKS[index].side: piece.half for index, piece in block_pieces.items()})
    phases.hold("mesh", local.nbytes + pieces.extra_bytes(block_pieces.values(), local.halves.values()))
    phases.end("distribution")  # the pieces cut, and the halves dropped: assembly holds what it works on
    blocks = collective(comm, lambda: make_blocks(scene, local, exchange, FACTOR_PACKAGE[method], block_pieces))
    interface = interface_of(scene, local, comm)
    hold_blocks(phases, blocks, factored=False)
    stages["Setup"].pop()
    phases.end("assembly")

    stages["Factorization"].push()
    def factor():
        for index, block in zip(exchange.local_blocks, blocks):
            if index in floating:
                block.make_floating(*kernel_rows[index])
            if not (block.floating and method == "schur"):  # schur inverts a floating block's interior only
                block.factor(schur=method == "schur", out_of_core=scene.solver.out_of_core)
            if method == "feti" or block.floating:
                block.factor_dirichlet(out_of_core=scene.solver.out_of_core)

    collective(comm, factor)
    hold_blocks(phases, blocks)
    stages["Factorization"].pop()
    phases.end("factorization")
    return Setup(local, exchange, blocks, interface, stages, phases, scene, block_pieces, whole_bytes)


def cut_pieces(local: LocalMesh, exchange: Exchange) -> dict[int, Piece]:
    """This rank's piece of the half of each of its blocks: the nodes of its rows (:mod:`ddsolve.mesh.pieces`;
    a block's rows are shared out as :func:`ddsolve.fem.assembly.row_ranges` says), made with the mesh or cut now."""
    if local.pieces:
        return {index: local.pieces[BLOCKS[index].side] for index in exchange.local_blocks}
    out = {}
    for index, group in zip(exchange.local_blocks, exchange.groups):
        half = local.half(BLOCKS[index].side)
        first, last = assembly.row_ranges(len(half.points), group.size)[group.rank]
        out[index] = pieces.cut(half, first // 2, last // 2)
    return out


def floating_kernel(scene: Scene, mesh: LocalMesh, index: int, piece: Piece, fixed: bool
                    ) -> tuple[np.ndarray, np.ndarray | None]:
    """A floating block's kernel at its rows here (the nodes ``piece`` owns) and, with ``fixed``, the dofs fixed
    for FETI's K⁺: m dofs of the half's outer boundary, off the trace and the prescribed dofs, where the kernel
    is independent (chosen from the skeleton every piece keeps, the same on every rank of the block)."""
    spec, half = BLOCKS[index], piece.half
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
    """The scene with ``auto`` replaced by the method :func:`ddsolve.dd.methods.choose` picks."""
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


def solve_decomposed(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, mesh: Mesh | None = None,
          setup: Setup | None = None, gather: bool = True, factors: np.ndarray | None = None,
          refined_next: Callable[[Result], bool] | None = None) -> Result | None:
    """Run the domain decomposition for ``scene`` on ``comm``; write ``output``.

    Not ``gather`` (the command line), with ``output`` on more than one rank and h5py built with MPI:
    every rank writes its part of the result set (:class:`OnRanks`) and rank 0's result holds only the
    Σ data, the scalars and G (``mesh`` None, ``solution`` empty); else rank 0 gathers the whole
    result and writes it.

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
    distributed = output is not None and not gather and hdf5.parallel_available(comm)
    if own:
        setup = prepare(scene, comm, mesh, Phases(launch_age() if mesh is None else 0.0), keep_halves=not distributed)
    else:
        # the method the setup was made for (``auto`` resolved), the scene's other solver settings
        scene = dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=setup.scene.solver.method))
        setup.scene = scene
    phases = setup.phases
    local, exchange, interface, stages, scene = setup.mesh, setup.exchange, setup.interface, setup.stages, setup.scene
    method = scene.solver.method

    try:
        piece_dofs = {index: piece.local_dofs() for index, piece in setup.pieces.items()}
        server = BlockServer(setup.blocks, exchange, piece_dofs, gather=not distributed)
        outcome, rounds, failure = run_method(scene, setup, server, progress)
        failure = comm.bcast(failure, root=0)
        if failure is not None:
            failure.collective = True
        phases.hold("schur complements", rounds.schur_bytes if rounds is not None else 0)  # rank 0's, during the method
        phases.hold("solutions", server.held_bytes)
        mine = {"mesh_bytes": local.nbytes, "unknowns": sum(len(b.system.rhs) for b in setup.blocks),
                "factor_mb": sum(b.factor_megabytes() for b in setup.blocks),
                "out_of_core": any(b.out_of_core() for b in setup.blocks)}
        if own:  # the factors are done with: the estimate and the output run in the memory they held
            for block in setup.blocks:
                block.destroy()
            hold_blocks(phases, [])
        phases.end("iterations")
        if failure is not None and not isinstance(failure, NotConvergedError):
            raise failure

        displacements = piece_displacements(setup, server)
        if distributed:  # the output reads the (x, y) copy alone
            server.piece_values.clear()
        indicators = block_indicators(setup, displacements, collect=not distributed)
        if distributed:
            shares = OnRanks(scene, local, exchange, setup.pieces, interface, outcome.lam if exchange.is_root else None,
                             indicators, displacements, server.held_bytes)
        else:
            parts = gather_estimate(local, exchange, indicators)
        phases.end("estimate")
        stages["Output"].push()
        volume = comm.reduce(fracture.block_terms(scene, local.sigma, local.tips, {
            index: (piece.points, piece.cells[:piece.owned], displacements[index])
            for index, piece in setup.pieces.items()}), root=0)  # each rank over the cells it owns
        sizes = [2 * local.nodes[spec.side] for spec in BLOCKS]
        whole_bytes = setup.whole_mesh_bytes
        if distributed:
            mine["held_bytes"] = shares.held_bytes
        else:
            solutions = exchange.gather_varying([server.solutions[b] for b in exchange.led_blocks], sizes)
            mesh = gather_upper(local, exchange)
            mine["held_bytes"] = (whole_bytes + 8 * sum(sizes) if exchange.is_root else
                                  local.nbytes + sum(8 * sizes[b] for b in exchange.led_blocks))
        gathered = not distributed and exchange.is_root  # the whole mesh and every solution
        phases.hold("mesh", whole_bytes if gathered else local.nbytes)
        phases.hold("solutions", mine["held_bytes"] - (whole_bytes if gathered else local.nbytes))
        result = None
        if exchange.is_root:
            record = dict(
                converged=outcome.converged, iterations=outcome.iterations, solves=rounds.count,
                wall_time=phases.wall["factorization"] + phases.wall["iterations"], ranks=comm.size,
                history=np.array(outcome.history), message=outcome.message,
                active_set_changes=np.array(outcome.active_set_changes, dtype=np.int64),
                attrs={**launch.provenance(), **local.quality, "stop": scene.solver.stop, "tol": scene.solver.tol,
                       **outcome.details})
            if distributed:
                result = Result(scene=scene, method=method, mesh=None, solution={},
                                multipliers=shares.on.multipliers, held=shares.on, **record)
                result.attrs["error_estimate"] = shares.relative
                result.reactions = shares.reactions
            else:
                result = Result.from_blocks(scene, method, mesh, solutions, interface, outcome.lam, **record)
                estimated = estimate.combine(mesh, parts, result.solution, result.multipliers["mu_c"],
                                             assembly.modulus(scene))
                result.attrs["error_estimate"], result.indicators = estimated.relative, estimated.indicators
                if refined_next is None or not refined_next(result):
                    result.fracture = fracture.finish(local.tips, volume, result.on_sigma,
                                                      fracture.mode_split(local.tips, result), scene, factors)
                    result.reactions = reactions.reactions(scene, mesh, result.solution, local.sigma_supports)
        if distributed:
            split = shares.mode_split()  # collective: the leaders integrate their blocks' shares
            if exchange.is_root:
                result.fracture = fracture.finish(local.tips, volume, shares.on, split, scene, factors)
            part, viewer = shares.files(result, output, block_cell_fields(setup, displacements))
        phases.end("output")  # G, its modes, the reactions and the files' contents included
        withdrawn = comm.bcast(result.claim() if exchange.is_root else None, root=0)
        if withdrawn and failure is None:  # written with converged = false, then raised on every rank
            failure = NotConvergedError(withdrawn)
            failure.collective = True
        memory = comm.gather((mine, phases), root=0)
        if exchange.is_root:
            timings = dict(phases.wall)
            timings["update"] = timings["iterations"] - rounds.elapsed
            timings["setup"] = sum(timings.get(name, 0.0) for name in ("meshing", "distribution", "assembly"))
            for name in phases.cpu:  # CPU seconds of every rank together
                timings[f"{name}_cpu"] = sum(ranked.cpu[name] for _, ranked in memory)
            result.timings, result.memory = timings, memory_record(memory, sum(sizes), whole_bytes)
            result.attrs["peak_memory_mb"] = [max(ranked.peak.values()) for _, ranked in memory]
            # what MUMPS did (a PETSc option may have overridden solver.out_of_core)
            result.attrs["factors_out_of_core"] = any(ranked["out_of_core"] for ranked, _ in memory)
        if distributed:
            if exchange.is_root:
                part.attrs = hdf5.attributes(result)
            written = time.perf_counter()
            hdf5.write_distributed(output, part, viewer, comm, final=True)
        elif output is not None:
            written = time.perf_counter()
            collective(comm, lambda: hdf5.write(output, result, final=True), root_only=True)
        if output is not None and result is not None:  # the launch's last phase, for whoever reports it
            result.timings["write"] = time.perf_counter() - written
        stages["Output"].pop()
        if failure is not None:  # not converged: the result is written with converged = false
            failure.result = result
            raise failure
        return result
    finally:
        if own:
            setup.destroy()


