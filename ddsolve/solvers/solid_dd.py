"""The domain decomposition of a 3-D box (``geometry.box = [x0, x1, y0, y1, z0, z1]``): its two halves as the
blocks u⁻ (below Σ) and u⁺ (above), or each half cut into slabs parallel to Σ (``solver.pieces``,
:mod:`ddsolve.mesh.slabs`) glued across their cuts as Σ is off the cracks, the structure's trace Σ's and the cuts'
(:meth:`~ddsolve.dd.interface.Interface.joined`, as for several interfaces); on any number of ranks up to the blocks
(some holding a block more: every rank assembles its own blocks from the whole mesh) or a multiple of them.

The plane driver's machinery (:mod:`ddsolve.solvers.stacked_dd`) with three trace entries per Σ vertex: a block's
trace is its displacements at every Σ vertex in Σ's frame (x, ν = y, z; :class:`~ddsolve.dd.interface.Interface`
with ``components = 3``), μᶜ acts on the normal (y) at the crack vertices, μᵍ on all three components off them.
The mesh is built once on rank 0 and broadcast; each rank assembles its blocks (or its rows of one,
:func:`block_system`); rank 0 runs the multiplier method and finishes the same
:class:`~ddsolve.post.solid.SolidResult` as the monolithic reference (:mod:`ddsolve.solvers.solid`), written to the
same files.  A half held only through Σ floats, as does a slab held only through its neighbours: its kernel is the
rigid motions (of six) its own supports leave (:mod:`ddsolve.dd.kernels`), factored and solved as the plane driver
does; a box that can move rigidly as a whole is refused in one line.  A box of several interfaces is decomposed into
its regions, a block each, joined at every Σ (:func:`regions_decomposition`).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse
from mpi4py import MPI
from petsc4py import PETSc

from ddsolve.dd import kernels, registry, solid_costs
from ddsolve.dd.constraints import Constraints
from ddsolve.dd.interface import Interface
from ddsolve.environment import physical_memory
from ddsolve.errors import DDSolveError, SceneError
from ddsolve.fem import tetra
from ddsolve.fem.assembly import BlockSystem, trace_entries
from ddsolve.io import solid as solid_files
from ddsolve.mesh import slabs
from ddsolve.mesh import solid as solid_meshes
from ddsolve.mesh.mesh import BlockSpec
from ddsolve.mesh.mesh import blocks as block_list
from ddsolve.mesh.slabs import Slab
from ddsolve.mesh.solid import SolidHalf, SolidMesh
from ddsolve.parallel.blocks import Block
from ddsolve.parallel.exchange import Exchange, collective
from ddsolve.parallel.launch import supported, usable
from ddsolve.parallel.rounds import BlockServer
from ddsolve.post.solid import SolidResult
from ddsolve.problem.scene import Scene
from ddsolve.solvers import driver, solid, solid_lines
from ddsolve.solvers.reference import Joint
from ddsolve.solvers.stacked_dd import trace_layout

#: The trace entries of a Σ vertex: x, y (Σ's normal, component 1 as in the plane) and z.
COMPONENTS = 3
#: The dense matrices of Σ's size (3 s)² that ``schur`` holds at once on one machine: each half's Schur complement
#: in MUMPS, in its block and gathered on rank 0, rank 0's interface stiffness and its factor (1 + 2 × 3 + 1).
SCHUR_COPIES = 8
#: The share of this machine's memory ``schur``'s dense matrices may take (above it: refused, ``auto`` takes feti).
SCHUR_MEMORY_SHARE = 0.5
#: The share of a block's tetrahedra with a vertex on each of two of its joints above which it is one element thick
#: and MUMPS fails to factor it with its Schur complement on the trace (INFOG(1) = -8; ``auto`` then takes feti): the
#: middle region of docs/three-d-interfaces.toml at mesh.size 0.25 and 0.45 fails at 0.76-0.81 (as thick as mesh.size
#: or less), works at 0.64 and below (0.3 thick at 0.25, 0.5 at 0.45).
THIN_SHARE = 0.7


@dataclass(frozen=True, eq=False)
class Decomposition:
    """The blocks of a 3-D box: its halves' slabs (:mod:`ddsolve.mesh.slabs`), block 2j the lower half's slab j and
    2j + 1 the upper half's (slab 0 at Σ), and the joints between them: Σ first, then the cuts of the lower half,
    then those of the upper; ``points``, the vertices of the structure's trace, joint after joint.  With one slab
    per half the interface is Σ's own."""

    slabs: list[Slab]
    supports: list[tuple[np.ndarray, np.ndarray]]  # each block's prescribed dofs and values, tied across its cuts
    specs: tuple[BlockSpec, ...]
    joints: list[Joint]
    points: np.ndarray
    interface: Interface
    regions: int = 2  # a box of several interfaces: its regions, one block each (:func:`regions_decomposition`)

    @property
    def count(self) -> int:
        """Slabs per half (per region)."""
        return len(self.slabs) // self.regions

    def half_of(self, block: int) -> int:
        """The half (0 lower, 1 upper), or the region (0 the lowest), of ``block``."""
        return block % self.regions


