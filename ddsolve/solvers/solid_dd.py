"""The domain decomposition of a 3-D box (``geometry.box = [x0, x1, y0, y1, z0, z1]``): its two halves as the
blocks u⁻ (below Σ) and u⁺ (above), on 1, 2 or 2k ranks.

The plane driver's machinery (:mod:`ddsolve.solvers.stacked_dd`) with three trace entries per Σ vertex: a block's
trace is its displacements at every Σ vertex in Σ's frame (x, ν = y, z; :class:`~ddsolve.dd.interface.Interface`
with ``components = 3``), μᶜ acts on the normal (y) at the crack vertices, μᵍ on all three components off them.
The mesh is built once on rank 0 and broadcast; each rank assembles its blocks (or its rows of one,
:func:`block_system`); rank 0 runs the multiplier method and finishes the same
:class:`~ddsolve.post.solid.SolidResult` as the monolithic reference (:mod:`ddsolve.solvers.solid`), written to the
same files.  A half held only through Σ floats: its kernel is the rigid motions (of six) its own supports leave
(:mod:`ddsolve.dd.kernels`), factored and solved as the plane driver does; a box that can move rigidly as a whole is
refused in one line.
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
from ddsolve.dd.constraints import Constraints
from ddsolve.dd.interface import Interface
from ddsolve.environment import physical_memory
from ddsolve.errors import DDSolveError, SceneError
from ddsolve.fem import tetra
from ddsolve.fem.assembly import BlockSystem
from ddsolve.io import solid as solid_files
from ddsolve.mesh import solid as solid_meshes
from ddsolve.mesh.mesh import blocks as block_list
from ddsolve.mesh.solid import SolidHalf, SolidMesh
from ddsolve.parallel.blocks import Block
from ddsolve.parallel.exchange import Exchange, collective
from ddsolve.parallel.launch import supported, usable
from ddsolve.parallel.rounds import BlockServer
from ddsolve.post.solid import SolidResult
from ddsolve.problem.scene import Scene
from ddsolve.solvers import driver, solid, solid_lines

#: The trace entries of a Σ vertex: x, y (Σ's normal, component 1 as in the plane) and z.
COMPONENTS = 3
#: The dense matrices of Σ's size (3 s)² that ``schur`` holds at once on one machine: each half's Schur complement
#: in MUMPS, in its block and gathered on rank 0, rank 0's interface stiffness and its factor (1 + 2 × 3 + 1).
SCHUR_COPIES = 8
#: The share of this machine's memory ``schur``'s dense matrices may take (above it: refused, ``auto`` takes feti).
SCHUR_MEMORY_SHARE = 0.5


@dataclass
class SolidSetup:
    """What every rank holds after assembly and factorization: the whole mesh, this rank's factored blocks and
    the interface (rank 0 runs the method on it)."""

    scene: Scene  # with the method resolved
    mesh: SolidMesh
    exchange: Exchange
    blocks: list[Block]
    interface: Interface
    kernels: kernels.Kernels
    stages: dict
    timings: dict[str, float]

    def kernel_traces(self) -> list[np.ndarray]:
        """The traces ``(3 s, m_b)`` of the halves' kernels on Σ."""
        modes = self.kernels.frame.modes(self.mesh.sigma.points).T
        return [modes @ kernel for kernel in self.kernels.kernels]

    def destroy(self) -> None:
        for block in self.blocks:
            block.destroy()
        self.exchange.free()


def kernels_of(scene: Scene, mesh: SolidMesh, interface: Interface) -> kernels.Kernels:
    """The halves' kernels: the rigid motions their own supports leave (:func:`ddsolve.dd.kernels.held_kernels`);
    a SceneError naming the motion when the box can move rigidly as a whole."""
    frame = kernels.frame_of(np.vstack([half.points for half in mesh.halves]))
    rows = [kernels.constraint_rows(frame.modes(half.points), tetra.prescribed(scene, half)[0])
            for half in mesh.halves]
    return kernels.held_kernels(rows, frame.modes(mesh.sigma.points).T, interface, frame)


