"""Command line: ``python -m ddsolve COMMAND ...`` (``./run COMMAND ...`` prepares the environment).

PETSc options go last (from the first single-dash option that is not ddsolve's own), e.g.
``ddsolve solve partial-closure -u_minus_ksp_type cg -u_minus_pc_type gamg -log_view``.
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
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
def cmd_solve(args, petsc_options: list[str]) -> int:
    if args.ranks is not None:  # launcher mode: start the ranks under mpiexec
        for module in ("petsc4py", "mpi4py", "h5py"):  # if one is missing, one line here, not one per rank
            importlib.import_module(module)
        forwarded = list(args.argv)
        i = next(j for j, a in enumerate(forwarded) if a.startswith("-n"))
        del forwarded[i:i + (2 if forwarded[i] == "-n" else 1)]
        command = mpiexec_command(args.ranks, forwarded)
        os.execvpe(command[0], command, dict(os.environ))
    init_petsc(petsc_options)
    from mpi4py import MPI

    from . import adapt, driver
    from .exchange import collective

    comm = MPI.COMM_WORLD
    scene = collective(comm, lambda: _load_scene(args), root_only=True)
    scene = comm.bcast(scene, root=0)
    output = _default_output(args)
    solve = adapt.solve if scene.mesh.target_error is not None else driver.solve
    result = solve(scene, comm, output, progress=_root_print)
    if result is not None:
        print(f"{result.method}: converged after {result.iterations} iterations, {result.solves} rounds of "
              f"block solves, {result.wall_time:.3f} s on {result.ranks} ranks -> {output}", flush=True)
        print(estimate_line(result), flush=True)
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
    print(estimate_line(result))
    return 0


def estimate_line(result) -> str:
    """The estimated discretization error of a result, in one line."""
    unknowns = 4 * (len(result.lower.points) + len(result.upper.points))
    return (f"estimated discretization error {100 * result.attrs['error_estimate']:.3g} % (relative, energy norm; "
            f"{unknowns} unknowns, P{result.mesh.degree})")


def cmd_compare(args, _petsc_options) -> int:
    from . import analysis, io

    result, reference = io.read(args.result), io.read(args.reference)
    comparison = analysis.compare(result, reference)
    print(f"relative energy-norm error {comparison.energy_error:.3e}   "
          f"max nodal difference {comparison.max_difference:.3e} (max |u| {comparison.max_displacement:.3e})"
          + ("" if analysis.same_meshes(result, reference) else "   (on the reference's mesh)"))
    return 0


def cmd_check(args, _petsc_options) -> int:
    from . import analysis, io

    c = analysis.constraints(io.read(args.result))
    print(f"max penetration {c.penetration:.3e}   max gluing gap {c.gluing_gap:.3e}   "
          f"complementarity {c.complementarity:.3e}   (relative to max |u| = {c.max_displacement:.3e}); "
          f"min mu_c {c.min_mu_c:.3e}")
    return 0


def cmd_plot(args, _petsc_options) -> int:
    from . import io, plots

    result = io.read(args.result)
    stem = Path(args.result).with_suffix("")
    plots.deformed_layers(result, Path(f"{stem}-deformed.png"), args.scale)
    plots.crack_faces(result, Path(f"{stem}-jump.png"))
    written = [f"{stem}-deformed.png", f"{stem}-jump.png"]
    if len(result.history):
        plots.convergence([(result.method, result)], Path(f"{stem}-convergence.png"))
        written.append(f"{stem}-convergence.png")
    print("wrote " + ", ".join(written))
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
    p = command("plot", "PNG pictures of a result (deformed layers, crack opening, convergence)", cmd_plot)
    p.add_argument("result")
    p.add_argument("--scale", type=float, help="displacement magnification (default: from the data)")
    command("scenes", "list the built-in scenes", cmd_scenes)
    command("version", "versions of ddsolve, PETSc and MPI", cmd_version)

    experiments = "experiments (each reruns its measurements and rewrites its part of docs/ and results/)"
    for name, (_, _, summary, written) in EXPERIMENTS.items():
        command(name, summary, cmd_experiment, experiments, f"; writes {written}")
    p = command("bench", "`bench methods`: every method and tolerance; `bench factor`: block factorizations",
                cmd_bench, experiments)
    p.add_argument("what", choices=("methods", "factor"))
    p.add_argument("--meshes", help="comma-separated P:M pairs (default: Table 1 and 400:512)")
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
