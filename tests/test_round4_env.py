"""Issue 40, classes 9 and 10: failures the environment causes, named in one line (an out-of-core folder
that cannot be written, a scene that is not UTF-8, an output name too long for its folder, PETSc options
nothing read, a result under a folder the user cannot enter, the package manager's lock held by another
install), and signals at the edges of a run (after its commit, during an import, before the rank has
found its launcher)."""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import pytest
from conftest import SMALL, refused, without_open_mpi_noise
from hypothesis import given, settings
from hypothesis import strategies as st

from ddsolve.errors import DDSolveError, SceneError
from ddsolve.io import safe
from ddsolve.parallel import runtime
from ddsolve.problem import scene as scenes

ROOT = Path(__file__).resolve().parents[1]
FEW = settings(derandomize=True, max_examples=4, deadline=None)
MANY = settings(derandomize=True, max_examples=40, deadline=None)


def run(*arguments: str, cwd: Path, env: dict | None = None, user: list[str] = (),
        timeout: float = 300) -> subprocess.CompletedProcess:
    """``python -m ddsolve ARGUMENTS`` in ``cwd`` (as ``user``: a setpriv prefix), Open MPI allowed as root."""
    environment = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                   "OMPI_MCA_rmaps_base_oversubscribe": "1", "MPLBACKEND": "Agg", "MPLCONFIGDIR": str(cwd),
                   "PYTHONPATH": str(ROOT), **(env or {})}
    return without_open_mpi_noise(subprocess.run([*user, sys.executable, "-m", "ddsolve", *arguments],
                                                 capture_output=True, text=True, cwd=cwd, env=environment,
                                                 stdin=subprocess.DEVNULL, timeout=timeout))


def as_nobody() -> list[str]:
    """How to run a command so that permissions stop it (as root: as nobody)."""
    if os.geteuid() != 0:
        return []
    if shutil.which("setpriv") is None:
        pytest.skip("root without setpriv: permissions do not stop root")
    return ["setpriv", "--reuid=nobody", "--regid=nogroup", "--clear-groups"]


@contextlib.contextmanager
def shared_folder():
    """A scratch folder that every user can enter and write (pytest's are private), removed afterwards."""
    folder = Path(tempfile.mkdtemp(prefix="ddsolve-env-"))
    folder.chmod(0o777)
    try:
        yield folder
    finally:
        for path in folder.rglob("*"):
            if path.is_dir():
                path.chmod(0o755)
        shutil.rmtree(folder, ignore_errors=True)


# --- class 9: the environment, named ------------------------------------------------------------------
@MANY
@given(st.lists(st.text(st.characters(blacklist_categories=("Cs",)), max_size=12), min_size=1, max_size=5),
       st.data(), st.sampled_from([b"\xff", b"\xc3", b"\xe2\x82", b"\x80", b"\xed\xa0\x80"]),
       st.booleans())
def test_bytes_that_are_not_utf8_are_named_by_line_column_and_offset(tmp_path_factory, lines, data, bad, bom):
    text = "\n".join(lines).encode()
    at = data.draw(st.integers(0, len(text)))
    while at > 0 and (text[at - 1] & 0xC0 == 0x80 or text[at - 1] >= 0xC0):  # not inside a character
        at -= 1
    prefix = b"\xef\xbb\xbf" if bom else b""
    path = tmp_path_factory.mktemp("utf8") / "s.toml"
    path.write_bytes(prefix + text[:at] + bad + b"x" + text[at:])
    offset = len(prefix) + at
    with pytest.raises(SceneError) as caught:
        scenes.utf8_text(path, "scene file", SceneError)
    message = str(caught.value)
    line = text[:at].count(b"\n") + 1
    column = offset - (prefix + text[:at]).rfind(b"\n")
    assert f"byte 0x{bad[0]:02x} at line {line}, column {column} (byte offset {offset})" in message, message
    assert message.startswith(f"{path}: scene file is not UTF-8 text")


def test_a_scene_with_a_byte_order_mark_is_read_without_it(tmp_path):
    path = tmp_path / "s.toml"
    path.write_bytes(b"\xef\xbb\xbftitle = \"\xc3\xa9\"\n")
    assert scenes.utf8_text(path, "scene file") == 'title = "é"\n'


@pytest.mark.mpi
def test_a_scene_that_is_not_utf8_is_one_line_naming_where(tmp_path):
    (tmp_path / "bad.toml").write_bytes(b'title = "x"\n\xff\xfe = 1\n')
    refused(run("solve", "-n", "2", "bad.toml", "-o", "b.h5", cwd=tmp_path), 1,
            "bad.toml: scene file is not UTF-8 text: byte 0xff at line 2, column 1 (byte offset 12)")


