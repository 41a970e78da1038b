"""The gallery: structures beyond the paper's square, each solved, drawn and described in docs/gallery.md.

``ddsolve gallery`` solves every gallery scene on 4 ranks (results in results/gallery/), draws the
deformed layers and the crack faces (docs/gallery-*.png) and rewrites docs/gallery.md from the results.
"""
from __future__ import annotations

from pathlib import Path

from experiments import report

RESULTS = Path("results/gallery")
DOCS = Path("docs")
#: scene -> what it shows (the numbers come from the run).
SCENES = {
    "strip-disbonds": "A strip eight times longer than high, clamped at its left end and free elsewhere, the "
                      "layers glued along the mid-line except on three disbonds. A pressure on top of layer 1 "
                      "varies along the strip: it pulls near the clamp and pushes towards the free end. The "
                      "disbond nearest the clamp opens, the middle one opens at its left end only, the last one "
                      "stays closed and carries contact pressure.",
    "arc-bond": "The bond line is a circular arc (arc-bond.geo) rising 0.2 over the width of the square; the "
                "crack is its middle part. Layer 1 is pulled at top and bottom (a negative pressure), so the "
                "crack opens along the whole arc; non-penetration and gluing act along the arc's normals.",
    "kinked-bond": "The bond line is a polyline with a kink at (0, 0.3) (kinked-bond.geo); the crack runs from "
                   "x = −0.4 to 0.4 through the kink. Under Example 1's loads the crack opens left of the "
                   "kink and closes right of it.",
    "orthotropic-plate": "The paper's square and Example 1's loads, but layer 1 is a fibre-reinforced orthotropic "
                         "material (E1 = 140, E2 = 10, G12 = 5, ν12 = 0.3) with fibres at 30° to x, and both "
                         "layers are in plane stress. Soft across its fibres, layer 1 deforms much more than in "
                         "Example 1, lopsidedly, with its stress in bands along the fibre direction; the crack "
                         "still closes on its right part.",
}


def gallery() -> None:
    """Solve, draw and describe every gallery scene."""
    from ddsolve.io import hdf5
    from ddsolve.post import analysis, plots

    RESULTS.mkdir(parents=True, exist_ok=True)
    sections = []
    for name, description in SCENES.items():
        path = RESULTS / f"{name}.h5"
        print(f"gallery: {name} -> {path}", flush=True)
        report.run(4, ["solve", name, "-o", str(path)])
        result = hdf5.read(path)
        scale = plots.deformed_layers(result, DOCS / f"gallery-{name}.png")
        plots.crack_faces(result, DOCS / f"gallery-{name}-crack.png")
        sections.append(section(name, description, result, scale, analysis.constraints(result)))
    (DOCS / "gallery.md").write_text(page(sections))


def section(name: str, description: str, result, scale: float, constraints) -> str:
    from ddsolve.post.analysis import along_sigma, contact_zones, normal_jump, overlap_zones

    position, axis = along_sigma(result)
    crack = result.crack
    touching = result.scene.nonpenetration
    zones = ", ".join(f"[{position[a]:.2f}, {position[b]:.2f}]"
                      for a, b in (contact_zones if touching else overlap_zones)(result)) or "none"
    faces = f"faces in contact on {zones}" if touching else f"no non-penetration: faces overlap on {zones}"
    unknowns = 4 * (len(result.lower.points) + len(result.upper.points))
    opening = normal_jump(result)[crack].max(initial=0.0)
    return "\n".join([
        f"## {name}",
        "",
        f"![{name}: deformed layers](gallery-{name}.png)",
        f"![{name}: crack faces](gallery-{name}-crack.png)",
        "",
        description,
        "",
        f"`./run solve -n 4 {name}`: {unknowns:,} unknowns (P{result.mesh.degree}), {result.solves} rounds of block "
        f"solves, {result.wall_time:.2f} s solve phase; total potential energy {result.attrs['energy']:.4e}; "
        f"largest crack opening {opening:.3e}; {faces} ({axis}); max penetration "
        f"{constraints.penetration:.1e} and max gluing gap {constraints.gluing_gap:.1e} relative to max |u| = "
        f"{constraints.max_displacement:.3e}. Displacements drawn ×{scale:g}.",
    ])


def page(sections: list[str]) -> str:
    return "\n\n".join([
        "# Gallery",
        "Structures beyond the paper's square, each a built-in scene (`./run scenes`). `./run gallery` solves them "
        "on 4 ranks with the default method, redraws the pictures and rewrites this page from the results "
        "(results/gallery/). Left or top: layer 1, right or bottom: layer 2, coloured by von Mises stress; the "
        "second picture shows the normal opening [u]·ν of layer 1 and the contact pressure μᶜ along Σ. The scene "
        "files are in ddsolve/problem/scenes/; [geometry.md](geometry.md) describes the geometry formats.",
        *sections,
    ]) + "\n"
