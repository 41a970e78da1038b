"""Message passing between the ranks that work on blocks and rank 0, which owns the multipliers.

Every round is driven by rank 0: it broadcasts a command, scatters one trace load per block to the
blocks' leaders (which share it with their block communicators), every rank solves its part, and
the results come back to rank 0 in block order — a small broadcast, a Scatterv and a Gatherv of
contiguous float64 buffers.  Errors found on any rank are raised on every rank (:func:`collective`),
so all ranks leave together.
"""
from __future__ import annotations

import time
from typing import Callable, TypeVar

import numpy as np
from mpi4py import MPI

from ddsolve.errors import DDSolveError
from ddsolve.parallel import launch

T = TypeVar("T")
ROOT = 0


def wait(request: MPI.Request) -> None:
    """Complete a nonblocking operation, polling briefly and then sleeping between tests.

    A blocking MPI call busy-polls: with more ranks than cores, ranks that wait for a long phase
    of other ranks (meshing, reading a file, assembling) would take CPU time from them.
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
    wait(comm.Ibarrier())  # ranks that finish early yield their core to those still working
    errors = comm.allgather(error)
    first = next((e for e in errors if e is not None), None)
    if first is not None:
        first.collective = True
        raise first
    return value


class Exchange:
    """Which blocks this rank works on, and scatter/gather of per-block arrays with rank 0.

    With a divisor of the block count as ranks (1, 2 or 4 with four blocks), rank r owns the blocks b
    with b mod size = r, each on COMM_SELF: with two ranks, u⁻ and v⁻ (the lower half) on rank 0 and u⁺
    and v⁺ on rank 1, so that a rank needs one half's mesh and its two blocks share a sparsity pattern (a
    one-layer structure's two blocks u⁻ and u⁺ are on one rank each).  With k ranks per block, block b is
    distributed over ranks b·k … (b+1)·k − 1 (its *block communicator*); the first of them is the block's
    *leader*.  ``uneven`` (a 3-D box's blocks) takes any rank count below the blocks too, dealt as a divisor's
    are (rank r the blocks b with b mod size = r: some ranks hold one more).  Rank 0 exchanges per-block arrays
    with the leaders (Scatterv/Gatherv, rows in block order on rank 0); each leader shares them with its block
    communicator.  Ranks wait for rank 0 without spinning (:func:`wait`), so the cores stay free for the ranks
    that work.
    """

    def __init__(self, comm: MPI.Comm, n_blocks: int, uneven: bool = False):
        if not launch.supported(comm.size, n_blocks, uneven):
            error = DDSolveError(f"unsupported number of ranks {comm.size} for {n_blocks} blocks: use "
                                 f"{launch.usable(n_blocks, uneven)}")
            error.collective = True  # every rank sees the same size
            raise error
        self.comm = comm
        self.n_blocks = n_blocks
        size, rank = comm.size, comm.rank
        if size <= n_blocks:
            self.local_blocks = list(range(rank, n_blocks, size))
            self.groups = [MPI.COMM_SELF] * len(self.local_blocks)
            self.led_blocks = self.local_blocks
        else:
            per = size // n_blocks  # ranks per block
            block = rank // per
            self.local_blocks = [block]
            self.groups = [comm.Split(color=block, key=rank)]
            self.led_blocks = [block] if rank % per == 0 else []
        led = comm.allgather(self.led_blocks)
        self.led_counts = [len(blocks) for blocks in led]
        self.order = np.array([block for blocks in led for block in blocks], dtype=np.int64)  # rank order
        self._command = np.zeros(1, dtype=np.int64)

    def leader(self, block: int) -> int:
        """The rank that leads ``block``."""
        return launch.leader(block, self.comm.size, self.n_blocks)

    def ranks(self, block: int) -> range:
        """The ranks that work on ``block``: its leader and, with more ranks than blocks, those after it."""
        per = max(1, self.comm.size // self.n_blocks)
        return range(self.leader(block), self.leader(block) + per)

    @property
    def is_root(self) -> bool:
        return self.comm.rank == ROOT

    def command(self, code: int | None = None) -> int:
        """Broadcast a command code from rank 0; the others wait for it without spinning (rank 0 may
        be busy between rounds, and a spinning rank would take a core from it)."""
        if self.is_root:
            self._command[0] = code
        wait(self.comm.Ibcast(self._command, root=ROOT))
        return int(self._command[0])

    def scatter(self, per_block: np.ndarray | None, width: int) -> list[np.ndarray]:
        """Rank 0's ``(n_blocks, width)`` rows -> one row per local block, on every rank of the block."""
        led = np.empty((len(self.led_blocks), width))
        send = None
        if self.is_root:
            rows = np.asarray(per_block, dtype=np.float64)[self.order]
            send = (np.ascontiguousarray(rows), [c * width for c in self.led_counts])
        self.comm.Scatterv(send, led, root=ROOT)
        rows = []
        for block, group in zip(self.local_blocks, self.groups):
            row = led[self.led_blocks.index(block)] if block in self.led_blocks else np.empty(width)
            if group.size > 1:
                group.Bcast(row, root=0)
            rows.append(row)
        return rows

    def gather(self, led: np.ndarray, width: int) -> np.ndarray | None:
        """The leaders' ``(led blocks, width)`` rows -> ``(n_blocks, width)`` on rank 0 (None elsewhere)."""
        received = np.empty((self.n_blocks, width)) if self.is_root else None
        receive = (received, [c * width for c in self.led_counts]) if self.is_root else None
        wait(self.comm.Igatherv(np.ascontiguousarray(led, dtype=np.float64).reshape(-1), receive, root=ROOT))
        if not self.is_root or np.array_equal(self.order, np.arange(self.n_blocks)):
            return received
        out = np.empty_like(received)
        out[self.order] = received
        return out

    def gather_varying(self, led: list[np.ndarray], sizes: list[int]) -> list[np.ndarray] | None:
        """One 1-D array per led block, lengths ``sizes`` per block (known everywhere) -> rank 0."""
        send = np.concatenate(led) if led else np.zeros(0)
        ordered = [sizes[block] for block in self.order]
        counts, start = [], 0
        for count in self.led_counts:
            counts.append(sum(ordered[start:start + count]))
            start += count
        out = np.empty(sum(sizes)) if self.is_root else None
        wait(self.comm.Igatherv(send, (out, counts) if self.is_root else None, root=ROOT))
        if not self.is_root:
            return None
        pieces = np.split(out, np.cumsum(ordered)[:-1])
        return [pieces[int(np.flatnonzero(self.order == block)[0])] for block in range(self.n_blocks)]

    def free(self) -> None:
        for group in self.groups:
            if group != MPI.COMM_SELF:
                group.Free()
