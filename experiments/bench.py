"""Benchmarks: every method against the monolithic reference, the default method against one MUMPS
factorization of the whole glued system, and the block factorization packages.

``ddsolve bench baseline`` launches one MPI job per scene and mesh (``bench-baseline``): rank 0 solves
the glued problem in one process with one MUMPS factorization (:func:`monolithic`) while the other
ranks sleep, then all ranks run the default method; the two alternate ``repeats`` times, so the ratio
is measured side by side.  With ``busy`` a second process keeps one core busy during the launch.

``ddsolve bench methods`` launches one MPI job per mesh (``ddsolve bench-mesh`` on 4 ranks). In that
job rank 0 computes the reference, all ranks measure the floor of any method with this DD structure
(one factorization and one solve of every block, with each package), then every method runs at
several tolerances; times are measured side by side in the same launch.  The results go to one
HDF5 file, a table in docs/results.md and a speed-against-error plot.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ddsolve.errors import DDSolveError
from experiments import report
from ddsolve.mesh.mesh import blocks as block_specs
from ddsolve.parallel import distribution
from ddsolve.problem import scene as scenes

if TYPE_CHECKING:
    from ddsolve.post.result import Result

#: The paper's Table 1 meshes (P, M) and one finer mesh.
TABLE1_MESHES = ((12, 32), (24, 48), (48, 80), (96, 144), (200, 256))
BENCH_MESHES = (*TABLE1_MESHES, (400, 512))
#: Tolerances per method for the speed-against-error curves; uzawa's first entry is the paper's setting.
TOLERANCES = {
    "schur": [("kkt", 1e-8)],
    "mprgp": [("kkt", 1e-4), ("kkt", 1e-6), ("kkt", 1e-8), ("kkt", 1e-10)],
    "fista": [("kkt", 1e-4), ("kkt", 1e-6), ("kkt", 1e-8)],
    "feti": [("kkt", 1e-4), ("kkt", 1e-6), ("kkt", 1e-8)],
    "uzawa": [("paper", 1e-6), ("relative", 1e-4), ("relative", 1e-6), ("relative", 1e-8)],
}
#: Above this P, uzawa runs only the paper's setting (each run takes minutes).
UZAWA_SWEEP_MAX_P = 200


@dataclass
class Run:
    P: int
    M: int
    method: str
    stop: str
    tol: float
    converged: bool
    iterations: int
    rounds: int
    wall_time: float
    factorization: float
    update: float
    energy_error: float
    penetration: float


def paper_scene(P: int, M: int, overrides: list[str] = (), name: str = "partial-closure") -> scenes.Scene:
    """Example 1 of the paper (or another built-in scene) on the (P, M) mesh."""
    return scenes.load(name, [f"mesh.sigma_vertices={P}", f"mesh.boundary_vertices={M}", *overrides])


# --- the strongest baseline: one MUMPS factorization of the glued system ---------------------
def monolithic(scene: scenes.Scene, mesh, systems) -> tuple[Result, dict]:
    """The glued problem in one process by the monolithic reference
    (:func:`ddsolve.solvers.reference.solve_assembled`: one MUMPS factorization, which also gives the Schur
    complement on the crack's jumps, the contact as the crack's small dense dual problem, then one solve with
    the contact forces) from the assembled ``systems``.

    Returns the result and its timings: ``merge`` (the glued matrix), ``factorization`` and
    ``solve`` (solves and the dense contact problem); ``factorization + solve`` is the solve phase;
    ``merge_cpu``, ``factorization_cpu`` and ``solve_cpu`` are CPU seconds.
    """
    from ddsolve.solvers import reference

    result = reference.solve_assembled(scene, mesh, systems)
    return result, result.timings


#: Orderings of the monolithic baseline: MUMPS's own choice (its defaults: what a user gets) and AMF
#: (what ddsolve asks for its blocks, faster here): the ratio is reported against both.
MONOLITHIC_ORDERINGS = {"mumps default": 7, "AMF": 2}


def bench_baseline(name: str, P: int, M: int, repeats: int, output: Path, comm) -> None:
    """Inside one launch: the monolithic MUMPS solve on rank 0 (the other ranks sleep), once with each
    of :data:`MONOLITHIC_ORDERINGS`, and the default method on all ranks, in turn ``repeats`` times,
    then :func:`phase_account` on rank 0; rank 0 writes the record as JSON (wall and CPU seconds of
    the solve phases: the CPU time of the DD sums its ranks)."""
    from petsc4py import PETSc

    from ddsolve.fem import assembly
    from ddsolve.parallel.exchange import collective
    from ddsolve.parallel.launch import provenance
    from ddsolve.post import analysis
    from ddsolve.solvers import driver

    scene = paper_scene(P, M, name=name)
    mesh = distribution.build_mesh(scene, comm)
    systems = assembly.block_systems(scene, mesh) if comm.rank == 0 else None
    record = {"scene": name, "P": P, "M": M, "ranks": comm.size, "load": os.getloadavg()[0],
              "unknowns": sum(2 * len(mesh.half(spec.side).points) for spec in block_specs(scene.geometry.layers)),
              "dd": [],
              **{f"mono {label}": [] for label in MONOLITHIC_ORDERINGS}}

    def timed(label, ordering):
        options = PETSc.Options()
        options["reference_mat_mumps_icntl_7"] = ordering
        try:
            result, timings = monolithic(scene, mesh, systems)
        finally:
            options.delValue("reference_mat_mumps_icntl_7")
        return result, {**timings, "solve_phase": timings["factorization"] + timings["solve"],
                        "cpu": timings["factorization_cpu"] + timings["solve_cpu"]}

    for _ in range(repeats):
        monos = {label: collective(comm, lambda: timed(label, ordering), root_only=True)
                 for label, ordering in MONOLITHIC_ORDERINGS.items()}
        dd = driver.solve_decomposed(scene, comm, None, progress=lambda line: None, mesh=mesh)
        if comm.rank == 0:
            for label, (reference, timings) in monos.items():
                record[f"mono {label}"].append(timings)
            record["dd"].append({"solve_phase": dd.wall_time, "method": dd.method, "rounds": dd.solves,
                                 "factorization": dd.timings["factorization"],
                                 "cpu": dd.timings["factorization_cpu"] + dd.timings["iterations_cpu"],
                                 "error": analysis.compare(dd, reference).energy_error})
    record["account"] = collective(comm, lambda: phase_account(scene, mesh, systems), root_only=True)
    if comm.rank == 0:
        record["load_after"] = os.getloadavg()[0]
        record["provenance"] = provenance()
        output.write_text(json.dumps(record))


#: Phases of :func:`phase_account`: what each side does once the matrices are assembled.
ACCOUNT_PHASES = ("assembly", "analysis", "numeric factorization", "Schur extraction", "interface solve",
                  "solves", "rounds, other")
#: PETSc's events (``-log_view`` names) that time the phases inside the factorizations and solves.
ACCOUNT_EVENTS = {"analysis": "MatCholFctrSym", "numeric factorization": "MatCholFctrNum", "solves": "MatSolve"}
#: Phases of the DD that the ranks share (block work); the interface solve runs on rank 0 alone.
PARALLEL_PHASES = ("assembly", "analysis", "numeric factorization", "Schur extraction", "solves", "rounds, other")


def _event_seconds() -> dict[str, float]:
    """Seconds in each of :data:`ACCOUNT_EVENTS` so far, over every logging stage of this process."""
    from petsc4py import PETSc

    from ddsolve.solvers.driver import STAGES

    stages = [0, *(PETSc.Log.Stage(name).id for name in STAGES)]
    return {phase: sum(PETSc.Log.Event(name).getPerfInfo(stage)["time"] for stage in stages)
            for phase, name in ACCOUNT_EVENTS.items()}


def phase_account(scene: scenes.Scene, mesh, systems) -> dict[str, dict[str, float]]:
    """CPU seconds per phase (:data:`ACCOUNT_PHASES`) of the default method with all four blocks in
    this process, and of the monolithic AMF solve, one after the other in one process.

    Phases inside MUMPS (:data:`ACCOUNT_EVENTS`) split the CPU seconds of the phase that holds them in
    proportion of PETSc's event times to the phase's wall time (on a loaded machine wall time is
    not CPU time).  The DD's ``assembly`` is the block matrices (the monolithic's: the glued matrix,
    built from them); ``Schur extraction`` the factorization phase beyond MUMPS's analysis and
    numeric factorization (copying S_b, factoring it for the solves); ``interface solve`` rank 0's
    dense solve between rounds (the monolithic's: its dense contact problem); ``rounds, other`` the
    rest of the rounds (messages, traces, checks).
    """
    from mpi4py import MPI
    from petsc4py import PETSc

    from ddsolve.solvers import driver

    def share(cpu: float, wall: float, seconds: float) -> float:
        return cpu * seconds / wall if wall > 0.0 else 0.0

    PETSc.Log.begin()
    before = _event_seconds()
    dd = driver.solve_decomposed(scene, MPI.COMM_SELF, None, progress=lambda line: None, mesh=mesh)
    events = {phase: seconds - before[phase] for phase, seconds in _event_seconds().items()}
    t = dd.timings
    analysis = share(t["factorization_cpu"], t["factorization"], events["analysis"])
    numeric = share(t["factorization_cpu"], t["factorization"], events["numeric factorization"])
    solves = share(t["iterations_cpu"], t["iterations"], events["solves"])
    interface = share(t["iterations_cpu"], t["iterations"], t["update"])
    dd_phases = {"assembly": t["assembly_cpu"], "analysis": analysis, "numeric factorization": numeric,
                 "Schur extraction": max(t["factorization_cpu"] - analysis - numeric, 0.0),
                 "interface solve": interface, "solves": solves,
                 "rounds, other": max(t["iterations_cpu"] - interface - solves, 0.0)}
    options = PETSc.Options()
    options["reference_mat_mumps_icntl_7"] = MONOLITHIC_ORDERINGS["AMF"]
    before = _event_seconds()
    try:
        _, t = monolithic(scene, mesh, systems)
    finally:
        options.delValue("reference_mat_mumps_icntl_7")
    events = {phase: seconds - before[phase] for phase, seconds in _event_seconds().items()}
    analysis = share(t["factorization_cpu"], t["factorization"], events["analysis"])
    numeric = share(t["factorization_cpu"], t["factorization"], events["numeric factorization"])
    solves = share(t["solve_cpu"], t["solve"], events["solves"])
    mono_phases = {"assembly": t["merge_cpu"], "analysis": analysis, "numeric factorization": numeric,
                   "Schur extraction": max(t["factorization_cpu"] - analysis - numeric, 0.0),
                   "interface solve": max(t["solve_cpu"] - solves, 0.0), "solves": solves, "rounds, other": 0.0}
    return {"dd": dd_phases, "mono": mono_phases}


def structure_bound(account: dict[str, dict[str, float]], ranks: int) -> float:
    """The largest wall-time ratio monolithic / DD that the DD's measured work allows on ``ranks``
    ranks: block work (:data:`PARALLEL_PHASES`) shared perfectly, rank 0's interface solve added;
    solve phases only (no assembly on either side)."""
    dd, mono = account["dd"], account["mono"]
    shared = sum(dd[phase] for phase in PARALLEL_PHASES if phase != "assembly")
    alone = sum(dd[phase] for phase in ACCOUNT_PHASES if phase not in PARALLEL_PHASES)
    return sum(mono[phase] for phase in ACCOUNT_PHASES if phase != "assembly") / (shared / ranks + alone)


def busy_process():
    """A process that keeps one core busy until it is killed."""
    import subprocess
    import sys

    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def default_ranks() -> int:
    """Ranks of the DD in ``bench baseline``: a block per rank, but no more ranks than cores."""
    return max(1, min(4, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()))


def baseline(meshes=((400, 512), (800, 1024)), names=("linear", "partial-closure"), ranks: int | None = None,
             repeats: int = 3, busy: bool = False, output: Path = Path("results/bench-baseline.h5"),
             docs: Path = Path("docs")) -> list[dict]:
    """The default method against the monolithic MUMPS solve, side by side; print the ratios and the
    per-phase account, and write it into docs/methods.md (section ``bench-baseline``)."""
    ranks = ranks or default_ranks()
    output.parent.mkdir(parents=True, exist_ok=True)
    records = []
    for P, M in meshes:
        for name in names:
            spinner = busy_process() if busy else None
            try:
                record = report.launch(ranks, ["bench-baseline", name, str(P), str(M), str(repeats)],
                                       output.with_name(f".{output.stem}-{name}-{P}.json"))
            finally:
                if spinner is not None:
                    spinner.kill()
                    spinner.wait()
            record["busy"] = busy
            records.append(record)
            print(baseline_line(record), flush=True)
            print("\n".join(account_lines(record)), flush=True)
    report.write_records(output, records, records[0]["provenance"])
    report.section(docs / "methods.md", "bench-baseline", account_table(records))
    return records


def baseline_line(record: dict) -> str:
    """One case: best times of each side, the ratio per side-by-side pair, the DD's error and the load."""
    dd = record["dd"]
    parts = [f"{record['scene']:15s} P={record['P']:5d} ({record['unknowns']:,} unknowns), DD {dd[0]['method']} on "
             f"{record['ranks']} ranks{' + 1 busy process' if record['busy'] else ''}: DD solve phase "
             f"{min(d['solve_phase'] for d in dd):.3f} s (CPU {min(d['cpu'] for d in dd):.2f} s)"]
    for label in MONOLITHIC_ORDERINGS:
        mono = record[f"mono {label}"]
        ratios = sorted(m["solve_phase"] / d["solve_phase"] for m, d in zip(mono, dd))
        cpu = min(m["cpu"] for m in mono) / min(d["cpu"] for d in dd)
        parts.append(f"monolithic MUMPS ({label}) {min(m['solve_phase'] for m in mono):.3f} s (CPU "
                     f"{min(m['cpu'] for m in mono):.2f} s): ratio {np.median(ratios):.2f} median, "
                     f"{ratios[0]:.2f}-{ratios[-1]:.2f}; CPU ratio {cpu:.2f}")
    parts.append(f"DD error {max(d['error'] for d in dd):.1e}; load {record['load']:.1f} -> {record['load_after']:.1f}")
    return "; ".join(parts)


def account_lines(record: dict) -> list[str]:
    """The per-phase account of one case, a line per phase: DD and monolithic CPU seconds."""
    dd, mono = record["account"]["dd"], record["account"]["mono"]
    lines = [f"  {'phase (CPU s, one process)':28s} {'DD':>8s} {'monolithic':>11s}"]
    lines += [f"  {phase:28s} {dd[phase]:8.3f} {mono[phase]:11.3f}" for phase in ACCOUNT_PHASES]
    solve = {side: sum(v for k, v in phases.items() if k != "assembly") for side, phases in (("dd", dd), ("mono", mono))}
    lines.append(f"  {'solve phase':28s} {solve['dd']:8.3f} {solve['mono']:11.3f}   DD / monolithic CPU "
                 f"{solve['dd'] / solve['mono']:.2f}; wall ratio the DD's work allows on {record['ranks']} ranks: "
                 f"{structure_bound(record['account'], record['ranks']):.2f}")
    return lines


def account_table(records: list[dict]) -> str:
    """Markdown for docs/methods.md: the side-by-side ratios and the per-phase account of every case."""
    lines = ["`./run bench baseline` (one launch per scene and mesh on "
             f"{records[0]['ranks']} ranks, {len(records[0]['dd'])} side-by-side pairs; machine load "
             f"{min(r['load'] for r in records):.1f}–{max(r['load'] for r in records):.1f}): the default method "
             "against one MUMPS factorization of the whole glued problem with AMF ordering. Wall: best solve "
             "phase of each side; ratio: monolithic / DD, median of the pairs; CPU: solve phase, the DD's summed "
             "over its ranks.", "",
             "| scene | P | unknowns | DD wall (s) | DD CPU (s) | monolithic wall (s) | monolithic CPU (s) "
             "| wall ratio | CPU DD / monolithic | ratio the DD's work allows |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for record in records:
        dd, mono = record["dd"], record["mono AMF"]
        ratio = np.median([m["solve_phase"] / d["solve_phase"] for m, d in zip(mono, dd)])
        lines.append(f"| {record['scene']} | {record['P']} | {record['unknowns']:,} "
                     f"| {min(d['solve_phase'] for d in dd):.3f} | {min(d['cpu'] for d in dd):.2f} "
                     f"| {min(m['solve_phase'] for m in mono):.3f} | {min(m['cpu'] for m in mono):.2f} | {ratio:.2f} "
                     f"| {min(d['cpu'] for d in dd) / min(m['cpu'] for m in mono):.2f} "
                     f"| {structure_bound(record['account'], record['ranks']):.2f} |")
    lines += ["", "Per phase, CPU seconds in one process (DD: all four blocks; phases inside "
              "MUMPS: the CPU seconds of the factorization or of the rounds split in proportion of PETSc's event times). "
              "*Ratio the DD's work allows*: monolithic solve phase / (the DD's block work shared perfectly among "
              "the ranks + rank 0's interface solve).", "",
              "| scene | P | side | " + " | ".join(ACCOUNT_PHASES) + " | solve phase |",
              "|---|---|---|" + "---|" * (len(ACCOUNT_PHASES) + 1)]
    for record in records:
        for side, label in (("dd", "DD"), ("mono", "monolithic")):
            phases = record["account"][side]
            lines.append(f"| {record['scene']} | {record['P']} | {label} | "
                         + " | ".join(f"{phases[phase]:.3f}" for phase in ACCOUNT_PHASES)
                         + f" | {sum(v for k, v in phases.items() if k != 'assembly'):.3f} |")
    return "\n".join(lines)


# --- inside the MPI launch ------------------------------------------------------------------
def floor_time(scene: scenes.Scene, mesh, comm, package: str) -> float:
    """Wall time for one factorization and one solve of every block, all ranks together."""
    from ddsolve.fem.supports import sigma_supports
    from ddsolve.parallel.distribution import whole
    from ddsolve.parallel.exchange import Exchange
    from ddsolve.solvers.driver import cut_pieces, make_blocks

    specs = block_specs(scene.geometry.layers)
    exchange = Exchange(comm, len(specs))
    local = whole(mesh, table=sigma_supports(scene, mesh))
    blocks = make_blocks(scene, local, exchange, package, cut_pieces(local, exchange, specs))
    comm.Barrier()
    started = time.perf_counter()
    for block in blocks:
        block.factor()
        block.solve(np.zeros(len(block.trace_dofs)), body=True)
    comm.Barrier()
    elapsed = time.perf_counter() - started
    for block in blocks:
        block.destroy()
    exchange.free()
    return comm.bcast(elapsed, root=0)


def method_runs() -> list[tuple[str, str, float]]:
    """(method, stop, tol) of ``bench methods``."""
    return [(method, stop, tol) for method, settings in TOLERANCES.items() for stop, tol in settings]


#: Runs of ``table1``: the paper's algorithm and the default method.
#: The default method for whole blocks (4 ranks), which ``auto`` resolves to.
DEFAULT = "schur"
TABLE1_RUNS = [("uzawa", "paper", 1e-6), (DEFAULT, "kkt", 1e-8)]
PLANS = {"methods": (method_runs, True), "table1": (lambda: TABLE1_RUNS, False)}


def bench_mesh(plan: str, P: int, M: int, output: Path, comm) -> None:
    """On one mesh: statistics, the reference, the floor (if the plan wants it) and the plan's runs.

    Every rank takes part; rank 0 writes the record as JSON to ``output``.
    """
    from ddsolve.mesh import geometry
    from ddsolve.mesh import mesh as meshes
    from ddsolve.parallel.launch import provenance
    from ddsolve.post import analysis
    from ddsolve.solvers import driver, reference

    runs, with_floor = PLANS[plan]
    base = paper_scene(P, M)
    mesh = comm.bcast(geometry.build(base) if comm.rank == 0 else None, root=0)
    record: dict = {"P": P, "M": M, "vertices": [len(half.points) for half in mesh.halves],
                    "mesh": {half.name: asdict(meshes.statistics(half)) for half in mesh.halves}, "runs": []}
    ref = None
    if comm.rank == 0:
        ref = reference.solve_monolithic(base, mesh)
        record["reference_time"] = ref.wall_time
        record["reference_steps"] = ref.iterations
    comm.Barrier()
    if with_floor:
        record["floor"] = {package: floor_time(base, mesh, comm, package) for package in ("mumps", "petsc")}
    for method, stop, tol in runs():
        if method == "uzawa" and P > UZAWA_SWEEP_MAX_P and stop != "paper":
            continue
        scene = paper_scene(P, M, [f"solver.method={method}", f"solver.stop={stop}", f"solver.tol={tol}"])
        try:
            result = driver.solve_decomposed(scene, comm, None, progress=lambda line: None, mesh=mesh)
        except DDSolveError as exc:
            if comm.rank == 0:
                print(f"  P={P} {method} {stop} {tol:g}: {exc}", flush=True)
            continue
        if comm.rank == 0:
            run = Run(P, M, method, stop, tol, result.converged, result.iterations, result.solves,
                      result.wall_time, result.timings["factorization"], result.timings["update"],
                      analysis.compare(result, ref).energy_error, analysis.constraints(result).penetration)
            record["runs"].append(asdict(run))
            print(f"  P={P:4d} {method:6s} {stop:8s} tol {tol:7.0e}: {run.rounds:6d} rounds "
                  f"{run.wall_time:8.3f} s  error {run.energy_error:.2e}", flush=True)
    if comm.rank == 0:
        record["provenance"] = provenance()
        output.write_text(json.dumps(record))


# --- the serial driver ----------------------------------------------------------------------
def methods(meshes=BENCH_MESHES, output: Path = Path("results/bench-methods.h5"),
            docs: Path = Path("docs")) -> list[dict]:
    """Run :func:`bench_mesh` in one 4-rank launch per mesh; write HDF5, the docs table and plot."""
    output.parent.mkdir(parents=True, exist_ok=True)
    records = []
    for P, M in meshes:
        print(f"bench methods: P = {P}, M = {M}", flush=True)
        records.append(report.launch(4, ["bench-mesh", "methods", str(P), str(M)],
                                     output.with_name(f".{output.stem}-{P}.json")))
    report.write_records(output, records, records[0]["provenance"])
    report.section(docs / "results.md", "bench-methods", methods_table(records))
    speed_error_plot(records, docs / "bench-methods.png")
    return records


def _default_run(record: dict) -> dict:
    return next(r for r in record["runs"] if r["method"] == DEFAULT)


def _paper_run(record: dict) -> dict | None:
    return next((r for r in record["runs"] if r["method"] == "uzawa" and r["stop"] == "paper"), None)


def methods_table(records: list[dict]) -> str:
    """Markdown: the summary per mesh, then every run."""
    lines = [
        "*default*: `schur`; *paper*: `uzawa` with θ = 65 and the paper's stop rule; *floor*: one factorization "
        "and one solve of every block with the cheaper package, the least any method with this DD structure can "
        "take; DOFs: all four blocks.",
        "",
        "| P | M | DOFs | reference (s) | floor (s) | default rounds | default (s) | default / floor | default error "
        "| paper rounds | paper (s) | paper error | rounds ratio | time ratio | reference / default |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for record in records:
        best = _default_run(record)
        paper = _paper_run(record)
        floor = min(record["floor"].values())
        dofs = 4 * sum(record["vertices"])
        paper_cells = ("| — " * 5) if paper is None else (
            f"| {paper['rounds']} | {paper['wall_time']:.3f} | {paper['energy_error']:.1e} "
            f"| {paper['rounds'] / best['rounds']:.0f}× | {paper['wall_time'] / best['wall_time']:.0f}× ")
        lines.append(
            f"| {record['P']} | {record['M']} | {dofs} | {record['reference_time']:.3f} | {floor:.3f} "
            f"| {best['rounds']} | {best['wall_time']:.3f} | {best['wall_time'] / floor:.2f} "
            f"| {best['energy_error']:.1e} {paper_cells}| {record['reference_time'] / best['wall_time']:.1f}× |")
    largest = records[-1]
    best, paper = _default_run(largest), _paper_run(largest)
    per_floor = [_default_run(r)["wall_time"] / min(r["floor"].values()) for r in records[-2:]]
    at_200 = next((r for r in records if r["P"] == 200), largest)
    lines += ["", "![wall time against energy error per method](bench-methods.png)", "",
              f"The default method needs {best['rounds']} rounds of block solves on every mesh and reaches round-off "
              f"accuracy; on the two finest meshes its solve phase takes {min(per_floor):.2f}–{max(per_floor):.2f} "
              "times the floor (one factorization and one solve of every block). It is "
              f"{_paper_run(at_200)['wall_time'] / _default_run(at_200)['wall_time']:.0f}× faster than the paper's "
              f"iteration at P = {at_200['P']} and "
              + (f"{paper['wall_time'] / best['wall_time']:.0f}× at P = {largest['P']}, where the paper's Uzawa needs "
                 f"{paper['rounds']} rounds. " if paper else ". ") +
              "Of the iterative methods MPRGP is the fastest, its rounds growing roughly like h^-1/2; Uzawa with "
              f"the `relative` rule is shown for P ≤ {UZAWA_SWEEP_MAX_P} only.",
              "", "All runs (error: relative energy-norm error against the reference; penetration: max (u⁻ − u⁺)·ν "
              "/ max |u|):", "",
              "| P | method | stop | tol | rounds | wall (s) | factorization (s) | rank-0 update (s) | error | penetration |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for record in records:
        for run in record["runs"]:
            lines.append(f"| {run['P']} | {run['method']} | {run['stop']} | {run['tol']:.0e} | {run['rounds']} "
                         f"| {run['wall_time']:.3f} | {run['factorization']:.3f} | {run['update']:.3f} "
                         f"| {run['energy_error']:.1e} | {run['penetration']:.1e} |")
    return "\n".join(lines)


def speed_error_plot(records: list[dict], path: Path) -> None:
    """Wall time against energy error, one curve per method, one panel per mesh (the largest three)."""
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    shown = records[-3:]
    fig, axes = plt.subplots(1, len(shown), figsize=(5 * len(shown), 4.2), constrained_layout=True, squeeze=False)
    for ax, record in zip(axes[0], shown):
        for method in TOLERANCES:
            runs = [r for r in record["runs"] if r["method"] == method and r["stop"] != "paper"]
            if runs:
                ax.loglog([r["wall_time"] for r in runs], [max(r["energy_error"], 1e-16) for r in runs],
                          marker="o", label=method)
        paper = _paper_run(record)
        if paper is not None:
            ax.loglog([paper["wall_time"]], [paper["energy_error"]], marker="*", markersize=12, linestyle="none",
                      color="black", label="uzawa, paper's rule")
        ax.axvline(min(record["floor"].values()), color="gray", linestyle=":", label="floor")
        ax.axvline(record["reference_time"], color="gray", linestyle="--", label="monolithic reference")
        ax.set_title(f"P = {record['P']}, M = {record['M']}")
        ax.set_xlabel("wall time of the solve phase (s)")
        ax.set_ylabel("relative energy error")
        ax.grid(alpha=0.3, which="both")
    axes[0][0].legend(fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def block_timings(P: int, M: int, solves: int = 20, repeats: int = 3) -> dict:
    """One block of the (P, M) mesh, best of ``repeats``: factorization, one solve and the interface
    matrix, for each factorization package (with MUMPS also with the Schur complement requested)."""
    from ddsolve.fem import assembly
    from ddsolve.mesh import geometry
    from ddsolve.parallel.blocks import Block, default_factor_package

    scene = paper_scene(P, M)
    system = assembly.block_systems(scene, geometry.build(scene), [0])[0]
    out = {"P": P, "M": M, "unknowns": system.size, "trace": len(system.trace_dofs)}
    for package, schur in (("petsc", False), ("mumps", False), ("mumps", True)):
        if default_factor_package(package) != package:
            continue
        best = np.full(3, np.inf)
        for _ in range(repeats):  # the first MUMPS call also pays its initialization
            block = Block(system, factor_package=package)
            started = time.perf_counter()
            block.factor(schur=schur)
            factor_time = time.perf_counter() - started
            load = np.ones(len(system.trace_dofs))
            started = time.perf_counter()
            for _ in range(solves):
                block.solve(load, body=False)
            solve_time = (time.perf_counter() - started) / solves
            started = time.perf_counter()
            block.schur_complement() if schur else block.flexibility()
            interface_time = time.perf_counter() - started
            block.destroy()
            best = np.minimum(best, [factor_time, solve_time, interface_time])
        out[package + ("_schur" if schur else "")] = {"factor": best[0], "solve": best[1], "interface": best[2]}
    return out


def factor(P: int = 200, M: int = 256) -> None:
    """Print the block factorization packages' timings side by side on one block of the (P, M) mesh."""
    t = block_timings(P, M)
    print(f"block u_minus of P = {P}, M = {M}: {t['unknowns']} unknowns, trace {t['trace']}")
    labels = {"petsc": "petsc", "mumps": "mumps", "mumps_schur": "mumps + Schur complement"}
    for key, label in labels.items():
        if key in t:
            row = t[key]
            print(f"  {label:26s} factor {row['factor'] * 1e3:8.1f} ms   solve {row['solve'] * 1e3:7.2f} ms   "
                  f"interface matrix {row['interface'] * 1e3:8.1f} ms")
    if "petsc" in t and "mumps" in t:
        p, m = t["petsc"], t["mumps"]
        print(f"  ratios mumps/petsc: factor {m['factor'] / p['factor']:.2f}, solve {m['solve'] / p['solve']:.2f}, "
              f"flexibility by multi-column solves {m['interface'] / p['interface']:.2f}")
    if "mumps_schur" in t and "mumps" in t:
        s, m = t["mumps_schur"], t["mumps"]
        print(f"  Schur complement from the factorization: factor time {s['factor'] / m['factor']:.2f}x the plain "
              f"one; the interface matrix {m['interface'] / s['interface']:.0f}x faster than by multi-column solves")
