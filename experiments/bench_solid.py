"""The 3-D case of ``bench baseline``: the default decomposition of a 3-D box against one MUMPS factorization of the
whole glued system in one process, side by side, the peak memory of each, and how the decomposition's rounds grow
with the mesh and the slabs.

The box is the 3-D page's (experiments/three_d.py: the paper's square cut by Σ with the crack (−½, ½), extruded
over [0, ½] with rollers on the z faces), the crack pulled open with its faces free (a linear problem), P1.  One
launch on 2 ranks (``bench-baseline-3d``) builds the mesh once; in turn ``repeats`` times, rank 0 solves the glued
system in one process with each of METIS's and AMF's orderings while the other rank sleeps, then both ranks run
the decomposition with the scene's defaults (``solver.pieces`` and feti's preconditioner chosen by it), and last
the decomposition once at each of several ``solver.tol`` (its speed against its error).  The solve
phase is the factorization and the solves (the monolithic's) or the factorization and the method's rounds (the
decomposition's); setup and assembly are reported apart.  Peak memory comes from launches of their own
(``bench-memory-3d``): the monolithic alone in one process, the decomposition alone on 2 ranks (their sum).
"""
from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path

import numpy as np

from experiments import report, three_d

#: mesh.size of the 3-D case: about 0.3 M unknowns (P1).
SIZE = 0.026
#: Orderings of the monolithic solve: the faster of them is the baseline.
ORDERINGS = {"METIS": 5, "AMF": 2}
#: Ranks of the decomposition.
RANKS = 2
#: The decomposition's solver.tol for the speed against error, one run each after the pairs.
TOLERANCES = (1e-4, 1e-6, 1e-8, 1e-10)


def scene_of(size: float):
    """The 3-D page's box pulled open, its crack faces free."""
    return three_d.scene_of("opening", size, 3).with_({"contact.nonpenetration": False})


def bench_solid(size: float, repeats: int, output: Path, comm) -> None:
    """Inside one launch: the monolithic solve on rank 0 (each ordering; the other ranks sleep) and the
    decomposition on every rank, in turn ``repeats`` times, then the decomposition once at each of
    :data:`TOLERANCES`; rank 0 writes the record as JSON."""
    from petsc4py import PETSc

    from ddsolve.mesh import solid as solid_meshes
    from ddsolve.parallel.exchange import collective
    from ddsolve.solvers import solid as solid_solver

    scene = scene_of(size)
    mesh = comm.bcast(collective(comm, lambda: solid_meshes.build(scene), root_only=True), root=0)
    record = {"size": size, "unknowns": mesh.unknowns, "ranks": comm.size, "load": os.getloadavg()[0], "dd": [],
              **{f"mono {label}": [] for label in ORDERINGS}}

    def monolithic(ordering: int) -> tuple[object, dict]:
        options = PETSc.Options()
        options["reference_mat_mumps_icntl_7"] = ordering
        cpu = time.process_time()
        try:
            result = solid_solver.solve_solid(scene, mesh)
        finally:
            options.delValue("reference_mat_mumps_icntl_7")
        t = result.timings
        return result, {"merge": t["merge"], "solve_phase": t["factorization"] + t["solve"],
                        "factorization": t["factorization"], "cpu": time.process_time() - cpu}

    reference = None
    for _ in range(repeats):
        for label, ordering in ORDERINGS.items():
            solved = collective(comm, lambda: monolithic(ordering), root_only=True)
            if comm.rank == 0:
                reference, timings = solved
                record[f"mono {label}"].append(timings)
        record["dd"].append(decomposed(scene, mesh, reference, comm))
    record["tolerances"] = [decomposed(scene.with_({"solver.tol": tol}), mesh, reference, comm)
                           for tol in TOLERANCES]
    if comm.rank == 0:
        record["load_after"] = os.getloadavg()[0]
        output.write_text(json.dumps(record))


