"""Issue 40, classes 9 and 10, measured for docs/robustness.md: failures the environment causes (an
out-of-core folder, a scene that is not UTF-8, a long output name, misspelt PETSc options of ``grow``, a
result under a folder the user cannot enter, the package manager's lock), and signals at the edges of a
run.  *Before* is what the code before the fix did (measured once, quoted)."""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from experiments import ROOT
from experiments.robustness import SMALL

CLASSES = {
    209: ("Failures caused by the environment, named",
          "each is checked where the environment is met, before any work: MUMPS_OOC_TMPDIR when out-of-core "
          "factors are asked for (scene or PETSc option), every output name against its folder's name limit "
          "with ddsolve's temporary names, a scene's bytes as UTF-8 (the first bad byte by line, column and "
          "offset), folders that cannot be examined as files that cannot be read, PETSc options nothing read "
          "by every command that takes them (one path), and ./run waits for the package manager's lock"),
    210: ("Signals at the edges of a run",
          "the status is decided once: after mpiexec (or the command) has ended, SIGINT and SIGTERM are ignored "
          "instead of getting back their default action during Python's exit; the handler never raises inside "
          "an import or a finalizer (it delivers the signal again once that is over), a signal before the "
          "handlers ends the process quietly with its status, and a rank takes as its launcher the parent it "
          "had when ddsolve was imported (ending at once if mpiexec already ended)"),
}

#: Open MPI as root and more ranks than cores, as ./run sets them.
MPI_ENVIRONMENT = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                   "OMPI_MCA_rmaps_base_oversubscribe": "1"}


