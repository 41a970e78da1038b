"""The Python API: load a scene, change it, solve it on any communicator, read and write results.

    import ddsolve

    scene = ddsolve.Scene.load("partial-closure").with_({"solver.tol": 1e-10})
    result = ddsolve.solve(scene)            # every rank of the communicator takes part
    print(result.energy, result.G)
    ddsolve.save(result, "ex1.h5")
    again = ddsolve.load("ex1.h5")

The command line is a layer over these functions; errors are :class:`ddsolve.DDSolveError` with the
same one-line messages, arguments of the wrong type included (:class:`ddsolve.ArgumentError`).  The
collective functions (``solve``, ``sweep``, ``grow``) first check on every rank the rank count, the
arguments and that every rank passes the same scene and arguments; an error every rank meets is raised
on every rank.  A ddsolve error a script does not catch ends it with its one line and a non-zero exit,
and under MPI ends every rank (as ``ddsolve solve`` does; any other uncaught exception too).
"""
from __future__ import annotations

import contextlib
import hashlib
import numbers
import sys
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ddsolve.errors import ArgumentError, DDSolveError, NotConvergedError, SceneError
from ddsolve.io import hdf5, inputs
from ddsolve.post.result import Result
from ddsolve.post.stack import StackResult
from ddsolve.problem.scene import Scene

#: Seconds the other ranks of an error every rank met wait for the rank that reports it to end the job.
REPORTER_WAIT = 10.0


def _scene(scene: Scene | str | Path) -> Scene:
    if not isinstance(scene, (Scene, str, Path)):
        raise SceneError(f"scene: a Scene, a built-in scene's name or a scene file's path (got "
                         f"{type(scene).__name__})")
    return scene if isinstance(scene, Scene) else Scene.load(scene)


def _got(value: Any) -> str:
    text = repr(value)
    return f"{type(value).__name__} {text if len(text) <= 40 else text[:37] + '...'}"


def _number(function: str, name: str, value: Any) -> float:
    """``value`` as a float, if it is a real number (not a boolean, not text)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ArgumentError(f"{function}: {name} must be a number (got {_got(value)})")
    return float(value)


def _whole(function: str, name: str, value: Any) -> int:
    """``value`` as an int, if it is a whole number (not a boolean, not a float)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ArgumentError(f"{function}: {name} must be a whole number (got {_got(value)})")
    return int(value)


