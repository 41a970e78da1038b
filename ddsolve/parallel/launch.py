"""Starting ddsolve under mpiexec (used by ``ddsolve solve -n N`` and by the experiments)."""
from __future__ import annotations

import functools
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Mapping

from ddsolve.environment import PARENT_AT_START, end_with_parent, process_exists
from ddsolve.errors import DDSolveError
from ddsolve.io import safe
from ddsolve.parallel.phases import LAUNCHED

#: Variables an MPI launcher (Open MPI, MPICH's hydra, PMIx) gives the ranks it starts.
RANK_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK")

#: Variables of a batch allocation (Slurm, PBS, LSF, Grid Engine) or a host file: the ranks may span hosts.
ALLOCATION_VARIABLES = ("SLURM_JOB_ID", "PBS_JOBID", "LSB_JOBID", "PE_HOSTFILE", "OMPI_MCA_orte_default_hostfile")

#: Blocks of a two-layer structure's decomposition (a one-layer structure has 2): a rank count must divide
#: the structure's blocks or be a multiple of them.
BLOCK_COUNT = 4


def supervised() -> bool:
    """Whether this rank was started by ``ddsolve solve -n`` (or ``sweep``, ``grow``), whose launcher
    reports an interrupt itself (:func:`supervise`)."""
    return bool(os.environ.get(LAUNCHED))


def interrupt_line(terminated: bool, complete: bool) -> str:
    """The one line an interrupted command ends with (SIGTERM or SIGINT; whether its result set is in place)."""
    word = "terminated" if terminated else "interrupted"
    return f"ddsolve: {word} after its result files were written (they are complete)" if complete else f"ddsolve: {word}"