@dataclass
class SolidSetup:
    """What every rank holds after assembly and factorization: the whole mesh, its decomposition, this rank's
    factored blocks and the interface (rank 0 runs the method on it)."""

    scene: Scene  # with the method resolved
    mesh: SolidMesh
    parts: Decomposition
    exchange: Exchange
    blocks: list[Block]
    positions: dict[int, np.ndarray] | None  # each local block's entries of the structure's trace (None: one slab)
    kernels: kernels.Kernels
    stages: dict
    timings: dict[str, float]
    trace_stiffness: list | None  # rank 0, feti's lumped preconditioner: each block's K_ΣΣ (sparse)

    @property
    def interface(self) -> Interface:
        """The multipliers of every joint (rank 0 runs the method on them)."""
        return self.parts.interface

    def trace_entries(self) -> list[np.ndarray] | None:
        """Each block's entries of the structure's trace (None: one slab per half, every block holds Σ's whole)."""
        return trace_layout(self.parts.joints, len(self.parts.slabs))[0] if self.positions is not None else None

    def kernel_traces(self) -> list[np.ndarray]:
        """The traces ``(trace size, m_b)`` of the blocks' kernels: zero off the entries a block holds."""
        modes = self.kernels.frame.modes(self.parts.points).T
        positions, _ = trace_layout(self.parts.joints, len(self.parts.slabs))
        traces = []
        for kernel, held in zip(self.kernels.kernels, positions):
            trace = np.zeros((len(modes), kernel.shape[1]))
            trace[held] = modes[held] @ kernel
            traces.append(trace)
        return traces

    def destroy(self) -> None:
        for block in self.blocks:
            block.destroy()
        self.exchange.free()


def kernels_of(parts: Decomposition) -> kernels.Kernels:
    """The blocks' kernels: the rigid motions their own supports leave (:func:`ddsolve.dd.kernels.held_kernels`);
    a SceneError naming the motion when the box can move rigidly as a whole."""
    frame = kernels.frame_of(np.vstack([slab.piece.points for slab in parts.slabs]))
    rows = [kernels.constraint_rows(frame.modes(slab.piece.points), dofs) for slab, (dofs, _) in
            zip(parts.slabs, parts.supports)]
    return kernels.held_kernels(rows, frame.modes(parts.points).T, parts.interface, frame)


