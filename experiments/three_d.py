"""The extrusion check of the 3-D reference: ``./run three-d`` writes docs/three-d.md.

A plane scene (the paper's square cut by Σ at y = 0, the crack (−½, ½), one body: the paper's two materials below
and above Σ, clamped left and right) extruded in z over [0, ½] with rollers (u_z = 0) on the front and the back
is plane strain: its energy per unit depth is the plane energy, and its crack opening at any depth the plane
opening.  Two load cases: the crack pulled open (Example 2's loads) and partly shut (Example 1's, contact
active).  The plane continuous values come from the plane reference at graded P2 (three sizes, the finest
quoted); the 3-D reference is P1 on uniform tetrahedra, set beside the plane reference's uniform P1 at the same
mesh sizes (comparable meshes), then P1 graded towards the crack front (``mesh.grading = true``), P2 uniform and P2
graded (``mesh.degree = 2``), and last the plane mesh of the section (graded towards the tips) extruded in layers
along z (``mesh.extrude``), set beside the plane reference on that same section mesh;
every solve's wall time (meshing included for 3-D) is measured in this process, on a shared machine.

The same scene comes from a 3-D gmsh file too: ``docs/three-d-strip.geo`` (its scene ``docs/three-d-strip.toml``,
[geometry.md](geometry.md#3-d-files)) builds the body as the box is built, so that at the same mesh size its
tetrahedra, and so its energies, are the box's (``tests/test_solid_files.py``, also for gmsh's .msh of it).
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from experiments import report
from ddsolve.mesh import geometry, solid
from ddsolve.problem.scene import loads
from ddsolve.solvers import reference as plane_reference
from ddsolve.solvers import solid as solid_reference

DOCS = Path("docs")
#: The load cases: name -> the loads of the body's bottom and top (Examples 2 and 1 of the paper, one body).
CASES = {"opening": ("[-0.078125]", "[0.078125]"), "partial closure": ("[0.0, 0.078125]", "[0.0, -0.078125]")}
DEPTH = 0.5
#: Mesh sizes: the plane graded P2 (its continuous value from the finest) and the 3-D P1 (and the plane P1 beside).
PLANE_SIZES, SOLID_SIZES = (0.1, 0.05, 0.025), (0.2, 0.14, 0.1, 0.07, 0.05)
#: More 3-D runs: (degree, graded towards the crack front, sizes).
MORE_RUNS = ((1, True, (0.14, 0.1, 0.07)), (2, False, (0.3, 0.2, 0.14)), (2, True, (0.2, 0.14)))
#: The extrusion acceptance: the energy per depth within this energy-norm error of the plane continuous energy.
ACCEPTED = 0.03
#: Extruded runs, the section graded towards the tips: (degree, size, layers along z); the last's opening compared.
EXTRUDED_RUNS = ((1, 0.1, 2), (1, 0.05, 2), (2, 0.2, 1), (2, 0.1, 1), (2, 0.1, 2), (2, 0.05, 1))
#: Where the page points for the 3-D decomposition's speed and for G along the fronts.
SPEED = ("Its speed: the scene pulled open with its crack faces free, at about 0.3 M unknowns, is the 3-D case of "
         "``./run bench baseline`` ([methods.md](methods.md), section *bench-baseline-3d*): the decomposition into "
         "slabs on 2 ranks against one MUMPS factorization of the whole, its speed against its error "
         "([bench-3d.png](bench-3d.png)) and how its rounds grow with the mesh and the slabs.  G along the fronts, "
         "the penny, a DCB across its width and an elliptical crack: [three-d-front.md](three-d-front.md).")
SCENE = """
title = "extrusion check: {case}"
[geometry]
box = {box}
crack = [-0.5, 0.5]
{layers}
[mesh]
size = {size}
{mesh}
[materials.layer1]
E = 200.0
nu = 0.28
[materials.layer1.upper]
E = 112.0
nu = 0.32
[loads.layer1.bottom]
y = {bottom}
[loads.layer1.top]
y = {top}
{rollers}
"""
ROLLERS = "[displacements.layer1.front]\nz = 0.0\n[displacements.layer1.back]\nz = 0.0\n"


def scene_of(case: str, size: float, dimension: int, graded: bool = False):
    """The case's scene: plane (P2 graded or P1 uniform) or extruded over [0, DEPTH] with rollers."""
    bottom, top = CASES[case]
    solid_box = dimension == 3
    return loads(SCENE.format(case=case, box=[-1, 1, -1, 1, 0, DEPTH] if solid_box else [-1, 1, -1, 1],
                              layers="" if solid_box else "layers = 1", size=size,
                              mesh="degree = 2\ngrading = true" if graded else "", bottom=bottom, top=top,
                              rollers=ROLLERS if solid_box else ""))


