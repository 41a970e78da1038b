"""Issue 40's inputs, measured for docs/robustness.md: class 1 (prescribed displacements, expansion coefficients
and temperature changes beyond double precision), class 2 (temperature keys that do nothing, temperature changes
that cannot be integrated), class 3 (prescribed displacements that push the crack faces through each other) and
the first-use friction of ``mesh.target_error`` alone on a box.  *Before* is what the code before the fix did
(measured once on the P = 13 mesh, on the shared two-core machine, and quoted)."""
from __future__ import annotations

from experiments.robustness import SMALL

CLASSES = {
    201: ("Inputs that scale the answer have no range: prescribed displacements, α and ΔT",
          "the range check of moduli and loads takes each layer's displacement scale from the largest of its "
          "loads, prescribed displacements and eigenstrain αΔT (sampled densely) and bounds the energy "
          "stiffness × displacement², and a result whose energy, G or field is not finite is written with "
          "converged = false (Result.claim, the last step of the driver and the reference)"),
    202: ("Keys that do nothing, fields that cannot be integrated",
          "a temperature change on a layer without expansion (or given by D) is refused by the scene's cross "
          "checks, and a temperature change is sampled over the cells as loads are over their boundaries, closing "
          "in on its largest values and on the zeros of its divisors, so that a pole inside a layer is refused"),
    203: ("Prescribed displacements that push the crack faces through each other",
          "crack nodes where both faces' normal components are prescribed are checked before work (refused "
          "naming the displacement keys when they overlap), and the KKT check (check, every solve's claim) "
          "measures the penetration at every crack node, prescribed or not"),
    211: ("First use: mesh.target_error alone on a box",
          "a box scene with mesh.target_error and no mesh size starts from a coarse graded mesh of "
          "min(width / 20, thinner half / 2), recorded in the result's scene"),
}

#: A double cantilever (Σ at y = 0, an edge crack [0, 3], clamped at x = 10) whose arms' ends are pushed through
#: each other by ±0.01.
DCB_GEO = """lc = 0.5;
Point(1) = {0, -1, 0, lc}; Point(2) = {10, -1, 0, lc}; Point(3) = {10, 0, 0, lc}; Point(4) = {10, 1, 0, lc};
Point(5) = {0, 1, 0, lc}; Point(6) = {0, 0, 0, lc}; Point(7) = {3, 0, 0, lc};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 5}; Line(5) = {5, 6}; Line(6) = {6, 1};
Line(7) = {6, 7}; Line(8) = {7, 3};
Curve Loop(1) = {1, 2, -8, -7, 6}; Plane Surface(1) = {1};
Curve Loop(2) = {7, 8, 3, 4, 5}; Plane Surface(2) = {2};
Physical Surface("lower") = {1}; Physical Surface("upper") = {2};
Physical Curve("sigma") = {7, 8}; Physical Curve("crack") = {7}; Physical Curve("clamped") = {2, 3};
Physical Curve("left_lower") = {6}; Physical Curve("left_upper") = {5};
"""
LAYERS = "[materials.layer1]\nE = 100.0\nnu = 0.3\n[materials.layer2]\nE = 100.0\nnu = 0.3\n"
CLOSING = ('[mesh]\nfile = "dcb.geo"\nsize = 0.5\n' + LAYERS
           + "".join(f"[displacements.{layer}.left_{face}]\ny = {value}\n" for layer in ("layer1", "layer2")
                     for face, value in (("lower", 0.01), ("upper", -0.01))))
ADAPTIVE = ('[geometry]\nbox = [0.0, 4.0, -0.5, 0.5]\ncrack = [0.0, 1.5]\nclamped = ["right"]\n[mesh]\n'
            "target_error = 0.2\n" + LAYERS + "[loads.layer1.top]\ny = 0.001\n")
ANISOTROPIC = "materials.layer1={D=[[280.0, 100.0, 0.0], [100.0, 280.0, 0.0], [0.0, 0.0, 90.0]]}"


