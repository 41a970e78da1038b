"""Result files: HDF5 (the layout of docs/usage.md) and the viewer files derived from it, written as
one set that replaces the previous one together or not at all."""
from __future__ import annotations

import contextlib
import functools
import glob
import json
import os
import re
import secrets
import signal
import socket
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Callable

import h5py
import numpy as np

from . import analysis, export, scene as scenes
from .errors import DDSolveError, SceneError
from .interface import BLOCKS
from .mesh import HalfMesh, Mesh, SigmaLine
from .result import Result

MULTIPLIERS = ("mu_c", "mu_g", "mu_minus", "mu_plus")
#: A dataset of a result file holds at most this many times the file's size (ddsolve does not
#: compress them): a larger claim is a damaged header, not read.
READ_LIMIT = 16
SIGMA_FIELDS = ("points", "normals", "weights", "crack", "tip", "clamped", "corner")


#: Temporary, backup and journal files of a write: ``.NAME.ddsolve~HOST~PID~RANDOM.tmp[.suffix]`` (the
#: suffix keeps writers that look at it happy), ``.NAME.ddsolve~HOST~PID~RANDOM.bak`` and, during the
#: renames of a set, ``.NAME.ddsolve~HOST~PID~RANDOM.journal`` (NAME: the set's first file).
_SCRATCH = re.compile(r"^\.(?P<name>.+)\.ddsolve~(?P<host>[^~]*)~(?P<pid>\d+)~[0-9a-f]+\.(?P<kind>tmp|bak|journal)")
#: Suffixes of a result file (and of a sweep file).
RESULT_SUFFIXES = (".h5", ".hdf5")


#: Temporary and backup files being written now (removed by :func:`remove_scratch` on a forced exit).
_LIVE: set[Path] = set()
#: Held while a set of files is renamed into place: whoever ends the process on an interrupt (the
#: watchdog of ddsolve.cli) takes it first, so that a set is never left half renamed.
COMMIT = threading.Lock()
#: True once the set of files that ends the command (``final``) is in place: an interrupt after that
#: point changes nothing, and the command ends with status 0.
committed = False


def remove_scratch() -> None:
    """Remove the temporary files of writes in progress (the previous files are untouched)."""
    for path in list(_LIVE):
        with contextlib.suppress(OSError):
            path.unlink()


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname()) or "host"


def _scratch(path: Path, tag: str, kind: str) -> Path:
    return path.parent / (f".{path.name}.{tag}.{kind}" + (path.suffix if kind == "tmp" else ""))


def _writer_gone(match: re.Match) -> bool:
    """Whether the process that wrote a scratch file (on this machine) no longer exists."""
    if match["host"] != _host():
        return False
    pid = int(match["pid"])
    try:
        if pid != os.getpid():
            os.kill(pid, 0)
        return False  # its writer is alive
    except ProcessLookupError:
        return True
    except (PermissionError, OverflowError):
        return False


def recover(paths: list[Path]) -> None:
    """Finish the sets that a run killed while renaming them left behind in the folders of ``paths``
    (their journals name every file, so the new set is put in place whole), then remove the temporary
    and backup files of killed runs for ``paths``."""
    for folder in dict.fromkeys(Path(path).parent for path in paths):
        for journal in folder.glob(".*.ddsolve~*.journal"):
            match = _SCRATCH.match(journal.name)
            if match and _writer_gone(match):
                _roll_forward(journal)
    for path in paths:
        remove_stale(path)


def _roll_forward(journal: Path) -> None:
    """Rename every temporary file a journal lists over its target, remove its backups, then the journal."""
    try:
        entries = json.loads(journal.read_text())
        for temporary, target in entries["renames"]:
            if os.path.lexists(temporary):
                os.replace(temporary, target)
        for backup in entries["backups"]:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(backup)
        journal.unlink()
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DDSolveError(f"{journal}: cannot finish the result files an interrupted run was renaming "
                           f"({_reason(exc) if isinstance(exc, OSError) else 'damaged journal'}); "
                           "remove the journal and check the files it names") from None


