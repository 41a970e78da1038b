"""A laminate with two delaminations at two interfaces: ``./run laminate`` (and ``./run stacks``) writes the
laminate section of docs/stacks.md, docs/stacks-laminate.png and results/stacks-laminate.h5 (the finest mesh's
result file, which ``ddsolve check``, ``compare``, ``plot`` and ``export`` read).

Four plies of one body (``geometry.layers = 1``), the outer ones stiff and the inner ones soft, clamped at one end
and sheared at the other; a delamination on the lowest and on the highest interface, none on the middle one.  The
monolithic reference solves it on three meshes (each half the last's size): G at every tip on each, its change on
the last refinement as its mesh-convergence error, the contact zones and the wall time.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from experiments import report
from experiments.stacks import _pyplot, table

RESULTS, DOCS = Path("results"), Path("docs")
#: The plies, bottom to top: Young's moduli (ν = 0.3 for all), each ply 1 thick and 20 long.
PLIES = (140.0, 10.0, 10.0, 140.0)
LENGTH, THICKNESS = 20.0, 1.0
#: The delaminations: one crack list per interface, bottom to top.
CRACKS = [[[6.0, 10.0]], [], [[12.0, 16.0]]]
#: The shear traction on the free end (every ply), downwards.
SHEAR = -0.05
SIZES = (0.25, 0.125, 0.0625)


def text_of(size: float) -> str:
    """The laminate's scene, P2 on ``mesh.size`` ``size``."""
    tops = [THICKNESS * (k + 1) for k in range(len(PLIES))]
    regions = "".join(f"[materials.layer1.region{k + 1}]\nE = {E:g}\n" for k, E in enumerate(PLIES) if E != PLIES[0])
    return f"""title = "a laminate of {len(PLIES)} plies with two delaminations"
[geometry]
box = [0.0, {LENGTH:g}, 0.0, {tops[-1]:g}]
sigma = {tops[:-1]}
cracks = {CRACKS}
clamped = ["left"]
layers = 1
[mesh]
size = {size:g}
degree = 2
[materials.layer1]
E = {PLIES[0]:g}
nu = 0.3
{regions}[loads.layer1.right]
y = {SHEAR:g}
"""


def solved(size: float):
    """The laminate on ``size`` solved by the monolithic reference, and its wall time (mesh, solve and G)."""
    from ddsolve.mesh import stack
    from ddsolve.problem import scene
    from ddsolve.solvers import stacked

    started = time.perf_counter()
    source = scene.loads(text_of(size), origin="laminate")
    result = stacked.solve_stack(source, stack.build_any(source))
    return result, time.perf_counter() - started


def row_of(size: float, result, seconds: float) -> dict:
    """What the page shows of one mesh."""
    fracture = result.fracture
    return {"size": size, "unknowns": 2 * sum(len(region.points) for region in result.mesh.regions),
            "G": np.asarray(fracture.G, dtype=float), "points": np.asarray(fracture.points),
            "interface": np.asarray(fracture.interface), "phase": np.asarray(fracture.phase, dtype=float),
            "zones": len(fracture.zones), "iterations": result.iterations, "converged": result.converged,
            "seconds": seconds}


def laminate() -> None:
    """Solve the laminate on every mesh, keep the finest result's file, draw, write the page's section."""
    from ddsolve.io import hdf5

    rows, finest = [], None
    for size in SIZES:
        finest, seconds = solved(size)
        rows.append(row_of(size, finest, seconds))
    RESULTS.mkdir(exist_ok=True)
    hdf5.write_stack(RESULTS / "stacks-laminate.h5", finest)
    picture(finest, DOCS / "stacks-laminate.png")
    report.section(DOCS / "stacks.md", "stacks-laminate", text(rows))


