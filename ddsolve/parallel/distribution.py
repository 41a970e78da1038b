"""The mesh on the ranks: each rank receives the half its blocks live on and Σ; rank 0 checks the
whole mesh once (its own half and the upper half's skeleton) and, for a gathered result, gets the upper
half for output."""
from __future__ import annotations

import dataclasses
import functools
import operator
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from ddsolve.dd import kernels
from ddsolve.fem import supports
from ddsolve.fem.assembly import check_range, row_ranges
from ddsolve.fem.supports import SigmaSupports
from ddsolve.mesh import curves, geometry, gmsh_io, pieces, refine
from ddsolve.mesh import mesh as meshes
from ddsolve.mesh.mesh import U_PLUS, HalfMesh, Mesh, SigmaLine
from ddsolve.mesh.pieces import Piece
from ddsolve.parallel.exchange import Exchange, collective, wait
from ddsolve.parallel.phases import Phases
from ddsolve.post import fracture, toughness
from ddsolve.problem.scene import Scene


@dataclass(frozen=True, eq=False)
class LocalMesh:
    """What a rank holds of the mesh: the halves its blocks live on, Σ, and the size of both halves."""

    halves: dict[int, HalfMesh]
    sigma: SigmaLine
    nodes: dict[int, int]  # side -> nodes of that half (both sides)
    cells: dict[int, int]  # side -> cells of that half (both sides)
    origin: str
    tips: list = dataclasses.field(default_factory=list)  # the crack tips (fracture.Tip)
    sigma_supports: SigmaSupports | None = None  # the prescribed trace entries (needs both halves to make)
    kernels: kernels.Kernels | None = None  # the blocks' kernels (rigid motions their supports leave)
    quality: dict = dataclasses.field(default_factory=dict)  # rank 0: the whole mesh's (meshes.quality)
    pieces: dict[int, Piece] = dataclasses.field(default_factory=dict)  # side -> this rank's piece, when made alone
    whole_bytes: dict[int, int] = dataclasses.field(default_factory=dict)  # side -> its arrays' bytes, with pieces

    def half(self, side: int) -> HalfMesh:
        return self.halves[side]

    @property
    def nbytes(self) -> int:
        """Bytes of the mesh arrays held here (halves and Σ)."""
        return self.sigma_bytes + sum(half_bytes(half) for half in self.halves.values())

    @property
    def sigma_bytes(self) -> int:
        """Bytes of Σ's arrays."""
        return int(sum(getattr(self.sigma, name).nbytes for name in ("points", "normals", "weights", "crack", "tip",
                                                                     "clamped", "corner")))


def whole(mesh: Mesh, tips: list | None = None, table: SigmaSupports | None = None,
          block_kernels: kernels.Kernels | None = None) -> LocalMesh:
    """The whole mesh as a rank holding both halves sees it."""
    halves = {-1: mesh.lower, 1: mesh.upper}
    return LocalMesh(halves, mesh.sigma, {side: len(half.points) for side, half in halves.items()},
                     {side: len(half.cells) for side, half in halves.items()}, mesh.origin, tips or [], table,
                     block_kernels)


def build_mesh(scene: Scene, comm: MPI.Comm) -> Mesh:
    """The scene's whole mesh on every rank, for experiments and adaptive levels that need it everywhere."""
    exchange = Exchange(comm, len(meshes.blocks(scene.geometry.layers)))
    try:
        mine = local_mesh(scene, comm, exchange, keep_whole=True)
    finally:
        exchange.free()
    halves = {side: comm.bcast(mine.halves.get(side) if comm.rank == 0 else None, root=0) for side in (-1, 1)}
    return Mesh(halves[-1], halves[1], mine.sigma, mine.origin)


