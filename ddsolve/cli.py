"""Command line: ``python -m ddsolve COMMAND ...`` (``./run COMMAND ...`` prepares the environment).

ddsolve's own options may come anywhere; every other single-dash option of ``solve``, ``reference``,
``version`` and ``bench`` is PETSc's (with the next word as its value unless that is an option),
e.g. ``ddsolve solve partial-closure -u_minus_ksp_type cg -u_minus_pc_type gamg -log_view -o r.h5``;
everything after ``--`` is PETSc's.  Commands without PETSc refuse unknown options.  PETSc options
that nothing read are reported when the run ends, as PETSc's ``-options_left`` does.
"""
from __future__ import annotations

import argparse
import codecs
import contextlib
import difflib
import faulthandler
import importlib
import math
import os
import signal
import socket
import sys
import threading
import time
import traceback
import unicodedata
from pathlib import Path

from . import __version__
from .environment import import_errors_explained
from .errors import DDSolveError, NotConvergedError, SceneError, UsageError
from .launch import end_with_launcher, end_with_parent, mpiexec_command

#: Commands that hand options to PETSc.
PETSC_COMMANDS = ("solve", "sweep", "reference", "version", "bench")
#: Options-prefixes of the KSPs (what a misspelt option is compared with).
PREFIXES = {"solve": ("u_minus_", "u_plus_", "v_minus_", "v_plus_"), "reference": ("reference_",)}
PREFIXES["sweep"] = PREFIXES["solve"]
#: Memory a rank needs before it holds any mesh (Python, numpy, PETSc, MPI), and per mesh vertex for
#: a solve (assembly, factorizations, Schur complements; measured with 4 ranks at P = 400, M = 512).
RANK_MEMORY = 100e6
VERTEX_MEMORY = 15e3
#: Suffix of the files ``mesh -o`` writes (gmsh chooses the format by the suffix).
MESH_SUFFIX = ".msh"


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit status 2) instead of a usage block."""

    def error(self, message: str):
        command = self.prog.removeprefix("ddsolve").strip()
        raise UsageError(f"{command + ': ' if command else ''}{message} (see {self.prog} --help)")


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _subcommands(top: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    return next(action.choices for action in top._actions if isinstance(action, argparse._SubParsersAction))


def split_arguments(top: argparse.ArgumentParser, argv: list[str], petsc_commands: tuple[str, ...] = PETSC_COMMANDS
                    ) -> tuple[list[str], list[str]]:
    """(ddsolve's arguments, PETSc's options), wherever the user typed them.

    An option of the command (and its value) is ddsolve's; any other single-dash word that is not a
    number starts a PETSc option, whose value is the next word unless that is an option; ``--``
    hands everything after it to PETSc.  A command without PETSc options refuses them.
    """
    command = next((arg for arg in argv if not arg.startswith("-")), None)
    sub = _subcommands(top).get(command)
    if sub is None:
        return list(argv), []
    options = sub._option_string_actions
    own: list[str] = []
    petsc: list[str] = []
    i = 0
    while i < len(argv):
        arg = argv[i]
        if arg == "--":
            petsc += argv[i + 1:]
            break
        name = arg.split("=", 1)[0] if arg.startswith("--") else arg
        glued = len(arg) > 2 and arg[:2] in options and _is_number(arg[2:])  # -n4
        if name in options or glued:
            own.append(arg)
            takes_value = not glued and "=" not in arg and options[name].nargs != 0
            if takes_value and i + 1 < len(argv):
                own.append(argv[i + 1])
                i += 1
        elif arg.startswith("-") and not arg.startswith("--") and len(arg) > 1 and not _is_number(arg):
            petsc.append(arg)
            if i + 1 < len(argv) and argv[i + 1] != "--" and (not argv[i + 1].startswith("-")
                                                             or _is_number(argv[i + 1])):
                petsc.append(argv[i + 1])
                i += 1
        else:
            own.append(arg)
        i += 1
    if petsc and command not in petsc_commands:
        close = difflib.get_close_matches(petsc[0], list(options), n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise UsageError(f"{command}: unknown option {petsc[0]}{hint}; {command} takes no PETSc options")
    return own, petsc


def init_petsc(options: list[str]) -> None:
    """PETSc without its signal handler: on a crash (SIGSEGV...) it calls MPI_Abort inside the handler,
    which can deadlock the crashed rank and with it the whole job; without it the rank dies of the
    signal (after Open MPI's backtrace) and mpiexec ends the others."""
    import petsc4py

    petsc4py.init([sys.argv[0], "-no_signal_handler", *options])
    from petsc4py import PETSc  # noqa: F401 -- PETSc starts here

    # A closed pipe on standard output is an error to report in one line (EPIPE), not a death by SIGPIPE.
    signal.signal(signal.SIGPIPE, signal.SIG_IGN)


def _root_print(*args, **kwargs) -> None:
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        print(*args, **kwargs, flush=True)


def _load_scene(args, ranks: int = 1):
    """The scene of ``args`` (with its ``--set`` items, each of which the command must read)."""
    from . import scene

    loaded = scene.load(args.scene, args.set or [])
    check_read(args.command, args.set or [], loaded, ranks)
    return loaded


def _default_output(args) -> Path:
    return Path(args.output) if args.output is not None else Path(Path(args.scene).stem + ".h5")


def _physical_memory() -> float:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return math.inf


def check_ranks(ranks: int) -> None:
    """Refuse a rank count ddsolve cannot use, or that this machine cannot start, before mpiexec."""
    from .launch import supported

    if not supported(ranks):
        raise UsageError(f"-n {ranks}: unsupported number of ranks: use 1, 2 or a multiple of 4")
    memory = ranks * RANK_MEMORY
    if memory > _physical_memory():
        raise UsageError(f"-n {ranks}: {ranks} ranks need about {memory / 1e9:.3g} GB before any mesh "
                         f"(about {RANK_MEMORY / 1e6:g} MB each), more than this machine's "
                         f"{_physical_memory() / 1e9:.3g} GB; for ranks on several machines start mpiexec yourself")


def check_size(scene, ranks: int = 1) -> None:
    """Refuse a mesh that cannot fit in this machine's memory, before it is made."""
    from . import geometry

    vertices = geometry.estimated_vertices(scene)
    if vertices is None:
        return
    memory = ranks * RANK_MEMORY + vertices * VERTEX_MEMORY
    if memory > _physical_memory():
        options = scene.mesh
        keys = (f"mesh.size = {options.size:g}" if options.size is not None else
                f"mesh.sigma_vertices = {options.sigma_vertices}, mesh.boundary_vertices = {options.boundary_vertices}")
        raise DDSolveError(f"{keys}: a mesh of about {vertices:.2g} vertices needs about {memory / 1e9:.2g} GB "
                           f"to solve (about {VERTEX_MEMORY / 1e3:g} kB per vertex), more than this machine's "
                           f"{_physical_memory() / 1e9:.3g} GB")


#: The sections of a scene that ``mesh`` does not read, besides mesh.target_error.
NOT_MESHING = ("title", "materials", "loads", "contact", "solver", "fracture")
#: Material keys that give only the out-of-plane stress or strain (``plane_stress``: E3, nu13 and nu23;
#: ``plane_strain``: Dzz), which a sweep file does not keep.
OUT_OF_PLANE = {"plane_stress": ("E3", "nu13", "nu23", "Dzz"), "plane_strain": ("Dzz",)}


def unread(command: str, path: list[str], scene, ranks: int) -> str | None:
    """Why ``command`` on ``ranks`` ranks would not read the key ``path`` of ``scene`` (None: it does)."""
    from .interface import BLOCKS

    section, leaf = path[0], path[2:3]
    if command == "mesh":
        if section in NOT_MESHING or path[:2] == ["mesh", "target_error"]:
            return "mesh makes the starting mesh only (solve, reference and sweep read the key)"
        return None
    if section == "solver" and command == "reference":
        return None if path[1:] == ["p"] else ("it sets how solve and sweep iterate, and reference solves the "
                                               "discrete problem exactly")
    if section == "materials" and leaf == ["Dzz"] and scene.model == "plane_stress":
        return "Dzz gives the out-of-plane stress of plane strain, and materials.model = plane_stress has none"
    if command == "sweep" and (section == "title" or section == "materials" and leaf
                               and leaf[0] in OUT_OF_PLANE[scene.model]):
        return ("a sweep file keeps no title" if section == "title" else "it gives only the out-of-plane stress or "
                "strain, which a sweep file does not keep (solve and reference write it)")
    if section == "solver":
        method = scene.solver.method
        if method == "auto" and ranks // len(BLOCKS) <= 1:  # whole blocks: auto is schur
            method = "schur"
        if path[1:] == ["theta"] and method != "uzawa":
            return f"it is the step of method uzawa, and method {method} takes none"
        if path[1:] == ["max_iterations"] and method == "schur":
            return "method schur is exact in a few rounds and iterates no further (uzawa, mprgp, fista and feti do)"
    return None


def check_read(command: str, items: list[str], scene, ranks: int = 1) -> None:
    """Refuse a ``--set`` item whose key (or a key of the table it sets) ``command`` would not read
    (:func:`unread`): every key a command is given is honoured or refused."""
    from .scene import parse_override, printable

    def leaves(path: list[str], value) -> list[list[str]]:
        if isinstance(value, dict) and value:
            return [leaf for key, sub in value.items() for leaf in leaves([*path, key], sub)]
        return [path]

    for item in items:
        for path in leaves(*parse_override(item)):
            why = unread(command, path, scene, ranks)
            if why is not None:
                raise SceneError(f"--set {printable(item)}: {printable('.'.join(path))} is not read by {command}: "
                                 f"{why}; leave it out")


def nodes_in_memory(ranks: int) -> float:
    """The most mesh nodes a solve on ``ranks`` ranks holds in this machine's memory (as in check_size)."""
    return max(_physical_memory() - ranks * RANK_MEMORY, 0.0) / VERTEX_MEMORY


def _inputs(args, scene) -> list[Path]:
    """The files a run reads: the scene file and its mesh or geometry file."""
    return [path for path in (Path(args.scene), scene.mesh.file) if path is not None and path.is_file()]


def check_outputs(args, scene) -> Path:
    """The result file of ``solve``/``reference`` and its viewer files, checked before any work."""
    from . import io

    output = _default_output(args)
    if not output.name:
        raise DDSolveError(f"-o {str(args.output)!r}: not a file name")
    io.check_result(output, _inputs(args, scene))
    return output


def report_unused_options(comm, command: str) -> None:
    """A PETSc ``-options_left``-style warning on rank 0: the options no rank read (misspelt ones)."""
    from .blocks import unused_options

    left = unused_options()
    every = comm.gather(left, root=0) if comm is not None else [left]
    if every is None or any(options is None for options in every):
        return
    common = [option for option in every[0] if all(option in other for other in every[1:])]
    if common:
        print(f"ddsolve: warning: PETSc options not used (misspelt? the prefixes here are "
              f"{', '.join(PREFIXES[command])}): {', '.join(common)}", file=sys.stderr, flush=True)


# --- commands -------------------------------------------------------------------------------
def _launch(args, petsc_options: list[str], scene_checks: bool) -> None:
    """With ``-n N``: check what can be checked here (the rank count, the modules, and with
    ``scene_checks`` the scene, the mesh size and the output files), then run mpiexec running the same
    command on N ranks and end this process with its status (:func:`_supervise`)."""
    if args.ranks is None:
        return
    check_ranks(args.ranks)
    for module in ("petsc4py", "mpi4py", "h5py"):  # if one is missing, one line here, not one per rank
        importlib.import_module(module)
    from . import export

    if scene_checks:
        scene = _load_scene(args, args.ranks)
        check_size(scene, args.ranks)
        output = check_outputs(args, scene)
        outputs = [output, *export.viewer_paths(output.parent, output.stem)]
    else:
        outputs = [_sweep_output(args)]
    forwarded = [arg for i, arg in enumerate(args.own) if i not in args.ranks_at]
    command = mpiexec_command(args.ranks, forwarded + (["--", *petsc_options] if petsc_options else []))
    sys.exit(_supervise(command, {**os.environ, "DDSOLVE_LAUNCHED": repr(time.time())}, outputs))  # start-up timing


def _sweep_output(args) -> Path:
    return Path(args.output) if args.output else Path(Path(args.scene).stem + "-sweep.h5")


def _supervise(command: list[str], env: dict, outputs: list[Path]) -> int:
    """Run the ranks' mpiexec and return its exit status.  SIGINT and SIGTERM are passed on to it once
    (Open MPI then stops every rank); afterwards the result set ``outputs`` is made whole if a rank was
    killed while renaming it (:func:`ddsolve.io.recover`), and the status is 0 if the run replaced it
    (the signal came after its commit: the set is complete), else 130 or 143."""
    import subprocess

    from . import io

    def identity(path: Path):
        try:
            info = os.stat(path, follow_symlinks=False)
            return info.st_ino, info.st_mtime_ns, info.st_size
        except OSError:
            return None

    before = identity(outputs[0])
    signal.set_wakeup_fd(-1)  # the watchdog stays asleep: this process only waits for mpiexec
    launcher = os.getpid()  # mpiexec gets SIGTERM (and stops the ranks) when this process ends, however
    job = subprocess.Popen(command, env=env, start_new_session=True,
                           preexec_fn=lambda: end_with_parent(launcher, signal.SIGTERM))
    received: list[int] = []

    def forward(signum, _frame) -> None:
        if not received:
            job.send_signal(signum)
        received.append(signum)

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, forward)
    status = job.wait()
    io.recover(outputs)
    if received:
        return 0 if identity(outputs[0]) != before else (143 if received[0] == signal.SIGTERM else 130)
    return status if status >= 0 else 128 - status


