"""Contact over long zones (``./run bench contact``): every method's solve phase against the length of Σ
in contact, on the ENF (its upper half held only through Σ), the ELS and a clamped strip whose crack a top
traction presses shut, with the active-set steps or iterations; and the acceptance cases of the issue
(the ENF and the strip at full size: the default method against the reference and against the same
structure with the crack faces free).  Every run is a launch of ``ddsolve solve -n 2`` (or ``ddsolve
reference``) in turn, so the times are side by side; the answers are compared with the reference's.
Writes results/bench-contact.h5, docs/methods.md (section ``bench-contact``) and docs/bench-contact.png.
"""
from __future__ import annotations

import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ddsolve.dd import registry
from ddsolve.errors import DDSolveError
from experiments import ROOT, report
from experiments.delamination import ARM, LAYERS, LOAD, LOAD_WIDTH, Case, strip_geo

RESULTS, DOCS = Path("results"), Path("docs")
RANKS = 2
#: The ENF of the issue: span 50, arms h = 1, a pin and a roller on 0.02-long pieces of the bottom at its
#: ends (the upper half touches no support: held only through Σ), the load on 0.2 of the top at midspan.
ENF_SPAN, SUPPORT = 50.0, 0.02
#: The closed strip: 20 long, 1 thick (Σ its mid-line), clamped at both ends, a top traction pressing a
#: centred crack shut.
STRIP_LENGTH, STRIP_HALF, STRIP_TRACTION = 20.0, 0.5, -1e-3
#: The sweep: crack lengths per specimen and the graded P2 element size.
SWEEP = {"ENF": (6.25, 12.5, 18.75), "ELS": (5.0, 10.0, 15.0), "closed strip": (4.0, 8.0, 12.0, 16.0)}
SWEEP_SIZE = {"ENF": 0.2, "ELS": 0.2, "closed strip": 0.1}
#: The acceptance cases: (specimen, crack length, element size).
ACCEPTANCE = (("ENF", 12.5, 0.1), ("closed strip", 16.0, 0.05))
#: Exit statuses a launch may end with and still be measured: 0 (converged), 3 (not converged).
MEASURED_EXITS = (0, 3)
#: The iterative methods' iteration limit in the sweep (their default tolerances; uzawa with its automatic step).
MAX_ITERATIONS = 5000


def enf_text(a: float, size: float, geo: str) -> str:
    materials = "".join(f"[materials.{layer}]\nE = {E!r}\nnu = {nu!r}\n"
                        for layer, (E, nu) in zip(("layer1", "layer2"), LAYERS["identical"]))
    supports = "".join(f"[displacements.{layer}.pin]\nx = 0.0\ny = 0.0\n[displacements.{layer}.roller]\ny = 0.0\n"
                       f"[loads.{layer}.load]\ny = {-LOAD / (2.0 * LOAD_WIDTH)!r}\n" for layer in ("layer1", "layer2"))
    return (f'title = "ENF, span {ENF_SPAN:g}, a = {a:g}, the upper half held only through Sigma"\n'
            f'[mesh]\nfile = "{geo}"\nsize = {size!r}\ndegree = 2\ngrading = true\n{materials}{supports}')


def strip_text(crack: float, size: float) -> str:
    start = 0.5 * (STRIP_LENGTH - crack)
    loads = "".join(f"[loads.{layer}.top]\ny = {STRIP_TRACTION!r}\n" for layer in ("layer1", "layer2"))
    materials = "".join(f"[materials.{layer}]\nE = {E!r}\nnu = {nu!r}\n"
                        for layer, (E, nu) in zip(("layer1", "layer2"), LAYERS["identical"]))
    return (f'title = "A strip clamped at both ends, its crack of {crack:g} pressed shut"\n'
            f"[geometry]\nbox = [0.0, {STRIP_LENGTH!r}, {-STRIP_HALF!r}, {STRIP_HALF!r}]\nsigma = 0.0\n"
            f'crack = [{start!r}, {start + crack!r}]\nclamped = ["left", "right"]\n'
            f"[mesh]\nsize = {size!r}\ndegree = 2\n{materials}{loads}")


def scene_file(folder: Path, specimen: str, crack: float, size: float, free: bool = False) -> Path:
    """Write the scene (and its .geo) of ``specimen`` with a crack of length ``crack``; ``free``: the crack
    faces without non-penetration (the same structure, linear)."""
    name = f"{specimen.replace(' ', '-')}-{crack:g}-{size:g}{'-free' if free else ''}"
    if specimen == "ENF":
        pieces = {"pin": [("bottom", 0.0, SUPPORT)], "roller": [("bottom", ENF_SPAN - SUPPORT, ENF_SPAN)],
                  "load": [("top", 0.5 * (ENF_SPAN - LOAD_WIDTH), 0.5 * (ENF_SPAN + LOAD_WIDTH))]}
        (folder / f"{name}.geo").write_text(strip_geo(ENF_SPAN, ARM, [(0.0, crack)], pieces))
        text = enf_text(crack, size, f"{name}.geo")
    elif specimen == "ELS":
        case = Case("ELS", "identical", crack, size=size)
        (folder / f"{name}.geo").write_text(case.geo())
        text = case.text(f"{name}.geo")
    else:
        text = strip_text(crack, size)
    path = folder / f"{name}.toml"
    path.write_text(text + ("[contact]\nnonpenetration = false\n" if free else ""))
    return path


