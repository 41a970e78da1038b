"""Accuracy against the continuous solution: uniform (the paper's family), graded and adaptive meshes,
P1 and P2, on Example 1 (partial-closure), Example 2 (full-opening) and the linear problem.

The exact energy Π(u) of each scene is extrapolated from the finest graded P2 meshes (Π(u_h) decreases
to Π(u) for these conforming approximations); the relative energy-norm error of a discrete solution is
then sqrt((Π(u_h) − Π(u)) / (−Π(u))), since ‖u − u_h‖²_E = 2(Π(u_h) − Π(u)) and ‖u‖²_E = −2Π(u).
Every family is one 4-rank launch per scene (``accuracy-family``); the acceptance launches are whole
``ddsolve solve`` runs, timed from the command to the written file.  Writes ``results/accuracy.h5``,
the accuracy section of ``docs/results.md`` and ``docs/accuracy.png``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from experiments import report
from ddsolve.parallel import distribution
from ddsolve.post.analysis import energy_error

RESULTS = Path("results")
DOCS = Path("docs")
RANKS = 4
SCENES = {"partial-closure": "Example 1", "full-opening": "Example 2", "linear": "linear problem"}
#: The paper's (P, M) meshes, per degree.
UNIFORM = {1: ((24, 48), (48, 80), (96, 144), (200, 256), (400, 512)), 2: ((24, 48), (48, 80), (96, 144), (200, 256))}
#: mesh.size H of the graded meshes, per degree (the finest P2 ones fix Π(u)).
GRADED = {1: (0.2, 0.1, 0.05, 0.025, 0.0125), 2: (0.2, 0.1, 0.05, 0.035, 0.025, 0.0177)}
#: (initial mesh.size, mesh.target_error) of the adaptive runs, per degree.
ADAPTIVE = {1: (0.2, 0.02), 2: (0.2, 0.001)}
FAMILIES = (("uniform", 1), ("uniform", 2), ("graded", 1), ("graded", 2), ("adaptive", 1), ("adaptive", 2))
TARGETS = (0.1, 0.01, 0.001)
#: Levels with fewer unknowns do not enter the rate fits; the second rate starts where every family
#: (the adaptive ones start from coarse uniform meshes) is past its start-up.
RATE_FROM = 5000
ASYMPTOTIC_FROM = 30000
#: A level's error is measured when its error² exceeds this many times the uncertainty of Π(u)
#: (relative): the uncertainty then moves the error by less than 5 %.
MEASURABLE = 10.0
#: The acceptance launches aim at this fraction of each target (graded P2, size from the measured fit).
AIM = 0.8


def _quiet(_line: str) -> None:
    pass


def _overrides(family: str, degree: int, level) -> list[str]:
    if family == "uniform":
        P, M = level
        return [f"mesh.sigma_vertices={P}", f"mesh.boundary_vertices={M}", f"mesh.degree={degree}"]
    size, target = (level, None) if family == "graded" else ADAPTIVE[degree]
    return [f"mesh.size={size}", f"mesh.degree={degree}"] + (
        ["mesh.grading=true"] if family == "graded" else [f"mesh.target_error={target}", "mesh.grading=false"])


def unknowns(mesh) -> int:
    """Displacement unknowns of the four blocks."""
    return 4 * (len(mesh.lower.points) + len(mesh.upper.points))


# --- inside the MPI launch ------------------------------------------------------------------
def family_run(scene_name: str, family: str, degree: int, output: Path, comm) -> None:
    """Every level of one family on one scene; a JSON record per level on rank 0."""
    from ddsolve.parallel.launch import provenance
    from ddsolve.problem import scene as scenes
    from ddsolve.solvers import adapt, driver

    def say(line: str) -> None:
        if comm.rank == 0:
            print(f"  {scene_name} {family} P{degree}: {line}", flush=True)

    # Warm up (imports, gmsh, the factorization path) so that the first level's time is its own.
    driver.solve_decomposed(scenes.load(scene_name, _overrides("graded", degree, 0.5)), comm, None, progress=_quiet)
    rows = []
    if family == "adaptive":
        started = time.perf_counter()
        result = adapt.solve_adaptively(scenes.load(scene_name, _overrides(family, degree, None)), comm, None, progress=say)
        if comm.rank == 0:
            levels = result.levels
            for i in range(len(levels["unknowns"])):
                rows.append({"unknowns": int(levels["unknowns"][i]), "energy": float(levels["energy"][i]),
                             "estimate": float(levels["error_estimate"][i]), "mesh_time": float(levels["mesh_time"][i]),
                             "solve_time": float(levels["solve_time"][i]), "time": float(levels["elapsed"][i])})
            rows[-1]["total"] = time.perf_counter() - started
    else:
        for level in (UNIFORM if family == "uniform" else GRADED)[degree]:
            scene = scenes.load(scene_name, _overrides(family, degree, level))
            comm.Barrier()
            started = time.perf_counter()
            mesh = distribution.build_mesh(scene, comm)
            meshed = time.perf_counter() - started
            result = driver.solve_decomposed(scene, comm, None, progress=_quiet, mesh=mesh)
            elapsed = time.perf_counter() - started
            if comm.rank == 0:
                t = result.timings
                rows.append({"level": list(level) if isinstance(level, tuple) else level,
                             "unknowns": unknowns(mesh), "energy": float(result.attrs["energy"]),
                             "estimate": float(result.attrs["error_estimate"]), "mesh_time": meshed,
                             "setup_time": t["setup"], "solve_time": result.wall_time,
                             "estimate_time": t["estimate"], "time": elapsed})
                say(f"{rows[-1]['unknowns']:,} unknowns, estimate {100 * rows[-1]['estimate']:.3g} %, "
                    f"{elapsed:.2f} s (solve {result.wall_time:.2f} s, estimate {t['estimate']:.2f} s)")
    if comm.rank == 0:
        output.write_text(json.dumps({"scene": scene_name, "family": family, "degree": degree, "rows": rows,
                                      "provenance": provenance()}))


# --- the exact energy, errors, rates ----------------------------------------------------------
def extrapolate(unknowns: np.ndarray, energies: np.ndarray) -> tuple[float, float, float]:
    """Π(u) from the three finest levels of one family: Π_h = Π + C N^(−α) through the three points.

    Returns (Π, α, uncertainty): the uncertainty is the distance to the two-point extrapolation with
    the α of the optimal P2 rate (α = 2: error² ∝ N^(−2)).
    """
    n, e = np.asarray(unknowns[-3:], dtype=float), np.asarray(energies[-3:], dtype=float)
    ratio = (e[0] - e[1]) / (e[1] - e[2])

    def mismatch(alpha: float) -> float:
        return (n[0] ** -alpha - n[1] ** -alpha) / (n[1] ** -alpha - n[2] ** -alpha) - ratio

    low, high = 0.2, 6.0
    if mismatch(low) * mismatch(high) > 0:
        alpha = 2.0
    else:
        for _ in range(100):
            middle = 0.5 * (low + high)
            low, high = (middle, high) if mismatch(low) * mismatch(middle) > 0 else (low, middle)
        alpha = 0.5 * (low + high)
    coefficient = (e[1] - e[2]) / (n[1] ** -alpha - n[2] ** -alpha)
    exact = e[2] - coefficient * n[2] ** -alpha
    two_point = e[2] - (e[1] - e[2]) / ((n[2] / n[1]) ** 2 - 1.0)
    return float(exact), float(alpha), float(abs(exact - two_point))


def rate(rows: list[dict], floor: float, start: int = RATE_FROM) -> float | None:
    """−slope of log(error) against log(unknowns) over the levels with at least ``start`` unknowns whose
    error is measured (error² above ``MEASURABLE`` × the extrapolation's relative uncertainty ``floor``);
    None with fewer than two such levels."""
    used = [r for r in rows if r["unknowns"] >= start and r["error"] ** 2 > MEASURABLE * floor]
    if len(used) < 2:
        return None
    return float(-np.polyfit(np.log([r["unknowns"] for r in used]), np.log([r["error"] for r in used]), 1)[0])


# --- the experiment ---------------------------------------------------------------------------
def accuracy() -> dict:
    """Every family on every scene, the exact energies, the acceptance launches, the docs section."""
    RESULTS.mkdir(exist_ok=True)
    started = time.perf_counter()
    records = {}
    for scene_name in SCENES:
        for family, degree in FAMILIES:
            print(f"accuracy: {scene_name}, {family} P{degree} ({time.perf_counter() - started:.0f} s)", flush=True)
            records[(scene_name, family, degree)] = report.launch(
                RANKS, ["accuracy-family", scene_name, family, str(degree)],
                RESULTS / f".accuracy-{scene_name}-{family}-{degree}.json")
    exact = {}
    for scene_name in SCENES:
        rows = records[(scene_name, "graded", 2)]["rows"]
        exact[scene_name] = extrapolate(np.array([r["unknowns"] for r in rows]), np.array([r["energy"] for r in rows]))
        for (name, _, _), record in records.items():
            if name == scene_name:
                for row in record["rows"]:
                    row["error"] = energy_error(row["energy"], exact[scene_name][0])
    launches = acceptance(records, exact)
    print(f"accuracy: done in {time.perf_counter() - started:.0f} s", flush=True)
    provenance = next(iter(records.values()))["provenance"]
    report.write_records(RESULTS / "accuracy.h5", [{"scene": s, "family": f, "degree": d, "rows": r["rows"]}
                                                   for (s, f, d), r in records.items()] + launches,
                         {**provenance, **{f"exact_energy_{s}": e[0] for s, e in exact.items()}})
    plot(records, DOCS / "accuracy.png")
    report.section(DOCS / "results.md", "accuracy", text(records, exact, launches))
    return {"records": records, "exact": exact, "launches": launches}


def acceptance(records: dict, exact: dict) -> list[dict]:
    """Whole ``ddsolve solve`` launches of graded P2 aimed at 1 % and 0.1 % on every scene."""
    from ddsolve.io import hdf5

    launches = []
    for scene_name in SCENES:
        rows = [r for r in records[(scene_name, "graded", 2)]["rows"] if r["unknowns"] >= RATE_FROM]
        slope, intercept = np.polyfit(np.log([r["level"] for r in rows]), np.log([r["error"] for r in rows]), 1)
        for target in (0.01, 0.001):
            size = float(np.exp((np.log(AIM * target) - intercept) / slope))
            path = RESULTS / f"accuracy-{scene_name}-{target:g}.h5"
            command = ["solve", scene_name, "--set", f"mesh.size={size:.4g}", "--set", "mesh.degree=2",
                       "--set", "mesh.grading=true", "-o", str(path)]
            mark = time.perf_counter()
            report.run(RANKS, command)
            whole = time.perf_counter() - mark
            result = hdf5.read(path)
            t = result.timings
            launch = {"scene": scene_name, "target": target, "size": float(f"{size:.4g}"),
                      "command": "./run solve -n 4 " + " ".join(command[1:]),
                      "unknowns": 4 * (len(result.lower.points) + len(result.upper.points)),
                      "error": energy_error(float(result.attrs["energy"]), exact[scene_name][0]),
                      "estimate": float(result.attrs["error_estimate"]), "solve": result.wall_time,
                      "launch": whole, "setup": t["setup"], "factorization": t["factorization"],
                      "iterations": t["iterations"], "estimate_time": t["estimate"],
                      "output": t["output"] + t["write"],
                      "inside": t["setup"] + t["factorization"] + t["iterations"] + t["estimate"] + t["output"]
                      + t["write"]}
            launches.append(launch)
            print(f"accuracy: {launch['command']}: error {100 * launch['error']:.3g} % (estimate "
                  f"{100 * launch['estimate']:.3g} %), {launch['unknowns']:,} unknowns, solve phase "
                  f"{launch['solve']:.2f} s, whole launch {whole:.1f} s", flush=True)
    return launches


LABELS = {("uniform", 1): "uniform P1 (paper's family)", ("uniform", 2): "uniform P2 (paper's family)",
          ("graded", 1): "graded P1", ("graded", 2): "graded P2", ("adaptive", 1): "adaptive P1",
          ("adaptive", 2): "adaptive P2"}
STYLES = {("uniform", 1): ("tab:gray", "o", ":"), ("uniform", 2): ("black", "s", ":"),
          ("graded", 1): ("tab:blue", "o", "-"), ("graded", 2): ("tab:blue", "s", "-"),
          ("adaptive", 1): ("tab:red", "o", "--"), ("adaptive", 2): ("tab:red", "s", "--")}


def plot(records: dict, path: Path) -> None:
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    fig, axes = plt.subplots(2, len(SCENES), figsize=(16, 9), constrained_layout=True)
    for column, (scene_name, title) in enumerate(SCENES.items()):
        top, bottom = axes[0, column], axes[1, column]
        for (name, family, degree), record in records.items():
            if name != scene_name:
                continue
            rows = [r for r in record["rows"] if r["error"] > 0]
            color, marker, line = STYLES[(family, degree)]
            top.loglog([r["time"] for r in rows], [r["error"] for r in rows], color=color, marker=marker,
                       linestyle=line, label=LABELS[(family, degree)])
            bottom.loglog([r["unknowns"] for r in rows], [r["error"] for r in rows], color=color, marker=marker,
                          linestyle=line, label=LABELS[(family, degree)])
        for ax in (top, bottom):
            for target in TARGETS:
                ax.axhline(target, color="gray", linewidth=0.8, linestyle=":")
            ax.grid(alpha=0.3, which="both")
        n = np.logspace(3, 6.3)
        for power, label in ((0.25, "N^-1/4"), (0.5, "N^-1/2"), (1.0, "N^-1")):
            bottom.loglog(n, 0.3 * (n / 1e3) ** -power, color="tab:green", linewidth=0.6, alpha=0.6)
            bottom.annotate(label, (n[-1], 0.3 * (n[-1] / 1e3) ** -power), fontsize=7, color="tab:green")
        top.set_title(f"{title} ({scene_name})")
        top.set_xlabel("wall time, meshing to solution, 4 ranks (s); adaptive: all levels so far")
        bottom.set_xlabel("unknowns N")
        top.set_ylabel("relative energy-norm error")
        bottom.set_ylabel("relative energy-norm error")
    axes[0, 0].legend(fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def fastest(records: dict, scene_name: str, target: float) -> tuple[tuple, dict] | None:
    """The (family, level) of ``scene_name`` that reached ``target`` in the least time."""
    candidates = [((f, d), row) for (s, f, d), record in records.items() if s == scene_name
                  for row in record["rows"] if row["error"] <= target]
    return min(candidates, key=lambda c: c[1]["time"]) if candidates else None


def text(records: dict, exact: dict, launches: list[dict]) -> str:
    lines = [f"| scene | family | observed rate r (error ∝ N^-r), N ≥ {RATE_FROM:,} | N ≥ {ASYMPTOTIC_FROM:,} | "
             "finest: unknowns | error | estimate | effectivity (levels measured) |", "|---|---|---|---|---|---|---|---|"]
    effectivities = []
    for (scene_name, family, degree), record in records.items():
        rows = record["rows"]
        for row in rows:
            row["effectivity"] = row["estimate"] / row["error"] if row["error"] > 0 else float("nan")
        floor = exact[scene_name][2] / -exact[scene_name][0]
        observed = rate(rows, floor), rate(rows, floor, ASYMPTOTIC_FROM)
        usable = [r["effectivity"] for r in rows if r["error"] ** 2 > MEASURABLE * floor]
        effectivities += [(scene_name, family, degree, e) for e in usable]
        last = rows[-1]
        lines.append(f"| {SCENES[scene_name]} | {LABELS[(family, degree)]} | "
                     + " | ".join("—" if r is None else f"{r:.2f}" for r in observed) +
                     f" | {last['unknowns']:,} | {last['error']:.2e} | "
                     f"{last['estimate']:.2e} | {min(usable):.2f}–{max(usable):.2f} ({len(usable)} of {len(rows)}) |")
    lines += ["", "![error against wall time and unknowns](accuracy.png)", ""]
    exact_lines = ", ".join(f"{SCENES[s]} Π(u) = {e[0]:.10e} (α = {e[1]:.2f}, ±{e[2]:.1e})" for s, e in exact.items())
    lines.append(
        "Errors are against the continuous solution: the exact energy Π(u) of each scene is extrapolated from its "
        "three finest graded P2 meshes with Π(u_h) = Π(u) + C N^-α through the three points (" + exact_lines +
        "; ± is the distance to the two-point extrapolation with α = 2, the optimal P2 rate), and the relative "
        "energy-norm error is sqrt((Π(u_h) − Π(u)) / (−Π(u))), since ‖u − u_h‖²_E = 2(Π(u_h) − Π(u)) and "
        "‖u‖²_E = −2Π(u). The observed rates are least-squares slopes over the levels with at least "
        f"{RATE_FROM:,} (or {ASYMPTOTIC_FROM:,}) unknowns whose error² is above {MEASURABLE:g} times the extrapolation's relative "
        "uncertainty, so that the uncertainty moves their error by less than 5 %; levels closer to Π(u) than that "
        "(among them the finest graded P2 levels, which fix it) enter neither the rates nor the effectivities. "
        "Times are wall times inside one 4-rank launch, from meshing to the solution with its error estimate (for "
        "the adaptive families: all levels up to that one), on the shared 2-core machine.")
    worst = min(effectivities, key=lambda e: e[3]), max(effectivities, key=lambda e: e[3])
    lines.append("")
    lines.append(f"**Effectivity** (estimate / true error) over every measured level of every family and scene: "
                 f"{worst[0][3]:.2f} ({SCENES[worst[0][0]]}, {LABELS[worst[0][1:3]]}) to {worst[1][3]:.2f} "
                 f"({SCENES[worst[1][0]]}, {LABELS[worst[1][1:3]]}).")
    lines += ["", "**The fastest way to each error** (smallest wall time among all levels of all families):", "",
              "| scene | 10 % | 1 % | 0.1 % |", "|---|---|---|---|"]
    for scene_name in SCENES:
        cells = []
        for target in TARGETS:
            best = fastest(records, scene_name, target)
            cells.append("not reached" if best is None else
                         f"{LABELS[best[0]]}, {best[1]['unknowns']:,} unknowns, {best[1]['time']:.2f} s "
                         f"(error {100 * best[1]['error']:.2g} %)")
        lines.append(f"| {SCENES[scene_name]} | " + " | ".join(cells) + " |")
    lines += ["", "**Whole launches** aimed at 1 % and 0.1 % (graded P2, mesh size from the fit above), each timed "
              "from the command to the written result file:", "",
              "| command | unknowns | error | estimate | solve phase (s) | whole launch (s) | mesh + assembly | "
              "factorization | rounds | estimate | output |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for launch in launches:
        lines.append(f"| `{launch['command']}` | {launch['unknowns']:,} | {100 * launch['error']:.3g} % | "
                     f"{100 * launch['estimate']:.3g} % | {launch['solve']:.2f} | {launch['launch']:.1f} | "
                     f"{launch['setup']:.2f} | {launch['factorization']:.2f} | {launch['iterations']:.2f} | "
                     f"{launch['estimate_time']:.2f} | {launch['output']:.2f} |")
    return "\n".join(lines)
