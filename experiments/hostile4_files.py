"""Issue 40, classes 6 and 7 and first use (files and the API): inputs reached through other files, the
API's arguments and its runs under MPI, a result's repr and docs/api.md's mpiexec line.

:func:`measure` adds the rows to docs/robustness.md: command-line cases through ``hostile.case``, the
API's as small scripts run with ``python`` or with docs/api.md's mpiexec line.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from experiments import ROOT

CLASSES = {
    206: ("Inputs reached through other files", "the files a run reads are the scene file, its mesh or geometry file "
          "and every file those name (an XDMF mesh's heavy-data .h5 and binary items, a .geo's Include, Merge and "
          "ShapeFromFile), collected by one function (io.inputs) that the -o check of every command and every writer "
          "of the API (output= of solve, reference, sweep, grow; save, which keeps its run's inputs) use"),
    207: ("The API under MPI and with wrong types", "the API checks its arguments' types (ArgumentError, naming the "
          "argument) and overrides (a dict or KEY=VALUE items, one string being one item); solve, sweep and grow "
          "check on every rank the rank count, the arguments and a hash of the scene and of each argument against "
          "rank 0's, and raise what fails on every rank; an uncaught ddsolve error ends a script with its one line "
          "and, under MPI, ends every rank (MPI_Abort with its exit status)"),
    211: ("First use: a result's repr and the documented mpiexec line", "repr(result) is one line (title, method, "
          "converged, energy, G, file); docs/api.md's mpiexec line carries Open MPI's --oversubscribe and --quiet "
          "and says what root needs, and a test runs it as written"),
}

#: The SMALL mesh, for the command line and for the API.
SMALL = ["--set", "mesh.sigma_vertices=13", "--set", "mesh.boundary_vertices=32"]
SMALL_KEYS = {"mesh.sigma_vertices": 13, "mesh.boundary_vertices": 32}

#: A scene on an XDMF mesh whose arrays are in box.h5 (written by :func:`_fixtures`), with a toughness for grow.
XDMF_SCENE = """\
[geometry]
crack = [-0.5, 0.5]
[mesh]
file = "box.xdmf"
[materials.layer1]
E = 200.0
nu = 0.28
[materials.layer2]
E = 112.0
nu = 0.32
[loads.layer1.bottom]
y = [0.0, 0.078125]
[loads.layer1.top]
y = [0.0, -0.078125]
[fracture]
toughness = 1e-6
"""


def _fixtures(folder: Path) -> None:
    """box.xdmf (a structured mesh of the square, its arrays in box.h5), x.toml on it, fo.toml (Example 2
    on the SMALL mesh with a toughness)."""
    import meshio
    import numpy as np

    x, y = np.meshgrid(np.linspace(-1.0, 1.0, 9), np.linspace(-1.0, 1.0, 9))
    points = np.column_stack([x.ravel(), y.ravel()])
    v = np.arange(81).reshape(9, 9)
    a, b, c, d = v[:-1, :-1].ravel(), v[:-1, 1:].ravel(), v[1:, 1:].ravel(), v[1:, :-1].ravel()
    cells = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    meshio.write(folder / "box.xdmf", meshio.Mesh(points, [("triangle", cells)]))
    (folder / "x.toml").write_text(XDMF_SCENE)
    from ddsolve.problem.scene import builtin_scenes

    text = builtin_scenes()["full-opening"]
    text = re.sub(r"sigma_vertices = \d+", "sigma_vertices = 13", re.sub(r"boundary_vertices = \d+",
                                                                         "boundary_vertices = 32", text))
    (folder / "fo.toml").write_text(text + "\n[fracture]\ntoughness = 1e-6\n")


def _geo_merging(folder: Path) -> None:
    """a.toml: the arc-bond scene on a.geo, which merges extra.msh."""
    from ddsolve.problem.scene import builtin_folder

    (folder / "a.geo").write_text((builtin_folder() / "arc-bond.geo").read_text() + 'Merge "extra.msh";\n')
    (folder / "a.toml").write_text((builtin_folder() / "arc-bond.toml").read_text().replace("arc-bond.geo", "a.geo"))
    (folder / "extra.msh").write_text("a mesh merged into the geometry\n")


def _kept(folder: Path, name: str):
    """An ``observe`` note: whether ``name`` is byte-identical after the run (put back if not)."""
    before = (folder / name).read_bytes()

    def observe(_completed) -> str:
        same = (folder / name).read_bytes() == before
        if not same:
            (folder / name).write_bytes(before)
        return f"; {name} kept" if same else f"; {name} REPLACED"

    return observe


def documented_line() -> str:
    """docs/api.md's mpiexec line (its first shell block)."""
    page = ROOT / "docs" / "api.md"
    block = re.search(r"```sh\n(.*?)```", page.read_text(encoding="utf-8"), re.S).group(1)
    return next(line.split("#")[0].strip() for line in block.splitlines() if line.startswith("mpiexec"))