def plane(case: str, size: float, graded: bool) -> dict:
    """The plane reference: energy, the opening along Σ's crack, closed vertices, unknowns, seconds."""
    scene = scene_of(case, size, 2, graded)
    started = time.perf_counter()
    result = plane_reference.solve_monolithic(scene, geometry.build(scene))
    seconds = time.perf_counter() - started
    x = result.interface_x
    return {"size": size, "energy": result.energy, "unknowns": result.unknowns, "seconds": seconds,
            "x": x, "opening": result.on_sigma.opening, "closed": int(result.attrs["closed_vertices"])}


def extruded(case: str, size: float, graded: bool = False, degree: int = 1, layers: int | None = None) -> dict:
    """The 3-D reference per unit depth: energy, the opening at mid-depth, closed vertices, unknowns, seconds; with
    ``layers``, on the section's plane mesh extruded in that many layers."""
    scene = scene_of(case, size, 3).with_({"mesh.grading": graded, "mesh.degree": degree,
                                           **({} if layers is None else {"mesh.extrude": layers})})
    started = time.perf_counter()
    mesh = solid.build(scene)
    result = solid_reference.solve_solid(scene, mesh)
    seconds = time.perf_counter() - started
    assert result.converged, result.message
    largest = max(float(np.abs(u).max()) for u in result.fields)
    return {"size": size, "energy": result.energy / DEPTH, "unknowns": mesh.unknowns, "seconds": seconds,
            "result": result, "closed": result.closed, "graded": graded, "degree": degree, "layers": layers,
            "u_z": max(float(np.abs(u[:, 2]).max()) for u in result.fields) / largest}


def opening_at(result, x: np.ndarray, z: float) -> np.ndarray:
    """The normal opening of a 3-D result at the points (x, z) of Σ, interpolated on Σ's triangles."""
    surface = result.mesh.sigma
    corners = surface.points[surface.triangles][:, :, [0, 2]]  # (t, 3, 2)
    values = result.normal_opening[surface.triangles]
    out = np.full(len(x), np.nan)
    for k, point in enumerate(np.column_stack([x, np.full(len(x), z)])):
        a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
        matrix = np.stack([b - a, c - a], axis=-1)
        weights = np.linalg.solve(matrix, (point - a)[..., None])[..., 0]
        inside = np.all(weights >= -1e-12, axis=1) & (weights.sum(axis=1) <= 1 + 1e-12)
        t = np.flatnonzero(inside)[0]
        s, r = weights[t]
        out[k] = (1 - s - r) * values[t, 0] + s * values[t, 1] + r * values[t, 2]
    return out


def extrapolated(rows: list[dict]) -> tuple[float, float]:
    """The limit Π and rate a of Π_h = Π + C N^-a through the last three (unknowns N, energy) rows."""
    (n1, e1), (n2, e2), (n3, e3) = [(row["unknowns"], row["energy"]) for row in rows[-3:]]
    ratio = (e1 - e2) / (e2 - e3)

    def mismatch(a: float) -> float:
        return (n1 ** -a - n2 ** -a) / (n2 ** -a - n3 ** -a) - ratio
    low, high = 1e-3, 3.0
    for _ in range(200):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if mismatch(low) * mismatch(middle) > 0 else (low, middle)
    a = 0.5 * (low + high)
    return e3 - (e2 - e3) * n3 ** -a / (n2 ** -a - n3 ** -a), a


def energy_norm_error(energy: float, exact: float) -> float:
    """The relative energy-norm error of a conforming solution from its energy: √((Π_h − Π)/|Π|)."""
    return math.sqrt(max(energy - exact, 0.0) / abs(exact))


