"""Adaptive 3-D meshes to a target error: ``./run three-d-adapt`` writes docs/three-d-adapt.md.

docs/three-d.md's extruded scene (two materials, clamped left and right, rollers on both z faces) solved with
``mesh.target_error`` (P2, the first mesh graded towards the crack front at ``mesh.size`` 0.2): every level by the
3-D reference, the first target's also by the domain decomposition (one process, its own levels), against the
plane continuous energy (the plane reference at graded P2, mesh.size 0.025) and the plane G (graded P2, mesh.size
0.05).
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from mpi4py import MPI

from experiments import three_d, three_d_front
from ddsolve.mesh import geometry
from ddsolve.post import front
from ddsolve.solvers import reference as plane_reference
from ddsolve.solvers import solid, solid_adapt, solid_dd

DOCS = Path("docs")
#: The runs: (case, target_error).
RUNS = (("opening", 0.1), ("opening", 0.08), ("opening", 0.06), ("partial closure", 0.08))
#: The first mesh's size.
FIRST_SIZE = 0.2
#: The plane estimate's effectivity on the same scene at graded P2 of these sizes (its section, for comparison).
PLANE_SIZES = (0.4, 0.2, 0.1)


def adaptive(case: str, target: float, decomposed: bool) -> tuple[object, list[str], float]:
    """The case solved to ``target`` by the reference or the DD (one process): the result, its level lines, seconds."""
    scene = three_d.scene_of(case, FIRST_SIZE, 3).with_({"mesh.target_error": target})
    lines: list[str] = []
    comm = MPI.COMM_SELF
    level = ((lambda mesh: solid_dd.solve(scene, comm, None, lambda _line: None, mesh)) if decomposed else
             (lambda mesh: solid.reference_on(scene, mesh)))
    started = time.perf_counter()
    result = solid_adapt.solve_adaptively(scene, comm, level, None, lines.append)
    return result, lines, time.perf_counter() - started


def measure() -> dict:
    """Every run's levels, estimate, true error, G along the fronts and the DD's difference from the reference."""
    planes = {case: {"energy": three_d.plane(case, 0.025, True)["energy"], "G": three_d_front.plane_G(case)}
              for case in dict(RUNS)}
    plane_rows = [plane_effectivity(case, size, planes[case]["energy"]) for case in planes for size in PLANE_SIZES]
    rows = []
    for case, target in RUNS:
        result, lines, seconds = adaptive(case, target, False)
        exact = planes[case]["energy"]
        released = front.release(result) if result.fracture is None else result.fracture
        ratios = [three_d_front.interior_ratios(released, planes[case]["G"], tip) for tip in (0, 1)]
        row = {"case": case, "target": target, "lines": lines, "seconds": seconds, "unknowns": result.mesh.unknowns,
               "estimate": float(lines[-1].split("estimated error ")[1].split(" %")[0]) / 100,
               "true": three_d.energy_norm_error(result.energy / three_d.DEPTH, exact), "ratios": ratios,
               "closed": result.closed}
        if (case, target) == RUNS[0]:
            dd, _, dd_seconds = adaptive(case, target, True)
            row["dd"] = (solid.comparison(dd, result)[0], dd.mesh.unknowns, dd_seconds)
        rows.append(row)
    return {"planes": planes, "rows": rows, "plane rows": plane_rows}


def plane_effectivity(case: str, size: float, exact: float) -> dict:
    """The plane reference's estimate and true error at graded P2 of ``size``."""
    scene = three_d.scene_of(case, size, 2, graded=True)
    result = plane_reference.solve_monolithic(scene, geometry.build(scene))
    return {"case": case, "size": size, "unknowns": result.unknowns, "estimate": float(result.attrs["error_estimate"]),
            "true": three_d.energy_norm_error(result.energy, exact)}