def remove_stale(path: Path) -> list[Path]:
    """Remove the temporary and backup files that runs killed while writing ``path`` left behind
    (those of a process on this machine that no longer exists); returns them."""
    removed = []
    for candidate in Path(path).parent.glob(f".{glob.escape(Path(path).name)}.ddsolve~*"):
        match = _SCRATCH.match(candidate.name)
        if not match or match["name"] != Path(path).name or candidate.name.endswith(".journal") \
                or not _writer_gone(match):
            continue
        try:
            candidate.unlink()
            removed.append(candidate)
        except OSError:
            pass
    return removed


def check_result(path: Path, inputs: list[Path] = (), viewer: bool = True) -> None:
    """Refuse a result (or sweep) file ``path`` that is not an HDF5 name, or whose set (with its viewer
    files unless not ``viewer``) cannot be written or would replace one of the ``inputs``."""
    path = Path(path)
    if not path.name:
        raise DDSolveError(f"-o {str(path)!r}: not a file name")
    if path.suffix.lower() not in RESULT_SUFFIXES:
        raise DDSolveError(f"-o {path}: a result is an HDF5 file: give it the suffix .h5"
                           + (" (its viewer files are written beside it)" if viewer else "")
                           + ("; this name is an input of this run" if any(_same(path, s) for s in inputs) else ""))
    check_targets([path, *(export.viewer_paths(path.parent, path.stem) if viewer else [])], inputs)


def _same(path: Path, source: Path) -> bool:
    return path.exists() and Path(source).exists() and os.path.samefile(path, source)


def check_targets(paths: list[Path], inputs: list[Path] = ()) -> None:
    """Refuse a set of output files that could not be written as a whole: an empty name, a name given
    twice, an existing file that is not a regular file (a directory, a device, a FIFO), one of the
    ``inputs``, or a folder that does not exist or where no file can be created."""
    seen: dict[str, Path] = {}
    for path in map(Path, paths):
        if not path.name or str(path).endswith(os.sep):
            raise DDSolveError(f"-o {str(path)!r}: not a file name")
        key = os.path.abspath(path)
        if key in seen:
            raise DDSolveError(f"{path}: written twice in one set of result files")
        seen[key] = path
        if path.is_symlink():
            continue  # the link itself is replaced, never its target
        if path.exists() and not path.is_file():
            kind = "a directory" if path.is_dir() else "not a regular file"
            raise DDSolveError(f"{path}: is {kind}; ddsolve replaces regular files only: choose another -o")
        for source in inputs:
            if _same(path, source):
                raise DDSolveError(f"{path}: is an input of this run ({source}); choose another -o")
    for folder, path in {Path(path).parent: Path(path) for path in reversed(paths)}.items():
        if not folder.is_dir():
            raise DDSolveError(f"{path}: output directory {folder} does not exist")
        try:
            handle, probe = tempfile.mkstemp(prefix=".ddsolve-probe.", dir=folder)
            os.close(handle)
            os.unlink(probe)
        except OSError as exc:
            raise DDSolveError(f"{path}: cannot write in {folder} ({exc.strerror or exc})") from None


@contextlib.contextmanager
def _commit_section():
    """The renames of a set: SIGINT and SIGTERM are deferred (blocked on this thread, and their Python
    handlers, which run on the main thread whichever thread the signal reaches, only note them) and
    :data:`COMMIT` is held, so the watchdog does not end the process in the middle either.  The noted
    signals are raised again afterwards."""
    received: list[int] = []
    previous = {}
    deferred = {signal.SIGINT, signal.SIGTERM}
    with COMMIT:
        main = threading.current_thread() is threading.main_thread()
        if main:
            blocked = signal.pthread_sigmask(signal.SIG_BLOCK, deferred)
            for signum in deferred:
                previous[signum] = signal.signal(signum, lambda number, _frame: received.append(number))
        try:
            yield
        finally:
            if main:
                received += [signum for signum in signal.sigpending() & deferred if signum not in blocked]
                for signum, handler in previous.items():
                    signal.signal(signum, handler)
                for signum in received:  # consume them here; they are raised again below
                    if signum in signal.sigpending():
                        signal.sigwait({signum})
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    for signum in dict.fromkeys(received):
        signal.raise_signal(signum)


