"""Starting ddsolve under mpiexec (used by ``ddsolve solve -n N`` and by the experiments)."""
from __future__ import annotations

import ctypes
import os
import shutil
import signal
import subprocess
import sys

from .errors import DDSolveError

#: Linux's prctl request: the signal the kernel sends a process when its parent ends.
PR_SET_PDEATHSIG = 1
#: Variables an MPI launcher (Open MPI, MPICH's hydra, PMIx) gives the ranks it starts.
RANK_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK")

#: Blocks of the decomposition: a rank count must divide them or be a multiple of them.
BLOCK_COUNT = 4


def supported(size: int) -> bool:
    """1, 2 or 4 ranks (whole blocks per rank), or a multiple of 4 (each block on size/4 ranks)."""
    return size in (1, 2) or (size > 0 and size % BLOCK_COUNT == 0)


def mpiexec_command(ranks: int, arguments: list[str], module: str = "ddsolve") -> list[str]:
    """``mpiexec -n N python -m MODULE ARGS`` (quiet Open MPI: our errors are one line).

    ddsolve's ``main`` gives the semantics of ``python -m mpi4py``: an error on one rank, an unexpected
    exception or an interrupt aborts every rank.  Errors that every rank raises together end every
    rank normally with the same status, so no abort (and no Open MPI banner) is needed for them.
    """
    mpiexec = os.environ.get("MPIEXEC", "mpiexec")
    if shutil.which(mpiexec) is None:
        raise DDSolveError(f"{mpiexec} not found: install Open MPI or MPICH, or set MPIEXEC")
    command = [mpiexec]
    version = subprocess.run([mpiexec, "--version"], capture_output=True, text=True).stdout
    if "Open MPI" in version or "OpenRTE" in version:
        # ddsolve reads no standard input: not forwarding it also spares a libevent warning line
        # ("Epoll MOD ... Bad file descriptor") when it is closed or a file.
        command += ["--quiet", "--stdin", "none"]
        if "OMPI_MCA_mpi_yield_when_idle" not in os.environ:
            # A rank waiting in MPI (inside a distributed MUMPS solve, say) yields its core instead of
            # spinning: with more ranks than cores, 5x faster rounds at 8 ranks on 2 cores.
            command += ["--mca", "mpi_yield_when_idle", "1"]
    return command + ["-n", str(ranks), sys.executable, "-m", module, *arguments]


def end_with_parent(parent: int, signum: int = signal.SIGKILL) -> None:
    """Have the kernel send ``signum`` to this process when its parent (the process ``parent``) ends,
    and end at once if it has ended already.  SIGKILL of a parent cannot be caught, so this is the only
    way its children learn of it.  Linux only: elsewhere nothing is done."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, int(signum), 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent ended before the request: nobody waits for this process
        os._exit(128 + int(signum))


def end_with_launcher(parent: int) -> None:
    """A rank that mpiexec (or its daemon, the rank's parent ``parent``) started ends when mpiexec ends,
    however it ends: ranks would otherwise outlive a killed launcher, reparented to init."""
    if any(name in os.environ for name in RANK_VARIABLES):
        end_with_parent(parent)
