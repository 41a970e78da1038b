"""Message passing between the ranks that own blocks and rank 0, which owns the multipliers.

Rank r owns blocks ``r·m … (r+1)·m − 1`` with m = 4 / size.  Every round is driven by rank 0:
it broadcasts a command, scatters one trace load per block, every rank solves its blocks, and the
results are gathered back on rank 0 in block order — one small broadcast, one Scatter and one Gather
of contiguous float64 buffers.  Errors found on any rank are raised on every rank
(:func:`collective`), so all ranks leave together.
"""
from __future__ import annotations

import time
from typing import Callable, TypeVar

import numpy as np
from mpi4py import MPI

from .errors import DDSolveError

T = TypeVar("T")
ROOT = 0


def wait(request: MPI.Request) -> None:
    """Complete a nonblocking operation, polling briefly and then sleeping between tests.

    A blocking MPI call busy-polls: with more ranks than cores, ranks that wait for a long rank-0
    phase (meshing, reading a file) would take CPU time from it.
    """
    started = time.perf_counter()
    pause = 0.0
    while not request.Test():
        if time.perf_counter() - started > 1e-3:  # after a millisecond of polling, yield the core
            pause = min(2.0 * pause or 5e-5, 2e-3)
            time.sleep(pause)


def collective(comm: MPI.Comm, work: Callable[[], T], root_only: bool = False) -> T:
    """Run ``work`` (on every rank, or on rank 0 only), then raise the first error on all ranks."""
    value, error = None, None
    if not root_only or comm.rank == ROOT:
        try:
            value = work()
        except DDSolveError as exc:
            error = exc
    if root_only:
        wait(comm.Ibarrier())
    errors = comm.allgather(error)
    first = next((e for e in errors if e is not None), None)
    if first is not None:
        first.collective = True
        raise first
    return value


class Exchange:
    """Scatter/gather of per-block arrays between block owners and rank 0."""

    def __init__(self, comm: MPI.Comm, n_blocks: int):
        self.comm = comm
        self.per_rank = n_blocks // comm.size
        self.n_blocks = n_blocks
        self.local_blocks = range(comm.rank * self.per_rank, (comm.rank + 1) * self.per_rank)
        self._command = np.zeros(1, dtype=np.int64)

    @property
    def is_root(self) -> bool:
        return self.comm.rank == ROOT

    def command(self, code: int | None = None) -> int:
        """Broadcast a command code from rank 0 (a blocking call: between rounds, latency matters most)."""
        if self.is_root:
            self._command[0] = code
        self.comm.Bcast(self._command, root=ROOT)
        return int(self._command[0])

    def scatter(self, per_block: np.ndarray | None, width: int) -> np.ndarray:
        """Rank 0's ``(n_blocks, width)`` rows -> this rank's ``(per_rank, width)`` rows."""
        local = np.empty((self.per_rank, width))
        send = np.ascontiguousarray(per_block, dtype=np.float64) if self.is_root else None
        self.comm.Scatter(send, local, root=ROOT)
        return local

    def gather(self, local: np.ndarray) -> np.ndarray | None:
        """This rank's ``(per_rank, ...)`` rows -> ``(n_blocks, ...)`` on rank 0 (None elsewhere)."""
        local = np.ascontiguousarray(local, dtype=np.float64)
        out = np.empty((self.n_blocks, *local.shape[1:])) if self.is_root else None
        self.comm.Gather(local, out, root=ROOT)
        return out

    def gather_varying(self, local: list[np.ndarray], sizes: list[int]) -> list[np.ndarray] | None:
        """Gather one 1-D array per block whose lengths differ (``sizes`` known on every rank)."""
        send = np.concatenate(local) if local else np.zeros(0)
        counts = [sum(sizes[r * self.per_rank:(r + 1) * self.per_rank]) for r in range(self.comm.size)]
        out = np.empty(sum(sizes)) if self.is_root else None
        self.comm.Gatherv(send, (out, counts) if self.is_root else None, root=ROOT)
        if not self.is_root:
            return None
        return np.split(out, np.cumsum(sizes)[:-1])
