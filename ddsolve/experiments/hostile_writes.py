"""Issue 21, classes 5 and 8 (writes): interrupted writes and outputs that name an input.

``python -m ddsolve.experiments.hostile_writes [solve|sweep] [COUNT]`` prints the outcome of SIGTERM at
COUNT (20) evenly spaced moments of a P = 400 solve on 4 ranks (or of a sweep): every time, either the
complete new result set with exit 0 or the complete previous one, byte-identical, with a non-zero exit.
:func:`measure` adds these outcomes and the ``-o INPUT`` cases to docs/robustness.md.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

#: The mesh of the interrupted solves (P = 400, M = 512).
LARGE = ["--set", "mesh.sigma_vertices=400", "--set", "mesh.boundary_vertices=512"]
SMALL = ["--set", "mesh.sigma_vertices=13", "--set", "mesh.boundary_vertices=32"]
#: A sweep of three load levels (one mesh, one factorization).
SWEEP = ["--set", "loads.layer1.top.y=0.05:0.15:3"]


def result_set(folder: Path, stem: str) -> list[Path]:
    """The files of the result set ``folder/stem.h5``: the HDF5 file and its viewer files."""
    from ..export import viewer_paths

    return [folder / f"{stem}.h5", *viewer_paths(folder, stem)]


@dataclass
class Outcome:
    """One interrupted run: when the signal came, the exit status, and which set the folder holds."""

    moment: float
    status: int
    state: str  # "new", "old" or "mixed: ..."
    scratch: int  # temporary files left

    @property
    def good(self) -> bool:
        return self.scratch == 0 and ((self.state == "new" and self.status == 0)
                                      or (self.state == "old" and self.status != 0))

    def __str__(self) -> str:
        return (f"SIGTERM at {self.moment:6.2f} s: exit {self.status:3d}, {self.state} set"
                + (f", {self.scratch} temporary files left" if self.scratch else "") + ("" if self.good else "  BAD"))


def state_of(paths: list[Path], previous: dict[Path, bytes]) -> str:
    """"old" if every file is byte-identical to ``previous``, "new" if every one exists and differs
    from it, otherwise which files are which."""
    same = [p for p in paths if p.is_file() and p.read_bytes() == previous.get(p)]
    changed = [p for p in paths if p.is_file() and p.read_bytes() != previous.get(p)]
    if len(same) == len(paths):
        return "old"
    if len(changed) == len(paths):
        return "new"
    missing = [p for p in paths if not p.is_file()]
    return ("mixed: new " + ", ".join(p.name for p in changed) + "; old " + ", ".join(p.name for p in same)
            + "; missing " + ", ".join(p.name for p in missing))


def _environment() -> dict:
    return {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
            "OMPI_MCA_rmaps_base_oversubscribe": "1", **os.environ,
            "PYTHONPATH": str(Path(__file__).resolve().parents[2])}


def interrupted(arguments: list[str], folder: Path, paths: list[Path], count: int = 20,
                timeout: float = 600, signum: int = signal.SIGTERM) -> list[Outcome]:
    """Run ``ddsolve ARGUMENTS`` in ``folder`` once to time it, then ``count`` times with ``signum`` sent
    to the launcher at evenly spaced moments of that time (from 1/(count+1) to count/(count+1) of it),
    each time over a previous set of placeholder files ``paths``; returns the outcomes."""
    command = [sys.executable, "-m", "ddsolve", *arguments]
    started = time.perf_counter()
    subprocess.run(command, cwd=folder, env=_environment(), stdin=subprocess.DEVNULL, capture_output=True,
                   timeout=timeout, check=True)
    duration = time.perf_counter() - started
    outcomes = []
    for i in range(1, count + 1):
        previous = {path: f"previous {path.name} {i}".encode() for path in paths}
        for path, data in previous.items():
            path.write_bytes(data)
        moment = duration * i / (count + 1)
        process = subprocess.Popen(command, cwd=folder, env=_environment(), stdin=subprocess.DEVNULL,
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            process.wait(timeout=moment)
        except subprocess.TimeoutExpired:
            process.send_signal(signum)
        try:
            status = process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            status = process.wait()
        scratch = len([p for p in folder.iterdir() if ".ddsolve~" in p.name])
        outcomes.append(Outcome(moment, status, state_of(paths, previous), scratch))
    return outcomes


def solve_moments(folder: Path, count: int = 20, mesh: list[str] = LARGE) -> list[Outcome]:
    """SIGTERM at ``count`` moments of ``solve -n 4 partial-closure`` (P = 400 by default)."""
    return interrupted(["solve", "-n", "4", "partial-closure", *mesh, "-o", "w.h5"], folder,
                       result_set(folder, "w"), count)


def sweep_moments(folder: Path, count: int = 20, mesh: list[str] = LARGE) -> list[Outcome]:
    """SIGTERM at ``count`` moments of a sweep of three loads on 4 ranks."""
    return interrupted(["sweep", "-n", "4", "partial-closure", *mesh, *SWEEP, "-o", "s.h5"], folder,
                       [folder / "s.h5"], count)


def summary(outcomes: list[Outcome]) -> str:
    new = sum(o.state == "new" and o.good for o in outcomes)
    old = sum(o.state == "old" and o.good for o in outcomes)
    bad = [o for o in outcomes if not o.good]
    return (f"{len(outcomes)} moments: {new} complete new set with exit 0, {old} previous set kept "
            f"(byte-identical) with a non-zero exit, {len(bad)} other"
            + (" (" + "; ".join(str(o).strip() for o in bad[:3]) + ")" if bad else ""))


if __name__ == "__main__":
    import tempfile

    which = sys.argv[1] if len(sys.argv) > 1 else "solve"
    with tempfile.TemporaryDirectory() as scratch:
        results = (sweep_moments if which == "sweep" else solve_moments)(
            Path(scratch), int(sys.argv[2]) if len(sys.argv) > 2 else 20)
    for outcome in results:
        print(outcome)
    print(summary(results))
