"""Hostile input, one group of tests per class of docs/robustness.md: a refusal is one line naming
what to change, with the documented exit status, no traceback, no hang, and the previous result
files byte-identical."""
from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import (SMALL, ddsolve, previous_set, refused, solved_reference, unchanged,
                      without_open_mpi_noise)

from ddsolve.errors import DDSolveError, SceneError
from ddsolve.io import hdf5
from ddsolve.io import safe
from ddsolve.post import analysis
from ddsolve.problem import scene


def run(*args: str, env: dict | None = None, timeout: float = 120, cwd: Path | None = None
        ) -> subprocess.CompletedProcess:
    """``python -m ddsolve ARGS`` (``solve -n N`` starts mpiexec itself)."""
    return without_open_mpi_noise(subprocess.run([sys.executable, "-m", "ddsolve", *args], capture_output=True,
                                                 text=True, timeout=timeout, stdin=subprocess.DEVNULL, cwd=cwd,
                                                 env={**os.environ, "MPLBACKEND": "Agg", **(env or {})}))


@pytest.fixture(scope="module")
def result_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("result") / "base.h5"
    ddsolve("solve", "partial-closure", *SMALL, "-o", str(path), ranks=2)
    return path


# --- 1. silent wrong answers -----------------------------------------------------------------------
@pytest.mark.mpi
@pytest.mark.parametrize("overrides", [
    ["--set", "solver.theta=1e6"],  # met the paper's rule after 3 iterations, gluing gap 1.7
    ["--set", "materials.layer1.E=1e-6", "--set", "materials.layer2.E=1e-6"],  # θ = 65 far too large
], ids=["theta-1e6", "moduli-1e-6"])
def test_a_stopping_rule_met_too_early_is_not_called_converged(tmp_path, overrides):
    output = tmp_path / "uzawa.h5"
    completed = run("solve", "-n", "2", "partial-closure", *SMALL, "--set", "solver.method=uzawa", *overrides,
                    "-o", str(output))
    refused(completed, 3, "uzawa: not converged: the final solution violates", "gluing gap", 'solver.stop = "kkt"')
    result = hdf5.read(output)  # written, and honest about it
    assert not result.converged and result.attrs["kkt_gluing_gap"] > 0.1
    refused(run("check", str(output)), 3, "KKT check failed", "converged = false")


@pytest.mark.mpi
def test_tiny_moduli_are_solved_as_accurately_as_ordinary_ones(tmp_path):
    """E = 1e-20 in both layers: MUMPS gave a 33 % error before the blocks were scaled to order one."""
    tiny = [*SMALL, "--set", "materials.layer1.E=1e-20", "--set", "materials.layer2.E=1e-20"]
    ddsolve("solve", "partial-closure", *tiny, "-o", str(tmp_path / "dd.h5"), ranks=4)
    solved_reference("partial-closure", *tiny, "-o", str(tmp_path / "ref.h5"))
    result, reference = hdf5.read(tmp_path / "dd.h5"), hdf5.read(tmp_path / "ref.h5")
    assert result.converged and result.solves == 3
    assert analysis.compare(result, reference).energy_error < 1e-12
    assert result.attrs["kkt_equilibrium"] < 1e-14


@pytest.mark.mpi
@pytest.mark.parametrize("command, overrides, fragment", [
    ("solve", ["--set", "materials.layer1.E=1e308"], "materials.layer1.E: the elastic matrix has entries of 1.28e+308"),
    ("reference", ["--set", "materials.layer1.E=1e-300"], "materials.layer1.E: the elastic matrix has entries of 1.28e-300"),
    ("reference", ["--set", "materials.layer1.E=1e-200"], "materials.layer1.E: the elastic matrix (largest entry 1.28e-200) "
     "with loads.layer1."),
    ("reference", ["--set", "loads.layer1.top.y=[0.0, -1e300]"], "loads.layer1.top up to 1e+300"),
])
def test_moduli_and_loads_beyond_double_precision_are_refused_by_name(tmp_path, command, overrides, fragment):
    output = tmp_path / "out.h5"
    kept = previous_set(output)
    arguments = ["-n", "2"] if command == "solve" else []
    refused(run(command, *arguments, "partial-closure", *SMALL, *overrides, "-o", str(output)), 1, fragment,
            "double-precision")
    assert unchanged(kept)


