"""Command line: ``python -m ddsolve COMMAND ...`` (``./run COMMAND ...`` prepares the environment).

PETSc options go last (from the first single-dash option that is not ddsolve's own), e.g.
``ddsolve solve partial-closure -u_minus_ksp_type cg -u_minus_pc_type gamg -log_view``.
"""
from __future__ import annotations

import argparse
import importlib
import math
import os
import signal
import sys
import time
import traceback
from pathlib import Path

from . import __version__
from .environment import import_errors_explained
from .errors import DDSolveError
from .launch import mpiexec_command

OWN_SHORT_OPTIONS = {"-n", "-o", "-h"}


def split_petsc_options(argv: list[str]) -> tuple[list[str], list[str]]:
    """Split argv at the first PETSc-looking option (``-name``, not ours, not a negative number)."""
    for i, arg in enumerate(argv):
        if arg == "--":
            return argv[:i], argv[i + 1:]
        if arg.startswith("-") and not arg.startswith("--") and arg not in OWN_SHORT_OPTIONS:
            try:
                float(arg)
            except ValueError:
                return argv[:i], argv[i:]
    return argv, []


def init_petsc(options: list[str]) -> None:
    import petsc4py

    petsc4py.init([sys.argv[0], *options])


def _root_print(*args, **kwargs) -> None:
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        print(*args, **kwargs, flush=True)


def _load_scene(args):
    from . import scene

    return scene.load(args.scene, args.set or [])


def _default_output(args) -> Path:
    return Path(args.output) if args.output else Path(Path(args.scene).stem + ".h5")


# --- commands -------------------------------------------------------------------------------
def _launch(args) -> None:
    """With ``-n N``: replace this process by mpiexec running the same command on N ranks."""
    if args.ranks is None:
        return
    for module in ("petsc4py", "mpi4py", "h5py"):  # if one is missing, one line here, not one per rank
        importlib.import_module(module)
    forwarded = list(args.argv)
    i = next(j for j, a in enumerate(forwarded) if a.startswith("-n"))
    del forwarded[i:i + (2 if forwarded[i] == "-n" else 1)]
    command = mpiexec_command(args.ranks, forwarded)
    os.execvpe(command[0], command, {**os.environ, "DDSOLVE_LAUNCHED": repr(time.time())})  # start-up timing


def cmd_solve(args, petsc_options: list[str]) -> int:
    _launch(args)
    init_petsc(petsc_options)
    from mpi4py import MPI

    from . import driver
    from .exchange import collective

    comm = MPI.COMM_WORLD
    scene = collective(comm, lambda: _load_scene(args), root_only=True)
    scene = comm.bcast(scene, root=0)
    output = _default_output(args)
    result = driver.solve(scene, comm, output, progress=_root_print)
    if result is not None:
        print(f"{result.method}: converged after {result.iterations} iterations, {result.solves} rounds of "
              f"block solves, {result.wall_time:.3f} s on {result.ranks} ranks -> {output}", flush=True)
        _print_fracture(result)
    return 0


def _print_fracture(result) -> None:
    """G at every crack tip and the contact zones, after a solve."""
    for line in result.fracture.lines() if result.fracture is not None else []:
        print(line, flush=True)


def cmd_sweep(args, petsc_options: list[str]) -> int:
    _launch(args)
    init_petsc(petsc_options)
    import time

    from mpi4py import MPI

    from . import sweep

    started = time.perf_counter()
    output = Path(args.output) if args.output else Path(Path(args.scene).stem + "-sweep.h5")
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

    scene = _load_scene(args)
    mesh = geometry.build(scene)
    geometry.check_loads(scene, mesh)
    result = reference.solve(scene, mesh)
    output = _default_output(args)
    io.write(output, result)
    print(f"reference: {result.iterations} active-set steps, {result.wall_time:.3f} s -> {output}")
    _print_fracture(result)
    return 0


def cmd_compare(args, _petsc_options) -> int:
    from . import analysis, io

    comparison = analysis.compare(io.read(args.result), io.read(args.reference))
    print(f"relative energy-norm error {comparison.energy_error:.3e}   "
          f"max nodal difference {comparison.max_difference:.3e} (max |u| {comparison.max_displacement:.3e})")
    return 0


def cmd_check(args, _petsc_options) -> int:
    from . import analysis, io

    c = analysis.constraints(io.read(args.result))
    print(f"max penetration {c.penetration:.3e}   max gluing gap {c.gluing_gap:.3e}   "
          f"complementarity {c.complementarity:.3e}   (relative to max |u| = {c.max_displacement:.3e}); "
          f"min mu_c {c.min_mu_c:.3e}")
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


