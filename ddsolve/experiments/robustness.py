"""Hard cases and bad input, measured (``ddsolve robustness`` writes docs/robustness.md).

Every case here is also an automated test (tests/test_robustness.py and tests/test_mpi.py); this
command records what each one measures on this machine: errors against the monolithic reference,
rounds, exit statuses, messages, times.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .. import scene as scenes

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
    from ..launch import mpiexec_command

    command = mpiexec_command(ranks, arguments) if ranks else [sys.executable, "-m", "ddsolve", *arguments]
    started = time.perf_counter()
    completed = subprocess.run(command, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL,
                               env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])},
                               cwd=folder)
    return completed, time.perf_counter() - started


class Cases:
    """Runs cases in a scratch folder and collects table rows."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.rows: list[tuple[str, str, str, str]] = []
        self.references: dict[tuple, object] = {}

    def _reference(self, name: str, overrides: tuple[str, ...]):
        from .. import io

        key = (name, overrides)
        if key not in self.references:
            path = self.folder / f"reference-{len(self.references)}.h5"
            settings = [item for setting in overrides for item in ("--set", setting)]
            completed, _ = _run(["reference", name, *_mesh(name), *settings, "-o", path.name], ranks=None,
                                folder=self.folder)
            if completed.returncode != 0:
                raise RuntimeError(completed.stderr)
            self.references[key] = io.read(path)
        return self.references[key]

    def against_reference(self, case: str, why: str, name: str, *settings: str, method: str = "schur",
                          test: str = "") -> None:
        """Solve with ``method`` on 4 ranks (``settings``: KEY=VALUE); the row shows rounds, error, penetration."""
        from .. import analysis, io

        path = self.folder / "dd.h5"
        overrides = [item for setting in (*settings, f"solver.method={method}") for item in ("--set", setting)]
        completed, _ = _run(["solve", name, *_mesh(name), *overrides, "-o", path.name], folder=self.folder)
        if completed.returncode != 0:
            self.rows.append((case, f"fails: {completed.stderr.strip()}", why, test))
            return
        result = io.read(path)
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


def interrupt(folder: Path, signum: int, wait: float = 6.0) -> dict:
    """Start a long run writing to ``folder/kept.h5`` (which holds a previous result), signal mpiexec.

    Returns the exit status, the seconds from the signal to the exit, the first line of standard
    error, whether the previous file survived and which temporary files are left in ``folder``.
    """
    from ..launch import mpiexec_command

    kept = folder / "kept.h5"
    kept.write_bytes(b"previous result")
    command = mpiexec_command(4, ["solve", "partial-closure", "--set", "solver.method=uzawa",
                                  "--set", "solver.stop=relative", "--set", "solver.tol=1e-300",
                                  "--set", "solver.max_iterations=10000000", "-o", str(kept)])
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               stdin=subprocess.DEVNULL, env=dict(os.environ))
    time.sleep(wait)  # well into the iterations
    running = process.poll() is None
    sent = time.perf_counter()
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=60)
    return {"running": running, "status": process.returncode, "seconds": time.perf_counter() - sent,
            "message": stderr.strip().splitlines()[0] if stderr.strip() else "",
            "traceback": "Traceback" in stderr, "kept": kept.read_bytes() == b"previous result",
            "leftovers": sorted(p.name for p in folder.iterdir() if p.name != "kept.h5")}


def _mesh_file(folder: Path, name: str, points, cells) -> Path:
    import meshio

    path = folder / f"{name}.vtu"
    meshio.write(path, meshio.Mesh(points, [("triangle", cells)]))
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
    with tempfile.TemporaryDirectory() as scratch:
        cases = Cases(Path(scratch))
        measure(cases, Path(scratch))
    lines = ["# Robustness", "",
             "`./run robustness` (about 3 minutes) measures every case below and rewrites this page; each one is "
             "also an automated test in `./run test` (last column). Solves run on 4 ranks, on the P = 48, M = 80 "
             "mesh unless the case says otherwise; errors are relative energy-norm errors against the monolithic "
             "reference, penetration is max (u⁻ − u⁺)·ν / max |u|.", "",
             "| case | measured outcome | why | test |", "|---|---|---|---|"]
    for case, outcome, why, test in cases.rows:
        lines.append(f"| {case} | {outcome.replace('|', '/')} | {why} | {test} |")
    lines += ["", "The scene parser is also fuzzed with hypothesis (random `--set` items, random text, shuffled "
              "lines of a valid scene: 800 examples per run of `./run test`): every input either parses or "
              "raises a one-line scene error — no other exception (`test_*_never_raise_anything_but_scene_errors`). "
              "The fuzzer found one real bug, an override containing a newline whose error message spanned two "
              "lines; user text is now escaped in every message."]
    (DOCS / "robustness.md").write_text("\n".join(lines) + "\n")


def measure(cases: Cases, folder: Path) -> None:
    t = "`test_robustness.py::"
    # --- numerically hard
    cases.fails("`uzawa`, θ = 65, crack fully closed", "θ above the stable bound 2/λmax = 58.1 of this mesh: with "
                "every contact multiplier active the full dual operator applies; divergence is detected from the "
                "growth of the multiplier steps",
                ["solve", "full-closure", *MESH, "--set", "solver.method=uzawa", "-o", "x.h5"],
                test=t + "test_uzawa_above_the_stable_bound_with_a_closed_crack`")
    cases.fails("`uzawa`, θ = 200", "far above the bound: detected within a few iterations",
                ["solve", "partial-closure", *MESH, "--set", "solver.method=uzawa", "--set", "solver.theta=200",
                 "-o", "x.h5"], test="`test_mpi.py::test_divergence_stops_early_and_keeps_the_previous_file`")
    cases.against_reference("default method, θ = 200 in the scene", "the default method needs no θ and ignores it",
                            "partial-closure", "solver.theta=200", test="")
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
    # --- bad input
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