def decomposed(chosen, mesh, reference, comm) -> dict | None:
    """The decomposition of the scene ``chosen`` on ``mesh`` on every rank of ``comm``: rank 0's record of its phases,
    CPU, what it ran and its error against ``reference`` (None elsewhere)."""
    from ddsolve.solvers import solid as solid_solver, solid_dd

    cpu = time.process_time()
    dd = solid_dd.solve(chosen, comm, None, progress=lambda line: None, mesh=mesh)
    cpus = comm.gather(time.process_time() - cpu, root=0)
    if comm.rank != 0:
        return None
    t = dd.timings
    method = t["total"] - t.get("meshing", 0.0) - t["setup"] - t["assembly"] - t["factorization"]
    return {"setup": t["setup"] + t["assembly"], "factorization": t["factorization"], "rounds_time": method,
            "solve_phase": t["factorization"] + method, "cpu": float(sum(cpus)), "cpu_largest": float(max(cpus)),
            "method": dd.scene.solver.method, "preconditioner": dd.scene.solver.preconditioner,
            "pieces": dd.scene.solver.pieces, "tol": dd.scene.solver.tol, "iterations": dd.steps,
            "rounds": dd.solves, "error": solid_solver.energy_error(dd, reference)}


def memory(side: str, size: float, output: Path, comm) -> None:
    """Inside a launch of its own: one side only (``mono``: the monolithic solve in one process; ``dd``: the
    decomposition on every rank), each rank's peak resident memory (MB) as JSON."""
    from ddsolve.solvers import solid as solid_solver, solid_dd

    scene = scene_of(size)
    if side == "mono":
        from ddsolve.mesh import solid as solid_meshes

        solid_solver.solve_solid(scene, solid_meshes.build(scene))
    else:
        solid_dd.solve(scene, comm, None, progress=lambda line: None)
    peaks = comm.gather(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, root=0)
    if comm.rank == 0:
        output.write_text(json.dumps({"side": side, "peaks": peaks}))


def baseline(size: float = SIZE, repeats: int = 3, output: Path = Path("results/bench-baseline-3d.json"),
             docs: Path = Path("docs")) -> dict:
    """The 3-D case: the side-by-side launch, the two memory launches; print the lines and write the record and
    its section of docs/methods.md (``bench-baseline-3d``)."""
    output.parent.mkdir(parents=True, exist_ok=True)
    record = report.launch(RANKS, ["bench-baseline-3d", str(size), str(repeats)],
                           output.with_name(f".{output.stem}-times.json"))
    record["memory"] = {side: report.launch(1 if side == "mono" else RANKS, ["bench-memory-3d", side, str(size)],
                                            output.with_name(f".{output.stem}-{side}.json"))["peaks"]
                        for side in ("mono", "dd")}
    print("\n".join(summary(record)), flush=True)
    record["rounds"] = rounds()
    output.write_text(json.dumps(record))
    speed_error_plot(record, docs / "bench-3d.png")
    report.section(docs / "methods.md", "bench-baseline-3d", table(record) + "\n\n" + tolerance_text(record)
                   + "\n\nHow the rounds grow with the mesh and the slabs, in one process on the same box:\n\n"
                   + rounds_table(record["rounds"]))
    return record


def ratios(record: dict) -> tuple[str, list[float]]:
    """The faster ordering of the monolithic solve and the ratios monolithic / decomposition of its solve phase,
    pair by pair."""
    best = min(ORDERINGS, key=lambda label: min(m["solve_phase"] for m in record[f"mono {label}"]))
    return best, sorted(m["solve_phase"] / d["solve_phase"] for m, d in zip(record[f"mono {best}"], record["dd"]))


def bests(record: dict) -> dict[str, dict[str, float]]:
    """Each side's best seconds of the pairs (``dd`` and each ordering's label): solve phase, factorization, setup
    (the monolithic's merge) and CPU."""
    sides = {"dd": record["dd"], **{label: record[f"mono {label}"] for label in ORDERINGS}}
    return {side: {key: min(r["merge" if key == "setup" and side != "dd" else key] for r in runs)
                   for key in ("solve_phase", "factorization", "setup", "cpu")} for side, runs in sides.items()}


