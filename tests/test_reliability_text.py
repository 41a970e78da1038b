"""Issue 21, class 3 (text that is not plain UTF-8 on the way out) and the text and command-line parts of
class 8: output in any encoding, standard output that cannot be written, plot titles that are not plain
text, `mesh -o` with a suffix it cannot write, `compare` of results on different domains, `-n` given twice.
Every refusal is one line naming what to change, with its exit status, no traceback, within a timeout."""
from __future__ import annotations

import codecs
import dataclasses
import hashlib
import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import h5py
import pytest
from conftest import SMALL, solved_reference, without_open_mpi_noise
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ddsolve.errors import DDSolveError
from ddsolve.io import hdf5
from ddsolve.parallel import runtime
from ddsolve.post import plots
from ddsolve.problem import scene

#: Standard outputs that are not UTF-8: Python's own setting, and a C locale without UTF-8 mode.
ENCODINGS = {"ascii": {"PYTHONIOENCODING": "ascii"}, "latin-1": {"PYTHONIOENCODING": "latin-1"},
             "C locale": {"LANG": "C", "LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONIOENCODING": ""}}


def run(*args: str, env: dict | None = None, stdout=subprocess.PIPE, cwd: Path | None = None,
        timeout: float = 120) -> subprocess.CompletedProcess:
    """``python -m ddsolve ARGS`` with ``env`` added to the environment, output as bytes (decoded by the
    test in the encoding it expects); ``stdout`` may be a file or a pipe."""
    completed = subprocess.run([sys.executable, "-m", "ddsolve", *args], stdout=stdout, stderr=subprocess.PIPE,
                               timeout=timeout, stdin=subprocess.DEVNULL, cwd=cwd,
                               env={**os.environ, "MPLBACKEND": "Agg", **(env or {})})
    completed.stderr = completed.stderr.decode("latin-1")
    return without_open_mpi_noise(completed)