def method_of(scene: Scene, parts: Decomposition, held: kernels.Kernels, ranks: int = 1) -> Scene:
    """The scene with ``auto`` resolved (the method and feti's preconditioner the cost model predicts fastest on
    ``parts`` and ``ranks``, :func:`ranking`; several interfaces: ``schur`` while it fits; never ``schur`` on
    :func:`thin_blocks`) and the slabs per half of
    ``parts``; in one line, what this solve does not take: ``schur`` above its memory limit (:func:`schur_bytes`), a
    floating block (kernels ``held``) with a method that cannot solve it (friction and bonds the scene refuses)."""
    method = registry.METHODS.get(scene.solver.method)
    if held.floating and method is not None and not method.floating:
        raise SceneError(f"solver.method = {method.name}: block {held.names()} of the 3-D box is floating (held "
                         f"only through its interfaces, its stiffness singular), which {method.name} cannot solve: "
                         f"use {' or '.join(registry.floating_methods())}")
    dense, limit = schur_bytes(parts.interface), schur_limit()
    if scene.solver.method == "schur" and dense > limit:
        raise SceneError(f"solver.method = schur: the dense Schur complements of this 3-D box's interfaces "
                         f"({parts.interface.trace_size} trace entries) need about {dense / 1e9:.3g} GB, above the "
                         f"{limit / 1e9:.3g} GB allowed ({SCHUR_MEMORY_SHARE:g} of this machine's memory): use "
                         "solver.method = feti")
    schur = dense <= limit and not thin_blocks(parts)
    if parts.regions > 2:  # the model knows a box of one Σ: several interfaces take schur while it fits
        best = solid_costs.Candidate("schur" if schur else "feti", 1, "dirichlet")
    else:
        best = ranking(scene, box_of(scene, parts), ranks, [parts.count], schur)[0]
    method = scene.solver.method if scene.solver.method in registry.METHODS else best.method
    preconditioner = best.preconditioner if scene.solver.preconditioner == "auto" else scene.solver.preconditioner
    degree = scene.solver.coarse_degree
    if degree == "auto":
        degree = solid_costs.COARSE_DEGREE if method == "feti" else 0
    return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=method, pieces=parts.count,
                                                                 preconditioner=preconditioner, coarse_degree=degree))


def schur_bytes(interface: Interface | int) -> float:
    """Bytes of the dense matrices ``schur`` holds at once (:data:`SCHUR_COPIES` of the size of the trace, or of
    ``interface`` trace entries)."""
    size = interface if isinstance(interface, int) else interface.trace_size
    return SCHUR_COPIES * 8.0 * size ** 2


def schur_limit() -> float:
    """Bytes ``schur``'s dense matrices may take (:data:`SCHUR_MEMORY_SHARE` of this machine's memory)."""
    return SCHUR_MEMORY_SHARE * physical_memory()


