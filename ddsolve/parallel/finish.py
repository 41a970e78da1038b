"""Finishing a solve once its multiplier method has ended: the error estimate, G and its modes, the
reactions, the cell fields and the files.  One interface (:class:`Finisher`), two ways:

- :class:`Gathered`: the leaders of the blocks gather their solutions (and the upper half) to rank 0,
  which finishes the whole result and writes it;
- :class:`OnRanks` (a result the ranks write together, parallel HDF5): every rank finishes on its pieces
  of its blocks' halves (:mod:`ddsolve.mesh.pieces`) and writes its slabs of the files; rank 0's result
  holds the Σ data, the scalars and G.

:func:`chosen` says which; the driver (:func:`ddsolve.solvers.driver.solve_decomposed`) makes it from its setup
(:class:`ddsolve.solvers.driver.Setup`) after the method, then calls :meth:`Finisher.collect`,
:meth:`Finisher.result` and :meth:`Finisher.write` in turn, on every rank.
"""
from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path

import numpy as np
from mpi4py import MPI

from ddsolve.fem import assembly
from ddsolve.io import hdf5, viewer
from ddsolve.mesh.mesh import U_MINUS, U_PLUS, partner
from ddsolve.mesh.pieces import Piece
from ddsolve.parallel.distribution import LocalMesh, gather_upper
from ddsolve.parallel.exchange import Exchange, collective
from ddsolve.parallel.rounds import BlockServer
from ddsolve.post import analysis, estimate, fracture, plots, reactions
from ddsolve.post.result import OnSigma, Result


def chosen(output: Path | None, gather: bool, comm: MPI.Comm) -> type[Finisher]:
    """:class:`OnRanks` when the ranks write ``output`` together (not ``gather``, more than one rank and h5py
    built with MPI), else :class:`Gathered`."""
    return OnRanks if output is not None and not gather and hdf5.parallel_available(comm) else Gathered


class Finisher(ABC):
    """What a solve does after its method, on every rank: made once the method has ended (the displacements of
    the last full solve on this rank's pieces, the error estimate's parts), then :meth:`collect`,
    :meth:`result` and :meth:`write` in turn.  ``setup``: the driver's :class:`~ddsolve.solvers.driver.Setup`; ``lam``: the multipliers
    (rank 0); ``output``: the result file, if any."""

    #: Whether the ranks keep their blocks' halves whole and the block server gathers the solutions to the
    #: blocks' leaders.
    whole: bool

    def __init__(self, setup, server: BlockServer, lam: np.ndarray | None, output: Path | None):
        self.setup, self.server, self.lam, self.output = setup, server, lam, output
        self.scene, self.local, self.exchange, self.pieces = setup.scene, setup.mesh, setup.exchange, setup.pieces
        self.specs = setup.interface.blocks  # the structure's blocks
        self.displacements = piece_displacements(setup, server)
        self.volume = None
        self.held_bytes = self.mesh_bytes = 0

    def collect(self) -> None:
        """G's volume terms on rank 0 (each rank over the cells it owns), and what this rank holds for the
        output: ``held_bytes``, of which ``mesh_bytes`` of mesh (collective)."""
        local = self.local
        self.volume = self.exchange.comm.reduce(fracture.block_terms(self.scene, local.sigma, local.tips, {
            index: (piece.points, piece.cells[:piece.owned], self.displacements[index])
            for index, piece in self.pieces.items()}), root=0)

    @abstractmethod
    def result(self, record: dict, factors: np.ndarray | None = None,
               refined_next: Callable[[Result], bool] | None = None) -> Result | None:
        """The result on rank 0 (None elsewhere) with ``record`` (its scalars and histories), the estimate,
        G and its modes (``factors``: the critical load factors, :func:`ddsolve.solvers.driver.solve_decomposed`) and the
        reactions; the files' contents ready (collective)."""

    @abstractmethod
    def write(self, result: Result | None) -> float:
        """Write the result set to ``output`` (collective; ``result``: rank 0's, its timings complete but the
        writing's); the seconds the writing took."""