def summary(record: dict) -> list[str]:
    """The case in a few lines: each side's best solve phase, the ratios, the memory."""
    best, pairs = ratios(record)
    seconds, first = bests(record), record["dd"][0]
    dd = seconds["dd"]
    lines = [f"3-D box, {record['unknowns']:,} unknowns (P1), load {record['load']:.1f} -> {record['load_after']:.1f}: "
             f"DD {first['method']} (slabs per half: {first['pieces']}, {first['preconditioner']} preconditioner), "
             f"{first['iterations']} iterations, {first['rounds']} rounds, on {record['ranks']} ranks: solve phase "
             f"{dd['solve_phase']:.2f} s (factorization {dd['factorization']:.2f} s), setup and assembly "
             f"{dd['setup']:.2f} s, CPU {dd['cpu']:.1f} s, error {max(d['error'] for d in record['dd']):.1e}"]
    lines += [f"  monolithic MUMPS ({label}): solve phase {seconds[label]['solve_phase']:.2f} s, merge "
              f"{seconds[label]['setup']:.2f} s, CPU {seconds[label]['cpu']:.1f} s" for label in ORDERINGS]
    lines.append(f"  ratio monolithic ({best}) / DD, solve phases: {np.median(pairs):.2f} median ({pairs[0]:.2f}-"
                 f"{pairs[-1]:.2f}); peak memory: monolithic {record['memory']['mono'][0]:.0f} MB, DD "
                 f"{sum(record['memory']['dd']):.0f} MB ({' + '.join(f'{m:.0f}' for m in record['memory']['dd'])})")
    return lines


def table(record: dict) -> str:
    """Markdown for docs/methods.md."""
    best, pairs = ratios(record)
    seconds, first = bests(record), record["dd"][0]
    memory = {"dd": sum(record["memory"]["dd"]), **{label: record["memory"]["mono"][0] for label in ORDERINGS}}
    rows = ["`./run bench baseline` (or `./run bench baseline-3d` alone), the 3-D case: the 3-D page's box pulled open "
            f"with its crack faces free (linear), P1 at mesh.size {record['size']:g}, {record['unknowns']:,} unknowns; "
            f"the decomposition with its defaults ({first['method']}, slabs per half: {first['pieces']}, "
            f"{first['preconditioner']} preconditioner, {first['iterations']} iterations, {first['rounds']} rounds) on "
            f"{record['ranks']} ranks against one MUMPS factorization of the whole glued system in one process, "
            f"{len(record['dd'])} side-by-side pairs in one launch (machine load {record['load']:.1f} before, "
            f"{record['load_after']:.1f} after). Seconds: the best of each side; ratio: monolithic / DD per pair "
            "(median, range), solve phases (factorization and solves, or factorization and rounds); CPU: the whole "
            "call, the DD's summed over its ranks; peak memory from launches of their own (the DD's: the sum of its "
            "ranks).", "",
            "| side | solve phase (s) | factorization (s) | setup and assembly (s) | CPU (s) | peak memory (MB) |",
            "|---|---|---|---|---|---|"]
    for side, name in (("dd", f"DD, {record['ranks']} ranks"), *((label, f"monolithic, {label}") for label in ORDERINGS)):
        row = seconds[side]
        rows.append(f"| {name} | {row['solve_phase']:.2f} | {row['factorization']:.2f} | {row['setup']:.2f} "
                    f"| {row['cpu']:.1f} | {memory[side]:.0f} |")
    rows += ["", f"Ratio monolithic ({best}, the faster) / DD of the solve phases: {np.median(pairs):.2f} (pairs "
             f"{', '.join(f'{p:.2f}' for p in pairs)}); the DD's energy-norm difference from the monolithic solution "
             f"{max(d['error'] for d in record['dd']):.1e}."]
    return "\n".join(rows)


def tolerance_text(record: dict) -> str:
    """Markdown: the decomposition's solve phase against its error at each of :data:`TOLERANCES`, and the figure."""
    best = ratios(record)[0]
    mono = bests(record)[best]["solve_phase"]
    rows = ["Speed against error (one run at each solver.tol after the pairs; docs/bench-3d.png), against the "
            f"monolithic solve phase ({best}) {mono:.2f} s:", "",
            "| solver.tol | iterations | rounds | solve phase (s) | ratio monolithic / DD | energy-norm error |",
            "|---|---|---|---|---|---|"]
    rows += [f"| {run['tol']:.0e} | {run['iterations']} | {run['rounds']} | {run['solve_phase']:.2f} "
             f"| {mono / run['solve_phase']:.2f} | {run['error']:.1e} |" for run in record["tolerances"]]
    return "\n".join(rows + ["", "![speed against error](bench-3d.png)"])


