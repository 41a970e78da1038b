"""The paper's experiments, regenerated: Table 1, the θ sweep of Fig. 2, Figs. 1, 3 and 4 (the accuracy
study against the continuous solution is :mod:`experiments.accuracy`).

Each command launches MPI jobs (this process starts no MPI itself), keeps HDF5 files with provenance
in ``results/`` and rewrites its section of ``docs/results.md`` and its PNG files in ``docs/``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ddsolve.errors import DDSolveError
from experiments import report
from experiments.bench import TABLE1_MESHES

#: The paper's Table 1: P, M, h⁻min, h⁻max, h⁺min, h⁺max, Nod⁻, Tri⁻, Nod⁺, Tri⁺, iterations.
PAPER_TABLE1 = {
    12: (32, 0.172, 0.358, 0.202, 0.358, 68, 106, 67, 104, 843),
    24: (48, 0.081, 0.260, 0.085, 0.239, 163, 276, 164, 268, 1164),
    48: (80, 0.041, 0.155, 0.041, 0.151, 498, 906, 498, 906, 1416),
    96: (144, 0.018, 0.084, 0.021, 0.086, 1733, 3296, 1716, 3262, 1909),
    200: (256, 0.0091, 0.045, 0.0098, 0.047, 6056, 11782, 6133, 11936, 2402),
}
#: Fig. 2 of the paper: divergence starts at θ = 78 on mesh1 (P/M = 12/32) and θ = 75 on mesh2 (48/80).
PAPER_DIVERGENCE = {12: 78.0, 48: 75.0}
THETA_GRID = (5.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 65.0, 70.0, 75.0, 80.0, 85.0, 90.0)
THETA_MESHES = ((12, 32), (48, 80))
SWEEP_MAX_ITERATIONS = 60000
BISECTION_STEPS = 6
RESULTS = Path("results")
DOCS = Path("docs")


def _quiet(_line: str) -> None:
    pass


# --- Table 1 ----------------------------------------------------------------------------------
def table1() -> list[dict]:
    """Table 1 beside the paper: mesh sizes, the paper's algorithm and the default method."""
    RESULTS.mkdir(exist_ok=True)
    records = []
    for P, M in TABLE1_MESHES:
        print(f"table1: P = {P}, M = {M}", flush=True)
        records.append(report.launch(4, ["bench-mesh", "table1", str(P), str(M)], RESULTS / f".table1-{P}.json"))
    report.write_records(RESULTS / "table1.h5", records, records[0]["provenance"])
    report.section(DOCS / "results.md", "table1", table1_text(records))
    return records