class Gathered(Finisher):
    """Rank 0 gathers the block solutions and the upper half, finishes the whole result and writes it."""

    whole = True

    def __init__(self, setup, server: BlockServer, lam: np.ndarray | None, output: Path | None):
        super().__init__(setup, server, lam, output)
        self.parts = gather_estimate(self.local, self.exchange, block_indicators(setup, self.displacements),
                                     self.specs)
        self.solutions = self.mesh = None

    def collect(self) -> None:
        super().collect()
        local, exchange, whole_bytes = self.local, self.exchange, self.setup.whole_mesh_bytes
        sizes = [2 * local.nodes[spec.side] for spec in self.specs]
        self.solutions = exchange.gather_varying([self.server.solutions[b] for b in exchange.led_blocks], sizes)
        self.mesh = gather_upper(local, exchange)
        self.held_bytes = (whole_bytes + 8 * sum(sizes) if exchange.is_root else
                           local.nbytes + sum(8 * sizes[b] for b in exchange.led_blocks))
        self.mesh_bytes = whole_bytes if exchange.is_root else local.nbytes  # the whole mesh on rank 0

    def result(self, record: dict, factors: np.ndarray | None = None,
               refined_next: Callable[[Result], bool] | None = None) -> Result | None:
        """As :meth:`Finisher.result`; ``refined_next`` (rank 0): given the result with its estimate and
        indicators, whether it is only a step to a finer mesh (then G, its modes and the reactions are not
        computed)."""
        if not self.exchange.is_root:
            return None
        scene, mesh, local = self.scene, self.mesh, self.local
        result = Result.from_blocks(scene, scene.solver.method, mesh, self.solutions, self.setup.interface,
                                    self.lam, **record)
        estimated = estimate.combine(mesh, self.parts, result.solution, result.multipliers["mu_c"],
                                     assembly.modulus(scene))
        result.attrs["error_estimate"], result.indicators = estimated.relative, estimated.indicators
        if refined_next is None or not refined_next(result):
            result.fracture = fracture.finish(local.tips, self.volume, result.on_sigma,
                                              fracture.mode_split(local.tips, result), scene, factors)
            result.reactions = reactions.reactions(scene, mesh, result.solution, local.sigma_supports)
        return result

    def write(self, result: Result | None) -> float:
        written = time.perf_counter()
        collective(self.exchange.comm, lambda: hdf5.write(self.output, result, final=True), root_only=True)
        return time.perf_counter() - written