def cmd_solve(args, petsc_options: list[str]) -> int:
    _launch(args, petsc_options, scene_checks=True)
    init_petsc(petsc_options)
    from mpi4py import MPI

    from . import adapt, driver
    from .exchange import collective

    comm = MPI.COMM_WORLD
    scene = collective(comm, lambda: _load_scene(args, comm.size), root_only=True)
    scene = comm.bcast(scene, root=0)
    output = collective(comm, lambda: (check_size(scene, comm.size), check_outputs(args, scene))[1], root_only=True)
    output = comm.bcast(output, root=0)
    try:
        solve = adapt.solve if scene.mesh.target_error is not None else driver.solve
        result = solve(scene, comm, output, progress=_root_print)
    except DDSolveError as exc:
        if exc.collective:  # every rank is here: the others are not waiting in a solve
            report_unused_options(comm, "solve")
        raise
    report_unused_options(comm, "solve")
    if result is not None:
        print(f"{result.method}: converged after {result.iterations} iterations, {result.solves} rounds of "
              f"block solves, {result.wall_time:.3f} s on {result.ranks} ranks -> {output}", flush=True)
        print(estimate_line(result), flush=True)
        _print_fracture(result)
    return 0


def _print_fracture(result) -> None:
    """G at every crack tip and the contact zones, after a solve."""
    for line in result.fracture.lines() if result.fracture is not None else []:
        print(line, flush=True)


