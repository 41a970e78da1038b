"""The process runtime of every command and rank: PETSc options and initialization, one-line
errors and exit statuses, interrupts and signals, output in any encoding, and ending every rank
together (abort)."""
from __future__ import annotations

import argparse
import codecs
import contextlib
import difflib
import faulthandler
import os
import signal
import socket
import sys
import threading
import time
import traceback
import unicodedata
from pathlib import Path
from typing import Callable

from ddsolve.environment import check_out_of_core_folder, import_errors_explained
from ddsolve.errors import DDSolveError, DivergedError, NotConvergedError, UsageError
from ddsolve.mesh import gmsh_io
from ddsolve.mesh.mesh import U_PLUS
from ddsolve.parallel.launch import end_with_launcher, interrupt_line, leader, supervised, world_position

class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit status 2) instead of a usage block."""

    def error(self, message: str):
        command = self.prog.removeprefix("ddsolve").strip() if self.prog.startswith("ddsolve ") else ""
        raise UsageError(f"{command + ': ' if command else ''}{message} (see {self.prog} --help)")


def is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _subcommands(top: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    return next(action.choices for action in top._actions if isinstance(action, argparse._SubParsersAction))


def split_arguments(top: argparse.ArgumentParser, argv: list[str], petsc_commands: tuple[str, ...]
                    ) -> tuple[list[str], list[str]]:
    """(ddsolve's arguments, PETSc's options), wherever the user typed them.

    An option of the command (and its value) is ddsolve's; any other single-dash word that is not a
    number starts a PETSc option, whose value is the next word unless that is an option; ``--``
    hands everything after it to PETSc.  A command without PETSc options refuses them.
    """
    command = next((arg for arg in argv if not arg.startswith("-")), None)
    sub = _subcommands(top).get(command)
    if sub is None:
        return list(argv), []
    options = sub._option_string_actions
    own: list[str] = []
    petsc: list[str] = []
    i = 0
    while i < len(argv):
        arg = argv[i]
        if arg == "--":
            petsc += argv[i + 1:]
            break
        name = arg.split("=", 1)[0] if arg.startswith("--") else arg
        glued = len(arg) > 2 and arg[:2] in options and is_number(arg[2:])  # -n4
        if name in options or glued:
            own.append(arg)
            takes_value = not glued and "=" not in arg and options[name].nargs != 0
            if takes_value and i + 1 < len(argv):
                own.append(argv[i + 1])
                i += 1
        elif arg.startswith("-") and not arg.startswith("--") and len(arg) > 1 and not is_number(arg):
            petsc.append(arg)
            if i + 1 < len(argv) and argv[i + 1] != "--" and (not argv[i + 1].startswith("-")
                                                             or is_number(argv[i + 1])):
                petsc.append(argv[i + 1])
                i += 1
        else:
            own.append(arg)
        i += 1
    if petsc and command not in petsc_commands:
        close = difflib.get_close_matches(petsc[0], list(options), n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise UsageError(f"{command}: unknown option {petsc[0]}{hint}; {command} takes no PETSc options")
    return own, petsc


#: PETSc options that name a file PETSc reads as it starts; and options whose value ``[type]:path[:format]``
#: names a file PETSc writes as it ends, after the result is written.
READ_FILE_OPTIONS = ("-options_file", "-options_file_yaml")
WRITE_FILE_OPTIONS = ("-log_view", "-log_trace", "-memory_view")


def check_petsc_files(options: list[str]) -> None:
    """Refuse, in one line naming the option, a file PETSc would fail to read as it starts (its own error is
    many lines) or to write as it ends (after the result set replaced the old one)."""
    from ddsolve.problem.scene import readable

    for name, value in zip(options, options[1:]):
        if value.startswith("-"):
            continue
        try:
            if name in READ_FILE_OPTIONS:
                readable(value, f"file of {name}", UsageError)
            elif name in WRITE_FILE_OPTIONS and ":" in value:
                path = Path(value.split(":")[1])
                if path.name and (path.is_dir() or not path.parent.is_dir() or not os.access(path.parent, os.W_OK)):
                    why = "is a directory" if path.is_dir() else f"no writable folder {path.parent}"
                    raise UsageError(f"{name} {value}: cannot write {path} ({why})")
        except UsageError as error:
            error.collective = True  # every rank has the same options and sees the same files
            raise


#: The MUMPS control (ICNTL) that asks for out-of-core factors (:data:`ddsolve.parallel.blocks.MUMPS_OUT_OF_CORE`).
OUT_OF_CORE_OPTION = "mat_mumps_icntl_22"


def petsc_options_given(options: list[str]) -> dict[str, str]:
    """PETSc's options -> their values (without the dash): PETSc's own database once it has started, else
    the command line's ``options`` and ``PETSC_OPTIONS``."""
    petsc = sys.modules.get("petsc4py.PETSc")
    if petsc is not None and petsc.Sys.isInitialized():
        return {name: str(value) for name, value in petsc.Options().getAll().items()}
    words = [*os.environ.get("PETSC_OPTIONS", "").split(), *options]
    return {word[1:]: (following if not following.startswith("-") or is_number(following) else "")
            for word, following in zip(words, [*words[1:], ""]) if word.startswith("-") and not is_number(word)}