def _environment(**extra: str) -> dict:
    return {**os.environ, **MPI_ENVIRONMENT, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg", **extra}


def _nobody() -> list[str]:
    """A prefix that runs a command as nobody when this is root (permissions do not stop root)."""
    return ["setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups"] \
        if os.geteuid() == 0 and shutil.which("setpriv") else []


def _timed(hostile, command: list[str], cwd: Path, env: dict) -> str:
    """Run ``command``; its outcome as the table writes it."""
    started = time.perf_counter()
    completed = subprocess.run(command, capture_output=True, text=True, cwd=cwd, env=env, timeout=300,
                               stdin=subprocess.DEVNULL, errors="backslashreplace")
    return hostile.outcome(completed, time.perf_counter() - started)


def measure(hostile) -> None:
    _environment_cases(hostile)
    _permission_cases(hostile)
    _package_lock(hostile)
    _late_signals(hostile)
    _signal_in_an_import(hostile)
    _orphan_rank(hostile)


def _environment_cases(hostile) -> None:
    folder = hostile.folder
    (folder / "latin1.toml").write_bytes(b'title = "x"\n\xff\xfe = 1\n')
    solve = ["solve", "-n", "2", "partial-closure", *SMALL]
    hostile.case(209, "scene file with the byte 0xff on line 2", "exit 1, 0.6 s: «ddsolve: error: bad.toml: cannot read "
                 "scene file (UnicodeDecodeError)»", ["solve", "-n", "2", "latin1.toml", "-o", "e.h5"], kept=("e",))
    hostile.case(209, "a 300-character output name (`-o aaa…a.h5`)", "exit 1, 0.2 s: 32-line traceback (OSError: [Errno "
                 "36] File name too long, from check_targets)", [*solve, "-o", "a" * 300 + ".h5"])
    hostile.case(209, "`MUMPS_OOC_TMPDIR` names a missing folder, `solver.out_of_core = true`", "exit 1, 4.3 s (after "
                 "meshing and assembly): «0 : PB in MUMPS_LOW_LEVEL_INIT_OOC_C» (5 lines, the last «ddsolve: error: "
                 "PETSc MatFactorFactorizeSchurComplement failed with error 81»)",
                 [*solve, "--set", "solver.out_of_core=true", "-o", "e.h5"],
                 env={**MPI_ENVIRONMENT, "MUMPS_OOC_TMPDIR": "no-such-folder"}, kept=("e",))
    hostile.case(209, "the same by a PETSc option, `reference ... -reference_mat_mumps_icntl_22 1`", "exit 1, 2.0 s: "
                 "«ddsolve: error: block reference: preonly solve did not converge (DIVERGED_PCSETUP_FAILED -11)»",
                 ["reference", "partial-closure", *SMALL, "-reference_mat_mumps_icntl_22", "1", "-o", "e.h5"],
                 env={"MUMPS_OOC_TMPDIR": "no-such-folder"}, kept=("e",))
    hostile.case(209, "`grow` with a misspelt PETSc option `-u_minus_ksp_typo cg`", "exit 0, 1.4 s, nothing said about "
                 "the option (solve names it)",
                 ["grow", "-n", "2", "partial-closure", *SMALL, "--set", "fracture.toughness=1e-6", "--to", "2",
                  "--steps", "2", "--pictures", "0", "-u_minus_ksp_typo", "cg", "-o", "g.h5"], env=MPI_ENVIRONMENT)


def _permission_cases(hostile) -> None:
    """As nobody: a result under a folder nobody can enter; an out-of-core folder nobody can write."""
    user = _nobody()
    shared = Path(tempfile.mkdtemp(prefix="ddsolve-env-"))
    try:
        shared.chmod(0o777)
        (shared / "locked" / "sub").mkdir(parents=True)
        (shared / "locked" / "sub" / "r.h5").write_bytes(b"previous r.h5")
        (shared / "locked").chmod(0o700)
        (shared / "factors").mkdir(mode=0o555)
        (shared / "factors").chmod(0o555)
        python = [*user, sys.executable, "-m", "ddsolve"]
        hostile.rows[209].append((
            "`plot locked/sub/r.h5`, `locked` of mode 700 (run as nobody)", "exit 1, 0.1 s: 30-line traceback "
            "(PermissionError: [Errno 13] Permission denied: 'locked/sub', from the journal recovery)",
            _timed(hostile, [*python, "plot", "locked/sub/r.h5"], shared, _environment(MPLCONFIGDIR=str(shared)))))
        hostile.rows[209].append((
            "`MUMPS_OOC_TMPDIR` a folder of mode 555, `solver.out_of_core = true` (run as nobody)", "exit 1: «0 : "
            "File creation failure: Permission denied» (MUMPS), then «ddsolve: error: PETSc "
            "MatFactorFactorizeSchurComplement failed with error 81»",
            _timed(hostile, [*python, "solve", "-n", "2", "partial-closure", *SMALL, "--set",
                             "solver.out_of_core=true", "-o", "o.h5"], shared,
                   _environment(MUMPS_OOC_TMPDIR="factors"))))
    finally:
        (shared / "locked").chmod(0o755)
        shutil.rmtree(shared, ignore_errors=True)


#: Holds an fcntl lock on a file (argv 1) for argv 2 seconds, as apt holds the package manager's.
HOLD = ("import fcntl, sys, time\nf = open(sys.argv[1], 'r+')\nfcntl.lockf(f, fcntl.LOCK_EX)\nprint('held', flush=True)\n"
        "time.sleep(float(sys.argv[2]))\n")


def _package_lock(hostile) -> None:
    """./run's first setup (every package missing, a stand-in apt-get) while another process holds the lock."""
    folder = hostile.folder / "first-run"
    (folder / "bin").mkdir(parents=True, exist_ok=True)
    for name in ("run", "pyproject.toml"):
        shutil.copy(ROOT / name, folder / name)
    for tool, body in (("dpkg-query", "exit 1"), ("apt-get", "exit 0")):
        (folder / "bin" / tool).write_text(f"#!/bin/sh\n{body}\n")
        (folder / "bin" / tool).chmod(0o755)
    (folder / "lock").write_text("")
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(folder / "lock"), "30"], stdout=subprocess.PIPE, text=True)
    try:
        holder.stdout.readline()
        env = {**os.environ, "PATH": f"{folder / 'bin'}:{os.environ['PATH']}", "DDSOLVE_PYTHON": "",
               "DDSOLVE_PACKAGE_LOCKS": "lock", "DDSOLVE_LOCK_WAIT": "3"}
        started = time.perf_counter()
        completed = subprocess.run(["bash", str(folder / "run"), "setup"], capture_output=True, text=True, env=env,
                                   cwd=folder, timeout=120, stdin=subprocess.DEVNULL)
    finally:
        holder.kill()
        holder.wait()
    said = [line for line in completed.stderr.splitlines() if not line.startswith("run: installing")]
    outcome = (f"exit {completed.returncode}, {time.perf_counter() - started:.1f} s: "
               + ", then ".join(f"«{line}»" for line in said))
    hostile.rows[209].append((
        "the first `./run` while another install holds the package manager's lock (DDSOLVE_LOCK_WAIT=3)",
        "exit 100, 0.6 s: «E: Could not get lock /var/lib/apt/lists/lock. It is held by process N (apt-get)» "
        "(2 lines: apt-get update failed at once)", outcome))


