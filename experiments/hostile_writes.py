"""Issue 21, classes 5 and 8 (writes): interrupted writes and outputs that name an input.

``python -m experiments.hostile_writes [solve|sweep] [COUNT]`` prints the outcome of SIGTERM at
COUNT (20) evenly spaced moments of a P = 400 solve on 4 ranks (or of a sweep): every time, either the
complete new result set with exit 0 or the complete previous one, byte-identical, with a non-zero exit.
:func:`measure` adds these outcomes and the ``-o INPUT`` cases to docs/robustness.md.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path

from ddsolve.io import safe
from experiments import ROOT

#: The mesh of the interrupted solves (P = 400, M = 512).
LARGE = ["--set", "mesh.sigma_vertices=400", "--set", "mesh.boundary_vertices=512"]
SMALL = ["--set", "mesh.sigma_vertices=13", "--set", "mesh.boundary_vertices=32"]
#: A sweep of three load levels (one mesh, one factorization).
SWEEP = ["--set", "loads.layer1.top.y=0.05:0.15:3"]


def result_set(folder: Path, stem: str) -> list[Path]:
    """The files of the result set ``folder/stem.h5``: the HDF5 file and its viewer files."""
    from ddsolve.io.viewer import viewer_paths

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
            "PYTHONPATH": str(ROOT)}


def interrupted(arguments: list[str], folder: Path, paths: list[Path], count: int = 20,
                timeout: float = 600, signum: int = signal.SIGTERM, progress=None) -> list[Outcome]:
    """Run ``ddsolve ARGUMENTS`` in ``folder`` once to time it, then ``count`` times with ``signum`` sent
    to the launcher at evenly spaced moments of that time (from 1/(count+1) to count/(count+1) of it),
    each time over a previous set of placeholder files ``paths``; returns the outcomes (each also
    given to ``progress`` as it comes)."""
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
        if progress is not None:
            progress(outcomes[-1])
    return outcomes


def solve_moments(folder: Path, count: int = 20, mesh: list[str] = LARGE, timeout: float = 600,
                  progress=None) -> list[Outcome]:
    """SIGTERM at ``count`` moments of ``solve -n 4 partial-closure`` (P = 400 by default)."""
    return interrupted(["solve", "-n", "4", "partial-closure", *mesh, "-o", "w.h5"], folder,
                       result_set(folder, "w"), count, timeout, progress=progress)


def sweep_moments(folder: Path, count: int = 20, mesh: list[str] = LARGE, timeout: float = 600,
                  progress=None) -> list[Outcome]:
    """SIGTERM at ``count`` moments of a sweep of three loads on 4 ranks."""
    return interrupted(["sweep", "-n", "4", "partial-closure", *mesh, *SWEEP, "-o", "s.h5"], folder,
                       [folder / "s.h5"], count, timeout, progress=progress)


#: A process that replaces ``count`` files (``existing`` of them there before) as one set and sends
#: itself ``signum`` just before file operation number ``step`` (the probe of the folder, the writes
#: of the temporaries, the journal, links, renames, removals), under ddsolve.parallel.runtime.guarded as the
#: commands are.  Arguments: FOLDER COUNT STEP SIGNUM FINAL(0/1).
COMMIT_CHILD = textwrap.dedent("""
    import os, sys
    from pathlib import Path
    from ddsolve.io import safe
    from ddsolve.parallel.runtime import guarded

    folder, count, step, signum, final = Path(sys.argv[1]), *map(int, sys.argv[2:5]), sys.argv[5] == "1"
    calls = [0]

    def counted(function):
        def wrapper(*args, **kwargs):
            calls[0] += 1
            if calls[0] == step:
                os.kill(os.getpid(), signum)
            return function(*args, **kwargs)
        return wrapper

    for name in ("replace", "link", "unlink"):
        setattr(os, name, counted(getattr(os, name)))

    def writer(i):
        return counted(lambda name: Path(name).write_bytes(f"new {i}".encode()))

    sys.exit(guarded(lambda: safe.replace_together({folder / f"f{i}.h5": writer(i) for i in range(count)},
                                                final=final) or 0))