def cmd_sweep(args, petsc_options: list[str]) -> int:
    _launch(args, petsc_options, scene_checks=False)
    init_petsc(petsc_options)
    import time

    from mpi4py import MPI

    from . import sweep

    started = time.perf_counter()
    output = _sweep_output(args)
    records = sweep.sweep(args.scene, args.set or [], args.zip, output, MPI.COMM_WORLD, progress=_root_print)
    if records is not None:
        converged = sum(bool(r["converged"]) for r in records)
        meshes = sum(not r["mesh_reused"] for r in records)
        factored = sum(not r["factors_reused"] for r in records)
        print(f"sweep: {len(records)} runs ({converged} converged), {meshes} meshes, {factored} factorizations, "
              f"{time.perf_counter() - started:.1f} s on {MPI.COMM_WORLD.size} ranks -> {output}", flush=True)
    return 0


def cmd_reference(args, petsc_options: list[str]) -> int:
    init_petsc(petsc_options)
    from . import geometry, io, reference
    from .scene import check_range

    scene = _load_scene(args)
    check_size(scene)
    output = check_outputs(args, scene)
    if scene.mesh.target_error is not None:  # adaptive, every level solved by the reference
        from mpi4py import MPI

        from . import adapt

        result = adapt.solve(scene, MPI.COMM_SELF, output, progress=_root_print,
                             level=lambda mesh: reference.solve(scene, mesh))
    else:
        mesh = geometry.build(scene)
        geometry.check_loads(scene, mesh)
        check_range(scene, mesh)
        result = reference.solve(scene, mesh)
        io.write(output, result, final=True)
    report_unused_options(None, "reference")
    if not result.converged:
        raise NotConvergedError(result.message)
    print(f"reference: {result.iterations} active-set steps, {result.wall_time:.3f} s -> {output}")
    print(estimate_line(result))
    _print_fracture(result)
    return 0


