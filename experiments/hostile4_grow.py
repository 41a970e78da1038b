"""Issue 40 (round 4), `grow`: its options' ranges (class 1), its whole output set (class 5), growth that
cannot go on (class 8) and what an engineer reads (first use).  ``measure(hostile)`` adds their rows to
docs/robustness.md; *before* is what the code before the fixes did, measured once on the P = 13 mesh (on
the shared two-core machine) and quoted.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from experiments import ROOT
from experiments.robustness import SMALL

CLASSES = {
    201: ("Inputs that scale the answer have no range: grow's options",
          "`grow` checks every option before work: `--to` against the factors whose scaled loads or prescribed "
          "displacements a double-precision solve represents (the range scenes are checked against), at its "
          "largest and at its first step, `--steps` up to 1,000, `--tolerance` from 1e-8, `--pictures` up to 100"),
    205: ("Outputs that are not part of the committed set",
          "`grow`'s outputs are one set (`OUT.h5`, `OUT.csv`, `OUT.png`, `OUT-step<k>.png`) checked before work "
          "(an earlier run's step pictures and the inputs included), drawn in memory and replaced together, "
          "the step pictures it no longer has removed in the same commit"),
    208: ("Growth that cannot go on",
          "a merge that frees a part ends the run with its steps written and the free motion named from the "
          "whole kernel; a glued piece shorter than its Σ edges counts as a merge; the critical-load search ends "
          "at what a solve resolves of G (or a bracket of 1e-9 λ); Hutchinson–Suo gives G_Ic where ψ is "
          "undefined; `--steps` is bounded"),
    211: ("First use: what an engineer reads of `grow`",
          "`/growth/boundaries/LAYER.NAME/{force,displacement}` (x, y) per controlled boundary, `OUT.csv` of the "
          "curve, step pictures titled with step, λ and crack lengths, events printed one a line, and without "
          "`--to` the control rises to 2 × the initiation factor"),
}

GROW = ["grow", "partial-closure", *SMALL, "--set", "fracture.toughness=4.61e-7"]
HUTCHINSON_SUO = ["--set", 'fracture.law="hutchinson-suo"', "--set", "fracture.G_Ic=4.61e-7", "--set",
                  "fracture.lambda=0.3"]
#: Two cracks whose merge would crack the whole of Σ: the upper half is then free.
DETACHING = """
[geometry]
box = [0.0, 6.0, -0.5, 0.5]
cracks = [[0.0, 2.8], [3.2, 6.0]]
clamped = ["bottom"]
[mesh]
size = 0.2
[materials.layer1]
E = 200.0
nu = 0.28
[materials.layer2]
E = 112.0
nu = 0.32
[loads.layer1.top]
y = "1e-3*exp(-20*(x - 3)^2)"
[loads.layer2.top]
y = "1e-3*exp(-20*(x - 3)^2)"
[fracture]
toughness = 1e-9
"""


def _files(hostile, stem: str):
    """A note: the files of the set ``stem`` present after the run."""
    def observe(_completed) -> str:
        names = sorted(path.name for path in hostile.folder.glob(f"{stem}*") if not path.name.startswith("."))
        return f"; files: {', '.join(names) or 'none'}"
    return observe


def _output(hostile, stem: str):
    """A note on a growth file: its steps, its last event and its boundaries."""
    def observe(completed) -> str:
        from ddsolve.solvers import growth_files

        path = hostile.folder / f"{stem}.h5"
        if completed.returncode != 0 or not path.exists():
            return ""
        data = growth_files.read(path)
        last = next((event for event in data["events"][::-1] if event), "")
        return (f"; {len(data['control'])} steps, last event «{last[:160]}»; boundaries "
                f"{', '.join(data['boundaries']) or 'none'}")
    return observe


def measure(hostile) -> None:
    """Rows of classes 201, 205, 208 and 211 for `grow`."""
    def case(number, label, before, arguments, observe=None, kept=()):
        hostile.case(number, label, before, arguments, kept=kept, observe=observe)

    case(201, "grow --to 1e160", "exit 1, 3.6 s: traceback (OverflowError: Numerical result out of range) after "
         "printing the initiation steps", [*GROW, "--to", "1e160", "-o", "g201.h5"], kept=("g201",))
    case(201, "grow --to 1e-300", "exit 1, 3.2 s: every step run and g.h5 written, then «materials.layer1.E: the "
         "elastic matrix … gives displacements of order 6e-304, outside the range …» while drawing",
         [*GROW, "--to", "1e-300", "-o", "g201.h5"], kept=("g201",))

    obstacles(hostile)
    case(205, "a scene named OUT.png (`grow g205s.png -o g205s.h5`)", "exit 0, 4.9 s: the scene file replaced by "
         "the picture of the curves", ["grow", _scene(hostile, "g205s.png"), *SMALL, "--set",
                                      "fracture.toughness=4.61e-7", "--to", "2", "--steps", "2", "-o", "g205s.h5"],
         observe=_files(hostile, "g205s"))
    case(205, "--pictures 3, then --pictures 1 on the same output", "exit 0 both: the three step pictures of the "
         "first run left beside the one of the second", [*GROW, "--to", "2", "--steps", "2", "--pictures", "1",
                                                         "-o", _stale(hostile)], observe=_files(hostile, "g205p"))
    hostile.rows[205].append(("SIGTERM while the step pictures are drawn (20 pictures)", "exit 0: «terminated after "
                              "its result files were written (they are complete)»; only g.h5 there, no curves, "
                              "no step picture", _signal_while_drawing(hostile)))

    (hostile.folder / "detach.toml").write_text(DETACHING)
    case(208, "merging cracks free the upper half", "exit 1, 2.0 s, nothing written: «blocks u_plus, v_plus can "
         "rotate about (-2960.61, 20.9429) relative to the rest: add a support …»",
         ["grow", "detach.toml", "--to", "1", "--steps", "2", "-o", "g208d.h5"], observe=_output(hostile, "g208d"))
    case(208, "strip-disbonds, layer 1 heated by 100 (α = 1e-5), G_c = 1e-12", "exit 1, 23.7 s: «critical load "
         "factor: G/G_c − 1 jumps from -5.98e-07 to 3.05e-08 at λ = 0.000954665766729659 at tip 2 (G is "
         "discontinuous there)»", ["grow", "strip-disbonds", "--set", "materials.layer1.alpha=1e-5", "--set",
                                    "temperature.layer1=100.0", "--set", "fracture.toughness=1e-12", "--to", "1",
                                    "--steps", "2", "--pictures", "0", "-o", "g208t.h5"],
         observe=_output(hostile, "g208t"))
    case(208, "Hutchinson–Suo, partial-closure (its closed tip at G ≈ 0)", "exit 0: G_c NaN at the closed tip "
         "(printed «nan G_c» on 4 lines; a tip with 0 < G ≈ 0 gets a NaN critical factor and the initiation step "
         "is skipped)", ["grow", "partial-closure", *SMALL, *HUTCHINSON_SUO, "--to", "2", "--steps", "2", "--pictures", "0", "-o", "g208h.h5"],
         observe=_output(hostile, "g208h"))
    case(208, "Hutchinson–Suo, strip-disbonds on P = 13: two tips close in on one glued piece", "exit 1, 1.5 s: «the "
         "glued piece between crack (0.5, 2) and crack (2.25, 4.5) is shorter than a Σ edge there (0.5): merge them»",
         ["grow", "strip-disbonds", *SMALL, *HUTCHINSON_SUO, "--to", "2", "--steps", "2", "--pictures", "0", "-o",
          "g208m.h5"], observe=_output(hostile, "g208m"))
    case(208, "--steps 1000000", "accepted: 124,710 steps printed in 10 s (the whole run: 2 min, 172 MB of output)",
         [*GROW, "--to", "2", "--steps", "1000000", "-o", "g208s.h5"], kept=("g208s",))

    case(211, "grow without --to", "exit 2, 0.3 s: «grow: the following arguments are required: --to»",
         [*GROW, "--steps", "2", "--pictures", "1", "-o", "g211.h5"], observe=_output(hostile, "g211"))


def _scene(hostile, name: str) -> str:
    from ddsolve.problem import scene as scenes

    (hostile.folder / name).write_text(scenes.builtin_scenes()["partial-closure"])
    return name


def obstacles(hostile) -> None:
    """A directory and a FIFO at a step picture's name of an earlier run."""
    for kind, before in (("directory", "exit 1, 6.5 s: g.h5 written, then a traceback (IsADirectoryError: "
                                       "'g-step3.png')"),
                         ("FIFO", "exit 1, 4.8 s: g.h5 written, then a traceback (io.UnsupportedOperation: File or "
                                  "stream is not seekable)")):
        stem = f"g205{kind[0]}"
        target = hostile.folder / f"{stem}-step3.png"
        if kind == "directory":
            target.mkdir(exist_ok=True)
        elif not target.exists():
            os.mkfifo(target)
        hostile.case(205, f"a {kind} at OUT-step3.png", before,
                     [*GROW, "--to", "2", "--steps", "2", "-o", f"{stem}.h5"], kept=(stem,))