def script(hostile, number: int, label: str, before: str, code: str, ranks: int | None = None, observe=None) -> None:
    """Run ``code`` as a script in the hostile folder, with ``python`` or (``ranks``) docs/api.md's mpiexec
    line in an environment without Open MPI's variables (as root with --allow-run-as-root, as the page
    says), and add its row."""
    path = hostile.folder / "script.py"
    path.write_text(textwrap.dedent(code), encoding="utf-8")
    environment = {key: value for key, value in os.environ.items() if not key.startswith("OMPI_")}
    environment.update(PATH=f"{Path(sys.executable).parent}{os.pathsep}{environment.get('PATH', '')}",
                       PYTHONPATH=str(ROOT))
    if ranks is None:
        command = [sys.executable, str(path)]
    else:
        line = documented_line().replace("-n 4", f"-n {ranks}")
        root = "--allow-run-as-root " if os.geteuid() == 0 else ""
        command = ["bash", "-c", line.replace("mpiexec ", f"mpiexec {root}", 1)]
    started = time.perf_counter()
    completed = subprocess.run(command, capture_output=True, text=True, errors="backslashreplace", timeout=600,
                               cwd=hostile.folder, env=environment, stdin=subprocess.DEVNULL)
    outcome = hostile.outcome(completed, time.perf_counter() - started)
    printed = completed.stdout.strip().splitlines()
    if printed:
        outcome += f"; printed «{printed[0][:120]}»" + (f" ({len(printed)} lines)" if len(printed) > 1 else "")
    hostile.rows[number].append((label, before, outcome + (observe(completed) if observe else "")))


def measure(hostile) -> None:
    _fixtures(hostile.folder)
    for command, before in (
            (["solve"], "exit 0, 0.8 s: box.h5 replaced by the result: the mesh destroyed"),
            (["reference"], "exit 0, 0.7 s: box.h5 replaced by the result: the mesh destroyed"),
            (["sweep", "--set", "materials.layer2.E=100:120:2"], "exit 0, 0.8 s: box.h5 replaced by the sweep"),
            (["grow", "--to", "2", "--steps", "2", "--pictures", "0"], "exit 0, 1.4 s: box.h5 replaced by the growth")):
        hostile.case(206, f"{command[0]} on an XDMF mesh (box.xdmf, arrays in box.h5) with -o box.h5", before,
                     [command[0], "x.toml", *command[1:], "-o", "box.h5"], observe=_kept(hostile.folder, "box.h5"))
    _geo_merging(hostile.folder)
    hostile.case(206, "mesh a.toml -o extra.msh, a.geo saying Merge \"extra.msh\"", "exit 1, 1.8 s: «a.geo: gmsh cannot "
                 "read it ('extra.msh', line 1: syntax error ...)»: -o not seen as an input (the Merge not followed); "
                 "kept only because gmsh failed first",
                 ["mesh", "a.toml", "-o", "extra.msh"], observe=_kept(hostile.folder, "extra.msh"))
    for label, before, code, kept in (
            ("API: solve('x.toml', output='box.h5') (XDMF mesh's arrays)", "exit 0, 1.5 s: box.h5 replaced",
             "import ddsolve; ddsolve.solve('x.toml', output='box.h5')", "box.h5"),
            ("API: save(solve('x.toml'), 'box.h5')", "exit 0, 1.5 s: box.h5 replaced",
             "import ddsolve; ddsolve.save(ddsolve.solve('x.toml'), 'box.h5')", "box.h5"),
            ("API: grow(scene of fo.toml, 2.0, steps=2, output='fo.toml')", "exit 0, 1.1 s: fo.toml replaced by "
             "the growth file", "import ddsolve; ddsolve.grow(ddsolve.Scene.load('fo.toml'), 2.0, steps=2, "
             "output='fo.toml')", "fo.toml"),
            ("API: sweep('fo.toml', {...}, output='g.txt')", "exit 1, 0.5 s: Traceback ... DDSolveError: -o g.txt: a "
             "result is an HDF5 file (named -o, a traceback)", "import ddsolve; ddsolve.sweep('fo.toml', "
             "{'materials.layer2.E': [100.0, 120.0]}, output='g.txt')", "fo.toml")):
        script(hostile, 206, label, before, code, observe=_kept(hostile.folder, kept))
    _measure_api(hostile)


