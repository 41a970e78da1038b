"""The Python API: load a scene, change it, solve it on any communicator, read and write results.

    import ddsolve

    scene = ddsolve.Scene.load("partial-closure").with_({"solver.tol": 1e-10})
    result = ddsolve.solve(scene)            # every rank of the communicator takes part
    print(result.energy, result.G)
    result.save("ex1.h5")
    again = ddsolve.load("ex1.h5")

The command line is a layer over these functions; errors are :class:`ddsolve.DDSolveError` with the
same one-line messages.  Under ``mpiexec -n 4 python -m mpi4py script.py`` an error on one rank
ends every rank (mpi4py's runner aborts the job on an uncaught exception).
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable, Sequence

from ddsolve.errors import DDSolveError, NotConvergedError, SceneError
from ddsolve.io import hdf5
from ddsolve.post.result import Result
from ddsolve.problem.scene import Scene

def _scene(scene: Scene | str | Path) -> Scene:
    if not isinstance(scene, (Scene, str, Path)):
        raise SceneError(f"scene: a Scene, a built-in scene's name or a scene file's path (got "
                         f"{type(scene).__name__})")
    return scene if isinstance(scene, Scene) else Scene.load(scene)


def _comm(comm):
    """The communicator to run on (MPI.COMM_WORLD by default), with PETSc initialized: as the command line
    does, without PETSc's signal handler, unless the script started PETSc itself."""
    import petsc4py

    if "petsc4py.PETSc" not in sys.modules:
        petsc4py.init([sys.argv[0] if sys.argv and sys.argv[0] else "ddsolve", "-no_signal_handler"])
    from mpi4py import MPI

    if comm is not None and not isinstance(comm, MPI.Comm):
        raise DDSolveError(f"comm: an mpi4py communicator (got {type(comm).__name__})")
    return MPI.COMM_WORLD if comm is None else comm


def _output(output: str | Path | None) -> Path | None:
    """The result file to write (checked as ``-o`` is: an ``.h5`` name whose set can be written), or None."""
    if output is None:
        return None
    hdf5.check_result(Path(output), named="output")
    return Path(output)


def _silent(*_args, **_kwargs) -> None:
    """No progress lines (the default of the API; the command line prints them)."""


def solve(scene: Scene | str | Path, comm=None, output: str | Path | None = None,
          progress: Callable[[str], None] | None = None) -> Result:
    """Solve ``scene`` by domain decomposition on every rank of ``comm`` (default: MPI.COMM_WORLD; a
    plain ``python`` process is one rank).  With ``mesh.target_error`` the mesh is refined adaptively.

    Returns the same :class:`Result` on every rank; ``output`` (an ``.h5`` path) also writes the result
    set (the HDF5 file and its viewer files) from rank 0.  ``progress`` receives progress lines on
    rank 0.  Raises :class:`ddsolve.NotConvergedError` (with the result as ``.result``) when the solve
    did not converge, and other :class:`ddsolve.DDSolveError` for what cannot be solved.
    """
    from ddsolve.solvers import run

    comm = _comm(comm)
    try:
        result = run.solve(_scene(scene), comm, _output(output), progress or _silent)
    except NotConvergedError as error:  # raised on every rank; the result (written) is rank 0's
        error.result = comm.bcast(getattr(error, "result", None), root=0)
        raise
    return comm.bcast(result, root=0)


def reference(scene: Scene | str | Path, output: str | Path | None = None) -> Result:
    """The monolithic reference: the same discrete problem as one system, solved exactly on this process."""
    from ddsolve.solvers import run

    _comm(None)
    return run.reference(_scene(scene), _output(output))


def load(path: str | Path) -> Result:
    """Read a result file written by :func:`solve`, :func:`reference`, :meth:`Result.save` or the CLI."""
    if not isinstance(path, (str, Path)):
        raise DDSolveError(f"load: a result file's path (got {type(path).__name__})")
    return hdf5.read(Path(path))


def sweep(scene: Scene | str | Path, parameters: dict[str, Sequence], paired: bool = False,
          output: str | Path | None = None, comm=None, progress: Callable[[str], None] | None = None) -> list[dict]:
    """Solve ``scene`` for every combination of ``parameters`` (dotted key -> values; ``paired``: the
    value lists side by side), reusing the mesh and the factorizations where they do not change.

    Returns one record per run (``parameters``, ``energy``, ``converged``, ``G`` per tip, ...) on every
    rank; ``output`` also writes them to one HDF5 file (the layout of ``ddsolve sweep``).
    """
    from ddsolve.solvers import sweep as sweeps

    comm = _comm(comm)
    records = sweeps.sweep(_scene(scene), [], paired, Path(output) if output is not None else None, comm,
                           progress or _silent, values=parameters)
    return comm.bcast(records, root=0)


def grow(scene: Scene | str | Path, limit: float, steps: int = 20, tolerance: float = 1e-4,
         output: str | Path | None = None, comm=None, progress: Callable[[str], None] | None = None) -> list:
    """Grow the cracks of ``scene`` along Σ (Griffith, the scene's ``[fracture]`` toughness) as a factor on
    its loads or prescribed displacements rises to ``limit`` in ``steps`` steps (docs/growth.md).

    Returns the steps (:class:`ddsolve.solvers.grow.Step`: ``state`` with control, load, displacement,
    cracks, G per tip; ``unstable``; ``events``) on every rank; ``output`` writes them to one HDF5 file
    (the layout of ``ddsolve grow``).
    """
    from ddsolve.solvers import grow as growth

    comm = _comm(comm)
    done = growth.grow(_scene(scene), comm, limit, steps, tolerance, progress=progress or _silent,
                         output=Path(output) if output is not None else None)
    return comm.bcast(done, root=0)