def estimate_line(result) -> str:
    """The estimated discretization error of a result, in one line."""
    unknowns = 4 * (len(result.lower.points) + len(result.upper.points))
    return (f"estimated discretization error {100 * result.attrs['error_estimate']:.3g} % (relative, energy norm; "
            f"{unknowns} unknowns, P{result.mesh.degree})")


def cmd_compare(args, _petsc_options) -> int:
    from . import analysis, io

    result, reference = io.read(args.result), io.read(args.reference)
    comparison = analysis.compare(result, reference, (args.result, args.reference))
    print(f"relative energy-norm error {comparison.energy_error:.3e}   "
          f"max nodal difference {comparison.max_difference:.3e} (max |u| {comparison.max_displacement:.3e})"
          + ("" if analysis.same_meshes(result, reference) else "   (on the reference's mesh)"))
    return 0


def cmd_check(args, _petsc_options) -> int:
    from . import analysis, io

    result = io.read(args.result)
    c = analysis.constraints(result)
    tolerance = analysis.tolerance_of(result)
    violations = c.violations(tolerance)
    print(f"{c.summary()}   (scale-free: relative to max |u| = {c.max_displacement:.3e}, max |mu|, ||K|| ||x||); "
          f"min mu_c {c.min_mu_c:.3e}")
    claim = f"the file says converged = {str(result.converged).lower()}"
    if violations:
        raise NotConvergedError(f"{args.result}: KKT check failed: {', '.join(violations)} above the tolerance "
                                f"{tolerance:g} ({claim})")
    print(f"KKT check passed: every residual within {tolerance:g} ({claim})")
    return 0