def table1_text(records: list[dict]) -> str:
    lines = [
        "| P | M | h⁻min | h⁻max | h⁺min | h⁺max | Nod⁻ | Tri⁻ | Nod⁺ | Tri⁺ | iter | paper iter | ratio "
        "| default rounds | default (s) | default error |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    worst_size, worst_h, ratios = 0.0, 0.0, []
    for r in records:
        paper = PAPER_TABLE1[r["P"]]
        lower, upper = r["mesh"]["lower"], r["mesh"]["upper"]
        ours = (lower["h_min"], lower["h_max"], upper["h_min"], upper["h_max"],
                lower["vertices"], lower["triangles"], upper["vertices"], upper["triangles"])
        worst_size = max(worst_size, *(abs(o / p - 1.0) for o, p in zip(ours[4:], paper[5:9])))
        worst_h = max(worst_h, *(abs(o / p - 1.0) for o, p in zip(ours[:4], paper[1:5])))
        uzawa = next(run for run in r["runs"] if run["method"] == "uzawa")
        best = next(run for run in r["runs"] if run["method"] != "uzawa")
        ratios.append(uzawa["iterations"] / paper[9])
        cells = " | ".join(f"{o:.4g} ({p:g})" if i < 4 else f"{o} ({p})" for i, (o, p) in enumerate(zip(ours, paper[1:9])))
        lines.append(f"| {r['P']} | {r['M']} | {cells} | {uzawa['iterations']} | {paper[9]} | {ratios[-1]:.2f} "
                     f"| {best['rounds']} | {best['wall_time']:.3f} | {best['energy_error']:.1e} |")
    lines += [
        "",
        "Our values with the paper's in parentheses. The paper does not say what its h is; we give the smallest and "
        "largest circumdiameter (2R) of a triangle, which is within 18 % of every one of its values (the longest "
        "edge would be within 23 %). *iter* is the "
        "Uzawa iterations with θ = 65 and the paper's stop rule, *default* the `schur` method (rounds of block "
        "solves, solve-phase time on 4 ranks, relative energy error against the monolithic reference).",
        "",
        f"Vertex and triangle counts are within {100 * worst_size:.0f} % of the paper's on every row, h within "
        f"{100 * worst_h:.0f} %. The iteration "
        f"counts are {min(ratios):.2f}–{max(ratios):.2f} times the paper's and grow with the mesh as the paper's do, "
        "but faster: plain Uzawa needs O(1/h) iterations on a dual problem whose condition number grows like 1/h, "
        "and the paper's rule ‖Δx‖/‖x‖² is not scale-free, so the counts also depend on units and meshing details "
        "the paper leaves open. The default method needs three rounds on every mesh.",
    ]
    return "\n".join(lines)


# --- θ sweep (Fig. 2) -------------------------------------------------------------------------
def converges(scene, comm, mesh) -> tuple[bool, int]:
    """Run uzawa; (converged, iterations).  A run that neither converges nor blows up counts as failed."""
    from ddsolve.errors import NotConvergedError
    from ddsolve.solvers import driver

    try:
        result = driver.solve_decomposed(scene, comm, None, progress=_quiet, mesh=mesh)
        return True, result.iterations
    except NotConvergedError:
        return False, SWEEP_MAX_ITERATIONS
    except DDSolveError:
        return False, 0


def theta_mesh(P: int, M: int, scene_name: str, output: Path, comm) -> None:
    """One mesh and scene: 2/λmax by power iteration, iterations over the θ grid, bisected threshold."""
    from ddsolve.mesh import geometry
    from ddsolve.parallel.launch import provenance
    from ddsolve.problem import scene as scenes
    from ddsolve.solvers import driver

    def scene(theta: float):
        return scenes.load(scene_name, [f"mesh.sigma_vertices={P}", f"mesh.boundary_vertices={M}",
                                        "solver.method=uzawa", f"solver.theta={theta}",
                                        f"solver.max_iterations={SWEEP_MAX_ITERATIONS}"])

    mesh = comm.bcast(geometry.build(scene(65.0)) if comm.rank == 0 else None, root=0)
    lam_max = driver.bound(scene(65.0), comm, mesh)
    runs = []
    for theta in THETA_GRID:
        ok, iterations = converges(scene(theta), comm, mesh)
        runs.append({"theta": theta, "converged": ok, "iterations": iterations})
    good = [r["theta"] for r in runs if r["converged"]]
    bad = [r["theta"] for r in runs if not r["converged"] and good and r["theta"] > max(good)]
    low, high = (max(good), min(bad)) if good and bad else (np.nan, np.nan)
    for _ in range(BISECTION_STEPS if bad else 0):
        middle = 0.5 * (low + high)
        ok, iterations = converges(scene(middle), comm, mesh)
        runs.append({"theta": middle, "converged": ok, "iterations": iterations})
        low, high = (middle, high) if ok else (low, middle)
    if comm.rank == 0:
        output.write_text(json.dumps({"P": P, "M": M, "scene": scene_name, "lambda_max": lam_max,
                                      "bound": 2.0 / lam_max, "threshold": [low, high],
                                      "runs": sorted(runs, key=lambda r: r["theta"]), "provenance": provenance()}))


def theta_sweep() -> list[dict]:
    """Iterations against θ on mesh1 and mesh2 (Example 1) and on mesh2 with the crack fully closed."""
    RESULTS.mkdir(exist_ok=True)
    records = []
    for (P, M), scene_name in [(THETA_MESHES[0], "partial-closure"), (THETA_MESHES[1], "partial-closure"),
                               (THETA_MESHES[1], "full-closure")]:
        print(f"theta-sweep: P = {P}, M = {M}, {scene_name}", flush=True)
        # One rank: the iteration counts do not depend on the number of ranks, and one rank is fastest here.
        records.append(report.launch(1, ["theta-mesh", str(P), str(M), scene_name],
                                     RESULTS / f".theta-{P}-{scene_name}.json"))
    report.write_records(RESULTS / "theta-sweep.h5", records, records[0]["provenance"])
    theta_plot(records, DOCS / "theta-sweep.png")
    report.section(DOCS / "results.md", "theta-sweep", theta_text(records))
    return records


def theta_plot(records: list[dict], path: Path) -> None:
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.8), constrained_layout=True)
    for record, color in zip(records, ("tab:blue", "tab:orange", "tab:red")):
        runs = [r for r in record["runs"] if r["converged"]]
        label = f"P/M = {record['P']}/{record['M']}, {record['scene']}"
        ax.semilogy([r["theta"] for r in runs], [r["iterations"] for r in runs], marker="o", color=color, label=label)
        ax.axvline(record["bound"], color=color, linestyle=":", linewidth=1)
        ax.axvspan(record["threshold"][0], record["threshold"][1], color=color, alpha=0.25)
        if record["scene"] == "partial-closure":
            ax.axvline(PAPER_DIVERGENCE[record["P"]], color=color, linestyle="--", linewidth=1,
                       label=f"paper: P/M = {record['P']}/{record['M']} diverges at {PAPER_DIVERGENCE[record['P']]:g}")
    ax.set_xlim(0, max(THETA_GRID) + 2)
    ax.set_xlabel("θ")
    ax.set_ylabel("Uzawa iterations (paper's stop rule)")
    ax.set_title("Iterations against θ; dotted: 2/λmax (power iteration); band: divergence threshold")
    ax.legend(fontsize=8, loc="upper center")
    ax.grid(alpha=0.3, which="both")
    fig.savefig(path, dpi=130)
    plt.close(fig)