def local_mesh(scene: Scene, comm: MPI.Comm, exchange: Exchange, phases: Phases | None = None,
               keep_whole: bool = False, whole_halves: bool = True) -> LocalMesh:
    """Each rank gets the half its blocks live on (both with one rank), Σ, and the crack tips.

    A box is meshed by the leaders of u⁻ (rank 0, lower half) and u⁺ (upper half) at once, else
    rank 0 makes the whole mesh.  Rank 0 pairs the halves (checks, Σ, the loads' boundaries; of a box's
    upper half it gets the skeleton, :func:`~ddsolve.mesh.mesh.skeleton`), then
    each half goes to the ranks that need it by a broadcast among them.  Rank 0 keeps the upper half
    only with one rank (or ``keep_whole``); it gets it back for output (:func:`gather_upper`).
    A mesh made by refinement (:func:`geometry.refinement`) is made by :func:`refined_local_mesh`; not
    ``whole_halves``, a rank of a block shared by several gets only its piece of it (:mod:`ddsolve.mesh.pieces`).
    """
    coarse_scene, levels = comm.bcast(collective(comm, lambda: geometry.refinement(scene), root_only=True),
                                      root=0)  # rank 0 decides
    if levels:
        return refined_local_mesh(scene, coarse_scene, levels, comm, exchange, phases, keep_whole, whole_halves)
    rank = comm.rank
    upper_maker = exchange.leader(U_PLUS)
    split = scene.mesh.kind == "box" and comm.size > 1
    if split:
        side = -1 if rank == 0 else 1 if rank == upper_maker else 0
        made = collective(comm, lambda: geometry.generate_half(scene, side) if side else None)
        meshed(phases, [made] if side else [])
        for_rank_0 = collective(comm, lambda: upper_for_rank_0(made, keep_whole) if rank == upper_maker else None)
        if rank == upper_maker:
            comm.send(for_rank_0, dest=0)
        halves = {side: made} if side else {}
        if rank == 0:
            halves[1], upper_size = comm.recv(source=upper_maker)
        paired = collective(comm, lambda: geometry.pair(scene, halves[-1], halves[1]), root_only=True)
    else:
        paired = collective(comm, lambda: geometry.build(scene), root_only=True)
        halves = {-1: paired.lower, 1: paired.upper} if rank == 0 else {}
        meshed(phases, halves.values())
        upper_size = (len(paired.upper.points), len(paired.upper.cells)) if rank == 0 else None
    checked = collective(comm, lambda: whole_mesh_checks(scene, paired), root_only=True)
    if phases is not None:  # the halves this rank made or was sent (rank 0: the upper one's skeleton, or whole)
        phases.hold("mesh", sum(half_bytes(half) for half in halves.values()))
    sigma, nodes, cells, (tips, table, block_kernels) = comm.bcast(
        (paired.sigma, {-1: len(paired.lower.points), 1: upper_size[0]},
         {-1: len(paired.lower.cells), 1: upper_size[1]}, checked) if rank == 0 else None, root=0)
    needed = sorted({meshes.blocks(scene.geometry.layers)[b].side for b in exchange.local_blocks})
    made, whole_bytes = {}, {}  # this rank's piece and the halves' sizes, when the maker sends pieces
    if comm.size > 1:
        if not split and upper_maker != 0:  # rank 0 made both halves: the upper one goes to u⁺'s leader
            if rank == 0:
                comm.send(halves[1], dest=upper_maker)
            elif rank == upper_maker:
                halves[1] = comm.recv(source=0)
        group = comm.Split(color=int(needed[0] > 0), key=rank)  # the ranks of one half; its maker is the first
        try:
            if not whole_halves and not keep_whole and comm.size > exchange.n_blocks:
                piece, size = collective(comm, lambda: scattered_piece(group, exchange.groups[0],
                                                                       halves.get(needed[0])))
                halves, made, whole_bytes = {needed[0]: piece.half}, {needed[0]: piece}, dict(comm.allgather(
                    (needed[0], size)))
            else:
                halves = {needed[0]: group.bcast(halves.get(needed[0]), root=0),
                          **({1: halves[1]} if keep_whole and rank == 0 else {})}
        finally:
            group.Free()
    local = LocalMesh(halves, sigma, nodes, cells, geometry.origin(scene), tips, table, block_kernels,
                      meshes.quality(paired) if rank == 0 else {}, made, whole_bytes)
    if phases is not None:
        phases.hold("mesh", local.nbytes + pieces.extra_bytes(made.values(), halves.values()))
        phases.end("distribution")
    return local


def scattered_piece(group: MPI.Comm, block_group: MPI.Comm, half: HalfMesh | None) -> tuple[Piece, int]:
    """This rank's piece of the half that ``group``'s first rank holds (:func:`~ddsolve.mesh.pieces.cut` there, one
    per row range of the block, and sent) and the bytes of that half's arrays."""
    size = group.bcast((len(half.points), half_bytes(half)) if group.rank == 0 else None, root=0)
    ranges = group.gather(assembly_ranges(size[0], block_group), root=0)
    if group.rank != 0:
        return group.recv(source=0), size[1]
    cut = {bounds: pieces.cut(half, *bounds) for bounds in set(ranges)}
    MPI.Request.waitall([group.isend(cut[bounds], dest=member) for member, bounds in enumerate(ranges) if member])
    return cut[ranges[0]], size[1]


