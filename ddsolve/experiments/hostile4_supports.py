"""Issue 40, first use (class 211): point supports and G at a closed tip, the rows about bad or edge input.
``measure(hostile)`` adds them to docs/robustness.md; *before* is what the previous code did, measured once on
the shared two-core machine and quoted.
"""
from __future__ import annotations

import shutil
from pathlib import Path

from ddsolve.experiments.robustness import SMALL

#: The ENF on point supports (docs/delamination.md): its scene and .geo.
ENF = Path(__file__).resolve().parents[2] / "docs" / "enf-points.toml"

CLASSES = {
    211: ("First use: point supports and G ≈ 0",
          "a support is a point where a pin is one: gmsh physical points and `point = [x, y]` in a box scene (the "
          "mesher puts a vertex there; a point off the layer's boundary, or with a normal, is refused naming the "
          "key), and G within its noise level (two θ contours) is reported as 0, its split non-negative and "
          "summing to G"),
}

#: A strip with an edge crack, clamped on the right: the point supports' examples add one point to it.
STRIP = """[geometry]
box = [0.0, 4.0, -0.5, 0.5]
cracks = [[0.0, 1.0]]
clamped = ["right"]
[mesh]
size = 0.25
[materials.layer1]
E = 200.0
nu = 0.28
[materials.layer2]
E = 112.0
nu = 0.32
[loads.layer1.top]
y = -1e-3
"""


def measure(hostile) -> None:
    """Rows of class 211: point supports off the layer, with a normal, from gmsh physical points; a closed tip."""
    (hostile.folder / "c211-strip.toml").write_text(STRIP)
    for path in (ENF, ENF.with_suffix(".geo")):
        shutil.copyfile(path, hostile.folder / path.name)
    strip = ["solve", "-n", "2", "c211-strip.toml"]
    unknown = "exit 1, 0.7 s: «ddsolve: error: strip.toml: unknown key displacements.layer1.pin.point; valid here: " \
              "normal, x, y»"
    hostile.case(211, "box scene, a point support outside the box (`point = [4.5, 0]`)", unknown,
                 [*strip, "--set", "displacements.layer1.pin={point = [4.5, 0.0], y = 0.0}", "-o", "c211.h5"],
                 kept=("c211",))
    hostile.case(211, "box scene, a point support inside a layer (`point = [2, 0.2]`)", unknown,
                 [*strip, "--set", "displacements.layer1.pin={point = [2.0, 0.2], y = 0.0}", "-o", "c211.h5"],
                 kept=("c211",))
    hostile.case(211, "box scene, a point support with a normal component", unknown,
                 [*strip, "--set", "displacements.layer1.pin={point = [2.0, -0.5], normal = 0.0}", "-o", "c211.h5"],
                 kept=("c211",))
    hostile.case(211, "box scene, a point support on the bottom side (`point = [2, -0.5]`, y = 0)", unknown,
                 [*strip, "--set", "displacements.layer1.pin={point = [2.0, -0.5], y = 0.0}", "-o", "c211.h5"])
    no_pin = "exit 1, 4.5 s: «ddsolve: error: displacements.layer1.pin: no boundary named 'pin' in enf-points.geo " \
             "(boundaries: bottom, load, top)»"
    hostile.case(211, "ENF on gmsh physical points `pin` and `roller` (docs/enf-points.toml, mesh.size = 0.5)", no_pin,
                 ["solve", "-n", "2", "enf-points.toml", "--set", "mesh.size=0.5", "-o", "c211-enf.h5"],
                 observe=_tips)
    hostile.case(211, "ENF, a normal displacement on the physical point `roller`", no_pin,
                 ["solve", "-n", "2", "enf-points.toml", "--set", "mesh.size=0.5", "--set",
                  "displacements.layer1.roller={normal = 0.0}", "-o", "c211-enf.h5"], kept=("c211-enf",))
    hostile.case(211, "Example 1's closed tip (P = 13): G ≈ 0", "exit 0, 3.7 s: «G at tip (0.5, 0) of crack 0: "
                 "-1.334738e-09 (G_I -1.461e-09, G_II 1.202e-10, ψ undefined: G ≈ 0)»; the open tip's G_I 2.758e-07 "
                 "above its G 2.634681e-07",
                 ["solve", "-n", "2", "partial-closure", *SMALL, "-o", "c211-closed.h5"], observe=_tips)


def _tips(completed) -> str:
    """The printed G lines of a run, without their radii."""
    return "; " + " | ".join(line.split("   (θ")[0] for line in completed.stdout.splitlines() if line.startswith("G at"))