def theta_text(records: list[dict]) -> str:
    lines = ["| mesh P/M | scene | 2/λmax | diverges above | paper | iterations at θ = 5, 30, 65 |",
             "|---|---|---|---|---|---|"]
    for r in records:
        at = {run["theta"]: run for run in r["runs"]}
        counts = ", ".join(str(at[t]["iterations"]) if at[t]["converged"] else "—" for t in (5.0, 30.0, 65.0))
        paper = f"{PAPER_DIVERGENCE[r['P']]:g}" if r["scene"] == "partial-closure" else "—"
        lines.append(f"| {r['P']}/{r['M']} | {r['scene']} | {r['bound']:.1f} | "
                     f"{r['threshold'][0]:.1f}–{r['threshold'][1]:.1f} | {paper} | {counts} |")
    ex1 = [r for r in records if r["scene"] == "partial-closure"]
    closed = next(r for r in records if r["scene"] == "full-closure")
    deviations = [abs(0.5 * sum(r["threshold"]) / PAPER_DIVERGENCE[r["P"]] - 1.0) for r in ex1]
    lines += [
        "",
        "![iterations against θ](theta-sweep.png)",
        "",
        "As in the paper's Fig. 2, the iteration count falls as θ grows until the iteration diverges, and small θ "
        f"converge but need many more iterations. Our divergence thresholds are within {100 * max(deviations):.0f} % "
        "of the paper's 78 and 75.",
        "",
        "Why θ = 65 converges although 2/λmax is smaller: 2/λmax is the stable bound of the *full* dual "
        "operator C K⁻¹ Cᵀ W, with every multiplier free to move. In Example 1 the crack is open on its left "
        "part (x < 0.18), where the projection onto μᶜ ≥ 0 holds the contact multipliers at zero: near the "
        "solution the iteration acts on the operator restricted to the other multipliers, whose largest "
        "eigenvalue is smaller, so larger steps stay stable. When the crack is fully closed "
        f"(scene `full-closure`, the loads of Example 2 reversed) every contact multiplier is active, the full "
        f"operator applies and the iteration diverges above θ ≈ {np.mean(closed['threshold']):.1f}, right at "
        f"2/λmax = {closed['bound']:.1f}: the paper's θ = 65 fails there. A robust solver therefore has to "
        "estimate the bound itself; the methods other than `uzawa` never need θ.",
    ]
    return "\n".join(lines)