def upper_for_rank_0(upper: HalfMesh, keep_whole: bool) -> tuple[HalfMesh, tuple[int, int]]:
    """What u⁺'s leader sends rank 0 to pair and check: the upper half's skeleton (the whole half if rank 0
    keeps it) and the half's numbers of nodes and cells."""
    return upper if keep_whole else meshes.skeleton(upper), (len(upper.points), len(upper.cells))


def meshed(phases: Phases | None, made: Iterable[HalfMesh] = ()) -> None:
    """End the ``meshing`` phase when this rank has made its mesh (holding the halves ``made``): sending, pairing
    and checking meshes are distribution's.  The warm gmsh child's import of gmsh counts as start-up, when it ran."""
    spent_starting = gmsh_io.warm_up_cpu()
    if phases is not None:
        phases.hold("mesh", sum(half_bytes(half) for half in made))
        phases.end("meshing")
        phases.move_cpu(spent_starting, "meshing", "startup")


def refined_local_mesh(scene: Scene, coarse_scene: Scene, levels: int, comm: MPI.Comm, exchange: Exchange,
                       phases: Phases | None = None, keep_whole: bool = False, whole_halves: bool = True
                       ) -> LocalMesh:
    """:func:`local_mesh` for a mesh that is ``coarse_scene``'s refined ``levels`` times.

    The coarse halves are made as a whole mesh is (a box's by the leaders of u⁻ and u⁺ at once, else on
    rank 0, which sends the upper one to u⁺'s leader); each goes to the ranks of its half, which refine
    an equal share of its coarse cells each (:class:`~ddsolve.mesh.refine.Lattice`; the first rank of a
    half none when the half has more than two: it made the coarse mesh, or it is rank 0, which pairs
    and checks next) and exchange the pieces and the shape of the cells each made (the whole half's
    shortest side and smallest angle).  Rank 0 then gets the skeleton of the upper half from u⁺'s
    leader (its boundary: :func:`~ddsolve.mesh.mesh.skeleton`; the whole half with ``keep_whole``),
    pairs and checks the mesh.  Not ``whole_halves``, with more ranks than blocks, each rank makes its
    piece alone instead (:func:`refined_pieces`).
    Phases: ``meshing`` is this rank's own work (gmsh's coarse mesh, its share of the refinement);
    ``distribution`` the waits and exchanges, the pairing and the checks on rank 0.
    """
    rank, upper_maker = comm.rank, exchange.leader(U_PLUS)
    end = phases.end if phases is not None else (lambda name: None)
    if scene.mesh.kind == "box" and comm.size > 1:
        side = -1 if rank == 0 else 1 if rank == upper_maker else 0
        made = collective(comm, lambda: geometry.generate_half(coarse_scene, side) if side else None)
        meshed(phases)
        coarse = {side: made} if side else {}
        if rank == upper_maker:
            comm.send(made, dest=0)
        elif rank == 0:
            coarse[1] = comm.recv(source=upper_maker)
        whole_coarse = collective(comm, lambda: geometry.pair(scene, coarse[-1], coarse[1]), root_only=True)
    else:
        whole_coarse = collective(comm, lambda: geometry.build_coarse(coarse_scene), root_only=True)
        meshed(phases)
        coarse = {-1: whole_coarse.lower, 1: whole_coarse.upper} if rank == 0 else {}
        if upper_maker != 0:
            if rank == 0:
                comm.send(coarse[1], dest=upper_maker)
            elif rank == upper_maker:
                coarse[1] = comm.recv(source=0)
    if not whole_halves and not keep_whole and comm.size > exchange.n_blocks:
        return refined_pieces(scene, levels, comm, exchange, coarse, whole_coarse, phases)
    needed = sorted({meshes.blocks(scene.geometry.layers)[b].side for b in exchange.local_blocks})
    project = curves.projector(scene)  # new vertices on a .geo's curves
    group = comm.Split(color=int(needed[0] > 0), key=rank) if comm.size > 1 else comm  # its maker is first
    fine = {}
    try:
        for side in needed:
            grid = refine.Lattice(group.bcast(coarse.get(side), root=0), levels, scene.mesh.degree)
            end("distribution")
            bounds = refine.shares(grid, group.size, idle_first=group.size > 2)
            first, stop = bounds[group.rank], bounds[group.rank + 1]
            points, cells = collective(comm, lambda: (grid.fine_points(first, stop, project), grid.fine_cells(first, stop)))
            end("meshing")
            whole_points, whole_cells = share_pieces(group, grid, bounds, points, cells)
            shape = functools.reduce(operator.and_, group.allgather(meshes.shape_of(whole_points, cells[:, :3])))
            fine[side] = grid.half(whole_points, whole_cells, shape)
    finally:
        if group != comm:
            group.Free()
    upper = fine.get(1)
    upper_size = (len(upper.points), len(upper.cells)) if upper is not None else None
    if comm.size > 1:
        for_rank_0 = collective(comm, lambda: upper_for_rank_0(upper, keep_whole) if rank == upper_maker else None)
        if rank == upper_maker:
            comm.send(for_rank_0, dest=0)
        elif rank == 0:
            upper, upper_size = comm.recv(source=upper_maker)
    paired = collective(comm, lambda: refine.pair_refined(whole_coarse, fine[-1], upper), root_only=True)
    checked = collective(comm, lambda: whole_mesh_checks(scene, paired), root_only=True)
    sizes = (paired.sigma, {-1: len(fine[-1].points), 1: upper_size[0]},
             {-1: len(fine[-1].cells), 1: upper_size[1]}, checked) if rank == 0 else None
    sigma, nodes, cells, (tips, table, block_kernels) = comm.bcast(sizes, root=0)
    if keep_whole and rank == 0:
        fine[1] = upper
    local = LocalMesh(fine, sigma, nodes, cells, geometry.origin(scene), tips, table, block_kernels,
                      meshes.quality(paired) if rank == 0 else {})
    if phases is not None:
        phases.hold("mesh", local.nbytes)
    end("distribution")
    return local


