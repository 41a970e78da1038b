"""Safe writes: a file or a set of files replaced whole or not at all, never an input, with the
temporaries of killed runs cleaned up; HDF5 files built in memory and written in one piece."""
from __future__ import annotations

import contextlib
import glob
import json
import os
import re
import secrets
import signal
import socket
import tempfile
import threading
from pathlib import Path
from typing import Callable, Iterable, Mapping

from ddsolve.environment import process_exists
from ddsolve.errors import DDSolveError

#: Temporary, backup and journal files of a write: ``.NAME.ddsolve~HOST~PID~RANDOM.tmp[.suffix]`` (the
#: suffix keeps writers that look at it happy), ``.NAME.ddsolve~HOST~PID~RANDOM.bak`` and, during the
#: renames of a set, ``.NAME.ddsolve~HOST~PID~RANDOM.journal`` (NAME: the set's first file).
_SCRATCH = re.compile(r"^\.(?P<name>.+)\.ddsolve~(?P<host>[^~]*)~(?P<pid>\d+)~[0-9a-f]+\.(?P<kind>tmp|bak|journal)")


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


def host_tag() -> str:
    return re.sub(r"[^A-Za-z0-9_-]", "_", socket.gethostname()) or "host"


def _scratch(path: Path, tag: str, kind: str) -> Path:
    return path.parent / (f".{path.name}.{tag}.{kind}" + (path.suffix if kind == "tmp" else ""))


def _writer_gone(match: re.Match) -> bool:
    """Whether the process that wrote a scratch file (on this machine) no longer exists."""
    if match["host"] != host_tag():
        return False
    pid = int(match["pid"])
    return pid != os.getpid() and not process_exists(pid)


def _entries(folder: Path, pattern: str) -> list[Path]:
    """The entries of ``folder`` that match ``pattern``; none if the folder cannot be listed or reached
    (no read or search permission: then the files in it cannot be replaced either)."""
    try:
        return list(folder.glob(pattern))
    except OSError:
        return []


def recover(paths: list[Path]) -> None:
    """Finish the sets that a run killed while renaming them left behind in the folders of ``paths``
    (their journals name every file, so the new set is put in place whole), then remove the temporary
    and backup files of killed runs for ``paths``.  A folder that cannot be listed holds nothing to finish."""
    for folder in dict.fromkeys(Path(path).parent for path in paths):
        for journal in _entries(folder, ".*.ddsolve~*.journal"):
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
        for gone in entries.get("removals", []):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(gone)
        for backup in entries["backups"]:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(backup)
        journal.unlink()
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DDSolveError(f"{journal}: cannot finish the result files an interrupted run was renaming "
                           f"({os_reason(exc) if isinstance(exc, OSError) else 'damaged journal'}); "
                           "remove the journal and check the files it names") from None


def remove_stale(path: Path) -> list[Path]:
    """Remove the temporary and backup files that runs killed while writing ``path`` left behind
    (those of a process on this machine that no longer exists); returns them."""
    removed = []
    for candidate in _entries(Path(path).parent, f".{glob.escape(Path(path).name)}.ddsolve~*"):
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


def same_file(path: Path, source: Path) -> bool:
    """Whether ``path`` and ``source`` are one existing file (False where either cannot be examined)."""
    try:
        return path.exists() and Path(source).exists() and os.path.samefile(path, source)
    except OSError:
        return False


#: The longest process id Linux gives (``/proc/sys/kernel/pid_max`` at most 2²²): scratch names are sized for it.
LONGEST_PID = 4194304


