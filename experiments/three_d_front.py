"""G along 3-D crack fronts: ``./run three-d-front`` writes docs/three-d-front.md (its front section: the shapes
section is ``./run three-d-shapes``'s) and docs/three-d-front.png.

Two checks of the G-θ integral with θ localised along the front (:mod:`ddsolve.post.front`) on the 3-D monolithic
reference (P1 or P2 tetrahedra graded towards the front):

* the plane scene of docs/three-d.md (two materials, the crack pulled open; and partly shut, contact active)
  extruded in z with rollers on both z faces: G(z) at the interior front nodes against the plane G of the same
  scene at graded P2 (``mesh.size`` 0.05);
* the penny-shaped crack of radius a = ½ in a box of half-side L, a quarter model by symmetry (rollers on x = 0 and
  z = 0), one material, a unit traction on the top and the bottom on rollers: the mean G along the front against
  Sneddon's G = 4 (1 − ν²) σ² a / (π E) of the infinite body, its spread, and the finite box's effect (L = 2
  against L = 3).
"""
from __future__ import annotations

import time

import numpy as np

from experiments import report, three_d
from ddsolve.mesh import geometry, solid
from ddsolve.post import fracture, front
from ddsolve.problem.scene import loads
from ddsolve.solvers import reference as plane_reference
from ddsolve.solvers import solid as solid_reference

#: The extruded scene's runs (mesh.size, degree), the penny's (mesh.size, box half-side L, degree), and the grading
#: exponent of all (mesh.grading: h ∝ r^0.8 near the front, stronger than P1's default 0.4).
EXTRUDED_RUNS = ((0.1, 1), (0.07, 1), (0.14, 2))
PENNY_RUNS = ((0.15, 2.0, 1), (0.1, 2.0, 1), (0.1, 3.0, 1), (0.2, 2.0, 2), (0.15, 2.0, 2), (0.2, 3.0, 2))
GRADING = 0.2
#: The quarter penny of radius ½ (tests/test_front.py solves its coarsest size).
PENNY = """
[geometry]
box = [0, {L}, -{L}, {L}, 0, {L}]
cracks = [{{center = [0, 0], radii = [0.5, 0.5]}}]
clamped = []
[mesh]
size = {size}
grading = {grading}
[materials.layer1]
E = 1.0
nu = 0.3
[loads.layer1.top]
y = 1.0
[displacements.layer1.bottom]
y = 0.0
[displacements.layer1.left]
x = 0.0
[displacements.layer1.front]
z = 0.0
"""
#: Sneddon's G of the penny in an infinite body, 4 (1 − ν²) σ² a / (π E), for σ = E = 1, ν = 0.3, a = ½.
SNEDDON = 4.0 * (1.0 - 0.3 ** 2) * 0.5 / np.pi


def penny_scene(size: float, half_side: float = 2.0, degree: int = 1):
    """The quarter penny in the box [0, L] × [−L, L] × [0, L] on P1 or P2 tetrahedra."""
    return loads(PENNY.format(L=half_side, size=size, grading=GRADING)).with_({"mesh.degree": degree})


def solved(scene) -> tuple:
    """The 3-D reference of ``scene`` and G along its fronts, with the unknowns and the seconds of the solve."""
    started = time.perf_counter()
    mesh = solid.build(scene)
    result = solid_reference.solve_solid(scene, mesh)
    seconds = time.perf_counter() - started
    return result, front.release(result), mesh.unknowns, seconds


def plane_G(case: str, size: float = 0.05) -> np.ndarray:
    """The plane G at both tips (left, right) at graded P2 of ``size``."""
    scene = three_d.scene_of(case, size, 2, graded=True)
    return fracture.evaluate(plane_reference.solve_monolithic(scene, geometry.build(scene))).G


def interior_ratios(released: front.FrontRelease, plane: np.ndarray, tip: int) -> np.ndarray:
    """G(z) / the plane G along the front of ``tip`` (0 left, 1 right) at its nodes off the z faces."""
    depth = released.points[:, 2]
    on = ((released.points[:, 0] > 0) == bool(tip)) & (depth > 1e-9) & (depth < three_d.DEPTH - 1e-9)
    return released.G[on] / plane[tip]


def measure() -> dict:
    """Every run's numbers and G along its fronts."""
    out = {"extruded": {}, "penny": []}
    for case in three_d.CASES:
        plane = plane_G(case)
        rows = []
        for size, degree in EXTRUDED_RUNS:
            scene = three_d.scene_of(case, size, 3).with_({"mesh.grading": GRADING, "mesh.degree": degree})
            result, released, unknowns, seconds = solved(scene)
            ratios = [interior_ratios(released, plane, tip) for tip in (0, 1)]
            rows.append({"size": size, "degree": degree, "unknowns": unknowns, "seconds": seconds,
                         "closed": result.closed,
                         "ratios": ratios, "released": released, "plane": plane})
        out["extruded"][case] = rows
    for size, half_side, degree in PENNY_RUNS:
        result, released, unknowns, seconds = solved(penny_scene(size, half_side, degree))
        out["penny"].append({"size": size, "L": half_side, "degree": degree, "unknowns": unknowns,
                             "seconds": seconds, "released": released})
    return out