def measure(case: str) -> dict:
    graded = [plane(case, size, True) for size in PLANE_SIZES]
    exact = graded[-1]
    uniform = {size: plane(case, size, False) for size in SOLID_SIZES}
    solids = [extruded(case, size) for size in SOLID_SIZES]
    more = [extruded(case, size, graded, degree) for degree, graded, sizes in MORE_RUNS for size in sizes]
    layered = [extruded(case, size, True, degree, layers) | {"plane": same_section(case, size, degree)}
               for degree, size, layers in EXTRUDED_RUNS]
    crack = np.abs(exact["x"]) < 0.5
    x, reference = exact["x"][crack], exact["opening"][crack]
    flat = uniform[solids[-1]["size"]]
    scale = np.abs(reference).max()
    return {"graded": graded, "uniform": uniform, "solids": solids, "more": more, "exact": exact["energy"],
            "extruded": layered,
            "plane P1 opening": float(np.abs(np.interp(x, flat["x"], flat["opening"]) - reference).max() / scale),
            "openings": {label: opening_comparison(run, x, reference) for label, run in
                         ((f"P1 {solids[-1]['size']:g}", solids[-1]), (f"P2 {more[-1]['size']:g} graded", more[-1]),
                          (label_of(layered[-1]), layered[-1]))}}


def same_section(case: str, size: float, degree: int) -> float:
    """The plane reference's energy on the section mesh an extruded run extrudes (graded, of its degree)."""
    scene = scene_of(case, size, 2).with_({"mesh.degree": degree, "mesh.grading": True})
    return plane_reference.solve_monolithic(scene, geometry.build(scene)).energy


def label_of(run: dict) -> str:
    """A 3-D run's name in the tables: degree, size, graded, extruded layers."""
    layers = run["layers"]
    extrusion = "" if layers is None else f", extruded in {layers} layer{'s' if layers > 1 else ''}"
    return f"P{run['degree']} {run['size']:g}{' graded' if run['graded'] else ''}{extrusion}"


def opening_comparison(run: dict, x: np.ndarray, reference: np.ndarray) -> dict:
    """A 3-D run's normal opening at the plane's crack vertices x against the plane's: at mid-depth and on the front
    face (largest differences relative to the plane's largest opening), and where each is largest."""
    at_mid, at_front = (opening_at(run["result"], x, z) for z in (0.5 * DEPTH, 0.0))
    scale = np.abs(reference).max()
    return {"mid max": float(at_mid.max()), "x at mid max": float(x[np.argmax(at_mid)]),
            "plane max": float(reference.max()), "x at plane max": float(x[np.argmax(reference)]),
            "mid": float(np.abs(at_mid - reference).max() / scale),
            "front": float(np.abs(at_front - reference).max() / scale)}


def page(measured: dict) -> str:
    lines = ["# Three dimensions: the extrusion check", "", __doc__.split("\n\n", 1)[1].strip(), "",
             "The same scene solved to a target error (``mesh.target_error``, meshes adapted by the estimate): "
             "[three-d-adapt.md](three-d-adapt.md) (``./run three-d-adapt``).", "", SPEED, ""]
    for case, record in measured.items():
        exact = record["exact"]
        lines += [f"## {case}", "", "The plane reference at graded P2 (its continuous value: the finest):", "",
                  "| mesh.size | unknowns | energy per unit depth | change from the previous | seconds |",
                  "|---|---|---|---|---|"]
        previous = None
        for row in record["graded"]:
            change = "" if previous is None else f"{(row['energy'] - previous) / abs(exact):.2e}"
            lines.append(f"| {row['size']:g} | {row['unknowns']} | {row['energy']:.8e} | {change} | "
                         f"{row['seconds']:.2f} |")
            previous = row["energy"]
        lines += ["", "The 3-D reference (P1 tetrahedra, uniform) against it, beside the plane P1 (uniform) of the "
                  "same size; errors relative to the plane continuous energy, energy norm √((Π_h − Π)/|Π|):", "",
                  "| 3-D mesh | 3-D unknowns | 3-D energy per depth | 3-D error | plane P1 error | 3-D closed "
                  "vertices | largest u_z / largest u | 3-D seconds |", "|---|---|---|---|---|---|---|---|"]
        for row in record["solids"] + record["more"]:
            same = row["degree"] == 1 and not row["graded"]
            flat = f"{100 * energy_norm_error(record['uniform'][row['size']]['energy'], exact):.1f} %" if same else ""
            lines.append(f"| {label_of(row)} | {row['unknowns']} | "
                         f"{row['energy']:.6e} | {100 * energy_norm_error(row['energy'], exact):.1f} % | {flat} | "
                         f"{row['closed']} | {row['u_z']:.1e} | {row['seconds']:.2f} |")
        rates = [math.log(energy_norm_error(a["energy"], exact) / energy_norm_error(b["energy"], exact))
                 / math.log(b["unknowns"] / a["unknowns"]) for a, b in zip(record["solids"][:-1], record["solids"][1:])]
        limit, rate = extrapolated(record["solids"])
        lines += ["", f"The 3-D error falls as N^-{np.mean(rates[-2:]):.2f} over the last sizes (uniform P1 at a crack "
                  "front: N^-1/6 in 3-D, against the singularity's r^½), and stays within a few points of the plane "
                  "P1's at the same size: the 3-D solve converges as the plane one does, to the same limit.  "
                  "Π_h = Π + C N^-a through the last three 3-D energies alone gives a = "
                  f"{rate:.3f} and Π = {limit:.6e} per unit depth, {100 * (limit - exact) / abs(exact):+.2f} % from the "
                  "plane continuous energy: so far from the asymptotic range (a = 1/3 there) such a fit is a rough "
                  "guess, not a check.  Graded P2 converges fastest where the crack front is the only singular "
                  "line; the plane graded P2 is within 0.05 % of its finest energy at 9 260 unknowns, while 3-D "
                  "isotropic tetrahedra about a singular edge need far more unknowns for a few per cent.", "",
                  *extruded_lines(record), "",
                  "The opening along x against the plane continuous one (the plane P1 of the finest 3-D P1 size "
                  f"differs from it by {100 * record['plane P1 opening']:.1f} % of the largest opening):", "",
                  "| 3-D mesh | largest opening at mid-depth (at x) | plane (at x) | largest difference at mid-depth | "
                  "on the front face z = 0 |", "|---|---|---|---|---|"]
        for label, opening in record["openings"].items():
            lines.append(f"| {label} | {opening['mid max']:.4e} ({opening['x at mid max']:.3g}) | "
                         f"{opening['plane max']:.4e} ({opening['x at plane max']:.3g}) | {100 * opening['mid']:.1f} % | "
                         f"{100 * opening['front']:.1f} % |")
        lines.append("")
    return "\n".join(lines)