@MANY
@given(st.integers(1, 320), st.sampled_from(["a", "é", "Σ"]), st.sampled_from([".h5", ".png", ""]))
def test_an_output_name_is_written_or_refused_as_too_long_never_an_os_error(tmp_path_factory, length, char, suffix):
    folder = tmp_path_factory.mktemp("names")
    path = folder / (char * length + suffix)
    limit = os.pathconf(folder, "PC_NAME_MAX")
    try:
        safe.check_targets([path])
    except DDSolveError as exc:
        assert "file name too long" in str(exc) and "choose a shorter name" in str(exc), exc
        return
    safe.atomic(path, lambda name: Path(name).write_bytes(b"x"))  # what check_targets let through is written
    assert path.read_bytes() == b"x" and len(os.fsencode(path.name)) <= limit
    assert [p.name for p in folder.iterdir()] == [path.name]


@pytest.mark.mpi
def test_a_300_character_output_name_is_one_line(tmp_path):
    name = "a" * 300 + ".h5"
    line = refused(run("solve", "-n", "2", "partial-closure", *SMALL, "-o", name, cwd=tmp_path), 1,
                   "file name too long (303 bytes", "choose a shorter name")
    assert len(line) < 300 and list(tmp_path.iterdir()) == []


@pytest.mark.mpi
@FEW
@given(st.sampled_from([0o000, 0o100, 0o300, 0o600, 0o644, 0o700]), st.sampled_from(["plot", "check", "export"]))
def test_a_result_under_a_folder_nobody_can_enter_is_one_line(mode, command):
    user = as_nobody()
    with shared_folder() as folder:
        (folder / "locked" / "sub").mkdir(parents=True)
        (folder / "locked" / "sub" / "r.h5").write_bytes(b"previous r.h5")
        (folder / "locked").chmod(mode)
        completed = run(command, "locked/sub/r.h5", cwd=folder, user=user)
    refused(completed, 1, "locked/sub/r.h5: cannot read result file (permission denied)")


def test_recovery_of_a_folder_that_cannot_be_examined_finds_nothing_to_finish(tmp_path, monkeypatch):
    def denied(self, pattern):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "glob", denied)
    safe.recover([tmp_path / "a" / "r.h5"])
    assert safe.remove_stale(tmp_path / "a" / "r.h5") == []


@MANY
@given(st.lists(st.sampled_from(["-u_minus_mat_mumps_icntl_22", "-reference_mat_mumps_icntl_22", "-log_view",
                                 "-u_plus_ksp_type", "1", "0", "cg", "-1", "2.5"]), max_size=6), st.booleans())
def test_out_of_core_is_asked_by_the_scene_or_a_nonzero_icntl_22(words, scene_asks):
    asked = []
    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(runtime, "check_out_of_core_folder", asked.append)
        monkeypatch.delenv("PETSC_OPTIONS", raising=False)
        runtime.check_out_of_core(scene_asks, words)
    options = runtime.petsc_options_given(words)
    by_option = any(name.endswith("mat_mumps_icntl_22") and value not in ("0", "") for name, value in options.items())
    assert bool(asked) == (scene_asks or by_option), (words, options, asked)


@pytest.mark.parametrize("folder, reason", [("missing", "no such folder"), ("file", "not a folder")])
def test_a_missing_out_of_core_folder_is_named_with_its_variable(tmp_path, monkeypatch, folder, reason):
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("MUMPS_OOC_TMPDIR", str(tmp_path / folder))
    with pytest.raises(DDSolveError, match=rf"^MUMPS_OOC_TMPDIR={tmp_path / folder}: cannot hold MUMPS's out-of-core "
                                           rf"factors \({reason}\), which solver.out_of_core = true asks for"):
        runtime.check_out_of_core(True)
    monkeypatch.setenv("MUMPS_OOC_TMPDIR", str(tmp_path))
    runtime.check_out_of_core(True)


@pytest.mark.mpi
@pytest.mark.parametrize("arguments", [
    ["solve", "-n", "2", "partial-closure", *SMALL, "--set", "solver.out_of_core=true", "-o", "o.h5"],
    ["reference", "partial-closure", *SMALL, "-reference_mat_mumps_icntl_22", "1", "-o", "o.h5"],
], ids=["solve", "reference"])
def test_an_out_of_core_folder_nobody_can_write_is_refused_before_work(arguments):
    user = as_nobody()
    with shared_folder() as folder:
        (folder / "factors").mkdir()
        (folder / "factors").chmod(0o555)
        completed = run(*arguments, cwd=folder, user=user, env={"MUMPS_OOC_TMPDIR": str(folder / "factors")})
        written = (folder / "o.h5").exists()
    refused(completed, 1, f"MUMPS_OOC_TMPDIR={folder / 'factors'}: cannot hold MUMPS's out-of-core factors "
                          "(permission denied)")
    assert not written


