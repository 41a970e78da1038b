"""Issue 21, classes 2 (coarse, thin, slender or far-away geometry), 8 (ν and mesh.grading at their edges)
and 4 (a gmsh size factor near zero in a .geo): the rows of docs/robustness.md, measured by
``measure(hostile)`` (see :class:`experiments.robustness.Hostile`)."""
from __future__ import annotations

from ddsolve.problem import scene as scenes

SMALL = ["--set", "mesh.sigma_vertices=13", "--set", "mesh.boundary_vertices=32"]


def _box(x0: float, x1: float, y0: float, y1: float, crack: tuple[float, float]) -> list[str]:
    return ["--set", f"geometry.box=[{x0!r}, {x1!r}, {y0!r}, {y1!r}]", "--set", f"geometry.crack=[{crack[0]!r}, {crack[1]!r}]"]


def measure(hostile) -> None:
    """Add the rows of classes 102, 108 and 104."""
    solve = ["solve", "-n", "4", "partial-closure"]
    traceback = "exit 1, 136-line traceback (numpy _UFuncOutputCastingError in the error estimate)"
    for size in ("2", "3", "100"):
        hostile.case(102, f"mesh.size = {size} (the box is 2 × 2)", traceback,
                     [*solve, "--set", f"mesh.size={size}", "-o", "g2.h5"])
    hostile.case(102, "reference, mesh.size = 2", "exit 1, 34-line traceback (_UFuncOutputCastingError)",
                 ["reference", "partial-closure", "--set", "mesh.size=2", "-o", "g2.h5"])
    hostile.case(102, "solve -n 1, mesh.size = 3", "exit 1, 34-line traceback (_UFuncOutputCastingError)",
                 ["solve", "-n", "1", "partial-closure", "--set", "mesh.size=3", "-o", "g2.h5"])
    hostile.case(102, "mesh.size = 100, clamped on the left only", "exit 1, traceback (numpy "
                 "_UFuncOutputCastingError in the error estimate)",
                 [*solve, "--set", "mesh.size=100", "--set", "geometry.clamped=['left']", "-o", "g2.h5"])
    hostile.case(102, "P2, mesh.size = 2", traceback,
                 [*solve, "--set", "mesh.size=2", "--set", "mesh.degree=2", "-o", "g2.h5"])
    hostile.case(102, "box 2 × 2e-4 (P = 13, M = 32)", traceback,
                 [*solve, *SMALL, "--set", "geometry.box=[-1.0, 1.0, -1e-4, 1e-4]", "-o", "g2.h5"])
    hostile.case(102, "box 1000 × 1 (P = 13, M = 32)", "exit 1, 4 tracebacks (_UFuncOutputCastingError), "
                 "135 lines", [*solve, *SMALL, *_box(0.0, 1000.0, -0.5, 0.5, (400.0, 600.0)), "-o", "g2.h5"])
    hostile.case(102, "box at x = 1e9", "exit 1, 78 lines: gmsh aborts («terminate called after throwing an "
                 "instance of std::string»), then EOFError tracebacks",
                 [*solve, *SMALL, *_box(1e9, 1e9 + 2.0, -1.0, 1.0, (1e9 + 0.5, 1e9 + 1.5)), "-o", "g2.h5"])
    hostile.case(102, "box at x = 1e12", "exit 1, 156 lines: gmsh aborts, then EOFError tracebacks",
                 [*solve, *SMALL, *_box(1e12, 1e12 + 2.0, -1.0, 1.0, (1e12 + 0.5, 1e12 + 1.5)), "-o", "g2k.h5"],
                 kept=("g2k",))
    hostile.case(108, "mesh.grading = 1e-9", "exit 1: «generated mesh: lower half: 1 inverted or degenerate "
                 "triangles (non-positive area)»",
                 [*solve, "--set", "mesh.size=0.05", "--set", "mesh.grading=1e-9", "-o", "g8.h5"])
    hostile.case(108, "ν = 0.4999999999999999", "exit 1: «PETSc MatFactorFactorizeSchurComplement failed with "
                 "error 81»", [*solve, *SMALL, "--set", "materials.layer1.nu=0.4999999999999999", "-o", "g8.h5"],
                 kept=("g8",))
    hostile.case(108, "reference, ν = 0.4999999999999999", "exit 3: «reference: the solution violates multiplier "
                 "bounds 3.44e-02, complementarity 2.00e-02 ...: the problem is too ill-conditioned for double "
                 "precision»", ["reference", "partial-closure", *SMALL, "--set",
                                "materials.layer1.nu=0.4999999999999999", "-o", "g8.h5"], kept=("g8",))
    hostile.case(108, "ν = 0.4999 (must still solve)", "exit 0",
                 [*solve, *SMALL, "--set", "materials.layer1.nu=0.4999", "-o", "g8ok.h5"])
    folder = scenes.builtin_folder()
    geo, toml = (folder / "arc-bond.geo").read_text(), (folder / "arc-bond.toml").read_text()
    for name, label, text, before in (
            ("factor", "Mesh.MeshSizeFactor = 1e-9 in a .geo (arc-bond)", "Mesh.MeshSizeFactor = 1e-9;\n" + geo,
             "no output; ended by timeout after 60 s"),
            ("tinylc", "lc = 1e-9 in a .geo (arc-bond)", geo.replace("lc = 1.0;", "lc = 1e-9;", 1),
             "no output; ended by timeout after 60 s"),
            ("smalllc", "lc = 1e-4 in a .geo (arc-bond: 6e8 vertices)", geo.replace("lc = 1.0;", "lc = 1e-4;", 1),
             "no output; ended by timeout after 60 s")):
        (hostile.folder / f"{name}.geo").write_text(text)
        (hostile.folder / f"{name}.toml").write_text(toml.replace("arc-bond.geo", f"{name}.geo"))
        hostile.case(104, label, before, ["mesh", f"{name}.toml"])