# --- 2. tracebacks ------------------------------------------------------------------------------
@pytest.mark.mpi
@pytest.mark.parametrize("arguments, env, fragment", [
    (["solve", "-n", "1", "partial-closure", *SMALL, "-u_minus_pc_type", "nonsense"], {},
     "block u_minus: Unable to find requested PC type nonsense (from -u_minus_pc_type nonsense)"),
    (["solve", "-n", "4", "partial-closure", *SMALL], {"PETSC_OPTIONS": "-v_plus_ksp_type nonsense"},
     "block v_plus: Unable to find requested KSP type nonsense (from -v_plus_ksp_type nonsense)"),
    (["reference", "partial-closure", *SMALL, "-reference_pc_factor_mat_solver_type", "nonsense"], {},
     "Could not locate solver type nonsense"),
    (["solve", "-n", "2", "partial-closure", *SMALL, "--set", 'title="a\\u0000b"'], {},
     "title must be text without NUL characters"),
], ids=["pc-type", "petsc-options-ksp-type", "reference-factor-package", "nul-title"])
def test_what_petsc_and_hdf5_refuse_is_one_line_naming_the_option(tmp_path, arguments, env, fragment):
    output = tmp_path / "out.h5"
    kept = previous_set(output)
    line = refused(run(*arguments, "-o", str(output), env=env), 1, fragment)
    assert "is the block clamped" not in line
    assert unchanged(kept)


def corrupt(source: Path, target: Path, edit: str) -> Path:
    """A copy of a result file with one part broken."""
    target.write_bytes(source.read_bytes() if edit != "truncated" else source.read_bytes()[:5000])
    if edit != "truncated":
        with h5py.File(target, "r+") as f:
            if edit == "wrong shape":
                del f["solution/u_minus"]
                f["solution/u_minus"] = np.zeros(3)
            elif edit == "rows missing":
                rows = f["solution/u_plus"].shape[0]
                del f["solution/u_plus"]
                f["solution/u_plus"] = np.zeros((rows - 5, 2))
            elif edit == "cell index":
                cells = f["mesh/lower/cells"][()]
                cells[0, 0] = 10 ** 9
                del f["mesh/lower/cells"]
                f["mesh/lower/cells"] = cells
            elif edit == "strings":
                del f["solution/u_minus"]
                f["solution/u_minus"] = np.array([b"abc", b"def"])
            elif edit == "scene":
                f.attrs["scene"] = "this is = not [ toml"
            elif edit == "crack flags":
                del f["interface/crack"]
                f["interface/crack"] = np.zeros(2, bool)
    return target


EDITS = ["truncated", "wrong shape", "rows missing", "cell index", "strings", "scene", "crack flags"]


@pytest.mark.mpi
@pytest.mark.parametrize("edit", EDITS)
def test_a_broken_result_file_is_named_with_what_is_broken(tmp_path, result_file, edit):
    broken = corrupt(result_file, tmp_path / "broken.h5", edit)
    with pytest.raises(DDSolveError, match=r"broken.h5: not a ddsolve result file \(.+\)$") as raised:
        hdf5.read(broken)
    assert "\n" not in str(raised.value)


@pytest.mark.mpi
@pytest.mark.parametrize("command, edit", [("check", "wrong shape"), ("plot", "cell index"),
                                           ("compare", "rows missing"), ("export", "strings")])
def test_commands_on_a_broken_result_file_give_one_line(tmp_path, result_file, command, edit):
    broken = corrupt(result_file, tmp_path / "broken.h5", edit)
    arguments = [str(broken), str(result_file)] if command == "compare" else [str(broken)]
    refused(run(command, *arguments), 1, "broken.h5: not a ddsolve result file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.h5"]  # nothing written


def test_a_full_disk_during_any_write_is_one_line_and_replaces_nothing(tmp_path, monkeypatch):
    kept = previous_set(tmp_path / "r.h5")
    targets = list(kept)

    def full(name):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    writers = {path: (lambda name: Path(name).write_bytes(b"new")) for path in targets}
    writers[targets[2]] = full
    with pytest.raises(DDSolveError, match="cannot write .No space left on device.$"):
        safe.replace_together(writers)
    assert unchanged(kept) and sorted(tmp_path.iterdir()) == sorted(targets)


