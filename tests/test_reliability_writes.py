"""Issue 21, classes 5 and 8 (writes): a result set is replaced whole (exit 0) or kept byte-identical
(non-zero exit) whenever a signal comes, SIGKILL at any step of the commit leaves a state the next
run completes, and no command writes over one of its inputs or to a name without its suffix."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, SMALL, ddsolve
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from experiments import hostile_writes
from ddsolve.io import hdf5
from ddsolve.problem.scene import builtin_folder

P48 = ["--set", "mesh.sigma_vertices=48", "--set", "mesh.boundary_vertices=80"]
SCENES = builtin_folder()

# --- the commit protocol, in a child process killed or signalled at every step --------------------
CHILD = hostile_writes.COMMIT_CHILD


def _commit(folder: Path, count: int, existing: int, step: int, signum: int, final: bool = True):
    """(exit status, state of the set after the next run's recovery, scratch files left)."""
    return hostile_writes.commit_step(folder, count, existing, step, signum, final)


#: The file operations of CHILD with 3 files, 2 of them there before: 1 the probe of check_targets,
#: 2-4 the temporaries, 5 the journal renamed into place (the commit point), 6-7 the backups (hard
#: links), 8-10 the renames, 11 the journal removed, 12-13 the backups removed; 14: no signal.
COMMIT_POINT, STEPS = 5, 14


@pytest.mark.mpi
@pytest.mark.parametrize("step", range(1, STEPS + 1))
def test_sigkill_at_every_step_of_a_commit_leaves_one_whole_set(tmp_path, step):
    status, state, left = _commit(tmp_path, 3, 2, step, signal.SIGKILL)
    assert not left, left
    assert state == ("old" if step <= COMMIT_POINT else "new"), (step, state)
    assert status == (0 if step == STEPS else -signal.SIGKILL)


@pytest.mark.mpi
@pytest.mark.parametrize("step", range(1, STEPS + 1))
def test_sigterm_at_every_step_of_a_commit_new_set_and_0_or_old_set_and_143(tmp_path, step):
    status, state, left = _commit(tmp_path, 3, 2, step, signal.SIGTERM)
    assert not left
    assert (state, status) == (("old", 143) if step <= COMMIT_POINT - 1 else ("new", 0)), (step, state, status)


@pytest.mark.mpi
def test_a_signal_during_a_commit_that_does_not_end_the_command_is_raised_after_it(tmp_path):
    status, state, left = _commit(tmp_path, 3, 2, COMMIT_POINT + 1, signal.SIGTERM, final=False)
    assert (state, status, left) == ("new", 143, [])


@pytest.mark.mpi
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(count=st.integers(1, 4), existing=st.integers(0, 4), step=st.integers(1, 20),
       signum=st.sampled_from([signal.SIGKILL, signal.SIGTERM, signal.SIGINT]))
def test_fuzz_signals_at_random_moments_of_a_write(tmp_path_factory, count, existing, step, signum):
    """The generator that would have found class 5: any set, any signal, any step of the write."""
    status, state, left = _commit(tmp_path_factory.mktemp("w"), count, min(existing, count), step, signum)
    assert state in ("old", "new") and not left, (state, left)
    if signum != signal.SIGKILL:
        assert (state, status) in (("new", 0), ("old", 143 if signum == signal.SIGTERM else 130)), (state, status)


@pytest.mark.mpi
def test_a_journal_left_by_a_killed_run_is_completed_by_the_next_read(tmp_path):
    paths = [tmp_path / f"f{i}.h5" for i in range(3)]
    for path in paths:
        path.write_bytes(b"old")
    child = subprocess.run([sys.executable, "-c", CHILD, str(tmp_path), "3", "10", str(int(signal.SIGKILL)), "1"],
                           timeout=60, env={**os.environ, "PYTHONPATH": str(ROOT)}, stdin=subprocess.DEVNULL)
    assert child.returncode == -signal.SIGKILL
    assert [p.read_bytes() for p in paths] == [b"new 0", b"old", b"old"]  # killed between two renames
    with pytest.raises(Exception, match="not a ddsolve result file"):
        hdf5.read(paths[1])  # the read completes the set first: f1.h5 is the new (not HDF5) file
    assert [p.read_bytes() for p in paths] == [b"new 0", b"new 1", b"new 2"]
    assert not [p for p in tmp_path.iterdir() if ".ddsolve~" in p.name]


# --- whole runs: SIGTERM at evenly spaced moments -------------------------------------------------
@pytest.mark.mpi
def test_sigterm_at_moments_of_a_solve_replaces_the_set_whole_or_keeps_it(tmp_path):
    outcomes = hostile_writes.solve_moments(tmp_path, 5, P48, timeout=120)
    assert all(outcome.good for outcome in outcomes), "\n".join(map(str, outcomes))


@pytest.mark.mpi
def test_sigterm_at_moments_of_a_sweep_replaces_its_file_or_keeps_it(tmp_path):
    outcomes = hostile_writes.sweep_moments(tmp_path, 3, SMALL, timeout=120)
    assert all(outcome.good for outcome in outcomes), "\n".join(map(str, outcomes))


# --- class 8: -o naming an input, or without the suffix -------------------------------------------
@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """scene.toml, a .geo scene (arc-bond.toml, arc-bond.geo), a mesh file sq.msh and its scene m.toml,
    and a result r.h5."""
    folder = tmp_path_factory.mktemp("inputs")
    shutil.copy(SCENES / "partial-closure.toml", folder / "scene.toml")
    for name in ("arc-bond.toml", "arc-bond.geo"):
        shutil.copy(SCENES / name, folder / name)
    ddsolve("mesh", str(folder / "scene.toml"), *SMALL, "-o", str(folder / "sq.msh"), timeout=120)
    materials = (folder / "scene.toml").read_text().split("[materials", 1)[1]
    (folder / "m.toml").write_text(f'title = "m"\n[mesh]\nfile = "sq.msh"\n[materials{materials}')
    ddsolve("solve", str(folder / "scene.toml"), *SMALL, "-o", str(folder / "r.h5"), timeout=120)
    return folder


SCENE_OF = {"scene.toml": ("scene.toml", SMALL), "arc-bond.geo": ("arc-bond.toml", ["--set", "mesh.size=0.3"]),
            "arc-bond.toml": ("arc-bond.toml", ["--set", "mesh.size=0.3"]), "sq.msh": ("m.toml", []),
            "m.toml": ("m.toml", []), "out.txt": ("scene.toml", SMALL), "noext": ("scene.toml", SMALL)}
SWEPT = ["--set", "materials.layer1.E=150:200:2"]


def _refused(folder: Path, arguments: list[str], named: str, ranks: bool = False) -> None:
    before = {path: path.read_bytes() for path in folder.iterdir() if path.is_file()}
    run = ddsolve(*arguments, check=False, timeout=120)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 1 and len(lines) == 1 and lines[0].startswith("ddsolve: error: "), run.stderr
    assert named in lines[0] and "-o" in lines[0], lines[0]
    assert "Traceback" not in run.stdout + run.stderr
    after = {path: path.read_bytes() for path in folder.iterdir() if path.is_file()}
    assert after == before


@pytest.mark.mpi
@pytest.mark.parametrize("command", ["solve", "solve -n 2", "reference", "sweep", "sweep -n 2"])
@pytest.mark.parametrize("output", sorted(SCENE_OF))
def test_no_result_command_writes_over_an_input_or_without_h5(inputs, command, output):
    scene, mesh = SCENE_OF[output]
    extra = SWEPT if command.startswith("sweep") else []
    _refused(inputs, [*command.split(), str(inputs / scene), *mesh, *extra, "-o", str(inputs / output)], output)


@pytest.mark.mpi
@pytest.mark.parametrize("output", ["scene.toml", "arc-bond.geo", "sq.msh", "m.toml"])
def test_mesh_does_not_write_over_an_input(inputs, output):
    scene, mesh = SCENE_OF[output]
    if output == "m.toml" or output == "scene.toml":
        scene = output
    _refused(inputs, ["mesh", str(inputs / scene), *mesh, "-o", str(inputs / output)], output)


@pytest.mark.mpi
@pytest.mark.parametrize("output", ["r.h5", "scene.toml", "sq.msh"])
def test_export_o_naming_a_file_is_refused(inputs, output):
    _refused(inputs, ["export", str(inputs / "r.h5"), "-o", str(inputs / output)], output)


@pytest.mark.mpi
def test_export_and_plot_write_beside_their_input_and_keep_it(inputs, tmp_path):
    result = tmp_path / "r.h5"
    shutil.copy(inputs / "r.h5", result)
    data = result.read_bytes()
    for arguments in (["export", str(result)], ["plot", str(result)]):
        run = ddsolve(*arguments, check=False, timeout=120)
        assert run.returncode == 0 and result.read_bytes() == data, run.stderr
    assert {p.name for p in tmp_path.iterdir()} >= {"r-layer1.vtu", "r-paraview.py", "r-deformed.png"}
    assert not [p for p in tmp_path.iterdir() if ".ddsolve~" in p.name]


@pytest.fixture
def small_file_system(tmp_path):
    """A 200 KiB file system (mounting one needs root; skipped otherwise)."""
    folder = tmp_path / "full"
    folder.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", str(folder)],
                      capture_output=True).returncode != 0:
        pytest.skip("mounting a small file system needs root")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], capture_output=True)