def _late_signals(hostile, count: int = 6) -> None:
    """SIGTERM to ``solve -n 2``'s launcher 0 to 50 ms after its mpiexec has ended: every set complete, status 0?"""
    outcomes = []
    for i in range(count):
        output = hostile.folder / "late.h5"
        output.write_bytes(b"previous")
        process = subprocess.Popen([sys.executable, "-m", "ddsolve", "solve", "-n", "2", "partial-closure", *SMALL, "-o",
                                    str(output)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                   env=_environment(), cwd=hostile.folder, stdin=subprocess.DEVNULL)
        for line in process.stdout:
            if line.startswith("reaction on layer2 at right"):  # the last line rank 0 prints
                break
        while _children(process.pid) and process.poll() is None:
            time.sleep(0.001)
        time.sleep(0.01 * i)
        process.send_signal(signal.SIGTERM)
        process.communicate(timeout=120)
        outcomes.append((process.returncode, output.read_bytes() != b"previous"))
    good = sum(new and status == 0 for status, new in outcomes)
    hostile.rows[210].append((
        f"SIGTERM to `solve -n 2`'s launcher 0 to {10 * (count - 1)} ms after its mpiexec has ended ({count} runs)",
        "7 of 7 runs: exit 143 (killed by SIGTERM) with the complete new set",
        f"{good} of {count} runs: exit 0 with the complete new set; others: "
        + (", ".join(f"exit {status} ({'new' if new else 'old'} set)" for status, new in outcomes
                     if not (new and status == 0)) or "none")))


def _children(pid: int) -> list[str]:
    try:
        return Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return []


IMPORTER = """
import sys, time
sys.path.insert(0, sys.argv[1])
from ddsolve.parallel.runtime import guarded

def call():
    import selfsignal
    print("imported", flush=True)
    time.sleep(5)
    return 0

sys.exit(guarded(call))
"""


def _signal_in_an_import(hostile) -> None:
    """A command whose import of a module gets SIGTERM half-way (the module signals itself)."""
    (hostile.folder / "selfsignal.py").write_text("import os, signal, time\ntime.sleep(0.05)\n"
                                                  "os.kill(os.getpid(), signal.SIGTERM)\ntime.sleep(0.05)\n")
    started = time.perf_counter()
    completed = subprocess.run([sys.executable, "-c", IMPORTER, str(hostile.folder)], capture_output=True, text=True,
                               env=_environment(), cwd=hostile.folder, timeout=60)
    outcome = hostile.outcome(completed, time.perf_counter() - started)
    hostile.rows[210].append((
        "SIGTERM during an import of a command (a module that signals itself while it is imported)",
        "the handler raised inside the import: cut short there (here: exit 143, «ddsolve: terminated»); where the "
        "import machinery swallows it, «Exception ignored in: <module 'collections.abc'>», a traceback ending "
        "«Terminated: SIGTERM», and the signal lost (issue 40)",
        outcome + ("; the import finished first" if "imported" in completed.stdout else "; the import was cut short")))


ORPHAN = """
import os, subprocess, sys
os.setsid()  # the stand-in for mpiexec leads a session, as under solve -n
child = subprocess.Popen([sys.executable, "-m", "ddsolve", "version"], stdout=open(sys.argv[1], "w"),
                         stderr=subprocess.STDOUT, env={**os.environ, "OMPI_COMM_WORLD_SIZE": "1", "DDSOLVE_LAUNCHED": "1"})
print(child.pid, flush=True)
os._exit(0)  # it ends before its rank has imported ddsolve
"""


def _orphan_rank(hostile) -> None:
    """A rank whose mpiexec has ended before the rank could look for it (a launcher killed at the start)."""
    log = hostile.folder / "orphan.txt"
    started = time.perf_counter()
    launcher = subprocess.run([sys.executable, "-c", ORPHAN, str(log)], capture_output=True, text=True,
                              env=_environment(), cwd=hostile.folder, timeout=60)
    rank = int(launcher.stdout)
    while os.path.exists(f"/proc/{rank}") and time.perf_counter() - started < 60:
        time.sleep(0.02)
    ran = "ddsolve 0.1" in log.read_text()
    hostile.rows[210].append((
        "a rank whose mpiexec ended before the rank had imported ddsolve (the launcher killed at its start)",
        "the rank ran its command to the end (`version` printed its line), reparented to init",
        f"the rank ended {time.perf_counter() - started:.1f} s after its start, "
        + ("after running its command" if ran else "without running its command")))