def measure(hostile) -> None:
    """Rows of classes 201, 202, 203 and 211."""
    for name, text in (("dcb.geo", DCB_GEO), ("closing.toml", CLOSING), ("adaptive.toml", ADAPTIVE)):
        (hostile.folder / name).write_text(text)
    paper = ["partial-closure", *SMALL]
    solve, output = ["solve", "-n", "2", *paper], ["-o", "i.h5"]
    displaced = ["--set", 'geometry.clamped=["left"]', "--set"]

    def case(number: int, label: str, before: str, arguments: list[str]) -> None:
        hostile.case(number, label, before, arguments + output, kept=("i",))

    case(201, "solve -n 2, ΔT = 1e300 (α = 1e-5)", "exit 0, 2.9 s, 56 lines of numpy warnings, «converged», G = nan "
         "at both tips", [*solve, "--set", "materials.layer1.alpha=1e-5", "--set", "temperature.layer1=1e300"])
    case(201, "reference, α = 1e300 (ΔT = 100)", "exit 1, 1.7 s: 39 lines, a traceback (OverflowError in the error "
         "estimate)", ["reference", *paper, "--set", "materials.layer1.alpha=1e300", "--set", "temperature.layer1=100.0"])
    case(201, "solve -n 2, a prescribed displacement of 1e160", "exit 0, 2.8 s, 48 lines of numpy warnings, "
         "«converged», G = nan at both tips", [*solve, *displaced, "displacements.layer2.right.y=1e160"])
    case(201, "reference, a prescribed displacement of 1e160", "exit 0, 1.7 s, 26 lines of numpy warnings, "
         "converged = true, G = nan", ["reference", *paper, *displaced, "displacements.layer2.right.y=1e160"])
    case(201, "reference, E = 1e250 with a prescribed displacement of 1e90 (energies of 1e430)", "exit 1, 2.2 s: "
         "«... loads.layer1.bottom up to 0.0781 ... gives displacements of order 1e-251 ...» (the prescribed values "
         "not counted)", ["reference", *paper, "--set", "materials.layer1.E=1e250", "--set", "materials.layer2.E=1e250",
                          *displaced, "displacements.layer2.right.y=1e90"])

    case(202, "solve -n 2, ΔT = 100 on a layer without α", "exit 0, 3.3 s, nothing said: the temperature ignored",
         [*solve, "--set", "temperature.layer1=100.0"])
    case(202, "solve -n 2, ΔT = 100 on a layer given by D", "exit 0, 3.9 s, nothing said: the temperature ignored",
         [*solve, "--set", ANISOTROPIC, "--set", "temperature.layer1=100.0"])
    case(202, "solve -n 2, ΔT = 1/(x − 0.0301) (a pole inside the layer)", "exit 0, 3.9 s, «converged», G < 0; "
         "unloaded, its reference energy is 0.56, 0.0040, 0.034 on P = 13, 25, 49 (no limit)",
         [*solve, "--set", "materials.layer1.alpha=1e-5", "--set", 'temperature.layer1="1/(x - 0.0301)"'])

    case(203, "solve, a double cantilever's arms pushed through each other (overlap 0.02)", "exit 0, 1.5 s, "
         "«converged», G = 3.4e-4; check on the file: «KKT check passed» (the overlap at the mouth unmeasured)",
         ["solve", "closing.toml"])
    case(203, "reference, the same scene", "exit 0, 1.6 s, converged = true; check passes",
         ["reference", "closing.toml"])

    hostile.case(211, "solve, a box scene with mesh.target_error = 0.2 and no mesh size", "exit 1, 1.4 s: «ddsolve: "
                 "error: adaptive.toml: missing key mesh.sigma_vertices (or give mesh.size or mesh.file)»",
                 ["solve", "adaptive.toml", "-o", "a.h5"], observe=lambda completed: _first_mesh(hostile.folder / "a.h5"))


def _first_mesh(path) -> str:
    """A note on an adaptive run that wrote ``path``: its first mesh size, unknowns and estimated error."""
    from ddsolve.io import hdf5

    if not path.exists():
        return ""
    result = hdf5.read(path)
    unknowns = 4 * (len(result.lower.points) + len(result.upper.points))
    return (f"; mesh.size = {result.scene.mesh.size:g} (P{result.scene.mesh.degree}, graded), "
            f"{unknowns:,} unknowns, estimated error {100 * result.error_estimate:.3g} %")