class OnRanks(Finisher):
    """The result as the ranks hold it for a distributed write: every rank its pieces of its blocks' halves
    (:mod:`ddsolve.mesh.pieces`) with the displacements (x, y) there, the indicators and cell fields of the
    cells it owns, and its slabs of the files; rank 0 the Σ data (:class:`OnSigma`) and the estimate, from
    sums over the ranks.  Only Σ-sized arrays and scalars are exchanged."""

    whole = False

    def __init__(self, setup, server: BlockServer, lam: np.ndarray | None, output: Path | None):
        super().__init__(setup, server, lam, output)
        server.piece_values.clear()  # the output reads the (x, y) copy alone
        indicators = block_indicators(setup, self.displacements, collect=False)
        local, exchange, block_pieces, displacements = self.local, self.exchange, self.pieces, self.displacements
        comm, sigma, scene = exchange.comm, local.sigma, self.scene
        frames = sigma.frames[sigma.multiplier_nodes]
        self.held_bytes = local.nbytes + server.held_bytes + sum(u.nbytes for u in displacements.values())
        self.mesh_bytes = local.nbytes
        # a piece has every Σ node of its half
        traces = exchange.gather_varying([displacements[b][block_pieces[b].half.sigma].ravel()
                                          for b in exchange.led_blocks], [2 * len(sigma.points)] * len(self.specs))
        largest = comm.allreduce(max((np.abs(displacements[b][piece.owned_nodes]).max(initial=0.0)
                                      for b, piece in block_pieces.items()), default=0.0), op=MPI.MAX)
        on = OnSigma(sigma, setup.interface.split(lam, frames),
                     {spec.name: trace.reshape(-1, 2) for spec, trace in zip(self.specs, traces)},
                     largest) if exchange.is_root else None
        self.on = comm.bcast(on, root=0)
        pressure, jump = estimate.contact_on_sigma(sigma, self.on.multipliers["mu_c"],
                                                   self.on.traces[self.specs[U_MINUS].name],
                                                   self.on.traces[self.specs[U_PLUS].name])
        self.indicators, squared, energy = {}, 0.0, 0.0
        for b, piece in block_pieces.items():
            contact = (estimate.half_contact_indicators(piece.owned_half, pressure, jump)
                       if b in (U_MINUS, U_PLUS) else 0.0)
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
        if scene.dissimilar_layers(thermal=False):  # every rank: no split (fracture.split_note)
            return None
        laws = [assembly.elasticity(scene, spec.layer, spec.region)[0] for spec in self.specs]
        mirrorable = [fracture.mirrorable(tip, sigma, scene) for tip in tips]
        shared = exchange.groups[0].size > 1  # the blocks' ranks own parts of their halves: ask where it may be
        boxes = comm.allgather({b: analysis.owned_box(piece) for b, piece in self.pieces.items()}
                               if shared and any(mirrorable) else {})
        discs, asks = {}, [[] for _ in range(comm.size)]
        for i, tip in enumerate(tips):
            for b, piece in self.pieces.items():
                if mirrorable[i]:
                    discs[i, b] = fracture.mirror_nodes(tip, sigma, piece.owned_half)
                    images = discs[i, b][2]
                    for rank in exchange.ranks(partner(b, self.specs)) if len(images) else ():  # no disc cells here
                        asked = np.arange(len(images))
                        if shared:
                            low, high = boxes[rank][partner(b, self.specs)]
                            asked = asked[np.all((images >= low) & (images <= high), axis=1)]
                        asks[rank].append((i, b, asked, images[asked]))
        answers = [[(i, b, asked, *analysis.owned_values_at(self.pieces[partner(b, self.specs)],
                                                            self.displacements[partner(b, self.specs)], images))
                    for i, b, asked, images in received]
                   for received in comm.alltoall(asks)]
        replies: dict[tuple[int, int], list] = {}
        for i, b, *answer in (answer for answered in comm.alltoall(answers) for answer in answered):
            replies.setdefault((i, b), []).append(answer)
        shares, failed = np.zeros((len(tips), 2)), np.zeros(len(tips), dtype=np.int64)
        for (i, b), answered in replies.items():
            spec, values = self.specs[b], analysis.nearest_answer(len(discs[i, b][2]), answered)
            terms = None if values is None else fracture.mirror_terms(
                tips[i], sigma, self.pieces[b].owned_half, laws[b], self.displacements[b], discs[i, b],
                values, assembly.thermal_of(scene, spec.layer, spec.region))
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

    def result(self, record: dict, factors: np.ndarray | None = None,
               refined_next: Callable[[Result], bool] | None = None) -> Result | None:
        """As :meth:`Finisher.result`: rank 0's result holds only the Σ data, the scalars and G (``mesh`` None,
        ``solution`` empty); every rank's slabs of the files are made (``refined_next`` is not asked)."""
        local, exchange, scene = self.local, self.exchange, self.scene
        result = None
        if exchange.is_root:
            result = Result(scene=scene, method=scene.solver.method, mesh=None, solution={},
                            multipliers=self.on.multipliers, held=self.on, **record)
            result.attrs["error_estimate"] = self.relative
            result.reactions = self.reactions
        split = self.mode_split()  # collective: the leaders integrate their blocks' shares
        if exchange.is_root:
            result.fracture = fracture.finish(local.tips, self.volume, self.on, split, scene, factors)
        self.part, self.viewer = self.files(result, self.output, block_cell_fields(self.setup, self.displacements))
        return result

    def write(self, result: Result | None) -> float:
        exchange = self.exchange
        if exchange.is_root:
            self.part.attrs = hdf5.attributes(result)
        written = time.perf_counter()
        hdf5.write_distributed(self.output, self.part, self.viewer, exchange.comm, final=True)
        return time.perf_counter() - written

    def _reactions(self) -> dict[str, dict[str, np.ndarray]] | None:
        """The reactions on rank 0: every rank the support forces at the nodes it owns, the gluing's ties
        settled on rank 0 from the Σ entries (:func:`ddsolve.post.reactions.reactions` in one process)."""
        scene, local, comm = self.scene, self.local, self.exchange.comm
        sigma = local.sigma
        count = 2 * len(sigma.multiplier_nodes)
        forces, positions, mine = {}, {}, {}
        specs = self.specs
        entries, owning = np.zeros((len(specs), count)), np.zeros((len(specs), count), dtype=np.int64)
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
        tied = reactions.tie(sigma, list(entries.reshape(len(specs), -1, 2)),
                             list(owning.reshape(len(specs), -1, 2) > 0), specs) if self.exchange.is_root else None
        tied = comm.bcast(tied, root=0)
        parts = []
        for b, piece in self.pieces.items():
            forces[b][positions[b][mine[b]]] = tied[b][mine[b]]
            parts.append((specs[b].layer, reactions.boundary_sums(scene, piece.half, sigma, specs[b].layer,
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
        datasets, specs = {}, self.specs
        for b, piece in self.pieces.items():  # a half's first block writes its mesh, its leader Σ and boundaries
            if b == min(c for c, spec in enumerate(specs) if spec.side == specs[b].side):
                datasets.update(hdf5.half_datasets(piece.half, nodes, piece, skeleton=b in exchange.led_blocks))
        held = comm.allgather({specs[b].side: (piece.nodes[piece.half.sigma],
                                                piece.points[piece.owned_nodes].min(axis=0, initial=np.inf),
                                                piece.points[piece.owned_nodes].max(axis=0, initial=-np.inf))
                               for b, piece in self.pieces.items()})
        halves_sigma, low, high = {}, np.full(2, np.inf), np.full(2, -np.inf)
        for ranked in held:
            for side, (numbers, lowest, highest) in ranked.items():
                halves_sigma[side], low, high = numbers, np.minimum(low, lowest), np.maximum(high, highest)
        shares, tops = {}, {}
        for b, piece in self.pieces.items():
            spec, fields = specs[b], cell_fields[b]
            u = self.displacements[b][piece.owned_nodes]
            datasets.update(hdf5.block_datasets(spec.name, u, fields.von_mises, self.indicators[b], piece=piece))
            glue = viewer.Glue(halves_sigma[-1], halves_sigma[1], sigma.crack, local.nodes, local.cells,
                               self.on.traces[specs[partner(b, specs)].name])
            shares[spec.layer] = viewer.layer_share(spec.layer, spec.side, piece.points[piece.owned_nodes], u,
                                                    piece.nodes[piece.owned_cells], fields, glue, self.indicators[b],
                                                    first_node=piece.first, first_cell=piece.cell_first)
            tops[spec.layer] = plots.largest_values(fields.von_mises, sum(local.cells.values()))
        tops = comm.gather(tops, root=0)
        script = ""
        if exchange.is_root:
            datasets.update(hdf5.sigma_datasets(self.on, result.history, result.active_set_changes, result.levels,
                                              result.fracture, result.reactions, result.scene.friction))
            shares["sigma"] = viewer.sigma_mesh(self.on, local.half(-1).degree, result.scene.friction)
            ceilings = {layer: plots.stress_ceiling(np.concatenate([top[layer] for top in tops if layer in top]),
                                                    sum(local.cells.values())) for layer in self.scene.layers}
            names = viewer.viewer_names(output.stem, layers=self.scene.layers)
            script = viewer.paraview_script(self.scene.title, output.parent, names,
                                            ceilings, plots.scale_for(float((high - low).max()), self.on.largest),
                                            plots.one_above_the_other(np.array([low, high])),
                                            analysis.sigma_is_graph(self.on))
        return hdf5.Part(datasets), viewer.Distributed(shares, script, self.scene.layers)


def piece_displacements(setup, server: BlockServer) -> dict[int, np.ndarray]:
    """Local block -> the last full solve at the nodes of this rank's piece of its half, ``(n, 2)`` in x, y."""
    sigma = setup.mesh.sigma
    frames = sigma.frames[sigma.multiplier_nodes]
    out = {}
    for index, piece in setup.pieces.items():  # a piece has every Σ node of its half
        out[index] = assembly.to_global(server.piece_values[index], assembly.trace_nodes(piece.half, sigma), frames)
    return out


def block_indicators(setup, displacements: dict[int, np.ndarray], collect: bool = True
                     ) -> dict[int, np.ndarray]:
    """The error indicators ``(2, cells)`` of the last full solve (:func:`ddsolve.post.estimate.block_indicators`):
    every rank of a block computes those of the cells it owns on its piece of the half (:mod:`ddsolve.mesh.pieces`,
    ``displacements`` there: :func:`piece_displacements`); with ``collect`` the block's leader gets the whole
    half's (local block -> indicators, on the leaders), else every rank keeps its own cells'."""
    out = {}
    for index, group in zip(setup.exchange.local_blocks, setup.exchange.groups):
        spec, piece = setup.interface.blocks[index], setup.pieces[index]
        D, _ = assembly.elasticity(setup.scene, spec.layer, spec.region)
        mine = estimate.block_indicators(piece.points, piece.cells, D, displacements[index],
                                         piece.outer_edges)[:, :piece.owned]
        whole = collect_owned(group, piece, setup.mesh.cells[spec.side], {"indicators": mine.T}) if collect else \
            {"indicators": mine.T}
        if whole is not None:
            out[index] = whole["indicators"].T
    return out


def block_cell_fields(setup, displacements: dict[int, np.ndarray]) -> dict[int, analysis.CellFields]:
    """The cell fields of the last full solve on the cells this rank owns (local block -> its
    :class:`~ddsolve.post.analysis.CellFields`)."""
    specs = setup.interface.blocks
    return {index: analysis.block_cell_fields(setup.scene, specs[index].layer, specs[index].region, piece.points,
                                              piece.owned_cells, displacements[index])
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


def gather_estimate(mesh: LocalMesh, exchange: Exchange, indicators: dict[int, np.ndarray], specs: tuple
                    ) -> dict[str, np.ndarray] | None:
    """The blocks' (``specs``) error indicators (:func:`block_indicators`) on rank 0 (block name ->
    ``(2, cells)``), None elsewhere."""
    parts = exchange.gather_varying([indicators[index].ravel() for index in exchange.led_blocks],
                                    [2 * mesh.cells[spec.side] for spec in specs])
    return None if parts is None else {spec.name: part.reshape(2, -1) for spec, part in zip(specs, parts)}