@pytest.mark.mpi
@pytest.mark.parametrize("filled_kib", [40, 120, 160])  # the HDF5 file, a layer file, then the other layer's
def test_four_ranks_writing_into_a_full_file_system_end_in_one_line(small_file_system, filled_kib):
    """The ranks write one file together: when rank 0 or all of them hit the full disk, every rank stops
    (no rank waits for the others at a barrier), one line says which file, nothing is left or replaced."""
    (small_file_system / "filler").write_bytes(bytes(filled_kib * 1024))
    completed = ddsolve("solve", "partial-closure", "--set", "mesh.sigma_vertices=13", "--set",
                        "mesh.boundary_vertices=32", "-o", str(small_file_system / "out.h5"), ranks=4, check=False,
                        timeout=120)
    assert completed.returncode == 1, completed.stderr
    lines = [line for line in completed.stderr.splitlines() if not line.startswith("[warn]")]
    assert len(lines) == 1 and lines[0].startswith("ddsolve: error: ") and \
        lines[0].endswith(": cannot write (No space left on device)"), lines
    assert sorted(path.name for path in small_file_system.iterdir()) == ["filler"]


def _zombie() -> subprocess.Popen:
    """A child that has ended and is not reaped yet (a zombie), as a rank killed by the launcher is
    until its parent, or init, reaps it."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    while Path(f"/proc/{child.pid}/stat").read_text().rpartition(")")[2].split()[0] != "Z":
        pass
    return child


@pytest.mark.mpi  # starts a process
def test_the_temporaries_of_a_killed_writer_that_is_not_reaped_are_removed(tmp_path):
    """A killed rank's temporary files go with the next recovery even while the rank is a zombie: a
    zombie writes nothing more (os.kill(pid, 0) still finds it)."""
    from ddsolve.environment import process_exists
    from ddsolve.io import safe

    child = _zombie()
    try:
        assert not process_exists(child.pid) and process_exists(os.getpid())
        left = tmp_path / f".w.h5.ddsolve~{safe.host_tag()}~{child.pid}~0123abcd.tmp.h5"
        left.write_bytes(b"half written")
        assert safe.remove_stale(tmp_path / "w.h5") == [left] and not left.exists()
    finally:
        child.wait()


@pytest.mark.mpi  # starts a process
def test_ending_a_session_waits_until_its_processes_are_gone():
    """The launcher SIGKILLs what an interrupted mpiexec left and repairs the result set next; the repair
    removes temporaries only of writers that are gone, so end_session returns once they are."""
    from ddsolve.environment import process_exists
    from ddsolve.parallel import launch

    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], start_new_session=True)
    try:
        launch.end_session(sleeper.pid)
        assert not process_exists(sleeper.pid)
    finally:
        sleeper.wait()


#: A commit section whose deferred SIGTERM another thread takes between the section's look at the pending
#: signals and its consuming them (the interrupt watchdog's thread does not block it): simulated by a
#: sigpending that reports a signal nobody sent.
TAKEN_CHILD = """
import signal, sys
from ddsolve.io import safe
seen = []
signal.signal(signal.SIGTERM, lambda number, _frame: seen.append(number))
signal.sigpending = lambda: {signal.SIGTERM}
with safe.commit_section():
    pass
sys.exit(0 if seen == [signal.SIGTERM] else 1)
"""


@pytest.mark.mpi
def test_a_deferred_signal_that_another_thread_took_does_not_hang_the_commit():
    import subprocess
    import sys

    child = subprocess.run([sys.executable, "-c", TAKEN_CHILD], capture_output=True, text=True, timeout=20,
                           stdin=subprocess.DEVNULL)
    assert child.returncode == 0, child.stderr