def one_line(completed: subprocess.CompletedProcess, status: int, *fragments: str) -> str:
    """Failed with ``status`` and one line on standard error holding every fragment, no traceback."""
    assert completed.returncode == status, (completed.returncode, completed.stderr)
    assert "Traceback" not in completed.stderr
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ddsolve: error: "), completed.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def clean(completed: subprocess.CompletedProcess) -> None:
    assert completed.returncode == 0, completed.stderr
    assert completed.stderr.strip() == "", completed.stderr


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A result of the small partial-closure mesh (base.h5), and one of a wider box (wide.h5)."""
    path = tmp_path_factory.mktemp("text")
    solved_reference("partial-closure", *SMALL, "-o", str(path / "base.h5"))
    solved_reference("partial-closure", *SMALL, "--set", "geometry.box=[-1.0, 1.2, -1.0, 1.0]",
                     "-o", str(path / "wide.h5"))
    return path


def titled(folder: Path, name: str, title: str) -> Path:
    """A copy of base.h5 whose scene has ``title``."""
    path = folder / f"{name}.h5"
    path.write_bytes((folder / "base.h5").read_bytes())
    with h5py.File(path, "r+") as f:
        text = f.attrs["scene"]
        f.attrs["scene"] = re.sub(r"^title = .*$", lambda _: "title = " + json.dumps(title, ensure_ascii=False),
                                  text, count=1, flags=re.M)
    assert hdf5.read(path).scene.title == title
    return path


# --- class 3: output that is not UTF-8 --------------------------------------------------------------
@pytest.mark.mpi
@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("command, spelt, in_latin1", [
    (["reference", "partial-closure", *SMALL, "-o", "r.h5"], "theta radii", "theta radii"),  # G at the tips
    (["mesh", "partial-closure", *SMALL], "Sigma vertices 13", "Sigma vertices 13"),
    (["plot", "base.h5"], "(displacements x", "(displacements ×"),  # latin-1 has ×
])
def test_output_in_any_encoding_spells_greek_in_ascii(folder, encoding, command, spelt, in_latin1):
    completed = run(*command, env=ENCODINGS[encoding], cwd=folder)
    clean(completed)
    if encoding == "latin-1":
        assert in_latin1 in completed.stdout.decode("latin-1")
    else:
        assert spelt in completed.stdout.decode("ascii")


@pytest.mark.mpi
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_an_error_with_greek_letters_is_spelt_in_ascii(tmp_path, encoding):
    completed = run("solve", "partial-closure", *SMALL, "--set", "geometry.crack=[-1, 0.5]", env=ENCODINGS[encoding],
                    cwd=tmp_path)
    one_line(completed, 1, "clamped boundary", "Gamma_D")


@pytest.mark.mpi
def test_every_rank_writes_in_ascii(tmp_path):
    completed = run("solve", "-n", "2", "partial-closure", *SMALL, "-o", "e.h5", env=ENCODINGS["C locale"],
                    cwd=tmp_path)
    clean(completed)
    assert "theta radii" in completed.stdout.decode("ascii")


@pytest.mark.mpi
@pytest.mark.parametrize("title", [r"$\frac{$", r"$\foo$", "$$", r"cost $5 and $6", "a\fb\tc\nd", "漢字 🎉",
                                   "long title " * 9310])
def test_plot_draws_any_title_as_plain_text(folder, title):
    path = titled(folder, "title-" + hashlib.sha1(title.encode()).hexdigest()[:8], title)
    clean(run("plot", path.name, cwd=folder))
    for name in ("deformed", "crack-faces", "convergence"):
        assert (folder / f"{path.stem}-{name}.png").stat().st_size > 1000


@pytest.mark.mpi
def test_a_long_title_is_shortened_with_an_ellipsis(folder):
    result = hdf5.read(titled(folder, "long", "x" * 100_000))
    shown = plots.drawn_title(result)
    assert len(shown) == plots.TITLE_LENGTH and shown.endswith("…")


@pytest.mark.mpi
@pytest.mark.parametrize("output", ["out.txt", "out", "out.h5", "out.vtu", "out.MSH", ".msh"])
def test_mesh_names_the_format_it_writes(tmp_path, output):
    (tmp_path / output).write_bytes(b"previous")
    one_line(run("mesh", "partial-closure", *SMALL, "-o", output, cwd=tmp_path, timeout=60), 1,
             f"-o {output}", "gmsh MSH 4.1", "suffix .msh")
    assert (tmp_path / output).read_bytes() == b"previous"


@pytest.mark.mpi
def test_mesh_writes_msh(tmp_path):
    clean(run("mesh", "partial-closure", *SMALL, "-o", "halves.msh", cwd=tmp_path, timeout=60))
    assert (tmp_path / "halves.msh").read_bytes().startswith(b"$MeshFormat\n4.1")


# --- class 8: standard output that cannot be written ------------------------------------------------------
COMMANDS = [["check", "base.h5"], ["compare", "base.h5", "base.h5"], ["scenes"], ["solve", "--help"],
            ["mesh", "partial-closure", *SMALL], ["reference", "partial-closure", *SMALL, "-o", "full.h5"],
            ["export", "base.h5", "-o", "exported"], ["version"]]


@pytest.mark.mpi
@pytest.mark.parametrize("buffered", [True, False], ids=["buffered", "unbuffered"])
@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0] + ("-help" if "--help" in c else ""))
def test_a_full_disk_on_standard_output_is_one_line(folder, command, buffered):
    (folder / "exported").mkdir(exist_ok=True)
    with open("/dev/full", "wb") as full:
        completed = run(*command, env={"PYTHONUNBUFFERED": "" if buffered else "1"}, stdout=full, cwd=folder)
    one_line(completed, 1, "cannot write to standard output: No space left on device")


@pytest.mark.mpi
@pytest.mark.parametrize("command", [["scenes"], ["reference", "partial-closure", *SMALL, "-o", "piped.h5"]],
                         ids=lambda c: c[0])
def test_a_closed_pipe_on_standard_output_is_one_line(folder, command):
    """The reader is gone before anything is written (as `| head -c1` once it has its byte)."""
    reader, writer = os.pipe()
    os.close(reader)
    try:
        completed = run(*command, env={"PYTHONUNBUFFERED": "1"}, stdout=writer, cwd=folder)
    finally:
        os.close(writer)
    one_line(completed, 1, "cannot write to standard output: Broken pipe")


# --- class 8: compare on different domains, -n twice --------------------------------------------------------
@pytest.mark.mpi
@pytest.mark.parametrize("order", [("base.h5", "wide.h5"), ("wide.h5", "base.h5")])
def test_compare_of_different_domains_names_both_files(folder, order):
    line = one_line(run("compare", *order, cwd=folder), 1, "different domains", *order, "geometry.box")
    assert "points lie outside" not in line


@pytest.mark.mpi
def test_compare_of_a_curved_bond_line_at_two_mesh_sizes(tmp_path):
    """The fine mesh's Σ nodes lie just outside the coarse mesh's chords: the same domain."""
    for name, size in (("coarse", "0.25"), ("fine", "0.125")):
        solved_reference("arc-bond", "--set", f"mesh.size={size}", "-o", str(tmp_path / f"{name}.h5"))
    for order in (("coarse.h5", "fine.h5"), ("fine.h5", "coarse.h5")):
        completed = run("compare", *order, cwd=tmp_path)
        clean(completed)
        assert float(completed.stdout.split()[3]) < 0.5


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [["-n", "4", "-n", "8"], ["-n4", "-n", "8"], ["-n", "2", "-n2"]])
@pytest.mark.parametrize("command", ["solve", "sweep"])
def test_ranks_given_twice_is_a_usage_error_before_mpiexec(tmp_path, command, ranks):
    completed = run(command, *ranks, "partial-closure", *SMALL, cwd=tmp_path, timeout=30)
    one_line(completed, 2, "-n given 2 times", "give the number of ranks once")
    assert list(tmp_path.iterdir()) == []


# --- fuzz: the generators that would have found these -----------------------------------------------------
@settings(max_examples=300, deadline=None)
@given(text=st.text(), encoding=st.sampled_from(["ascii", "latin-1", "cp1252", "iso8859-7", "utf-8", "koi8-r"]))
def test_fuzz_any_text_in_any_encoding(text, encoding):
    """Whatever a message holds (Greek, symbols, a user's title with lone surrogates), every output encoding
    takes it: the error handler of standard output and error never fails, and spells in ASCII."""
    codecs.register_error("ddsolve", runtime.spelled_in_ascii)  # as every command does (runtime.prepare_output)
    encoded = text.encode(encoding, "ddsolve")
    encoded.decode(encoding)
    if encoding == "ascii":
        assert encoded.isascii()


@pytest.mark.mpi
@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                 HealthCheck.too_slow])
@given(title=st.one_of(
    st.text(alphabet=st.sampled_from("$\\{}^_ax frac \n\t\f"), max_size=40),
    st.text(max_size=40),
    st.builds(lambda piece, count: piece * count, st.text(min_size=1, max_size=5), st.integers(100, 20_000))))
def test_fuzz_titles_plot_without_error(folder, title):
    """Random titles -- math text, control characters, any Unicode, very long -- draw without an error or
    a warning (in-process: the pictures of ``plot``)."""
    result = hdf5.read(folder / "base.h5")
    text = re.sub(r"^title = .*$", lambda _: "title = " + json.dumps(title, ensure_ascii=False), result.scene.text,
                  count=1, flags=re.M)
    try:
        result = dataclasses.replace(result, scene=scene.loads(text))
    except DDSolveError:  # a title the scene refuses (a lone surrogate, NUL): not a plotting matter
        return
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plots.crack_faces(result, folder / "fuzz-crack-faces.png")
        plots.deformed_layers(result, folder / "fuzz-deformed.png")


@pytest.mark.mpi
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(encoding=st.sampled_from(sorted(ENCODINGS)), command=st.sampled_from(COMMANDS[:5]),
       output=st.sampled_from(["file", "full", "closed"]), buffered=st.booleans())
def test_fuzz_commands_on_unusual_standard_outputs(folder, tmp_path, encoding, command, output, buffered):
    """Any command, any output encoding, standard output a file, a full disk or a closed pipe: exit 0 with
    every line written, or one line naming standard output."""
    (folder / "exported").mkdir(exist_ok=True)
    env = {**ENCODINGS[encoding], "PYTHONUNBUFFERED": "" if buffered else "1"}
    if output == "closed":
        reader, writer = os.pipe()
        os.close(reader)
        try:
            completed = run(*command, env=env, stdout=writer, cwd=folder)
        finally:
            os.close(writer)
    else:
        with open("/dev/full" if output == "full" else tmp_path / "out.txt", "wb") as stream:
            completed = run(*command, env=env, stdout=stream, cwd=folder)
    if output == "file":
        clean(completed)
        (tmp_path / "out.txt").read_bytes().decode("latin-1" if encoding == "latin-1" else "ascii")
    else:
        one_line(completed, 1, "cannot write to standard output")
