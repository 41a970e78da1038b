"""Scaling experiments and a per-phase cost model (``ddsolve scaling``).

Strong scaling (one mesh, N = 1, 2, 4, 8 ranks) and weak scaling (unknowns per rank fixed) of
``schur``, MPRGP (many rounds: it exposes the per-round exchange) and ``feti``; rounds against P for
the iterative methods; the whole launch of Example 1 (P = 800 and 1600, its 0.1 % runs) with every
phase on every rank; meshing against the ranks; the memory per unknown; the monolithic MUMPS
baseline; calibration runs: one block's factorization, solve and interface-matrix times at several
sizes (one rank), and MPI latency and bandwidth (two ranks).  A cost model fitted to the calibration
data predicts every measured run (validation) and the solve phase on 64 to 1024 cores.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from ddsolve.errors import DDSolveError
from experiments import report

RESULTS = Path("results/scaling")
DOCS = Path("docs")
STRONG_MESH = (400, 512)
RANKS = (1, 2, 4, 8)
#: Weak scaling: about 12k unknowns per block and rank (P ∝ √N).
WEAK_MESHES = {1: (100, 128), 2: (141, 181), 4: (200, 256), 8: (283, 362)}
#: The whole launch (default method, 4 ranks): label -> the ``--set`` items on Example 1.
LAUNCH_CASES = {
    "P = 800": ("mesh.sigma_vertices=800", "mesh.boundary_vertices=1024"),
    "P = 1600": ("mesh.sigma_vertices=1600", "mesh.boundary_vertices=2048"),
    "P = 1600, out of core": ("mesh.sigma_vertices=1600", "mesh.boundary_vertices=2048", "solver.out_of_core=true"),
    "0.1 %, graded P2": ("mesh.size=0.02458", "mesh.degree=2", "mesh.grading=true"),
    "target 0.1 %": ("mesh.target_error=0.001",),
    "target 1 %": ("mesh.target_error=0.01",),
}
#: Meshing against the ranks: these meshes (P, M), each on every one of RANKS, meshed and distributed
#: as a solve does it, without the solve.
MESHING_MESHES = ((800, 1024), (1600, 2048), (3200, 4096))
CALIBRATION_MESHES = ((100, 128), (141, 181), (200, 256), (283, 362), (400, 512))
METHODS = ("schur", "mprgp", "feti")
#: Rounds against P (kkt 1e-6, 4 ranks): the iterative methods up to their largest affordable mesh.
ROUNDS_MESHES = ((100, 128), (200, 256), (400, 512), (800, 1024), (1600, 2048))
ROUNDS_LARGEST = {"mprgp": 800, "feti": 1600}
#: The monolithic baseline (bench baseline, one pair each).
BASELINE_MESHES = ((400, 512), (800, 1024))
PREDICTED_CORES = (64, 128, 256, 512, 1024)
#: Unknowns per core in the predicted weak scaling (the block has this many times its ranks).
WEAK_UNKNOWNS_PER_CORE = 50_000


def cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


# --- calibration (inside MPI launches) ---------------------------------------------------------
def network(output: Path, comm) -> None:
    """Latency and bandwidth of the collectives a round uses, between two ranks."""
    from ddsolve.parallel.launch import provenance

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
    from experiments.bench import block_timings

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
        feti = [r for r in runs if r["method"] == "feti" and r["ranks"] == 4]
        self.feti_rounds = power_law([r["P"] for r in feti], [r["rounds"] for r in feti])
        self.factor["feti"], self.solve["feti"] = self.factor["mumps"], self.solve["mumps"]

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
        factorizations = 2 if method == "feti" else 1  # feti: the Neumann and the Dirichlet problem
        out = {"factorization": factorizations * share * self._law(self.factor[path], unknowns), "interface": 0.0,
               "gather": 0.0}
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


def meshing(P: int, M: int, refine: str, output: Path, comm) -> None:
    """Inside one launch: Example 1's (P, M) mesh (``refine``: ``auto`` or the ``mesh.refine`` levels) made
    and distributed as a solve that writes its result in parallel makes it
    (:func:`ddsolve.parallel.distribution.local_mesh`, each rank of a shared block making its piece); rank 0 writes
    every rank's meshing and distribution CPU seconds, its own wall seconds and the peak memory of each
    rank as JSON."""
    from experiments.bench import paper_scene
    from ddsolve.mesh.mesh import blocks
    from ddsolve.parallel import distribution
    from ddsolve.parallel.exchange import Exchange
    from ddsolve.parallel.phases import Phases, launch_age

    phases = Phases(launch_age())
    scene = paper_scene(P, M, [] if refine == "auto" else [f"mesh.refine={refine}"])
    exchange = Exchange(comm, len(blocks(scene.geometry.layers)))
    try:
        local = distribution.local_mesh(scene, comm, exchange, phases, whole_halves=False)
    finally:
        exchange.free()
    ranks = comm.gather(phases, root=0)
    if comm.rank == 0:
        record = {"P": P, "M": M, "refine": refine, "ranks": comm.size, "unknowns": 4 * sum(local.nodes.values()),
                  "meshing": phases.wall["meshing"], "distribution": phases.wall["distribution"],
                  "meshing_cpu": [ranked.cpu["meshing"] for ranked in ranks],
                  "distribution_cpu": [ranked.cpu["distribution"] for ranked in ranks],
                  "peak_memory_mb": [max(ranked.peak.values()) for ranked in ranks]}
        output.write_text(json.dumps(record))


# --- the experiment ---------------------------------------------------------------------------
#: A Python MPI program that only starts (numpy, MPI and PETSc); rank 0 prints when the last rank had started.
BARE_START = ("import sys, time, numpy; from mpi4py import MPI; import petsc4py; petsc4py.init(sys.argv[:1]); "
              "from petsc4py import PETSc; last = MPI.COMM_WORLD.reduce(time.time(), op=MPI.MAX); "
              "MPI.COMM_WORLD.rank or print(last)")


def bare_start(ranks: int, repeats: int = 3) -> float:
    """Seconds from starting mpiexec (as ``ddsolve solve -n`` does) until the last of ``ranks`` ranks of
    :data:`BARE_START` has started, the median of ``repeats`` launches: what any launch of a Python
    program on MPI and PETSc pays before it can work, the floor of a launch's start-up."""
    import subprocess

    from ddsolve.parallel.launch import mpiexec_command

    command = [*mpiexec_command(ranks, [])[:-2], "-c", BARE_START]  # python -c instead of python -m ddsolve
    seconds = []
    for _ in range(repeats):
        launched = time.time()
        # Python's view of the environment, as report.run passes it (not what an MPI library added in C)
        done = subprocess.run(command, capture_output=True, text=True, env=dict(os.environ))
        if done.returncode != 0:
            raise DDSolveError(f"the bare start failed (exit {done.returncode}): {done.stderr.strip()[-300:]}")
        seconds.append(float(done.stdout) - launched)
    return float(np.median(seconds))