def replace_together(writers: dict[Path, Callable[[str], None]], final: bool = False) -> None:
    """Write a set of files so that they replace the previous ones together or not at all.

    Each ``write(temporary)`` writes its file under a temporary name in the target's folder; only
    when every one has succeeded does the commit begin, with interrupts deferred (:func:`_commit_section`):
    a journal naming every rename is written (the commit point), the previous versions are kept as
    hard links (or renamed away), every temporary file is renamed over its target, then the journal
    and the backups are removed.  A failed rename puts the previous set back.  On any failure or
    interrupt before the commit point the temporary files are removed and the previous files are left
    as they were.  A run killed (SIGKILL) after the commit point leaves its journal: the next write or
    read of these files (:func:`recover`) completes the renames, so the set seen is always one whole
    set.  ``final``: this set ends the command (a later interrupt ends it with status 0,
    :data:`committed`).
    """
    global committed
    paths = [Path(path) for path in writers]
    check_targets(paths)
    recover(paths)
    tag = f"ddsolve~{_host()}~{os.getpid()}~{secrets.token_hex(4)}"
    temporaries: dict[Path, Path] = {}
    backups: dict[Path, Path] = {}
    journal = _scratch(paths[0], tag, "journal")
    draft = journal.with_name(journal.name + ".tmp")  # the journal while it is written
    try:
        for path, write in zip(paths, writers.values()):
            temporaries[path] = _scratch(path, tag, "tmp")
            _LIVE.add(temporaries[path])
            try:
                temporaries[path].open("xb").close()
            except OSError as exc:
                raise DDSolveError(f"{path}: cannot write in {path.parent} ({exc.strerror or exc})") from None
            try:
                write(str(temporaries[path]))
                os.chmod(temporaries[path], 0o644)
            except OSError as exc:
                raise DDSolveError(f"{path}: cannot write ({_reason(exc)})") from None
        backups = {path: _scratch(path, tag, "bak") for path in paths if os.path.lexists(path)}
        entries = json.dumps({"renames": [[str(temporaries[path].absolute()), str(path.absolute())] for path in paths],
                              "backups": [str(backup.absolute()) for backup in backups.values()]})
        moved: set[Path] = set()  # previous versions renamed away (no hard links here)
        done: list[Path] = []
        try:
            with _commit_section():
                draft.write_text(entries)
                os.replace(draft, journal)  # the commit point
                for path, backup in backups.items():
                    if _keep(path, backup):
                        moved.add(path)
                for path in paths:
                    os.replace(temporaries[path], path)
                    done.append(path)
                journal.unlink()
                committed = final
        except OSError as exc:
            for path in paths:  # undo: the previous set comes back
                if path in done and path not in backups:
                    os.unlink(path)
                elif path in done or path in moved:
                    os.replace(backups[path], path)
            failed = next((path for path in paths if path not in done), paths[0])
            raise DDSolveError(f"{failed}: cannot replace ({exc.strerror or exc}); the previous files are kept") \
                from None
    finally:
        for scratch in (*temporaries.values(), *backups.values(), draft, journal):
            if os.path.lexists(scratch):
                os.unlink(scratch)
        _LIVE.difference_update(temporaries.values())


def _keep(path: Path, backup: Path) -> bool:
    """Keep the current ``path`` as ``backup``: a hard link, else (file systems without them) a
    rename; returns whether it was renamed away."""
    try:
        os.link(path, backup, follow_symlinks=False)
        return False
    except OSError:
        os.replace(path, backup)
        return True


def _reason(exc: OSError) -> str:
    """The one-line reason of a failed write."""
    return exc.strerror or " ".join(str(exc).split())


@contextlib.contextmanager
def hdf5_image(name: str):
    """An HDF5 file built in memory and written to ``name`` in one piece when the block ends: the
    HDF5 library never writes to the disk itself (a full disk would leave it broken), and a failed
    write is a plain OSError."""
    f = h5py.File(f"{name}.image", "w", driver="core", backing_store=False)
    try:
        yield f
        f.flush()
        image = f.id.get_file_image()
    finally:
        f.close()
    with open(name, "wb") as out:
        out.write(image)