def speed_error_plot(record: dict, path: Path) -> None:
    """The decomposition's solve phase against its error at each solver.tol, the monolithic solve phases as lines."""
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6, 4.2), constrained_layout=True)
    runs = record["tolerances"]
    ax.semilogx([run["error"] for run in runs], [run["solve_phase"] for run in runs], marker="o",
                label=f"DD on {record['ranks']} ranks (slabs per half: {runs[0]['pieces']})")
    for run in runs:
        ax.annotate(f"tol {run['tol']:.0e}", (run["error"], run["solve_phase"]), textcoords="offset points",
                    xytext=(4, 4), fontsize=8)
    for label, style in zip(ORDERINGS, ("--", ":")):
        ax.axhline(bests(record)[label]["solve_phase"], color="gray", linestyle=style,
                   label=f"one MUMPS factorization, one process ({label})")
    ax.set_xlabel("relative energy-norm difference from the monolithic solution")
    ax.set_ylabel("solve phase (s)")
    ax.set_ylim(bottom=0.0)
    ax.set_title(f"3-D box, {record['unknowns']:,} unknowns (P1)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)


#: The rounds' growth: slabs per half and mesh sizes of the in-process solves (iterations only, no timing).
ROUND_PIECES, ROUND_SIZES = (1, 2, 4), (0.1, 0.07, 0.05, 0.04)


def rounds() -> list[dict]:
    """The decomposition's iterations and rounds in this process on the linear box at :data:`ROUND_SIZES`, with
    :data:`ROUND_PIECES` slabs per half (where they fit) and feti's two preconditioners, at solver.tol 1e-10."""
    from mpi4py import MPI

    from ddsolve.errors import SceneError
    from ddsolve.mesh import solid as solid_meshes
    from ddsolve.solvers import solid as solid_solver, solid_dd

    rows = []
    for size in ROUND_SIZES:
        scene = scene_of(size).with_({"solver.method": "feti", "solver.tol": 1e-10})
        mesh = solid_meshes.build(scene)
        reference = solid_solver.solve_solid(scene, mesh)
        for pieces in ROUND_PIECES:
            for preconditioner in ("dirichlet", "lumped"):
                chosen = scene.with_({"solver.pieces": pieces, "solver.preconditioner": preconditioner})
                try:
                    result = solid_dd.solve(chosen, MPI.COMM_SELF, None, progress=lambda line: None, mesh=mesh)
                except SceneError:  # the slabs do not fit this mesh
                    continue
                rows.append({"size": size, "unknowns": mesh.unknowns, "pieces": pieces,
                             "preconditioner": preconditioner, "iterations": result.steps, "rounds": result.solves,
                             "error": solid_solver.energy_error(result, reference)})
                print(f"rounds: size {size}, slabs per half {pieces}, {preconditioner}: {result.steps} iterations, "
                      f"{result.solves} rounds", flush=True)
    return rows


def rounds_table(rows: list[dict]) -> str:
    """Markdown: iterations / rounds per mesh (rows) and slabs and preconditioner (columns)."""
    columns = sorted({(r["pieces"], r["preconditioner"]) for r in rows})
    lines = ["| mesh.size | unknowns | " + " | ".join(f"{p} slab{'s' if p > 1 else ''}, {c}" for p, c in columns)
             + " |", "|---|---|" + "---|" * len(columns)]
    for size in sorted({r["size"] for r in rows}, reverse=True):
        mine = {(r["pieces"], r["preconditioner"]): r for r in rows if r["size"] == size}
        cells = [f"{mine[c]['iterations']} / {mine[c]['rounds']}" if c in mine else "" for c in columns]
        unknowns = next(r["unknowns"] for r in rows if r["size"] == size)
        lines.append(f"| {size:g} | {unknowns:,} | " + " | ".join(cells) + " |")
    worst = max(r["error"] for r in rows)
    lines += ["", f"(iterations / rounds of block solves; feti at solver.tol = 1e-10, every result within {worst:.1e} "
              "of the monolithic solution in energy norm.)"]
    return "\n".join(lines)