def _flag(function: str, name: str, value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ArgumentError(f"{function}: {name} must be True or False (got {_got(value)})")
    return bool(value)


def _progress(function: str, progress: Any) -> Callable[[str], None]:
    if progress is not None and not callable(progress):
        raise ArgumentError(f"{function}: progress must be a function taking a line, or None (got {_got(progress)})")
    return progress or _silent


def _path(function: str, name: str, value: Any) -> Path | None:
    if value is not None and not isinstance(value, (str, Path)):
        raise ArgumentError(f"{function}: {name} must be a file's path (got {_got(value)})")
    return None if value is None else Path(value)


def _parameters(parameters: Any) -> dict[str, list]:
    """A sweep's swept keys: dotted key -> the values (a list, tuple or array, not text)."""
    if not isinstance(parameters, Mapping):
        raise ArgumentError(f"sweep: parameters must be a dict of dotted keys and value lists (got {_got(parameters)})")
    checked = {}
    for key, values in parameters.items():
        if not isinstance(key, str):
            raise ArgumentError(f"sweep: parameters: {_got(key)} is not a dotted key (a string such as "
                                "'materials.layer2.E')")
        values = values.tolist() if hasattr(values, "tolist") else values
        if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
            raise ArgumentError(f"sweep: parameters[{key!r}] must be a list of values (got {_got(values)})")
        checked[key] = list(values)
    return checked


def _comm(comm, function: str | None = None):
    """The communicator to run on (MPI.COMM_WORLD by default), with PETSc initialized: as the command line
    does, without PETSc's signal handler, unless the script started PETSc itself.  With ``function`` (a
    collective one) its rank count is checked."""
    import petsc4py

    if "petsc4py.PETSc" not in sys.modules:
        petsc4py.init([sys.argv[0] if sys.argv and sys.argv[0] else "ddsolve", "-no_signal_handler"])
    from mpi4py import MPI

    from ddsolve.parallel.launch import supported

    if comm is not None and not isinstance(comm, MPI.Comm):
        raise DDSolveError(f"comm: an mpi4py communicator (got {type(comm).__name__})")
    comm = MPI.COMM_WORLD if comm is None else comm
    if function is not None and not (supported(comm.size) or supported(comm.size, 2)):  # any structure's
        error = DDSolveError(f"{function}: unsupported number of ranks {comm.size} in comm: use 1, 2 or a multiple "
                             "of 4 (mpiexec -n; a one-layer structure: 1 or a multiple of 2)")
        raise _everywhere(error, comm)
    return comm


def _everywhere(error: DDSolveError, comm) -> DDSolveError:
    """``error``, met by every rank of ``comm``: its rank 0 reports it (see :func:`_uncaught`)."""
    error.collective = True
    error.reporter = comm.rank == 0
    return error


@contextlib.contextmanager
def _reported_once(comm):
    """An error every rank of ``comm`` meets (a collective one) is reported by its rank 0 only."""
    try:
        yield
    except DDSolveError as error:
        if error.collective and not hasattr(error, "reporter"):
            _everywhere(error, comm)
        raise


def _digest(value: Any) -> str:
    return hashlib.sha256(repr(value).encode()).hexdigest()


def _agreed(comm, function: str, check: Callable[[], tuple[Scene, dict]]) -> tuple[Scene, dict]:
    """``check()`` (the scene and the other arguments, checked) on every rank of ``comm``: the first error
    of any rank is raised on every rank, and so is a scene or an argument that differs from rank 0's (a
    collective call solves one problem)."""
    value, error = None, None
    try:
        value = check()
    except DDSolveError as exc:
        error = exc
    digests = None if value is None else (_digest((value[0].text, value[0])),  # its text and what it holds
                                          {key: _digest(item) for key, item in value[1].items()
                                           if key != "progress"})  # a function on each rank
    gathered = comm.allgather((error, digests))
    first = next((e for e, _ in gathered if e is not None), None)
    if first is None:
        first = _disagreement(function, [d for _, d in gathered])
    if first is not None:
        raise _everywhere(first, comm)
    return value


def _disagreement(function: str, digests: list) -> DDSolveError | None:
    """An error naming the first rank whose scene or arguments differ from rank 0's, or None."""
    scene, arguments = digests[0]
    for rank, (other_scene, other_arguments) in enumerate(digests[1:], 1):
        if other_scene != scene:
            return DDSolveError(f"{function}: rank {rank} passed a different scene than rank 0: every rank of comm "
                                "must pass the same scene to one collective call")
        differ = next((key for key in arguments if other_arguments.get(key) != arguments[key]), None)
        if differ is not None:
            return DDSolveError(f"{function}: rank {rank} passed a different {differ} than rank 0: every rank of "
                                "comm must pass the same arguments to one collective call")
    return None


def _output(output: Path | None, scene: Scene, source: Any = None, viewer: bool = True) -> Path | None:
    """The result file to write, checked as ``-o`` is: an ``.h5`` name whose set can be written and that
    is none of the files the scene reads (its scene file, mesh file and the files that one reaches)."""
    if output is not None:
        hdf5.check_result(output, inputs.of_scene(scene, source), viewer=viewer, named="output")
    return output


def _silent(*_args, **_kwargs) -> None:
    """No progress lines (the default of the API; the command line prints them)."""


def _read_by(result: Result, scene: Scene, source: Any) -> Result:
    """``result`` with the files its run read noted (:func:`ddsolve.io.save` never writes over them)."""
    if result is not None:
        result.inputs = inputs.of_scene(scene, source)
    return result


def solve(scene: Scene | str | Path, comm=None, output: str | Path | None = None,
          progress: Callable[[str], None] | None = None) -> Result:
    """Solve ``scene`` by domain decomposition on every rank of ``comm`` (default: MPI.COMM_WORLD; a
    plain ``python`` process is one rank).  With ``mesh.target_error`` the mesh is refined adaptively.

    Returns the same :class:`Result` on every rank (a structure of several interfaces: a
    :class:`ddsolve.post.stack.StackResult`, as :func:`reference` gives); ``output`` (an ``.h5`` path) also
    writes the result set (the HDF5 file and its viewer files) from rank 0.  ``progress`` receives progress lines on
    rank 0.  Raises :class:`ddsolve.NotConvergedError` (with the result as ``.result``) when the solve
    did not converge, and other :class:`ddsolve.DDSolveError` for what cannot be solved.
    """
    from ddsolve.solvers import run

    comm = _comm(comm, "solve")

    def check():
        loaded, path = _scene(scene), _path("solve", "output", output)
        return loaded, {"output": _output(path, loaded, scene), "progress": _progress("solve", progress)}

    loaded, arguments = _agreed(comm, "solve", check)
    try:
        with _reported_once(comm):
            result = run.decomposition(loaded, comm, arguments["output"], arguments["progress"])
    except NotConvergedError as error:  # raised on every rank; the result (written) is rank 0's
        error.result = _read_by(comm.bcast(getattr(error, "result", None), root=0), loaded, scene)
        raise
    return _read_by(comm.bcast(result, root=0), loaded, scene)


def reference(scene: Scene | str | Path, output: str | Path | None = None) -> Result | StackResult:
    """The monolithic reference: the same discrete problem as one system, solved exactly on this process (a
    structure of several interfaces gives a :class:`ddsolve.post.stack.StackResult`: each block's
    displacements, the energy, each interface's view as a Result, G at every tip of every interface)."""
    from ddsolve.solvers import run

    _comm(None)
    loaded = _scene(scene)
    path = _output(_path("reference", "output", output), loaded, scene)
    return _read_by(run.reference(loaded, path, progress=_silent), loaded, scene)


def load(path: str | Path) -> Result | StackResult:
    """Read a result file written by :func:`solve`, :func:`reference`, :func:`ddsolve.io.save` or the CLI (of
    several interfaces: a :class:`ddsolve.post.stack.StackResult`)."""
    if not isinstance(path, (str, Path)):
        raise DDSolveError(f"load: a result file's path (got {type(path).__name__})")
    result = hdf5.read(Path(path))
    result.path = Path(path)
    return result


def sweep(scene: Scene | str | Path, parameters: dict[str, Sequence], paired: bool = False,
          output: str | Path | None = None, comm=None, progress: Callable[[str], None] | None = None) -> list[dict]:
    """Solve ``scene`` for every combination of ``parameters`` (dotted key -> values; ``paired``: the
    value lists side by side), reusing the mesh and the factorizations where they do not change.

    Returns one record per run (``parameters``, ``energy``, ``converged``, ``G`` per tip, ...) on every
    rank; ``output`` also writes them to one HDF5 file (the layout of ``ddsolve sweep``), which may be
    none of the files the scenes read.
    """
    from ddsolve.solvers import sweep as sweeps

    comm = _comm(comm, "sweep")

    def check():
        loaded, path = _scene(scene), _path("sweep", "output", output)
        return loaded, {"parameters": _parameters(parameters), "paired": _flag("sweep", "paired", paired),
                        "output": _output(path, loaded, scene, viewer=False), "progress": _progress("sweep", progress)}

    loaded, arguments = _agreed(comm, "sweep", check)
    with _reported_once(comm):
        records = sweeps.sweep(loaded, [], arguments["paired"], arguments["output"], comm, arguments["progress"],
                               values=arguments["parameters"], named="output")
    return comm.bcast(records, root=0)


def grow(scene: Scene | str | Path, limit: float | Sequence[float], steps: int = 20, tolerance: float = 1e-4,
         output: str | Path | None = None, comm=None, progress: Callable[[str], None] | None = None) -> list:
    """Grow the cracks of ``scene`` along Σ (Griffith, the scene's ``[fracture]`` toughness; or the damage of its
    ``[interface]`` bilinear bond, :mod:`ddsolve.solvers.bond_growth`) as a factor on its loads or prescribed
    displacements rises to ``limit`` in ``steps`` steps (docs/growth.md); a bilinear bond also takes a path of
    targets, ``limit=[0.2, 0.05, 0.3]``: it rises, unloads along the secant and reloads.

    Returns the steps (:class:`ddsolve.solvers.grow.Step`: ``state`` with control, load, displacement,
    cracks, G per tip; ``unstable``; ``events``) on every rank; ``output`` writes them as ``ddsolve grow``
    does (the HDF5 file with the CSV and picture of the curve beside it, replaced together), none of which
    may be one of the files the scene reads.
    """
    from ddsolve.solvers import bond_growth
    from ddsolve.solvers import grow as growth

    comm = _comm(comm, "grow")

    def check():
        loaded, path = _scene(scene), _path("grow", "output", output)
        targets = (tuple(_number("grow", "limit", target) for target in limit)
                   if isinstance(limit, (list, tuple)) else _number("grow", "limit", limit))
        return loaded, {"limit": targets, "steps": _whole("grow", "steps", steps),
                        "tolerance": _number("grow", "tolerance", tolerance),
                        "output": _output(path, loaded, scene, viewer=False), "progress": _progress("grow", progress)}

    loaded, arguments = _agreed(comm, "grow", check)
    with _reported_once(comm):
        if bond_growth.damaging(loaded):
            done = bond_growth.grow(loaded, comm, arguments["limit"], arguments["steps"],
                                    progress=arguments["progress"], output=arguments["output"],
                                    inputs=inputs.of_scene(loaded, scene))
        else:
            done = growth.grow(loaded, comm, arguments["limit"], arguments["steps"], arguments["tolerance"],
                               progress=arguments["progress"], output=arguments["output"],
                               inputs=inputs.of_scene(loaded, scene))
    return comm.bcast(done, root=0)


def _uncaught(kind, error, trace) -> None:
    """``sys.excepthook`` while the API is in use: a ddsolve error is its one line (once, when every rank
    met it), anything else the usual traceback; under MPI every rank then ends (MPI_Abort with the
    error's exit status), so that no rank waits for one that has gone."""
    from ddsolve.parallel import runtime

    world = runtime.comm_world()
    reporter = getattr(error, "reporter", world is None or world.rank == 0)
    if isinstance(error, DDSolveError):
        if reporter or not error.collective:
            runtime.report(f"ddsolve: error: {error}", everywhere=True)
    else:
        _previous_hook(kind, error, trace)
    if world is not None and world.size > 1:
        if isinstance(error, DDSolveError) and error.collective and not reporter:
            time.sleep(REPORTER_WAIT)  # the reporting rank ends the job once its line is out
        runtime.abort(getattr(error, "exit_status", 1))


_previous_hook = sys.excepthook
sys.excepthook = _uncaught