def check_out_of_core(scene_asks: bool, options: list[str] = ()) -> None:
    """Before any work: when the scene (``solver.out_of_core``) or a PETSc option (``-PREFIX_mat_mumps_icntl_22
    N``, N not 0) asks for out-of-core factors, refuse a ``MUMPS_OOC_TMPDIR`` where they cannot be written
    (:func:`~ddsolve.environment.check_out_of_core_folder`)."""
    asking = ["solver.out_of_core = true"] if scene_asks else []
    asking += [f"-{name} {value}" for name, value in petsc_options_given(options).items()
               if name.endswith(OUT_OF_CORE_OPTION) and value.strip() not in ("0", "")]
    if asking:
        check_out_of_core_folder(asking[0])


def init_petsc(options: list[str]) -> None:
    """PETSc without its signal handler: on a crash (SIGSEGV...) it calls MPI_Abort inside the handler,
    which can deadlock the crashed rank and with it the whole job; without it the rank dies of the
    signal (after Open MPI's backtrace) and mpiexec ends the others.  First, on the ranks that mesh
    (rank 0 and the leader of u⁺), the child that will run gmsh starts and imports it meanwhile
    (:func:`~ddsolve.mesh.gmsh_io.warm_up`: forked before MPI starts, it holds no MPI state)."""
    rank, size = world_position()
    if rank in (0, leader(U_PLUS, size)):
        gmsh_io.warm_up()
    import petsc4py

    check_petsc_files(options)
    try:
        petsc4py.init([sys.argv[0], "-no_signal_handler", *options])
        from petsc4py import PETSc  # noqa: F401 -- PETSc starts here
    except Exception as exc:  # PETSc.Error: PetscInitialize refused an option (its message is above)
        error = UsageError(f"PETSc did not start with the options {' '.join(options)} "
                           f"(PETSc error code {getattr(exc, 'ierr', '?')})")
        error.collective = True  # every rank has the same options
        raise error from None
    limit_blas_threads()

    # A closed pipe on standard output is an error to report in one line (EPIPE), not a death by SIGPIPE.
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)


def report_unused_options(comm, prefixes: tuple[str, ...] = ()) -> None:
    """A PETSc ``-options_left``-style warning on rank 0: the options no rank read (misspelt ones), with the
    options prefixes of the command's solvers."""
    from ddsolve.parallel.blocks import made_prefixes, unused_options

    mine = (unused_options(), made_prefixes())
    gathered = comm.gather(mine, root=0) if comm is not None else [mine]
    if gathered is None or any(options is None for options, _ in gathered):
        return
    every = [options for options, _ in gathered]
    common = [option for option in every[0] if all(option in other for other in every[1:])]
    if common:
        prefixes = _solved_prefixes(prefixes, [prefix for _, made in gathered for prefix in made])
        named = f" the prefixes here are {', '.join(prefixes)}" if prefixes else ""
        print(f"ddsolve: warning: PETSc options not used (misspelt?{named}): {', '.join(common)}",
              file=sys.stderr, flush=True)