def picture(result, path: Path) -> None:
    """The deformed plies coloured by von Mises stress, and along each cracked interface the jump (opening and
    slip) with G at its tips."""
    from ddsolve.post import plots, stack

    plt = _pyplot()
    blocks = stack.drawn(result)
    scale = plots.block_magnification(blocks, 0.05)
    cracked = [(number, view) for number, view in enumerate(result.interfaces, start=1) if len(view.fracture.G)]
    fig = plt.figure(figsize=(11, 3.2 + 2.4 * len(cracked)), constrained_layout=True)
    grid = fig.add_gridspec(1 + len(cracked), 1, height_ratios=[1.4] + [1.0] * len(cracked))
    top = fig.add_subplot(grid[0])
    ceiling = plots.stress_ceiling(np.concatenate([block.stress for block in blocks]))
    for block in blocks:
        moved = block.points + scale * block.u
        triangles, parent = plots.linear_triangles(block.cells)
        image = top.tripcolor(moved[:, 0], moved[:, 1], triangles, facecolors=block.stress[parent], cmap="viridis",
                              vmin=0.0, vmax=ceiling, edgecolors="none")
    fig.colorbar(image, ax=top, label="von Mises stress")
    top.set_aspect("equal")
    top.set_title(f"{result.scene.title}: displacements ×{scale:g} (plies E = "
                  f"{', '.join(f'{E:g}' for E in PLIES)} bottom to top; clamped left, sheared right)", fontsize=10)
    for k, (number, view) in enumerate(cracked, start=1):
        ax = fig.add_subplot(grid[k])
        on = view.on_sigma
        jump = on.traces["u_plus"] - on.traces["u_minus"]
        x = on.sigma.points[:, 0]
        ax.plot(x, np.einsum("sd,sd->s", jump, on.sigma.normals), label="opening [u]·ν")
        ax.plot(x, jump[:, 0], label="slip [u]·x")
        for first, last in on.sigma.pieces(on.sigma.crack):
            ax.axvspan(x[first], x[last], color="0.92")
        for (tip_x, _), G, psi in zip(view.fracture.points, view.fracture.G, view.fracture.phase):
            ax.axvline(tip_x, color="k", linewidth=0.6, linestyle=":")
            ax.annotate(f"G = {G:.4e}\nψ = {psi:.1f}°", (tip_x, 0.5), xycoords=("data", "axes fraction"),
                        fontsize=8, ha="center", bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8})
        ax.set_xlim(0.0, LENGTH)
        ax.set_ylabel("jump")
        ax.set_title(f"interface {number} (y = {on.sigma.points[0, 1]:g}); shaded: its crack", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower left")
    ax.set_xlabel("x")
    fig.savefig(path, dpi=110)
    plt.close(fig)


def text(rows: list[dict]) -> str:
    """The page's laminate section."""
    finest = rows[-1]
    change = np.abs(rows[-1]["G"] - rows[-2]["G"]) / np.abs(rows[-1]["G"])
    header = ["tip", "interface", *(f"G, mesh.size {row['size']:g}" for row in rows), "change on the last refinement",
              "ψ at l = 1"]
    body = [[f"({x:g}, {y:g})", str(interface), *(f"{row['G'][t]:.6e}" for row in rows), f"{change[t]:.2%}",
             f"{finest['phase'][t]:.1f}°"]
            for t, ((x, y), interface) in enumerate(zip(finest["points"], finest["interface"]))]
    speed = [[f"{row['size']:g}", f"{row['unknowns']:,}", str(row["iterations"]), str(row["zones"]),
              str(row["converged"]).lower(), f"{row['seconds']:.1f} s"] for row in rows]
    E = ", ".join(f"{value:g}" for value in PLIES)
    out = ["### A laminate with two delaminations at two interfaces", "",
           f"Generated by `./run laminate` (also part of `./run stacks`). {len(PLIES)} plies of one body "
           f"(`geometry.layers = 1`), each {THICKNESS:g} thick and {LENGTH:g} long, E = {E} bottom to top (ν = 0.3), "
           f"clamped on the left and sheared on the right (traction y = {SHEAR:g} on every ply's end); a "
           f"delamination over x ∈ {CRACKS[0][0]} on interface 1 and over x ∈ {CRACKS[2][0]} on interface 3, none "
           "on interface 2. The monolithic reference solves it (P2, plane strain; the DD methods converge to it) on "
           "three meshes, each refinement halving mesh.size. Bending shears the delaminations: their faces slide "
           "and partly touch (contact zones), so the tips are nearly in mode II (ψ near ±90°, measured at l = 1 "
           "as Rice's phase between the plies' different materials).", "",
           "![The laminate: deformed plies, the jumps along the cracked interfaces, G at every tip]"
           "(stacks-laminate.png)", "", "G at every tip, and its mesh-convergence error (its change on the last "
           "refinement):", ""]
    out += table(header, body)
    out += ["", f"Speed and the solve: unknowns, active-set steps, contact zones, the KKT check, wall time (the "
            "regions meshed by gmsh, the solve and G; one process):", ""]
    out += table(["mesh.size", "unknowns", "active-set steps", "contact zones", "converged", "wall time"],
                        speed)
    out += ["", "The finest result is `results/stacks-laminate.h5`: `ddsolve check` prints each interface's KKT "
            "residuals, `ddsolve compare` takes it against another mesh's file, `ddsolve export` writes a viewer "
            "file per ply and per interface."]
    return "\n".join(out)