def test_a_failed_rename_puts_the_previous_set_back(tmp_path, monkeypatch):
    kept = previous_set(tmp_path / "r.h5")
    targets = list(kept)
    replace = os.replace

    def failing(source, target):
        if Path(target) == targets[3]:
            raise OSError(errno.EPERM, os.strerror(errno.EPERM))
        replace(source, target)

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(DDSolveError, match="cannot replace .Operation not permitted.; the previous files are kept"):
        safe.replace_together({path: (lambda name: Path(name).write_bytes(b"new")) for path in targets})
    monkeypatch.undo()
    assert unchanged(kept) and sorted(tmp_path.iterdir()) == sorted(targets)


@pytest.mark.mpi
def test_hdf5_never_writes_to_a_full_disk_itself():
    """A full disk used to leave the HDF5 library broken (tracebacks, then a segfault at exit)."""
    code = ("from ddsolve.io import safe\n"
            "try:\n"
            "    with safe.hdf5_image('/dev/full') as f:\n"
            "        f['x'] = list(range(100000))\n"
            "except OSError as exc:\n"
            "    print(exc.strerror)\n")
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert completed.returncode == 0 and completed.stdout.strip() == "No space left on device"
    assert completed.stderr == ""


# --- 3. hangs and runaway work ---------------------------------------------------------------
@pytest.mark.mpi
@pytest.mark.parametrize("ranks, fragment", [
    ("99999999999", "unsupported number of ranks"), ("-1", "unsupported number of ranks"),
    ("0", "unsupported number of ranks"), ("2147483648", "more than this machine's"),
])
def test_impossible_rank_counts_are_refused_before_mpiexec(ranks, fragment):
    started = time.perf_counter()
    refused(run("solve", "-n", ranks, "partial-closure", *SMALL, timeout=30), 2, f"-n {ranks}: ", fragment)
    assert time.perf_counter() - started < 20


@pytest.mark.mpi
@pytest.mark.parametrize("command", [["solve", "-n", "4"], ["reference"], ["mesh"]])
def test_an_impossible_mesh_is_refused_with_its_memory_estimate(command):
    huge = ["--set", "mesh.sigma_vertices=1000000000", "--set", "mesh.boundary_vertices=400000000"]
    refused(run(*command, "partial-closure", *huge, timeout=30), 1,
            "mesh.sigma_vertices = 1000000000, mesh.boundary_vertices = 400000000: a mesh of about", " GB")