def refined_pieces(scene: Scene, levels: int, comm: MPI.Comm, exchange: Exchange, coarse: dict[int, HalfMesh],
                   whole_coarse: Mesh | None, phases: Phases | None) -> LocalMesh:
    """The rest of :func:`refined_local_mesh` when every rank makes only its piece of its block's half.

    The coarse half goes to the ranks of its half; each makes its piece (:func:`~ddsolve.mesh.pieces.of_lattice`:
    the nodes of its rows of the block, their cells and two rings; making the fine cells and points counts as
    meshing, choosing, ordering and numbering them as distribution, as cutting a piece from a whole half does)
    and learns where its owned cells start from the ranks before it in the block.  The half's shape comes
    from every rank's owned cells; the leaders of u⁻ (rank 0) and u⁺ make their half's skeleton from the
    coarse one (:meth:`~ddsolve.mesh.refine.Lattice.skeleton`), and rank 0 pairs and checks those.  No rank
    holds a whole fine half.
    """
    rank, upper_maker = comm.rank, exchange.leader(U_PLUS)
    end = phases.end if phases is not None else (lambda name: None)
    index, block_group = exchange.local_blocks[0], exchange.groups[0]
    side = meshes.blocks(scene.geometry.layers)[index].side
    project = curves.projector(scene)
    group = comm.Split(color=int(side > 0), key=rank)  # the ranks of one half; its coarse mesh's holder is first
    partners = comm.Split(color=2 * block_group.rank + int(side > 0), key=rank)  # those making the same piece
    try:
        grid = refine.Lattice(group.bcast(coarse.get(side), root=0), levels, scene.mesh.degree)
        end("distribution")

        def mark(name: str, nbytes: int) -> None:  # the piece made so far and the coarse half
            if phases is not None:
                phases.hold("mesh", nbytes + half_bytes(grid.coarse))
            end(name)

        first, last = assembly_ranges(grid.node_count, block_group)
        piece = collective(comm, lambda: pieces.of_lattice(grid, first, last, project, share=(partners.rank,
                                                                                               partners.size),
                                                           join=lambda part: joined(partners, part), mark=mark))
        piece = dataclasses.replace(piece, cell_first=block_group.exscan(piece.owned) or 0)
        shape = functools.reduce(operator.and_, group.allgather(meshes.shape_of(piece.points,
                                                                                piece.owned_cells[:, :3])))
        whole_bytes = grid_bytes(grid)
        skeleton = collective(comm, lambda: grid.skeleton(shape, project) if rank in (0, upper_maker) else None)
    finally:
        group.Free()
        partners.Free()
    if rank == upper_maker:
        comm.send((skeleton, (grid.node_count, grid.cell_count * grid.cells_per_cell), whole_bytes), dest=0)
    elif rank == 0:
        upper, upper_size, upper_bytes = comm.recv(source=upper_maker)
    paired = collective(comm, lambda: refine.pair_refined(whole_coarse, skeleton, upper), root_only=True)
    checked = collective(comm, lambda: whole_mesh_checks(scene, paired), root_only=True)
    sizes = (paired.sigma, {-1: grid.node_count, 1: upper_size[0]},
             {-1: grid.cell_count * grid.cells_per_cell, 1: upper_size[1]}, {-1: whole_bytes, 1: upper_bytes},
             checked) if rank == 0 else None
    sigma, nodes, cells, whole_sizes, (tips, table, block_kernels) = comm.bcast(sizes, root=0)
    local = LocalMesh({side: piece.half}, sigma, nodes, cells, geometry.origin(scene), tips, table, block_kernels,
                      meshes.quality(paired) if rank == 0 else {}, {side: piece}, whole_sizes)
    if phases is not None:  # with the coarse half, still held
        phases.hold("mesh", local.nbytes + pieces.extra_bytes([piece], local.halves.values()) + half_bytes(grid.coarse))
    end("distribution")
    return local