def _solved_prefixes(known: tuple[str, ...], made: list[str]) -> tuple[str, ...]:
    """The options prefixes of the blocks the ranks ``made`` (in the order of the ``known`` ones, then the others'),
    or the ``known`` ones of the command when no block was made."""
    if not made:
        return known
    return (*(prefix for prefix in known if prefix in made), *dict.fromkeys(p for p in made if p not in known))


def unused_options_reported(command: Callable[[], int], prefixes: tuple[str, ...] = ()) -> int:
    """Run a command that hands options to PETSc (of ddsolve or of the experiments); once its solves have
    ended on every rank (successfully, or not converged or diverged on every rank), name the PETSc options
    nothing read (:func:`report_unused_options`; after an error that stopped the run before its solves they
    went unread for want of a solve).  A launcher (``-n N``) starts no PETSc: its ranks report."""
    def report() -> None:
        petsc = sys.modules.get("petsc4py.PETSc")
        if petsc is not None and petsc.Sys.isInitialized() and not petsc.Sys.isFinalized():
            report_unused_options(comm_world(), prefixes)

    try:
        status = command()
    except (NotConvergedError, DivergedError) as exc:
        if exc.collective:  # every rank is here: none is waiting in a solve
            report()
        raise
    report()
    return status


#: Variables by which a user sets the BLAS's threads himself (then :func:`limit_blas_threads` keeps them).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "GOTO_NUM_THREADS")
#: Variables by which MPI launchers tell a rank how many ranks share its node (Open MPI, MPICH).
LOCAL_SIZE_VARIABLES = ("OMPI_COMM_WORLD_LOCAL_SIZE", "MPI_LOCALNRANKS")


def blas_threads(cores: int, environment: dict[str, str]) -> int | None:
    """Threads each rank's BLAS should use: the node's cores shared among its ranks (at least one);
    None when the user chose (a ``BLAS_THREAD_VARIABLES`` entry is set).

    OpenBLAS starts as many threads as there are cores in every process, and its threads spin while
    they wait: two ranks on two cores then run four threads, and the CPU time of a factorization
    doubles for the same wall time (measured by ``./run bench baseline``).
    """
    if any(environment.get(name) for name in BLAS_THREAD_VARIABLES):
        return None
    ranks = next((int(environment[name]) for name in LOCAL_SIZE_VARIABLES
                  if environment.get(name, "").isdigit()), 1)
    return max(1, cores // max(ranks, 1))


def limit_blas_threads() -> None:
    """Give OpenBLAS (the BLAS of MUMPS and numpy here) :func:`blas_threads` threads, if it is loaded."""
    threads = blas_threads(len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1,
                           dict(os.environ))
    if threads is None:
        return
    import ctypes

    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line and ".so" in line}
    except OSError:
        return
    for path in sorted(paths):
        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(path).openblas_set_num_threads(threads)


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that temporary files are removed on the way out."""


#: Seconds after which a signal that came during an import is delivered again (:func:`_interrupt`).
IMPORT_RETRY = 0.01


def _swallowing(frame) -> bool:
    """Whether ``frame`` (where a signal handler was called) runs where an exception can be printed and
    lost instead of propagating: inside an import (Python's import machinery and the modules it
    initializes: "Exception ignored in: <module ...>") or a finalizer (``__del__``)."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib") or frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def _interrupt(signum, frame) -> None:
    """SIGINT and SIGTERM as exceptions (KeyboardInterrupt, :class:`Terminated`); never inside an import or
    a finalizer, where one could be printed and lost (:func:`_swallowing`): there the signal is sent again
    IMPORT_RETRY seconds later, until it is over (the watchdog, :func:`watch_interrupts`, ends the process
    if that takes too long)."""
    if _swallowing(frame):
        timer = threading.Timer(IMPORT_RETRY, os.kill, (os.getpid(), signum))
        timer.daemon = True
        timer.start()
        return
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signal.Signals(signum).name)