def launch(arguments: list[str], ranks: int | None) -> tuple[int, float]:
    """Run ``ddsolve ARGUMENTS`` on ``ranks`` ranks (None: one process, no mpiexec, as a user runs the
    reference): its exit status and the whole launch's wall seconds."""
    import sys

    from ddsolve.parallel.launch import mpiexec_command

    command = mpiexec_command(ranks, arguments, "ddsolve") if ranks else [sys.executable, "-m", "ddsolve", *arguments]
    started = time.perf_counter()
    completed = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
    elapsed = time.perf_counter() - started
    if completed.returncode not in MEASURED_EXITS:
        raise DDSolveError(f"{' '.join(arguments)}: exit {completed.returncode}: {(completed.stderr or completed.stdout).strip()[-300:]}")
    return completed.returncode, elapsed


@dataclass
class Run:
    specimen: str
    crack: float
    size: float
    method: str
    converged: bool
    solve_phase: float  # s: factorization and iterations (the reference: its whole solve)
    launch: float  # s: the whole launch, from the parent
    iterations: int
    active_set_steps: int
    rounds: int
    unknowns: int
    contact_length: float  # Σ in contact (the reference's): arc length of its contact zones
    energy_error: float  # against the reference (energy norm, relative)


def contact_length(result) -> float:
    """The length of Σ where the crack faces touch (the runs of :func:`ddsolve.post.analysis.contact_zones`)."""
    from ddsolve.post import analysis

    arclength = result.mesh.sigma.arclength[result.multiplier_nodes]
    return float(sum(arclength[last] - arclength[first] for first, last in analysis.contact_zones(result)))


def measure(scene: Path, specimen: str, crack: float, size: float, methods: list[str]) -> list[Run]:
    """The reference, then every method of ``methods`` on :data:`RANKS` ranks, on one scene."""
    from ddsolve.io import hdf5
    from ddsolve.post import analysis

    output = scene.with_suffix(".reference.h5")
    _, elapsed = launch(["reference", str(scene), "-o", str(output)], None)
    reference = hdf5.read(output)
    length = contact_length(reference)
    unknowns = sum(2 * len(half.points) for half in (reference.lower, reference.upper)) * 2
    runs = [Run(specimen, crack, size, "reference", reference.converged, reference.wall_time, elapsed,
                reference.iterations, reference.iterations, reference.solves, unknowns, length, 0.0)]
    for method in methods:
        output = scene.with_suffix(f".{method}.h5")
        settings = [f"solver.method={method}"]
        settings += [f"solver.max_iterations={MAX_ITERATIONS}"] if method in registry.iterating_methods() else []
        settings += ["solver.theta=auto"] if method in registry.stepping_methods() else []
        status, elapsed = launch(["solve", str(scene), *(f"--set={setting}" for setting in settings), "-o", str(output)],
                                 RANKS)
        result = hdf5.read(output)
        runs.append(Run(specimen, crack, size, result.method, status == 0 and result.converged, result.wall_time,
                        elapsed, result.iterations, int(result.attrs.get("active_set_steps", 0)), result.solves,
                        unknowns, length, analysis.compare(result, reference).energy_error))
        print(f"  {method:9s} {runs[-1].solve_phase:8.2f} s  {runs[-1].iterations:6d} iterations  "
              f"error {runs[-1].energy_error:.1e}", flush=True)
    return runs


def methods_for(specimen: str) -> list[str]:
    """Every method that can solve the specimen (the ENF's floating half: those that solve floating blocks)."""
    return registry.floating_methods() if specimen == "ENF" else list(registry.METHODS)


def sweep(folder: Path) -> list[Run]:
    runs = []
    for specimen, cracks in SWEEP.items():
        for crack in cracks:
            print(f"{specimen}, crack {crack:g}, size {SWEEP_SIZE[specimen]:g}:", flush=True)
            scene = scene_file(folder, specimen, crack, SWEEP_SIZE[specimen])
            runs += measure(scene, specimen, crack, SWEEP_SIZE[specimen], methods_for(specimen))
    return runs