def method_of(scene: Scene, mesh: SolidMesh, held: kernels.Kernels) -> Scene:
    """The scene with ``auto`` resolved (``schur`` while its dense matrices fit, :func:`schur_bytes`, else
    ``feti``); in one line, what this solve does not take: ``schur`` above that limit, a floating half (kernels
    ``held``) with a method that cannot solve it (friction and bonds the scene refuses)."""
    method = registry.METHODS.get(scene.solver.method)
    if held.floating and method is not None and not method.floating:
        raise SceneError(f"solver.method = {method.name}: the {held.names()} half of the 3-D box is floating (held "
                         f"only through Σ, its stiffness singular), which {method.name} cannot solve: use "
                         f"{' or '.join(registry.floating_methods())}")
    dense, limit = schur_bytes(mesh), SCHUR_MEMORY_SHARE * physical_memory()
    if scene.solver.method == "schur" and dense > limit:
        raise SceneError(f"solver.method = schur: the dense Σ Schur complements of this 3-D box ({COMPONENTS} × "
                         f"{len(mesh.sigma.points)} trace entries) need about {dense / 1e9:.3g} GB, above the "
                         f"{limit / 1e9:.3g} GB allowed ({SCHUR_MEMORY_SHARE:g} of this machine's memory): use "
                         "solver.method = feti")
    method = scene.solver.method if scene.solver.method in registry.METHODS else "schur" if dense <= limit else "feti"
    return dataclasses.replace(scene, solver=dataclasses.replace(scene.solver, method=method))


def schur_bytes(mesh: SolidMesh) -> float:
    """Bytes of the dense matrices ``schur`` holds at once (:data:`SCHUR_COPIES` of Σ's size)."""
    return SCHUR_COPIES * 8.0 * (COMPONENTS * len(mesh.sigma.points)) ** 2


def trace_dofs(half: SolidHalf) -> np.ndarray:
    """The half's dofs at every Σ vertex, in Σ order: x, y, z per vertex."""
    return tetra.element_dofs(half.sigma_nodes[:, None]).ravel()


def block_system(scene: Scene, half: SolidHalf, name: str, rows: tuple[int, int] | None = None) -> BlockSystem:
    """The half's system with its prescribed dofs decoupled and its trace on Σ (its ``rows`` only, where given;
    the energy offset counted on the rows that start at 0)."""
    system = tetra.half_system(scene, half)
    whole = dataclasses.replace(system.decoupled(name), trace_dofs=trace_dofs(half),
                                energy_offset=prescribed_energy(system))
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


def interface_of(scene: Scene, mesh: SolidMesh) -> Interface:
    """Σ's multipliers: μᶜ on the crack vertices' normal under non-penetration, μᵍ (three components) off the
    cracks; none between two prescribed entries."""
    fixed = np.zeros((len(mesh.halves), COMPONENTS * len(mesh.sigma.points)), dtype=bool)
    for row, half in zip(fixed, mesh.halves):
        row[:] = np.isin(trace_dofs(half), tetra.prescribed(scene, half)[0])
    modulus = max(tetra.largest_modulus(scene.material("layer1", half.name)) for half in mesh.halves)
    return Interface(mesh.sigma.weights, mesh.sigma.cracked, scene.nonpenetration, fixed, modulus,
                     specs=block_list(1), components=COMPONENTS)


