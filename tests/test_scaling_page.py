"""docs/scaling.md is written from a record of measurements: a synthetic record gives the whole page, its
sections in order and every table row as wide as its header."""
from __future__ import annotations

import re

import numpy as np

from ddsolve.parallel.phases import PHASES
from experiments import scaling
from experiments.bench import MONOLITHIC_ORDERINGS

#: The kinds of memory a rank holds (``/memory`` ``held_mb_<phase>``), one column each.
HELD = 5


def memory(rng: np.random.Generator, ranks: int) -> dict:
    """A rank-by-rank ``/memory`` record of a launch."""
    record = {"rank_unknowns": list(rng.uniform(1e4, 2e4, ranks)), "rank_factor_mb": list(rng.uniform(10, 50, ranks)),
              "rank_mesh_bytes": list(rng.uniform(1e6, 1e7, ranks))}
    for phase in PHASES:
        record[f"cpu_s_{phase}"] = list(rng.uniform(0.1, 2.0, ranks))
        record[f"peak_mb_{phase}"] = list(rng.uniform(100, 200, ranks))
        record[f"held_mb_{phase}"] = rng.uniform(1, 90, (ranks, HELD)).tolist()
        record[f"bytes_per_unknown_{phase}"] = float(rng.uniform(100, 900))
    return record


def solve_run(rng: np.random.Generator, kind: str, method: str, ranks: int, P: int) -> dict:
    """A strong, weak or rounds run of ``method``."""
    rounds = 3 if method == "schur" else int(5 * P ** 0.4)
    return {"kind": kind, "method": method, "ranks": ranks, "P": P, "unknowns": int(0.295 * P * P),
            "trace": 2 * (P - 2), "interface_unknowns": 3 * P, "multipliers": 6 * (P - 2), "rounds": rounds,
            "factorization": rng.uniform(0.1, 1), "iterations": rng.uniform(1, 2), "update": rng.uniform(0.01, 0.1),
            "wall_time": rng.uniform(1, 3), "setup": rng.uniform(1, 5), "rank0_time": 1e-7 * (3 * P) ** 2,
            "peak_memory_mb": list(rng.uniform(100, 300, ranks)), "memory": memory(rng, ranks)}


def launch_run(rng: np.random.Generator, label: str, adaptive: bool) -> dict:
    """A whole launch of Example 1 on 4 ranks (``adaptive``: a ``mesh.target_error`` run)."""
    run = {"kind": "launch", "label": label, "method": "schur", "ranks": 4, "P": 800, "unknowns": 190_000,
           "trace": 1596, "interface_unknowns": 2400, "multipliers": 4788, "rounds": 3,
           "error_estimate": rng.uniform(1e-3, 1e-2), "sum": rng.uniform(8, 9), "launch": rng.uniform(9, 10),
           "solve_phase": rng.uniform(2, 3), "peak_memory_mb": list(rng.uniform(100, 300, 4)),
           "memory": memory(rng, 4), **{phase: rng.uniform(0.1, 2) for phase in PHASES}}
    return run | ({"adaptive": rng.uniform(5, 6), "levels": 3} if adaptive else {})


def meshing_run(rng: np.random.Generator, P: int, ranks: int) -> dict:
    return {"kind": "meshing", "P": P, "ranks": ranks, "unknowns": int(1.18 * P * P), "meshing": rng.uniform(1, 2),
            "meshing_cpu": list(rng.uniform(0.5, 2, ranks)), "distribution": rng.uniform(0.1, 1),
            "distribution_cpu": list(rng.uniform(0.1, 1, ranks)), "peak_memory_mb": list(rng.uniform(100, 300, ranks))}


def baseline_row(rng: np.random.Generator, scene: str, P: int) -> dict:
    return {"scene": scene, "P": P, "unknowns": int(1.18 * P * P), "ranks": 4, "load": rng.uniform(0, 2),
            "dd": [{"method": "schur", "solve_phase": rng.uniform(1, 2), "error": 1e-9}],
            **{f"mono {label}": [{"solve_phase": rng.uniform(1, 4)}] for label in MONOLITHIC_ORDERINGS}}


def calibration(rng: np.random.Generator) -> dict:
    blocks = []
    for P, _ in scaling.CALIBRATION_MESHES:
        n = 0.295 * P * P
        paths = {path: {"factor": 1e-6 * n ** 1.2 * rng.uniform(0.9, 1.1), "solve": 1e-7 * n * rng.uniform(0.9, 1.1),
                        "interface": 1e-6 * n ** 1.1 * rng.uniform(0.9, 1.1)} for path in ("mumps_schur", "mumps", "petsc")}
        blocks.append({"unknowns": n, "trace": 2 * (P - 2), **paths})
    return {"blocks": blocks}


def synthetic_record(seed: int = 0) -> tuple[dict, scaling.CostModel]:
    """A record shaped as :func:`experiments.scaling.scaling` writes it, and the model fitted to it."""
    rng = np.random.default_rng(seed)
    runs = [solve_run(rng, kind, method, ranks, P) for method in scaling.METHODS for ranks in scaling.RANKS
            for kind, P in (("strong", scaling.STRONG_MESH[0]), ("weak", scaling.WEAK_MESHES[ranks][0]))]
    runs += [solve_run(rng, "rounds", method, 4, P) for method, largest in scaling.ROUNDS_LARGEST.items()
             for P, _ in scaling.ROUNDS_MESHES if P <= largest]
    runs += [launch_run(rng, label, "target" in label) for label in scaling.LAUNCH_CASES]
    runs += [meshing_run(rng, P, ranks) for P, _ in scaling.MESHING_MESHES for ranks in scaling.RANKS]
    record = {"cores": 2, "calibration": calibration(rng), "network": {"latency": 2e-6, "bandwidth": 5e9},
              "runs": runs, "baseline": [baseline_row(rng, scene, P) for P, _ in scaling.BASELINE_MESHES
                                         for scene in ("linear", "partial-closure")], "bare_start": 0.6}
    model = scaling.CostModel(record["calibration"], record["network"],
                              [r for r in runs if r["kind"] in ("strong", "weak", "rounds")])
    for run in (r for r in runs if r["kind"] != "meshing"):
        run["predicted"] = model.phases(run["method"], run["ranks"], run["unknowns"], run["trace"],
                                        run["interface_unknowns"], run["rounds"], run["multipliers"], 2)["total"]
    return record, model


def test_the_page_has_every_section_in_order():
    page = scaling.text(*synthetic_record())
    headings = re.findall(r"^#+ (.*)$", page, re.M)
    assert headings == ["Scaling", "How the work is distributed", "Measured (`schur`, `mprgp`, `feti`)",
                        "Rounds against P (kkt 1e-6 for the iterative methods, 4 ranks)",
                        "Whole launch (default method, 4 ranks)", "Meshing against the ranks", "Memory",
                        "The monolithic baseline", "Cost model", "Predictions for 64 to 1024 cores"]
    assert page.endswith("slowly with P, and its Dirichlet factorization doubles the factorization work and memory.\n")
    assert "\n\n\n" not in page and "**This machine has 2 cores.**" in page


def test_every_table_row_is_as_wide_as_its_header():
    page = scaling.text(*synthetic_record())
    for table in re.findall(r"(?:^\|.*\|\n)+", page, re.M):
        widths = {row.count(" | ") for row in table.splitlines() if not row.startswith("|---")}
        assert len(widths) == 1, table