def interrupts_ignored() -> None:
    """The command's outcome is decided (its status is known): a later SIGINT or SIGTERM changes nothing,
    and is ignored, so that it cannot end the process with another status as Python exits (which gives
    the signals their default action back first)."""
    with contextlib.suppress(ValueError):  # not the main thread: its handlers are not ours
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)


#: Seconds an interrupt may wait for the main thread (busy in a library call: gmsh, a factorization,
#: a blocking MPI call) before the watchdog stops the process itself.
INTERRUPT_GRACE = 3.0


#: Seconds MPI_Abort may take before the process ends itself (Abort waits for mpiexec, which may not answer).
ABORT_GRACE = 2.0


def watch_interrupts() -> None:
    """Make every phase interruptible: Python runs signal handlers only between bytecodes, so a signal
    that arrives during a long library call waits for it.  The signal's byte on the wakeup fd wakes
    this thread at once; if the process is still alive INTERRUPT_GRACE seconds later, it reports,
    removes the temporary files being written and ends the job itself."""
    try:
        reader, writer = socket.socketpair()
        writer.setblocking(False)
        signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    except (ValueError, OSError):  # not the main thread: nothing to watch
        return

    def watch() -> None:
        signum = 0
        while signum not in (signal.SIGINT, signal.SIGTERM):
            signum = reader.recv(1)[0]
        time.sleep(INTERRUPT_GRACE)
        status = 143 if signum == signal.SIGTERM else 130
        try:  # whatever fails here (a closed standard error, an Abort that hangs), the process ends
            if "ddsolve.io.safe" in sys.modules:
                sys.modules["ddsolve.io.safe"].COMMIT.acquire()  # a set being renamed into place is finished first
                sys.modules["ddsolve.io.safe"].remove_scratch()
            status = interrupted_status(status)
            abort(status, alone=True)
        finally:
            os._exit(status)

    threading.Thread(target=watch, name="ddsolve-interrupts", daemon=True).start()
    watch_interrupts.sockets = (reader, writer)  # keep them open


def interrupted_status(status: int) -> int:
    """Report an interrupt (unless the launcher of ``solve -n`` does, :func:`~ddsolve.parallel.launch.supervise`);
    its exit status, or 0 if the result files that end the command were already in place (they are complete)."""
    io = sys.modules.get("ddsolve.io.safe")
    complete = io is not None and io.committed
    if not supervised():
        report(interrupt_line(status == 143, complete))
    return 0 if complete else status


def guarded(call) -> int:
    """Run a command: a DDSolveError (or a missing petsc4py, mpi4py, h5py, gmsh...) becomes one line
    and its exit status, an interrupt or SIGTERM stops every rank, anything else is a bug (one
    traceback, abort)."""
    end_with_launcher()
    prepare_output()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, _interrupt)
    watch_interrupts()
    try:
        with import_errors_explained():
            status = call()
            if sys.stdout is not None:
                sys.stdout.flush()  # a full disk or a closed pipe is this command's error
            return status
    except DDSolveError as exc:
        interrupts_ignored()  # the status is decided: another rank's abort (SIGTERM) must not cut this report short
        report(f"ddsolve: error: {exc}", everywhere=not exc.collective)
        if not exc.collective:  # raised on this rank only: the others cannot know, so stop them
            abort(exc.exit_status)
        return exc.exit_status
    except KeyboardInterrupt as exc:
        status = interrupted_status(143 if isinstance(exc, Terminated) else 130)
        abort(status)
        return status
    except Exception:
        traceback.print_exc()
        abort(1)
        return 1
    finally:
        interrupts_ignored()


#: ASCII spellings of the symbols in ddsolve's messages that are neither Greek letters (spelt by their
#: names: Σ -> Sigma, θ -> theta) nor letters with accents or super- and subscripts (their base forms).
SPELLINGS = {"−": "-", "×": "x", "·": "*", "≤": "<=", "≥": ">=", "≈": "~", "±": "+-", "∞": "inf", "→": "->",
             "‖": "||", "«": '"', "»": '"', "—": "--", "–": "-", "…": "...", "°": " deg", "⁄": "/"}