def extruded_lines(record: dict) -> list[str]:
    """The table of the extruded runs against the plane continuous energy and the plane on the same section mesh."""
    exact = record["exact"]
    lines = ["The section's plane mesh (graded towards the tips) extruded along z (``mesh.extrude``): its P1 (P2) "
             "space holds the plane P1 (P2) solution of that section mesh extended in z, so its energy per depth "
             "lies at or below the plane's on the same mesh (the 3-D space is larger), above the continuous one:",
             "", "| 3-D mesh | 3-D unknowns | 3-D energy per depth | 3-D error | plane error, same section mesh | "
             "3-D − plane, same section mesh | 3-D closed vertices | largest u_z / largest u | 3-D seconds |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in record["extruded"]:
        lines.append(f"| {label_of(row)} | {row['unknowns']} | {row['energy']:.8e} | "
                     f"{100 * energy_norm_error(row['energy'], exact):.2f} % | "
                     f"{100 * energy_norm_error(row['plane'], exact):.2f} % | "
                     f"{(row['energy'] - row['plane']) / abs(exact):+.2e} | {row['closed']} | {row['u_z']:.1e} | "
                     f"{row['seconds']:.2f} |")
    within = next((row for row in record["extruded"] if energy_norm_error(row["energy"], exact) < ACCEPTED), None)
    best = min(record["solids"] + record["more"], key=lambda row: energy_norm_error(row["energy"], exact))
    reached = ("no extruded mesh here" if within is None else f"from {label_of(within)} on ({within['unknowns']} "
               f"unknowns, {100 * energy_norm_error(within['energy'], exact):.2f} %)")
    gmsh = 100 * energy_norm_error(best["energy"], exact)
    return lines + ["", f"Within {100 * ACCEPTED:g} % energy norm of the plane continuous energy (the extrusion "
                    f"acceptance): {reached}; gmsh's tetrahedra reach {gmsh:.1f} % at best ({label_of(best)}, "
                    f"{best['unknowns']} unknowns)."]


def three_d() -> None:
    """Measure both cases and write docs/three-d.md."""
    measured = {case: measure(case) for case in CASES}
    path = DOCS / "three-d.md"
    kept = path.read_text() if path.exists() else ""
    path.write_text(page(measured))
    begin, end = "<!-- three-d-interfaces:start -->", "<!-- three-d-interfaces:end -->"
    if begin in kept and end in kept:  # ./run three-d-interfaces's section stays
        report.section(path, "three-d-interfaces", kept[kept.index(begin) + len(begin):kept.index(end)])
    print(f"wrote {DOCS / 'three-d.md'}")
