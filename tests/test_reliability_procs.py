"""Class 9 of issue 21: no process outlives its command.  However the launcher ends (SIGTERM, SIGINT,
SIGKILL) and at whatever phase (meshing, adaptive levels, factorization, write), and when a rank
crashes, no rank and no gmsh process of the run is alive 5 s after the launcher's end."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from experiments.hostile_procs import AFTER, PHASES, left_after, marked, stop
from ddsolve.parallel.launch import interrupt_line

SIGNALS = [signal.SIGTERM, signal.SIGINT, signal.SIGKILL]


def launcher_status(signum: int) -> int:
    """The status of ``solve -n N`` after SIGINT or SIGTERM (docs/usage.md): the launcher supervises
    mpiexec, passes the signal on once and exits 130 or 143 itself."""
    return 143 if signum == signal.SIGTERM else 130


def ended_cleanly(outcome: dict, *statuses: int) -> None:
    """The phase was reached, the launcher ended with one of ``statuses`` within seconds, without a
    traceback, and nothing of the run was left."""
    assert outcome["reached"], outcome["output"][-2000:]
    assert outcome["status"] in statuses, (outcome["status"], outcome["output"][-2000:])
    assert outcome["seconds"] < 15.0, outcome["seconds"]
    assert "Traceback" not in outcome["output"], outcome["output"][-2000:]
    assert outcome["left"] == {}, f"alive {AFTER:g} s after the launcher's end: {outcome['left']}"


@pytest.mark.mpi
@pytest.mark.parametrize("phase", ["meshing", "levels", "factorization", "write"])
@pytest.mark.parametrize("signum", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_a_signal_to_the_launcher_ends_every_process_at_every_phase(tmp_path, phase, signum):
    outcome = stop(tmp_path, phase, signum)
    if signum == signal.SIGKILL:
        ended_cleanly(outcome, -signal.SIGKILL)
    else:  # at the write, the set may be complete (0); the launcher says which, in one line, always
        ended_cleanly(outcome, launcher_status(signum), *((0,) if phase == "write" else ()))
        said = [line for line in outcome["output"].splitlines() if line.startswith("ddsolve:")]
        assert said == [interrupt_line(signum == signal.SIGTERM, complete=outcome["status"] == 0)], said


@pytest.mark.mpi
@pytest.mark.parametrize("signum", [signal.SIGKILL, signal.SIGSEGV], ids=lambda s: signal.Signals(s).name)
def test_a_crashing_rank_ends_the_others_and_its_gmsh_process(tmp_path, signum):
    """The rank that meshes crashes: Open MPI ends the others, the kernel its gmsh process."""
    outcome = stop(tmp_path, "meshing", signum, target="rank")
    assert outcome["reached"] and outcome["status"] not in (0, None), outcome["output"][-2000:]
    assert outcome["left"] == {}, outcome["left"]


@pytest.mark.mpi
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=lambda s: signal.Signals(s).name)
def test_on_one_rank_too_the_launcher_exits_with_the_signal_status(tmp_path, signum):
    """docs/usage.md: ``solve -n N`` (any N) exits 130 or 143 and says which signal stopped it."""
    outcome = stop(tmp_path, "meshing on one rank", signum)
    ended_cleanly(outcome, launcher_status(signum))
    assert outcome["output"].strip().splitlines()[-1] == interrupt_line(signum == signal.SIGTERM, complete=False)


@pytest.mark.mpi
def test_ranks_end_when_mpiexec_does_not_answer_their_abort(tmp_path):
    """SIGTERM to every rank while mpiexec is stopped: MPI_Abort never returns (and holds the GIL)."""
    outcome = stop(tmp_path, "levels", signal.SIGTERM, target="ranks")
    assert outcome["reached"] and outcome["ranks_seconds"] < 10.0, outcome
    assert outcome["left"] == {}, outcome["left"]


@pytest.mark.mpi
@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130),
                                            (signal.SIGKILL, -signal.SIGKILL)], ids=["SIGTERM", "SIGINT", "SIGKILL"])
def test_a_one_process_run_ends_with_its_gmsh_process_and_the_documented_status(tmp_path, signum, status):
    outcome = stop(tmp_path, "one process, meshing", signum)
    ended_cleanly(outcome, status)
    if signum != signal.SIGKILL:
        assert outcome["output"].strip().splitlines()[-1] == ("ddsolve: terminated" if status == 143
                                                               else "ddsolve: interrupted")


@pytest.mark.mpi
def test_a_child_asking_to_end_with_its_parent_ends_when_the_parent_is_killed():
    """A parent that sleeps, its child that asked for SIGKILL on the parent's end: SIGKILL the parent."""
    code = ("import os, time\n"
            "from ddsolve.environment import end_with_parent\n"
            "parent = os.getpid()  # known before the fork: the child may run only once the parent is gone\n"
            "if os.fork() == 0:\n"
            "    end_with_parent(parent)\n"
            "    time.sleep(60)\n"
            "    os._exit(0)\n"
            "print('ready', flush=True)\n"
            "time.sleep(60)\n")
    tag = f"child-{os.getpid()}-{time.time_ns()}"
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "DDSOLVE_PROCS_RUN": tag})
    try:
        assert parent.stdout.readline().strip() == "ready"
        deadline = time.perf_counter() + 10
        while len(marked(tag)) < 2 and time.perf_counter() < deadline:
            time.sleep(0.02)
        assert len(marked(tag)) == 2
        parent.kill()
        parent.wait(timeout=10)
        deadline = time.perf_counter() + 5
        while marked(tag) and time.perf_counter() < deadline:
            time.sleep(0.02)
        assert marked(tag) == {}
    finally:
        for pid in marked(tag):
            os.kill(pid, signal.SIGKILL)
        parent.kill()
        parent.wait()


@pytest.mark.mpi
def test_a_child_whose_parent_is_already_gone_ends_at_once():
    """The parent may end between the fork and the request: the child then ends itself."""
    completed = subprocess.run([sys.executable, "-c", "from ddsolve.environment import end_with_parent\n"
                                "end_with_parent(1 << 22)\nprint('still alive')"],
                               capture_output=True, text=True, timeout=60)
    assert completed.returncode == 128 + signal.SIGKILL and "still alive" not in completed.stdout


# --- fuzz: a signal at a random moment of a run ------------------------------------------------
@pytest.mark.mpi
@settings(max_examples=3, deadline=None)
@given(signum=st.sampled_from(SIGNALS), delay=st.floats(0.0, 12.0))
def test_a_signal_at_any_moment_leaves_no_process(tmp_path_factory, signum, delay):
    """A small adaptive solve signalled ``delay`` seconds after its start (start-up, meshing, levels, write)."""
    folder = tmp_path_factory.mktemp("fuzz")
    tag = f"fuzz-{os.getpid()}-{time.time_ns()}"
    arguments = PHASES["levels"][0]
    process = subprocess.Popen([sys.executable, "-m", "ddsolve", *arguments], cwd=folder, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
                               env={**os.environ, "MPLBACKEND": "Agg", "DDSOLVE_PROCS_RUN": tag})
    try:
        time.sleep(delay)
        process.send_signal(signum)
        _, stderr = process.communicate(timeout=60)
        left = left_after(tag, time.perf_counter())
        assert left == {}, left
        assert "Traceback" not in stderr, stderr
    finally:
        for pid in marked(tag):
            os.kill(pid, signal.SIGKILL)
        process.kill()
        process.wait()