def _scale(text: str | None) -> float | None:
    """The --scale option: None (from the data) or a finite positive number."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (math.isfinite(value) and value > 0.0):
        raise DDSolveError(f"--scale {text}: must be a finite positive number")
    return value


#: The largest displacement ``plot --scale`` may draw, in domain sizes.
MAX_DRAWN = 100.0


def cmd_plot(args, _petsc_options) -> int:
    import io as memory

    import numpy as np

    from . import analysis, io, plots

    scale = _scale(args.scale)
    result = io.read(args.result)
    stem = Path(args.result).with_suffix("")
    if scale is not None:
        points = np.vstack([result.lower.points, result.upper.points])
        drawn = scale * analysis.largest_displacement(result.solution.values()) / np.ptp(points, axis=0).max()
        if not drawn <= MAX_DRAWN:
            raise DDSolveError(f"--scale {args.scale}: draws the largest displacement at {drawn:.3g} times the "
                               f"domain's size (at most {MAX_DRAWN:g}); leave --scale out to choose it from the data")
    names = [Path(f"{stem}-{name}.png") for name in ("deformed", "crack-faces", "convergence")]
    images = [memory.BytesIO() for _ in names]
    scale = plots.deformed_layers(result, images[0], scale)
    plots.crack_faces(result, images[1])
    plots.convergence([(result.method, result)], images[2])
    io.check_targets(names, [Path(args.result)])
    io.replace_together({path: (lambda name, data=image.getvalue(): Path(name).write_bytes(data))
                         for path, image in zip(names, images)}, final=True)
    print(f"wrote {', '.join(map(str, names))} (displacements ×{scale:g})")
    return 0


def cmd_export(args, _petsc_options) -> int:
    from . import export, io

    result = io.read(args.result)
    folder = Path(args.output) if args.output is not None else Path(args.result).parent
    if not folder.is_dir():
        raise DDSolveError(f"-o {folder}: " + ("is a file, not a folder: give -o the folder for the viewer files"
                                               if folder.exists() else "no such directory"))
    stem = Path(args.result).stem
    io.check_targets(export.viewer_paths(folder, stem, args.format), [Path(args.result)])
    written = io.write_viewer(result, folder, stem, args.format, final=True)
    print("wrote " + ", ".join(map(str, written)))
    return 0


def cmd_mesh(args, _petsc_options) -> int:
    from . import geometry, io, mesh as meshes

    if args.output is not None and Path(args.output).suffix != MESH_SUFFIX:
        raise DDSolveError(f"-o {args.output}: the mesh command writes one format, gmsh MSH 4.1 with physical "
                           f"groups: give -o a file name with the suffix {MESH_SUFFIX} (e.g. halves{MESH_SUFFIX})")
    scene = _load_scene(args)
    check_size(scene)
    if args.output is not None:
        io.check_targets([Path(args.output)], _inputs(args, scene))
    mesh = geometry.build(scene)
    print(f"{'half':6s} {'h_min':>8s} {'h_max':>8s} {'vertices':>9s} {'nodes':>9s} {'triangles':>10s} {'min angle':>9s}")
    for half in mesh.halves:
        s = meshes.statistics(half)
        print(f"{half.name:6s} {s.h_min:8.4f} {s.h_max:8.4f} {s.vertices:9d} {len(half.points):9d} {s.triangles:10d} "
              f"{s.min_angle:9.1f}")
    print(f"Σ vertices {int(mesh.sigma.corner.sum())}, boundary vertices {meshes.boundary_vertex_count(mesh)}, "
          f"degree {mesh.degree}, boundaries: {', '.join(mesh.boundary_names())}")
    if args.output is not None:
        io.atomic(Path(args.output), lambda name: geometry.write_msh(mesh, Path(name)), final=True)
        print(f"wrote {args.output} (gmsh, physical groups lower, upper, {', '.join(sorted(mesh.lower.boundaries.keys() | mesh.upper.boundaries.keys()))})")
    return 0


def _meshes(text: str | None):
    from .experiments.bench import BENCH_MESHES

    if not text:
        return BENCH_MESHES
    try:
        return tuple(tuple(int(v) for v in pair.split(":")) for pair in text.split(","))
    except ValueError:
        raise DDSolveError(f"--meshes {text}: expected P:M pairs separated by commas, e.g. 48:80,96:144") from None


def cmd_bench(args, petsc_options) -> int:
    from .experiments import bench

    if args.what == "factor":
        init_petsc(petsc_options)
        for P, M in _meshes(args.meshes or "200:256"):
            bench.factor(P, M)
    elif args.what == "baseline":
        bench.baseline(_meshes(args.meshes or "400:512,800:1024"), ranks=args.ranks, repeats=args.repeats,
                       busy=args.busy)
    else:
        bench.methods(_meshes(args.meshes), Path(args.output), Path("docs"))
        print(f"wrote {args.output}, docs/results.md (bench-methods section), docs/bench-methods.png")
    return 0


#: Experiments: command -> (module, function, one-line summary, what it writes).
EXPERIMENTS = {
    "table1": ("paper", "table1", "the paper's Table 1: meshes, the paper's algorithm and the default method",
               "docs/results.md (table1)"),
    "theta-sweep": ("paper", "theta_sweep", "Uzawa's iterations against its step θ",
                    "docs/results.md (theta-sweep), docs/theta-sweep.png"),
    "figures": ("paper", "figures", "the paper's figures: deformed layers, normal jump along Σ",
                "docs/results.md (figures), docs/fig*.png"),
    "accuracy": ("accuracy", "accuracy", "error against the continuous solution: uniform, graded, adaptive, P1, P2",
                 "docs/results.md (accuracy), docs/accuracy.png, results/accuracy.h5"),
    "scaling": ("scaling", "scaling", "strong and weak scaling, P = 800 and 1600, a fitted cost model",
                "docs/scaling.md, docs/scaling-*.png, results/scaling.h5"),
    "robustness": ("robustness", "robustness", "every hard case and bad input, measured", "docs/robustness.md"),
    "gallery": ("gallery", "gallery", "structures beyond the paper's square, solved and drawn",
                "docs/gallery.md, docs/gallery-*.png, results/gallery/"),
    "fracture": ("fracture", "fracture", "G at the crack tips: finite differences, radii, a plate; G against "
                 "crack length and E2/E1", "docs/fracture.md, docs/fracture-*.png, results/fracture-*"),
}


def cmd_experiment(args, _petsc_options) -> int:
    module, function, _, written = EXPERIMENTS[args.command]
    getattr(importlib.import_module(f".experiments.{module}", __package__), function)()
    print(f"wrote {written}")
    return 0


def cmd_scenes(_args, _petsc_options) -> int:
    from . import scene

    for name, text in sorted(scene.builtin_scenes().items()):
        print(f"{name:18s} {scene.loads(text).title}")
    return 0


def cmd_version(_args, petsc_options) -> int:
    init_petsc(petsc_options)
    from mpi4py import MPI
    from petsc4py import PETSc

    from .blocks import default_factor_package

    petsc = ".".join(map(str, PETSc.Sys.getVersion()))
    print(f"ddsolve {__version__}; PETSc {petsc} (factorization: {default_factor_package()}); "
          f"{MPI.Get_library_version().replace(chr(0), '').splitlines()[0].strip()}")
    return 0


def parser() -> argparse.ArgumentParser:
    """The command line; ``ddsolve --help`` lists the commands (the epilog), experiments apart."""
    top = Parser(prog="ddsolve", description="Domain decomposition (PETSc/MPI) for a two-layer "
                                  "elastic structure with a non-penetrating crack.",
                                  formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = top.add_subparsers(dest="command", required=True, metavar="COMMAND",
                             help="one of the commands below (`ddsolve COMMAND --help` for its options)")
    listing: dict[str, list[tuple[str, str]]] = {}

    def command(name: str, summary: str, run, group: str = "commands", details: str = "") -> argparse.ArgumentParser:
        listing.setdefault(group, []).append((name, summary))
        p = sub.add_parser(name, description=summary + details)
        p.set_defaults(run=run)
        return p

    def scene_command(name: str, summary: str, run) -> argparse.ArgumentParser:
        p = command(name, summary, run)
        p.add_argument("scene", help="scene file or built-in scene name (see `ddsolve scenes`)")
        p.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a scene entry")
        return p

    p = scene_command("solve", "domain-decomposition solve (under mpiexec, or -n N to launch it)", cmd_solve)
    p.add_argument("-n", dest="ranks", type=int, metavar="N",
                   help="launch N ranks with mpiexec: 1, 2, 4 (a block per rank) or 4k (a block on k ranks)")
    p.add_argument("-o", dest="output", help="result file (default: SCENE.h5)")
    p = scene_command("sweep", "solves over ranges of scene values (--set KEY=START:STOP:COUNT), one launch, "
                      "one HDF5 file", cmd_sweep)
    p.add_argument("-n", dest="ranks", type=int, metavar="N", help="launch N ranks with mpiexec (as for solve)")
    p.add_argument("-o", dest="output", help="HDF5 file of every run (default: SCENE-sweep.h5)")
    p.add_argument("--zip", action="store_true",
                   help="take the ranges side by side (same COUNT) instead of every combination")
    p = scene_command("reference", "monolithic reference solve (one process)", cmd_reference)
    p.add_argument("-o", dest="output", help="result file (default: SCENE.h5)")
    p = scene_command("mesh", "mesh statistics per half (as the paper's Table 1); -o writes the mesh as gmsh .msh",
                      cmd_mesh)
    p.add_argument("-o", dest="output", help="write the mesh as a gmsh .msh file with physical groups")
    p = command("compare", "energy-norm error of a result against a reference result", cmd_compare)
    p.add_argument("result")
    p.add_argument("reference")
    p = command("check", "constraint residuals of a result (penetration, gluing gap, complementarity)", cmd_check)
    p.add_argument("result")
    p = command("plot", "PNG pictures of a result (deformed layers, crack faces, convergence)", cmd_plot)
    p.add_argument("result")
    p.add_argument("--scale", help="displacement magnification, a positive number (default: from the data)")
    p = command("export", "viewer files of a result for ParaView and meshio (layers, Σ, a ParaView script)",
                cmd_export)
    p.add_argument("result")
    p.add_argument("--format", choices=("vtu", "xdmf"), default="vtu", help="file format (default: vtu)")
    p.add_argument("-o", dest="output", metavar="DIR", help="folder for the files (default: the result's)")
    command("scenes", "list the built-in scenes", cmd_scenes)
    command("version", "versions of ddsolve, PETSc and MPI", cmd_version)

    experiments = "experiments (each reruns its measurements and rewrites its part of docs/ and results/)"
    for name, (_, _, summary, written) in EXPERIMENTS.items():
        command(name, summary, cmd_experiment, experiments, f"; writes {written}")
    p = command("bench", "`bench methods`: every method and tolerance; `bench baseline`: the default method against "
                "one MUMPS factorization of the whole problem; `bench factor`: block factorizations", cmd_bench, experiments)
    p.add_argument("what", choices=("methods", "baseline", "factor"))
    p.add_argument("--meshes", help="comma-separated P:M pairs (default: Table 1 and 400:512; baseline: 400:512,800:1024)")
    p.add_argument("-n", dest="ranks", type=int, metavar="N", help="ranks of the DD in `bench baseline` (default: 4, or fewer if there are fewer cores)")
    p.add_argument("--repeats", type=int, default=3, help="side-by-side pairs per case in `bench baseline`")
    p.add_argument("--busy", action="store_true", help="`bench baseline` with a second process keeping a core busy")
    p.add_argument("-o", dest="output", default="results/bench-methods.h5", help="HDF5 file for `methods`")

    width = max(len(name) for commands in listing.values() for name, _ in commands) + 2
    top.epilog = "\n\n".join(group + ":\n" + "\n".join(f"  {name:{width}s}{summary}" for name, summary in commands)
                              for group, commands in listing.items())
    top.epilog += ("\n\nPETSc options (solve, reference) may come anywhere after the scene: ddsolve solve SCENE "
                   "-u_minus_ksp_type cg -u_minus_pc_type gamg -log_view")
    return top


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that temporary files are removed on the way out."""