def page(measured: dict) -> str:
    lines = ["# Three dimensions: adaptive meshes to a target error", "", __doc__.split("\n\n", 1)[1].strip(), "",
             "`mesh.target_error = e` on a 3-D box: solve, estimate (Zienkiewicz–Zhu patch recovery on the "
             "tetrahedra, ddsolve.post.solid_estimate), mesh the box again with gmsh at the sizes the estimate asks "
             "for (the old mesh as a background size field), until the estimate is at most e "
             "(ddsolve.solvers.solid_adapt).  True error: √((Π_h − Π)/|Π|) of the energy per depth against the plane "
             "continuous energy; effectivity = estimate / true error; G / G_plane at the front nodes off the z "
             "faces.", "",
             "| case | target | levels: unknowns (estimate) | final unknowns | estimate | true error | effectivity | "
             "G / G_plane, left tip | right tip | closed vertices | seconds |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in measured["rows"]:
        levels = ", ".join(f"{line.split(': ')[1].split(' unknowns')[0]} ({line.split('estimated error ')[1].split(',')[0]})"
                           for line in row["lines"])
        tips = [f"{ratio.min():.4f} – {ratio.max():.4f}" for ratio in row["ratios"]]
        lines.append(f"| {row['case']} | {row['target']:g} | {levels} | {row['unknowns']} | {100 * row['estimate']:.2f} % "
                     f"| {100 * row['true']:.2f} % | {row['estimate'] / row['true']:.2f} | {tips[0]} | {tips[1]} | "
                     f"{row['closed']} | {row['seconds']:.1f} |")
    dd = next(row for row in measured["rows"] if "dd" in row)
    error, unknowns, seconds = dd["dd"]
    within = [row for row in measured["rows"] if row["true"] <= row["target"]]
    met = ", ".join(f"{row['case']} {row['target']:g}" for row in within) or "none"
    worst = {case: max(max(np.abs(ratio - 1.0).max() for ratio in row["ratios"]) for row in measured["rows"]
                       if row["case"] == case) for case in measured["planes"]}
    shut = measured["planes"]["partial closure"]["G"]
    effectivities = [row["estimate"] / row["true"] for row in measured["rows"] if row["case"] == "opening"]
    low, high = min(effectivities), max(effectivities)
    lines += ["", f"The domain decomposition with the same target ({dd['case']}, {dd['target']:g}; one process, its own "
              f"levels) ends on the same mesh ({unknowns} unknowns: the sizes are rounded to 0.1 % so that solutions "
              f"that differ by rounding give one gmsh mesh) and differs from the reference there by {error:.1e} in "
              f"the energy norm ({seconds:.1f} s).", "",
              f"G(z) at the interior front nodes of the open crack is within {100 * worst['opening']:.1f} % of the plane G "
              f"at every target.  Partly shut, the left tip's G is within {100 * np.abs(measured['rows'][-1]['ratios'][0] - 1).max():.1f} %; "
              f"the right tip is nearly shut (plane G {shut[1]:.3g} against {shut[0]:.3g} at the left), its G a "
              "small difference of large terms that the energy-norm target does not control.", "",
              f"Calibration: the estimate's effectivity against the plane continuous energy is {low:.2f}–{high:.2f} on "
              "the open crack and lower partly shut (its contact term, the complementarity defect between the "
              "crack's nodes, adds little there; where the rest of the missing error lies was not located): patch "
              "recovery misses part of the error of the r^½ field along the front, so the true error "
              "is about a tenth above the estimate, and within the target only where the last level lands that far "
              f"below it: in {len(within)} of {len(measured['rows'])} runs ({met}).  The last level's estimate "
              "lies below the target by the plan's margin (it aims at the target ÷ 1.3) less what the model misses.  "
              "The plane estimate on the scene's section behaves alike on coarse meshes, and reaches one as the "
              "mesh resolves the tips:", "", "| case | plane mesh.size (graded P2) | unknowns | estimate | true error | "
              "effectivity |", "|---|---|---|---|---|---|"]
    lines += [f"| {row['case']} | {row['size']:g} | {row['unknowns']} | {100 * row['estimate']:.2f} % | "
              f"{100 * row['true']:.2f} % | {row['estimate'] / row['true']:.2f} |" for row in measured["plane rows"]]
    lines.append("")
    return "\n".join(lines)


def three_d_adapt() -> None:
    """Measure the runs and write docs/three-d-adapt.md."""
    (DOCS / "three-d-adapt.md").write_text(page(measure()))
    print(f"wrote {DOCS / 'three-d-adapt.md'}")