def _solve(ranks: int, P: int, M: int, method: str, name: str) -> dict:
    """One ``ddsolve solve`` launch of the paper's family; its result file stays in results/scaling."""
    tolerance = "solver.tol=1e-8" if method == "schur" else "solver.tol=1e-6"
    return {"P": P, "M": M, **_launch(ranks, (f"mesh.sigma_vertices={P}", f"mesh.boundary_vertices={M}",
                                               f"solver.method={method}", tolerance), name)}


def _launch(ranks: int, settings: tuple[str, ...], name: str) -> dict:
    """One ``ddsolve solve`` launch of Example 1 with ``settings``; what the scaling page reads of it.

    *sum* is the launch from the result's ``/timings`` (an adaptive run: its start-up, every level and
    the write); *solve phase* its factorizations and iterations (an adaptive run: of every level)."""
    from ddsolve.io import hdf5
    from ddsolve.parallel.phases import PHASES

    path = RESULTS / f"{name}.h5"
    started = time.perf_counter()
    report.run(ranks, ["solve", "partial-closure", *[item for setting in settings for item in ("--set", setting)],
                       "-o", str(path)])
    launch = time.perf_counter() - started
    result = hdf5.read(path)
    timings = {key: float(value) for key, value in result.timings.items()}
    levels = getattr(result, "levels", None) or {}
    if "adaptive" in timings:
        total = timings["startup"] + timings["adaptive"] + timings.get("write", 0.0)
        solve_phase = float(np.sum(levels["solve_time"])) if "solve_time" in levels else result.wall_time
    else:
        total, solve_phase = sum(timings.get(phase, 0.0) for phase in PHASES), result.wall_time
    memory = {key: (value.tolist() if hasattr(value, "tolist") else value) for key, value in result.memory.items()}
    return {"name": name, "ranks": ranks, "settings": " ".join(settings), "method": result.method,
            "rounds": result.solves, "unknowns": 2 * len(result.lower.points),
            "trace": 2 * len(result.multiplier_nodes),
            "multipliers": int(sum(v.size for v in result.multipliers.values())),
            "interface_unknowns": int(result.attrs.get("interface_unknowns", 0)),
            "rank0_time": float(result.attrs.get("rank0_solve_time", 0.0)),
            "peak_memory_mb": [float(m) for m in result.attrs["peak_memory_mb"]], "wall_time": result.wall_time,
            "error_estimate": float(result.attrs.get("error_estimate", np.nan)),
            "levels": len(levels.get("unknowns", [])), "sum": total, "solve_phase": solve_phase,
            "launch": launch, "memory": memory, **timings}


def scaling() -> dict:
    """Calibrate, run strong, weak, rounds and large cases and the baseline, fit the model; write HDF5,
    docs/scaling.md, plots."""
    from experiments.bench import default_ranks

    RESULTS.mkdir(parents=True, exist_ok=True)
    print("scaling: calibration (one block at 5 sizes; MPI latency and bandwidth)", flush=True)
    calibration = report.launch(1, ["scaling-calibrate"], RESULTS / ".calibration.json")
    net = report.launch(2, ["scaling-network"], RESULTS / ".network.json")
    print("scaling: a bare start of 4 ranks", flush=True)
    bare = bare_start(4)
    runs = []
    for method in METHODS:
        for ranks in RANKS:
            print(f"scaling: strong, {method}, N = {ranks}", flush=True)
            runs.append({"kind": "strong", **_solve(ranks, *STRONG_MESH, method, f"strong-{method}-{ranks}")})
            print(f"scaling: weak, {method}, N = {ranks}", flush=True)
            runs.append({"kind": "weak", **_solve(ranks, *WEAK_MESHES[ranks], method, f"weak-{method}-{ranks}")})
    for method, largest in ROUNDS_LARGEST.items():
        for P, M in (mesh for mesh in ROUNDS_MESHES if mesh[0] <= largest):
            print(f"scaling: rounds, {method}, P = {P}", flush=True)
            runs.append({"kind": "rounds", **_solve(4, P, M, method, f"rounds-{method}-{P}")})
    for label, settings in LAUNCH_CASES.items():
        print(f"scaling: whole launch, {label}", flush=True)
        runs.append({"kind": "launch", "label": label, **_launch(4, settings, f"launch-{len(runs)}")})
    for P, M in MESHING_MESHES:
        for ranks in RANKS:
            print(f"scaling: meshing, P = {P}, N = {ranks}", flush=True)
            runs.append({"kind": "meshing", **report.launch(ranks, ["scaling-meshing", str(P), str(M), "auto"],
                                                            RESULTS / f".meshing-{P}-{ranks}.json")})
    baseline = []
    for P, M in BASELINE_MESHES:
        for name in ("linear", "partial-closure"):
            print(f"scaling: monolithic baseline, {name}, P = {P}", flush=True)
            baseline.append(report.launch(default_ranks(), ["bench-baseline", name, str(P), str(M), "1"],
                                          RESULTS / f".baseline-{name}-{P}.json"))
    record = {"cores": cores(), "calibration": calibration, "network": net, "runs": runs, "baseline": baseline,
              "bare_start": bare}
    (RESULTS / "record.json").write_text(json.dumps(record))
    render(record)
    return record