def _ascii(char: str) -> str:
    if char in SPELLINGS:
        return SPELLINGS[char]
    name = unicodedata.name(char, "")
    if name.startswith("GREEK ") and " LETTER " in name:
        letter = name.split(" LETTER ")[1].replace("FINAL ", "").split()[0].lower()
        return letter.capitalize() if " CAPITAL " in name else letter
    if char.isascii() and char.isprintable():
        return char
    return char.encode("ascii", "backslashreplace").decode("ascii")


def spelled_in_ascii(error: UnicodeError) -> tuple[str, int]:
    """Codec error handler ``ddsolve``: what an output's encoding cannot hold, in ASCII spellings
    (:data:`SPELLINGS`, Greek letters by name, base forms without accents), else as backslash escapes."""
    if not isinstance(error, UnicodeEncodeError):
        raise error
    text = unicodedata.normalize("NFKD", error.object[error.start:error.end])
    return "".join(_ascii(char) for char in text if not unicodedata.combining(char)), error.end


class CheckedOutput:
    """Standard output whose write errors (a full disk, a closed pipe) are one-line errors, whatever
    writes -- a print, argparse's help, the final flush; after one, the rest goes to /dev/null, so
    that the flush at Python's exit does not fail again."""

    def __init__(self, stream):
        self.stream = stream

    def __getattr__(self, name: str):
        return getattr(self.stream, name)

    def write(self, text: str) -> int:
        return self._checked(self.stream.write, text)

    def flush(self) -> None:
        self._checked(self.stream.flush)

    def _checked(self, call, *args):
        try:
            return call(*args)
        except OSError as exc:
            with contextlib.suppress(OSError, ValueError):
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, self.stream.fileno())
                os.close(devnull)
            raise DDSolveError(f"cannot write to standard output: {exc.strerror or exc}") from None


def prepare_output() -> None:
    """Standard output and error in any encoding (ASCII in a C locale, latin-1...): what the encoding
    cannot hold is spelt in ASCII (:func:`spelled_in_ascii`), never an error; standard output checked
    (:class:`CheckedOutput`)."""
    codecs.register_error("ddsolve", spelled_in_ascii)
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="ddsolve")
    if sys.stdout is not None and not isinstance(sys.stdout, CheckedOutput):
        sys.stdout = CheckedOutput(sys.stdout)


def flush_output() -> None:
    """Flush standard output before an error line or an abort (a failure to write it is reported by
    the command's own flush, or lost with the error being reported)."""
    with contextlib.suppress(DDSolveError, AttributeError):
        sys.stdout.flush()


def comm_world():
    """MPI.COMM_WORLD if mpi4py is in use, else None."""
    if "mpi4py.MPI" not in sys.modules:
        return None
    from mpi4py import MPI

    return MPI.COMM_WORLD if MPI.Is_initialized() and not MPI.Is_finalized() else None


def abort(status: int, alone: bool = False) -> None:
    """End every rank at once (with ``alone``, even a single rank): waiting for the others (PETSc's
    finalize does) would hang.  MPI_Abort waits for mpiexec and holds the GIL meanwhile, so no Python
    thread can run: if mpiexec does not answer, faulthandler's own C thread ends this process (status
    1) ABORT_GRACE seconds later."""
    world = comm_world()
    if world is not None and (world.size > 1 or alone):
        flush_output()
        with contextlib.suppress(OSError, ValueError):
            sys.stderr.flush()
        faulthandler.dump_traceback_later(ABORT_GRACE, exit=True, file=open(os.devnull, "w"))
        world.Abort(status)


def report(message: str, everywhere: bool = False) -> None:
    """Print an error once (on rank 0 when MPI is running, unless it happened on one rank only)."""
    world = comm_world()
    if world is None or world.rank == 0 or everywhere:
        flush_output()
        print(message, file=sys.stderr, flush=True)