def atomic(path: Path, write: Callable[[str], None], final: bool = False) -> None:
    """Call ``write(temporary_path)`` then rename over ``path``: never a truncated file (``final``: as
    for :func:`replace_together`)."""
    replace_together({Path(path): write}, final)


@functools.lru_cache(maxsize=None)
def provenance() -> dict[str, str]:
    """What produced a file: ddsolve version and git commit, PETSc, MPI, Python, PETSc options.

    Computed once per process (it asks git); do not modify the returned dict.
    """
    import platform

    from petsc4py import PETSc
    from mpi4py import MPI

    from . import __version__

    checkout = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "-C", str(checkout), "rev-parse", "HEAD"], capture_output=True,
                                text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(checkout), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit, dirty = "", ""
    options = PETSc.Options().getAll()
    return {
        "version": __version__,
        "git_commit": (commit + ("-modified" if dirty else "")) or "unknown",
        "petsc": ".".join(map(str, PETSc.Sys.getVersion())),
        "mpi": MPI.Get_library_version().replace("\x00", "").splitlines()[0].strip(),
        "python": platform.python_version(),
        "petsc_options": " ".join(f"-{k} {v}".strip() for k, v in sorted(options.items())),
    }


def write(path: Path, result: Result, viewer: str = "vtu", final: bool = False) -> list[Path]:
    """Write ``path`` (HDF5) and its viewer files (format ``viewer``, see :mod:`ddsolve.export`) beside
    it, as one set (``final``: as for :func:`replace_together`); returns the paths written."""
    path = Path(path)
    fields = analysis.cell_fields(result)
    writers = {path: lambda name: _write_hdf5(name, result, fields),
               **export.viewer_files(result, path.parent, path.stem, viewer, fields)}
    replace_together(writers, final)
    return list(writers)


def write_viewer(result: Result, folder: Path, stem: str, viewer: str = "vtu", final: bool = False) -> list[Path]:
    """(Re)write the viewer files of ``result`` as ``folder/stem-*``; returns the paths written."""
    writers = export.viewer_files(result, Path(folder), stem, viewer)
    replace_together(writers, final)
    return list(writers)


def _write_hdf5(name: str, result: Result, fields: dict[str, analysis.CellFields]) -> None:
    started = time.perf_counter()
    with hdf5_image(name) as f:
        for key in ("converged", "iterations", "solves", "method", "wall_time", "ranks", "scene", "message"):
            f.attrs[key] = getattr(result, key)
        for key, value in result.attrs.items():
            f.attrs[key] = value
        timings = f.create_group("timings")
        for key, value in result.timings.items():
            timings.attrs[key] = value
        if result.memory:
            memory = f.create_group("memory")
            for key, value in result.memory.items():
                memory.attrs[key] = value
        for half in (result.lower, result.upper):
            group = f.create_group(f"mesh/{half.name}")
            group["points"] = half.points
            group["cells"] = half.cells
            group["sigma"] = half.sigma
            group["interface"] = half.sigma[result.multiplier_nodes]
            for boundary, edges in half.boundaries.items():
                group[f"boundaries/{boundary}"] = edges
        sigma = result.mesh.sigma
        for key in SIGMA_FIELDS:
            f[f"sigma/{key}"] = getattr(sigma, key)
        for name, values in result.solution.items():
            f[f"solution/{name}"] = values
        f["interface/x"] = result.interface_x
        f["interface/points"] = result.interface_points
        f["interface/normal"] = result.normals
        f["interface/crack"] = result.crack
        for name in MULTIPLIERS:
            f[f"interface/{name}"] = result.multipliers[name]
        f["history/criterion"] = np.asarray(result.history, dtype=np.float64)
        f["history/active_set_changes"] = np.asarray(result.active_set_changes, dtype=np.int64)
        for name, per_block in result.cell_data.items():
            for block, values in per_block.items():
                f[f"cell_data/{name}/{block}"] = values
        for name, values in result.indicators.items():
            f[f"error/indicator/{name}"] = values
        for name, values in result.levels.items():
            f[f"levels/{name}"] = values
        _write_fracture(f, result)
        for spec in BLOCKS:
            f[f"paraview/{spec.name}/displacement"] = export.padded(result.solution[spec.name])
            f[f"paraview/{spec.name}/von_mises"] = fields[spec.name].von_mises
        timings.attrs["write"] = time.perf_counter() - started