def render(record: dict) -> None:
    """Fit the model to a record of measurements; write results/scaling.h5, the plots and docs/scaling.md."""
    runs = record["runs"]
    model = CostModel(record["calibration"], record["network"],  # fitted to the method measurements
                      [r for r in runs if r["kind"] in ("strong", "weak", "rounds")])
    for run in (r for r in runs if r["kind"] != "meshing"):  # a meshing run solves nothing
        run["predicted"] = model.phases(run["method"], run["ranks"], run["unknowns"], run["trace"],
                                        run["interface_unknowns"], run["rounds"], run["multipliers"],
                                        record["cores"])["total"]
    parameters = {"factor": model.factor, "solve": model.solve, "interface": model.interface, "column": model.column,
                  "latency": model.latency, "bandwidth": model.bandwidth, "rank0": model.rank0,
                  "update": model.update, "mprgp_rounds": model.mprgp_rounds, "feti_rounds": model.feti_rounds}
    flat = [{key: value for key, value in run.items() if key != "memory"} for run in runs]
    attrs = {**record["network"]["provenance"], "cores": record["cores"], "bare_start": record["bare_start"],
             "model": json.dumps(parameters)}
    report.write_records(RESULTS.parent / "scaling.h5", flat, attrs)
    plots(runs, model)
    (DOCS / "scaling.md").write_text(text(record, model))


#: The phases a launch adds around the solve that grow with a rank's unknowns.
AROUND = ("assembly", "estimate", "output")


class LaunchModel:
    """The launch around the solve phase, fitted to the measured whole launches (kind ``launch``, not
    adaptive): start-up, meshing and the distribution as measured (a coarse gmsh mesh and a refinement
    share that hardly grows), and per phase of :data:`AROUND` plus the write, the largest rank's seconds
    per unknown it works on (medians over the runs)."""

    def __init__(self, runs: list[dict]):
        fitted = [r for r in runs if r["kind"] == "launch" and "adaptive" not in r]
        self.constant = float(np.median([r["startup"] + max(r["memory"]["cpu_s_meshing"]) + r["distribution"]
                                         for r in fitted])) if fitted else 0.0
        self.per_unknown = {phase: float(np.median([max(np.asarray(r["memory"][f"cpu_s_{phase}"])
                                                        / np.asarray(r["memory"]["rank_unknowns"])) for r in fitted]))
                            if fitted else 0.0 for phase in AROUND}
        self.per_unknown["write"] = float(np.median([r["write"] / max(r["memory"]["rank_unknowns"]) for r in fitted])) \
            if fitted else 0.0

    def around(self, unknowns_per_rank: float) -> float:
        """Seconds the launch adds to the solve phase for a rank with this many unknowns."""
        return self.constant + sum(rate * unknowns_per_rank for rate in self.per_unknown.values())


#: Mesh-size relations of the generated meshes (P vertices on Σ): block unknowns ≈ 0.295 P²,
#: interface unknowns of schur ≈ 3P, multipliers ≈ 3·2(P − 2).
def _at(model: CostModel, ranks: int, P: int, launch: LaunchModel | None = None) -> dict:
    trace = 2 * (P - 2)
    unknowns = 0.295 * P * P
    schur = model.phases("schur", ranks, unknowns, trace, 3 * P, 3, 3 * trace)
    iterative = {}
    for method in ("mprgp", "feti"):
        rounds = round(model._law(getattr(model, f"{method}_rounds"), P))
        phases = model.phases(method, ranks, unknowns, trace, 0, rounds, 3 * trace)
        if method == "mprgp" and ranks > 4:  # PETSc's Cholesky is sequential: distributed blocks use MUMPS
            phases["factorization"] = model._law(model.factor["mumps"], unknowns) * 4 / ranks
            phases["rounds"] = rounds * (model._law(model.solve["mumps"], unknowns) * 4 / ranks
                                         + model.exchange(ranks, trace))
            phases["total"] = phases["factorization"] + phases["rounds"] + phases["rank0"]
        iterative[method] = phases["total"]
    chosen = "schur" if ranks <= 4 else min(("schur", "feti"), key=lambda m: schur["total"] if m == "schur"
                                             else iterative["feti"])
    solve = schur["total"] if chosen == "schur" else iterative[chosen]
    around = launch.around(4 * unknowns / ranks) if launch is not None else float("nan")
    return {"ranks": ranks, "P": P, **schur, **iterative, "auto": chosen, "launch": solve + around}


