"""Hard cases and bad input, measured (``ddsolve robustness`` writes docs/robustness.md).

Every case here is also an automated test (tests/test_robustness.py and tests/test_mpi.py); this
command records what each one measures on this machine: errors against the monolithic reference,
rounds, exit statuses, messages, times.
"""
from __future__ import annotations

import importlib
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ddsolve.problem import scene as scenes
from experiments import ROOT

MESH = ["--set", "mesh.sigma_vertices=48", "--set", "mesh.boundary_vertices=80"]
DOCS = Path("docs")


def _mesh(name: str) -> list[str]:
    """The P, M overrides for built-in scenes (a scene file brings its own mesh)."""
    return [] if name.endswith(".toml") else MESH


def _name(path: Path) -> str:
    return path.name


def _run(arguments: list[str], ranks: int | None = 4, timeout: float = 600,
         folder: Path | None = None) -> tuple[subprocess.CompletedProcess, float]:
    """Run ddsolve (under mpiexec with ``ranks``) in ``folder``, so messages name files relatively."""
    from ddsolve.parallel.launch import mpiexec_command

    command = mpiexec_command(ranks, arguments) if ranks else [sys.executable, "-m", "ddsolve", *arguments]
    started = time.perf_counter()
    completed = subprocess.run(command, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL,
                               env={**os.environ, "PYTHONPATH": str(ROOT)},
                               cwd=folder)
    return completed, time.perf_counter() - started


