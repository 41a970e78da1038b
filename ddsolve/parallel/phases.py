"""The phases of a launch, each timed (wall and CPU seconds) with the peak memory at its end."""
from __future__ import annotations

import os
import time

import numpy as np


def peak_memory_mb() -> float:
    """This process's peak resident memory so far, in MB."""
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # kB on Linux


#: Environment variable with the wall-clock time (time.time()) at which ``ddsolve solve -n`` started mpiexec.
LAUNCHED = "DDSOLVE_LAUNCHED"


#: The phases of a launch, in order; their sum is the whole launch (``total``).
PHASES = ("startup", "meshing", "distribution", "assembly", "factorization", "critical_factors", "iterations",
          "estimate", "output", "write")


def launch_age() -> float:
    """Seconds since the launch began: since ``ddsolve solve -n`` started mpiexec, else since this
    process started (Linux), else 0."""
    launched = os.environ.get(LAUNCHED)
    if launched:
        try:
            return max(0.0, time.time() - float(launched))
        except ValueError:
            pass
    try:
        with open("/proc/self/stat") as stat, open("/proc/uptime") as uptime:
            started = int(stat.read().rsplit(")", 1)[1].split()[19]) / os.sysconf("SC_CLK_TCK")
            return max(0.0, float(uptime.read().split()[0]) - started)
    except (OSError, ValueError, IndexError):
        return 0.0


def cpu_seconds() -> float:
    """CPU seconds of this process and of its children that ended (gmsh meshes in one), to the microsecond
    (``os.times`` counts clock ticks of 10 ms, as long as a phase of a small run)."""
    import resource

    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


#: What the memory account of a launch counts (bytes a rank holds), in the order of ``/memory``'s columns.
HELD = ("mesh", "matrices", "factors", "schur complements", "solutions")


class Phases:
    """Wall seconds (this rank's clock), CPU seconds and peak memory at the end of each phase, and the
    account of what the rank held: per phase the most bytes of each of :data:`HELD` (:meth:`hold`).  A phase
    may end several times (a step of one, then of another): its seconds add up, its account keeps the most."""

    def __init__(self, startup: float = 0.0):
        self.wall = {"startup": startup}
        self.cpu = {"startup": cpu_seconds()}
        self.peak = {"startup": peak_memory_mb()}
        self.held: dict[str, dict[str, float]] = {}
        self._holding = dict.fromkeys(HELD, 0.0)
        self._most = dict(self._holding)
        self._wall, self._cpu = time.perf_counter(), cpu_seconds()

    def hold(self, what: str, nbytes: float) -> None:
        """This rank now holds ``nbytes`` of ``what`` (one of :data:`HELD`; 0 once dropped)."""
        self._holding[what] = float(nbytes)
        self._most[what] = max(self._most[what], float(nbytes))

    def end(self, name: str) -> None:
        wall, cpu = time.perf_counter(), cpu_seconds()
        self.wall[name] = self.wall.get(name, 0.0) + wall - self._wall
        self.cpu[name] = self.cpu.get(name, 0.0) + cpu - self._cpu
        self.peak[name] = peak_memory_mb()
        before = self.held.get(name, {})
        self.held[name] = {what: max(most, before.get(what, 0.0)) for what, most in self._most.items()}
        self._most = dict(self._holding)
        self._wall, self._cpu = wall, cpu

    def move_cpu(self, seconds: float, source: str, destination: str) -> None:
        """Count ``seconds`` of phase ``source``'s CPU seconds as ``destination``'s (a child's work that ended
        in ``source`` but ran during ``destination``)."""
        moved = min(seconds, self.cpu.get(source, 0.0))
        self.cpu[source] -= moved
        self.cpu[destination] = self.cpu.get(destination, 0.0) + moved

    def skip(self, name: str) -> None:
        """Record phase ``name`` as not done (zero seconds), e.g. a factorization reused."""
        self.wall.setdefault(name, 0.0)
        self.cpu.setdefault(name, 0.0)
        self.peak[name] = peak_memory_mb()


def memory_record(ranks: list[tuple[dict, Phases]], unknowns: int, whole_mesh_bytes: int) -> dict:
    """The result file's ``/memory`` from every rank's (numbers, :class:`Phases`): per rank, the peak resident
    memory (MB) and the CPU seconds of every phase, the unknowns it works on, its mesh arrays, its factors
    (MUMPS's own count, MB) and the mesh and solution arrays it holds at output (``rank_held_bytes``, against
    ``whole_held_bytes``: the whole mesh and the four solutions); per phase the largest peak per unknown of
    a rank (bytes); and the account ``held_mb_<phase>`` ``(ranks, len(HELD))``: the most MB of each of
    :data:`HELD` (``held``) the rank held during the phase."""
    record = {"unknowns": unknowns, "whole_mesh_bytes": whole_mesh_bytes,
              "whole_held_bytes": whole_mesh_bytes + 8 * unknowns, "held": list(HELD)}
    for key in ("unknowns", "mesh_bytes", "factor_mb", "held_bytes"):
        if all(key in mine for mine, _ in ranks):
            record[f"rank_{key}"] = np.array([mine[key] for mine, _ in ranks])
    for phase in ranks[0][1].peak:
        peaks = np.array([phases.peak[phase] for _, phases in ranks])
        record[f"cpu_s_{phase}"] = np.array([phases.cpu.get(phase, 0.0) for _, phases in ranks])
        record[f"peak_mb_{phase}"] = peaks
        if phase in ranks[0][1].held:
            record[f"held_mb_{phase}"] = np.array([[phases.held[phase][what] / 2 ** 20 for what in HELD]
                                                   for _, phases in ranks])
        record[f"bytes_per_unknown_{phase}"] = float(np.max(peaks * 2 ** 20 / record["rank_unknowns"]))
    return record
