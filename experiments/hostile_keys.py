"""Issue 21, classes 4 and 7 (keys): work that is never refused (sweep counts, adaptive targets out of
reach) and keys a command was given but did not read.  ``measure(hostile)`` adds their rows to
docs/robustness.md; *before* is what the previous code did, measured once on the P = 13 mesh (on the
shared two-core machine) and quoted.
"""
from __future__ import annotations

import subprocess

from experiments.robustness import SMALL


def _unknowns(output: str):
    """A note on a run that wrote ``output``: its unknowns, estimated error and levels."""
    def observe(completed: subprocess.CompletedProcess, hostile) -> str:
        from ddsolve.io import hdf5

        path = hostile.folder / output
        if completed.returncode != 0 or not path.exists():
            return ""
        result = hdf5.read(path)
        levels = result.attrs.get("levels")
        return (f"; {4 * (len(result.lower.points) + len(result.upper.points)):,} unknowns, estimated error "
                f"{100 * float(result.attrs['error_estimate']):.3g} %" + (f" after {levels} levels" if levels else ""))
    return observe


def _sweep_unknowns(output: str):
    def observe(completed: subprocess.CompletedProcess, hostile) -> str:
        from ddsolve.solvers import sweep

        path = hostile.folder / output
        if completed.returncode != 0 or not path.exists():
            return ""
        return f"; unknowns per run {', '.join(str(int(n)) for n in sweep.read(path)['unknowns'])}"
    return observe


def measure(hostile) -> None:
    """Rows of classes 104 (work that is never refused) and 107 (keys ignored)."""
    def case(number, label, before, arguments, observe=None, kept=()):
        hostile.case(number, label, before, arguments, kept=kept,
                     observe=None if observe is None else (lambda completed: observe(completed, hostile)))

    sweep = ["sweep", "-n", "2", "partial-closure", *SMALL]
    case(104, "sweep, COUNT 1,000,000 (`--set materials.layer2.E=1:100:1000000`)",
         "no output in 60 s (a million scenes checked before the first run); ended by timeout",
         [*sweep, "--set", "materials.layer2.E=1:100:1000000", "-o", "c104.h5"])
    case(104, "sweep, COUNT 1,000,000,000", "within a 6 GB address-space limit: exit 1 after 1.6 s, 60 lines: "
         "two tracebacks (numpy _ArrayMemoryError, 7.45 GiB for the values); without a limit memory runs out",
         [*sweep, "--set", "materials.layer2.E=1:100:1000000000", "-o", "c104.h5"])
    case(104, "sweep, 200 × 100 ranges (20,000 runs)", "no output in 40 s; ended by timeout",
         [*sweep, "--set", "materials.layer2.E=1:100:200", "--set", "loads.layer1.top.x=0:1:100", "-o", "c104.h5"])
    case(104, "sweep on a mesh of P = 1e9, M = 4e8", "within a 4 GB address-space limit: no output in 40 s; "
         "ended by timeout (the sweep never checked the mesh size)",
         ["sweep", "-n", "2", "partial-closure", "--set", "mesh.sigma_vertices=1000000000", "--set",
          "mesh.boundary_vertices=400000000", "--set", "materials.layer2.E=1:2:2", "-o", "c104.h5"])
    case(104, "solve -n 2, mesh.target_error = 1e-12", "no refusal in 15 min: 13 levels up to 2.2 million "
         "unknowns (0.48 %), then meshing the 14th; ended by timeout (900 s)",
         ["solve", "-n", "2", "partial-closure", *SMALL, "--set", "mesh.target_error=1e-12", "-o", "c104.h5"],
         kept=("c104",))

    reference = ["reference", "partial-closure", *SMALL]
    case(107, "reference, solver.p = 0.001 (a bound the multipliers reach)", "exit 0, 1.3 s, nothing said: the bound "
         "ignored, the file records solver.p = 0.001", [*reference, "--set", "solver.p=0.001", "-o", "c107.h5"])
    case(107, "reference, solver.p = 1e9 (a bound nothing reaches)", "exit 0, 4.5 s: the bound never checked (the same solution, "
         "by chance)",
         [*reference, "--set", "solver.p=1e9", "-o", "c107p.h5"], observe=_unknowns("c107p.h5"))
    case(107, "reference, mesh.target_error = 0.15", "exit 0, 4.3 s: the unrefined mesh (560 unknowns, estimated "
         "error 32.5 %); the file records the target", [*reference, "--set", "mesh.target_error=0.15", "-o", "c107t.h5"],
         observe=_unknowns("c107t.h5"))
    case(107, "reference, mesh.target_error = 1e-12", "exit 0, 4.8 s, nothing said: the unrefined mesh (560 unknowns, 32.5 %)",
         [*reference, "--set", "mesh.target_error=1e-12", "-o", "c107.h5"])
    for key in ("solver.tol=1e-3", "solver.method=uzawa", "solver.max_iterations=1"):
        case(107, f"reference, {key}", "exit 0, nothing said: ignored", [*reference, "--set", key, "-o", "c107.h5"])
    case(107, "sweep, mesh.target_error = 0.2", "exit 0, 20 s (measured with target 0.05): every run on the unrefined mesh (560 unknowns)",
         [*sweep, "--set", "mesh.target_error=0.2", "--set", "materials.layer2.E=100:200:2", "-o", "c107s.h5"],
         observe=_sweep_unknowns("c107s.h5"))
    case(107, "solve -n 2, solver.theta = 10 (method schur)", "exit 0, nothing said: ignored",
         ["solve", "-n", "2", "partial-closure", *SMALL, "--set", "solver.theta=10", "-o", "c107.h5"])
    case(107, "solve, solver.max_iterations = 10 (method schur)", "exit 0, nothing said: ignored",
         ["solve", "partial-closure", *SMALL, "--set", "solver.max_iterations=10", "-o", "c107.h5"])
    case(107, "mesh, materials.layer1.E = 10", "exit 0, nothing said: ignored",
         ["mesh", "partial-closure", *SMALL, "--set", "materials.layer1.E=10"])
    case(107, "sweep, title = \"x\"", "exit 0, nothing said: the sweep file keeps no title",
         [*sweep, "--set", 'title="x"', "--set", "materials.layer2.E=1:2:2", "-o", "c107s.h5"])