def _terminate(signum, _frame) -> None:
    raise Terminated(signal.Signals(signum).name)


#: Seconds an interrupt may wait for the main thread (busy in a library call: gmsh, a factorization,
#: a blocking MPI call) before the watchdog stops the process itself.
INTERRUPT_GRACE = 3.0
#: Seconds MPI_Abort may take before the process ends itself (Abort waits for mpiexec, which may not answer).
ABORT_GRACE = 2.0


def _watch_interrupts() -> None:
    """Make every phase interruptible: Python runs signal handlers only between bytecodes, so a signal
    that arrives during a long library call waits for it.  The signal's byte on the wakeup fd wakes
    this thread at once; if the process is still alive INTERRUPT_GRACE seconds later, it reports,
    removes the temporary files being written and ends the job itself."""
    try:
        reader, writer = socket.socketpair()
        writer.setblocking(False)
        signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    except (ValueError, OSError):  # not the main thread: nothing to watch
        return

    def watch() -> None:
        signum = 0
        while signum not in (signal.SIGINT, signal.SIGTERM):
            signum = reader.recv(1)[0]
        time.sleep(INTERRUPT_GRACE)
        status = 143 if signum == signal.SIGTERM else 130
        try:  # whatever fails here (a closed standard error, an Abort that hangs), the process ends
            if "ddsolve.io" in sys.modules:
                sys.modules["ddsolve.io"].COMMIT.acquire()  # a set being renamed into place is finished first
                sys.modules["ddsolve.io"].remove_scratch()
            status = _interrupted_status(status)
            _abort(status, alone=True)
        finally:
            os._exit(status)

    threading.Thread(target=watch, name="ddsolve-interrupts", daemon=True).start()
    _watch_interrupts.sockets = (reader, writer)  # keep them open


