"""Class 106 of docs/robustness.md, files users have: gmsh's MSH 2.2 files (an element listed once per
physical group it is in) and input files that cannot be opened.

``msh_versions`` and ``geometries`` make the test files (tests/test_reliability_msh.py uses them too).
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from experiments import ROOT

CLASS = 106
#: The paper's geometry (docs/example1.geo) and scene: the MSH 2.2 cases mesh it.
EXAMPLE1 = ROOT / "docs" / "example1.geo"
MATERIALS = "[materials.layer1]\nE = 200.0\nnu = 0.28\n[materials.layer2]\nE = 112.0\nnu = 0.32\n"
PAPER_LOADS = '[loads.layer1.bottom]\ny = "0.078125*x"\n[loads.layer1.top]\ny = "-0.078125*x"\n'
#: A strip with three cracks on Σ, clamped on the left, loaded on three sides.
CRACKS = """\
lc = 1.0;
Point(1) = {0, -0.5, 0, lc}; Point(2) = {4, -0.5, 0, lc}; Point(3) = {4, 0.5, 0, lc}; Point(4) = {0, 0.5, 0, lc};
Point(5) = {0, 0, 0, lc}; Point(6) = {0.5, 0, 0, lc}; Point(7) = {1, 0, 0, lc}; Point(8) = {1.75, 0, 0, lc};
Point(9) = {2.25, 0, 0, lc}; Point(10) = {3, 0, 0, lc}; Point(11) = {3.5, 0, 0, lc}; Point(12) = {4, 0, 0, lc};
Line(1) = {1, 2}; Line(2) = {2, 12}; Line(3) = {12, 3}; Line(4) = {3, 4}; Line(5) = {4, 5}; Line(6) = {5, 1};
Line(7) = {5, 6}; Line(8) = {6, 7}; Line(9) = {7, 8}; Line(10) = {8, 9}; Line(11) = {9, 10}; Line(12) = {10, 11};
Line(13) = {11, 12};
Curve Loop(1) = {1, 2, -13, -12, -11, -10, -9, -8, -7, 6}; Plane Surface(1) = {1};
Curve Loop(2) = {7, 8, 9, 10, 11, 12, 13, 3, 4, 5}; Plane Surface(2) = {2};
Physical Surface("lower") = {1};
Physical Surface("upper") = {2};
Physical Curve("sigma") = {7, 8, 9, 10, 11, 12, 13};
Physical Curve("crack") = {8, 10, 12};
Physical Curve("clamped") = {5, 6};
Physical Curve("bottom") = {1};
Physical Curve("top") = {4};
Physical Curve("right") = {2, 3};
"""
CRACKS_LOADS = ('[loads.layer1.bottom]\ny = -0.01\n[loads.layer2.top]\npressure = "0.01*x"\n'
                "[loads.layer2.right]\nx = 0.005\n")
#: Extra groups on example1.geo: both surfaces in a second group and the lower one in a third, curves
#: in a second group (MSH 2.2 then lists those triangles and lines two or three times).
EXTRA_GROUPS = ('Physical Surface("layers") = {1, 2};\nPhysical Surface("below") = {1};\n'
                'Physical Curve("outer") = {1, 2, 3, 4, 5, 6};\nPhysical Curve("glue") = {7, 9};\n')


def geometries() -> dict[str, tuple[str, str]]:
    """name -> (.geo text, the scene's loads): example1, several cracks, extra groups, and example1
    without the groups of the contract (a mesh of the box, read by meshio, its surfaces in two groups)."""
    example1 = EXAMPLE1.read_text()
    plain = "".join(line + "\n" for line in example1.splitlines() if not line.startswith("Physical"))
    return {"example1": (example1, PAPER_LOADS), "cracks": (CRACKS, CRACKS_LOADS),
            "groups": (example1 + EXTRA_GROUPS, PAPER_LOADS),
            "box": (plain + 'Physical Surface("domain") = {1, 2};\nPhysical Surface("all") = {1, 2};\n'
                    'Physical Curve("edges") = {1, 2, 3, 4, 5, 6, 7, 8, 9};\n', PAPER_LOADS)}


def _mesh_and_write(geo: Path, size: float, order: int, outputs: dict[float, Path]) -> None:
    """Mesh ``geo`` with gmsh (largest size ``size``, ``order`` 1 or 2) and write it in each version."""
    import gmsh

    gmsh.initialize([], readConfigFiles=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.open(str(geo))
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(2)
        if order == 2:
            gmsh.model.mesh.setOrder(2)
        for version, path in outputs.items():
            gmsh.option.setNumber("Mesh.MshFileVersion", version)
            gmsh.write(str(path))
    finally:
        gmsh.finalize()


def msh_versions(folder: Path, name: str, geo_text: str, loads: str, size: float, order: int = 1
                 ) -> dict[int, Path]:
    """One gmsh mesh of ``geo_text`` written as MSH 2.2 and as MSH 4.1, each with a scene file:
    {2: scene of the 2.2 file, 4: scene of the 4.1 file} (gmsh runs in a child process)."""
    from ddsolve.mesh.gmsh_io import apart

    geo = folder / f"{name}.geo"
    geo.write_text(geo_text)
    stem = f"{name}-p{order}"
    files = {2.2: folder / f"{stem}-v2.msh", 4.1: folder / f"{stem}-v4.msh"}
    apart(_mesh_and_write, geo, size, order, files)
    scenes = {}
    for version, path in files.items():
        scenes[int(version)] = folder / f"{path.stem}.toml"
        scenes[int(version)].write_text(f'[mesh]\nfile = "{path.name}"\ndegree = {order}\n{MATERIALS}{loads}')
    return scenes


def energy(path: Path) -> float:
    """The energy stored in a result file."""
    import h5py

    with h5py.File(path, "r") as f:
        return float(f.attrs["energy"])


#: Measured on the code before the fix (same files, same commands).
SIGMA_TWICE = "«ddsolve: error: {name}: lower half: Σ is not one simple curve; it must run from the outer boundary to the outer boundary»"
BEFORE_MSH = {
    ("example1", 1, "solve"): "exit 1, 6.9 s: " + SIGMA_TWICE,
    ("example1", 1, "reference"): "exit 1, 2.4 s: " + SIGMA_TWICE,
    ("example1", 2, "solve"): "exit 1, 6.1 s: " + SIGMA_TWICE,
    ("example1", 2, "reference"): "exit 1, 1.9 s: " + SIGMA_TWICE,
    ("cracks", 1, "solve"): "exit 1, 8.9 s: " + SIGMA_TWICE,
    ("cracks", 2, "reference"): "exit 1, 2.2 s: " + SIGMA_TWICE,
    ("groups", 1, "solve"): "exit 1, 5.6 s: «ddsolve: error: {name}: lower half: 964 triangles are listed more than once»",
    ("box", 1, "reference"): "exit 1, 2.3 s: «ddsolve: error: {name}: lower half: 482 triangles are listed more than once»",
}


def measure(hostile) -> None:
    """Add the rows of class 106 to ``hostile`` (a :class:`~experiments.robustness.Hostile`)."""
    folder = hostile.folder
    shapes = geometries()
    for (name, order, command), before in BEFORE_MSH.items():
        scenes = msh_versions(folder, name, *shapes[name], size=0.1 if order == 1 else 0.2, order=order)
        launch = ["solve", "-n", "4"] if command == "solve" else ["reference"]
        msh = f"{scenes[2].stem}.msh"
        output = f"{scenes[2].stem}-{command}.h5"

        def observe(completed, scenes=scenes, launch=launch, output=output) -> str:
            if completed.returncode != 0:
                return ""
            other = f"{scenes[4].stem}-{launch[0]}.h5"
            second, _ = hostile.run([*launch, scenes[4].name, "-o", other])
            if second.returncode != 0:
                return f"; the MSH 4.1 run failed: {second.stderr.strip()}"
            a, b = energy(folder / output), energy(folder / other)
            return f"; energy {a!r}, from the MSH 4.1 file {b!r} (difference {abs(a - b):.1e})"
        hostile.case(CLASS, f"MSH 2.2 file, {name} P{order} ({command})", before.format(name=msh),
                     [*launch, scenes[2].name, "-o", output], observe=observe)
    _unopenable(hostile)


#: What each input that cannot be opened did before the fix (as root, with a directory in its place; as
#: an unprivileged user, with mode 000 or in a folder without search permission).
BEFORE_DIRECTORY = {
    "scene": "exit 1, 0.8 s: «ddsolve: error: dir.toml: no such scene file or built-in scene (built-in: ...)»",
    "mesh": "exit 1, 1.2 s: «ddsolve: error: dir.msh: mesh file not found»",
    "result": "exit 1, 0.6 s: «ddsolve: error: dir.h5: result file not found»",
}
BEFORE_DENIED = {
    "scene": "exit 1, 0.7 s: «ddsolve: error: scene.toml: cannot read scene file (PermissionError)»",
    "geo": "exit 1, 1.4 s: «ddsolve: error: example1.geo: missing physical surface 'lower' (required: ...)»",
    "msh": "exit 1, 2.0 s: «ddsolve: error: e4.msh: cannot read mesh ([Errno 13] Permission denied: 'e4.msh')»",
    "sweep": "exit 0, 2.6 s, nothing on standard error: every run «failed: ... Permission denied»",
    "check": "exit 1, 0.9 s: «ddsolve: error: res.h5: not a ddsolve result file ([Errno 13] Unable to open file ...)»",
    "locked folder": "exit 1, 1.0 s: 26-line traceback (PermissionError)",
}


def _unopenable(hostile) -> None:
    """Inputs that cannot be opened: a directory in their place (any user), and mode 000 or a folder
    without search permission (an unprivileged user: as root, ddsolve is run as nobody)."""
    folder = hostile.folder
    for name in ("dir.toml", "dir.msh", "dir.h5"):
        (folder / name).mkdir(exist_ok=True)
    scene = folder / "readable.toml"
    scene.write_text(f'[mesh]\nfile = "example1-p1-v4.msh"\n{MATERIALS}{PAPER_LOADS}')
    hostile.case(CLASS, "scene file is a directory", BEFORE_DIRECTORY["scene"], ["mesh", "dir.toml"])
    hostile.case(CLASS, "mesh file is a directory", BEFORE_DIRECTORY["mesh"],
                 ["mesh", scene.name, "--set", "mesh.file=dir.msh"])
    hostile.case(CLASS, "result file is a directory (check)", BEFORE_DIRECTORY["result"], ["check", "dir.h5"])
    shared = Path(tempfile.mkdtemp(prefix="ddsolve-unreadable-"))
    try:
        _denied(hostile, shared)
    finally:
        shutil.rmtree(shared, ignore_errors=True)


def _denied(hostile, shared: Path) -> None:
    folder = hostile.folder
    shared.chmod(0o777)
    for name in ("example1.geo", "example1-p1-v4.msh"):
        shutil.copy(folder / name, shared / name)
    result = next(folder.glob("example1-p1-v4-solve.h5"), None)
    scene_text = f'[mesh]\nfile = "{{}}"\n{{}}{MATERIALS}{PAPER_LOADS}'
    (shared / "scene.toml").write_text(scene_text.format("example1.geo", "size = 0.2\n"))
    (shared / "geo.toml").write_text(scene_text.format("example1.geo", "size = 0.2\n"))
    (shared / "msh.toml").write_text(scene_text.format("example1-p1-v4.msh", ""))
    (shared / "locked").mkdir()
    shutil.copy(shared / "geo.toml", shared / "locked" / "s.toml")
    if result is not None:
        shutil.copy(result, shared / "res.h5")
    for name in ("scene.toml", "example1.geo", "example1-p1-v4.msh", "res.h5"):
        if (shared / name).exists():
            (shared / name).chmod(0)
    (shared / "locked").chmod(0o700)
    cases = [("scene file mode 000", "scene", ["mesh", "scene.toml"]),
             (".geo file mode 000", "geo", ["mesh", "geo.toml"]),
             (".msh file mode 000", "msh", ["mesh", "msh.toml"]),
             ("sweep over a .msh file of mode 000", "sweep",
              ["sweep", "msh.toml", "--set", "materials.layer2.E=100:200:2", "-o", "s.h5"]),
             ("scene in a folder without search permission", "locked folder", ["mesh", "locked/s.toml"])]
    if result is not None:
        cases.append(("result file mode 000 (check)", "check", ["check", "res.h5"]))
    prefix = ["setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups"] if os.geteuid() == 0 else []
    for label, key, arguments in cases:
        started = time.perf_counter()
        try:
            completed = subprocess.run(
                [*prefix, sys.executable, "-m", "ddsolve", *arguments], capture_output=True, text=True, timeout=300,
                cwd=shared, stdin=subprocess.DEVNULL,
                env={**os.environ, "PYTHONPATH": str(ROOT), "HOME": str(shared),
                     "MPLCONFIGDIR": str(shared), "PYTHONDONTWRITEBYTECODE": "1"})
        except (OSError, subprocess.SubprocessError) as exc:
            hostile.rows[CLASS].append((label, BEFORE_DENIED[key], f"not measured here ({exc})"))
            continue
        user = " (run as nobody)" if prefix else ""
        hostile.rows[CLASS].append((label + user, BEFORE_DENIED[key],
                                    hostile.outcome(completed, time.perf_counter() - started)))