def joined(comm: MPI.Comm, part: np.ndarray) -> np.ndarray:
    """The ``part`` arrays of the ranks of ``comm``, in their order, one after the other (one Allgatherv)."""
    part = np.ascontiguousarray(part)
    counts = comm.allgather(part.size)
    whole = np.empty((sum(counts) // max(1, int(np.prod(part.shape[1:]))), *part.shape[1:]), dtype=part.dtype)
    wait(comm.Iallgatherv(part, [whole, counts]))
    return whole


def assembly_ranges(nodes: int, block_group: MPI.Comm) -> tuple[int, int]:
    """The nodes ``first:stop`` of this rank's rows of its block (:func:`ddsolve.fem.assembly.row_ranges`)."""
    first, last = row_ranges(nodes, block_group.size)[block_group.rank]
    return first // 2, last // 2


def half_bytes(half: HalfMesh) -> int:
    """Bytes of a half's mesh arrays."""
    return int(sum(a.nbytes for a in (half.points, half.cells, half.sigma, *half.boundaries.values())))


def grid_bytes(grid: refine.Lattice) -> int:
    """Bytes the arrays of the fine half ``grid`` numbers would take whole (int64 cells)."""
    cells = grid.cell_count * grid.cells_per_cell * 3 * grid.degree
    return 16 * grid.node_count + 8 * cells + grid.sigma().nbytes + sum(e.nbytes for e in grid.boundaries().values())


def share_pieces(group: MPI.Comm, grid: refine.Lattice, bounds, points, cells) -> tuple:
    """The whole fine half's points and cells on every rank of ``group``, from each rank's piece (the
    fine nodes and cells of its coarse cells ``bounds[r]:bounds[r + 1]``), placed by one Allgatherv each."""
    per_cell = grid.cells_per_cell * 3 * grid.degree
    whole_points = np.empty((grid.node_count, 2))
    whole_cells = np.empty((grid.cell_count * grid.cells_per_cell, 3 * grid.degree), dtype=np.int64)
    node_counts = 2 * np.diff(grid.node_offsets[bounds])
    cell_counts = per_cell * np.diff(bounds)
    for mine, whole_array, counts, kind in ((points, whole_points, node_counts, MPI.DOUBLE),
                                            (cells, whole_cells, cell_counts, MPI.INT64_T)):
        displacements = np.concatenate([[0], np.cumsum(counts)[:-1]])
        wait(group.Iallgatherv(np.ascontiguousarray(mine), [whole_array, counts.tolist(), displacements.tolist(),
                                                            kind]))
    return whole_points, whole_cells


def whole_mesh_checks(scene: Scene, mesh: Mesh) -> tuple[list[fracture.Tip], SigmaSupports, kernels.Kernels]:
    """What needs the whole mesh (rank 0, before it is distributed): the loads' and displacements'
    boundaries, the range of the moduli and loads, the supports (a structure that can move rigidly is
    refused); the crack tips with their θ radii (which keep clear of the outer boundary), the Σ supports
    and the blocks' kernels; a per-crack toughness or friction against the mesh's cracks."""
    geometry.check_loads(scene, mesh)
    table = supports.check(scene, mesh)
    check_range(scene, mesh)
    block_kernels = kernels.of_scene(scene, mesh, table)
    cracks = len(mesh.sigma.pieces(mesh.sigma.crack))
    toughness.check_cracks(scene, cracks)
    if scene.friction is not None:
        scene.friction.per_crack(cracks)  # refused here once, before every rank builds its interface
    return fracture.find_tips(mesh, scene.fracture.inner, scene.fracture.outer), table, block_kernels


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
