"""``./run scaling-3d``: the cost model by which ``auto`` decomposes a 3-D box (:mod:`ddsolve.dd.solid_costs`), fitted
on measurements in one process and checked against every candidate solved side by side on 2 ranks.

The box is the 3-D page's (experiments/three_d.py), pulled open with its crack faces free or partly shut (contact
active), P1 and P2.  Measured in this process, one rank: the blocks of a decomposition into 1, 2, 4 and 8 slabs per
half (the slab at Σ: its plain MUMPS factorization, one solve, its Dirichlet problem's factorization and solve; a
whole half's factorization with the Schur complement on Σ), rank 0's dense Cholesky factorization of ``schur``'s
interface stiffness, and the methods' rounds (feti with either preconditioner on every slab count, with rank 0's
seconds outside the rounds; schur's active-set steps) on the smaller meshes.  Power laws fitted in logs: a block's
seconds against its unknowns n and Σ's vertices s (the slab's face), rank 0's against its unknowns or multipliers,
feti's rounds against the slabs per half, the box's unknowns and whether the crack faces press.  The candidates' launch (part ``scaling-3d-candidates``) solves
one scene with every candidate in turn, twice, beside the monolithic reference: measured against predicted, and
what ``auto`` takes.  Writes docs/scaling.md's section *scaling-3d* and results/scaling-3d.json.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from ddsolve.dd.solid_costs import PIECES, coarse_columns, multipliers
from experiments import report, three_d

RESULT = Path("results/scaling-3d.json")
DOCS = Path("docs")
#: Block measurements: (degree, mesh.size) of the box, slabs per half.
BLOCK_MESHES = ((1, 0.1), (1, 0.07), (1, 0.05), (1, 0.04), (1, 0.032), (2, 0.2), (2, 0.14), (2, 0.1), (2, 0.08))
BLOCK_PIECES = (1, 2, 4, 8)
#: Iteration measurements: (degree, mesh.size), each pulled open and partly shut.
ROUND_MESHES = ((1, 0.1), (1, 0.07), (1, 0.05), (2, 0.2), (2, 0.14))
#: The candidates' launches: (degree, mesh.size, contact) on 2 ranks.
CANDIDATE_SCENES = ((1, 0.07, False), (2, 0.14, True), (1, 0.05, True), (2, 0.1, False), (1, 0.035, False),
                    (1, 0.03, True))
RANKS = 2
#: Blocks of fewer unknowns (n, the box's over its blocks) are left out of the block laws: their milliseconds are
#: MUMPS's fixed costs, which flatten the laws where the choice does not matter.
SMALLEST_FITTED = 4000


def box(degree: int, size: float, contact: bool):
    """The 3-D page's box at ``mesh.size`` and ``mesh.degree``: partly shut (contact active) or pulled open with its
    crack faces free."""
    if contact:
        return three_d.scene_of("partial closure", size, 3).with_({"mesh.degree": degree})
    return three_d.scene_of("opening", size, 3).with_({"mesh.degree": degree, "contact.nonpenetration": False})


def _seconds(action, repeats: int) -> float:
    """The best of ``repeats`` wall times of ``action()``."""
    best = np.inf
    for _ in range(repeats):
        started = time.perf_counter()
        action()
        best = min(best, time.perf_counter() - started)
    return float(best)


def block_seconds(system, schur: bool, solves: int = 5) -> dict[str, float]:
    """One block on one rank: its factorization (with the Schur complement on its trace with ``schur``; else its
    Dirichlet problem's too), one solve and (else) one multi-column solve of feti's coarse directions
    (:func:`~ddsolve.dd.solid_costs.coarse_columns`) and one Dirichlet solve, best of two."""
    from ddsolve.parallel.blocks import Block

    out = {}
    for _ in range(2):
        block = Block(system, factor_package="mumps")
        try:
            started = time.perf_counter()
            block.factor(schur=schur)
            if schur:
                block.schur_complement()
            timed = {"schur_factor" if schur else "factor": time.perf_counter() - started}
            load = np.ones(len(system.trace_dofs))
            timed["solve"] = _seconds(lambda: block.solve(load, body=True), solves)
            if not schur:
                columns = np.ones((len(system.trace_dofs), coarse_columns()))
                timed["columns"] = _seconds(lambda: block.solve_many(columns), 2)
                started = time.perf_counter()
                block.factor_dirichlet()
                timed["dirichlet_factor"] = time.perf_counter() - started
                timed["dirichlet_solve"] = _seconds(lambda: block.dirichlet(load), solves)
        finally:
            block.destroy()
        out = {key: min(value, out.get(key, np.inf)) for key, value in timed.items()}
    return out


def blocks(degree: int, size: float) -> list[dict]:
    """The slab at Σ of the lower half for each of :data:`BLOCK_PIECES` that fits (and the half with the Schur
    complement): unknowns, Σ's vertices, trace entries and seconds."""
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid_dd
    from ddsolve.solvers.stacked_dd import trace_layout

    scene = box(degree, size, False)
    mesh = solid.build(scene)
    rows = []
    for pieces in BLOCK_PIECES:
        parts = solid_dd.decomposition(scene, mesh, pieces)
        if parts is None:
            continue
        dofs = trace_layout(parts.joints, len(parts.slabs))[1]
        system = solid_dd.block_system(scene, parts.slabs[0].piece, parts.specs[0].name, dofs[0], parts.supports[0])
        row = {"degree": degree, "size": size, "pieces": pieces, "box": mesh.unknowns, "unknowns": system.size,
               "sigma": len(mesh.sigma.points), "trace": len(dofs[0]), **block_seconds(system, False)}
        if pieces == 1:
            row.update({key: value for key, value in block_seconds(system, True).items() if key == "schur_factor"})
        rows.append(row)
        print(f"blocks: P{degree} size {size}, {pieces} slabs per half: {system.size} unknowns, factor "
              f"{row['factor']:.3f} s, solve {row['solve'] * 1e3:.1f} ms"
              + (f", with the Schur complement {row['schur_factor']:.3f} s" if pieces == 1 else ""), flush=True)
    return rows


def dense(sizes: list[int]) -> list[dict]:
    """Rank 0's dense Cholesky factorization (LAPACK, as ``schur``'s interface solve) at each size, best of three."""
    import scipy.linalg

    rng = np.random.default_rng(0)
    rows = []
    for m in sizes:
        a = rng.standard_normal((m, m))
        spd = a @ a.T + m * np.eye(m)
        rows.append({"unknowns": m, "seconds": _seconds(lambda: scipy.linalg.cho_factor(spd), 3)})
    return rows


def iterations() -> list[dict]:
    """The methods' iterations in this process (deterministic): feti with each preconditioner on every slab count
    that fits, schur's active-set steps, on each of :data:`ROUND_MESHES` pulled open and partly shut; and rank 0's
    seconds outside the rounds of block solves (``update``)."""
    from mpi4py import MPI

    from ddsolve.errors import SceneError
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid_dd

    rows = []
    for (degree, size), contact in ((mesh, contact) for mesh in ROUND_MESHES for contact in (False, True)):
        scene = box(degree, size, contact)
        mesh = solid.build(scene)
        runs = [("schur", 1, "dirichlet")] + [("feti", pieces, preconditioner) for pieces in BLOCK_PIECES
                                              for preconditioner in ("dirichlet", "lumped")]
        for method, pieces, preconditioner in runs:
            chosen = scene.with_({"solver.method": method, "solver.pieces": pieces,
                                  "solver.preconditioner": preconditioner})
            try:
                result = solid_dd.solve(chosen, MPI.COMM_SELF, None, progress=lambda line: None, mesh=mesh)
            except SceneError:  # the slabs do not fit this mesh
                continue
            t = result.timings
            method_time = t["total"] - t.get("meshing", 0.0) - t["setup"] - t["assembly"] - t["factorization"]
            rows.append({"degree": degree, "size": size, "contact": contact, "box": mesh.unknowns,
                         "sigma": len(mesh.sigma.points), "crack_rows": int(np.count_nonzero(mesh.sigma.cracked)),
                         "method": method, "pieces": pieces, "preconditioner": preconditioner,
                         "iterations": result.steps, "rounds": result.solves, "update": method_time - t["rounds"]})
            print(f"iterations: P{degree} size {size}, contact {contact}, {method} {pieces} {preconditioner}: "
                  f"{result.steps} iterations, {result.solves} rounds", flush=True)
    return rows


def measure() -> dict:
    """Every measurement of the fit, in this process."""
    started = time.perf_counter()
    record = {"load": os.getloadavg()[0], "blocks": [row for degree, size in BLOCK_MESHES
                                                     for row in blocks(degree, size)]}
    sigmas = sorted({3 * row["sigma"] for row in record["blocks"]})
    record["dense"] = dense(sigmas)
    record["iterations"] = iterations()
    record["load_after"] = os.getloadavg()[0]
    record["seconds"] = time.perf_counter() - started
    return record


def measure_launch(output: Path, comm) -> None:
    """Inside a launch on one rank: :func:`measure`, written as JSON."""
    output.write_text(json.dumps(measure()))


# --- the fit ------------------------------------------------------------------------------------
def fit_logs(columns: list[np.ndarray], y) -> tuple[float, ...]:
    """(a, p1, p2, ..) with y ≈ a·Π x_i^p_i (a column of ones for no x), least squares in logs; a column of 0/1
    (an indicator) enters as e^(p·x)."""
    design = np.column_stack([np.ones(len(y)), *columns])
    coefficients = np.linalg.lstsq(design, np.log(y), rcond=None)[0]
    return (float(np.exp(coefficients[0])), *(float(c) for c in coefficients[1:]))


def block_law(rows: list[dict], kind: str) -> tuple[float, float, float]:
    """``kind``'s seconds a·n^p·s^q over ``rows`` of at least :data:`SMALLEST_FITTED` unknowns (n: the box's unknowns
    over its blocks, s: Σ's vertices); a whole half's Schur factorization, measured on one shape only (n and s grow
    together), against n alone."""
    mine = [row for row in rows if kind in row and row["box"] / (2 * row["pieces"]) >= SMALLEST_FITTED]
    n = np.log([row["box"] / (2 * row["pieces"]) for row in mine])
    s = np.log([row["sigma"] for row in mine])
    seconds = [row[kind] for row in mine]
    return (*fit_logs([n], seconds), 0.0) if kind == "schur_factor" else fit_logs([n, s], seconds)


def round_law(rows: list[dict], preconditioner: str) -> tuple[float, float, float, float]:
    """feti's rounds a·k^b·N^c·e^(d·contact) with ``preconditioner`` over ``rows`` of the model's slab counts."""
    mine = [row for row in rows if row["method"] == "feti" and row["preconditioner"] == preconditioner
            and row["pieces"] in PIECES]
    return fit_logs([np.log([row["pieces"] for row in mine]), np.log([row["box"] for row in mine]),
                     np.array([float(row["contact"]) for row in mine])], [row["rounds"] for row in mine])


def scene_rounds(record: dict) -> list[dict]:
    """feti's rounds in the candidates' launches (deterministic, as in one process), as rows of :func:`iterations`:
    they reach the larger meshes."""
    return [{"degree": scene["degree"], "size": scene["size"], "contact": scene["contact"], "box": scene["unknowns"],
             "sigma": scene["box"]["sigma"], "crack_rows": scene["box"]["contact_rows"], "method": method,
             "pieces": pieces, "preconditioner": preconditioner, "rounds": entry["runs"][0]["rounds"]}
            for scene in record.get("scenes", []) for entry in scene["candidates"]
            for method, pieces, preconditioner in [entry["candidate"]] if method == "feti"]


def update_law(rows: list[dict], preconditioner: str) -> tuple[float, float]:
    """feti's rank-0 seconds per round outside the block solves, a·m^p on its multipliers, with ``preconditioner``."""
    mine = [row for row in rows if row["preconditioner"] == preconditioner]
    return fit_logs([np.log([multipliers(_box_of(row), row["pieces"]) for row in mine])],
                    [row["update"] / row["rounds"] for row in mine])


KINDS = ("factor", "solve", "columns", "dirichlet_factor", "dirichlet_solve", "schur_factor")


def fit(record: dict) -> dict:
    """Every law of :mod:`ddsolve.dd.solid_costs` from the measurements."""
    steps = [row for row in record["iterations"] if row["method"] == "schur" and row["contact"]]
    feti = [row for row in record["iterations"] if row["method"] == "feti" and row["pieces"] in PIECES]
    dense_rows = record["dense"]
    return {"blocks": {degree: {kind: block_law([row for row in record["blocks"] if row["degree"] == degree], kind)
                                for kind in KINDS} for degree in (1, 2)},
            "dense": fit_logs([np.log([row["unknowns"] for row in dense_rows])],
                              [row["seconds"] for row in dense_rows]),
            "rounds": {preconditioner: round_law(record["iterations"] + scene_rounds(record), preconditioner)
                           for preconditioner in ("dirichlet", "lumped")},
            "update": {preconditioner: update_law(feti, preconditioner) for preconditioner in ("dirichlet", "lumped")},
            "steps": fit_logs([np.log([row["crack_rows"] for row in steps])], [row["iterations"] for row in steps])}


# --- the candidates, side by side ---------------------------------------------------------------
def candidates_launch(degree: int, size: float, contact: int, repeats: int, output: Path, comm) -> None:
    """Inside one launch: the box (:func:`box`) meshed once, the monolithic reference on rank 0, then every candidate
    of ``auto`` whose slabs fit the mesh on every rank, in turn ``repeats`` times (:func:`bench_solid.decomposed`);
    what ``auto`` takes on these ranks; rank 0 writes the record as JSON."""
    from ddsolve.dd import solid_costs
    from ddsolve.mesh import solid
    from ddsolve.parallel.exchange import collective
    from ddsolve.solvers import solid as solid_solver, solid_dd
    from experiments.bench_solid import decomposed

    scene = box(degree, size, bool(contact))
    mesh = comm.bcast(collective(comm, lambda: solid.build(scene), root_only=True), root=0)
    reference = collective(comm, lambda: solid_solver.solve_solid(scene, mesh), root_only=True)
    parts = solid_dd.pieces_of(scene, mesh, comm.size)
    held = solid_dd.kernels_of(parts)
    auto = solid_dd.method_of(scene, parts, held, comm.size).solver
    whole = solid_dd.decomposition(scene, mesh, 1)
    fitting = [count for count in solid_costs.PIECES if count == 1 or solid_dd.decomposition(scene, mesh, count)]
    options = solid_dd.ranking(scene, solid_dd.box_of(scene, whole), comm.size, fitting)
    runs: dict[int, list] = {index: [] for index in range(len(options))}
    load = os.getloadavg()[0]
    for _ in range(repeats):
        for index, candidate in enumerate(options):
            chosen = scene.with_({"solver.method": candidate.method, "solver.pieces": candidate.pieces,
                                  "solver.preconditioner": candidate.preconditioner
                                  if candidate.method == "feti" else "auto"})
            runs[index].append(decomposed(chosen, mesh, reference, comm))
    if comm.rank == 0:
        output.write_text(json.dumps({
            "degree": degree, "size": size, "contact": bool(contact), "ranks": comm.size, "unknowns": mesh.unknowns,
            "box": vars(solid_dd.box_of(scene, whole)), "load": load, "load_after": os.getloadavg()[0],
            "auto": [auto.method, auto.pieces, auto.preconditioner],
            "candidates": [{"candidate": [c.method, c.pieces, c.preconditioner], "runs": runs[index]}
                           for index, c in enumerate(options)]}))


# --- the command --------------------------------------------------------------------------------
def scaling_3d(repeats: int = 2) -> dict:
    """The candidates' launches on :data:`RANKS` ranks, the measurements on one rank, the fit; print the laws and
    write the record and docs/scaling.md's section."""
    RESULT.parent.mkdir(parents=True, exist_ok=True)
    record = {"scenes": [report.launch(RANKS, ["scaling-3d-candidates", str(degree), str(size), str(int(contact)),
                                               str(repeats)], RESULT.with_name(".scaling-3d-candidates.json"))
                         for degree, size, contact in CANDIDATE_SCENES]}
    record.update(report.launch(1, ["scaling-3d-measure"], RESULT.with_name(".scaling-3d-measure.json")))
    record["laws"] = fit(record)
    RESULT.write_text(json.dumps(record))
    print(laws_text(record["laws"]), flush=True)
    report.section(DOCS / "scaling.md", "scaling-3d", text(record))
    return record


# --- the page -----------------------------------------------------------------------------------
def laws_of(fitted: dict):
    """The fitted record as :class:`ddsolve.dd.solid_costs.Laws` (JSON keeps the degrees as strings)."""
    from ddsolve.dd.solid_costs import Laws

    return Laws(blocks={int(degree): {kind: tuple(law) for kind, law in kinds.items()}
                        for degree, kinds in fitted["blocks"].items()},
                dense=tuple(fitted["dense"]), rounds={name: tuple(law) for name, law in fitted["rounds"].items()},
                update={name: tuple(law) for name, law in fitted["update"].items()}, steps=tuple(fitted["steps"]))


def laws_text(fitted: dict) -> str:
    """The laws as the code's constant (ddsolve/dd/solid_costs.py, ``FITTED``)."""
    laws = laws_of(fitted)

    def numbers(law) -> str:
        return "(" + ", ".join(f"{value:.3g}" for value in law) + ")"

    def named(laws: dict, indent: int) -> str:
        items = [f'"{name}": {numbers(law)}' for name, law in laws.items()]
        lines = [", ".join(items[i:i + 2]) for i in range(0, len(items), 2)]
        return "{" + (",\n" + " " * indent).join(lines) + "}"

    blocks = (",\n" + " " * 22).join(f"{degree}: {named(kinds, 26)}" for degree, kinds in laws.blocks.items())
    return (f"FITTED = Laws(blocks={{{blocks}}},\n{' ' * 14}dense={numbers(laws.dense)}, steps={numbers(laws.steps)},\n"
            f"{' ' * 14}update={named(laws.update, 22)},\n{' ' * 14}rounds={named(laws.rounds, 22)})")


def _box_of(row: dict):
    from ddsolve.dd.solid_costs import Box

    return Box(row["box"], row["sigma"], row["crack_rows"] if row.get("contact") else 0, row["degree"])


def _quality(pairs: list[tuple[float, float]]) -> str:
    """Measured over predicted: the median and the range."""
    ratios = sorted(m / p for m, p in pairs)
    return f"{np.median(ratios):.2f} ({ratios[0]:.2f}–{ratios[-1]:.2f})"


def law_rows(record: dict) -> list[str]:
    """Markdown: each law, its constants, the range it was fitted on and measured / predicted there."""
    from ddsolve.dd.solid_costs import feti_rounds

    laws = laws_of(record["laws"])
    rows = ["| law | form | constants | fitted on | measured / predicted: median (range) |", "|---|---|---|---|---|"]
    for degree, kinds in laws.blocks.items():
        mine = [row for row in record["blocks"] if row["degree"] == degree]
        for kind, (a, p, q) in kinds.items():
            points = [row for row in mine if kind in row and row["box"] / (2 * row["pieces"]) >= SMALLEST_FITTED]
            pairs = [(row[kind], a * (row["box"] / (2 * row["pieces"])) ** p * row["sigma"] ** q) for row in points]
            n = [row["box"] / (2 * row["pieces"]) for row in points]
            rows.append(f"| P{degree} {kind.replace('_', ' ')} | a·n^p·s^q | a = {a:.3g}, p = {p:.3f}, q = {q:.3f} "
                        f"| n {min(n):,.0f}–{max(n):,.0f} ({len(points)} blocks) | {_quality(pairs)} |")
    a, p = laws.dense
    dense = record["dense"]
    rows.append(f"| rank 0's dense Cholesky | a·m^p | a = {a:.3g}, p = {p:.3f} | m {dense[0]['unknowns']:,}–"
                f"{dense[-1]['unknowns']:,} | {_quality([(r['seconds'], a * r['unknowns'] ** p) for r in dense])} |")
    for name, (a, b, c, d) in laws.rounds.items():
        mine = [row for row in record["iterations"] + scene_rounds(record) if row["method"] == "feti"
                and row["preconditioner"] == name and row["pieces"] in PIECES]
        pairs = [(row["rounds"], sum(feti_rounds(_box_of(row), row["pieces"], name, laws))) for row in mine]
        rows.append(f"| feti rounds, {name} | a·k^b·N^c·e^(d·contact) | a = {a:.3g}, b = {b:.3f}, c = {c:.3f}, "
                    f"d = {d:.3f} | N {min(r['box'] for r in mine):,}–{max(r['box'] for r in mine):,}, k "
                    f"{min(r['pieces'] for r in mine)}–{max(r['pieces'] for r in mine)} ({len(mine)} solves) "
                    f"| {_quality(pairs)} |")
    for name, (a, p) in laws.update.items():
        mine = [row for row in record["iterations"] if row["method"] == "feti" and row["pieces"] in PIECES
                and row["preconditioner"] == name]
        m = [multipliers(_box_of(row), row["pieces"]) for row in mine]
        rows.append(f"| feti's rank 0 per round, {name} | a·m^p | a = {a:.3g}, p = {p:.3f} | m {min(m):,}–{max(m):,} | "
                    f"{_quality([(r['update'] / r['rounds'], a * x ** p) for r, x in zip(mine, m)])} |")
    a, p = laws.steps
    steps = [row for row in record["iterations"] if row["method"] == "schur" and row["contact"]]
    contact_rows = [r["crack_rows"] for r in steps]
    rows.append(f"| schur's active-set steps | a·c^p | a = {a:.3g}, p = {p:.3f} | c {min(contact_rows)}–"
                f"{max(contact_rows)} | {_quality([(r['iterations'], a * r['crack_rows'] ** p) for r in steps])} |")
    return rows


def _label(candidate: list) -> str:
    method, pieces, preconditioner = candidate
    slabs = f"{pieces} slab{'s' if pieces > 1 else ''}"
    return f"{method}, {slabs}" + (f", {preconditioner}" if method == "feti" else "")


def scene_verdict(scene: dict, laws) -> dict:
    """A scene's candidates: each one's median solve phase (wall) and median CPU seconds of its busiest rank (the
    whole call: under load the wall measures the machine's other jobs more than the method), predicted seconds,
    iterations, rounds, worst error; the fastest by each measure, what ``auto`` takes (the model's pick with ``laws``,
    which are the code's once copied into it) and its time over the fastest's by each measure."""
    from ddsolve.dd.solid_costs import Box, Candidate, predicted_seconds

    box = Box(**scene["box"])
    rows = []
    for entry in scene["candidates"]:
        runs = entry["runs"]
        rows.append({"candidate": entry["candidate"], "wall": float(np.median([r["solve_phase"] for r in runs])),
                     "cpu": float(np.median([r["cpu_largest"] for r in runs])),
                     "predicted": predicted_seconds(box, Candidate(*entry["candidate"]), scene["ranks"], laws),
                     "iterations": runs[0]["iterations"], "rounds": runs[0]["rounds"],
                     "error": max(r["error"] for r in runs)})
    taken = min(rows, key=lambda row: row["predicted"])
    fastest = {measure: min(rows, key=lambda row: row[measure]) for measure in ("wall", "cpu")}
    return {"rows": rows, "fastest": fastest, "taken": taken,
            "over": {measure: taken[measure] / fastest[measure][measure] - 1 for measure in fastest}}


def candidate_rows(record: dict) -> list[str]:
    """Markdown: per scene what auto took against the fastest, then every candidate measured against predicted."""
    laws = laws_of(record["laws"])
    summary = ["| scene | unknowns | Σ vertices | contact rows | runs | load | auto takes | fastest: wall | auto over it | "
               "fastest: CPU | auto over it |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    detail = ["| scene | candidate | predicted (s) | solve phase, wall (s) | busiest rank's CPU (s) | iterations | "
              "rounds | energy-norm error |", "|---|---|---|---|---|---|---|---|"]
    for scene in sorted(record["scenes"], key=lambda scene: scene["unknowns"]):
        verdict = scene_verdict(scene, laws)
        name = f"P{scene['degree']} {scene['size']:g}, {'contact' if scene['contact'] else 'faces free'}"
        box, fastest, over = scene["box"], verdict["fastest"], verdict["over"]
        summary.append(f"| {name} | {scene['unknowns']:,} | {box['sigma']:,} | {box['contact_rows']:,} | "
                       f"{len(scene['candidates'][0]['runs'])} | "
                       f"{scene['load']:.1f}–{scene['load_after']:.1f} | {_label(verdict['taken']['candidate'])} | "
                       f"{_label(fastest['wall']['candidate'])} | {100 * over['wall']:+.0f} % | "
                       f"{_label(fastest['cpu']['candidate'])} | {100 * over['cpu']:+.0f} % |")
        for row in sorted(verdict["rows"], key=lambda row: row["predicted"]):
            detail.append(f"| {name} | {_label(row['candidate'])} | {row['predicted']:.2f} | {row['wall']:.2f} | "
                          f"{row['cpu']:.2f} | {row['iterations']} | {row['rounds']} | {row['error']:.1e} |")
    return summary + [""] + detail


def block_rows(record: dict) -> list[str]:
    """Markdown: every measured block against its laws."""
    laws = laws_of(record["laws"])
    rows = ["| degree | mesh.size | slabs per half | box unknowns | block unknowns | Σ vertices | factor (s) | "
            "solve (ms) | coarse columns (ms) | Dirichlet factor (s) | Dirichlet solve (ms) | with the Schur complement "
            "(s) |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in record["blocks"]:
        def cell(kind: str, scale: float) -> str:
            if kind not in row:
                return ""
            a, p, q = laws.blocks[row["degree"]][kind]
            predicted = a * (row["box"] / (2 * row["pieces"])) ** p * row["sigma"] ** q
            return f"{scale * row[kind]:.3g} ({row[kind] / predicted:.2f})"
        rows.append(f"| P{row['degree']} | {row['size']:g} | {row['pieces']} | {row['box']:,} | {row['unknowns']:,} | "
                    f"{row['sigma']:,} | {cell('factor', 1)} | {cell('solve', 1e3)} | {cell('columns', 1e3)} | "
                    f"{cell('dirichlet_factor', 1)} | "
                    f"{cell('dirichlet_solve', 1e3)} | {cell('schur_factor', 1)} |")
    return rows


def round_rows(record: dict) -> list[str]:
    """Markdown: feti's rounds per mesh (rows) and slabs and preconditioner (columns), measured (predicted); schur's
    active-set steps."""
    from ddsolve.dd.solid_costs import feti_rounds

    laws = laws_of(record["laws"])
    rows = record["iterations"]
    columns = sorted({(r["pieces"], r["preconditioner"]) for r in rows if r["method"] == "feti"})
    lines = ["| mesh | unknowns | schur's steps | " + " | ".join(f"feti {k}, {name}" for k, name in columns) + " |",
             "|---|---|---|" + "---|" * len(columns)]
    for mesh in dict.fromkeys((r["degree"], r["size"], r["contact"]) for r in rows):
        mine = {(r["method"], r["pieces"], r["preconditioner"]): r for r in rows
                if (r["degree"], r["size"], r["contact"]) == mesh}
        cells = []
        for k, name in columns:
            row = mine.get(("feti", k, name))
            predicted = f" ({sum(feti_rounds(_box_of(row), k, name, laws)):.0f})" if row and k in PIECES else ""
            cells.append(f"{row['rounds']}{predicted}" if row else "")
        schur = mine[("schur", 1, "dirichlet")]
        lines.append(f"| P{mesh[0]} {mesh[1]:g}, {'contact' if mesh[2] else 'faces free'} | {schur['box']:,} | "
                     f"{schur['iterations']} | " + " | ".join(cells) + " |")
    return lines


def text(record: dict) -> str:
    """docs/scaling.md's section *scaling-3d*."""
    return "\n".join([
        "`./run scaling-3d`: the model by which `auto` decomposes a 3-D box (ddsolve/dd/solid_costs.py). The box is "
        "the 3-D page's (experiments/three_d.py), pulled open with its crack faces free or partly shut. Measured in "
        f"one process (load {record['load']:.1f}–{record['load_after']:.1f}, {record['seconds']:.0f} s): the slab at Σ "
        "of 1, 2, 4 and 8 slabs per half (its plain MUMPS factorization, one solve, the multi-column solve of feti's "
        f"coarse directions ({coarse_columns()} columns), its Dirichlet problem's), a whole "
        "half with its Schur complement on Σ, rank 0's dense Cholesky factorization, and the methods' rounds on the "
        "smaller meshes. A candidate's solve phase on R ranks is its 2k blocks' share per rank of their "
        "factorizations (feti Dirichlet's: two each), of one solve per round and (feti) of its coarse directions' "
        "multi-column solve, plus rank 0's work: schur's dense "
        "factorization on 3s unknowns and its active-set steps (each a dense factorization of at most the contact "
        "rows, the plane's law), feti's work per round outside the block solves. `schur` is a candidate only where its "
        "dense matrices fit the memory limit (as before).", "",
        "Laws (n: the box's unknowns over its 2k blocks; s: Σ's vertices; m: rank 0's dense unknowns, 3s; k: slabs per "
        "half; N: the box's unknowns; contact: 1 where the crack faces press; c: contact rows):", "",
        *law_rows(record), "",
        f"Every candidate of each scene on {RANKS} ranks in one launch, in turn, *runs* times (medians; solve phase: "
        "factorization and rounds, wall seconds; CPU: the busiest rank's CPU seconds of the whole call, which the "
        "machine's other jobs do not inflate as they do the wall), beside the monolithic reference (the energy-norm "
        "error); the predictions are the laws above; *auto takes*: the candidate they predict fastest, which `auto` "
        "takes with these laws in the code:", "",
        *candidate_rows(record), "",
        "feti's rounds at the default solver.tol in one process, measured (in brackets: predicted; eight slabs are "
        "no candidate) and schur's active-set steps:", "",
        *round_rows(record), "",
        "Every measured block (seconds; in brackets measured / predicted by its law):", "",
        *block_rows(record)])
