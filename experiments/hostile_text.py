"""Issue 21, class 3 (text that is not plain UTF-8 on the way out) and the output and message cases of
class 8 (standard output that cannot be written, compare across domains, -n twice), before and after,
for docs/robustness.md.  *Before* was measured once on the code before the fixes (quoted here)."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

from experiments import ROOT
from experiments.robustness import SMALL

TEXT, MESSAGES = 103, 108
#: Standard outputs that are not UTF-8: Python's setting, and a C locale without Python's UTF-8 mode.
ASCII = {"PYTHONIOENCODING": "ascii"}
LATIN1 = {"PYTHONIOENCODING": "latin-1"}
C_LOCALE = {"LANG": "C", "LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONIOENCODING": ""}
BUFFERED, UNBUFFERED = {"PYTHONUNBUFFERED": ""}, {"PYTHONUNBUFFERED": "1"}


def measure(hostile) -> None:
    for name, overrides in (("text-base", []), ("text-wide", ["--set", "geometry.box=[-1.0, 1.2, -1.0, 1.0]"]),
                            ("text-arc-coarse", None), ("text-arc-fine", None)):
        arguments = (["arc-bond", "--set", f"mesh.size={0.2 if 'coarse' in name else 0.1}"] if overrides is None
                     else ["partial-closure", *SMALL, *overrides])
        completed, _ = hostile.run(["reference", *arguments, "-o", f"{name}.h5"])
        if completed.returncode != 0:
            raise RuntimeError(completed.stderr)
    _encodings(hostile)
    _titles(hostile)
    _mesh_outputs(hostile)
    _standard_output(hostile)
    _messages(hostile)


def _stdout_line(*words: str):
    """A note: the first line of standard output holding one of ``words`` (as the encoding spelt it)."""
    def observe(completed: subprocess.CompletedProcess) -> str:
        line = next((line for line in completed.stdout.splitlines() if any(word in line for word in words)), None)
        return "" if line is None else f"; prints «{line[:70]}{'…' if len(line) > 70 else ''}»"
    return observe


def _encodings(hostile) -> None:
    traceback = ("exit 1 after the result was written: 15-line traceback (UnicodeEncodeError: {} codec can't "
                 "encode 'θ')")
    for label, env, codec in (("PYTHONIOENCODING=ascii", ASCII, "'ascii'"),
                              ("PYTHONIOENCODING=latin-1", LATIN1, "'latin-1'"),
                              ("LANG=C LC_ALL=C PYTHONUTF8=0", C_LOCALE, "'ascii'")):
        hostile.case(TEXT, f"`{label}`, solve on 2 ranks", traceback.format(codec),
                     ["solve", "-n", "2", "partial-closure", *SMALL, "-o", "text-enc.h5"], env=env,
                     observe=_stdout_line("theta"))
    hostile.case(TEXT, "`PYTHONIOENCODING=ascii`, reference", traceback.format("'ascii'"),
                 ["reference", "partial-closure", *SMALL, "-o", "text-enc.h5"], env=ASCII,
                 observe=_stdout_line("theta"))
    for label, env in (("PYTHONIOENCODING=latin-1", LATIN1), ("LANG=C LC_ALL=C PYTHONUTF8=0", C_LOCALE)):
        hostile.case(TEXT, f"`{label}`, mesh", "exit 1: 13-line traceback (UnicodeEncodeError: can't encode 'Σ')",
                     ["mesh", "partial-closure", *SMALL], env=env, observe=_stdout_line("Sigma"))
    hostile.case(TEXT, "`LANG=C LC_ALL=C PYTHONUTF8=0`, plot", "exit 1 after the pictures were made: 13-line traceback "
                 "(UnicodeEncodeError: can't encode '×')", ["plot", "text-base.h5"], env=C_LOCALE,
                 observe=_stdout_line("wrote"))
    hostile.case(TEXT, "`PYTHONIOENCODING=ascii`, an error naming Γ_D", "exit 1, «ddsolve: error: generated mesh: a "
                 "crack reaches the clamped boundary at (-1, 0); the crack must stay off \\u0393_D»",
                 ["solve", "partial-closure", *SMALL, "--set", "geometry.crack=[-1, 0.5]", "-o", "text-enc.h5"],
                 env=ASCII)


def _titled(hostile, name: str, title: str) -> str:
    """A copy of text-base.h5 whose scene has ``title`` (as `--set title=...` would give it)."""
    import h5py

    path = hostile.folder / f"{name}.h5"
    path.write_bytes((hostile.folder / "text-base.h5").read_bytes())
    with h5py.File(path, "r+") as f:
        f.attrs["scene"] = re.sub(r"^title = .*$", lambda _: "title = " + json.dumps(title, ensure_ascii=False),
                                  f.attrs["scene"], count=1, flags=re.M)
    return path.name


def _titles(hostile) -> None:
    def drawn(completed: subprocess.CompletedProcess) -> str:
        return "; 3 pictures" if completed.returncode == 0 else ""
    for number, (label, title, before) in enumerate((
            ("title `$\\frac{$`", "$\\frac{$", "exit 1: 72-line traceback (ValueError: Expected \\frac{num}{den}, "
             "from matplotlib's math text)"),
            ("title `$\\foo$` (an unknown command)", "$\\foo$", "exit 1: 68-line traceback (ValueError: Unknown "
             "symbol: \\foo)"),
            ("title `$$`", "$$", "exit 1: 68-line traceback (ValueError: Expected end of text, found '$')"),
            ("title `cost $5 and $6`", "cost $5 and $6", "exit 0, «5 and » drawn as math (italic, spaces dropped)"),
            ("`--set 'title=\"$\\frac{\"'` (TOML reads \\f as a form feed)", "$\frac{", "exit 0, 4 lines of "
             "UserWarning (Glyph 12 missing from current font)"),
            ("title of 100 kB", "long title " * 9310, "exit 1 after 4.4 s: 50-line traceback (RuntimeError: In "
             "draw_glyphs_to_bitmap: raster overflow)"),
            ("title `漢字 🎉` (glyphs the font lacks)", "漢字 🎉", "exit 0, 12 lines of UserWarning (Glyph ... "
             "missing from current font)"))):
        name = _titled(hostile, f"text-title-{number}", title)
        hostile.case(TEXT, f"plot, {label}", before, ["plot", name], observe=drawn)


def _mesh_outputs(hostile) -> None:
    for output in ("out.txt", "out", "out.h5"):
        def untouched(completed: subprocess.CompletedProcess, output=output) -> str:
            return "" if (hostile.folder / output).exists() else f"; no {output} written"
        hostile.case(TEXT, f"mesh -o {output}", "exit 1: 24-line traceback (gmsh's Exception: Unknown output file "
                     "format)", ["mesh", "partial-closure", *SMALL, "-o", output], observe=untouched)


def _redirected(hostile, arguments: list[str], env: dict, closed_pipe: bool) -> str:
    """ddsolve ARGUMENTS with standard output /dev/full, or a pipe whose reader is gone (as `head -c1`'s is
    once it has its byte): the outcome, as :meth:`Hostile.outcome` words it."""
    reader, writer = os.pipe() if closed_pipe else (None, os.open("/dev/full", os.O_WRONLY))
    if reader is not None:
        os.close(reader)
    started = time.perf_counter()
    try:
        completed = subprocess.run([sys.executable, "-m", "ddsolve", *arguments], stdout=writer, stderr=subprocess.PIPE,
                                   text=True, errors="backslashreplace", timeout=300, cwd=hostile.folder,
                                   stdin=subprocess.DEVNULL,
                                   env={**os.environ, "PYTHONPATH": str(ROOT), **env})
    finally:
        os.close(writer)
    completed.stdout = ""
    return hostile.outcome(completed, time.perf_counter() - started)


def _standard_output(hostile) -> None:
    full_buffered = ("exit 120, 2 lines: «Exception ignored in: <_io.TextIOWrapper name='<stdout>' ...>», "
                     "OSError: [Errno 28]")
    for label, arguments, env, closed, before in (
            ("check > /dev/full", ["check", "text-base.h5"], BUFFERED, False, full_buffered),
            ("check > /dev/full, PYTHONUNBUFFERED=1", ["check", "text-base.h5"], UNBUFFERED, False,
             "exit 1: 13-line traceback (OSError: [Errno 28] No space left on device)"),
            ("solve --help > /dev/full", ["solve", "--help"], BUFFERED, False, full_buffered),
            ("mesh > /dev/full", ["mesh", "partial-closure", *SMALL], BUFFERED, False, full_buffered),
            ("scenes into a closed pipe (as `head -c1` leaves it)", ["scenes"], BUFFERED, True,
             "exit 120, 2 lines: «Exception ignored in: ...», BrokenPipeError"),
            ("scenes into a closed pipe, PYTHONUNBUFFERED=1", ["scenes"], UNBUFFERED, True,
             "exit 1: 13-line traceback (BrokenPipeError: [Errno 32] Broken pipe)"),
            ("reference into a closed pipe", ["reference", "partial-closure", *SMALL, "-o", "text-pipe.h5"], BUFFERED,
             True, "exit 59: 14 lines of «PETSC ERROR» (PETSc's handler of SIGPIPE)")):
        hostile.rows[MESSAGES].append((label, before, _redirected(hostile, arguments, env, closed)))


def _messages(hostile) -> None:
    hostile.case(MESSAGES, "compare a result with one of a wider box (geometry.box)", "exit 1, «ddsolve: error: "
                 "8 points lie outside the lower mesh»", ["compare", "text-base.h5", "text-wide.h5"])
    hostile.case(MESSAGES, "compare the wider box's result with the first", "exit 0, «relative energy-norm error "
                 "4.314e-01», measured on part of the domain only", ["compare", "text-wide.h5", "text-base.h5"])
    hostile.case(MESSAGES, "compare arc-bond, mesh.size 0.2 against 0.1 (one domain, curved Σ)", "exit 1, «ddsolve: "
                 "error: 20 points lie outside the lower mesh»", ["compare", "text-arc-coarse.h5", "text-arc-fine.h5"],
                 observe=_stdout_line("relative"))
    hostile.case(MESSAGES, "solve -n 4 -n 8", "exit 1 after 7.7 s: 47 lines of PMIx and Open MPI errors, a "
                 "segmentation fault", ["solve", "-n", "4", "-n", "8", "partial-closure", *SMALL])