def check_name_length(path: Path) -> None:
    """Refuse an output name that the folder's file system cannot hold, with the scratch files written
    beside it (``.NAME.ddsolve~HOST~PID~RANDOM.journal.tmp``, the longest), in one line naming it."""
    try:
        limit = os.pathconf(path.parent, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    tag = f"ddsolve~{host_tag()}~{LONGEST_PID}~{'f' * 8}"
    longest = max(len(os.fsencode(_scratch(path, tag, "journal").name)) + len(".tmp"),
                  len(os.fsencode(_scratch(path, tag, "tmp").name)))
    extra = longest - len(os.fsencode(path.name))
    if longest > limit:
        name = path.name if len(path.name) <= 60 else f"{path.name[:40]}…{path.name[-12:]}"
        raise DDSolveError(f"{path.parent / name}: file name too long ({len(os.fsencode(path.name))} bytes; its "
                           f"file system holds {limit} and ddsolve's temporary files beside it add {extra}, so at "
                           f"most {limit - extra}): choose a shorter name")


def check_targets(paths: list[Path], inputs: Iterable[Path] | Mapping[Path, str] = (), named: str = "-o") -> None:
    """Refuse a set of output files that could not be written as a whole: an empty name, a name given
    twice, a name too long for its folder, an existing file that is not a regular file (a directory, a
    device, a FIFO), one of the ``inputs`` (paths, or paths with how the run reads each), or a folder that
    does not exist, cannot be reached or where no file can be created; ``named``: how the messages name the
    output's argument."""
    reads = inputs if isinstance(inputs, Mapping) else dict.fromkeys(inputs, "")
    seen: dict[str, Path] = {}
    for path in map(Path, paths):
        if not path.name or str(path).endswith(os.sep):
            raise DDSolveError(f"{named} {str(path)!r}: not a file name")
        key = os.path.abspath(path)
        if key in seen:
            raise DDSolveError(f"{path}: written twice in one set of result files")
        seen[key] = path
        check_name_length(path)
        try:
            _check_target(path, reads, named)
        except OSError as exc:  # a folder on the way without search permission, a path too long...
            raise DDSolveError(f"{path}: cannot write ({os_reason(exc).lower()})") from None
    for folder, path in {Path(path).parent: Path(path) for path in reversed(paths)}.items():
        try:
            exists = folder.is_dir()
        except OSError as exc:
            raise DDSolveError(f"{path}: cannot write in {folder} ({os_reason(exc).lower()})") from None
        if not exists:
            raise DDSolveError(f"{path}: output directory {folder} does not exist")
        try:
            handle, probe = tempfile.mkstemp(prefix=".ddsolve-probe.", dir=folder)
            os.close(handle)
            os.unlink(probe)
        except OSError as exc:
            raise DDSolveError(f"{path}: cannot write in {folder} ({exc.strerror or exc})") from None


def _check_target(path: Path, reads: Mapping[Path, str], named: str) -> None:
    """Refuse an existing ``path`` that is not a regular file, or one of the files the run ``reads`` (each
    with how it is read)."""
    if path.is_symlink():
        return  # the link itself is replaced, never its target
    if path.exists() and not path.is_file():
        kind = "a directory" if path.is_dir() else "not a regular file"
        raise DDSolveError(f"{path}: is {kind}; ddsolve replaces regular files only: choose another {named}")
    for source, how in reads.items():
        if same_file(path, source):
            raise DDSolveError(f"{path}: is an input of this run ({source}{', ' * bool(how)}{how}); "
                               f"choose another {named}")


@contextlib.contextmanager
def commit_section():
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
                for signum in received:  # consume them here (if no other thread took them since); raised below
                    signal.sigtimedwait({signum}, 0)
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    for signum in dict.fromkeys(received):
        signal.raise_signal(signum)


def replace_together(writers: dict[Path, Callable[[str], None]], final: bool = False, comm=None,
                     remove: list[Path] = ()) -> None:
    """Write a set of files so that they replace the previous ones together or not at all (and remove
    the files ``remove`` names, those of the previous set that the new one no longer has, with them).

    Each ``write(temporary)`` writes its file under a temporary name in the target's folder; only
    when every one has succeeded does the commit begin, with interrupts deferred (:func:`commit_section`):
    a journal naming every rename is written (the commit point), the previous versions are kept as
    hard links (or renamed away), every temporary file is renamed over its target, then the journal
    and the backups are removed.  A failed rename puts the previous set back.  On any failure or
    interrupt before the commit point the temporary files are removed and the previous files are left
    as they were.  A run killed (SIGKILL) after the commit point leaves its journal: the next write or
    read of these files (:func:`recover`) completes the renames, so the set seen is always one whole
    set.  ``final``: this set ends the command (a later interrupt ends it with status 0,
    :data:`committed`).  With ``comm`` (an MPI communicator, more than one rank) every rank calls every
    writer with the same temporary name (writers that write one file together); rank 0 checks,
    creates the temporaries and commits; an error on any rank is raised on every rank and no rank
    returns before the commit is decided.
    """
    global committed
    paths = [Path(path) for path in writers]
    gone = [Path(path) for path in remove if Path(path) not in paths]
    root = comm is None or comm.rank == 0
    tag = _on_all(comm, lambda: _begin(paths + gone), root_only=True)
    temporaries = {path: _scratch(path, tag, "tmp") for path in paths}
    journal = _scratch(paths[0], tag, "journal")
    draft = journal.with_name(journal.name + ".tmp")  # the journal while it is written
    _LIVE.update(temporaries.values())
    try:
        # the first file (the result file, which names the journal) last: its timings can count the others
        for path, write in reversed(list(zip(paths, writers.values()))):
            _on_all(comm, lambda: _create(path, temporaries[path]), root_only=True)
            _on_all(comm, lambda: _write(path, write, temporaries[path]))
        _on_all(comm, lambda: _commit(paths, temporaries, tag, final, gone), root_only=True)
        committed = final
    finally:
        if root:
            for scratch in (*temporaries.values(), draft, journal):
                if os.path.lexists(scratch):
                    os.unlink(scratch)
        _LIVE.difference_update(temporaries.values())


def _on_all(comm, work: Callable[[], object], root_only: bool = False):
    """``work()`` on every rank of ``comm`` (or rank 0 only; its value to all), its first DDSolveError
    raised on every rank; without ``comm`` just ``work()``."""
    if comm is None or comm.size == 1:
        return work()
    value, error = None, None
    if not root_only or comm.rank == 0:
        try:
            value = work()
        except DDSolveError as exc:
            error = exc
    first = next((e for e in comm.allgather(error) if e is not None), None)
    if first is not None:
        first.collective = True
        raise first
    return comm.bcast(value, root=0) if root_only else value


def _begin(paths: list[Path]) -> str:
    """Check the targets, finish or clean up what killed runs left; the tag of this write."""
    check_targets(paths)
    recover(paths)
    return f"ddsolve~{host_tag()}~{os.getpid()}~{secrets.token_hex(4)}"


def _create(path: Path, temporary: Path) -> None:
    try:
        temporary.open("xb").close()
    except OSError as exc:
        raise DDSolveError(f"{path}: cannot write in {path.parent} ({exc.strerror or exc})") from None


def _write(path: Path, write: Callable[[str], None], temporary: Path) -> None:
    try:
        write(str(temporary))
        if os.path.exists(temporary):
            os.chmod(temporary, 0o644)
    except OSError as exc:
        raise DDSolveError(f"{path}: cannot write ({os_reason(exc)})") from None


def _commit(paths: list[Path], temporaries: dict[Path, Path], tag: str, final: bool, gone: list[Path] = ()) -> None:
    """The commit of a written set (see :func:`replace_together`): ``paths`` replaced, ``gone`` removed."""
    global committed
    journal = _scratch(paths[0], tag, "journal")
    draft = journal.with_name(journal.name + ".tmp")
    gone = [path for path in gone if os.path.lexists(path)]
    backups = {path: _scratch(path, tag, "bak") for path in [*paths, *gone] if os.path.lexists(path)}
    entries = json.dumps({"renames": [[str(temporaries[path].absolute()), str(path.absolute())] for path in paths],
                          "backups": [str(backup.absolute()) for backup in backups.values()],
                          "removals": [str(path.absolute()) for path in gone]})
    moved: set[Path] = set()  # previous versions renamed away (no hard links here)
    done: list[Path] = []
    try:
        with commit_section():
            draft.write_text(entries)
            os.replace(draft, journal)  # the commit point
            for path, backup in backups.items():
                if _keep(path, backup):
                    moved.add(path)
            for path in paths:
                os.replace(temporaries[path], path)
                done.append(path)
            for path in gone:
                if path not in moved:
                    os.unlink(path)
                done.append(path)
            journal.unlink()
            committed = final
    except OSError as exc:
        for path in [*paths, *gone]:  # undo: the previous set comes back
            if path in done and path not in backups:
                os.unlink(path)
            elif path in done or path in moved:
                os.replace(backups[path], path)
        failed = next((path for path in [*paths, *gone] if path not in done), paths[0])
        raise DDSolveError(f"{failed}: cannot replace ({exc.strerror or exc}); the previous files are kept") \
            from None
    finally:
        for backup in backups.values():
            if os.path.lexists(backup):
                os.unlink(backup)


def _keep(path: Path, backup: Path) -> bool:
    """Keep the current ``path`` as ``backup``: a hard link, else (file systems without them) a
    rename; returns whether it was renamed away."""
    try:
        os.link(path, backup, follow_symlinks=False)
        return False
    except OSError:
        os.replace(path, backup)
        return True


def os_reason(exc: OSError) -> str:
    """The one-line reason of a failed write."""
    return exc.strerror or " ".join(str(exc).split())


@contextlib.contextmanager
def hdf5_image(name: str):
    """An HDF5 file built in memory and written to ``name`` in one piece when the block ends: the
    HDF5 library never writes to the disk itself (a full disk would leave it broken), and a failed
    write is a plain OSError."""
    import h5py  # here: the command line's checks import this module without HDF5

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
