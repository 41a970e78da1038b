"""Rounds of block solves: rank 0 sends a command and interface loads, every rank solves its blocks,
rank 0 gathers traces (or Schur complements); the other ranks serve rounds until STOP."""
from __future__ import annotations

import math
import time

import numpy as np
from mpi4py import MPI

from ddsolve.dd import kernels
from ddsolve.errors import DDSolveError, SolverError
from ddsolve.parallel.blocks import Block
from ddsolve.parallel.exchange import Exchange

(STOP, SOLVE_LOAD, SOLVE_FULL, SCHUR, REPORT_ERROR, DIRICHLET, DIAGONAL, CONDENSED, KERNEL_WORK, SOLVE_HELD,
 SOLVE_MANY) = range(11)


#: Commands whose round sends a trace vector to every block (SOLVE_HELD: two, loads and held traces; SOLVE_MANY:
#: ``columns`` loads of the block's entries, rank 0 broadcasting the entries and columns a block gets after the
#: command).
WITH_LOADS = (SOLVE_LOAD, SOLVE_FULL, DIRICHLET, SOLVE_HELD, SOLVE_MANY)


def result_width(command: int, trace_size: int, rows: int = 0, columns: int = 1) -> int:
    """Values per block a round returns (before the status flag): a Schur complement, ``columns`` traces of
    ``rows`` entries (SOLVE_MANY), or the trace, the energy xᵀ K x, the work of the body loads, and (full solves) the
    relative residual and the largest nodal |x|."""
    if command == SOLVE_MANY:
        return rows * columns
    return trace_size ** 2 if command == SCHUR else trace_size + 4


def load_width(command: int, trace_size: int, rows: int = 0, columns: int = 1) -> int:
    """Values per block a round sends."""
    return rows * columns if command == SOLVE_MANY else trace_size * (2 if command == SOLVE_HELD else 1)