def _measure_api(hostile) -> None:
    """Class 207 and the first-use rows (211)."""
    small = repr(SMALL_KEYS)
    scene = f"ddsolve.Scene.load('fo.toml')"
    for label, before, code in (
            ("scene.with_(None)", "exit 1, 0.1 s: Traceback ... TypeError: 'NoneType' object is not iterable",
             f"import ddsolve; {scene}.with_(None)"),
            ("scene.with_('solver.tol=1e-10')", "exit 1, 0.1 s: Traceback ... SceneError: --set s: expected KEY=VALUE "
             "(the string read character by character)",
             f"import ddsolve; print({scene}.with_('solver.tol=1e-10').solver.tol)"),
            ("grow(scene, '2', steps=2)", "exit 1, 0.5 s: Traceback ... TypeError: must be real number, not str",
             f"import ddsolve; ddsolve.grow({scene}, '2', steps=2)"),
            ("grow(scene, 2.0, steps=True)", "exit 0, 1.1 s: True taken as 1 step, 3 steps returned",
             f"import ddsolve; ddsolve.grow({scene}, 2.0, steps=True)"),
            ("sweep(scene, {'materials.layer2.E': '100'})", "not measured before (a string of values)",
             f"import ddsolve; ddsolve.sweep({scene}, {{'materials.layer2.E': '100'}})")):
        script(hostile, 207, f"API: {label}", before, code)
    for label, before, code, ranks in (
            ("solve under mpiexec -n 3", "exit 1, 0.8 s: a traceback from each of the 3 ranks (unsupported number "
             "of ranks 3) and Open MPI's MPI_ABORT banner",
             f"import ddsolve; ddsolve.solve(ddsolve.Scene.load('partial-closure', {small}))", 3),
            ("solve under mpiexec -n 5", "exit 1: a traceback from each of the 5 ranks",
             f"import ddsolve; ddsolve.solve(ddsolve.Scene.load('partial-closure', {small}))", 5),
            ("a misspelt key on rank 1 of 2", "exit 1, 0.4 s: Traceback ... SceneError: partial-closure: unknown key "
             "solver.tl, Open MPI's MPI_ABORT banner",
             "import ddsolve; from mpi4py import MPI\n"
             f"ddsolve.solve(ddsolve.Scene.load('partial-closure', {{**{small}, **({{'solver.tl': 1}} "
             "if MPI.COMM_WORLD.rank == 1 else {})}))", 2),
            ("a different E on each of 2 ranks, one solve", "exit 0, 0.8 s: both ranks print rank 0's energy "
             "-6.4299e-06", "import ddsolve; from mpi4py import MPI\n"
             f"print(ddsolve.solve(ddsolve.Scene.load('partial-closure', {{**{small}, 'materials.layer2.E': "
             "100.0 + 50 * MPI.COMM_WORLD.rank})).energy)", 2)):
        script(hostile, 207, f"API: {label}", before, code, ranks=ranks)
    script(hostile, 211, "len(repr(ddsolve.solve('partial-closure')))", "42 005 characters (the arrays in full)",
           "import ddsolve; r = ddsolve.solve('partial-closure'); print(len(repr(r)), repr(r))")
    script(hostile, 211, "docs/api.md's mpiexec line as written (4 ranks, 2 cores, as root as the page says)",
           "«mpiexec has detected an attempt to run as root»; with --allow-run-as-root: «There are not enough "
           "slots available in the system to satisfy the 4 slots», exit 1",
           "import ddsolve; from mpi4py import MPI\n"
           f"r = ddsolve.solve(ddsolve.Scene.load('partial-closure', {small}))\n"
           "if MPI.COMM_WORLD.rank == 0: print(f'solved on {r.ranks} ranks, converged {r.converged}')", 4)
