"""Fuzzing ddsolve as a user could call it: generated scenes (``--set`` values), command lines (ddsolve
and PETSc options in any order, outputs of every kind) on 1 and 4 ranks, and corrupted result files.

Every run must end within its timeout, with an exit status of the documented set, at most one error
line (and one warning line), no traceback, the previous result files byte-identical unless it wrote
a result (0, or 3: not converged), and a result that says converged must pass the KKT check.  The
examples are derandomized (the same every run, so CI is stable); DDSOLVE_FUZZ_EXAMPLES=200 searches
further.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import ddsolve, without_open_mpi_noise
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ddsolve.io import hdf5
from ddsolve.io import viewer
from ddsolve.post import analysis
from ddsolve.problem import scene as scene_module

pytestmark = pytest.mark.mpi

EXIT_STATUSES = {0, 1, 2, 3, 4}
EXAMPLES = int(os.environ.get("DDSOLVE_FUZZ_EXAMPLES", "0"))
SMALL = ["mesh.sigma_vertices=13", "mesh.boundary_vertices=32"]

#: Scene values: ordinary, extreme and malformed.
SETTINGS = st.one_of(
    st.sampled_from([
        "materials.layer1.E=1e-20", "materials.layer2.E=1e-300", "materials.layer1.E=1e308", "materials.layer1.E=0",
        "materials.layer2.nu=0.4999", "materials.layer1.nu=0.5", "solver.method=uzawa", "solver.method=mprgp",
        "solver.method=fista", "solver.method=newton", "solver.theta=1e6", "solver.theta=0.5", "solver.theta=auto",
        "solver.stop=kkt", "solver.stop=paper", "solver.tol=1e-3", "solver.tol=1e-15", "solver.p=0.005",
        "solver.max_iterations=5", "loads.layer1.top.y=[0.0, -1e300]", "loads.layer1.top.y=[0.0]",
        "loads.layer2.bottom.x=1e-200", "loads.layer1.top.y=\"1/x\"", "geometry.crack=[0.1, 0.100000000001]",
        "geometry.crack=[-0.98, 0.98]", "geometry.crack=[]", "geometry.crack=[0.5, -0.5]", 'title="a\\u0000b"',
        'title="\\u00e9t\\u00e9 \\u2603"', "mesh.degree=2", "contact.nonpenetration=false",
        "mesh.sigma_vertices=1000000000", "mesh.boundary_vertices=3", "mesh.size=0.3", "solver.thta=1", "=",
    ]),
    st.builds(lambda layer, value: f"materials.{layer}.E={value!r}", st.sampled_from(["layer1", "layer2"]),
              st.floats(min_value=1e-310, max_value=1e308)),
)
PETSC = st.sampled_from([
    [], ["-u_minus_ksp_type", "cg"], ["-v_plus_pc_type", "nonsense"], ["-u_minus_ksp_typo", "cg"],
    ["-uminus_ksp_type", "cg"], ["-u_plus_pc_factor_mat_solver_type", "nonsense"],
    ["-v_minus_ksp_type", "cg", "-v_minus_pc_type", "none", "-v_minus_ksp_max_it", "3"],
])
OUTPUTS = st.sampled_from(["out.h5", "other.h5", "", "out.xdmf", "scene.toml", "dir.h5", "missing/out.h5", "out-layer1.h5"])


@pytest.fixture(scope="module")
def previous(tmp_path_factory) -> Path:
    """A folder with a scene file and a previous result set ``out.h5`` (and its viewer files)."""
    folder = tmp_path_factory.mktemp("previous")
    ddsolve("solve", "partial-closure", *[item for s in SMALL for item in ("--set", s)], "-o",
            str(folder / "out.h5"), ranks=2)
    shutil.copy(scene_module.builtin_folder() / "partial-closure.toml",
                folder / "scene.toml")
    (folder / "dir.h5").mkdir()
    return folder


def fresh(previous: Path, tmp_path: Path) -> Path:
    folder = tmp_path / "run"
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(previous, folder)
    return folder


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


def run(folder: Path, arguments: list[str], timeout: float = 120) -> subprocess.CompletedProcess:
    try:
        return without_open_mpi_noise(subprocess.run([sys.executable, "-m", "ddsolve", *arguments],
                                                     capture_output=True, text=True, timeout=timeout, cwd=folder,
                                                     stdin=subprocess.DEVNULL, env={**os.environ, "MPLBACKEND": "Agg"}))
    except subprocess.TimeoutExpired:
        pytest.fail(f"no answer within {timeout} s (a hang): ddsolve {' '.join(arguments)}")


def well_behaved(completed: subprocess.CompletedProcess) -> None:
    """The documented exit statuses, no traceback, at most one error line and one warning line."""
    what = f"ddsolve {' '.join(completed.args[3:])}\n{completed.stderr}"
    assert completed.returncode in EXIT_STATUSES, what
    assert "Traceback" not in completed.stdout + completed.stderr, what
    lines = completed.stderr.strip().splitlines()
    errors = [line for line in lines if line.startswith("ddsolve: error: ")]
    warnings = [line for line in lines if line.startswith("ddsolve: warning: ")]
    assert len(errors) + len(warnings) == len(lines) and len(errors) <= 1 and len(warnings) <= 1, what
    assert (completed.returncode == 0) == (not errors), what


def converged_results_pass_the_check(folder: Path, output: str) -> None:
    result = hdf5.read(folder / output)
    if result.converged:
        checked = analysis.constraints(result)
        assert not checked.violations(analysis.tolerance_of(result)), checked


@settings(max_examples=EXAMPLES or 8, deadline=None, derandomize=not EXAMPLES,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(ranks=st.sampled_from([1, 4]), items=st.lists(SETTINGS, max_size=3), petsc=PETSC, output=OUTPUTS,
       order=st.randoms(use_true_random=False), scene=st.sampled_from(["partial-closure", "scene.toml"]))
def test_generated_scenes_and_command_lines(previous, tmp_path, ranks, items, petsc, output, order, scene):
    folder = fresh(previous, tmp_path)
    before = snapshot(folder)
    groups = [["--set", item] for item in [*SMALL, *items]] + [["-o", output]] + ([petsc] if petsc else [])
    order.shuffle(groups)
    arguments = ["solve", "-n", str(ranks), scene, *[word for group in groups for word in group]]
    completed = run(folder, arguments)
    well_behaved(completed)
    written = completed.returncode in (0, 3)
    if written:
        converged_results_pass_the_check(folder, output)
    kept = [output, *(p.name for p in viewer.viewer_paths(Path("."), Path(output).stem))] if written else []
    for name, data in before.items():  # every other file, and all of them after a failure, unchanged
        if name not in kept:
            assert (folder / name).read_bytes() == data, (name, arguments, completed.stderr)


def corrupted(source: Path, target: Path, data: st.DataObject) -> None:
    """A copy of ``source`` with one generated corruption: bytes overwritten, the file cut, or a dataset
    or attribute replaced by something of another shape, kind or value."""
    raw = bytearray(source.read_bytes())
    kind = data.draw(st.sampled_from(["bytes", "cut", "dataset", "attribute"]))
    if kind == "bytes":
        for _ in range(data.draw(st.integers(1, 20))):
            raw[data.draw(st.integers(0, len(raw) - 1))] = data.draw(st.integers(0, 255))
    elif kind == "cut":
        raw = raw[:data.draw(st.integers(0, len(raw) - 1))]
    target.write_bytes(bytes(raw))
    if kind in ("dataset", "attribute"):
        with h5py.File(target, "r+") as f:
            if kind == "dataset":
                names: list[str] = []
                f.visit(lambda name: names.append(name) if isinstance(f[name], h5py.Dataset) else None)
                name = data.draw(st.sampled_from(sorted(names)))
                shape = f[name].shape
                del f[name]
                replacement = data.draw(st.sampled_from(["shape", "nan", "strings", "huge", "negative", "gone"]))
                if replacement == "shape":
                    f[name] = np.zeros(tuple(data.draw(st.lists(st.integers(0, 4), max_size=3))))
                elif replacement == "strings":
                    f[name] = np.array([b"abc"] * max(1, shape[0] if shape else 1))
                elif replacement != "gone":
                    value = {"nan": np.nan, "huge": 1e308, "negative": -1}[replacement]
                    f[name] = np.full(shape, value)
            else:
                name = data.draw(st.sampled_from(sorted(f.attrs.keys())))
                f.attrs[name] = data.draw(st.sampled_from(["", "x = [", "-1", "nan"]))


@settings(max_examples=EXAMPLES or 12, deadline=None, derandomize=not EXAMPLES,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(command=st.sampled_from(["check", "plot", "compare", "export"]), data=st.data())
def test_corrupted_result_files(previous, tmp_path, command, data):
    folder = fresh(previous, tmp_path)
    corrupted(folder / "out.h5", folder / "bad.h5", data)
    for stem in ("bad",):  # previous pictures and viewer files of the broken result
        for name in ("deformed", "crack-faces", "convergence"):
            (folder / f"{stem}-{name}.png").write_bytes(b"previous")
    before = snapshot(folder)
    arguments = {"check": ["check", "bad.h5"], "plot": ["plot", "bad.h5"], "compare": ["compare", "bad.h5", "out.h5"],
                 "export": ["export", "bad.h5"]}[command]
    completed = run(folder, arguments, timeout=60)
    well_behaved(completed)
    assert completed.returncode in (0, 1, 3)
    if completed.returncode != 0:
        assert snapshot(folder) == before, completed.stderr