""")


def commit_step(folder: Path, count: int, existing: int, step: int, signum: int, final: bool = True
                ) -> tuple[int, str, list[str]]:
    """Run :data:`COMMIT_CHILD` in ``folder``, then what the next run does first (:func:`ddsolve.io.safe.recover`);
    returns the child's exit status, the set's state ("new", "old" or "mixed") and the scratch files left."""

    paths = [folder / f"f{i}.h5" for i in range(count)]
    previous = {}
    for path in paths[:existing]:
        previous[path] = f"old {path.name}".encode()
        path.write_bytes(previous[path])
    child = subprocess.run([sys.executable, "-c", COMMIT_CHILD, str(folder), str(count), str(step), str(int(signum)),
                            "1" if final else "0"], capture_output=True, text=True, timeout=60,
                           env=_environment(), stdin=subprocess.DEVNULL)
    if "Traceback" in child.stderr:
        raise RuntimeError(child.stderr)
    safe.recover(paths)
    new = all(path.is_file() and path.read_bytes() == f"new {i}".encode() for i, path in enumerate(paths))
    old = all(path.read_bytes() == data for path, data in previous.items()) and \
        not any(path.exists() for path in paths[existing:])
    left = [p.name for p in folder.iterdir() if ".ddsolve~" in p.name]
    for path in folder.iterdir():
        path.unlink()
    return child.returncode, ("new" if new else "old" if old else "mixed"), left


def commit_steps(folder: Path, signum: int, steps: int = 14) -> str:
    """``signum`` before each file operation of a commit of 3 files (2 there before): what was left."""
    folder.mkdir(exist_ok=True)
    outcomes = [commit_step(folder, 3, 2, step, signum) for step in range(1, steps + 1)]
    states = {state: sum(o[1] == state for o in outcomes) for state in ("new", "old", "mixed")}
    statuses = sorted({o[0] for o in outcomes})
    return (f"{steps} moments: {states['new']} new set, {states['old']} previous set, {states['mixed']} mixed; "
            f"exit statuses {', '.join(map(str, statuses))}; {sum(bool(o[2]) for o in outcomes)} left scratch files")


def summary(outcomes: list[Outcome]) -> str:
    new = sum(o.state == "new" and o.good for o in outcomes)
    old = sum(o.state == "old" and o.good for o in outcomes)
    bad = [o for o in outcomes if not o.good]
    return (f"{len(outcomes)} moments: {new} complete new set with exit 0, {old} previous set kept "
            f"(byte-identical) with a non-zero exit, {len(bad)} other"
            + (" (" + "; ".join(str(o).strip() for o in bad[:3]) + ")" if bad else ""))


def measure(hostile) -> None:
    """Classes 5 (105) and 8 (108) of docs/robustness.md."""
    folder = hostile.folder / "writes"
    folder.mkdir(exist_ok=True)
    hostile.rows[105].append((
        "SIGTERM at 20 evenly spaced moments of solve -n 4, P = 400, M = 512 (over a previous set)",
        "18 previous set kept, exit 1; 1 new set but exit 1; 1 new set, exit 0 (the issue: also new .h5 and layers "
        "beside no Σ file and no ParaView script)", summary(solve_moments(folder))))
    hostile.rows[105].append((
        "SIGTERM at 20 evenly spaced moments of sweep -n 4, 3 loads, P = 400", BEFORE_SWEEP,
        summary(sweep_moments(folder))))
    for signum, before in ((signal.SIGKILL, BEFORE_KILL), (signal.SIGTERM, BEFORE_TERM)):
        hostile.rows[105].append((f"{signal.Signals(signum).name} before each file operation of a write of 3 files "
                                  "(2 there before), then the next run", before,
                                  commit_steps(folder / "steps", signum)))
    _outputs_over_inputs(hostile)


def _outputs_over_inputs(hostile) -> None:
    """-o naming an input (scene, .geo, mesh file) or without .h5, for every command that takes -o."""
    from ddsolve.problem import scene as scenes

    folder = hostile.folder
    (folder / "w-scene.toml").write_text(scenes.builtin_scenes()["partial-closure"])
    for name in ("arc-bond.toml", "arc-bond.geo"):
        shutil.copy(scenes.builtin_folder() / name, folder / name)
    hostile.run(["mesh", "w-scene.toml", *SMALL, "-o", "w-sq.msh"])
    materials = (folder / "w-scene.toml").read_text().split("[materials", 1)[1]
    (folder / "w-m.toml").write_text(f'title = "m"\n[mesh]\nfile = "w-sq.msh"\n[materials{materials}')
    inputs = ["w-scene.toml", "arc-bond.toml", "arc-bond.geo", "w-sq.msh", "w-m.toml"]

    def unchanged(previous: dict):
        def observe(_completed) -> str:
            changed = [name for name, data in previous.items() if (folder / name).read_bytes() != data]
            return "; inputs byte-identical" if not changed else f"; CHANGED: {', '.join(changed)}"
        return observe

    swept = ["--set", "materials.layer1.E=150:200:2"]
    for command, output, scene, before in (
            ("sweep", "w-scene.toml", "w-scene.toml", "exit 0; the scene file replaced by the sweep's HDF5 file"),
            ("sweep", "arc-bond.geo", "arc-bond.toml", "exit 0; the .geo file replaced by the sweep's HDF5 file"),
            ("sweep", "w-sq.msh", "w-m.toml", "exit 0; the mesh file replaced by the sweep's HDF5 file"),
            ("sweep", "w.txt", "w-scene.toml", "exit 0; an HDF5 file named w.txt"),
            ("solve", "arc-bond.geo", "arc-bond.toml", "exit 1: «-o arc-bond.geo: a result is an HDF5 file: give "
             "it the suffix .h5»"),
            ("reference", "w-sq.msh", "w-m.toml", "exit 1: «-o w-sq.msh: a result is an HDF5 file: give it the "
             "suffix .h5»"),
            ("mesh", "arc-bond.geo", "arc-bond.toml", "exit 1: «arc-bond.geo: is an input of this run»"),
            ("export", "w-scene.toml", "", "exit 1: «-o w-scene.toml: no such directory»")):
        mesh = [] if scene == "w-m.toml" else ["--set", "mesh.size=0.3"] if scene == "arc-bond.toml" else SMALL
        arguments = ([command, "w-result.h5", "-o", output] if command == "export" else
                     [command, scene, *mesh, *(swept if command == "sweep" else []), "-o", output])
        if command == "export" and not (folder / "w-result.h5").exists():
            hostile.run(["solve", "w-scene.toml", *SMALL, "-o", "w-result.h5"])
        previous = {name: (folder / name).read_bytes() for name in inputs}
        hostile.case(108, f"{command} -o {output}" + (f" ({scene})" if scene != output and scene else ""), before,
                     arguments, observe=unchanged(previous))


#: Measured on the code before these fixes (quoted).
BEFORE_SWEEP = ("1 previous file kept, exit 1; 11 the file replaced by the runs finished so far, exit 1; 8 after "
                "the sweep had ended, exit 0")
BEFORE_KILL = ("14 moments: 5 new set, 7 previous set, 2 mixed for good (no journal: the next run "
               "does not complete it)")
BEFORE_TERM = "14 moments: 10 new set, 7 of them with exit 143; 4 previous set, exit 143"


if __name__ == "__main__":
    import tempfile

    which = sys.argv[1] if len(sys.argv) > 1 else "solve"
    with tempfile.TemporaryDirectory() as scratch:
        results = (sweep_moments if which == "sweep" else solve_moments)(
            Path(scratch), int(sys.argv[2]) if len(sys.argv) > 2 else 20, progress=lambda o: print(o, flush=True))
    print(summary(results))