class BlockServer:
    """The blocks this rank works on and what a round does with them."""

    def __init__(self, blocks: list[Block], exchange: Exchange, piece_dofs: dict[int, np.ndarray] | None = None,
                 gather: bool = True, positions: dict[int, np.ndarray] | None = None):
        """``positions``: with several interfaces, each local block's trace entries in the structure's trace
        (rounds send and return the structure's trace, which a block holds only at these; none: a block's
        trace is the structure's)."""
        self.blocks, self.exchange, self.gather = blocks, exchange, gather
        self.positions = positions or {}
        self.solutions: dict[int, np.ndarray] = {}  # led blocks' solutions from the last full solve (``gather``)
        self.piece_dofs = piece_dofs or {}  # local block -> the dofs of this rank's piece of its half
        self.piece_values: dict[int, np.ndarray] = {}  # ... and the last full solve there
        self.error = ""

    @property
    def held_bytes(self) -> int:
        """Bytes of the solutions held: the led blocks' whole ones and the pieces' values (once each)."""
        return sum({id(u): u.nbytes for u in (*self.solutions.values(), *self.piece_values.values())}.values())

    def run(self, command: int, loads: list[np.ndarray] | None, width: int, columns: int = 1) -> np.ndarray:
        """One round on the local blocks: the rows of the led blocks, each ending with a status flag (``columns``:
        the trace loads per block of SOLVE_MANY)."""
        rows, failed = {}, False
        try:
            for i, (index, block) in enumerate(zip(self.exchange.local_blocks, self.blocks)):
                if command == SOLVE_MANY:
                    value = self._solve_many(index, block, loads[i], columns)
                elif command == SCHUR:
                    value = block.schur_complement()
                elif command in (DIRICHLET, DIAGONAL, CONDENSED, KERNEL_WORK):
                    trace = (block.dirichlet(self._own(index, loads[i])) if command == DIRICHLET else
                             block.trace_diagonal() if command == DIAGONAL else self._floating_value(block, command))
                    value = np.concatenate([trace, np.zeros(width - len(trace))]) if block.is_leader else None
                elif command == SOLVE_HELD:
                    given, held = np.split(loads[i], 2)
                    value = self._solve(index, block, self._own(index, given), full=True,
                                        held=self._own(index, held) if block.floating else None)
                else:
                    value = self._solve(index, block, self._own(index, loads[i]), full=command == SOLVE_FULL)
                if block.is_leader:
                    rows[index] = self._spread(index, command, value, width)
        except DDSolveError as exc:
            self.error, failed = str(exc), True
        # Every rank of a block learns whether one of them failed (PETSc errors are collective anyway).
        for group in self.exchange.groups:
            if group.size > 1:
                failed = group.allreduce(failed, op=MPI.LOR)
        out = np.full((len(self.exchange.led_blocks), width + 1), np.nan)
        out[:, -1] = float(failed)
        if not failed:
            for i, index in enumerate(self.exchange.led_blocks):
                out[i, :-1] = rows[index].ravel()
        return out

    def _own(self, index: int, values: np.ndarray) -> np.ndarray:
        """The entries of a structure's trace ``values`` that block ``index`` holds."""
        return values[self.positions[index]] if index in self.positions else values

    def _spread(self, index: int, command: int, value: np.ndarray, width: int) -> np.ndarray:
        """A block's round ``value`` on the structure's trace: a Schur complement with zero rows and columns off
        its entries, a trace with zeros (a diagonal: infinity, no share of a jump) and the numbers after it; the work
        in a floating block's rigid motions (KERNEL_WORK) is no trace and stays as it is."""
        if index not in self.positions or command in (KERNEL_WORK, SOLVE_MANY):
            return value
        at, size = self.positions[index], len(self.positions[index])
        if command == SCHUR:
            out = np.zeros((math.isqrt(width),) * 2)
            out[np.ix_(at, at)] = value
            return out
        out = np.full(width, np.inf if command == DIAGONAL else 0.0)
        out[width - 4:] = value[size:size + 4]  # see result_width
        out[at] = value[:size]
        return out

    def _solve_many(self, index: int, block: Block, loads: np.ndarray, columns: int) -> np.ndarray | None:
        """The block's traces ``(rows, columns)`` for the ``columns`` loads ``loads`` (raveled ``(rows, columns)``,
        ``rows`` its entries of the structure's trace first, in order, then padding), raveled, on the leader; a
        column that loads none of its entries is not solved."""
        loads = loads.reshape(-1, columns)
        own = loads[:len(self.positions[index])] if index in self.positions else loads
        loaded = np.flatnonzero(np.any(own != 0.0, axis=0))
        traces = block.solve_many(own[:, loaded]) if len(loaded) else None
        if not block.is_leader:
            return None
        out = np.zeros_like(loads)
        if len(loaded):
            out[:len(own), loaded] = traces
        return out.ravel()

    @staticmethod
    def _floating_value(block: Block, command: int) -> np.ndarray | None:
        """CONDENSED: g = f_Σ − K_ΣI K_II⁻¹ f_I of a floating block, the uncoupled trace of K⁻¹ f of another
        (rank 0 multiplies it by S); KERNEL_WORK: Rᵀ f of a floating block, nothing of another."""
        if command == CONDENSED:
            return block.condensed_load() if block.floating else block.trace(block.solve(np.zeros(len(block.trace_dofs)), body=True))
        return block.kernel_work() if block.floating else np.zeros(0)

    def _solve(self, index: int, block: Block, load: np.ndarray, full: bool,
               held: np.ndarray | None = None) -> np.ndarray | None:
        x = block.solve(load, body=full) if held is None else block.expand(held, load)
        trace, energies = block.trace(x), block.energies()
        checks = np.zeros(2)
        if full:
            checks = np.array([block.residual(), block.largest_displacement(x)])
            whole = block.gather(x) if self.gather or block.mpi.size == 1 else None
            if block.is_leader and self.gather:
                self.solutions[index] = whole
            if index in self.piece_dofs:
                self.piece_values[index] = (whole if block.mpi.size == 1 else
                                            block.values_at(self.piece_dofs[index]))
        return np.concatenate([trace, energies, checks]) if block.is_leader else None


