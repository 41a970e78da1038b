"""Round 5, the new input surfaces (one-layer structures, friction on the crack faces, several interfaces, the
interface crack's reference length and region materials), measured for docs/robustness.md: friction values
beyond double precision (class 301), friction and the phase's length where they do nothing (302), a mesh's
per-crack refusal printed by every rank (303), messages that misname what a list holds (304).  *Before* is what
the code before the fixes did (measured once on the shared two-core machine, quoted)."""
from __future__ import annotations

from experiments import ROOT
from experiments.robustness import SMALL

CLASSES = {
    301: ("Friction values beyond double precision",
          "`contact.friction` and `contact.slip_bound` are numbers >= 0 up to 1e100 (long before, the faces stick "
          "wherever they touch), each in a per-crack list too; -0.0 is 0"),
    302: ("Keys that do nothing: friction without cracks, the phase's length without an interface crack",
          "friction on a box scene without cracks is refused by the scene's cross checks, on a mesh without cracks "
          "by rank 0's checks of the whole mesh; `fracture.reference_length` is refused where no layer has a "
          "region of its own material, or where the regions' materials have no isotropic pair (G is then not "
          "split and has no phase)"),
    303: ("A refusal printed by every rank, and cut short by their aborts",
          "a per-crack friction list is checked against a mesh file's cracks on rank 0 with the toughness's, "
          "before the mesh is distributed, so that the ranks end together on one line; a rank reporting an error "
          "ignores SIGINT and SIGTERM (its status is decided), so that another rank's abort cannot cut the report "
          "into a traceback"),
    304: ("Messages that misname what a list or a file holds",
          "`geometry.sigma = [y1, ...]` and the nested `geometry.cracks` say what each item must be (a height; an "
          "[a, b] interval of finite numbers); the file of a growth or a sweep given where one result is read "
          "(check, compare, export, plot, ddsolve.load) is named as such"),
}

#: A mesh file without a crack and a scene on it with friction (written by ``mesh`` in ``measure``).
NO_CRACK = """[mesh]
file = "nocrack.msh"
[materials.layer1]
E = 1.0
nu = 0.3
[materials.layer2]
E = 1.0
nu = 0.3
[contact]
friction = {friction}
[loads.layer1.top]
y = -0.01
"""
ORTHOTROPIC_UPPER = "materials.layer1.upper={E1=300.0, E2=100.0, G12=50.0, nu12=0.25}"


def measure(hostile) -> None:
    """Rows of classes 301 to 304."""
    folder = hostile.folder
    (folder / "closed-crack.toml").write_text((ROOT / "docs" / "closed-crack.toml").read_text())
    hostile.run(["mesh", "partial-closure", "--set", "geometry.cracks=[]", "-o", "nocrack.msh"])
    (folder / "nocrack.toml").write_text(NO_CRACK.format(friction="0.5"))
    (folder / "nocrack-list.toml").write_text(NO_CRACK.format(friction="[0.5]"))
    closed = ["solve", "closed-crack.toml", "-o", "f.h5"]

    def case(number: int, label: str, before: str, arguments: list[str]) -> None:
        hostile.case(number, label, before, arguments, kept=("f",))

    case(301, "solve, the closed crack with μ = 1e308", "exit 1, 1.1 s, 5 lines: numpy's «RuntimeWarning: overflow "
         "encountered in multiply» (dd/interface.py) and «invalid value encountered in subtract» (dd/friction.py), "
         "then «ddsolve: error: schur: Coulomb's friction found no fixed point in 50 Tresca problems (relative "
         "change of the slip bound nan)»", [*closed, "--set", "contact.friction=1e308"])
    case(301, "solve -n 2, the closed crack with g = 1e308 and feti", "exit 0, 1.2 s, 2 lines: «dd/feti.py:132: "
         "RuntimeWarning: overflow encountered in divide», «converged»",
         [*closed[:1], "-n", "2", *closed[1:], "--set", "contact.slip_bound=1e308", "--set", 'solver.method="feti"'])
    case(302, "solve, Example 1 without cracks (geometry.cracks = []) and μ = 0.5", "exit 0, 1.8 s, nothing said; "
         "«crack faces slip: nowhere», «crack faces stick: nowhere»",
         ["solve", "partial-closure", "--set", "geometry.cracks=[]", "--set", "contact.friction=0.5", "-o", "f.h5"])
    case(302, "solve -n 2, a mesh file without cracks and μ = 0.5", "exit 0, 1.4 s, nothing said",
         ["solve", "-n", "2", "nocrack.toml", "-o", "f.h5"])
    case(302, "solve, Example 1 (no region materials) with fracture.reference_length = 1e-300", "exit 0, 1.1 s, "
         "nothing said: ψ and G_I the same at l = 1e-300 and 1e300",
         ["solve", "partial-closure", "--set", "fracture.reference_length=1e-300", "-o", "f.h5"])
    case(302, "solve, an orthotropic upper region of layer 1 with fracture.reference_length = 0.5", "exit 0, 1.0 s: "
         "«(nothing on standard error)», «G is not split into modes I and II ...»",
         ["solve", "partial-closure", "--set", ORTHOTROPIC_UPPER, "--set", "fracture.reference_length=0.5",
          "-o", "f.h5"])
    case(303, "solve -n 4, a per-crack friction list [0.5] on a mesh file without cracks", "exit 1, 3.1 s: «ddsolve: "
         "error: contact.friction lists 1 values for the 0 cracks of the mesh ...» once per rank (4 lines); in 1 of 5 "
         "runs 62 lines, two ranks' reports cut short by the others' abort (SIGTERM) with 2 tracebacks",
         ["solve", "-n", "4", "nocrack-list.toml", "-o", "f.h5"])
    case(304, "geometry.sigma = [\"a\", 0.1]", "exit 1: «... geometry.sigma must be a number (got ['a', 0.1])»",
         ["solve", "partial-closure", "--set", 'geometry.sigma=["a", 0.1]', "-o", "f.h5"])
    case(304, "geometry.cracks = [[[nan, 0.2]], []] with two interfaces", "exit 1: «... geometry.cracks must be one "
         "list of intervals per interface, each a finite number (got [[[nan, 0.2]], []])»",
         ["solve", "partial-closure", "--set", "geometry.sigma=[-0.1, 0.1]", "--set", "geometry.cracks=[[[nan, 0.2]], []]",
          "-o", "f.h5"])
    hostile.run(["sweep", "partial-closure", *SMALL, "--set", "materials.layer1.E=100:200:2", "-o", "s.h5"])
    hostile.run(["grow", "partial-closure", *SMALL, "--set", "fracture.toughness=4.61e-7", "--steps", "2", "-o", "g.h5"])
    case(304, "check, the file of a sweep", "exit 1, 0.2 s: «ddsolve: error: s.h5: not a ddsolve result file ('Unable "
         "to open object (component not found)')»", ["check", "s.h5"])
    case(304, "export, the file of a growth", "exit 1, 0.2 s: «ddsolve: error: g.h5: not a ddsolve result file "
         "('Unable to open object (component not found)')»", ["export", "g.h5"])