@pytest.mark.mpi
@pytest.mark.parametrize("command", ["solve", "sweep", "grow", "reference"])
def test_every_command_with_petsc_options_names_those_nothing_read(tmp_path, command):
    folder = tmp_path
    extra = {"solve": ["-n", "2"], "reference": [],
             "sweep": ["-n", "2", "--set", "loads.layer1.top.y=0.05:0.1:2"],
             "grow": ["-n", "2", "--set", "fracture.toughness=1e-6", "--to", "2", "--steps", "1", "--pictures", "0"]}
    typo = "-reference_ksp_typo" if command == "reference" else "-u_minus_ksp_typo"
    completed = run(command, "partial-closure", *SMALL, *extra[command], typo, "cg", "-o", "o.h5", cwd=folder)
    assert completed.returncode == 0, completed.stderr
    warnings = [line for line in completed.stderr.splitlines() if line.startswith("ddsolve: warning: PETSc options")]
    assert len(warnings) == 1 and warnings[0].endswith(f"{typo} cg"), completed.stderr


def _fake_setup(folder: Path, wait: int) -> dict:
    """A copy of ``run`` whose setup finds every package missing and whose apt-get notes its call and fails;
    the package manager's lock is the file ``lock``, waited for at most ``wait`` s."""
    shutil.copy(ROOT / "run", folder / "run")
    shutil.copy(ROOT / "pyproject.toml", folder / "pyproject.toml")
    (folder / "bin").mkdir()
    (folder / "bin" / "dpkg-query").write_text("#!/bin/sh\nexit 1\n")
    (folder / "bin" / "apt-get").write_text(f'#!/bin/sh\necho "$*" >> {folder / "apt.log"}\nexit 100\n')
    for tool in ("dpkg-query", "apt-get"):
        (folder / "bin" / tool).chmod(0o755)
    (folder / "lock").write_text("")
    return {**os.environ, "PATH": f"{folder / 'bin'}:{os.environ['PATH']}", "DDSOLVE_PACKAGE_LOCKS": str(folder / "lock"),
            "DDSOLVE_PYTHON": "", "DDSOLVE_LOCK_WAIT": str(wait)}


#: Holds an fcntl lock on a file (argv 1), as apt holds the package manager's, until it is killed.
HOLD = "import fcntl, sys, time\nf = open(sys.argv[1], 'r+')\nfcntl.lockf(f, fcntl.LOCK_EX)\nprint('held', flush=True)\n" \
       "time.sleep(3600)\n"


@pytest.mark.mpi
@pytest.mark.parametrize("released", [True, False], ids=["released", "held"])
def test_the_first_run_waits_for_the_package_managers_lock_then_fails_in_one_line(tmp_path, released):
    env = _fake_setup(tmp_path, wait=120 if released else 2)
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(tmp_path / "lock")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        setup = subprocess.Popen(["bash", str(tmp_path / "run"), "setup"], stderr=subprocess.PIPE, text=True, env=env,
                                 stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
        lines = [setup.stderr.readline().strip() for _ in range(2)]  # what it installs; that it waits
        assert "is held by process" in lines[1] and "waiting for it to finish" in lines[1], lines
        if released:  # the other install ends
            holder.kill()
        _, rest = setup.communicate(timeout=120)
    finally:
        holder.kill()
        holder.wait()
    lines += [line for line in rest.splitlines() if line.startswith("run:")]
    assert setup.returncode == 1 and "Traceback" not in rest
    if released:  # apt-get ran once the lock was free (this stand-in fails, in one line)
        assert (tmp_path / "apt.log").read_text().startswith("-o DPkg::Lock::Timeout=120 update")
        assert lines[2:] == ["run: apt-get update failed (its message is above)"], lines
    else:
        assert len(lines) == 3 and "after 2 s: run ./run again once that install has finished" in lines[2], lines
        assert not (tmp_path / "apt.log").exists()  # apt-get never ran into the lock


# --- class 10: signals at the edges of a run ----------------------------------------------------------
def _children(pid: int) -> list[str]:
    try:
        return Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return []


def _interrupted_after_the_end(folder: Path, delay: float) -> tuple[int, bool, str]:
    """SIGTERM to ``solve -n 2``'s launcher ``delay`` s after its mpiexec has ended (as it exits): (status,
    new set?, stderr)."""
    output = folder / "w.h5"
    output.write_bytes(b"previous")
    environment = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
                   "OMPI_MCA_rmaps_base_oversubscribe": "1", "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen([sys.executable, "-m", "ddsolve", "solve", "-n", "2", "partial-closure", *SMALL, "-o",
                                str(output)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env=environment, stdin=subprocess.DEVNULL, cwd=folder)
    for line in process.stdout:
        if line.startswith("reaction on layer2 at right"):  # the last line rank 0 prints
            break
    while _children(process.pid) and process.poll() is None:  # mpiexec still runs
        time.sleep(0.001)
    time.sleep(delay)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=120)
    return process.returncode, output.read_bytes() != b"previous", err