@pytest.mark.mpi
def test_a_signal_stops_a_long_library_call_within_seconds(tmp_path):
    """gmsh meshing P = 1600 runs for tens of seconds inside C code, where Python's handlers wait."""
    process = subprocess.Popen([sys.executable, "-m", "ddsolve", "mesh", "partial-closure", "--set",
                                "mesh.sigma_vertices=1600", "--set", "mesh.boundary_vertices=2048", "--set",
                                "mesh.refine=0"],  # gmsh, not a coarse mesh refined in a second
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    time.sleep(4.0)
    assert process.poll() is None
    sent = time.perf_counter()
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 143 and stderr.strip() == "ddsolve: terminated"
    assert time.perf_counter() - sent < 10.0


# --- 4. lost or corrupted files -------------------------------------------------------------
@pytest.mark.mpi
def test_outputs_that_would_lose_a_file_are_refused_before_the_solve(tmp_path, mesh_file):
    scene_file = tmp_path / "s.toml"
    scene_file.write_text(scene.builtin_scenes()["partial-closure"].replace(
        "sigma_vertices = 96\nboundary_vertices = 144", f'file = "{mesh_file.name}"'))
    inputs = {path: path.read_bytes() for path in (scene_file, mesh_file)}
    os.link(mesh_file, tmp_path / "input.h5")  # the mesh file under a result's name
    (tmp_path / "dir.h5").mkdir()
    os.mkfifo(tmp_path / "fifo.h5")
    kept = previous_set(tmp_path / "v.h5")
    (tmp_path / "v-layer2.vtu").unlink()
    (tmp_path / "v-layer2.vtu").mkdir()  # one file of the result set cannot be replaced
    del kept[tmp_path / "v-layer2.vtu"]
    for output, fragment in [("s.toml", "-o s.toml: a result is an HDF5 file"),
                             ("input.h5", "input.h5: is an input of this run"),
                             ("dir.h5", "dir.h5: is a directory"),
                             ("fifo.h5", "fifo.h5: is not a regular file"),
                             ("v.h5", "v-layer2.vtu: is a directory"),
                             ("missing/x.h5", "missing/x.h5: output directory missing does not exist"),
                             ("", "-o '': not a file name")]:
        started = time.perf_counter()
        refused(run("solve", "-n", "4", scene_file.name, "-o", output, cwd=tmp_path), 1, fragment)
        assert time.perf_counter() - started < 20  # refused before mpiexec
    assert all(path.read_bytes() == data for path, data in inputs.items())
    assert unchanged(kept) and (tmp_path / "fifo.h5").exists()


@pytest.mark.mpi
def test_temporary_files_of_killed_runs_are_removed_by_the_next_write(tmp_path):
    target = tmp_path / "x.h5"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".x.h5.ddsolve~{safe.host_tag()}~{dead.pid}~0abc.tmp.h5"
    alive = tmp_path / f".x.h5.ddsolve~{safe.host_tag()}~{os.getppid()}~0abd.tmp.h5"
    other = tmp_path / f".x.h5.ddsolve~elsewhere~{dead.pid}~0abe.tmp.h5"
    for path in (stale, alive, other):
        path.write_bytes(b"half written")
    safe.atomic(target, lambda name: Path(name).write_bytes(b"new"))
    assert target.read_bytes() == b"new"
    assert not stale.exists() and alive.exists() and other.exists()


@pytest.mark.mpi
def test_a_kill_during_the_write_keeps_the_previous_set(tmp_path):
    """SIGKILL (nothing can be cleaned up) while the result set is being written."""
    output = tmp_path / "k.h5"
    kept = previous_set(output)
    process = subprocess.Popen([sys.executable, "-m", "ddsolve", "reference", "partial-closure", "--set",
                                "mesh.sigma_vertices=200", "--set", "mesh.boundary_vertices=256", "-o", str(output)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL)
    deadline = time.perf_counter() + 120
    while not list(tmp_path.glob(".k*.tmp*")) and process.poll() is None and time.perf_counter() < deadline:
        time.sleep(0.002)
    seen = bool(list(tmp_path.glob(".k*.tmp*")))
    process.kill()
    process.wait()
    assert seen and unchanged(kept)
    safe.replace_together({path: (lambda name: Path(name).write_bytes(b"next")) for path in kept})  # the next write
    assert sorted(tmp_path.iterdir()) == sorted(kept)  # ... left nothing of the killed one


# --- 5. unclear messages ---------------------------------------------------------------------
def test_a_crack_too_short_to_mesh_names_the_crack_key():
    with pytest.raises(SceneError, match=r"geometry.crack: two points of Σ .* only 1e-12 apart"):
        scene.load("partial-closure", ["geometry.crack=[0.1, 0.100000000001]"])


@pytest.mark.mpi
def test_a_scale_that_draws_nothing_useful_is_refused(tmp_path, result_file):
    local = tmp_path / "r.h5"
    local.write_bytes(result_file.read_bytes())
    refused(run("plot", str(local), "--scale", "1e308"), 1, "--scale 1e308: draws the largest displacement")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]


# --- 6. options typed after PETSc options -----------------------------------------------------
@pytest.mark.mpi
def test_ddsolve_options_after_petsc_options_are_honoured(tmp_path):
    completed = run("solve", "-n", "2", "partial-closure", *SMALL, "-u_minus_ksp_type", "preonly",
                    "--set", "solver.method=mprgp", "-o", str(tmp_path / "out.h5"), "-u_minus_ksp_typo", "cg",
                    cwd=tmp_path)
    assert completed.returncode == 0, completed.stderr
    assert hdf5.read(tmp_path / "out.h5").method == "mprgp"
    assert not (tmp_path / "partial-closure.h5").exists()
    assert completed.stderr.strip() == ("ddsolve: warning: PETSc options not used (misspelt? the prefixes here "
                                        "are u_minus_, u_plus_, v_minus_, v_plus_): -u_minus_ksp_typo cg")


@pytest.mark.mpi
@pytest.mark.parametrize("arguments, fragment", [
    (["check", "x.h5", "-bogus"], "check: unknown option -bogus"),
    (["plot", "x.h5", "-scale", "5"], "did you mean --scale?"),
    (["solve", "-n", "4", "-log_view", "partial-closure"], "give the scene first"),
])
def test_options_nobody_takes_are_refused_as_usage_errors(arguments, fragment):
    refused(run(*arguments, timeout=30), 2, fragment)
