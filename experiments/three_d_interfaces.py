"""A 3-D box of several interfaces: ``./run three-d-interfaces`` writes its section of docs/three-d.md.

Two checks.  The plane structure of docs/two-interfaces.toml as one body (three regions, the middle one twice as
stiff, a crack on each interface, clamped on the left, pulled on the right and pressed top and bottom: contact on
both cracks) extruded in z over [0, ½] with rollers (u_z = 0) on the front and the back is plane strain: its
energy per unit depth against the plane reference (P2, three sizes: the continuous value extrapolated), and G at
the interior front nodes of each crack against the plane G at its tip (the finest plane mesh), on P2 tetrahedra
graded towards the fronts at three sizes.  And docs/three-d-interfaces.toml (a rectangle crack on the lower Σ,
both cracks partly shut) solved by the reference and by the regions' decomposition in this process (schur and
feti, one rank): their energy-norm difference and the shut vertices on each Σ.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from experiments import report, three_d
from ddsolve.mesh import solid
from ddsolve.problem.scene import load, loads
from ddsolve.solvers import run
from ddsolve.solvers import solid as solid_reference

DOCS = Path("docs")
SAMPLE = DOCS / "three-d-interfaces.toml"
DEPTH = 0.5
#: The plane P2 sizes (the continuous energy extrapolated through them, G from the finest) and the 3-D P2 ones.
PLANE_SIZES, SOLID_SIZES = (0.1, 0.05, 0.025), (0.3, 0.25, 0.2)
#: The grading of the 3-D tetrahedra towards the fronts (h ∝ r^0.8 near them, as docs/three-d-front.md's).
GRADING = 0.2
#: The crack tips: (interface, x), bottom to top, left to right.
TIPS = ((1, 1.0), (1, 2.0), (2, 2.0), (2, 3.0))
STRUCTURE = """
title = "two interfaces, {dimension}"
[geometry]
box = {box}
sigma = [1.0, 2.0]
cracks = [[[1.0, 2.0]], [[2.0, 3.0]]]
clamped = ["left"]
{layers}
[mesh]
size = {size}
degree = 2
{grading}
[materials.layer1]
E = 1.0
nu = 0.3
[materials.layer1.region2]
E = 2.0
[loads.layer1.right]
x = 0.1
[loads.layer1.top]
y = -0.05
[loads.layer1.bottom]
y = 0.05
{rollers}
"""


def scene_of(size: float, dimension: int):
    """The structure in the plane (one body) or extruded over [0, DEPTH] with rollers, P2 (graded in 3-D)."""
    solid_box = dimension == 3
    return loads(STRUCTURE.format(dimension="extruded" if solid_box else "plane", size=size,
                                  box=[0.0, 4.0, 0.0, 3.0, 0.0, DEPTH] if solid_box else [0.0, 4.0, 0.0, 3.0],
                                  layers="" if solid_box else "layers = 1",
                                  grading=f"grading = {GRADING}" if solid_box else "",
                                  rollers=three_d.ROLLERS if solid_box else ""))


def plane(size: float) -> dict:
    """The plane reference: energy, G at every tip (in :data:`TIPS` order), unknowns, seconds."""
    started = time.perf_counter()
    result = run.reference(scene_of(size, 2), None)
    seconds = time.perf_counter() - started
    fracture = result.fracture
    G = [float(fracture.G[(fracture.interface == k) & np.isclose(fracture.points[:, 0], x)][0]) for k, x in TIPS]
    return {"size": size, "energy": result.energy, "G": G, "seconds": seconds,
            "unknowns": sum(u.size for u in result.solution.values())}


def extruded(size: float) -> dict:
    """The 3-D reference per unit depth: energy, shut vertices, and G at the interior front nodes of each tip."""
    scene = scene_of(size, 3)
    started = time.perf_counter()
    mesh = solid.build(scene)
    result = solid_reference.reference_on(scene, mesh)
    seconds = time.perf_counter() - started
    assert result.converged, result.message
    fracture = result.fracture
    inside = (fracture.points[:, 2] > 1e-9) & (fracture.points[:, 2] < DEPTH - 1e-9)
    G = [fracture.G[inside & (result.fracture_interface == k) & np.isclose(fracture.points[:, 0], x)]
         for k, x in TIPS]
    return {"size": size, "energy": result.energy / DEPTH, "unknowns": mesh.unknowns, "seconds": seconds,
            "closed": [int(np.count_nonzero(p > 0)) for p in result.pressures], "G": G}


def sample() -> dict:
    """docs/three-d-interfaces.toml by the reference and by the regions' decomposition (one rank, schur and
    feti at solver.tol 1e-12): energies, energy-norm differences, iterations and shut vertices per Σ."""
    from mpi4py import MPI

    from ddsolve.solvers import solid_dd

    scene = load(SAMPLE)
    mesh = solid.build(scene)
    reference = solid_reference.reference_on(scene, mesh)
    rows = {"reference": (reference, 0.0)}
    for method in ("schur", "feti"):
        result = solid_dd.solve(scene.with_({"solver.method": method, "solver.tol": 1e-12}), MPI.COMM_SELF, None,
                                progress=lambda _line: None, mesh=mesh)
        rows[method] = (result, solid_reference.energy_error(result, reference))
    return {"unknowns": mesh.unknowns, "cracked": [int(s.cracked.sum()) for s in mesh.sigmas], "rows": rows}


def page(planes: list[dict], solids: list[dict], checked: dict) -> str:
    """The section's text from the measurements."""
    exact, rate = three_d.extrapolated(planes)
    finest = planes[-1]["G"]
    lines = ["## Several interfaces", "",
             "Generated by `./run three-d-interfaces` (experiments/three_d_interfaces.py).  A 3-D box takes "
             "`geometry.sigma = [y1, y2, ...]` and one crack list per interface (`cracks = [[...], [...]]`, each "
             "crack a strip, a rectangle or an ellipse), materials per region (`[materials.layer1.region2]`, "
             "region1 the lowest); it is meshed conforming across every Σ, solved by `ddsolve reference` and by "
             "`ddsolve solve` (a block per region, joints at every Σ: μᶜ on its cracks, μᵍ off them; any rank count "
             "up to the regions or a multiple of them), and writes each region's group (`/region1` …), each Σ under "
             "`/interfaces/N/sigma`, `/fracture` with `/fracture/interface` (each front node's Σ, 1 the lowest), "
             "a VTU file per region and per Σ and the ParaView script that shows them.  `mesh.extrude`, "
             "`mesh.target_error` and slabs (`solver.pieces` > 1) are refused there; a region held only through its "
             "interfaces floats and is solved as a floating slab is.  A 3-D gmsh file of several interfaces "
             "(surfaces `sigma1`, `sigma2`, … and a volume per region, [geometry.md](geometry.md#3-d-files)) is "
             "solved the same way: `docs/three-d-interfaces.geo` (`three-d-interfaces-file.toml`) gives the "
             "sample's tetrahedra, energy and G.", "",
             "### The plane structure extruded", "",
             f"docs/two-interfaces.toml's structure as one body, extruded over z in [0, {DEPTH:g}] with rollers on "
             f"both z faces; the plane reference at P2 gives the continuous energy per unit depth {exact:.9e} "
             f"(Π_h = Π + C N^-a through its three sizes, a = {rate:.2f}):", "",
             "| plane mesh.size | unknowns | energy | " + " | ".join(f"G Σ{k} x = {x:g}" for k, x in TIPS)
             + " | seconds |", "|---|---|---|" + "---|" * len(TIPS) + "---|"]
    lines += [f"| {p['size']:g} | {p['unknowns']} | {p['energy']:.9e} | " + " | ".join(f"{g:.5e}" for g in p["G"])
              + f" | {p['seconds']:.1f} |" for p in planes]
    lines += ["", f"The 3-D reference on P2 tetrahedra graded towards the fronts (mesh.grading = {GRADING}): the "
              "energy per unit depth against the plane continuous one (energy norm √((Π_h − Π)/|Π|)), and G at the "
              "front nodes off the z faces over the finest plane G of the same tip (mean, lowest, highest):", "",
              "| 3-D mesh.size | unknowns | energy per depth | error | shut vertices Σ1, Σ2 | "
              + " | ".join(f"G / G_plane Σ{k} x = {x:g}" for k, x in TIPS) + " | seconds |",
              "|---|---|---|---|---|" + "---|" * len(TIPS) + "---|"]
    for s in solids:
        ratios = [f"{(g / reference).mean():.4f} ({(g / reference).min():.4f}–{(g / reference).max():.4f})"
                  if len(g) else "no interior node" for g, reference in zip(s["G"], finest)]
        lines.append(f"| {s['size']:g} | {s['unknowns']} | {s['energy']:.9e} | "
                     f"{100 * three_d.energy_norm_error(s['energy'], exact):.2f} % | {s['closed'][0]}, "
                     f"{s['closed'][1]} | " + " | ".join(ratios) + f" | {s['seconds']:.1f} |")
    change = [100 * (g / h - 1) for g, h in zip(finest, planes[-2]["G"])]
    last = solids[-1]
    lines += ["", "The tip at x = 1 of the lower crack lies in its contact zone: its G is about a thousandth of the "
              "others' and its ratio measures the meshes' resolution of a closed tip, not G.  At the other tips the "
              f"3-D G at mesh.size {last['size']:g} ({last['unknowns']} unknowns) is within "
              f"{100 * max(abs(g.mean() / h - 1) for g, h in zip(last['G'][1:], finest[1:])):.1f} % of the finest "
              "plane G, and the ratios rise towards 1 as the tetrahedra shrink; the plane G itself (uniform P2, "
              "no grading: a plane structure of several interfaces is not graded) still changes by "
              + ", ".join(f"{c:+.1f} %" for c in change[1:]) + " at its last halving, so part of what is left is "
              "the plane's own error.  The energy error falls slowly, as that of gmsh's tetrahedra about one "
              "interface's crack front does above.", "",
              "### The sample: the decomposition against the reference", "",
              f"docs/three-d-interfaces.toml ({checked['unknowns']} unknowns; crack vertices {checked['cracked'][0]} "
              f"on Σ1 and {checked['cracked'][1]} on Σ2), in this process:", "",
              "| solve | iterations | energy | energy-norm difference from the reference | shut vertices Σ1, Σ2 |",
              "|---|---|---|---|---|"]
    for name, (result, error) in checked["rows"].items():
        shut = [int(np.count_nonzero(p > 0)) for p in result.pressures]
        lines.append(f"| {name} | {result.steps} | {result.energy:.10e} | {error:.1e} | {shut[0]}, {shut[1]} |")
    lines += ["", "On ranks (each region on its own rank, or on 2): `./run reference docs/three-d-interfaces.toml "
              "-o ref.h5`, `./run solve -n 3 docs/three-d-interfaces.toml -o dd.h5` (and `-n 6`), `./run compare "
              "dd.h5 ref.h5`."]
    return "\n".join(lines)


def three_d_interfaces() -> None:
    """Measure and write the section of docs/three-d.md."""
    planes = [plane(size) for size in PLANE_SIZES]
    solids = [extruded(size) for size in SOLID_SIZES]
    report.section(DOCS / "three-d.md", "three-d-interfaces", page(planes, solids, sample()))