def cmd_plot(args, _petsc_options) -> int:
    from . import io, plots

    scale = _scale(args.scale)
    result = io.read(args.result)
    stem = Path(args.result).with_suffix("")
    written = [Path(f"{stem}-{name}.png") for name in ("deformed", "crack-faces", "convergence")]
    scale = plots.deformed_layers(result, written[0], scale)
    plots.crack_faces(result, written[1])
    plots.convergence([(result.method, result)], written[2])
    print(f"wrote {', '.join(map(str, written))} (displacements ×{scale:g})")
    return 0


def cmd_export(args, _petsc_options) -> int:
    from . import io

    result = io.read(args.result)
    folder = Path(args.output) if args.output else Path(args.result).parent
    if not folder.is_dir():
        raise DDSolveError(f"-o {folder}: no such directory")
    written = io.write_viewer(result, folder, Path(args.result).stem, args.format)
    print("wrote " + ", ".join(map(str, written)))
    return 0


def cmd_mesh(args, _petsc_options) -> int:
    from . import geometry, mesh as meshes

    scene = _load_scene(args)
    mesh = geometry.build(scene)
    print(f"{'half':6s} {'h_min':>8s} {'h_max':>8s} {'vertices':>9s} {'nodes':>9s} {'triangles':>10s} {'min angle':>9s}")
    for half in mesh.halves:
        s = meshes.statistics(half)
        print(f"{half.name:6s} {s.h_min:8.4f} {s.h_max:8.4f} {s.vertices:9d} {len(half.points):9d} {s.triangles:10d} "
              f"{s.min_angle:9.1f}")
    print(f"Σ vertices {int(mesh.sigma.corner.sum())}, boundary vertices {meshes.boundary_vertex_count(mesh)}, "
          f"degree {mesh.degree}, boundaries: {', '.join(mesh.boundary_names())}")
    if args.output:
        geometry.write_msh(mesh, Path(args.output))
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
    "accuracy": ("paper", "accuracy", "discretization error under refinement, error against wall time",
                 "docs/results.md (accuracy), docs/accuracy.png"),
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
    top = argparse.ArgumentParser(prog="ddsolve", description="Domain decomposition (PETSc/MPI) for a two-layer "
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
    top.epilog += ("\n\nPETSc options go last: ddsolve solve SCENE -u_minus_ksp_type cg -u_minus_pc_type gamg "
                   "-log_view")
    return top


class Terminated(KeyboardInterrupt):
    """SIGTERM, turned into an exception so that temporary files are removed on the way out."""


def _terminate(signum, _frame) -> None:
    raise Terminated(signal.Signals(signum).name)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    own, petsc_options = split_petsc_options(argv)
    args = parser().parse_args(own)
    args.argv = argv
    return guarded(lambda: args.run(args, petsc_options))


def guarded(call) -> int:
    """Run a command: a DDSolveError (or a missing petsc4py, mpi4py, h5py, gmsh...) becomes one line
    and its exit status, an interrupt or SIGTERM stops every rank, anything else is a bug (traceback,
    abort)."""
    signal.signal(signal.SIGTERM, _terminate)
    try:
        with import_errors_explained():
            return call()
    except DDSolveError as exc:
        _report(f"ddsolve: error: {exc}", everywhere=not exc.collective)
        if not exc.collective:  # raised on this rank only: the others cannot know, so stop them
            _abort(exc.exit_status)
        return exc.exit_status
    except KeyboardInterrupt as exc:
        status = 143 if isinstance(exc, Terminated) else 130
        _report("ddsolve: terminated" if status == 143 else "ddsolve: interrupted")
        _abort(status)
        return status
    except Exception:
        traceback.print_exc()
        _abort(1)
        raise


def _world():
    """MPI.COMM_WORLD if mpi4py is in use, else None."""
    if "mpi4py.MPI" not in sys.modules:
        return None
    from mpi4py import MPI

    return MPI.COMM_WORLD if MPI.Is_initialized() and not MPI.Is_finalized() else None


def _abort(status: int) -> None:
    """End every rank at once: waiting for the others (PETSc's finalize does) would hang."""
    world = _world()
    if world is not None and world.size > 1:
        sys.stdout.flush()
        sys.stderr.flush()
        world.Abort(status)


def _report(message: str, everywhere: bool = False) -> None:
    """Print an error once (on rank 0 when MPI is running, unless it happened on one rank only)."""
    world = _world()
    if world is None or world.rank == 0 or everywhere:
        print(message, file=sys.stderr, flush=True)