def prepare(scene: Scene, comm: MPI.Comm, progress=None, mesh: SolidMesh | None = None) -> SolidSetup:
    """Build the mesh on rank 0 (rank 0's ``mesh`` if given), broadcast it, assemble and factor every rank's blocks
    (collective: the refusals too); rank 0's ``progress`` lines after the mesh and after the factorization."""
    started = time.perf_counter()
    specs = block_list(1)
    if not supported(comm.size, len(specs)):
        error = DDSolveError(f"unsupported number of ranks {comm.size}: use {usable(len(specs))} (the two halves "
                             "of a 3-D box)")
        error.collective = True  # every rank sees the same size
        raise error
    mesh = comm.bcast(collective(comm, lambda: mesh or solid_meshes.build(scene), root_only=True), root=0)
    meshed = time.perf_counter()
    if progress is not None and comm.rank == 0:
        progress(solid_lines.mesh_line(mesh, meshed - started))
    interface = interface_of(scene, mesh)
    held = collective(comm, lambda: kernels_of(scene, mesh, interface))
    scene = collective(comm, lambda: method_of(scene, mesh, held))
    method = registry.METHODS[scene.solver.method]
    exchange = Exchange(comm, len(specs))
    stages = {name: PETSc.Log.Stage(name) for name in driver.STAGES}
    timings = {"meshing": meshed - started, "setup": time.perf_counter() - meshed}

    def make() -> list[Block]:
        made = []
        timings["assembly"] = 0.0
        for index, group in zip(exchange.local_blocks, exchange.groups):
            half = mesh.halves[index]
            rows = None if group.size == 1 else row_ranges(len(half.points), group.size)[group.rank]
            assembled = time.perf_counter()
            block = Block(block_system(scene, half, specs[index].name, rows), comm=PETSc.Comm(group),
                          factor_package=method.factorization)
            made.append(block)
            timings["assembly"] += time.perf_counter() - assembled
            if index in held.floating:
                block.make_floating(*floating_kernel(scene, half, held, index, rows,
                                                     fixed=method.floating == registry.GENERALIZED_INVERSE))
            block.factor(schur=method.schur_complements, out_of_core=scene.solver.out_of_core)
            if method.dirichlet or block.floating:
                block.factor_dirichlet(out_of_core=scene.solver.out_of_core)
        return made

    blocks = collective(comm, make)
    timings["factorization"] = time.perf_counter() - meshed - timings["setup"] - timings["assembly"]
    if progress is not None and comm.rank == 0:
        progress(solid_lines.factored_line(f"rank 0's blocks ({scene.solver.method})", timings))
    return SolidSetup(scene, mesh, exchange, blocks, interface, held, stages, timings)


def floating_kernel(scene: Scene, half: SolidHalf, held: kernels.Kernels, index: int, rows: tuple[int, int] | None,
                    fixed: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """A floating half's kernel ``(m, rows)`` at its ``rows`` here (all where None) and, with ``fixed``, the m dofs
    fixed for FETI's K⁺: off Σ and the prescribed dofs, where the kernel is independent (the same on every rank)."""
    vectors = (held.frame.modes(half.points).T @ held.kernels[index]).T
    chosen = None
    if fixed:
        excluded = np.union1d(tetra.prescribed(scene, half)[0], trace_dofs(half))
        chosen = kernels.fixing_dofs(vectors, excluded).astype(np.int64)
    first, last = rows if rows is not None else (0, half.dofs)
    return vectors[:, first:last], chosen


def solve(scene: Scene, comm: MPI.Comm, output: Path | None, progress=print, mesh: SolidMesh | None = None
          ) -> SolidResult | None:
    """The domain decomposition of the 3-D box ``scene`` on ``comm`` (on rank 0's ``mesh`` if given, else the scene's);
    ``output`` and its VTU files written (:func:`ddsolve.io.solid.write`).  The result on rank 0 (None elsewhere); a method that does not converge
    writes its result with converged = false and raises NotConvergedError on every rank, with the result."""
    started = time.perf_counter()
    setup = prepare(scene, comm, progress, mesh)
    try:
        def made(outcome, rounds, fields: list[np.ndarray]) -> SolidResult:
            result = finished(setup, outcome, rounds, fields)
            solid.with_fracture(result, progress)
            return result

        return driver.gathered_solve(setup, BlockServer(setup.blocks, setup.exchange),
                                     [half.dofs for half in setup.mesh.halves], made, solid_files.write, output,
                                     started, progress)
    finally:
        setup.destroy()


def finished(setup: SolidSetup, outcome, rounds, fields: list[np.ndarray]) -> SolidResult:
    """Rank 0: the method's ``outcome`` as the reference's record: the halves' displacements, the contact
    pressure μᶜ at the crack vertices, the potential energy of the final round, the method's iterations as its
    ``steps`` (schur's are its active-set steps), the blocks' largest relative residual and the final KKT check's
    residuals as its ``checks``."""
    interface = setup.interface
    pressure = np.zeros(len(setup.mesh.sigma.points))
    contact = interface.slices["mu_c"]
    pressure[interface.vertex[contact]] = outcome.lam[contact]
    return SolidResult(setup.scene, setup.mesh, tuple(u.reshape(-1, COMPONENTS) for u in fields), pressure,
                       energy=float(outcome.details["energy"]), steps=outcome.iterations, solves=rounds.count,
                       converged=bool(outcome.converged), message=outcome.message or "",
                       checks={"residual": float(np.max(rounds.residuals, initial=0.0)),
                               **{name: float(outcome.details[f"kkt_{name}"]) for name in Constraints.NAMES}},
                       timings=dict(setup.timings))