def read(path: Path) -> Result:
    """Read a result file written by :func:`write`, checking that its parts fit together (one line
    naming the file and the part otherwise)."""
    path = Path(path)
    recover([path])
    scenes.readable(path, "result file")
    try:
        with h5py.File(path, "r") as f:
            result = _read(f, path)
    except (OSError, KeyError, TypeError, ValueError, IndexError, AttributeError, RuntimeError, MemoryError) as exc:
        raise DDSolveError(f"{path}: not a ddsolve result file ({' '.join(str(exc).split())})") from None
    except DDSolveError as exc:
        raise DDSolveError(f"{path}: not a ddsolve result file ({exc})") from None
    return result


def _array(f: h5py.File, name: str, kind: str, shape: tuple) -> np.ndarray:
    """Dataset ``name`` as an array of ``kind`` (numpy kinds: "f" numbers, "i" integers, "b" flags)
    and ``shape`` (None: any length), checked before it is read (a damaged header may claim any size)."""
    dataset = _dataset(f, name)
    if dataset.dtype.kind not in {"f": "fiu", "i": "iu", "b": "biu"}[kind]:
        raise DDSolveError(f"{name} holds {dataset.dtype}, not {({'f': 'numbers', 'i': 'integers', 'b': 'flags'})[kind]}")
    got = dataset.shape or ()
    if len(got) != len(shape) or any(want is not None and size != want for size, want in zip(got, shape)):
        expected = tuple("n" if want is None else want for want in shape)
        raise DDSolveError(f"{name} has shape {got}, expected {expected}".replace("'", ""))
    values = dataset[()]
    if kind == "f" and not np.all(np.isfinite(values)) and name.startswith(("mesh/", "sigma/")):
        raise DDSolveError(f"{name} holds values that are not finite")
    return values.astype(bool) if kind == "b" else values


def _dataset(f: h5py.File, name: str) -> h5py.Dataset:
    """Dataset ``name``, if its size is one the file can hold."""
    dataset = f[name]
    if not isinstance(dataset, h5py.Dataset):
        raise DDSolveError(f"{name} is not a dataset")
    if dataset.size * dataset.dtype.itemsize > READ_LIMIT * os.path.getsize(f.filename) + 2 ** 20:
        raise DDSolveError(f"{name} claims {dataset.shape} values, more than the file can hold")
    return dataset


def _indices(values: np.ndarray, count: int, name: str) -> np.ndarray:
    if values.size and (values.min() < 0 or values.max() >= count):
        raise DDSolveError(f"{name} refers to node {int(values.max() if values.max() >= count else values.min())} "
                           f"of {count}")
    return values.astype(np.int64)


