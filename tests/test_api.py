"""docs/api.md's examples, run as users run them: plain Python (one rank) and under mpiexec -n 4."""
from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest
from conftest import ROOT, without_open_mpi_noise

import ddsolve
from ddsolve.parallel.launch import mpiexec_command

EXAMPLES = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "api.md").read_text(encoding="utf-8"), re.S)
STUDY = next(i for i, code in enumerate(EXAMPLES) if "half_length" in code)


def run_example(code: str, tmp_path, ranks: int | None = None) -> subprocess.CompletedProcess:
    script = tmp_path / "example.py"
    script.write_text(code, encoding="utf-8")
    command = [sys.executable, str(script)]
    if ranks is not None:
        command = mpiexec_command(ranks, [])[:-3] + [sys.executable, "-m", "mpi4py", str(script)]
    completed = without_open_mpi_noise(subprocess.run(command, capture_output=True, text=True, timeout=600,
                                                      cwd=tmp_path, stdin=subprocess.DEVNULL,
                                                      env={**os.environ, "PYTHONPATH": str(ROOT)}))
    assert completed.returncode == 0, completed.stdout + completed.stderr
    return completed


def test_the_examples_are_found():
    assert len(EXAMPLES) >= 5


@pytest.mark.mpi
@pytest.mark.parametrize("number", range(len(EXAMPLES)))
def test_every_example_runs_on_one_rank(number, tmp_path):
    out = run_example(EXAMPLES[number], tmp_path).stdout
    assert out.strip(), "an example prints what it shows"


@pytest.mark.mpi
def test_the_study_runs_on_four_ranks_and_prints_g_at_both_tips_once(tmp_path):
    serial = run_example(EXAMPLES[STUDY], tmp_path).stdout.splitlines()
    parallel = run_example(EXAMPLES[STUDY], tmp_path, ranks=4).stdout.splitlines()
    assert len(parallel) == 5 and all("left tip" in line and "right tip" in line for line in parallel)
    for one, four in zip(serial, parallel):  # the same G on 1 and 4 ranks, to the printed digits
        assert one == four


@pytest.mark.mpi
@pytest.mark.parametrize("number", [i for i, code in enumerate(EXAMPLES) if "ddsolve.solve(" in code
                                    and "save(" not in code])
def test_solving_examples_run_on_four_ranks(number, tmp_path):
    run_example(EXAMPLES[number], tmp_path, ranks=4)


def test_with_validates_as_a_scene_file_does():
    scene = ddsolve.Scene.load("partial-closure")
    assert scene.with_({"solver.tol": 1e-10}).solver.tol == 1e-10
    assert scene.with_(**{"materials.layer2.E": 20}).materials["layer2"].E == 20.0
    assert scene.solver.tol == 1e-8  # unchanged: scenes are values
    with pytest.raises(ddsolve.SceneError, match=r"unknown key solver\.tl \(did you mean solver\.tol\?\)"):
        scene.with_({"solver.tl": 1})
    with pytest.raises(ddsolve.SceneError, match="materials.layer1.E must be > 0"):
        scene.with_({"materials.layer1.E": -1.0})


def test_with_keeps_files_relative_to_the_scene():
    scene = ddsolve.Scene.load("arc-bond")
    assert scene.with_({"mesh.size": 0.3}).mesh.file == scene.mesh.file


def test_with_gives_the_scene_load_gives_with_the_same_overrides():
    """Defaults that follow other keys follow them through ``with_`` (``mesh.target_error`` chooses P2 and,
    with a size, a graded mesh), and overrides given in turns add up as one list of them does."""
    base = ddsolve.Scene.load("partial-closure")
    adaptive = base.with_({"mesh.target_error": 0.01})
    assert (base.mesh.degree, adaptive.mesh.degree) == (1, 2)
    assert adaptive == ddsolve.Scene.load("partial-closure", {"mesh.target_error": 0.01})
    sized = adaptive.with_({"mesh.size": 0.1})
    assert sized == ddsolve.Scene.load("partial-closure", {"mesh.target_error": 0.01, "mesh.size": 0.1})
    assert sized.mesh.grading == 0.2 and base.with_({"mesh.size": 0.1}).mesh.grading is None
    table = {"E": 70.0, "nu": 0.33}  # a table, as --set 'materials.layer1={E = 70.0, nu = 0.33}' gives
    assert base.with_({"materials.layer1": table}) == ddsolve.Scene.load(
        "partial-closure", ["materials.layer1={E = 70.0, nu = 0.33}"])


def test_arguments_of_the_wrong_type_are_one_line_errors():
    with pytest.raises(ddsolve.SceneError, match=r"^scene: a Scene, a built-in scene's name or a scene file's path "
                                                 r"\(got int\)$"):
        ddsolve.reference(5)
    with pytest.raises(ddsolve.DDSolveError, match=r"^load: a result file's path \(got dict\)$"):
        ddsolve.load({})
    for run in (lambda **comm: ddsolve.solve("full-opening", **comm),
                lambda **comm: ddsolve.sweep("full-opening", {"solver.theta": [60.0, 65.0]}, **comm),
                lambda **comm: ddsolve.grow("full-opening", 2.0, **comm)):
        with pytest.raises(ddsolve.DDSolveError, match=r"^comm: an mpi4py communicator \(got int\)$"):
            run(comm=5)


@pytest.mark.solve
def test_a_result_is_written_only_under_an_hdf5_name(tmp_path):
    """As ``-o`` is checked: the API's ``output`` and ``save`` refuse another suffix, nothing written."""
    scene = ddsolve.Scene.load("full-opening").with_({"mesh.sigma_vertices": 24, "mesh.boundary_vertices": 40})
    with pytest.raises(ddsolve.DDSolveError, match=r"^output .*o\.txt: a result is an HDF5 file: give it the suffix"):
        ddsolve.solve(scene, output=tmp_path / "o.txt")
    with pytest.raises(ddsolve.DDSolveError, match=r"^save .*noext: a result is an HDF5 file"):
        ddsolve.save(ddsolve.reference(scene), tmp_path / "noext")
    assert list(tmp_path.iterdir()) == []


def test_load_refuses_what_is_not_a_scene(tmp_path):
    with pytest.raises(ddsolve.SceneError, match="no such scene file or built-in scene"):
        ddsolve.Scene.load(tmp_path / "missing.toml")