def page(measured: dict) -> str:
    """docs/three-d-front.md from :func:`measure`."""
    lines = ["# Three dimensions: G along the crack front", "",
             "G per unit length of front at every front node by the G-θ integral with θ localised along the front "
             "(the 3-D reference, P1 or P2 tetrahedra graded towards the front; ddsolve.post.front): θ_k = "
             "φ_k(s) c(r) n(s), φ_k a hat along the front's arc length s of half-width the inner radius (at least "
             "one front edge), c the radial cut-off (1 inside the inner radius, 0 beyond the outer) and n the "
             "in-plane normal of the front; G_k = J(θ_k) / ∫ φ_k ds.  J is exact for the discrete problem (the "
             "derivative of the discrete energy as the nodes move by θ: tests/test_front.py).  A hat one front "
             "edge wide scatters G from node to node by ±30 % on P1 (the error of the field at the element scale "
             "enters through ∂φ/∂s); the hats as wide as the inner radius keep the spread to a few per cent and "
             "still resolve G along a front many inner radii long.", "",
             "## Input and output", "",
             "A crack on a 3-D box's Σ is a strip `[a, b]`, a rectangle `[a, b, c, d]` or an ellipse "
             "`{center = [x, z], radii = [r1, r2]}` (axes along x and z; its part inside the box is the crack: a "
             "centre on a side gives half or a quarter of it, with rollers the model of a symmetric crack).  "
             "`ddsolve reference` computes G at every front node (`fracture.inner` and `fracture.outer` set θ's "
             "radii; by default half the distance to the nearest side the front does not end on, other front or "
             "the front's smallest radius of curvature, and half that) and writes, one row per front node, "
             "`/fracture/points`, `/fracture/tangents`, `/fracture/normals` (n, 3), `/fracture/front` (which chain), "
             "`/fracture/arclength`, `/fracture/G`, `/fracture/G_I`, `/fracture/G_II`, `/fracture/G_III`, the phase "
             "angles `/fracture/phase` ψ = atan2(K_II, K_I) and `/fracture/phase_III` φ = atan2(K_III, "
             "√(K_I² + K_II²)) in degrees, and the radii `/fracture/inner`, `/fracture/outer`.", "",
             "## The extruded plane scene", "",
             f"docs/three-d.md's scene (two materials, clamped left and right) extruded over z in [0, 0.5] with "
             f"rollers on both z faces, mesh.grading = {GRADING}, against the plane G at graded P2 (mesh.size "
             "0.05) of the same scene; G(z) / G_plane over the front nodes off the z faces (the modes are not split "
             "between two materials):",
             ""]
    for case, rows in measured["extruded"].items():
        plane = rows[0]["plane"]
        lines += [f"### {case} (plane G: {plane[0]:.6e} at the left tip, {plane[1]:.6e} at the right)", "",
                  "| tetrahedra | mesh.size | 3-D unknowns | closed vertices | front | mean G / G_plane | lowest | "
                  "highest | seconds |", "|---|---|---|---|---|---|---|---|---|"]
        lines += [f"| P{r['degree']} | {r['size']:g} | {r['unknowns']} | {r['closed']} | {side} | "
                  f"{ratios.mean():.4f} | "
                  f"{ratios.min():.4f} | {ratios.max():.4f} | {r['seconds']:.1f} |"
                  for r in rows for side, ratios in zip(("left", "right"), r["ratios"])]
        lines.append("")
    lines += ["## The penny-shaped crack", "",
              f"A quarter of the penny of radius a = ½ (rollers on x = 0 and z = 0), one material (E = 1, ν = 0.3), "
              f"a unit traction on the top of the box [0, L] × [−L, L] × [0, L] and its bottom on rollers, "
              f"mesh.grading = {GRADING}; Sneddon's G of the infinite body {SNEDDON:.6f}.  Spread = "
              "(largest − smallest G) / mean G over the front; G_II and G_III (the mirror split) against G:", "",
              "| tetrahedra | mesh.size | L / a | unknowns | front nodes | mean G / Sneddon | spread | "
              "mean G_I / Sneddon | largest abs G_II, G_III / G | seconds |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for run in measured["penny"]:
        f = run["released"]
        mixed = max(np.abs(f.G_II).max(), np.abs(f.G_III).max()) / f.G.mean()
        lines.append(f"| P{run['degree']} | {run['size']:g} | {run['L'] / 0.5:g} | {run['unknowns']} | {len(f.G)} | "
                     f"{f.G.mean() / SNEDDON:.4f} | {100 * np.ptp(f.G) / f.G.mean():.1f} % | "
                     f"{f.G_I.mean() / SNEDDON:.4f} | {mixed:.1e} | {run['seconds']:.1f} |")
    lines += ["", penny_text(measured["penny"]), "", MODES_TEXT, "", "![G along each front](three-d-front.png)", ""]
    return "\n".join(lines)


#: How the modes are split, and why.
MODES_TEXT = (
    "Modes: where the materials above and below Σ are the same, the fields split into their parts symmetric and "
    "antisymmetric about Σ (the other half's field read at each node's mirror image, located in its tetrahedra), "
    "as the plane code splits them; G_I is the integral of the symmetric part, and the antisymmetric part splits "
    "in the front's frame into its component along the tangent t (tearing: G_III) and the rest (sliding: G_II).  "
    "This needs no auxiliary fields, so it holds on a curved front without the curvature terms an interaction "
    "integral with the straight front's fields would need; between two materials it does not apply (the modes "
    "are NaN: the interface crack's oscillatory fields, which the plane code splits by an interaction integral).")


def penny_text(runs: list[dict]) -> str:
    """The penny's accuracy at P1 and P2 and the finite box's effect, read from the runs."""
    by = {(run["degree"], run["size"], run["L"]): run["released"] for run in runs}
    error = {key: released.G.mean() / SNEDDON - 1.0 for key, released in by.items()}
    box = error[2, 0.15, 2.0] - error[2, 0.2, 3.0]
    return (f"P2 is {100 * error[2, 0.2, 3.0]:+.1f} % from Sneddon at L/a = 6 (mesh.size 0.2) and "
            f"{100 * error[2, 0.15, 2.0]:+.1f} % at L/a = 4 (mesh.size 0.15): the finite box releases more than "
            f"the infinite body, by about {100 * box:.1f} % at L/a = 4.  P1 at mesh.size 0.1 is "
            f"{100 * error[1, 0.1, 2.0]:+.1f} % at L/a = 4 and {100 * error[1, 0.1, 3.0]:+.1f} % at L/a = 6: within "
            "3 % of Sneddon with the spread near 1 %, but below the box's own value by its stiffness at the front "
            f"(about {100 * (box - error[1, 0.1, 2.0]):.1f} % at L/a = 4).  At one mesh.size the grading radius, "
            "which scales with the box, makes the meshes at the front differ (P2 at mesh.size 0.2: "
            f"{len(by[2, 0.2, 2.0].G)} front nodes at L/a = 4, {len(by[2, 0.2, 3.0].G)} at L/a = 6), so runs of "
            "one mesh.size in two boxes do not isolate the box.")


def plot(measured: dict) -> None:
    """docs/three-d-front.png: G along the extruded fronts (finest) and along the penny's front (every run)."""
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for case, rows in measured["extruded"].items():
        f = rows[-1]["released"]
        for tip, marker in ((0, "o"), (1, "s")):
            on = (f.points[:, 0] > 0) == bool(tip)
            axes[0].plot(f.points[on, 2], f.G[on] / rows[-1]["plane"][tip], marker + "-", markersize=3,
                         label=f"{case}, {'right' if tip else 'left'} front")
    axes[0].set_xlabel("z along the front")
    axes[0].set_ylabel("G(z) / plane G (graded P2)")
    axes[0].set_title(f"extruded plane scene, P{rows[-1]['degree']} at mesh.size {rows[-1]['size']:g}", fontsize=10)
    for run in measured["penny"]:
        f = run["released"]
        angle = np.degrees(np.arctan2(f.points[:, 2], f.points[:, 0]))
        axes[1].plot(angle, f.G / SNEDDON, ".-",
                     label=f"P{run['degree']}, mesh.size {run['size']:g}, L/a = {run['L'] / 0.5:g}")
    axes[1].axhline(1.0, color="k", lw=0.8)
    axes[1].set_xlabel("angle along the front (degrees from the x axis)")
    axes[1].set_ylabel("G / Sneddon")
    axes[1].set_title("quarter penny-shaped crack", fontsize=10)
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.savefig(three_d.DOCS / "three-d-front.png", dpi=130)
    plt.close(fig)


def three_d_front() -> None:
    """Measure, and write docs/three-d-front.md and its picture."""
    measured = measure()
    plot(measured)
    report.section(three_d.DOCS / "three-d-front.md", "front", page(measured))
    print(f"wrote {three_d.DOCS / 'three-d-front.md'}")