def thin_blocks(parts: Decomposition) -> list[int]:
    """The blocks MUMPS cannot factor with their Schur complement on the trace (``schur``): those with no free dof
    off their trace, and those one element thick between two of their joints (more than :data:`THIN_SHARE` of their
    tetrahedra with a vertex on each: a region as thin as mesh.size)."""
    _, dofs = trace_layout(parts.joints, len(parts.slabs))
    thin = []
    for block, slab in enumerate(parts.slabs):
        held = np.union1d(dofs[block], parts.supports[block][0])
        touching = [np.isin(slab.piece.tetrahedra, joint.dofs[joint.blocks.index(block)][::COMPONENTS] // COMPONENTS)
                    .any(axis=1) for joint in parts.joints if block in joint.blocks]  # per joint: each tetrahedron
        spanning = max((np.mean(first & second) for i, first in enumerate(touching) for second in touching[i + 1:]),
                       default=0.0)
        if len(held) == slab.piece.dofs or spanning > THIN_SHARE:
            thin.append(block)
    return thin


def box_of(scene: Scene, parts: Decomposition) -> solid_costs.Box:
    """What the cost model reads of the box that ``parts`` cut: its unknowns (a cut's vertices once), Σ's vertices
    and contact rows, the element degree."""
    surface = parts.joints[0].interface
    shared = COMPONENTS * len(parts.points) - surface.trace_size  # the cuts' dofs, held by two slabs each
    return solid_costs.Box(sum(slab.piece.dofs for slab in parts.slabs) - shared, surface.trace_size // COMPONENTS,
                           int(np.count_nonzero(surface.is_contact)), scene.mesh.degree)


def ranking(scene: Scene, box: solid_costs.Box, ranks: int, counts: list[int], schur: bool = True
            ) -> list[solid_costs.Candidate]:
    """``auto``'s candidates on ``counts`` slabs per half that the ranks share and ``scene``'s solver keys leave
    (its method and feti's preconditioner; the halves whole for a method the model does not know), predicted
    fastest first (:mod:`ddsolve.dd.solid_costs`); ``schur`` where its dense matrices fit and ``schur`` (False: a
    half is too thin for it, :func:`thin_blocks`).  Where none is left (``schur`` asked on slabs, a count the ranks
    cannot share), feti's on those counts: its preconditioner."""
    fits = schur and schur_bytes(COMPONENTS * box.sigma) <= schur_limit()
    method, preconditioner = scene.solver.method, scene.solver.preconditioner
    modelled = method in ("auto", "schur", "feti")
    shared = [count for count in counts
              if supported(ranks, 2 * count, uneven=True) and (modelled or count == 1)] or counts
    every = solid_costs.candidates(shared, fits)
    kept = [c for c in every if method in ("auto", c.method) or not modelled]
    kept = [c for c in kept if preconditioner in ("auto", c.preconditioner) or c.method == "schur"]
    return solid_costs.ranked(box, ranks, kept or [c for c in every if c.method == "feti"])


def trace_dofs(half: SolidHalf) -> np.ndarray:
    """The half's dofs at every Σ vertex, in Σ order: x, y, z per vertex."""
    return node_dofs(half.sigma_nodes)


def node_dofs(nodes: np.ndarray) -> np.ndarray:
    """The dofs of ``nodes``, in their order: x, y, z per node."""
    return tetra.element_dofs(nodes[:, None]).ravel()


def block_system(scene: Scene, half: SolidHalf, name: str, trace: np.ndarray, supports: tuple[np.ndarray, np.ndarray],
                 rows: tuple[int, int] | None = None) -> BlockSystem:
    """The half's (or slab's) system with its ``supports`` (prescribed dofs, values) decoupled and its ``trace`` dofs
    (its ``rows`` only, where given; the energy offset counted on the rows that start at 0)."""
    system = tetra.half_system(scene, half, supports)
    whole = dataclasses.replace(system.decoupled(name), trace_dofs=trace, energy_offset=prescribed_energy(system))
    if rows is None:
        return whole
    first, last = rows
    indptr = whole.indptr[first:last + 1]
    return dataclasses.replace(whole, indptr=indptr - indptr[0], indices=whole.indices[indptr[0]:indptr[-1]],
                               data=whole.data[indptr[0]:indptr[-1]], rhs=whole.rhs[first:last], first=first,
                               energy_offset=whole.energy_offset if first == 0 else 0.0)


def prescribed_energy(system: tetra.HalfSystem) -> float:
    """What Π adds to ½ xᵀ K̃ x − xᵀ f̃ of the decoupled system at its solution (:class:`BlockSystem`):
    ½ g·K_PP g + ½ Σ K_ii g_i² − f_P·g, with g the prescribed values, and the thermal offset ½ ∫ ε₀ᵀ D ε₀."""
    g, P = system.values, system.dofs
    return float(0.5 * g @ (system.K[P][:, P] @ g) + 0.5 * system.K.diagonal()[P] @ g ** 2 - system.f[P] @ g) \
        + system.offset


def row_ranges(nodes: int, parts: int) -> list[tuple[int, int]]:
    """A block's dofs in ``parts`` contiguous ranges of whole nodes (three dofs each)."""
    bounds = np.linspace(0, nodes, parts + 1).round().astype(int)
    return [(COMPONENTS * a, COMPONENTS * b) for a, b in zip(bounds[:-1], bounds[1:])]


def interface_of(scene: Scene, mesh: SolidMesh, k: int = 0) -> Interface:
    """The multipliers of Σ number ``k``: μᶜ on the crack vertices' normal under non-penetration, μᵍ (three
    components) off the cracks; none between two prescribed entries."""
    sigma = mesh.sigmas[k]
    fixed = np.zeros((2, COMPONENTS * len(sigma.points)), dtype=bool)
    for row, region, nodes in zip(fixed, mesh.regions[k:k + 2], mesh.border(k)):
        row[:] = np.isin(node_dofs(nodes), tetra.prescribed(scene, region)[0])
    return Interface(sigma.weights, sigma.cracked, scene.nonpenetration, fixed, modulus_of(scene, mesh),
                     specs=block_list(1), components=COMPONENTS, points=sigma.points)


def modulus_of(scene: Scene, mesh: SolidMesh) -> float:
    """The largest elastic modulus of the regions' materials (the KKT check's stress scale)."""
    return max(tetra.largest_modulus(scene.material("layer1", region.name)) for region in mesh.regions)


def regions_decomposition(scene: Scene, mesh: SolidMesh) -> Decomposition:
    """The blocks of a box of several interfaces: its regions, bottom to top, one block each, joined at every Σ
    (μᶜ on its cracks, μᵍ off them); the structure's trace the interfaces' vertices, bottom to top."""
    count = len(mesh.regions)
    joints = [Joint(interface_of(scene, mesh, k), (k, k + 1),
                    tuple(node_dofs(nodes) for nodes in mesh.border(k)))
              for k in range(len(mesh.sigmas))]
    supports = [tetra.prescribed(scene, region) for region in mesh.regions]
    specs = tuple(BlockSpec(region.name, "layer1", 0) for region in mesh.regions)
    interface = Interface.joined([joint.interface for joint in joints], [joint.blocks for joint in joints], specs)
    return Decomposition([Slab(region, np.arange(len(region.points))) for region in mesh.regions], supports, specs,
                         joints, np.vstack([sigma.points for sigma in mesh.sigmas]), interface, count)


def decomposition(scene: Scene, mesh: SolidMesh, count: int) -> Decomposition | None:
    """The box's blocks with ``count`` slabs per half, None where that many do not fit both halves (a box of
    several interfaces: its regions, :func:`regions_decomposition`, with one)."""
    if len(mesh.sigmas) > 1:
        return regions_decomposition(scene, mesh) if count == 1 else None
    sigma = float(mesh.sigma.points[0, 1])  # Σ is the plane y = sigma (a box's, or a file's)
    cut = [slabs.slabs(half, sigma, count) for half in mesh.halves]
    if any(pieces is None for pieces in cut):
        return None
    (lower, lower_cuts), (upper, upper_cuts) = cut
    ordered = [slab for pair in zip(lower, upper) for slab in pair]
    surface = interface_of(scene, mesh)
    joints = [Joint(surface, (0, 1), (trace_dofs(lower[0].piece), trace_dofs(upper[0].piece)))]
    points = [mesh.sigma.points]
    modulus = modulus_of(scene, mesh)
    values = []
    for slab in ordered:  # each block's prescribed values, NaN where free
        dofs, given = tetra.prescribed(scene, slab.piece)
        values.append(np.full(slab.piece.dofs, np.nan))
        values[-1][dofs] = given
    for half, cuts in enumerate((lower_cuts, upper_cuts)):
        for j, between in enumerate(cuts):
            near, far = 2 * j + half, 2 * (j + 1) + half  # the lower half's far slab lies below its near one
            pair = (far, near) if half == 0 else (near, far)
            nodes = between.nodes[::-1] if half == 0 else between.nodes
            dofs = tuple(node_dofs(own) for own in nodes)
            _tie(values, pair, dofs)
            fixed = np.array([~np.isnan(values[block][own]) for own, block in zip(dofs, pair)])
            glued = Interface(between.weights, np.zeros(len(between.points), dtype=bool), False, fixed,
                              modulus, specs=block_list(1), components=COMPONENTS, points=between.points)
            joints.append(Joint(glued, pair, dofs))
            points.append(between.points)
    supports = [(np.flatnonzero(~np.isnan(v)), v[~np.isnan(v)]) for v in values]
    names = [f"{spec.name}{f'_{j}' if j else ''}" for j in range(count) for spec in block_list(1)]
    specs = tuple(BlockSpec(name, "layer1", -1 if block % 2 == 0 else 1) for block, name in enumerate(names))
    interface = surface if count == 1 else Interface.joined([joint.interface for joint in joints],
                                                          [joint.blocks for joint in joints], specs)
    return Decomposition(ordered, supports, specs, joints, np.vstack(points), interface)


def _tie(values: list[np.ndarray], pair: tuple[int, int], dofs: tuple[np.ndarray, np.ndarray]) -> None:
    """A cut vertex's component that one of the ``pair`` of blocks prescribes is prescribed in both (its value at
    the same point), as the plane Σ ties its supports: a multiplier row then never loads a prescribed dof."""
    first, second = (values[block][own] for block, own in zip(pair, dofs))
    values[pair[0]][dofs[0]] = np.where(np.isnan(first), second, first)
    values[pair[1]][dofs[1]] = np.where(np.isnan(second), first, second)


def pieces_of(scene: Scene, mesh: SolidMesh, ranks: int) -> Decomposition:
    """The decomposition ``solver.pieces`` asks for (``auto``: the slabs of the candidate the cost model predicts
    fastest on ``ranks``, :func:`ranking`, the next where they do not fit); a SceneError where the slabs asked for
    do not fit."""
    wanted = scene.solver.pieces
    if wanted != "auto":
        parts = decomposition(scene, mesh, wanted)
        if parts is None:
            raise SceneError(f"solver.pieces = {wanted}: this mesh's halves do not hold {wanted} slabs each (a "
                             "slab must be at least one element thick, whole, and touch only its neighbours): "
                             "give fewer, or a finer mesh.size")
        return parts
    whole = decomposition(scene, mesh, 1)
    if whole.regions > 2:  # several interfaces: a block a region
        return whole
    ranked = ranking(scene, box_of(scene, whole), ranks, list(solid_costs.PIECES), not thin_blocks(whole))
    for count in dict.fromkeys(candidate.pieces for candidate in ranked):
        parts = whole if count == 1 else decomposition(scene, mesh, count)
        if parts is not None:
            return parts
    return whole


def prepare(scene: Scene, comm: MPI.Comm, progress=None, mesh: SolidMesh | None = None) -> SolidSetup:
    """Build the mesh on rank 0 (rank 0's ``mesh`` if given), broadcast it, cut it into blocks, assemble and factor
    every rank's blocks (collective: the refusals too); rank 0's ``progress`` lines after the mesh and after the
    factorization."""
    started = time.perf_counter()
    mesh = comm.bcast(collective(comm, lambda: tetra.check_range(scene, mesh or solid_meshes.build(scene)),
                                 root_only=True), root=0)
    meshed = time.perf_counter()
    if progress is not None and comm.rank == 0:
        progress(solid_lines.mesh_line(mesh, meshed - started))
    parts = collective(comm, lambda: pieces_of(scene, mesh, comm.size))
    if not supported(comm.size, len(parts.slabs), uneven=True):
        error = DDSolveError(f"unsupported number of ranks {comm.size}: use {usable(len(parts.slabs), uneven=True)} "
                             f"(the {len(parts.slabs)} blocks of the 3-D box: " + (
                                 f"{parts.count} slabs per half)" if parts.regions == 2 else "one per region)"))
        error.collective = True  # every rank sees the same size
        raise error
    held = collective(comm, lambda: kernels_of(parts))  # floating slabs and regions: solved as floating halves
    scene = collective(comm, lambda: method_of(scene, parts, held, comm.size))
    method = registry.METHODS[scene.solver.method]
    exchange = Exchange(comm, len(parts.slabs), uneven=True)
    positions, dofs = trace_layout(parts.joints, len(parts.slabs))
    stages = {name: PETSc.Log.Stage(name) for name in driver.STAGES}
    timings = {"meshing": meshed - started, "setup": time.perf_counter() - meshed}

    lumped = method.name == "feti" and scene.solver.preconditioner == "lumped"
    entries = []  # this rank's blocks' K_ΣΣ entries, for the lumped preconditioner

    def make() -> list[Block]:
        made = []
        timings["assembly"] = 0.0
        for index, group in zip(exchange.local_blocks, exchange.groups):
            piece = parts.slabs[index].piece
            rows = None if group.size == 1 else row_ranges(len(piece.points), group.size)[group.rank]
            assembled = time.perf_counter()
            system = block_system(scene, piece, parts.specs[index].name, dofs[index], parts.supports[index], rows)
            if lumped:
                entries.append((index, trace_entries(system, positions[index])))
            block = Block(system, comm=PETSc.Comm(group), factor_package=method.factorization)
            made.append(block)
            timings["assembly"] += time.perf_counter() - assembled
            if index in held.floating:
                block.make_floating(*floating_kernel(piece, parts.supports[index][0], dofs[index], held, index, rows,
                                                     fixed=method.floating == registry.GENERALIZED_INVERSE))
            block.factor(schur=method.schur_complements, out_of_core=scene.solver.out_of_core)
            if (method.dirichlet and not lumped) or (block.floating and method.floating == registry.INTERIOR):
                block.factor_dirichlet(out_of_core=scene.solver.out_of_core)  # feti's K⁺ alone: Block.expand
        return made

    blocks = collective(comm, make)
    timings["factorization"] = time.perf_counter() - meshed - timings["setup"] - timings["assembly"]
    if progress is not None and comm.rank == 0:
        progress(solid_lines.factored_line(f"rank 0's blocks ({describe(scene, parts)})", timings))
    local = {index: positions[index] for index in exchange.local_blocks} if len(parts.joints) > 1 else None
    stiffness = trace_stiffness(comm.gather(entries, root=0), len(parts.slabs), parts.interface.trace_size) \
        if lumped else None
    return SolidSetup(scene, mesh, parts, exchange, blocks, local, held, stages, timings, stiffness)


def describe(scene: Scene, parts: Decomposition) -> str:
    """The method, and the slabs and feti's preconditioner where the halves are cut, for the progress lines."""
    if parts.count == 1:
        return scene.solver.method
    lumped = f", {scene.solver.preconditioner} preconditioner" if scene.solver.method == "feti" else ""
    return f"{scene.solver.method}, {parts.count} slabs per half{lumped}"

def trace_stiffness(gathered: list | None, count: int, size: int) -> list[scipy.sparse.csr_matrix] | None:
    """Rank 0: each of the ``count`` blocks' K_ΣΣ on the structure's trace (``size``) from every rank's ``gathered``
    entries (:func:`ddsolve.fem.assembly.trace_entries`; a distributed block's rows from each of its ranks)."""
    if gathered is None:
        return None
    parts: list[list] = [[] for _ in range(count)]
    for rank_entries in gathered:
        for index, triplets in rank_entries:
            parts[index].append(triplets)
    return [scipy.sparse.csr_matrix((np.concatenate([v for _, _, v in block]),
                                     (np.concatenate([r for r, _, _ in block]), np.concatenate([c for _, c, _ in block]))),
                                    shape=(size, size)) for block in parts]


def floating_kernel(piece: SolidHalf, prescribed: np.ndarray, trace: np.ndarray, held: kernels.Kernels, index: int,
                    rows: tuple[int, int] | None, fixed: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """A floating block's kernel ``(m, rows)`` at its ``rows`` here (all where None) and, with ``fixed``, the m dofs
    fixed for FETI's K⁺: off its ``trace`` and its ``prescribed`` dofs, where the kernel is independent (the same on
    every rank)."""
    vectors = (held.frame.modes(piece.points).T @ held.kernels[index]).T
    chosen = None
    if fixed:
        excluded = np.union1d(prescribed, trace)
        chosen = kernels.fixing_dofs(vectors, excluded).astype(np.int64)
    first, last = rows if rows is not None else (0, piece.dofs)
    return vectors[:, first:last], chosen


def solve(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, mesh: SolidMesh | None = None
          ) -> SolidResult | None:
    """The domain decomposition of the 3-D box ``scene`` on ``comm`` (on rank 0's ``mesh`` if given, else the
    scene's); ``output`` and its VTU files written (:func:`ddsolve.io.solid.write`).  The result on rank 0 (None
    elsewhere); a method that does not converge writes its result with converged = false and raises
    NotConvergedError on every rank, with the result."""
    started = time.perf_counter()
    setup = prepare(scene, comm, progress, mesh)
    try:
        def made(outcome, rounds, fields: list[np.ndarray]) -> SolidResult:
            result = finished(setup, outcome, rounds, fields)
            solid.with_fracture(result, progress)
            return result

        return driver.gathered_solve(setup, BlockServer(setup.blocks, setup.exchange, positions=setup.positions),
                                     [slab.piece.dofs for slab in setup.parts.slabs], made, solid_files.write, output,
                                     started, progress)
    finally:
        setup.destroy()


def halves_of(mesh: SolidMesh, parts: Decomposition, fields: list[np.ndarray]) -> tuple[np.ndarray, ...]:
    """The halves' (regions') displacements ``(n, 3)`` from the blocks' ``fields`` (a cut's vertices: the nearer
    slab's, glued to the other's within the method's tolerance)."""
    halves = [np.zeros((len(half.points), COMPONENTS)) for half in mesh.regions]
    for block in reversed(range(len(parts.slabs))):
        halves[parts.half_of(block)][parts.slabs[block].nodes] = fields[block].reshape(-1, COMPONENTS)
    return tuple(halves)


def finished(setup: SolidSetup, outcome, rounds, fields: list[np.ndarray]) -> SolidResult:
    """Rank 0: the method's ``outcome`` as the reference's record: the halves' displacements, the contact
    pressure μᶜ at the crack vertices, the potential energy of the final round, the method's iterations as its
    ``steps`` (schur's are its active-set steps), the blocks' largest relative residual and the final KKT check's
    residuals as its ``checks``, the setup's timings with the seconds inside the rounds of block solves
    (``rounds``)."""
    interface, sigmas = setup.interface, setup.mesh.sigmas
    pressure = np.zeros(len(setup.parts.points))  # the trace's vertices: every Σ's first, bottom to top
    contact = interface.slices["mu_c"]
    pressure[interface.vertex[contact]] = outcome.lam[contact]
    pressures = np.split(pressure[:sum(len(sigma.points) for sigma in sigmas)],
                         np.cumsum([len(sigma.points) for sigma in sigmas])[:-1])
    return SolidResult(setup.scene, setup.mesh, halves_of(setup.mesh, setup.parts, fields), tuple(pressures),
                       energy=float(outcome.details["energy"]), steps=outcome.iterations, solves=rounds.count,
                       converged=bool(outcome.converged), message=outcome.message or "",
                       checks={"residual": float(np.max(rounds.residuals, initial=0.0)),
                               **{name: float(outcome.details[f"kkt_{name}"]) for name in Constraints.NAMES}},
                       timings={**setup.timings, "rounds": rounds.elapsed}, attrs=solver_record(setup.scene, outcome))


def solver_record(scene: Scene, outcome) -> dict:
    """What ran, for the result file: the method and slabs per half, feti's preconditioner, coarse degree and the
    coarse directions kept."""
    solver = scene.solver
    record = {"method": solver.method, "pieces": solver.pieces}
    if solver.method == "feti":
        record.update(preconditioner=solver.preconditioner, coarse_degree=solver.coarse_degree,
                      coarse_directions=int(outcome.details.get("coarse_directions", 0)))
    return record
