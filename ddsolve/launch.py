"""Starting ddsolve under mpiexec (used by ``ddsolve solve -n N`` and by the experiments)."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys

from .errors import DDSolveError

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