def _read(f: h5py.File, path: Path) -> Result:
    sigma_count = len(_array(f, "sigma/points", "f", (None, 2)))
    sigma = SigmaLine(**{key: _array(f, f"sigma/{key}", "f" if key in ("points", "normals", "weights") else "b",
                                     (sigma_count, 2) if key in ("points", "normals") else (sigma_count,))
                         for key in SIGMA_FIELDS})
    halves = []
    for side, name in ((-1, "lower"), (1, "upper")):
        group = f"mesh/{name}"
        points = _array(f, f"{group}/points", "f", (None, 2))
        cells = _indices(_array(f, f"{group}/cells", "i", (None, None)), len(points), f"{group}/cells")
        if cells.shape[1] not in (3, 6):
            raise DDSolveError(f"{group}/cells has {cells.shape[1]} nodes per cell, expected 3 or 6")
        on_sigma = _indices(_array(f, f"{group}/sigma", "i", (sigma_count,)), len(points), f"{group}/sigma")
        boundaries = {key: _indices(_array(f, f"{group}/boundaries/{key}", "i", (None, None)), len(points),
                                    f"{group}/boundaries/{key}") for key in f[group].get("boundaries", {})}
        halves.append(HalfMesh(points, cells, side, on_sigma, boundaries))
    mesh = Mesh(*halves, sigma, str(path))
    k = len(sigma.multiplier_nodes)
    solution = {spec.name: _array(f, f"solution/{spec.name}", "f", (len(mesh.half(spec.side).points), 2))
                for spec in BLOCKS}
    multipliers = {name: _array(f, f"interface/{name}", "f", (k,) if name == "mu_c" else (k, 2)) for name in MULTIPLIERS}
    for name, kind, shape in (("x", "f", (k,)), ("points", "f", (k, 2)), ("normal", "f", (k, 2)), ("crack", "b", (k,))):
        _array(f, f"interface/{name}", kind, shape)  # derived from the above: only their form is checked
    cell_data = {}
    for name, group in f.get("cell_data", {}).items():
        cell_data[name] = {}
        for block in group:
            half = mesh.half(-1 if block.endswith("minus") else 1)
            values = _dataset(f, f"cell_data/{name}/{block}")[()]
            if block not in {spec.name for spec in BLOCKS} or np.ndim(values) == 0 or len(values) != len(half.cells):
                raise DDSolveError(f"cell_data/{name}/{block} does not match the cells of its half")
            cell_data[name][block] = values
    scene_text = f.attrs["scene"]
    scene_text = scene_text.decode() if isinstance(scene_text, bytes) else str(scene_text)
    try:
        scenes.loads(scene_text, origin="its scene")
    except SceneError as exc:
        raise DDSolveError(str(exc)) from None
    known = {"converged", "iterations", "solves", "method", "wall_time", "ranks", "scene", "message"}
    return Result(
        scene=scene_text, method=str(f.attrs["method"]),
        converged=bool(f.attrs["converged"]), iterations=int(f.attrs["iterations"]),
        solves=int(f.attrs["solves"]), wall_time=float(f.attrs["wall_time"]),
        ranks=int(f.attrs["ranks"]), mesh=mesh, solution=solution, multipliers=multipliers,
        history=_array(f, "history/criterion", "f", (None,)),
        active_set_changes=_array(f, "history/active_set_changes", "i", (None,))
        if "history/active_set_changes" in f else np.zeros(0, dtype=np.int64),
        cell_data=cell_data,
        timings={k: float(v) for k, v in f["timings"].attrs.items()} if "timings" in f else {},
        memory=dict(f["memory"].attrs.items()) if "memory" in f else {},
        message=str(f.attrs.get("message", "")),
        attrs={k: v for k, v in f.attrs.items() if k not in known},
        fracture=_read_fracture(f),
        indicators={spec.name: _array(f, f"error/indicator/{spec.name}", "f", (len(mesh.half(spec.side).cells),))
                    for spec in BLOCKS if spec.name in f.get("error/indicator", {})},
        levels={name: _array(f, f"levels/{name}", "f", (None,)) for name in f.get("levels", {})},
    )


# --- /fracture: G at the crack tips, crack faces and contact zones ------------------------------
#: Per-tip datasets of /fracture (the fields of ddsolve.fracture.Fracture), then the contact zones.
FRACTURE_FIELDS = ("points", "directions", "crack", "inner", "outer", "spacing", "G", "contact", "zones",
                   "zone_crack")


def _write_fracture(f, result: Result) -> None:
    """/fracture/{G, points, ...} (tips), /fracture/{zones, zone_crack} (contact zones as arc length along
    Σ) and, over the multiplier nodes, /fracture/arclength, opening ([u]·ν) and pressure (μᶜ)."""
    from .analysis import normal_jump

    if result.fracture is None:
        return
    group = f.create_group("fracture")
    for key in FRACTURE_FIELDS:
        group[key] = getattr(result.fracture, key)
    group["arclength"] = result.mesh.sigma.arclength[result.multiplier_nodes]
    group["opening"] = normal_jump(result)
    group["pressure"] = result.multipliers["mu_c"]


def _read_fracture(f):
    from .fracture import Fracture

    if "fracture" not in f:
        return None
    return Fracture(**{key: _dataset(f, f"fracture/{key}")[()] for key in FRACTURE_FIELDS})
