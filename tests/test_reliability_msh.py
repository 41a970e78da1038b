"""Issue 21, class 6 (files users have): gmsh's MSH 2.2 files, where an element in several physical
groups is listed once per group, read as MSH 4.1 files are; an input file that cannot be opened is
one line naming it and the reason."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from conftest import ddsolve, structured_square
from hypothesis import given, settings
from hypothesis import strategies as st

from ddsolve.errors import DDSolveError, MeshError
from experiments.hostile_msh import MATERIALS, PAPER_LOADS, energy, geometries, msh_versions
from ddsolve.io import hdf5
from ddsolve.mesh import geometry, mesh
from ddsolve.problem import scene
from ddsolve.solvers import sweep

SHAPES = geometries()


def build(scene_file: Path) -> mesh.Mesh:
    return geometry.build(scene.load(scene_file))


def same_mesh(a: mesh.Mesh, b: mesh.Mesh) -> None:
    for x, y in zip(a.halves, b.halves):
        assert np.array_equal(x.points, y.points) and np.array_equal(x.cells, y.cells)
        assert sorted(x.boundaries) == sorted(y.boundaries)
        for name in x.boundaries:
            assert np.array_equal(x.boundaries[name], y.boundaries[name]), name
    assert np.array_equal(a.sigma.crack, b.sigma.crack) and np.array_equal(a.sigma.tip, b.sigma.tip)


# --- MSH 2.2 -------------------------------------------------------------------------------------
def test_merge_repeats_keeps_one_copy_per_element_listed_by_several_groups():
    cells = np.array([[1, 2], [2, 1], [2, 3], [2, 3], [3, 4]])
    assert mesh.merge_repeats(cells, np.array([5, 6, 5, 6, 5])).tolist() == [[1, 2], [2, 3], [3, 4]]
    assert mesh.merge_repeats(cells, 2).tolist() == [[1, 2], [2, 3], [3, 4]]
    # a copy within one group stays, to be refused
    assert len(mesh.merge_repeats(cells, np.array([5, 5, 5, 6, 5]))) == 4
    assert len(mesh.merge_repeats(cells, 1)) == 5
    assert len(mesh.merge_repeats(np.array([[1, 2]] * 3), 2)) == 2
    assert mesh.merge_repeats(np.zeros((0, 3), dtype=np.int64), 2).shape == (0, 3)


@pytest.mark.parametrize("name, order", [("example1", 1), ("example1", 2), ("cracks", 1), ("cracks", 2),
                                         ("groups", 1), ("box", 1)])
def test_msh22_and_msh41_give_the_same_mesh(tmp_path, name, order):
    scenes = msh_versions(tmp_path, name, *SHAPES[name], size=0.3, order=order)
    text = (tmp_path / f"{name}-p{order}-v2.msh").read_text()
    assert text.startswith("$MeshFormat\n2.2")
    old, new = build(scenes[2]), build(scenes[4])
    same_mesh(old, new)
    assert new.degree == order
    if name == "cracks":
        assert len(new.sigma.pieces(new.sigma.crack)) == 3


def _msh2_elements(path: Path) -> tuple[list[str], int, int]:
    lines = path.read_text().splitlines()
    start = lines.index("$Elements")
    return lines, start, lines.index("$EndElements")


def _repeat_line(path: Path, kind: int, physical: int | None = None) -> None:
    """Append a copy of the first element of gmsh type ``kind`` (in physical group ``physical``) to a
    MSH 2.2 file, with a new element number."""
    lines, start, end = _msh2_elements(path)
    count = int(lines[start + 1])
    for line in lines[start + 2:end]:
        fields = line.split()
        if int(fields[1]) == kind and (physical is None or int(fields[3]) == physical):
            copy = " ".join([str(count + 1), *fields[1:]])
            break
    lines[start + 1] = str(count + 1)
    lines.insert(end, copy)
    path.write_text("\n".join(lines) + "\n")


def test_a_msh22_element_repeated_within_one_group_is_refused(tmp_path):
    scenes = msh_versions(tmp_path, "example1", *SHAPES["example1"], size=0.4)
    path = tmp_path / "example1-p1-v2.msh"
    original = path.read_text()
    _repeat_line(path, 2)  # a triangle of 'lower' listed twice by 'lower'
    with pytest.raises(MeshError, match="lower half: 1 triangles are listed more than once"):
        build(scenes[2])
    path.write_text(original)
    bottom = re.search(r'^1 (\d+) "bottom"$', original, re.M).group(1)
    _repeat_line(path, 1, int(bottom))  # a 'bottom' edge listed twice by 'bottom': it would be loaded twice
    with pytest.raises(MeshError, match="boundary 'bottom' lists 1 edges more than once"):
        build(scenes[2])


def test_a_vtu_listing_a_triangle_twice_is_still_refused(tmp_path):
    import meshio

    points, cells = structured_square(4, 2)
    path = tmp_path / "m.vtu"
    meshio.write(path, meshio.Mesh(points, [("triangle", np.vstack([cells, cells[:1]]))]))
    (tmp_path / "s.toml").write_text(f'[mesh]\nfile = "m.vtu"\n{MATERIALS}')
    with pytest.raises(MeshError, match="1 triangles are listed more than once"):
        build(tmp_path / "s.toml")


@pytest.mark.mpi
@pytest.mark.parametrize("name, order", [("example1", 1), ("cracks", 2)])
def test_msh22_and_msh41_give_the_same_energy(tmp_path, name, order):
    scenes = msh_versions(tmp_path, name, *SHAPES[name], size=0.2, order=order)
    energies = {}
    for version, scene_file in scenes.items():
        for command in ("solve", "reference"):
            out = tmp_path / f"v{version}-{command}.h5"
            ddsolve(command, str(scene_file), "-o", str(out), ranks=4 if command == "solve" else None, timeout=300)
            energies[version, command] = energy(out)
    print(energies)
    for command in ("solve", "reference"):
        assert abs(energies[2, command] - energies[4, command]) <= 1e-12 * abs(energies[4, command])


@settings(max_examples=6, deadline=None, derandomize=True)
@given(curves=st.lists(st.sets(st.integers(1, 9), min_size=1, max_size=9), max_size=3),
       surfaces=st.lists(st.sets(st.integers(1, 2), min_size=1), max_size=2),
       reuse_name=st.booleans(), order=st.integers(1, 2))
def test_fuzz_extra_physical_groups(curves, surfaces, reuse_name, order):
    """Any extra physical groups (named alike or not) on example1.geo: the MSH 2.2 file reads as the 4.1."""
    extra = "".join(f'Physical Curve("{"bottom" if reuse_name and i == 0 else f"c{i}"}") = '
                    f'{{{", ".join(map(str, sorted(group)))}}};\n' for i, group in enumerate(curves))
    extra += "".join(f'Physical Surface("s{i}") = {{{", ".join(map(str, sorted(group)))}}};\n'
                     for i, group in enumerate(surfaces))
    folder = Path(tempfile.mkdtemp(prefix="ddsolve-msh-fuzz-"))
    try:
        scenes = msh_versions(folder, "fuzz", SHAPES["example1"][0] + extra, PAPER_LOADS, size=0.5, order=order)
        outcomes = []
        for version in (2, 4):
            try:
                outcomes.append(build(scenes[version]))
            except MeshError as exc:  # the same refusal from both versions (e.g. a load name on Σ)
                outcomes.append(str(exc).replace(f"v{version}.msh", ""))
        if isinstance(outcomes[1], mesh.Mesh):
            assert isinstance(outcomes[0], mesh.Mesh), outcomes[0]
            same_mesh(*outcomes)
        else:
            assert outcomes[0] == outcomes[1]
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# --- input files that cannot be opened -----------------------------------------------------------
def _run(folder: Path, *arguments: str, user: list[str] = ()) -> subprocess.CompletedProcess:
    return subprocess.run([*user, sys.executable, "-m", "ddsolve", *arguments], capture_output=True, text=True,
                          timeout=120, cwd=folder, stdin=subprocess.DEVNULL,
                          env={**os.environ, "HOME": str(folder), "MPLCONFIGDIR": str(folder), "MPLBACKEND": "Agg",
                               "PYTHONDONTWRITEBYTECODE": "1",
                               "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                                             os.environ.get("PYTHONPATH", "")])})


def _one_line(completed: subprocess.CompletedProcess, message: str) -> None:
    assert completed.returncode == 1, completed.stderr
    assert "Traceback" not in completed.stderr
    assert completed.stderr.count("\n") == 1 and completed.stderr.startswith("ddsolve: error: "), completed.stderr
    assert message in completed.stderr, completed.stderr


@pytest.fixture(scope="module")
def inputs():
    """A folder every user can enter with readable inputs: a scene, its .geo and .msh, a result file."""
    folder = Path(tempfile.mkdtemp(prefix="ddsolve-inputs-"))
    folder.chmod(0o777)
    scenes = msh_versions(folder, "example1", *SHAPES["example1"], size=0.4)
    (folder / "geo.toml").write_text(f'[mesh]\nfile = "example1.geo"\nsize = 0.4\n{MATERIALS}{PAPER_LOADS}')
    (folder / "vtu.toml").write_text(f'[mesh]\nfile = "m.vtu"\n{MATERIALS}{PAPER_LOADS}')
    import meshio

    points, cells = structured_square(4, 2)
    meshio.write(folder / "m.vtu", meshio.Mesh(points, [("triangle", cells)]))
    completed = _run(folder, "reference", scenes[4].name, "-o", "res.h5")
    assert completed.returncode == 0, completed.stderr
    for path in folder.iterdir():
        path.chmod(0o644)
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


#: command, the input it reads (made unreadable), the file the message names, and what it calls it.
CASES = [
    (["mesh", "geo.toml"], "geo.toml", "scene file"),
    (["mesh", "geo.toml"], "example1.geo", "mesh file"),
    (["reference", "geo.toml", "-o", "out.h5"], "example1.geo", "mesh file"),
    (["mesh", "example1-p1-v4.toml"], "example1-p1-v4.msh", "mesh file"),
    (["mesh", "example1-p1-v2.toml"], "example1-p1-v2.msh", "mesh file"),
    (["mesh", "vtu.toml"], "m.vtu", "mesh file"),
    (["sweep", "example1-p1-v4.toml", "--set", "materials.layer2.E=100:200:2", "-o", "s.h5"], "example1-p1-v4.msh",
     "mesh file"),
    (["check", "res.h5"], "res.h5", "result file"),
    (["compare", "res.h5", "res.h5"], "res.h5", "result file"),
    (["plot", "res.h5"], "res.h5", "result file"),
    (["export", "res.h5", "-o", "."], "res.h5", "result file"),
]


def _unprivileged() -> list[str]:
    """How to run a command so that mode 000 stops its reads (as root: as nobody)."""
    if os.geteuid() != 0:
        return []
    if shutil.which("setpriv") is None:
        pytest.skip("root without setpriv: mode 000 does not stop root's reads")
    return ["setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups"]


@pytest.mark.mpi
@pytest.mark.parametrize("arguments, target, what", CASES)
def test_an_input_without_read_permission_is_one_line(inputs, arguments, target, what):
    user = _unprivileged()
    before = {path.name: path.read_bytes() for path in inputs.iterdir() if path.is_file()}
    (inputs / target).chmod(0)
    try:
        completed = _run(inputs, *arguments, user=user)
    finally:
        (inputs / target).chmod(0o644)
    _one_line(completed, f"{target}: cannot read {what} (permission denied)")
    assert before == {path.name: path.read_bytes() for path in inputs.iterdir() if path.is_file()}
    assert not (inputs / "s.h5").exists() and not (inputs / "out.h5").exists()


@pytest.mark.mpi
@pytest.mark.parametrize("arguments, target, what", CASES[:1] + CASES[3:4] + CASES[7:8])
def test_an_input_in_a_folder_without_search_permission_is_one_line(inputs, arguments, target, what):
    user = _unprivileged()
    locked = inputs / "locked"
    locked.mkdir(mode=0o755)
    try:
        for name in os.listdir(inputs):
            if (inputs / name).is_file():
                shutil.copy(inputs / name, locked / name)
        locked.chmod(0o700 if user else 0o600)
        completed = _run(inputs, *[f"locked/{a}" if a == arguments[1] else a for a in arguments], user=user)
    finally:
        locked.chmod(0o755)
        shutil.rmtree(locked)
    _one_line(completed, f"ddsolve: error: locked/{arguments[1]}: cannot read")
    assert "(permission denied)" in completed.stderr


@pytest.mark.mpi
@pytest.mark.parametrize("arguments, target, what", CASES[:1] + CASES[2:3] + CASES[3:4] + CASES[6:9])
def test_a_directory_in_place_of_an_input_is_one_line(inputs, tmp_path, arguments, target, what):
    folder = tmp_path / "work"
    shutil.copytree(inputs, folder)
    (folder / target).unlink()
    (folder / target).mkdir()
    completed = _run(folder, *arguments)
    _one_line(completed, f"{target}: cannot read {what} (is a directory)")


@pytest.mark.mpi
def test_a_fifo_in_place_of_a_mesh_file_does_not_hang(inputs, tmp_path):
    folder = tmp_path / "work"
    shutil.copytree(inputs, folder)
    (folder / "example1-p1-v4.msh").unlink()
    os.mkfifo(folder / "example1-p1-v4.msh")
    completed = _run(folder, "mesh", "example1-p1-v4.toml")
    _one_line(completed, "example1-p1-v4.msh: cannot read mesh file (not a regular file)")


@pytest.mark.mpi
def test_missing_inputs_keep_their_messages(inputs):
    _one_line(_run(inputs, "mesh", "nope.toml"), "nope.toml: no such scene file or built-in scene (built-in: ")
    _one_line(_run(inputs, "mesh", "geo.toml", "--set", "mesh.file=gone.geo"), "gone.geo: mesh file not found")
    _one_line(_run(inputs, "check", "gone.h5"), "gone.h5: result file not found")


OBSTACLES = ("missing", "directory", "fifo", "dangling link", "under a file")


@settings(max_examples=15, deadline=None, derandomize=True)
@given(kind=st.sampled_from(("scene", "mesh", "result", "sweep")), obstacle=st.sampled_from(OBSTACLES))
def test_fuzz_inputs_that_cannot_be_opened(kind, obstacle):
    """Every reader of an input file refuses one it cannot open with a DDSolveError naming it."""
    folder = Path(tempfile.mkdtemp(prefix="ddsolve-open-fuzz-"))
    try:
        target = folder / f"input.{ {'scene': 'toml', 'mesh': 'msh', 'result': 'h5', 'sweep': 'h5'}[kind]}"
        if obstacle == "directory":
            target.mkdir()
        elif obstacle == "fifo":
            os.mkfifo(target)
        elif obstacle == "dangling link":
            target.symlink_to(folder / "nowhere")
        elif obstacle == "under a file":
            (folder / "plain").write_text("")
            target = folder / "plain" / target.name
        (folder / "s.toml").write_text(f'[mesh]\nfile = "{target}"\n{MATERIALS}')
        read = {"scene": lambda: scene.load(target), "mesh": lambda: scene.load(folder / "s.toml"),
                "result": lambda: hdf5.read(target), "sweep": lambda: sweep.read(target)}[kind]
        with pytest.raises(DDSolveError) as caught:
            read()
        message = str(caught.value)
        assert message.startswith(f"{target}: ") and "\n" not in message
        reason = {"missing": "not found", "dangling link": "not found", "directory": "(is a directory)",
                  "fifo": "(not a regular file)", "under a file": "(not a directory)"}[obstacle]
        assert reason in message or (kind == "scene" and "no such scene file" in message), message
        if kind == "mesh":
            with pytest.raises(MeshError):  # the geometry reader refuses it the same way
                geometry.build(scene.loads((folder / "s.toml").read_text()))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