def predictions(model: CostModel, launch: LaunchModel | None = None) -> tuple[list[dict], list[dict]]:
    """Strong scaling of P = 1600 and weak scaling at WEAK_UNKNOWNS_PER_CORE, on 64 … 1024 cores (with the
    whole launch when ``launch`` is given)."""
    strong = [_at(model, ranks, 1600, launch) for ranks in PREDICTED_CORES]
    weak = [_at(model, ranks, int(np.sqrt(WEAK_UNKNOWNS_PER_CORE * (ranks // 4) / 0.295)), launch)
            for ranks in PREDICTED_CORES]
    return strong, weak


def plots(runs: list[dict], model: CostModel) -> None:
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    for ax, kind in zip(axes, ("strong", "weak")):
        for method, color in zip(METHODS, ("tab:blue", "tab:orange", "tab:green")):
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
        ax.plot(ranks, [r["feti"] for r in rows], marker="D", color="tab:green", linestyle="--", label="feti: total")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("cores (one rank each)")
        ax.set_ylabel("predicted seconds")
        ax.set_title(f"model, default method, {title}")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.savefig(DOCS / "scaling-model.png", dpi=120)
    plt.close(fig)


def _launch_rows(runs: list[dict]) -> list[str]:
    from ddsolve.parallel.phases import PHASES

    rows = []
    for r in (r for r in runs if r["kind"] == "launch"):
        phases = " | ".join(f"{r.get(name, 0.0):.2f}" for name in PHASES)
        adaptive = f"{r['adaptive']:.2f} ({r['levels']} solves)" if "adaptive" in r else "—"
        rows.append(f"| {r['label']} | {4 * r['unknowns']:,} | {100 * r['error_estimate']:.3g} % | {phases} "
                    f"| {adaptive} | {r['sum']:.1f} | {r['launch']:.1f} | {r['solve_phase']:.2f} "
                    f"| {r['sum'] / r['solve_phase']:.2f} |")
    return rows


def floor_rows(runs: list[dict], bare: float) -> list[str]:
    """Per whole launch: what it pays before it can solve (start-up and one assembly, its last level's for an
    adaptive run) and the least sum / solve those allow, with its own start-up and with a ``bare`` one."""
    rows = []
    for r in (r for r in runs if r["kind"] == "launch"):
        solve = r["solve_phase"]
        rows.append(f"| {r['label']} | {solve:.2f} | {r['startup']:.2f} | {r['assembly']:.2f} "
                    f"| {(solve + r['startup'] + r['assembly']) / solve:.2f} "
                    f"| {(solve + bare + r['assembly']) / solve:.2f} | {r['sum'] / solve:.2f} |")
    return rows


def _per_rank_rows(runs: list[dict]) -> list[str]:
    """CPU seconds of every phase on each rank (``/memory`` ``cpu_s_<phase>``), the launch cases."""
    from ddsolve.parallel.phases import PHASES

    rows = []
    for r in (r for r in runs if r["kind"] == "launch" and "adaptive" not in r):
        for rank in range(r["ranks"]):
            cpu = [r["memory"].get(f"cpu_s_{name}", [float("nan")] * r["ranks"])[rank] for name in PHASES]
            peak = max(r["memory"].get(f"peak_mb_{name}", [0.0] * r["ranks"])[rank] for name in PHASES)
            rows.append(f"| {r['label']} | {rank} | " + " | ".join("—" if np.isnan(t) else f"{t:.2f}" for t in cpu)
                        + f" | {peak:.0f} |")
    return rows


def _meshing_rows(runs: list[dict]) -> list[str]:
    """Meshing against the ranks, per mesh: rank 0's wall time, the largest and smallest per-rank CPU
    seconds and the largest against the 2-rank run's, the distribution, the peak memory."""
    meshing = sorted((r for r in runs if r["kind"] == "meshing"), key=lambda r: (r["P"], r["ranks"]))
    two = {r["P"]: max(r["meshing_cpu"]) for r in meshing if r["ranks"] == 2}
    return [f"| {r['P']} | {r['ranks']} | {r['unknowns']:,} | {r['meshing']:.3f} | {max(r['meshing_cpu']):.3f} "
            f"| {min(r['meshing_cpu']):.3f} | {max(r['meshing_cpu']) / two.get(r['P'], np.nan):.2f} "
            f"| {r['distribution']:.2f} | {max(r['distribution_cpu']):.2f} | {max(r['peak_memory_mb']):.0f} |"
            for r in meshing]


def _memory_rows(runs: list[dict]) -> list[str]:
    rows = []
    for r in (r for r in runs if (r["kind"] == "launch" and "adaptive" not in r)
              or (r["kind"] == "rounds" and r["P"] >= 800)):
        m = r["memory"]
        per_phase = [m.get(f"bytes_per_unknown_{name}", float("nan")) for name in
                     ("meshing", "assembly", "factorization", "iterations", "estimate", "output")]
        factor = max(m.get("rank_factor_mb", [0.0]))
        mesh = max(m.get("rank_mesh_bytes", [0])) / 2 ** 20
        label = r.get("label", f"P = {r.get('P')}")
        rows.append(f"| {label} | {r['method']} | {max(r['peak_memory_mb']):.0f} | {factor:.0f} | {mesh:.0f} | "
                    + " | ".join(f"{b:.0f}" for b in per_phase) + " |")
    return rows


def _account_rows(runs: list[dict]) -> list[str]:
    """What rank 0 and the largest other rank held per phase (``/memory`` ``held_mb_<phase>``), MB."""
    rows = []
    for r in (r for r in runs if r["kind"] == "launch" and "adaptive" not in r):
        m = r["memory"]
        for phase in ("assembly", "factorization", "iterations", "estimate", "output"):
            held = np.asarray(m[f"held_mb_{phase}"])
            others = held[1:].max(axis=0) if len(held) > 1 else np.full(held.shape[1], np.nan)
            rows.append(f"| {r['label']} | {phase} | " + " | ".join(f"{a:.0f} / {b:.0f}" for a, b in zip(held[0], others))
                        + f" | {m[f'peak_mb_{phase}'][0]:.0f} / {max(m[f'peak_mb_{phase}'][1:], default=float('nan')):.0f} |")
    return rows


def _rounds_rows(runs: list[dict]) -> list[str]:
    table = {}
    for r in runs:
        if (r["ranks"] == 4 and r["kind"] in ("strong", "weak")) or r["kind"] == "rounds":
            table.setdefault(r["method"], {})[r["P"]] = r["rounds"]
    sizes = sorted({P for rounds in table.values() for P in rounds})
    rows = ["| method | " + " | ".join(f"P = {P}" for P in sizes) + " |", "|---|" + "---|" * len(sizes)]
    for method, rounds in table.items():
        rows.append(f"| `{method}` | " + " | ".join(str(rounds.get(P, "—")) for P in sizes) + " |")
    return rows


def _baseline_rows(baseline: list[dict]) -> list[str]:
    from experiments.bench import MONOLITHIC_ORDERINGS

    rows = []
    for b in baseline:
        dd = b["dd"][0]
        monos = [b[f"mono {label}"][0] for label in MONOLITHIC_ORDERINGS]
        rows.append(f"| {b['scene']} | {b['P']} | {b['unknowns']:,} | {b['ranks']} | {dd['method']} "
                    f"| {dd['solve_phase']:.2f} | " + " | ".join(f"{m['solve_phase']:.2f} ({m['solve_phase'] / dd['solve_phase']:.2f}×)"
                                                     for m in monos) + f" | {dd['error']:.0e} | {b['load']:.1f} |")
    return rows


#: How ``ddsolve solve -n`` distributes the work (a section of docs/scaling.md).
DISTRIBUTION = (
    "`ddsolve solve -n` starts the ranks on one host with Open MPI's shared-memory layer named (`--mca pml ob1`, "
    "half of MPI_Init's time). The leaders of u⁻ (rank 0) and u⁺ mesh the two halves at once (gmsh in a child "
    "process, so a signal ends the job at once; forked before MPI starts, it imports gmsh while the rank starts). "
    "Above P = 400 (and for large `mesh.size` boxes) gmsh makes only a coarse mesh of about 4,000 vertices with "
    "the same sizes and grading, and the ranks of each half refine it uniformly (`mesh.refine`, "
    "ddsolve/mesh/refine.py): every rank of a half makes the fine cells of an equal share of the coarse cells "
    "(with more than two ranks on a half, all but its first, which made the coarse mesh or is rank 0), numbered "
    "from the coarse mesh alone, and one Allgatherv places the pieces; each measures the cells it made (shortest "
    "side, smallest angle). Rank 0 pairs and checks the halves (Σ, the loads' boundaries, the supports, the crack "
    "tips' radii) on its own half and the skeleton of the upper one (its boundary nodes and edges, sent by u⁺'s "
    "leader; the outer edges come from the coarse mesh's), and each half goes only to the ranks whose blocks live "
    "on it, Σ to all: every rank holds one half (both with one rank). With 1, 2 or 4 ranks, rank r owns the "
    "blocks b ≡ r (mod N): with two ranks u⁻, v⁻ on rank 0 and u⁺, v⁺ on rank 1, so both blocks of a rank share "
    "one half and its sparsity pattern. With 4k ranks the world communicator splits into four block communicators "
    "of k ranks (block b on ranks b·k … (b+1)·k − 1); each rank cuts its piece of the half "
    "(ddsolve/mesh/pieces.py: the cells of its rows' nodes, a contiguous row range being a compact piece of the "
    "half, with two rings of neighbours and the half's skeleton — Σ, the named boundaries and the outer "
    "boundary), and a `solve` whose ranks write the result together drops the whole half then. On a refined mesh "
    "such a solve makes each rank's piece directly from the coarse half (`pieces.of_lattice`; rank 0 checks the "
    "two halves' skeletons, made from the coarse ones), so no rank ever holds a whole fine half: at P = 600 on 8 "
    "ranks at most 57 % of its half's mesh arrays in every phase, the coarse half included while the piece is "
    "made. A half gmsh makes whole (P ≤ 400, mesh files) is held whole by the rank that makes it (rank 0, or u⁺'s "
    "leader) until it has cut every rank of the half its piece and sent it; the other ranks receive only their "
    "pieces (at P = 300 on 8 ranks 58 % of the half; the two makers 99–102 % during meshing and distribution). "
    "Each rank assembles its rows on its piece into an MPIAIJ matrix with block size 2 and the rigid-body "
    "near-null space, factored by parallel MUMPS. Assembly builds the CSR pattern once per half (one sort of the "
    "cells' node pairs, which gives the graph's edges in their rows' order, and each pair's entry) and sums the "
    "element matrices a slice of cells at a time, over the range of values the slice touches. A round scatters "
    "the interface loads from rank 0 to the block leaders, which broadcast them in their block; the traces come "
    "back the same way. Waiting ranks sleep instead of spinning. After the rounds the factors are freed. Every "
    "rank of a block takes the last solve on its piece (one PETSc scatter): on it it computes the error "
    "indicators, cell fields and G's domain integrals of the cells it owns (those whose smallest node is among "
    "its rows), and the reactions at the nodes it owns and its share of the split of G (the partner block's ranks "
    "interpolating its field at the mirror images of the disc on the cells they own); with parallel HDF5 "
    "(`python3-h5py-mpi`) every rank writes the rows of its nodes and owned cells into the one result file and "
    "the viewer files, and no rank gathers a block's solution: rank 0 gathers only Σ-sized data and sums (the "
    "*output* phase counts all of it). With `solver.out_of_core = true` MUMPS keeps the factors on disk "
    "(`MUMPS_OOC_TMPDIR`) and reads them back at every solve; rank 0 factors the dense interface stiffness in "
    "place."
)


def text(record: dict, model: CostModel) -> str:
    """docs/scaling.md from a record of measurements (:func:`scaling`) and the model fitted to it: a
    section per function, joined by blank lines."""
    runs, cores_here = record["runs"], record["cores"]
    launch = LaunchModel(runs)
    strong, weak = predictions(model, launch)
    sections = [_introduction(cores_here), _measured(runs), _rounds(runs, model),
                _whole_launch(runs, record["bare_start"]), _meshing(runs), _memory(runs),
                _baseline(record.get("baseline", [])), _cost_model(model, cores_here), _validation(runs, cores_here),
                _predictions(launch, strong, weak), _limits(strong, weak)]
    return "\n\n".join("\n".join(section) for section in sections) + "\n"


def _introduction(cores_here: int) -> list[str]:
    """The page's title, what regenerates it, this machine, and how the work is distributed."""
    c = cores_here
    return [
        "# Scaling",
        "",
        "`./run scaling` regenerates this page: calibration, strong and weak scaling on N = 1, 2, 4, 8 ranks, "
        "rounds against P for the iterative methods, the whole launch of Example 1 (P = 800 and 1600, and its 0.1 % "
        "runs) phase by phase and rank by rank, meshing against the ranks, the memory per unknown, the monolithic "
        "MUMPS baseline, the fitted cost model and its predictions. Result files of every run are in "
        "`results/scaling/`, the aggregate in `results/scaling.h5`.",
        "",
        f"**This machine has {c} cores.** With more ranks than cores the ranks share cores (Open MPI "
        "oversubscription; waiting ranks yield their core), so every run with N > 2 here measures overhead, not "
        "speed-up. The measured points are used to fit and to validate a cost model; its predictions for 64 to 1024 "
        "cores assume one rank per core. Other jobs may have shared the machine: each baseline row gives the load.",
        "",
        "## How the work is distributed",
        "",
        DISTRIBUTION,
    ]


def _measured(runs: list[dict]) -> list[str]:
    """The strong and weak runs, phase by phase, against the model."""
    lines = [
        "## Measured (`schur`, `mprgp`, `feti`)",
        "",
        "| run | N | P | block unknowns | rounds | factorization (s) | rounds (s) | rank-0 update (s) | solve phase (s) "
        "| model (s) | setup (s) | peak memory per rank (MB) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in (r for r in runs if r["kind"] in ("strong", "weak")):
        memory = f"{max(r['peak_memory_mb']):.0f}" + (f" (max of {len(r['peak_memory_mb'])})" if r["ranks"] > 1 else "")
        lines.append(f"| {r['kind']} {r['method']} | {r['ranks']} | {r['P']} | {r['unknowns']:,} | {r['rounds']} "
                     f"| {r['factorization']:.3f} | {r['iterations'] - r['update']:.3f} | {r['update']:.3f} "
                     f"| {r['wall_time']:.3f} | {r['predicted']:.3f} | {r['setup']:.1f} | {memory} |")
    return lines + ["", "![measured phases](scaling-measured.png)"]


def _rounds(runs: list[dict], m: CostModel) -> list[str]:
    """Rounds against P and the fitted laws."""
    return [
        "## Rounds against P (kkt 1e-6 for the iterative methods, 4 ranks)",
        "",
        *_rounds_rows(runs),
        "",
        f"Fitted: `mprgp` {m.mprgp_rounds[0]:.1f}·P^{m.mprgp_rounds[1]:.2f}, `feti` {m.feti_rounds[0]:.1f}·P^"
        f"{m.feti_rounds[1]:.2f}. `schur` is exact in 3 rounds on every mesh. `feti`'s CG iterations on the linear "
        "problem are nearly constant in P (the Dirichlet preconditioner); what grows is the number of active-set "
        "steps of the contact problem, each a few warm-started iterations.",
    ]


def _whole_launch(runs: list[dict], bare: float) -> list[str]:
    """Example 1 launched as a user does: phases, what bounds sum / solve, CPU per rank."""
    from ddsolve.parallel.phases import PHASES

    return [
        "## Whole launch (default method, 4 ranks)",
        "",
        "Example 1 as a user launches it (`./run solve -n 4 partial-closure --set ...`, the settings in "
        "`results/scaling.h5`). Phases from the result file's `/timings` (rank 0's clock; *startup*: from "
        "`ddsolve solve -n` starting mpiexec to the solver's start; *iterations*: the rounds and rank 0's updates; "
        "*adaptive*: every level of a `mesh.target_error` run, whose other columns are its last level's; *output*: G, "
        "its modes, the reactions and the fields the files hold; *write*: the result file and its viewer files); "
        "*sum*: the launch from the timings, *launch*: the command's wall time measured outside it (with the Python and "
        "MPI start-up of the launcher); *solve phase* = factorization + iterations (of every level).",
        "",
        "| case | unknowns | estimated error | " + " | ".join(PHASES)
        + " | adaptive (s) | sum (s) | launch (s) | solve phase (s) | sum / solve |",
        "|---" * (len(PHASES) + 8) + "|",
        *_launch_rows(runs),
        "",
        "No launch can solve before its ranks have started and assembled their blocks: start-up and one assembly "
        "(the last level's, for an adaptive run) bound sum / solve from below, whatever the meshing, the estimate "
        "and the output cost. The least start-up of any Python program on MPI and PETSc is measured too: "
        f"{bare:.2f} s from mpiexec's start until the last of 4 ranks that only import numpy and "
        "start MPI and PETSc has started (`BARE_START`, the median of three). Where start-up and one assembly "
        "exceed half the solve phase, no launch of that case reaches 1.5× on this machine:",
        "",
        "| case | solve phase (s) | startup (s) | assembly (s) | least sum / solve | least with a bare start "
        "| sum / solve |",
        "|---|---|---|---|---|---|---|",
        *floor_rows(runs, bare),
        "",
        "CPU seconds of every phase on each rank (`/memory` `cpu_s_<phase>`) and the rank's peak memory:",
        "",
        "| case | rank | " + " | ".join(PHASES) + " | peak (MB) |",
        "|---" * (len(PHASES) + 3) + "|",
        *_per_rank_rows(runs),
    ]


def _meshing(runs: list[dict]) -> list[str]:
    """Meshing and distribution against the ranks."""
    return [
        "## Meshing against the ranks",
        "",
        f"Example 1's mesh of (P, M) = {', '.join(f'({P}, {M})' for P, M in MESHING_MESHES)} made and distributed "
        "on N ranks as a solve that writes its result in parallel does it (on 8 ranks each rank makes only its "
        "piece of its half, with the rank of the other layer's block, which needs the same piece, making half its "
        "cells and points), without the solve (`scaling-meshing`; the levels of refinement chosen as by default): "
        "rank 0's meshing wall time, the largest and smallest per-rank meshing CPU seconds (the warm gmsh "
        "child's import of gmsh counts as start-up, when it ran; sending and pairing the coarse halves count as "
        "distribution), the largest against the 2-rank run's, rank 0's "
        "distribution wall time (receiving the upper half's skeleton, pairing and checking the mesh) and the largest "
        "rank's distribution CPU seconds, the peak memory. The coarse mesh costs gmsh about the same on every "
        "mesh; the refinement grows with the mesh and is shared. On 8 ranks the busiest are u⁻'s and u⁺'s "
        "leaders, which also made the coarse halves:",
        "",
        "| P | N | unknowns | meshing wall (s) | meshing CPU, largest rank (s) | smallest rank (s) "
        "| largest / 2 ranks | distribution wall (s) | distribution CPU, largest rank (s) | peak per rank (MB) |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *_meshing_rows(runs),
    ]


def _memory(runs: list[dict]) -> list[str]:
    """Peak memory, factors and mesh per rank, bytes per unknown, and what the ranks hold per phase."""
    return [
        "## Memory",
        "",
        "Peak resident memory per rank (largest rank), MUMPS's own count of its factors (INFO(16), largest rank), "
        "the mesh arrays a rank holds, and the largest peak per unknown of a rank at the end of each phase (bytes "
        "per unknown it works on; the result file's `/memory`):",
        "",
        "| case | method | peak per rank (MB) | factors (MB) | mesh (MB) | meshing | assembly | factorization "
        "| iterations | estimate | output |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *_memory_rows(runs),
        "",
        "What the ranks hold, phase by phase (the account in `/memory` `held_mb_<phase>`: the most MB of each "
        "kind a rank held during the phase; rank 0 / the largest other rank) against the peak resident memory at "
        "the phase's end. The factors and matrices are dropped after the last round; the estimate and the "
        "output run in the memory they held:",
        "",
        "| case | phase | mesh | matrices | factors | Schur complements | solutions | peak resident |",
        "|---|---|---|---|---|---|---|---|",
        *_account_rows(runs),
    ]


def _baseline(baseline: list[dict]) -> list[str]:
    """The default method against one MUMPS factorization of the whole problem."""
    from experiments.bench import MONOLITHIC_ORDERINGS

    return [
        "## The monolithic baseline",
        "",
        "`bench baseline`: one MUMPS factorization of the whole glued problem in one process (contact by the active "
        "set on the crack faces' Schur complement from that factorization), alternating with the default method in "
        f"one launch; the monolithic solve with MUMPS's own ordering choice and with AMF ({', '.join(MONOLITHIC_ORDERINGS)}), "
        "ratio = monolithic / DD:",
        "",
        "| scene | P | unknowns | DD ranks | DD method | DD solve phase (s) | "
        + " | ".join(f"monolithic, {label} (s)" for label in MONOLITHIC_ORDERINGS) + " | DD error | load |",
        "|---|---|---|---|---|---|" + "---|" * len(MONOLITHIC_ORDERINGS) + "---|---|",
        *_baseline_rows(baseline),
    ]


def _cost_model(m: CostModel, cores_here: int) -> list[str]:
    """The fitted laws of the cost model, phase by phase."""
    c = cores_here
    return [
        "## Cost model",
        "",
        "Solve phase = factorization + interface matrices + rounds + gather + rank-0 work. Block work is "
        "measured on one block and one rank at five sizes (`bench.block_timings`; n = block unknowns, "
        "kΣ = inner Σ vertices) and fitted by power laws; message costs are measured between two ranks:",
        "",
        "| phase | path | law (seconds) |",
        "|---|---|---|",
        f"| factorization per block | MUMPS with the Schur complement (`schur`, whole blocks; AMD ordering) | "
        f"{m.factor['schur'][0]:.2e}·n^{m.factor['schur'][1]:.2f} |",
        f"| | plain MUMPS, AMF ordering (distributed blocks; `feti` twice: Neumann and Dirichlet) | "
        f"{m.factor['mumps'][0]:.2e}·n^{m.factor['mumps'][1]:.2f} |",
        f"| | PETSc's Cholesky (`mprgp`) | {m.factor['mprgp'][0]:.2e}·n^{m.factor['mprgp'][1]:.2f} |",
        f"| one solve per block | MUMPS with / without the Schur complement | {m.solve['schur'][0]:.2e}·n^"
        f"{m.solve['schur'][1]:.2f} / {m.solve['mumps'][0]:.2e}·n^{m.solve['mumps'][1]:.2f} |",
        f"| | PETSc's Cholesky | {m.solve['mprgp'][0]:.2e}·n^{m.solve['mprgp'][1]:.2f} |",
        f"| interface matrix per block | from the factorization | {m.interface[0]:.2e}·n^{m.interface[1]:.2f} |",
        f"| | by multi-column solves (distributed blocks) | {m.column[0]:.2e}·(n·2kΣ)^{m.column[1]:.2f} |",
        f"| a round's messages | 3 world collectives (+2 per block if k > 1), 2·4 traces | "
        f"{1e6 * m.latency:.1f} µs per log₂N step + bytes / {m.bandwidth / 1e9:.1f} GB/s |",
        f"| `schur`: interface matrices to rank 0 | 4·(2kΣ)² doubles | bytes / {m.bandwidth / 1e9:.1f} GB/s |",
        f"| `schur`: rank-0 dense interface solve (Cholesky) | nΣ ≈ 3P interface unknowns | {m.rank0[0]:.2e}·nΣ^{m.rank0[1]:.2f} |",
        f"| `mprgp`, `feti`: rank-0 update per round | m multipliers | {m.update:.1e}·m |",
        f"| `mprgp`: rounds (kkt 1e-6) | P vertices on Σ | {m.mprgp_rounds[0]:.1f}·P^{m.mprgp_rounds[1]:.2f} |",
        f"| `feti`: rounds (kkt 1e-6) | P vertices on Σ | {m.feti_rounds[0]:.1f}·P^{m.feti_rounds[1]:.2f} |",
        "",
        f"Four blocks of work W each take 4W/min(N, C) on N ranks and C cores (C = {c} here): whole blocks "
        "per rank for N ≤ 4, a block over k = N/4 ranks otherwise. Parallel MUMPS is assumed to scale "
        "ideally within a block — nothing on this machine can measure that (k ≤ 2, and only oversubscribed) — "
        "so the predictions are lower bounds for the block work.",
    ]


def _validation(runs: list[dict], cores_here: int) -> list[str]:
    """How far the model is from the measured runs (with at most one rank per core, and oversubscribed)."""
    c = cores_here
    fitted = [r for r in runs if r["ranks"] <= c and r["kind"] in ("strong", "weak")]
    errors = [abs(r["predicted"] / r["wall_time"] - 1.0) for r in fitted]
    overhead = [r["wall_time"] / r["predicted"] for r in runs if r["ranks"] > c and r["kind"] in ("strong", "weak")]
    return [
        f"**Validation.** On the {len(fitted)} measured runs with at most one rank per core the model's "
        f"solve-phase time is within {100 * np.median(errors):.0f} % in the median and {100 * max(errors):.0f} % "
        "at worst (column *model* above). The oversubscribed runs are overhead measurements: they take "
        f"{min(overhead):.1f}–{max(overhead):.1f}× the model.",
    ]


def _predictions(launch: LaunchModel, strong: list[dict], weak: list[dict]) -> list[str]:
    """The predicted strong and weak scaling on 64 to 1024 cores, and the launch around the solve phase."""
    lines = ["## Predictions for 64 to 1024 cores", "", "![model predictions](scaling-model.png)", ""]
    for title, rows in (("Strong scaling, P = 1600 (about 3M unknowns)", strong),
                        (f"Weak scaling, {WEAK_UNKNOWNS_PER_CORE:,} unknowns per core", weak)):
        lines += [f"**{title}** (seconds; the phases are those of `schur`; *auto*: what the default picks; "
                  "*launch*: auto's solve phase and the launch around it):", "",
                  "| cores | P | factorization | interface matrices | rounds | gather | rank-0 solve | `schur` total "
                  "| `mprgp` total | `feti` total | auto | launch |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            lines.append(f"| {r['ranks']} | {r['P']} | {r['factorization']:.3f} | {r['interface']:.3f} "
                         f"| {r['rounds']:.3f} | {r['gather']:.3f} | {r['rank0']:.3f} | {r['total']:.2f} "
                         f"| {r['mprgp']:.2f} | {r['feti']:.2f} | `{r['auto']}` | {r['launch']:.2f} |")
        lines.append("")
    rates = ", ".join(f"{phase} {1e6 * rate:.2f} µs" for phase, rate in launch.per_unknown.items())
    lines += [f"The launch around the solve phase (*launch* above) is fitted to the whole launches measured here: "
              f"{launch.constant:.2f} s for the start-up, the meshing (a coarse gmsh mesh and a refinement share) "
              f"and the distribution, and per unknown of the busiest rank {rates} (CPU seconds of one rank; the "
              "write assumes a file system whose bandwidth grows with the writers). The per-unknown phases shrink with "
              "the ranks; the constant does not (the start-up of Python, MPI and PETSc, gmsh's coarse mesh, rank "
              "0's checks of the whole mesh), and on many cores it is most of the launch."]
    return lines


def _limits(strong: list[dict], weak: list[dict]) -> list[str]:
    """Where the design stops scaling, and what the default method does about it."""
    crossover = next((r["ranks"] for r in weak if r["rank0"] > r["factorization"] + r["interface"]), None)
    return [
        "**Where the design stops scaling, and what the default does.** With distributed blocks `schur` needs "
        "the interface matrices by 2kΣ right-hand sides of multi-column solves (PETSc's MUMPS interface has no "
        "parallel Schur complement), and rank 0's dense interface solve does not shrink with the number of ranks "
        f"({strong[0]['rank0']:.1f} s at P = 1600"
        + (f"; in weak scaling it overtakes the block work at about {crossover} cores" if crossover else "") +
        "). `feti` needs neither: only block solves and products, rank 0's work per round is linear in the "
        "multipliers, and its rounds grow slowly with P. The default (`auto`) takes whichever the model predicts "
        "cheaper (`registry.choose`, with the per-block laws above and the contact steps of `./run bench contact`): "
        "`schur` on whole blocks, `feti` on every predicted configuration of distributed blocks here. What remains: `feti`'s active-set steps grow "
        "slowly with P, and its Dirichlet factorization doubles the factorization work and memory.",
    ]