def _interrupted_status(status: int) -> int:
    """Report an interrupt; its exit status, or 0 if the result files that end the command were
    already in place (they are complete)."""
    io = sys.modules.get("ddsolve.io")
    if io is not None and io.committed:
        _report("ddsolve: " + ("terminated" if status == 143 else "interrupted") + " after its result files "
                "were written (they are complete)")
        return 0
    _report("ddsolve: terminated" if status == 143 else "ddsolve: interrupted")
    return status


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    return guarded(lambda: _dispatch(argv))


def _dispatch(argv: list[str]) -> int:
    top = parser()
    own, petsc_options = split_arguments(top, argv)
    try:
        args = top.parse_args(own)
    except UsageError as exc:
        if petsc_options and "required" in str(exc):
            raise UsageError(f"{exc}; a PETSc option takes the next word as its value ({' '.join(petsc_options[:2])}): "
                             "give the scene first") from None
        raise
    except SystemExit as exc:  # --help: its text is printed; the final flush tells whether it was written
        return int(exc.code or 0)
    args.own = own
    args.ranks_at = _ranks_positions(own)
    return args.run(args, petsc_options)


def _ranks_positions(own: list[str]) -> set[int]:
    """Where ``-n N`` (or ``-n4``) is in ddsolve's arguments (removed when the ranks are started).
    Given twice, a usage error: the one left behind would make every rank launch ranks again."""
    found = [{i, i + 1} if arg == "-n" else {i} for i, arg in enumerate(own)
             if arg == "-n" or (arg.startswith("-n") and _is_number(arg[2:]))]
    if len(found) > 1:
        given = ", ".join(" ".join(own[j] for j in sorted(at)) for at in found)
        raise UsageError(f"-n given {len(found)} times ({given}): give the number of ranks once")
    return found[0] if found else set()


