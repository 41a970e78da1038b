"""The mesh on the ranks: each rank receives the half its blocks live on and Σ; rank 0 checks the
whole mesh once (its own half and the upper half's skeleton) and, for a gathered result, gets the upper
half for output."""
from __future__ import annotations

import dataclasses
import functools
import operator
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from ddsolve.dd import kernels
from ddsolve.fem import supports
from ddsolve.fem.assembly import check_range
from ddsolve.fem.supports import SigmaSupports
from ddsolve.mesh import curves, geometry, gmsh_io, refine
from ddsolve.mesh import mesh as meshes
from ddsolve.mesh.mesh import BLOCKS, U_PLUS, HalfMesh, Mesh, SigmaLine
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


def whole(mesh: Mesh, tips: list | None = None, table: SigmaSupports | None = None,
          block_kernels: kernels.Kernels | None = None) -> LocalMesh:
    """The whole mesh as a rank holding both halves sees it."""
    halves = {-1: mesh.lower, 1: mesh.upper}
    return LocalMesh(halves, mesh.sigma, {side: len(half.points) for side, half in halves.items()},
                     {side: len(half.cells) for side, half in halves.items()}, mesh.origin, tips or [], table,
                     block_kernels)


def build_mesh(scene: Scene, comm: MPI.Comm) -> Mesh:
    """The scene's whole mesh on every rank, for experiments and adaptive levels that need it everywhere."""
    exchange = Exchange(comm, len(BLOCKS))
    try:
        mine = local_mesh(scene, comm, exchange, keep_whole=True)
    finally:
        exchange.free()
    halves = {side: comm.bcast(mine.halves.get(side) if comm.rank == 0 else None, root=0) for side in (-1, 1)}
    return Mesh(halves[-1], halves[1], mine.sigma, mine.origin)


def local_mesh(scene: Scene, comm: MPI.Comm, exchange: Exchange, phases: Phases | None = None,
               keep_whole: bool = False) -> LocalMesh:
    """Each rank gets the half its blocks live on (both with one rank), Σ, and the crack tips.

    A box is meshed by the leaders of u⁻ (rank 0, lower half) and u⁺ (upper half) at once, else
    rank 0 makes the whole mesh.  Rank 0 pairs the halves (checks, Σ, the loads' boundaries; of a box's
    upper half it gets the skeleton, :func:`~ddsolve.mesh.mesh.skeleton`), then
    each half goes to the ranks that need it by a broadcast among them.  Rank 0 keeps the upper half
    only with one rank (or ``keep_whole``); it gets it back for output (:func:`gather_upper`).
    A mesh made by refinement (:func:`geometry.refinement`) is made by :func:`refined_local_mesh`.
    """
    coarse_scene, levels = comm.bcast(collective(comm, lambda: geometry.refinement(scene), root_only=True),
                                      root=0)  # rank 0 decides
    if levels:
        return refined_local_mesh(scene, coarse_scene, levels, comm, exchange, phases, keep_whole)
    rank = comm.rank
    upper_maker = exchange.leader(U_PLUS)
    split = scene.mesh.kind == "box" and comm.size > 1
    if split:
        side = -1 if rank == 0 else 1 if rank == upper_maker else 0
        made = collective(comm, lambda: geometry.generate_half(scene, side) if side else None)
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
        upper_size = (len(paired.upper.points), len(paired.upper.cells)) if rank == 0 else None
    checked = collective(comm, lambda: whole_mesh_checks(scene, paired), root_only=True)
    meshed(phases)
    sigma, nodes, cells, (tips, table, block_kernels) = comm.bcast(
        (paired.sigma, {-1: len(paired.lower.points), 1: upper_size[0]},
         {-1: len(paired.lower.cells), 1: upper_size[1]}, checked) if rank == 0 else None, root=0)
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
    local = LocalMesh(halves, sigma, nodes, cells, geometry.origin(scene), tips, table, block_kernels,
                      meshes.quality(paired) if rank == 0 else {})
    if phases is not None:
        phases.hold("mesh", local.nbytes)
        phases.end("distribution")
    return local


def upper_for_rank_0(upper: HalfMesh, keep_whole: bool) -> tuple[HalfMesh, tuple[int, int]]:
    """What u⁺'s leader sends rank 0 to pair and check: the upper half's skeleton (the whole half if rank 0
    keeps it) and the half's numbers of nodes and cells."""
    return upper if keep_whole else meshes.skeleton(upper), (len(upper.points), len(upper.cells))


def meshed(phases: Phases | None) -> None:
    """End the ``meshing`` phase; the warm gmsh child's import of gmsh counts as start-up, when it ran."""
    spent_starting = gmsh_io.warm_up_cpu()
    if phases is not None:
        phases.end("meshing")
        phases.move_cpu(spent_starting, "meshing", "startup")


def refined_local_mesh(scene: Scene, coarse_scene: Scene, levels: int, comm: MPI.Comm, exchange: Exchange,
                       phases: Phases | None = None, keep_whole: bool = False) -> LocalMesh:
    """:func:`local_mesh` for a mesh that is ``coarse_scene``'s refined ``levels`` times.

    The coarse halves are made as a whole mesh is (a box's by the leaders of u⁻ and u⁺ at once, else on
    rank 0, which sends the upper one to u⁺'s leader); each goes to the ranks of its half, which refine
    an equal share of its coarse cells each (:class:`~ddsolve.mesh.refine.Lattice`; the first rank of a
    half none when the half has more than two: it made the coarse mesh, or it is rank 0, which pairs
    and checks next) and exchange the pieces and the shape of the cells each made (the whole half's
    shortest side and smallest angle).  Rank 0 then gets the skeleton of the upper half from u⁺'s
    leader (its boundary: :func:`~ddsolve.mesh.mesh.skeleton`; the whole half with ``keep_whole``),
    pairs and checks the mesh.
    Phases: ``meshing`` is this rank's own work (gmsh's coarse mesh, its share of the refinement);
    ``distribution`` the waits and exchanges, the pairing and the checks on rank 0.
    """
    rank, upper_maker = comm.rank, exchange.leader(U_PLUS)
    end = phases.end if phases is not None else (lambda name: None)
    if scene.mesh.kind == "box" and comm.size > 1:
        side = -1 if rank == 0 else 1 if rank == upper_maker else 0
        made = collective(comm, lambda: geometry.generate_half(coarse_scene, side) if side else None)
        coarse = {side: made} if side else {}
        if rank == upper_maker:
            comm.send(made, dest=0)
        elif rank == 0:
            coarse[1] = comm.recv(source=upper_maker)
        whole_coarse = collective(comm, lambda: geometry.pair(scene, coarse[-1], coarse[1]), root_only=True)
    else:
        whole_coarse = collective(comm, lambda: geometry.build_coarse(coarse_scene), root_only=True)
        coarse = {-1: whole_coarse.lower, 1: whole_coarse.upper} if rank == 0 else {}
        if upper_maker != 0:
            if rank == 0:
                comm.send(coarse[1], dest=upper_maker)
            elif rank == upper_maker:
                coarse[1] = comm.recv(source=0)
    meshed(phases)
    needed = sorted({BLOCKS[b].side for b in exchange.local_blocks})
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
    and the blocks' kernels."""
    geometry.check_loads(scene, mesh)
    table = supports.check(scene, mesh)
    check_range(scene, mesh)
    block_kernels = kernels.of_scene(scene, mesh, table)
    toughness.check_cracks(scene, len(mesh.sigma.pieces(mesh.sigma.crack)))
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