def acceptance(folder: Path) -> list[dict]:
    """The issue's two cases at full size: the default method with contact and with the faces free, and the
    reference, each launched in turn (default, free, reference, default, free)."""
    from ddsolve.io import hdf5
    from ddsolve.post import analysis

    rows = []
    for specimen, crack, size in ACCEPTANCE:
        scene, free = scene_file(folder, specimen, crack, size), scene_file(folder, specimen, crack, size, free=True)
        print(f"acceptance: {specimen}, crack {crack:g}, size {size:g}", flush=True)
        times: dict[str, list[tuple[float, float]]] = {"contact": [], "free": [], "reference": []}
        for label, arguments, ranks in (("contact", ["solve", str(scene)], RANKS), ("free", ["solve", str(free)], RANKS),
                                        ("reference", ["reference", str(scene)], None), ("contact", ["solve", str(scene)], RANKS),
                                        ("free", ["solve", str(free)], RANKS)):
            output = folder / f"{scene.stem}.{label}.h5"
            _, elapsed = launch([*arguments, "-o", str(output)], ranks)
            times[label].append((hdf5.read(output).wall_time, elapsed))
        result, reference = (hdf5.read(folder / f"{scene.stem}.{label}.h5") for label in ("contact", "reference"))
        best = {label: (min(t for t, _ in pairs), min(w for _, w in pairs)) for label, pairs in times.items()}
        rows.append({"specimen": specimen, "crack": crack, "size": size, "method": result.method,
                     "steps": int(result.attrs.get("active_set_steps", 0)),
                     "contact_length": contact_length(reference),
                     "error": analysis.compare(result, reference).energy_error,
                     **{f"{label}_solve": solve for label, (solve, _) in best.items()},
                     **{f"{label}_launch": whole for label, (_, whole) in best.items()}})
    return rows


def table(runs: list[Run], rows: list[dict]) -> str:
    lines = ["Measured by `./run bench contact` (2 ranks; the reference in one process; each run a launch of its own, "
             "one after another). Solve phase: the factorizations and the iterations (the reference: its whole solve); "
             f"error: relative energy-norm difference from the reference. The iterative methods stop at their default "
             f"tolerances or {MAX_ITERATIONS} iterations (uzawa with `solver.theta = \"auto\"`).", "",
             "| specimen | crack | unknowns | Σ in contact | method | solve phase (s) | launch (s) | iterations | "
             "active-set steps | rounds | error |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {r.specimen} | {r.crack:g} | {r.unknowns:,} | {r.contact_length:.2f} | {r.method}"
              f"{'' if r.converged else ' (not converged)'} | {r.solve_phase:.2f} | {r.launch:.2f} | {r.iterations} | "
              f"{r.active_set_steps or ''} | {r.rounds} | {r.energy_error:.1e} |" for r in runs]
    lines += ["", "The issue's cases at full size (best of the launches in turn: default, free, reference, default, "
              "free):", "", "| case | default method | active-set steps | Σ in contact | solve phase, contact (s) | "
              "solve phase, faces free (s) | contact / free | reference solve (s) | default / reference (solve) | "
              "launches: default / reference | error |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {row['specimen']}, crack {row['crack']:g}, size {row['size']:g} | {row['method']} | {row['steps']} | "
              f"{row['contact_length']:.2f} | {row['contact_solve']:.2f} | {row['free_solve']:.2f} | "
              f"{row['contact_solve'] / row['free_solve']:.2f} | {row['reference_solve']:.2f} | "
              f"{row['contact_solve'] / row['reference_solve']:.2f} | "
              f"{row['contact_launch'] / row['reference_launch']:.2f} | {row['error']:.1e} |" for row in rows]
    return "\n".join(lines + ["", "![time against the length in contact](bench-contact.png)"])


def plot(runs: list[Run], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    specimens = list(SWEEP)
    figure, axes = plt.subplots(1, len(specimens), figsize=(5 * len(specimens), 4), squeeze=False)
    for axis, specimen in zip(axes[0], specimens):
        mine = [r for r in runs if r.specimen == specimen]
        for method in dict.fromkeys(r.method for r in mine):
            points = sorted((r.contact_length, r.solve_phase, r.converged, r.energy_error) for r in mine
                            if r.method == method)
            worst = max(error for *_, error in points)
            axis.plot([p[0] for p in points], [p[1] for p in points], "o-",
                      label=f"{method} (error ≤ {worst:.0e})" if method != "reference" else method)
            axis.plot([p[0] for p in points if not p[2]], [p[1] for p in points if not p[2]], "kx", ms=10)
        axis.set_yscale("log")
        axis.set_xlabel("length of Σ in contact")
        axis.set_ylabel("solve phase (s)")
        axis.set_title(f"{specimen} (P2, size {SWEEP_SIZE[specimen]:g}, {RANKS} ranks)")
        axis.grid(True, which="both", alpha=0.3)
        axis.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def contact(output: Path = RESULTS / "bench-contact.h5", docs: Path = DOCS) -> list[Run]:
    """The sweep and the acceptance cases; the record, the page section and the picture."""
    from dataclasses import asdict

    from ddsolve.parallel.launch import provenance

    with tempfile.TemporaryDirectory(prefix="bench-contact-") as scratch:
        folder = Path(scratch)
        runs = sweep(folder)
        rows = acceptance(folder)
    output.parent.mkdir(parents=True, exist_ok=True)
    report.write_records(output, [asdict(run) for run in runs] + rows, provenance())
    plot(runs, docs / "bench-contact.png")
    report.section(docs / "methods.md", "bench-contact", table(runs, rows))
    return runs