def guarded(call) -> int:
    """Run a command: a DDSolveError (or a missing petsc4py, mpi4py, h5py, gmsh...) becomes one line
    and its exit status, an interrupt or SIGTERM stops every rank, anything else is a bug (one
    traceback, abort)."""
    end_with_launcher(os.getppid())
    prepare_output()
    signal.signal(signal.SIGTERM, _terminate)
    _watch_interrupts()
    try:
        with import_errors_explained():
            status = call()
            if sys.stdout is not None:
                sys.stdout.flush()  # a full disk or a closed pipe is this command's error
            return status
    except DDSolveError as exc:
        _report(f"ddsolve: error: {exc}", everywhere=not exc.collective)
        if not exc.collective:  # raised on this rank only: the others cannot know, so stop them
            _abort(exc.exit_status)
        return exc.exit_status
    except KeyboardInterrupt as exc:
        status = _interrupted_status(143 if isinstance(exc, Terminated) else 130)
        _abort(status)
        return status
    except Exception:
        traceback.print_exc()
        _abort(1)
        return 1


#: ASCII spellings of the symbols in ddsolve's messages that are neither Greek letters (spelt by their
#: names: Σ -> Sigma, θ -> theta) nor letters with accents or super- and subscripts (their base forms).
SPELLINGS = {"−": "-", "×": "x", "·": "*", "≤": "<=", "≥": ">=", "≈": "~", "±": "+-", "∞": "inf", "→": "->",
             "‖": "||", "«": '"', "»": '"', "—": "--", "–": "-", "…": "...", "°": " deg", "⁄": "/"}


def _ascii(char: str) -> str:
    if char in SPELLINGS:
        return SPELLINGS[char]
    name = unicodedata.name(char, "")
    if name.startswith("GREEK ") and " LETTER " in name:
        letter = name.split(" LETTER ")[1].replace("FINAL ", "").split()[0].lower()
        return letter.capitalize() if " CAPITAL " in name else letter
    if char.isascii() and char.isprintable():
        return char
    return char.encode("ascii", "backslashreplace").decode("ascii")


def spelled_in_ascii(error: UnicodeError) -> tuple[str, int]:
    """Codec error handler ``ddsolve``: what an output's encoding cannot hold, in ASCII spellings
    (:data:`SPELLINGS`, Greek letters by name, base forms without accents), else as backslash escapes."""
    if not isinstance(error, UnicodeEncodeError):
        raise error
    text = unicodedata.normalize("NFKD", error.object[error.start:error.end])
    return "".join(_ascii(char) for char in text if not unicodedata.combining(char)), error.end


class CheckedOutput:
    """Standard output whose write errors (a full disk, a closed pipe) are one-line errors, whatever
    writes -- a print, argparse's help, the final flush; after one, the rest goes to /dev/null, so
    that the flush at Python's exit does not fail again."""

    def __init__(self, stream):
        self.stream = stream

    def __getattr__(self, name: str):
        return getattr(self.stream, name)

    def write(self, text: str) -> int:
        return self._checked(self.stream.write, text)

    def flush(self) -> None:
        self._checked(self.stream.flush)

    def _checked(self, call, *args):
        try:
            return call(*args)
        except OSError as exc:
            with contextlib.suppress(OSError, ValueError):
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, self.stream.fileno())
                os.close(devnull)
            raise DDSolveError(f"cannot write to standard output: {exc.strerror or exc}") from None


def prepare_output() -> None:
    """Standard output and error in any encoding (ASCII in a C locale, latin-1...): what the encoding
    cannot hold is spelt in ASCII (:func:`spelled_in_ascii`), never an error; standard output checked
    (:class:`CheckedOutput`)."""
    codecs.register_error("ddsolve", spelled_in_ascii)
    for stream in (sys.stdout, sys.stderr):
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="ddsolve")
    if sys.stdout is not None and not isinstance(sys.stdout, CheckedOutput):
        sys.stdout = CheckedOutput(sys.stdout)


def _flush_output() -> None:
    """Flush standard output before an error line or an abort (a failure to write it is reported by
    the command's own flush, or lost with the error being reported)."""
    with contextlib.suppress(DDSolveError, AttributeError):
        sys.stdout.flush()


def _world():
    """MPI.COMM_WORLD if mpi4py is in use, else None."""
    if "mpi4py.MPI" not in sys.modules:
        return None
    from mpi4py import MPI

    return MPI.COMM_WORLD if MPI.Is_initialized() and not MPI.Is_finalized() else None


def _abort(status: int, alone: bool = False) -> None:
    """End every rank at once (with ``alone``, even a single rank): waiting for the others (PETSc's
    finalize does) would hang.  MPI_Abort waits for mpiexec and holds the GIL meanwhile, so no Python
    thread can run: if mpiexec does not answer, faulthandler's own C thread ends this process (status
    1) ABORT_GRACE seconds later."""
    world = _world()
    if world is not None and (world.size > 1 or alone):
        _flush_output()
        with contextlib.suppress(OSError, ValueError):
            sys.stderr.flush()
        faulthandler.dump_traceback_later(ABORT_GRACE, exit=True, file=open(os.devnull, "w"))
        world.Abort(status)


def _report(message: str, everywhere: bool = False) -> None:
    """Print an error once (on rank 0 when MPI is running, unless it happened on one rank only)."""
    world = _world()
    if world is None or world.rank == 0 or everywhere:
        _flush_output()
        print(message, file=sys.stderr, flush=True)