@pytest.mark.mpi
@FEW
@given(st.floats(0.0, 0.1))
def test_a_signal_after_the_commit_ends_the_launcher_with_0(tmp_path_factory, delay):
    status, new, err = _interrupted_after_the_end(tmp_path_factory.mktemp("late"), delay)
    assert new and status == 0, (delay, status, err)
    assert "Traceback" not in err


SELF_TERMINATING = """
import os, signal, time
for _ in range({before}):
    time.sleep(0.002)
os.kill(os.getpid(), signal.{name})
for _ in range({after}):
    time.sleep(0.002)
DONE = True
"""

IMPORTER = """
import sys, time
sys.path.insert(0, sys.argv[1])
from ddsolve.parallel.runtime import guarded

def call():
    import selfsignal
    print("imported", selfsignal.DONE, flush=True)
    time.sleep(5)
    return 0

sys.exit(guarded(call))
"""


@pytest.mark.mpi
@FEW
@given(st.integers(0, 20), st.integers(0, 20), st.sampled_from(["SIGTERM", "SIGINT"]))
def test_a_signal_during_an_import_is_raised_once_the_import_is_over(tmp_path_factory, before, after, name):
    folder = tmp_path_factory.mktemp("import")
    (folder / "selfsignal.py").write_text(SELF_TERMINATING.format(before=before, after=after, name=name))
    completed = subprocess.run([sys.executable, "-c", IMPORTER, str(folder)], capture_output=True, text=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60, cwd=folder)
    assert completed.stdout == "imported True\n"  # the import finished; the signal came after it
    assert completed.returncode == (143 if name == "SIGTERM" else 130), completed.stderr
    assert completed.stderr == ("ddsolve: terminated\n" if name == "SIGTERM" else "ddsolve: interrupted\n")


@pytest.mark.mpi
@FEW
@given(st.floats(0.0, 0.3))
def test_a_signal_while_a_command_starts_ends_it_with_its_status_and_no_traceback(tmp_path_factory, delay):
    folder = tmp_path_factory.mktemp("start")
    process = subprocess.Popen([sys.executable, "-m", "ddsolve", "solve", "partial-closure", *SMALL, "-o", "s.h5"],
                               cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONPATH": str(ROOT)}, stdin=subprocess.DEVNULL)
    time.sleep(delay)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=60)
    assert process.returncode in (143, -signal.SIGTERM), (process.returncode, err)
    assert "Traceback" not in err and "ignored" not in err, err
    assert err in ("", "ddsolve: terminated\n"), err
    assert list(folder.iterdir()) == []


ORPHAN = textwrap.dedent("""
    import os, subprocess, sys
    os.setsid()  # the stand-in for mpiexec leads a session, as under solve -n
    child = subprocess.Popen([sys.executable, "-m", "ddsolve", "version"], stdout=open(sys.argv[1], "w"),
                             stderr=subprocess.STDOUT, env={**os.environ, "OMPI_COMM_WORLD_SIZE": "1",
                                                            "DDSOLVE_LAUNCHED": "1"})
    print(child.pid, flush=True)
    os._exit(0)  # it ends before its rank has imported ddsolve
""")


@pytest.mark.mpi
def test_a_rank_whose_launcher_ended_before_it_started_ends_at_once(tmp_path):
    launcher = subprocess.run([sys.executable, "-c", ORPHAN, str(tmp_path / "rank.txt")], capture_output=True, text=True,
                              env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=60, cwd=tmp_path)
    rank = int(launcher.stdout)
    deadline = time.monotonic() + 30
    while os.path.exists(f"/proc/{rank}") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not os.path.exists(f"/proc/{rank}"), "the rank outlived its launcher"
    assert "ddsolve 0.1" not in (tmp_path / "rank.txt").read_text()  # it ended before running its command