class ParallelRounds:
    """Rank 0's implementation of :class:`~ddsolve.dd.dual.Rounds` over an :class:`Exchange`.

    Between rounds rank 0 is updating multipliers: that time is logged in the PETSc stage
    ``Update``, the rounds themselves in ``Rounds``.
    """

    def __init__(self, exchange: Exchange, server: BlockServer, trace_size: int, stages: dict,
                 kernel_traces: list[np.ndarray] | None = None, trace_stiffness: list | None = None,
                 entries: list[np.ndarray] | None = None):
        """``trace_stiffness``: the blocks' stiffness on their traces (sparse, for :meth:`lumped`), where gathered;
        ``entries``: each block's entries of the structure's trace (None: every block holds all of it)."""
        self.exchange, self.server, self.trace_size, self.stages = exchange, server, trace_size, stages
        self.entries = entries or [np.arange(trace_size)] * exchange.n_blocks
        self.trace_stiffness = trace_stiffness
        # the traces (2k, m_b) of the blocks' kernels (m_b = 0: invertible)
        self.kernel_traces = kernel_traces or [np.zeros((trace_size, 0))] * exchange.n_blocks
        self.floating = [b for b, kernel in enumerate(self.kernel_traces) if kernel.shape[1]]
        self.count = 0
        self.schur_bytes = 0  # the blocks' Schur complements gathered here (bytes)
        self.elapsed = 0.0  # seconds inside rounds
        self.work = np.zeros(exchange.n_blocks)  # work of the body loads less the energy offsets, last solve
        self.residuals = np.zeros(exchange.n_blocks)  # relative residuals of the last full solve
        self.largest = 0.0  # largest nodal displacement in the last full solve

    def _round(self, command: int, loads: np.ndarray | None, rows: int = 0, columns: int = 1) -> np.ndarray:
        """One round of ``command`` (SOLVE_MANY: ``columns`` loads of ``rows`` entries per block, whose sizes rank 0
        broadcasts after the command)."""
        self.stages["Update"].pop()
        self.stages["Rounds"].push()
        started = time.perf_counter()
        self.exchange.command(command)
        if command == SOLVE_MANY:
            self.exchange.command(rows)
            self.exchange.command(columns)
        local = None
        if loads is not None:
            local = self.exchange.scatter(loads, load_width(command, self.trace_size, rows, columns))
        width = result_width(command, self.trace_size, rows, columns)
        results = self.exchange.gather(self.server.run(command, local, width, columns), width + 1)
        self.count += 1
        if np.any(results[:, -1] != 0.0):
            self.exchange.command(REPORT_ERROR)
            messages = self.exchange.comm.gather(self.server.error, root=0)
            raise SolverError(next(m for m in messages if m))
        self.elapsed += time.perf_counter() - started
        self.stages["Rounds"].pop()
        self.stages["Update"].push()
        return results[:, :-1]

    def solve(self, loads: np.ndarray, full: bool, held: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        if held is not None and self.floating:  # floating blocks take their traces, the others their loads
            results = self._round(SOLVE_HELD, np.hstack([loads, held]))
        else:
            results = self._round(SOLVE_FULL if full else SOLVE_LOAD, loads)
        trace = self.trace_size
        self.work = results[:, trace + 1]
        if full:
            self.residuals, self.largest = results[:, trace + 2], float(results[:, trace + 3].max())
        return results[:, :trace], results[:, trace]

    def solve_many(self, loads: list[np.ndarray]) -> list[np.ndarray]:
        """Per block the traces ``(2k, m_b)`` of its solves with its trace loads ``(2k, m_b)``, in one round (a
        multi-column solve per block).  A round carries per block its entries of the trace only, as many as the
        largest block holds, and the widest block's columns; the rest is padding, which is not solved."""
        rows, columns = max(len(entries) for entries in self.entries), max(load.shape[1] for load in loads)
        out = [np.zeros_like(load) for load in loads]
        if columns == 0:
            return out
        packed = np.zeros((len(loads), rows, columns))
        for block, (load, entries) in enumerate(zip(loads, self.entries)):
            packed[block, :len(entries), :load.shape[1]] = load[entries]
        results = self._round(SOLVE_MANY, packed.reshape(len(loads), -1), rows, columns)
        results = results.reshape(len(loads), rows, columns)
        for block, (traces, entries) in enumerate(zip(out, self.entries)):
            traces[entries] = results[block, :len(entries), :traces.shape[1]]
        return out

    def potential_energy(self, energies: np.ndarray) -> float:
        """Π = Σ_b ½ x_bᵀ K_b x_b − (f_bᵀ x_b − c_b) of the last full solve, whose energies are given
        (c_b: the block's energy offset, :class:`~ddsolve.fem.assembly.BlockSystem`)."""
        return float(0.5 * energies.sum() - self.work.sum())

    def schur_complements(self) -> np.ndarray:
        complements = self._round(SCHUR, None).reshape(-1, self.trace_size, self.trace_size)
        self.schur_bytes = complements.nbytes
        return complements

    def dirichlet(self, traces: np.ndarray) -> np.ndarray:
        return self._round(DIRICHLET, traces)[:, :self.trace_size]

    def lumped(self, traces: np.ndarray) -> np.ndarray:
        if self.trace_stiffness is None:
            raise SolverError("feti's lumped preconditioner needs the blocks' stiffness on their traces, which this "
                              "structure's driver does not gather: solver.preconditioner = dirichlet")
        return np.array([stiffness @ trace for stiffness, trace in zip(self.trace_stiffness, traces)])

    def trace_diagonals(self) -> np.ndarray:
        return self._round(DIAGONAL, None)[:, :self.trace_size]

    def condensed_loads(self, schur_complements: np.ndarray) -> np.ndarray:
        uncoupled = self._round(CONDENSED, None)[:, :self.trace_size]
        invertible = [b for b in range(self.exchange.n_blocks) if b not in self.floating]
        uncoupled[invertible] = np.einsum("bij,bj->bi", schur_complements[invertible], uncoupled[invertible])
        return uncoupled

    def kernel_work(self) -> list[np.ndarray]:
        work = self._round(KERNEL_WORK, None)
        return [row[:kernel.shape[1]] for row, kernel in zip(work, self.kernel_traces)]

    def stop(self) -> None:
        self.exchange.command(STOP)


def serve(exchange: Exchange, server: BlockServer, trace_size: int, stages: dict) -> None:
    """Worker loop: answer rank 0's rounds until it says STOP."""
    stages["Rounds"].push()
    while True:
        command = exchange.command()
        if command == STOP:
            break
        if command == REPORT_ERROR:
            exchange.comm.gather(server.error, root=0)
            continue
        rows, columns = (exchange.command(), exchange.command()) if command == SOLVE_MANY else (0, 1)
        local = exchange.scatter(None, load_width(command, trace_size, rows, columns)) if command in WITH_LOADS else None
        width = result_width(command, trace_size, rows, columns)
        exchange.gather(server.run(command, local, width, columns), width + 1)
    stages["Rounds"].pop()


def kernel_traces(mesh) -> list[np.ndarray] | None:
    """The traces of the blocks' kernels of a :class:`~ddsolve.parallel.distribution.LocalMesh` (None
    when they are unknown)."""
    if mesh.kernels is None:
        return None
    modes = kernels.trace_modes(mesh.sigma, mesh.kernels.frame)
    return [modes @ kernel for kernel in mesh.kernels.kernels]


def drive(setup, server: BlockServer, work) -> tuple[object, ParallelRounds | None, DDSolveError | None]:
    """Rank 0 runs ``work(rounds)`` (its time between rounds is the Update stage) while the other
    ranks serve rounds; rank 0 always sends STOP, so an error there cannot leave the others waiting.
    Returns (value, rounds, error) on rank 0 and (None, None, None) elsewhere."""
    exchange, stages = setup.exchange, setup.stages
    if not exchange.is_root:
        serve(exchange, server, setup.interface.trace_size, stages)
        return None, None, None
    rounds = ParallelRounds(exchange, server, setup.interface.trace_size, stages, setup.kernel_traces(),
                            setup.trace_stiffness, setup.trace_entries())
    value, failure = None, None
    stages["Update"].push()
    try:
        value = work(rounds)
    except DDSolveError as exc:
        failure = exc
    finally:
        stages["Update"].pop()
    rounds.stop()
    return value, rounds, failure
