"""A scene solved as the commands solve it: the checks before any work, the solve (adaptive when the
scene sets ``mesh.target_error``), the result set written.  The command line and the Python API both
call these, so a script and ``ddsolve solve`` do the same thing (sweeps: :func:`ddsolve.solvers.sweep.sweep`)."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from ddsolve.errors import NotConvergedError, SceneError
from ddsolve.io import hdf5
from ddsolve.mesh import geometry, stack
from ddsolve.parallel.distribution import build_mesh
from ddsolve.parallel.exchange import collective
from ddsolve.parallel.phases import Phases, launch_age
from ddsolve.parallel.runtime import check_out_of_core
from ddsolve.post.result import Result
from ddsolve.post.solid import SolidResult
from ddsolve.problem.scene import Scene
from ddsolve.solvers import adapt, checks, critical, driver, solid, solid_adapt, solid_dd, stacked, stacked_dd
from ddsolve.solvers import reference as monolithic
from ddsolve.solvers.stacked import StackResult


def _before_work(scene: Scene, ranks: int = 1) -> None:
    """What the machine must offer a solve of ``scene`` on ``ranks`` ranks: the memory of its mesh, and a
    folder for out-of-core factors if the scene or a PETSc option asks for them (see
    :func:`ddsolve.solvers.checks.check_size`)."""
    checks.check_size(scene, ranks, stacks=True, solid=True)
    check_out_of_core(scene.solver.out_of_core)


def decomposition(scene: Scene, comm, output: Path | None, progress: Callable[[str], None] = print,
          gather: bool = True) -> Result | None:
    """The domain decomposition of ``scene`` on every rank of ``comm``, adaptive when the scene asks;
    ``output`` written.  The result on rank 0, None elsewhere; not ``gather``: the ranks write their
    parts of ``output`` and rank 0's result holds only Σ, the scalars and G (see
    :func:`ddsolve.solvers.driver.solve_decomposed`).  A scene with a toughness and a temperature change has its
    critical load factors found first, by solves of the scaled scene on the same mesh and factors
    (:func:`ddsolve.solvers.critical.factors`), so that the file written holds them; the search is the
    launch's phase ``critical_factors``."""
    collective(comm, lambda: _before_work(scene, comm.size), root_only=True)
    if scene.geometry.dimension == 3:
        if scene.mesh.target_error is not None:
            return solid_adapt.solve_adaptively(scene, comm, lambda mesh: solid_dd.solve(scene, comm, None, _silent, mesh),
                                                output, progress)
        return solid_dd.solve(scene, comm, output, progress)
    if scene.geometry.above:
        collective(comm, lambda: refuse_critical_factors(scene))
        return stacked_dd.solve(scene, comm, output, progress)
    if scene.mesh.target_error is not None:
        return adapt.solve_adaptively(scene, comm, output, progress=progress)
    if not critical.needed(scene):
        return driver.solve_decomposed(scene, comm, output, progress=progress, gather=gather)
    phases = Phases(launch_age())
    mesh = build_mesh(scene, comm)  # whole on every rank: the scaled scenes' prescribed values need both halves
    phases.end("meshing")
    setup = driver.prepare(scene, comm, mesh, phases)
    try:
        found = critical.factors(scene, comm, mesh, progress, setup=setup)
        driver.reload(setup, scene)
        setup.phases = phases
        phases.end("critical_factors")
        return driver.solve_decomposed(scene, comm, output, progress=progress, gather=gather, setup=setup, factors=found)
    finally:
        setup.destroy()


def reference(scene: Scene, output: Path | None = None, progress: Callable[[str], None] = print
              ) -> Result | StackResult | SolidResult:
    """The monolithic reference of ``scene`` on this process (adaptive when the scene asks; several interfaces:
    :func:`_stack_reference`; a 3-D box: :func:`ddsolve.solvers.solid.reference`); raises
    NotConvergedError, with the result, when its final check fails.  The critical load factors of a scene
    with a toughness and a temperature change come from reference solves of the scaled scene."""
    if scene.geometry.dimension == 3:
        if scene.mesh.target_error is not None:  # adaptive, every level solved by the reference
            from mpi4py import MPI

            return _converged(solid_adapt.solve_adaptively(scene, MPI.COMM_SELF, lambda mesh: solid.reference_on(
                scene, mesh), output, progress))
        return _converged(solid.reference(scene, output, progress))
    _before_work(scene)
    monolithic.refuse_friction(scene)
    monolithic.refuse_bond(scene)
    if scene.geometry.above:
        return _stack_reference(scene, output)
    if scene.mesh.target_error is not None:  # adaptive, every level solved by the reference
        from mpi4py import MPI

        result = adapt.solve_adaptively(scene, MPI.COMM_SELF, output, progress=progress,
                             level=lambda mesh, solved, _refined_next: monolithic.solve_monolithic(solved, mesh))
    else:
        mesh = geometry.build(scene)
        found = critical.search(scene, lambda lam: monolithic.solve_monolithic(scene.scaled(lam), mesh).fracture, progress) \
            if critical.needed(scene) else None
        result = monolithic.solve_monolithic(scene, mesh, found)
        if output is not None:
            hdf5.write(output, result, final=True)
    return _converged(result)


def _silent(_line: str) -> None:
    pass


def _converged(result):
    """``result``, or NotConvergedError with it when its final check failed."""
    if not result.converged:
        error = NotConvergedError(result.message)
        error.result = result
        raise error
    return result


def refuse_critical_factors(scene: Scene) -> None:
    """The critical load factors of several interfaces are refused in one line."""
    if critical.needed(scene):
        raise SceneError("fracture.toughness: the critical load factors of a structure of several interfaces are not "
                         "found yet (a toughness with a temperature change)")


def _stack_reference(scene: Scene, output: Path | None) -> StackResult:
    """The monolithic reference of several interfaces (:func:`ddsolve.solvers.stacked.solve_stack`), ``output``
    written (:func:`ddsolve.io.hdf5.write_stack`)."""
    refuse_critical_factors(scene)
    result = stacked.solve_stack(scene, stack.build_any(scene))
    if output is not None:
        hdf5.write_stack(output, result)
    return _converged(result)