def leader(block: int, size: int, count: int = BLOCK_COUNT) -> int:
    """The rank that leads ``block`` of ``count`` among ``size`` ranks (see
    :class:`~ddsolve.parallel.exchange.Exchange`)."""
    return block % size if size <= count else block * (size // count)


def world_position(environ: Mapping[str, str] = os.environ) -> tuple[int, int]:
    """This process's rank and the number of ranks, from the launcher's variables before MPI starts
    (0 of 1 outside a launcher, or for a launcher that sets none of them)."""
    for rank, size in (("OMPI_COMM_WORLD_RANK", "OMPI_COMM_WORLD_SIZE"), ("PMI_RANK", "PMI_SIZE")):
        if environ.get(rank, "").isdigit() and environ.get(size, "").isdigit():
            return int(environ[rank]), int(environ[size])
    return 0, 1


def supported(size: int, count: int = BLOCK_COUNT, uneven: bool = False) -> bool:
    """Whether ``size`` ranks can work on ``count`` blocks: a divisor of ``count`` (whole blocks per rank) or a
    multiple of it (each block on size/count ranks): 1, 2, 4 or 4k ranks for 4 blocks, 1 or 2k for 2.  ``uneven``
    (a 3-D box's blocks, each rank assembling its own): any count up to ``count`` too, some ranks holding a block
    more than others."""
    return size > 0 and (count % size == 0 or size % count == 0 or uneven and size <= count)


def usable(count: int = BLOCK_COUNT, uneven: bool = False) -> str:
    """The rank counts :func:`supported` takes for ``count`` blocks, in words: ``1, 2 or a multiple of 4``
    (``uneven``: ``1, 2, 3 or a multiple of 4``, ``1 to 7 or a multiple of 8``)."""
    fewer = [size for size in range(1, count) if uneven or count % size == 0]
    words = f"1 to {fewer[-1]}" if uneven and len(fewer) > 3 else ", ".join(map(str, fewer))
    return f"{words} or a multiple of {count}" if fewer else f"a multiple of {count}"


def mpiexec_command(ranks: int, arguments: list[str], module: str = "ddsolve") -> list[str]:
    """``mpiexec -n N python -m MODULE ARGS`` (quiet Open MPI: our errors are one line).

    ddsolve's ``main`` gives the semantics of ``python -m mpi4py``: an error on one rank, an unexpected
    exception or an interrupt aborts every rank.  Errors that every rank raises together end every
    rank normally with the same status, so no abort (and no Open MPI banner) is needed for them.
    """
    mpiexec = os.environ.get("MPIEXEC", "mpiexec")
    if shutil.which(mpiexec) is None:
        raise DDSolveError(f"{mpiexec} not found: install Open MPI or MPICH, or set MPIEXEC")
    version = subprocess.run([mpiexec, "--version"], capture_output=True, text=True).stdout
    return [mpiexec, *launcher_options(version, os.environ), "-n", str(ranks), sys.executable, "-m", module,
            *arguments]


def launcher_options(version: str, environ: Mapping[str, str]) -> list[str]:
    """mpiexec's options for the launcher that prints ``version``, where the variables ``environ`` are set
    (Open MPI's; none for others)."""
    if "Open MPI" not in version and "OpenRTE" not in version:
        return []
    # ddsolve reads no standard input: not forwarding it also spares a libevent warning line
    # ("Epoll MOD ... Bad file descriptor") when it is closed or a file.
    options = ["--quiet", "--stdin", "none"]
    if "OMPI_MCA_mpi_yield_when_idle" not in environ:
        # A rank waiting in MPI (inside a distributed MUMPS solve, say) yields its core instead of
        # spinning: with more ranks than cores, 5x faster rounds at 8 ranks on 2 cores.
        options += ["--mca", "mpi_yield_when_idle", "1"]
    if "OMPI_MCA_pml" not in environ and not any(name in environ for name in ALLOCATION_VARIABLES):
        # One host: the ranks talk through shared memory (ob1 with vader). Naming the layer spares every
        # rank probing the network layers (cm with PSM, PSM2, OFI): MPI_Init 0.2 s instead of 0.4 s.
        options += ["--mca", "pml", "ob1"]
    return options



#: Seconds end_session waits for the processes it killed to be gone.
KILL_WAIT = 10.0


def end_session(session: int) -> None:
    """SIGKILL every process still in the session ``session`` (mpiexec's: the ranks it started and their
    gmsh children, each in a process group of its own), mpiexec included, and wait until they are gone
    (at most KILL_WAIT s): the temporary files of a rank killed mid-write are removed by the next
    :func:`ddsolve.io.safe.recover` only once their writer no longer exists."""
    killed = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit() or int(entry) == os.getpid():
            continue
        try:
            if os.getsid(int(entry)) == session:
                os.kill(int(entry), signal.SIGKILL)
                killed.append(int(entry))
        except OSError:  # ended meanwhile
            continue
    deadline = time.monotonic() + KILL_WAIT
    while any(process_exists(pid) for pid in killed) and time.monotonic() < deadline:
        time.sleep(0.01)


def end_with_launcher() -> None:
    """A rank that mpiexec (or its daemon, the rank's parent) started ends when mpiexec ends, however it
    ends: ranks would otherwise outlive a killed launcher, reparented to init.  The parent is the one the
    rank had as ddsolve was imported (:data:`~ddsolve.environment.PARENT_AT_START`), so that a launcher
    killed during the rank's imports ends it at once; under ``solve -n`` mpiexec also leads the rank's
    session, and a rank whose session leader has ended before it was first imported ends at once too."""
    if not any(name in os.environ for name in RANK_VARIABLES):
        return
    session = os.getsid(0)
    if supervised() and session != PARENT_AT_START and not process_exists(session):
        os._exit(128 + signal.SIGTERM)  # mpiexec ended before this rank began: nobody waits for it
    end_with_parent(PARENT_AT_START)


@functools.lru_cache(maxsize=None)
def provenance() -> dict[str, str]:
    """What produced a file: ddsolve version and git commit, PETSc, MPI, Python, PETSc options.

    Computed once per process (it asks git); do not modify the returned dict.
    """
    import platform

    from mpi4py import MPI
    from petsc4py import PETSc

    from ddsolve import __version__

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



def _identity(path: Path):
    """What tells a replaced file from the one that was there (None: no file)."""
    try:
        info = os.stat(path, follow_symlinks=False)
        return info.st_ino, info.st_mtime_ns, info.st_size
    except OSError:
        return None


def supervise(command: list[str], env: dict, outputs: list[Path]) -> int:
    """Run the ranks' mpiexec and return its exit status.  SIGINT and SIGTERM are passed on to it once
    (Open MPI then stops every rank); afterwards the result set ``outputs`` is made whole if a rank was
    killed while renaming it (:func:`ddsolve.io.safe.recover`), and the status is 0 if the run replaced it
    (the signal came after its commit: the set is complete), else 130 or 143.  The interrupt's one line is
    printed here, not by the ranks: Open MPI may stop them before their output reaches it, and it gives
    them SIGTERM whatever this process received.  Once mpiexec has ended, the status no longer depends on
    a signal: later ones are ignored (Python's exit gives them their default action back, which would
    end this process with 130 or 143 after a complete run)."""
    import subprocess

    before = _identity(outputs[0])
    signal.set_wakeup_fd(-1)  # the watchdog stays asleep: this process only waits for mpiexec
    launcher = os.getpid()  # mpiexec gets SIGTERM (and stops the ranks) when this process ends, however
    received: list[int] = []
    job: list[subprocess.Popen] = []

    def forward(signum, _frame) -> None:
        if not received and job:
            job[0].send_signal(signum)
        received.append(signum)

    for signum in (signal.SIGINT, signal.SIGTERM):  # before mpiexec starts: no signal is left unforwarded
        signal.signal(signum, forward)
    try:
        job.append(subprocess.Popen(command, env=env, start_new_session=True,
                                    preexec_fn=lambda: end_with_parent(launcher, signal.SIGTERM)))
        if received:  # came while mpiexec was being started
            job[0].send_signal(received[0])
        status = job[0].wait()
    finally:
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)
        if received and job:  # what the signal left of the job ends with it, before the result set is repaired
            end_session(job[0].pid)
    safe.recover(outputs)
    if received:
        complete = _identity(outputs[0]) != before
        print(interrupt_line(received[0] == signal.SIGTERM, complete), file=sys.stderr, flush=True)
        return 0 if complete else (143 if received[0] == signal.SIGTERM else 130)
    return status if status >= 0 else 128 - status