class Cases:
    """Runs cases in a scratch folder and collects table rows."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.rows: list[tuple[str, str, str, str]] = []
        self.references: dict[tuple, object] = {}

    def _reference(self, name: str, overrides: tuple[str, ...]):
        from ddsolve.io import hdf5

        key = (name, overrides)
        if key not in self.references:
            path = self.folder / f"reference-{len(self.references)}.h5"
            settings = [item for setting in overrides for item in ("--set", setting)]
            completed, _ = _run(["reference", name, *_mesh(name), *settings, "-o", path.name], ranks=None,
                                folder=self.folder)
            if completed.returncode != 0:
                raise RuntimeError(completed.stderr)
            self.references[key] = hdf5.read(path)
        return self.references[key]

    def against_reference(self, case: str, why: str, name: str, *settings: str, method: str = "schur",
                          test: str = "") -> None:
        """Solve with ``method`` on 4 ranks (``settings``: KEY=VALUE); the row shows rounds, error, penetration."""
        from ddsolve.io import hdf5
        from ddsolve.post import analysis

        path = self.folder / "dd.h5"
        overrides = [item for setting in (*settings, f"solver.method={method}") for item in ("--set", setting)]
        completed, _ = _run(["solve", name, *_mesh(name), *overrides, "-o", path.name], folder=self.folder)
        if completed.returncode != 0:
            self.rows.append((case, f"fails: {completed.stderr.strip()}", why, test))
            return
        result = hdf5.read(path)
        reference = self._reference(name, tuple(s for s in settings if not s.startswith("solver.")))
        comparison = analysis.compare(result, reference)
        checks = analysis.constraints(result)
        self.rows.append((case, f"`{method}`: {result.solves} rounds, energy error {comparison.energy_error:.1e}, "
                                f"penetration {checks.penetration:.1e}", why, test))

    def fails(self, case: str, why: str, arguments: list[str], ranks: int | None = 4, test: str = "",
              kept: Path | None = None) -> None:
        """A run that must fail: exit status, the message, elapsed time, whether ``kept`` survived."""
        if kept is not None:
            kept.write_bytes(b"previous result")
        completed, elapsed = _run(arguments, ranks, folder=self.folder)
        lines = completed.stderr.strip().splitlines()
        message = lines[0] if len(lines) == 1 else f"{len(lines)} lines: " + " / ".join(lines[:2])
        outcome = f"exit {completed.returncode} after {elapsed:.1f} s: «{message}»"
        if kept is not None:
            outcome += "; previous file kept" if kept.read_bytes() == b"previous result" else "; PREVIOUS FILE LOST"
        self.rows.append((case, outcome, why, test))

    def signal(self, case: str, why: str, signum: int, test: str) -> None:
        outcome = interrupt(self.folder, signum)
        kept = "kept" if outcome["kept"] else "LOST"
        left = "; temporary files left: " + ", ".join(outcome["leftovers"]) if outcome["leftovers"] else ""
        self.rows.append((case, f"exit {outcome['status']} {outcome['seconds']:.1f} s after the signal, "
                                f"«{outcome['message']}»; previous file {kept}{left}", why, test))


#: Uzawa's first progress line, printed once it has iterated for 2 s (:class:`ddsolve.dd.dual.Progress`).
ITERATING = "uzawa: iteration"


def interrupt(folder: Path, signum: int, timeout: float = 120.0) -> dict:
    """Start a long run writing to ``folder/kept.h5`` (which holds a previous result), signal mpiexec once
    the iterations have run for 2 s (their first progress line; at most ``timeout`` s after the start).

    Returns whether the run was still running then, the exit status, the seconds from the signal to the
    exit, the first line of standard error, whether the previous file survived and which temporary files
    are left in ``folder``.
    """
    from ddsolve.parallel.launch import mpiexec_command

    kept = folder / "kept.h5"
    kept.write_bytes(b"previous result")
    present = {p.name for p in folder.iterdir()}
    command = mpiexec_command(4, ["solve", "partial-closure", "--set", "solver.method=uzawa",
                                  "--set", "solver.stop=relative", "--set", "solver.tol=1e-300",
                                  "--set", "solver.max_iterations=10000000", "-o", str(kept)])
    with tempfile.TemporaryFile() as printed:
        process = subprocess.Popen(command, stdout=printed, stderr=subprocess.PIPE, text=True,
                                   stdin=subprocess.DEVNULL, env=dict(os.environ))
        deadline = time.perf_counter() + timeout
        while process.poll() is None and time.perf_counter() < deadline and not _printed(printed, ITERATING):
            time.sleep(0.05)
        running = process.poll() is None
        sent = time.perf_counter()
        process.send_signal(signum)
        _, stderr = process.communicate(timeout=60)
    return {"running": running, "status": process.returncode, "seconds": time.perf_counter() - sent,
            "message": stderr.strip().splitlines()[0] if stderr.strip() else "",
            "traceback": "Traceback" in stderr, "kept": kept.read_bytes() == b"previous result",
            "leftovers": sorted(p.name for p in folder.iterdir() if p.name not in present)}


def _printed(stream, text: str) -> bool:
    """Whether the file ``stream`` (a process's standard output) holds ``text``; read without moving the
    offset the process writes at."""
    descriptor = stream.fileno()
    return text.encode() in os.pread(descriptor, os.fstat(descriptor).st_size, 0)


def _mesh_file(folder: Path, name: str, points, cells) -> Path:
    import meshio

    path = folder / f"{name}.vtu"
    meshio.write(path, meshio.Mesh(np.column_stack([points, np.zeros(len(points))]), [("triangle", cells)]))
    scene_file = folder / f"{name}.toml"
    scene_file.write_text(scenes.builtin_scenes()["partial-closure"].replace(
        "sigma_vertices = 96\nboundary_vertices = 144", f'file = "{path.name}"'))
    return scene_file


def _square(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.linspace(-1, 1, nx + 1), np.linspace(-1, 1, 2 * ny + 1)
    X, Y = np.meshgrid(x, y)
    v = np.arange((nx + 1) * (2 * ny + 1)).reshape(2 * ny + 1, nx + 1)
    a, b, c, d = v[:-1, :-1].ravel(), v[:-1, 1:].ravel(), v[1:, 1:].ravel(), v[1:, :-1].ravel()
    return np.column_stack([X.ravel(), Y.ravel()]), np.concatenate([np.column_stack([a, b, c]),
                                                                    np.column_stack([a, c, d])])


def robustness() -> None:
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        cases = Cases(Path(scratch))
        measure(cases, Path(scratch))
    with tempfile.TemporaryDirectory() as scratch:
        hostile = Hostile(Path(scratch))
        hostile.measure()
    minutes = (time.perf_counter() - started) / 60.0
    lines = ["# Robustness", "",
             f"`./run robustness` (about {minutes:.0f} minutes) measures every case below and rewrites this page; each "
             "one is also an automated test in `./run test` (last column). Solves run on 4 ranks, on the P = 48, M = 80 "
             "mesh unless the case says otherwise; errors are relative energy-norm errors against the monolithic "
             "reference, penetration is max (u⁻ − u⁺)·ν / max |u|.", "",
             "| case | measured outcome | why | test |", "|---|---|---|---|"]
    for case, outcome, why, test in cases.rows:
        lines.append(f"| {case} | {outcome.replace('|', '/')} | {why} | {test} |")
    lines += hostile.section()
    lines += ["", "The scene parser is also fuzzed with hypothesis (random `--set` items, random text, shuffled "
              "lines of a valid scene: 800 examples per run of `./run test`): every input either parses or "
              "raises a one-line scene error — no other exception (`test_*_never_raise_anything_but_scene_errors`). "
              "The fuzzer found one real bug, an override containing a newline whose error message spanned two "
              "lines; user text is now escaped in every message."]
    (DOCS / "robustness.md").write_text("\n".join(lines) + "\n")


#: Where the tests of the cases below are (most are in tests/test_robustness.py).
ROBUSTNESS_TESTS = "`test_robustness.py::"


def measure(cases: Cases, folder: Path) -> None:
    """Every hard case and bad input of the page's first table, in its order (files in ``folder``)."""
    _divergence(cases)
    _contrast_and_cracks(cases)
    _loads_and_meshes(cases, folder)
    _bad_input(cases, folder)
    _failures_while_running(cases, folder)


def _divergence(cases: Cases) -> None:
    """Uzawa above its stable step, and θ given to the default method."""
    t = ROBUSTNESS_TESTS
    cases.fails("`uzawa`, θ = 65, crack fully closed", "θ above the stable bound 2/λmax = 58.1 of this mesh: with "
                "every contact multiplier active the full dual operator applies; divergence is detected from the "
                "growth of the multiplier steps",
                ["solve", "full-closure", *MESH, "--set", "solver.method=uzawa", "-o", "x.h5"],
                test=t + "test_uzawa_above_the_stable_bound_with_a_closed_crack`")
    cases.fails("`uzawa`, θ = 200", "far above the bound: detected within a few iterations",
                ["solve", "partial-closure", *MESH, "--set", "solver.method=uzawa", "--set", "solver.theta=200",
                 "-o", "x.h5"], test="`test_mpi.py::test_divergence_stops_early_and_keeps_the_previous_file`")
    cases.fails("default method, --set solver.theta=200", "the default method reads no θ: given with --set it is "
                "refused naming the key (the θ = 65 the paper's scene files carry is not read)",
                ["solve", "partial-closure", *MESH, "--set", "solver.theta=200", "-o", "x.h5"],
                test="`test_reliability_keys.py`")


def _contrast_and_cracks(cases: Cases) -> None:
    """Stiffness contrast, near-incompressible layers, cracks of every extent."""
    t = ROBUSTNESS_TESTS
    for label, overrides in (("E2/E1 = 1e-4", ("materials.layer2.E=0.02",)),
                             ("E2/E1 = 1e4", ("materials.layer2.E=2e6",))):
        cases.against_reference(label, "the exact solve is insensitive to the contrast; the Schur complement is "
                                "validated by a solve", "partial-closure", *overrides,
                                test=t + "test_default_method_matches_the_reference_on_hard_cases`")
    for nu in (0.49, 0.4999):
        cases.against_reference(f"ν = {nu} (both layers)", "solved exactly; P1 triangles lock near ν = 0.5 "
                                "(the discrete solution is too stiff), a discretization matter the solver "
                                "reproduces faithfully", "partial-closure", f"materials.layer1.nu={nu}",
                                f"materials.layer2.nu={nu}",
                                test=t + "test_default_method_matches_the_reference_on_hard_cases`")
    for label, crack, why in (
            ("crack (−0.98, 0.98)", "[-0.98, 0.98]", "the crack nearly reaches the clamped ends; only two glued "
             "Σ elements are left at each end"),
            ("crack of one Σ element (0, 0.05)", "[0.0, 0.05]", "no crack vertex inside: no μᶜ, and the P1 solution "
             "is the uncracked one"),
            ("no crack", "[]", "no μᶜ at all; every Σ vertex glued")):
        cases.against_reference(label, why, "partial-closure", f"geometry.crack={crack}",
                                test=t + "test_default_method_matches_the_reference_on_hard_cases`")
    cases.fails("crack reaching a clamped end, (−1, 0.5)", "rejected: the paper requires the crack to stay off Γ_D",
                ["solve", "partial-closure", "--set", "geometry.crack=[-1.0, 0.5]"], ranks=None,
                test="`test_scene.py::test_bad_values_name_the_key`")


def _loads_and_meshes(cases: Cases, folder: Path) -> None:
    """Zero and scaled loads, a load on layer 2 only, all contact or none, a strongly graded mesh."""
    t = ROBUSTNESS_TESTS
    zero = ("loads.layer1.bottom.y=[0.0]", "loads.layer1.top.y=[0.0]")
    for method in ("schur", "mprgp", "fista", "uzawa"):
        cases.against_reference(f"zero load, `{method}`", "exactly zero; every stopping rule treats 0/0 as converged",
                                "partial-closure", *zero, method=method,
                                test=t + "test_zero_load_gives_exactly_zero_without_division_by_zero`")
    for factor in (1e-12, 1.0, 1e12):
        c = 0.078125 * factor
        for method in ("schur", "mprgp"):
            cases.against_reference(f"loads × {factor:g}", "the kkt rule is scale-free: the same rounds up to one "
                                    "(1e12 is not exact in binary; scaled by 2^±40 the rounds are identical, as the "
                                    "test checks)",
                                    "partial-closure", "solver.p=1e300",
                                    f"loads.layer1.bottom.y=[0.0, {c!r}]", f"loads.layer1.top.y=[0.0, {-c!r}]",
                                    method=method,
                                    test=t + "test_scaled_loads_give_scaled_solutions_in_the_same_iterations`")
    cases.against_reference("load on layer 2 only", "layer 1 moves through the gluing", "partial-closure",
                            "loads.layer1.bottom.y=[]", "loads.layer1.top.y=[]",
                            "loads.layer2.bottom.y=[0.0, 0.05]", test=t + "test_load_on_layer_2_only`")
    for name in ("full-closure", "full-opening"):
        cases.against_reference(name.replace("-", " "), "every crack vertex in contact / none",
                                name, test=t + "test_full_closure_and_full_opening`")
    points, cells = _square(16, 12)
    heights = (1.6 ** np.arange(13) - 1.0) / (1.6 ** 12 - 1.0)
    levels = np.concatenate([-heights[::-1], heights[1:]])
    points[:, 1] = levels[np.round((points[:, 1] + 1.0) * 12).astype(int)]
    graded = _mesh_file(folder, "graded", points, cells)
    cases.against_reference("graded mesh, aspect ratio 58 at Σ", "direct block solves do not mind the aspect ratio",
                            graded.name, test=t + "test_strongly_graded_and_distorted_mesh`")


def _bad_input(cases: Cases, folder: Path) -> None:
    """Bad scenes and bad mesh files: refused before any work."""
    t = ROBUSTNESS_TESTS
    bad = [
        ("malformed TOML", ["solve", _name(_text(folder, "bad.toml", "[mesh\nx = 1"))]),
        ("unknown key", ["solve", "partial-closure", "--set", "solver.thta=60"]),
        ("wrong type", ["solve", "partial-closure", "--set", "mesh.sigma_vertices=\"many\""]),
        ("E ≤ 0", ["solve", "partial-closure", "--set", "materials.layer1.E=0"]),
        ("ν outside (−1, 0.5)", ["solve", "partial-closure", "--set", "materials.layer2.nu=0.5"]),
        ("crack reversed", ["solve", "partial-closure", "--set", "geometry.crack=[0.5, -0.5]"]),
        ("crack outside (−1, 1)", ["solve", "partial-closure", "--set", "geometry.crack=[-2, 0]"]),
        ("P too small", ["solve", "partial-closure", "--set", "mesh.sigma_vertices=3"]),
        ("M inconsistent with P", ["solve", "partial-closure", "--set", "mesh.boundary_vertices=5000"]),
        ("unknown method", ["solve", "partial-closure", "--set", "solver.method=newton"]),
        ("θ ≤ 0", ["solve", "partial-closure", "--set", "solver.method=uzawa", "--set", "solver.theta=0"]),
        ("tol ≤ 0", ["solve", "partial-closure", "--set", "solver.tol=-1"]),
        ("mesh file missing", ["solve", _name(_mesh_scene(folder, folder / "missing.msh"))]),
    ]
    for case, arguments in bad:
        cases.fails(case, "validated on rank 0 before any work; every rank exits with the same status", arguments,
                    test="`test_scene.py`, `test_io_cli.py`")
    garbage = _text(folder, "garbage.msh", "not a mesh\n")
    cases.fails("mesh file unreadable", "meshio's exceptions (even its SystemExit) become one line",
                ["solve", _name(_mesh_scene(folder, garbage))], test="`test_mesh.py::test_unreadable_files`")
    p, c = _square(8, 2)
    c[3] = c[3, ::-1]
    cases.fails("inverted triangle", "mixed orientation is rejected by the mesh check",
                ["solve", _name(_mesh_file(folder, "inverted", p, c))], test="`test_mesh.py::test_bad_meshes_are_rejected`")
    p, c = _square(8, 2)
    p[:, 0] *= 0.9
    cases.fails("no clamped boundary", "a block without clamped vertices would be singular",
                ["solve", _name(_mesh_file(folder, "floating", p, c))], test="`test_mesh.py::test_bad_meshes_are_rejected`")
    cases.fails("Σ vertices of the halves differ", "the nodal constraints need matching vertices",
                ["solve", _name(_mismatched(folder))], ranks=2,
                test=t + "test_halves_with_different_sigma_vertices_are_rejected`")


def _failures_while_running(cases: Cases, folder: Path) -> None:
    """Unsupported rank counts, an unwritable output, a failing block solver, signals."""
    t = ROBUSTNESS_TESTS
    for ranks in (3, 5):
        cases.fails(f"{ranks} ranks", "checked collectively before any work", ["solve", "partial-closure", *MESH,
                    "-o", "x.h5"], ranks=ranks, test=t + "test_five_ranks_are_refused_on_every_rank`")
    cases.fails("output directory not writable", "the temporary file cannot be created; all ranks exit",
                ["solve", "partial-closure", *MESH, "-o", "/proc/ddsolve-result.h5"],
                test=t + "test_unwritable_output_is_reported_and_all_ranks_exit`")
    cases.fails("a block solver failing on one rank", "the failing block's rank reports it; rank 0 stops every rank",
                ["solve", "partial-closure", *MESH, "--set", "solver.method=mprgp", "-o", "kept.h5",
                 "-v_plus_ksp_type", "cg", "-v_plus_pc_type", "none", "-v_plus_ksp_max_it", "2"],
                kept=folder / "kept.h5", test=t + "test_a_block_solver_failing_on_one_rank_stops_every_rank`")
    for signum in (signal.SIGINT, signal.SIGTERM):
        cases.signal(f"{signal.Signals(signum).name} to mpiexec during a run", "Open MPI's mpiexec sends the ranks "
                     "SIGTERM, which ddsolve turns into an exception (temporary files removed) and an abort of the "
                     "job; results are written to a temporary file and renamed, so the previous one survives",
                     signum, test=t + "test_a_signal_stops_every_rank_promptly_and_keeps_the_previous_file`")


def _text(folder: Path, name: str, content: str) -> Path:
    path = folder / name
    path.write_text(content)
    return path


def _mesh_scene(folder: Path, mesh: Path) -> Path:
    scene_file = folder / f"{mesh.stem}.toml"
    scene_file.write_text(scenes.builtin_scenes()["partial-closure"].replace(
        "sigma_vertices = 96\nboundary_vertices = 144", f'file = "{mesh.name}"'))
    return scene_file


def _mismatched(folder: Path) -> Path:
    """A mesh file whose upper half has its own Σ vertices, moved sideways."""
    points, cells = _square(8, 2)
    inner = (points[:, 1] == 0) & (np.abs(points[:, 0]) < 1) & (np.abs(points[:, 0]) != 0.5)
    duplicate = np.flatnonzero(inner)
    moved = np.vstack([points, points[duplicate] + [0.05, 0.0]])
    renumber = np.arange(len(points))
    renumber[duplicate] = len(points) + np.arange(len(duplicate))
    upper = np.any(points[cells, 1] > 0, axis=1)
    cells = np.where(upper[:, None], renumber[cells], cells)
    return _mesh_file(folder, "mismatch", moved, cells)


# --- hostile input: the classes of issue 14, before and after -------------------------------------
SMALL = ["--set", "mesh.sigma_vertices=13", "--set", "mesh.boundary_vertices=32"]
CLASSES = {
    1: ("Silent wrong answers", "every method's «converged» is checked on the final solve's KKT residuals; "
        "blocks are scaled to order one; repeated triangles, moduli and loads beyond double precision are refused"),
    2: ("Tracebacks", "PETSc's and HDF5's refusals, broken result files and failed writes become one line"),
    3: ("Hangs and runaway work", "impossible rank counts and meshes are refused before any work, with the "
        "memory estimate; a watchdog ends the job within seconds of a signal, even inside gmsh"),
    4: ("Lost or corrupted files", "outputs are checked before the solve; a result set is replaced as a whole "
        "or not at all; inputs and non-regular files are never replaced; killed runs' temporaries are removed"),
    5: ("Unclear messages", "every message names the key, file or option to change"),
    6: ("Options typed after PETSc options", "ddsolve's options are taken anywhere; PETSc options nobody read "
        "are reported"),
}
#: The classes of issue 21 (round 3), numbered 101 to 109; each is measured by a module
#: ``hostile_<topic>`` of this package whose ``measure(hostile)`` adds its rows.
ROUND3 = {
    101: ("Load expressions at the parser's limits", "expressions are bounded (10 000 characters, nesting 50 deep, "
          "polynomial degree 100, 101 coefficients); constants that overflow are refused where they are written; "
          "sums and products are flat chains, so length costs no depth"),
    102: ("Coarse, thin, slender or far-away geometry", "a box far from the origin is meshed about a nearby origin and "
          "shifted back; a mesh whose coordinates double precision cannot place against its shortest edge is "
          "refused naming geometry.box; a load that would act only on clamped nodes is refused; the error estimate "
          "survives meshes without patches"),
    103: ("Text that is not plain UTF-8 on the way out", "every command's standard output and error spell in ASCII "
          "what their encoding cannot hold; a plot title is drawn as plain text on one line, shortened with an "
          "ellipsis; mesh -o names the one format it writes"),
    104: ("Work that is never refused", "sweeps are bounded before the first run (10 000 runs, 24 h by a lower "
          "estimate, a mesh that fits in memory); an adaptive target out of reach is refused after the first level "
          "with the unknowns it needs; a .geo is meshed in 1D with bounded sizes and refused before gmsh meshes a "
          "surface it cannot finish"),
    105: ("Interrupted writes", "every set is written to temporaries and renamed in one critical section (a journal "
          "first, signals deferred, the watchdog waiting for it); a run interrupted after its commit exits 0; the "
          "launcher supervises mpiexec and repairs a set a killed rank left half-renamed"),
    106: ("Files users have", "an element that MSH 2.2 lists once per physical group is one element carrying every "
          "group; every input file goes through one check that names it and why it cannot be read"),
    107: ("Silent wrong answers: keys ignored, inputs without meaning", "every --set key a command does not read is "
          "refused naming it; reference and sweep honour mesh.target_error, the reference checks solver.p; loads "
          "that are not finite or grow without bound on their boundary, and fibre angles a double cannot place, "
          "are refused"),
    108: ("Outputs that destroy inputs, and messages that blame the wrong thing", "every command that writes refuses "
          "an output that is one of its inputs; write errors of standard output are one line; compare names both "
          "files when the domains differ; -n given twice is a usage error; nearly incompressible layers, mesh.grading "
          "near 0 and scene files with a byte-order mark are handled where they arise"),
    109: ("Processes that outlive their command", "gmsh children and ranks get SIGKILL from the kernel when their "
          "parent ends (PR_SET_PDEATHSIG), mpiexec SIGTERM when the launcher ends; an MPI_Abort that mpiexec does "
          "not answer ends the rank after 2 s; PETSc's crash handler no longer calls MPI inside a signal handler"),
}
#: What round 5 tried, and what held (its rows are the cases that needed a fix).
ROUND5_INTRO = (
    "The surfaces added by one-layer structures (`geometry.layers = 1`), friction on the crack faces "
    "(`contact.friction`, `contact.slip_bound`), several interfaces (`geometry.sigma = [y1, ...]`, nested "
    "`geometry.cracks`, `materials.LAYER.regionK`) and the interface crack's `fracture.reference_length`, tried "
    "as a hostile user would: about 150 probes, every command on 1, 2 and 4 ranks. What held without a change: "
    "one layer with every command (solve, reference, compare, sweep, grow, mesh, export, plot, check, the API's "
    "load), gmsh .geo and .msh files, region materials (isotropic and orthotropic, against the reference to "
    "1e-15), thermal loads, floating parts, point supports, P2 and mesh.target_error, and every --set that adds a "
    "layer2 key (refused naming it); friction's odd values (nan, inf, strings, booleans, tables, nested or empty "
    "lists, negative values) refused naming the key, every method on 1 and 2 ranks within 2e-6 of schur in the "
    "energy norm, growth, sweeps and critical factors with friction, the reference's refusal (one line, exit 1), "
    "the iterative methods' iteration limit inside Coulomb's fixed point (exit 3, the result written with "
    "converged = false), the ranks of a failed Coulomb iteration ending together; several "
    "interfaces refused in one line by solve, reference, sweep and grow on every rank count, their malformed "
    "nesting, unsorted heights, heights on the box's edges, cracks outside the box and region names of the other "
    "form refused naming the key. Open, in modules under change: schur's Coulomb iteration that finds no fixed "
    "point in 50 Tresca problems ends with exit 1 and nothing written, where the iterative methods write the "
    "result with converged = false (exit 3); `grow` with a per-crack friction list stops at the first merge of "
    "two cracks («contact.friction lists 3 values for the 2 cracks of the mesh», exit 1, the steps before it not "
    "written); a region of several interfaces far thinner than mesh.size is meshed with triangles of angle 0 (the "
    "mesh command prints min angle 0.0). *Before* is what the code before the fixes did, measured once (quoted); "
    "*after* is measured by `./run robustness`. The tests are in `tests/test_round5_inputs.py`.")
#: The modules that measure the classes of ROUND3, each with ``measure(hostile)``.
ROUND3_MODULES = ("hostile_expr", "hostile_geom", "hostile_text", "hostile_keys", "hostile_writes", "hostile_msh",
                  "hostile_procs")


def round_modules(number: int) -> list:
    """The modules ``hostile<number>_<topic>`` of this package that measure round ``number`` (4: issue 40; 5: the
    one-layer structures, friction, several interfaces): each holds ``CLASSES`` (its class numbers, 201 to 211 in
    round 4, 301 on in round 5, with a title and how the class is fixed at the root) and ``measure(hostile)``,
    which adds its rows."""
    names = sorted(path.stem for path in (ROOT / "experiments").glob(f"hostile{number}_*.py"))
    return [importlib.import_module(f"experiments.{name}") for name in names]


def round_classes(number: int) -> dict:
    """A round's classes, in number order, from the modules that measure them.  Modules that share a class
    (the first-use items, 211) each name their part of it: «Topic: part»; the parts are joined."""
    classes: dict[int, tuple[str, str]] = {}
    for module in round_modules(number):
        for number_, (title, how) in module.CLASSES.items():
            if number_ in classes:
                topic, _, part = title.partition(": ")
                title = f"{classes[number_][0]}; {part or topic}"
                how = f"{classes[number_][1]}; {how}"
            classes[number_] = (title, how)
    return dict(sorted(classes.items()))


class Hostile:
    """The hostile inputs of docs/robustness.md, measured in a scratch folder: each row gives what the
    previous code did (measured once, before the fixes; those numbers are quoted) and what this code does."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.rows: dict[int, list[tuple[str, str, str]]] = {number: [] for number in
                                                            (*CLASSES, *ROUND3, *round_classes(4),
                                                             *round_classes(5))}

    def run(self, arguments: list[str], env: dict | None = None, timeout: float = 300
            ) -> tuple[subprocess.CompletedProcess, float]:
        started = time.perf_counter()
        completed = subprocess.run([sys.executable, "-m", "ddsolve", *arguments], capture_output=True, text=True,
                                   errors="backslashreplace",  # what a latin-1 or ASCII run printed, byte for byte
                                   timeout=timeout, cwd=self.folder, stdin=subprocess.DEVNULL,
                                   env={**os.environ, "PYTHONPATH": str(ROOT),
                                        **(env or {})})
        return completed, time.perf_counter() - started

    def case(self, number: int, label: str, before: str, arguments: list[str], env: dict | None = None,
             kept: tuple[str, ...] = (), observe=None) -> None:
        """Run ``ddsolve ARGUMENTS``; ``kept``: result files (and their viewer files) made beforehand, which
        must be byte-identical afterwards unless the run wrote a result; ``observe(completed)`` adds a note."""
        previous = self._previous(kept)
        completed, elapsed = self.run(arguments, env)
        outcome = self.outcome(completed, elapsed)
        if previous:
            same = all(path.read_bytes() == data for path, data in previous.items() if path.is_file())
            outcome += "; previous files kept" if same else "; previous files replaced"
        if observe is not None:
            outcome += observe(completed)
        self.rows[number].append((label, before, outcome))

    def _previous(self, stems: tuple[str, ...]) -> dict[Path, bytes]:
        from ddsolve.io.viewer import viewer_paths

        files = {}
        for stem in stems:
            for path in [self.folder / f"{stem}.h5", *viewer_paths(self.folder, stem)]:
                if not path.exists():
                    path.write_bytes(b"previous " + path.name.encode())
                if path.is_file():
                    files[path] = path.read_bytes()
        return files

    @staticmethod
    def outcome(completed: subprocess.CompletedProcess, elapsed: float) -> str:
        lines = [line for line in completed.stderr.strip().splitlines() if line]
        first = lines[0] if lines else "(nothing on standard error)"
        text = f"exit {completed.returncode}, {elapsed:.1f} s: «{first}»"
        if len(lines) > 1:
            text += f" ({len(lines)} lines)"
        if "Traceback" in completed.stdout + completed.stderr:
            text += "; TRACEBACK"
        return text

    def error_against_reference(self, output: str, overrides: list[str]):
        """A note for a run that wrote ``output``: converged or not, and its energy error against the reference."""
        def observe(completed: subprocess.CompletedProcess) -> str:
            from ddsolve.io import hdf5
            from ddsolve.post import analysis

            if not (self.folder / output).exists() or completed.returncode not in (0, 3):
                return ""
            reference, _ = self.run(["reference", "partial-closure", *SMALL, *overrides, "-o", "reference.h5"])
            result = hdf5.read(self.folder / output)
            note = f"; written with converged = {str(result.converged).lower()}"
            if reference.returncode == 0:
                error = analysis.compare(result, hdf5.read(self.folder / "reference.h5")).energy_error
                note += f", energy error {error:.1e} against the reference"
            return note
        return observe

    def measure(self) -> None:
        self._fixtures()
        self._wrong_answers()
        self._tracebacks()
        self._hangs()
        self._files()
        self._messages()
        self._options()
        for name in ROUND3_MODULES:
            importlib.import_module(f"experiments.{name}").measure(self)
        for module in (*round_modules(4), *round_modules(5)):
            module.measure(self)

    def _fixtures(self) -> None:
        completed, _ = self.run(["solve", "-n", "2", "partial-closure", *SMALL, "-o", "base.h5"])
        if completed.returncode != 0:
            raise RuntimeError(completed.stderr)
        points, cells = _square(8, 4)
        n = 8

        def index(i: int, j: int, k: int) -> int:
            """Triangle k of the square (i, j) in :func:`_square`'s numbering."""
            return k * n * n + j * n + i
        _mesh_file(self.folder, "clean", points, cells)
        _mesh_file(self.folder, "dupint", points, np.vstack([cells, cells[[index(3, 2, 0), index(3, 2, 1),
                                                                           index(4, 5, 0), index(4, 5, 1)]]]))
        broken = points.copy()
        broken[3 + 2 * (n + 1)] = np.nan
        _mesh_file(self.folder, "nan", broken, cells)
        import h5py

        for name, edit in (("wrongshape", lambda f: f.__setitem__("solution/u_minus", np.zeros(3))),
                           ("wrongrows", lambda f: f.__setitem__("solution/u_plus", np.zeros((len(f["mesh/upper/points"])
                                                                                            - 5, 2)))),
                           ("badcells", lambda f: f.__setitem__("mesh/lower/cells", np.full((3, 3), 10 ** 9)))):
            path = self.folder / f"{name}.h5"
            path.write_bytes((self.folder / "base.h5").read_bytes())
            with h5py.File(path, "r+") as f:
                target = {"wrongshape": "solution/u_minus", "wrongrows": "solution/u_plus",
                          "badcells": "mesh/lower/cells"}[name]
                del f[target]
                edit(f)
        (self.folder / "scene.toml").write_text(scenes.builtin_scenes()["partial-closure"])

    def _wrong_answers(self) -> None:
        uzawa = ["--set", "solver.method=uzawa"]
        for label, before, overrides in (
                ("uzawa, θ = 1e6", "exit 0, «converged after 3 iterations», energy error 9.6e+08, gluing gap 1.8",
                 [*uzawa, "--set", "solver.theta=1e6"]),
                ("uzawa, E1 = E2 = 1e-6", "exit 0, «converged after 1 iterations», energy error 4.3e+07",
                 [*uzawa, "--set", "materials.layer1.E=1e-6", "--set", "materials.layer2.E=1e-6"]),
                ("schur, E1 = E2 = 1e-20", "exit 0, «converged», energy error 0.33 (MUMPS's Schur complement)",
                 ["--set", "materials.layer1.E=1e-20", "--set", "materials.layer2.E=1e-20"]),
                ("schur, E1 = 1e-300", "exit 0, «converged», energy error 0.31",
                 ["--set", "materials.layer1.E=1e-300"])):
            self.case(1, label, before, ["solve", "-n", "4", "partial-closure", *SMALL, *overrides, "-o", "c1.h5"],
                      observe=self.error_against_reference("c1.h5", [o for o in overrides if "solver." not in o]))
            (self.folder / "c1.h5").unlink(missing_ok=True)
        self.case(1, "mesh file listing 4 interior triangles twice", "exit 0, accepted, energy error 5.1e-02 against "
                  "the clean mesh", ["solve", "-n", "4", "dupint.toml", "-o", "c1.h5"])
        self.case(1, "loads of 1e300", "exit 0, «converged», energy error inf, 2 lines of numpy warnings",
                  ["solve", "-n", "4", "partial-closure", *SMALL, "--set", "loads.layer1.top.y=[0.0, -1e300]",
                   "--set", "loads.layer1.bottom.y=[0.0, 1e300]", "-o", "c1.h5"], kept=("c1",))
        self.case(1, "reference, E1 = 1e308", "exit 0, converged = true over 480 NaN values of 560",
                  ["reference", "partial-closure", *SMALL, "--set", "materials.layer1.E=1e308", "-o", "c1.h5"],
                  kept=("c1",))

    def _tracebacks(self) -> None:
        base = ["solve", "-n", "4", "partial-closure", *SMALL, "-o", "c2.h5"]
        self.case(2, "unknown PC type (command line)", "31-line traceback (petsc4py.PETSc.Error), printed twice",
                  [*base, "-u_minus_pc_type", "nonsense"], kept=("c2",))
        self.case(2, "unknown KSP type in PETSC_OPTIONS", "31-line traceback", base,
                  env={"PETSC_OPTIONS": "-v_plus_ksp_type nonsense"}, kept=("c2",))
        self.case(2, "reference, unknown PC type", "43-line traceback",
                  ["reference", "partial-closure", *SMALL, "-o", "c2.h5", "-reference_pc_type", "nonsense"],
                  kept=("c2",))
        self.case(2, "title with a NUL character", "39-line traceback (ValueError) after the whole solve",
                  [*base, "--set", 'title="a\\u0000b"'], kept=("c2",))
        self.case(2, "title with a lone surrogate (bytes ED A0 80)", "39-line traceback (UnicodeEncodeError)",
                  [*base, "--set", 'title="a\udced\udca0\udc80b"'], kept=("c2",))
        for label, before, arguments in (
                ("check: solution of shape (3,)", "27-line traceback (IndexError)", ["check", "wrongshape.h5"]),
                ("check: 5 rows missing", "exit 0, numbers computed from the mis-shaped data", ["check", "wrongrows.h5"]),
                ("plot: cell index 10^9", "55-line traceback (IndexError)", ["plot", "badcells.h5"]),
                ("compare: solution of shape (3,)", "33-line traceback (ValueError)",
                 ["compare", "wrongshape.h5", "base.h5"])):
            self.case(2, label, before, arguments)
        self._full_disk()

    def _full_disk(self) -> None:
        """solve -o into a 200 KiB file system with 24 KiB free (needs root to mount it)."""
        full = self.folder / "full"
        full.mkdir()
        if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", str(full)],
                          capture_output=True).returncode != 0:
            self.rows[2].append(("solve -o into a full file system", "exit 59, 81 lines: h5py tracebacks and a "
                                 "segmentation fault", "not measured here (mounting a small file system needs root)"))
            return
        try:
            (full / "filler").write_bytes(bytes(168 * 1024))
            self.case(2, "solve -o into a full file system", "exit 59, 81 lines: h5py tracebacks and a "
                      "segmentation fault", ["solve", "-n", "4", "partial-closure", *SMALL, "-o", "full/out.h5"],
                      kept=("full/out",))
        finally:
            subprocess.run(["umount", str(full)], capture_output=True)

    def _hangs(self) -> None:
        for ranks, before in (("99999999999", "no output; mpiexec took +18 GB; ended by timeout after 60 s"),
                              ("-1", "exit 1, nothing printed"), ("0", "exit 0: ran on 2 ranks without a word"),
                              ("2147483648", "exit 1, nothing printed")):
            self.case(3, f"-n {ranks}", before, ["solve", "-n", ranks, "partial-closure", *SMALL])
        huge = ["--set", "mesh.sigma_vertices=1000000000", "--set", "mesh.boundary_vertices=400000000"]
        self.case(3, "P = 1e9, M = 4e8 (consistent spacing)", "no output; +11 GB in 30 s; ended by timeout",
                  ["solve", "-n", "4", "partial-closure", *huge])
        self.case(3, "mesh command, P = 1e9, M = 4e8", "SIGTERM after 60 s ignored; killed at 70 s",
                  ["mesh", "partial-closure", *huge])
        process = subprocess.Popen([sys.executable, "-m", "ddsolve", "mesh", "partial-closure", "--set",
                                    "mesh.sigma_vertices=1600", "--set", "mesh.boundary_vertices=2048"],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=self.folder,
                                   stdin=subprocess.DEVNULL)
        time.sleep(4.0)
        sent = time.perf_counter()
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=300)
        self.rows[3].append(("SIGTERM during gmsh meshing (mesh, P = 1600, M = 2048)",
                             "ended 37 s after the signal (Python's handler waits for gmsh)",
                             f"exit {process.returncode}, {time.perf_counter() - sent:.1f} s after the signal: "
                             f"«{stderr.strip()}»"))

    def _files(self) -> None:
        self.folder.joinpath("c4-layer1.vtu").mkdir()
        self.case(4, "a viewer file of the set is a directory (the XDMF, before)", "exit 1, but the previous .h5 "
                  "already replaced", ["solve", "-n", "4", "partial-closure", *SMALL, "-o", "c4.h5"], kept=("c4",))
        for label, before, output in (
                ("-o c4.xdmf", "exit 0; the XDMF text written over the HDF5 result: the result is lost", "c4.xdmf"),
                ("-o the input scene file", "exit 0; the scene file overwritten with HDF5", "scene.toml"),
                ("-o '' (empty)", "exit 0; the default partial-closure.h5 replaced", "")):
            self.case(4, label, before, ["solve", "-n", "4", "scene.toml", *SMALL, "-o", output])
        os.link(self.folder / "clean.vtu", self.folder / "mesh.h5")
        self.case(4, "-o the scene's mesh file", "exit 0; the mesh file overwritten with HDF5",
                  ["solve", "-n", "4", "clean.toml", "-o", "mesh.h5"])
        os.mkfifo(self.folder / "fifo.h5")
        self.case(4, "-o a FIFO (a character device, before)", "exit 0; the device node replaced by a regular file",
                  ["solve", "-n", "4", "partial-closure", *SMALL, "-o", "fifo.h5"])
        self.rows[4].append(("SIGKILL during the write of the result set", "`.c4.11.h5.hm2vg6p2.tmp` left for good",
                             self._killed_write()))

    def _killed_write(self) -> str:
        """Kill a reference run as soon as its temporary file appears; then run again."""
        process = subprocess.Popen([sys.executable, "-m", "ddsolve", "reference", "partial-closure", "--set",
                                    "mesh.sigma_vertices=200", "--set", "mesh.boundary_vertices=256", "-o", "k.h5"],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=self.folder,
                                   stdin=subprocess.DEVNULL)
        deadline = time.perf_counter() + 300
        while not list(self.folder.glob(".k*.tmp*")) and process.poll() is None and time.perf_counter() < deadline:
            time.sleep(0.002)
        process.kill()
        process.wait()
        left = sorted(p.name.replace(socket.gethostname(), "HOST") for p in self.folder.glob(".k*"))
        completed, _ = self.run(["reference", "partial-closure", *SMALL, "-o", "k.h5"])
        after = sorted(p.name for p in self.folder.glob(".k*"))
        return (f"{len(left)} temporary file(s) left by the killed run ({', '.join(left) or 'none'}); the next "
                f"run (exit {completed.returncode}) removed them: {len(after)} left")

    def _messages(self) -> None:
        base = ["solve", "-n", "4", "partial-closure", *SMALL, "-o", "c5.h5"]
        self.case(5, "E1 = 1e308", "exit 3, 5 lines: numpy warnings, «schur: the exact solution has criterion nan, "
                  "above tol 1e-08»", [*base, "--set", "materials.layer1.E=1e308"])
        self.case(5, "mesh file with a NaN vertex", "exit 3: «criterion nan»; the file not named",
                  ["solve", "-n", "4", "nan.toml", "-o", "c5.h5"])
        self.case(5, "uzawa, E1 = 1e-30", "«block u_minus: KSP did not converge (reason -11)»",
                  [*base, "--set", "solver.method=uzawa", "--set", "materials.layer1.E=1e-30"])
        self.case(5, "crack 1e-12 long", "«generated mesh: upper half: 1 inverted or degenerate triangles»",
                  [*base, "--set", "geometry.crack=[0.1, 0.100000000001]"])
        self.case(5, "unknown factorization package", "«solver setup failed (PETSc error 92); is the block clamped?»",
                  [*base, "-u_minus_pc_factor_mat_solver_type", "nonsense"])
        self.case(5, "plot --scale 1e308", "exit 0 without a word", ["plot", "base.h5", "--scale", "1e308"])

    def _options(self) -> None:
        def method_and_file(output: str):
            def observe(completed: subprocess.CompletedProcess) -> str:
                from ddsolve.io import hdf5

                if not (self.folder / output).exists():
                    return f"; nothing written to {output}"
                result = hdf5.read(self.folder / output)
                return (f"; {output} written by {result.method} (tol {result.scene.solver.tol:g}, "
                        f"{len(result.lower.points)} lower-half vertices)")
            return observe

        self.case(6, "--set and -o after a PETSc option", "exit 0: schur ran (not mprgp), partial-closure.h5 "
                  "replaced, c6.h5 untouched", ["solve", "-n", "4", "partial-closure", *SMALL, "-u_minus_ksp_type",
                                                "preonly", "--set", "solver.method=mprgp", "-o", "c6.h5"],
                  observe=method_and_file("c6.h5"))
        self.case(6, "--set solver.tol after PETSc options", "exit 0; tol 1e-08 used, the --set ignored",
                  ["solve", "-n", "4", "partial-closure", *SMALL, "-o", "c6t.h5", "-u_minus_ksp_type", "cg",
                   "-u_minus_pc_type", "cholesky", "--set", "solver.tol=1e-12"], observe=method_and_file("c6t.h5"))
        for label, arguments, env in (("misspelt -u_minus_ksp_typo", ["-u_minus_ksp_typo", "cg"], None),
                                      ("misspelt prefix -uminus_ksp_type", ["-uminus_ksp_type", "cg"], None),
                                      ("misspelt option in PETSC_OPTIONS", [], {"PETSC_OPTIONS": "-v_plus_pc_tpye lu"})):
            self.case(6, label, "exit 0, not reported", ["solve", "-n", "4", "partial-closure", *SMALL, "-o", "c6m.h5",
                                                         *arguments], env=env)
        self.case(6, "reference: -o after a PETSc option", "exit 0; partial-closure.h5 written instead",
                  ["reference", "partial-closure", *SMALL, "-reference_ksp_type", "preonly", "-o", "c6r.h5"],
                  observe=method_and_file("c6r.h5"))
        self.case(6, "plot -scale 5", "exit 0; -scale silently ignored", ["plot", "base.h5", "-scale", "5"])
        self.case(6, "check base.h5 -bogus", "exit 0; -bogus silently ignored", ["check", "base.h5", "-bogus"])

    def section(self) -> list[str]:
        lines = ["", "## Hostile input, before and after", "",
                 "The inputs of issue 14, grouped by class. *Before* is what the previous code did, measured once "
                 "before the fixes (numbers quoted, not measured again); *after* is measured by `./run robustness` "
                 "on this code, from a scratch folder, on the P = 13, M = 32 mesh. Exit statuses: 0 success, "
                 "1 refused or failed (nothing written), 2 command-line usage, 3 not converged (result written with "
                 "converged = false), 4 diverged, 130 and 143 SIGINT and SIGTERM (`solve -n N` and `sweep -n N` too, "
                 "which supervise mpiexec; 0 when the signal came after the result set was in place; under your own "
                 "mpiexec, Open MPI's 1 or 143). The tests of each class are in "
                 "`tests/test_hostile_input.py`; `tests/test_fuzz.py` generates scenes, command lines and "
                 "corrupted result files, and `tests/test_convergence_claim.py` checks every converged result of "
                 "every method on the built-in scenes."]
        lines += self._classes(CLASSES)
        lines += ["", "## Hostile input, round 3", "",
                  "The inputs of issue 21, about 320 of them tried as a careful user would, grouped by class. *Before* "
                  "is what the code before the fixes did, measured once (quoted); *after* is measured by `./run "
                  "robustness` on this code. Each class has its tests in `tests/test_reliability_*.py`, each with a "
                  "hypothesis generator of the inputs that would have found it."]
        lines += self._classes(ROUND3)
        lines += ["", "## Hostile input, round 4", "",
                  "The inputs of issue 40: the surfaces added by prescribed displacements, thermal loads, toughness "
                  "laws, `grow` and the Python API, tried as a new user would, grouped by class. *Before* is what the "
                  "code before the fixes did, measured once (quoted); *after* is measured by `./run robustness` on "
                  "this code. Each class has its tests and a hypothesis generator of its inputs in "
                  "`tests/test_round4_*.py`."]
        lines += self._classes(round_classes(4))
        lines += ["", "## Hostile input, round 5", "",
                  ROUND5_INTRO]
        lines += self._classes(round_classes(5))
        return lines

    def _classes(self, classes: dict) -> list[str]:
        lines = []
        for number, (title, how) in classes.items():
            lines += ["", f"### {number % 100}. {title}", "", f"Fixed at the root: {how}.", "",
                      "| case | before (previous code) | after (measured) |", "|---|---|---|"]
            for label, before, after in self.rows[number]:
                lines.append(f"| {label} | {before} | {after.replace('|', '/')} |")
        return lines
