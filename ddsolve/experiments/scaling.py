"""Scaling experiments and a per-phase cost model (``ddsolve scaling``).

Strong scaling (one mesh, N = 1, 2, 4, 8 ranks) and weak scaling (unknowns per rank fixed) of the
default method and of MPRGP (many rounds: it exposes the per-round exchange), the two large meshes,
and calibration runs: one block's factorization, solve and interface-matrix times at several sizes
(one rank), and MPI latency and bandwidth (two ranks).  A cost model fitted to the calibration data
predicts every measured run (validation) and the solve phase on 64 to 1024 cores.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from . import report

RESULTS = Path("results/scaling")
DOCS = Path("docs")
STRONG_MESH = (400, 512)
RANKS = (1, 2, 4, 8)
#: Weak scaling: about 12k unknowns per block and rank (P ∝ √N).
WEAK_MESHES = {1: (100, 128), 2: (141, 181), 4: (200, 256), 8: (283, 362)}
LARGE_MESHES = ((800, 1024), (1600, 2048))
CALIBRATION_MESHES = ((100, 128), (141, 181), (200, 256), (283, 362), (400, 512))
METHODS = ("schur", "mprgp")
PREDICTED_CORES = (64, 128, 256, 512, 1024)
#: Unknowns per core in the predicted weak scaling (the block has this many times its ranks).
WEAK_UNKNOWNS_PER_CORE = 50_000


def cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


# --- calibration (inside MPI launches) ---------------------------------------------------------
def network(output: Path, comm) -> None:
    """Latency and bandwidth of the collectives a round uses, between two ranks."""
    from ..io import provenance

    sizes = [8, 800, 8_000, 80_000, 800_000, 8_000_000]
    samples = []
    for size in sizes:
        data = np.ones(size // 8)
        repeats = max(3, min(1000, 2_000_000 // size))
        comm.Barrier()
        started = time.perf_counter()
        for _ in range(repeats):
            comm.Bcast(data, root=0)
        samples.append({"bytes": size, "seconds": (time.perf_counter() - started) / repeats})
    if comm.rank == 0:
        sizes_, times = np.array([s["bytes"] for s in samples]), np.array([s["seconds"] for s in samples])
        inverse_bandwidth, latency = np.polyfit(sizes_, times, 1)
        output.write_text(json.dumps({"samples": samples, "latency": max(latency, times[0]),
                                      "bandwidth": 1.0 / inverse_bandwidth, "provenance": provenance()}))


def calibrate(output: Path, comm) -> None:
    """One block at each calibration size, on one rank: factorization, solve and interface-matrix times."""
    from .bench import block_timings

    if comm.rank == 0:
        output.write_text(json.dumps({"blocks": [block_timings(P, M, solves=10, repeats=2)
                                                 for P, M in CALIBRATION_MESHES]}))


# --- the cost model ---------------------------------------------------------------------------
def power_law(x, y) -> tuple[float, float]:
    """(a, p) with y ≈ a x^p, least squares in logs."""
    p, log_a = np.polyfit(np.log(x), np.log(y), 1)
    return float(np.exp(log_a)), float(p)


class CostModel:
    """Per-phase cost of the solve phase (factorization, interface matrices, rounds, gather, rank 0).

    Block work, per block on one rank, as power laws of its unknowns n (measured by
    ``bench.block_timings``): factorization F(n) and one solve S(n) for each path — MUMPS with the
    Schur complement on Σ (``schur`` on whole blocks), plain MUMPS (distributed blocks), PETSc's
    Cholesky (``mprgp``) — and the interface matrix: from the factorization (plus one checking solve),
    or for distributed blocks by multi-column solves with 2kΣ right-hand sides.  Four blocks of work
    W take 4W/min(N, cores).  A round costs 3 world collectives (log₂N latency steps each, 2 more per
    block when k > 1) and 2·4 trace vectors of 2kΣ doubles; ``schur`` gathers four (2kΣ)² matrices.
    Rank 0: a·nΣ^p for the dense interface solve of ``schur``, c·m per ``mprgp`` round.
    """

    def __init__(self, calibration: dict, network: dict, runs: list[dict]):
        blocks = calibration["blocks"]
        n = [b["unknowns"] for b in blocks]

        def law(path: str, item: str) -> tuple[float, float]:
            return power_law(n, [b[path][item] for b in blocks])

        self.factor = {"schur": law("mumps_schur", "factor"), "mumps": law("mumps", "factor"),
                       "mprgp": law("petsc", "factor")}
        self.solve = {"schur": law("mumps_schur", "solve"), "mumps": law("mumps", "solve"),
                      "mprgp": law("petsc", "solve")}
        self.interface = law("mumps_schur", "interface")
        self.column = power_law([b["unknowns"] * b["trace"] for b in blocks], [b["mumps"]["interface"] for b in blocks])
        self.latency, self.bandwidth = network["latency"], network["bandwidth"]
        schur = [r for r in runs if r["method"] == "schur"]
        self.rank0 = power_law([r["interface_unknowns"] for r in schur], [r["rank0_time"] for r in schur])
        mprgp = [r for r in runs if r["method"] == "mprgp"]
        self.update = float(np.median([r["update"] / (r["rounds"] * r["multipliers"]) for r in mprgp]))
        self.mprgp_rounds = power_law([r["P"] for r in mprgp], [r["rounds"] for r in mprgp])

    @staticmethod
    def _law(law: tuple[float, float], x: float) -> float:
        return law[0] * x ** law[1]

    def exchange(self, ranks: int, trace: int) -> float:
        """One round's messages: 3 world collectives plus, with k > 1, 2 within each block."""
        k = max(1, ranks // 4)
        steps = 3 * np.ceil(np.log2(max(ranks, 2))) + (2 * np.ceil(np.log2(k)) if k > 1 else 0)
        return steps * self.latency + 2 * 4 * trace * 8 / self.bandwidth

    def phases(self, method: str, ranks: int, unknowns: float, trace: int, interface: int, rounds: int,
               multipliers: int, cores: int | None = None) -> dict:
        """Predicted seconds per phase on ``ranks`` ranks sharing ``cores`` cores (default: one each).

        Four blocks of work W each, on N ranks and C cores, take 4W/min(N, C) in the ideal: whole
        blocks per rank when N ≤ 4, a block over k = N/4 ranks otherwise, ranks sharing cores when N > C.
        """
        share = 4.0 / min(ranks, cores or ranks)
        path = "mumps" if method == "schur" and ranks > 4 else method
        out = {"factorization": share * self._law(self.factor[path], unknowns), "interface": 0.0, "gather": 0.0}
        out["rounds"] = rounds * (share * self._law(self.solve[path], unknowns) + self.exchange(ranks, trace))
        if method == "schur":
            if ranks > 4:  # no parallel Schur complement: the interface matrix comes from multi-column solves
                out["interface"] = share * self._law(self.column, unknowns * trace)
            else:
                out["interface"] = share * self._law(self.interface, unknowns)
            out["gather"] = 4 * trace * trace * 8 / self.bandwidth
            out["rank0"] = self._law(self.rank0, interface)
        else:
            out["rank0"] = self.update * rounds * multipliers
        out["total"] = sum(out.values())
        return out


# --- the experiment ---------------------------------------------------------------------------
def _solve(ranks: int, P: int, M: int, method: str, name: str) -> dict:
    """One ``ddsolve solve`` launch; its result file stays in results/scaling."""
    from .. import io

    path = RESULTS / f"{name}.h5"
    report.run(ranks, ["solve", "partial-closure", "--set", f"mesh.sigma_vertices={P}",
                       "--set", f"mesh.boundary_vertices={M}", "--set", f"solver.method={method}",
                       "--set", "solver.tol=1e-6" if method == "mprgp" else "solver.tol=1e-8", "-o", str(path)])
    result = io.read(path)
    lower = result.lower
    return {"name": name, "ranks": ranks, "P": P, "M": M, "method": method, "rounds": result.solves,
            "unknowns": 2 * len(lower.points), "trace": 2 * len(result.multiplier_nodes),
            "multipliers": int(sum(v.size for v in result.multipliers.values())),
            "interface_unknowns": int(result.attrs.get("interface_unknowns", 0)),
            "rank0_time": float(result.attrs.get("rank0_solve_time", 0.0)),
            "peak_memory_mb": [float(m) for m in result.attrs["peak_memory_mb"]], "wall_time": result.wall_time,
            **{key: float(value) for key, value in result.timings.items()}}


def scaling() -> dict:
    """Calibrate, run strong, weak and large cases, fit the model; write HDF5, docs/scaling.md, plots."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    print("scaling: calibration (one block at 5 sizes; MPI latency and bandwidth)", flush=True)
    calibration = report.launch(1, ["scaling-calibrate"], RESULTS / ".calibration.json")
    net = report.launch(2, ["scaling-network"], RESULTS / ".network.json")
    runs = []
    for method in METHODS:
        for ranks in RANKS:
            print(f"scaling: strong, {method}, N = {ranks}", flush=True)
            runs.append({"kind": "strong", **_solve(ranks, *STRONG_MESH, method, f"strong-{method}-{ranks}")})
            print(f"scaling: weak, {method}, N = {ranks}", flush=True)
            runs.append({"kind": "weak", **_solve(ranks, *WEAK_MESHES[ranks], method, f"weak-{method}-{ranks}")})
    for P, M in LARGE_MESHES:
        print(f"scaling: large, P = {P}", flush=True)
        started = time.perf_counter()
        runs.append({"kind": "large", **_solve(4, P, M, "schur", f"large-{P}"), "launch": time.perf_counter() - started})
    record = {"cores": cores(), "calibration": calibration, "network": net, "runs": runs}
    (RESULTS / "record.json").write_text(json.dumps(record))
    render(record)
    return record


def render(record: dict) -> None:
    """Fit the model to a record of measurements; write results/scaling.h5, the plots and docs/scaling.md."""
    runs = record["runs"]
    model = CostModel(record["calibration"], record["network"], runs)
    for run in runs:
        run["predicted"] = model.phases(run["method"], run["ranks"], run["unknowns"], run["trace"],
                                        run["interface_unknowns"], run["rounds"], run["multipliers"],
                                        record["cores"])["total"]
    parameters = {"factor": model.factor, "solve": model.solve, "interface": model.interface, "column": model.column,
                  "latency": model.latency, "bandwidth": model.bandwidth, "rank0": model.rank0,
                  "update": model.update, "mprgp_rounds": model.mprgp_rounds}
    report.write_records(RESULTS.parent / "scaling.h5", runs, {**record["network"]["provenance"],
                                                              "cores": record["cores"], "model": json.dumps(parameters)})
    plots(runs, model)
    (DOCS / "scaling.md").write_text(text(record, model))


#: Mesh-size relations of the generated meshes (P vertices on Σ): block unknowns ≈ 0.295 P²,
#: interface unknowns of schur ≈ 3P, multipliers ≈ 3·2(P − 2).
def _at(model: CostModel, ranks: int, P: int) -> dict:
    trace = 2 * (P - 2)
    unknowns = 0.295 * P * P
    schur = model.phases("schur", ranks, unknowns, trace, 3 * P, 3, 3 * trace)
    mprgp = model.phases("mprgp", ranks, unknowns, trace, 0, round(model._law(model.mprgp_rounds, P)), 3 * trace)
    # PETSc's Cholesky is sequential: distributed blocks use MUMPS for mprgp too
    if ranks > 4:
        mprgp = {**mprgp, "factorization": model._law(model.factor["mumps"], unknowns) * 4 / ranks}
        mprgp["rounds"] = round(model._law(model.mprgp_rounds, P)) * (
            model._law(model.solve["mumps"], unknowns) * 4 / ranks + model.exchange(ranks, trace))
        mprgp["total"] = mprgp["factorization"] + mprgp["rounds"] + mprgp["rank0"]
    return {"ranks": ranks, "P": P, **schur, "mprgp": mprgp["total"]}


def predictions(model: CostModel) -> tuple[list[dict], list[dict]]:
    """Strong scaling of P = 1600 and weak scaling at WEAK_UNKNOWNS_PER_CORE, on 64 … 1024 cores."""
    strong = [_at(model, ranks, 1600) for ranks in PREDICTED_CORES]
    weak = [_at(model, ranks, int(np.sqrt(WEAK_UNKNOWNS_PER_CORE * (ranks // 4) / 0.295))) for ranks in PREDICTED_CORES]
    return strong, weak


def plots(runs: list[dict], model: CostModel) -> None:
    from ..plots import _pyplot

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    for ax, kind in zip(axes, ("strong", "weak")):
        for method, color in zip(METHODS, ("tab:blue", "tab:orange")):
            chosen = sorted((r for r in runs if r["kind"] == kind and r["method"] == method), key=lambda r: r["ranks"])
            ranks = [r["ranks"] for r in chosen]
            ax.plot(ranks, [r["factorization"] for r in chosen], marker="s", linestyle=":", color=color,
                    label=f"{method}: factorization")
            ax.plot(ranks, [r["iterations"] - r["update"] for r in chosen], marker="^", linestyle="--", color=color,
                    label=f"{method}: rounds")
            ax.plot(ranks, [r["update"] for r in chosen], marker="v", linestyle="-.", color=color,
                    label=f"{method}: rank-0 update")
            ax.plot(ranks, [r["wall_time"] for r in chosen], marker="o", color=color, label=f"{method}: solve phase")
            ax.plot(ranks, [r["predicted"] for r in chosen], marker="x", linestyle="none", color="black",
                    markersize=8, label="model" if method == METHODS[0] else None)
        ax.axvline(cores(), color="gray", linestyle=":")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel(f"ranks N (this machine: {cores()} cores)")
        ax.set_ylabel("seconds")
        ax.set_title("strong scaling, P = 400" if kind == "strong" else "weak scaling, ~12k unknowns per block·rank")
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7, ncol=2)
    fig.savefig(DOCS / "scaling-measured.png", dpi=120)
    plt.close(fig)

    strong, weak = predictions(model)
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    for ax, rows, title in zip(axes, (strong, weak), ("strong: P = 1600", f"weak: {WEAK_UNKNOWNS_PER_CORE:,} "
                                                                         "unknowns per core")):
        ranks = [r["ranks"] for r in rows]
        for phase in ("factorization", "interface", "rounds", "gather", "rank0", "total"):
            ax.plot(ranks, [max(r[phase], 1e-4) for r in rows], marker="o", label=f"schur: {phase}",
                    linewidth=2.5 if phase == "total" else 1.2)
        ax.plot(ranks, [r["mprgp"] for r in rows], marker="s", color="black", linestyle="--", label="mprgp: total")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("cores (one rank each)")
        ax.set_ylabel("predicted seconds")
        ax.set_title(f"model, default method, {title}")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.savefig(DOCS / "scaling-model.png", dpi=120)
    plt.close(fig)


def text(record: dict, model: CostModel) -> str:
    runs = record["runs"]
    c = record["cores"]
    lines = [
        "# Scaling",
        "",
        "`./run scaling` (about 6 minutes) regenerates this page: calibration, strong and weak scaling on "
        "N = 1, 2, 4, 8 ranks, the two largest meshes, the fitted cost model and its predictions. Result files "
        "of every run are in `results/scaling/`, the aggregate in `results/scaling.h5`.",
        "",
        f"**This machine has {c} cores.** With more ranks than cores the ranks share cores (Open MPI "
        "oversubscription), so every run with N > 2 here measures overhead, not speed-up. The measured "
        "points are used to fit and to validate a cost model; its predictions for 64 to 1024 cores assume one "
        "rank per core.",
        "",
        "## How the work is distributed",
        "",
        "With 4k ranks the world communicator splits into four block communicators of k ranks (block b on "
        "ranks b·k … (b+1)·k − 1). Each rank assembles only its rows of its block (vertices are numbered in "
        "x-slabs, so a contiguous row range is a compact piece of the half) into an MPIAIJ matrix with block "
        "size 2 and the rigid-body near-null space; the block is factored by parallel MUMPS (or, with "
        "`-<block>_ksp_type cg -<block>_pc_type gamg`, solved by CG with smoothed aggregation). A round "
        "scatters the interface loads from rank 0 to the four block leaders (Scatterv), which broadcast them "
        "in their block; the traces come back the same way (Gatherv). The multiplier update stays on rank 0. "
        "The meshes are generated by two ranks, one half each, and broadcast; peak memory per rank is in every "
        "result file (`peak_memory_mb`).",
        "",
        "## Measured (default method `schur`, and `mprgp`)",
        "",
        "| run | N | P | block unknowns | rounds | factorization (s) | rounds (s) | rank-0 update (s) | solve phase (s) "
        "| model (s) | setup (s) | peak memory per rank (MB) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        memory = f"{max(r['peak_memory_mb']):.0f}" + (f" (max of {len(r['peak_memory_mb'])})" if r["ranks"] > 1 else "")
        lines.append(f"| {r['kind']} {r['method']} | {r['ranks']} | {r['P']} | {r['unknowns']:,} | {r['rounds']} "
                     f"| {r['factorization']:.3f} | {r['iterations'] - r['update']:.3f} | {r['update']:.3f} "
                     f"| {r['wall_time']:.3f} | {r['predicted']:.3f} | {r['setup']:.1f} | {memory} |")
    fitted = [r for r in runs if r["ranks"] <= c]
    errors = [abs(r["predicted"] / r["wall_time"] - 1.0) for r in fitted]
    overhead = [r["wall_time"] / r["predicted"] for r in runs if r["ranks"] > c]
    m = model
    lines += [
        "",
        "![measured phases](scaling-measured.png)",
        "",
        "## Cost model",
        "",
        "Solve phase = factorization + interface matrices + rounds + gather + rank-0 work. Block work is "
        "measured on one block and one rank at five sizes (`bench.block_timings`; n = block unknowns, "
        "kΣ = inner Σ vertices) and fitted by power laws; message costs are measured between two ranks:",
        "",
        "| phase | path | law (seconds) |",
        "|---|---|---|",
        f"| factorization per block | MUMPS with the Schur complement (`schur`, whole blocks) | "
        f"{m.factor['schur'][0]:.2e}·n^{m.factor['schur'][1]:.2f} |",
        f"| | plain MUMPS (distributed blocks) | {m.factor['mumps'][0]:.2e}·n^{m.factor['mumps'][1]:.2f} |",
        f"| | PETSc's Cholesky (`mprgp`) | {m.factor['mprgp'][0]:.2e}·n^{m.factor['mprgp'][1]:.2f} |",
        f"| one solve per block | MUMPS with / without the Schur complement | {m.solve['schur'][0]:.2e}·n^"
        f"{m.solve['schur'][1]:.2f} / {m.solve['mumps'][0]:.2e}·n^{m.solve['mumps'][1]:.2f} |",
        f"| | PETSc's Cholesky | {m.solve['mprgp'][0]:.2e}·n^{m.solve['mprgp'][1]:.2f} |",
        f"| interface matrix per block | from the factorization (+ one checking solve) | "
        f"{m.interface[0]:.2e}·n^{m.interface[1]:.2f} |",
        f"| | by multi-column solves (distributed blocks) | {m.column[0]:.2e}·(n·2kΣ)^{m.column[1]:.2f} |",
        f"| a round's messages | 3 world collectives (+2 per block if k > 1), 2·4 traces | "
        f"{1e6 * m.latency:.1f} µs per log₂N step + bytes / {m.bandwidth / 1e9:.1f} GB/s |",
        f"| `schur`: interface matrices to rank 0 | 4·(2kΣ)² doubles | bytes / {m.bandwidth / 1e9:.1f} GB/s |",
        f"| `schur`: rank-0 dense interface solve | nΣ ≈ 3P interface unknowns | {m.rank0[0]:.2e}·nΣ^{m.rank0[1]:.2f} |",
        f"| `mprgp`: rank-0 update per round | m multipliers | {m.update:.1e}·m |",
        f"| `mprgp`: rounds (kkt 1e-6) | P vertices on Σ | {m.mprgp_rounds[0]:.1f}·P^{m.mprgp_rounds[1]:.2f} |",
        "",
        f"Four blocks of work W each take 4W/min(N, C) on N ranks and C cores (C = {c} here): whole blocks "
        "per rank for N ≤ 4, a block over k = N/4 ranks otherwise. Parallel MUMPS is assumed to scale "
        "ideally within a block — nothing on this machine can measure that (k ≤ 2, and only oversubscribed) — "
        "so the predictions are lower bounds for the block work.",
        "",
        f"**Validation.** On the {len(fitted)} measured runs with at most one rank per core the model's "
        f"solve-phase time is within {100 * np.median(errors):.0f} % in the median and {100 * max(errors):.0f} % "
        "at worst (column *model* above). The oversubscribed runs are overhead measurements: they take "
        f"{min(overhead):.1f}–{max(overhead):.1f}× the model, most of all with 8 ranks, where the two ranks of "
        "a block exchange many small MUMPS messages while six other ranks poll for theirs on the same two "
        "cores.",
        "",
        "## Predictions for 64 to 1024 cores",
        "",
        "![model predictions](scaling-model.png)",
        "",
    ]
    strong, weak = predictions(model)
    for title, rows in (("Strong scaling, P = 1600 (about 3M unknowns)", strong),
                        (f"Weak scaling, {WEAK_UNKNOWNS_PER_CORE:,} unknowns per core", weak)):
        lines += [f"**{title}** (seconds; the phases are those of the default method `schur`):", "",
                  "| cores | P | factorization | interface matrices | rounds | gather | rank-0 solve | `schur` total "
                  "| `mprgp` total |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['ranks']} | {r['P']} | {r['factorization']:.3f} | {r['interface']:.3f} "
                         f"| {r['rounds']:.3f} | {r['gather']:.3f} | {r['rank0']:.3f} | {r['total']:.2f} "
                         f"| {r['mprgp']:.2f} |")
        lines.append("")
    crossover = next((r["ranks"] for r in weak if r["rank0"] > r["factorization"] + r["interface"]), None)
    switch = next((r["ranks"] for r in strong if r["mprgp"] < r["total"]), None)
    lines += [
        "**Where the rank-0 update becomes the bottleneck.** Rank 0's dense interface solve does not shrink "
        f"with the number of ranks: {strong[0]['rank0']:.1f} s at P = 1600. In strong scaling it is the largest "
        f"phase from {next((r['ranks'] for r in strong if r['rank0'] >= max(r['factorization'], r['interface'])), '—')} "
        f"cores on, and no number of cores brings the total below it. In weak scaling nΣ ≈ 3P grows like √N, so "
        "rank 0's work grows "
        f"like N^{1.5 * m.rank0[1] / 3:.1f} while the block work per rank grows slowly"
        + (f"; rank 0 overtakes the block work at about {crossover} cores." if crossover else ".") +
        " The interface matrices of distributed blocks are the other phase that scales badly: PETSc's MUMPS "
        "interface has no parallel Schur complement, so they take 2kΣ right-hand sides of multi-column solves"
        + (f", and from {switch} cores on the model prefers `mprgp` (its rounds only need solves)." if switch else ".") +
        " Remedies, in order of effort: distributed blocks running `mprgp` (possible today with "
        "`--set solver.method=mprgp`); the Schur complement of a distributed block from MUMPS itself "
        "(ICNTL(19) returns it distributed, which PETSc does not expose); the interface problem solved by a "
        "parallel dense solver (ScaLAPACK or Elemental through PETSc) or iteratively on a few ranks instead of "
        "rank 0 alone.",
        "",
        "## Large meshes",
        "",
        "| P | M | unknowns in all | solve phase (s) | setup (s) | launch (s) | peak memory per rank (MB) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in (r for r in runs if r["kind"] == "large"):
        lines.append(f"| {r['P']} | {r['M']} | {4 * r['unknowns']:,} | {r['wall_time']:.1f} | {r['setup']:.1f} "
                     f"| {r['launch']:.0f} | {', '.join(f'{m:.0f}' for m in r['peak_memory_mb'])} |")
    lines += ["", "Both solved by the default method on 4 ranks (one block each); *setup* is meshing (two "
              "ranks, one half each, gmsh single-threaded) and assembly, *launch* the whole command including "
              "writing the result."]
    return "\n".join(lines) + "\n"