def _stale(hostile) -> str:
    """g205p.h5 after a run with three step pictures (this code's)."""
    hostile.run([*GROW, "--to", "2", "--steps", "2", "--pictures", "3", "-o", "g205p.h5"])
    return "g205p.h5"


def _signal_while_drawing(hostile) -> str:
    """SIGTERM half a second after the last step's line, while 20 step pictures are drawn: the exit status
    and the files of the set then present."""
    out = hostile.folder / "g205t.out"
    with open(out, "w") as stdout:
        started = time.perf_counter()
        job = subprocess.Popen([sys.executable, "-m", "ddsolve", *GROW, "--to", "2", "--steps", "20", "--pictures",
                                "20", "-o", "g205t.h5"], cwd=hostile.folder, stdout=stdout,
                               stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
                               env={**os.environ, "PYTHONPATH": str(ROOT)})
        while "grow 21/21" not in out.read_text() and job.poll() is None and time.perf_counter() - started < 300:
            time.sleep(0.05)
        time.sleep(0.5)
        job.send_signal(signal.SIGTERM)
        _, stderr = job.communicate(timeout=120)
    names = sorted(path.name for path in hostile.folder.glob("g205t*") if path.suffix != ".out")
    last = (stderr.strip().splitlines() or ["(nothing on standard error)"])[-1]
    return f"exit {job.returncode}: «{last}»; files of the set: {', '.join(names) or 'none'}"