# --- Figs. 1, 3 and 4 -------------------------------------------------------------------------
#: (figure, scene, magnification) at the paper's P = 96, M = 144.
FIGURES = (("fig1", "partial-closure", 500.0), ("fig3", "linear", 500.0), ("fig4", "full-opening", 100.0))


def figures() -> None:
    """Deformed layers coloured by von Mises stress, and the normal jump along Σ (contact vs overlap)."""
    from ddsolve.io import hdf5
    from ddsolve.post import plots

    RESULTS.mkdir(exist_ok=True)
    results = {}
    for figure, scene_name, scale in FIGURES:
        path = RESULTS / f"{figure}-{scene_name}.h5"
        print(f"figures: {scene_name} -> {path}", flush=True)
        report.run(4, ["solve", scene_name, "--set", "mesh.sigma_vertices=96", "--set",
                          "mesh.boundary_vertices=144", "-o", str(path)])
        results[scene_name] = hdf5.read(path)
        plots.deformed_layers(results[scene_name], DOCS / f"{figure}-{scene_name}.png", scale)
    plots.interface_jumps([("Example 1 (non-penetration)", results["partial-closure"]),
                           ("linear problem (faces free)", results["linear"])], DOCS / "fig3-jump.png")
    report.section(DOCS / "results.md", "figures", figures_text(results))


def figures_text(results: dict) -> str:
    from ddsolve.post.analysis import normal_jump

    contact, linear = results["partial-closure"], results["linear"]
    crack = contact.crack
    overlap = contact.interface_x[crack][normal_jump(linear)[crack] < 0]
    closed = contact.interface_x[crack][contact.multipliers["mu_c"][crack] > 0]
    return "\n".join([
        "![Example 1, displacements x500](fig1-partial-closure.png)",
        "",
        "Fig. 1 (Example 1, partial closure, ×500): the loaded layer 1 (left) bends so that the crack opens on "
        "its left part and closes on the right; layer 2 (right), unloaded, follows through the gluing and "
        "concentrates stress at the left crack tip, as in the paper's figure.",
        "",
        "![Linear problem, displacements x500](fig3-linear.png)",
        "![Normal jump along Σ](fig3-jump.png)",
        "",
        f"Fig. 3 (the linear problem, ×500, and the jump [u]·ν along Σ): without the non-penetration condition "
        f"the faces overlap (negative jump) on the right half of the crack, x in [{overlap.min():.2f}, "
        f"{overlap.max():.2f}] — the paper's observation that linear crack conditions allow interpenetration. "
        f"With the condition (Example 1) the faces are in contact there instead (μᶜ > 0 for x in "
        f"[{closed.min():.2f}, {closed.max():.2f}], zero jump), and the contact pressure opens the left part "
        "slightly wider.",
        "",
        "![Example 2, displacements x100](fig4-full-opening.png)",
        "",
        f"Fig. 4 (Example 2, full opening, ×100): uniform tension opens the whole crack (largest opening "
        f"{normal_jump(results['full-opening'])[crack].max():.2e}); no contact multiplier is active.",
        "",
        "All three at the paper's mesh P = 96, M = 144, solved by the default method; regenerate with "
        "`./run figures` (about a minute).",
    ])
