"""Command line: ``python -m ddsolve COMMAND ...`` (``./run COMMAND ...`` prepares the environment).

ddsolve's own options may come anywhere; every other single-dash option of ``solve``, ``reference``,
``version`` and ``bench`` is PETSc's (with the next word as its value unless that is an option),
e.g. ``ddsolve solve partial-closure -u_minus_ksp_type cg -u_minus_pc_type gamg -log_view -o r.h5``;
everything after ``--`` is PETSc's.  Commands without PETSc refuse unknown options.  PETSc options
that nothing read are reported when the run ends, as PETSc's ``-options_left`` does.
"""
from __future__ import annotations

import argparse
import importlib
import math
import os
import sys
import time
from pathlib import Path

from ddsolve import __version__
from ddsolve.errors import DDSolveError, NotConvergedError, UsageError
from ddsolve.io import safe
from ddsolve.mesh import gmsh_io
from ddsolve.parallel.launch import mpiexec_command, supervise
from ddsolve.parallel.phases import LAUNCHED
from ddsolve.mesh.mesh import blocks
from ddsolve.parallel import runtime
from ddsolve.parallel.runtime import Parser, check_petsc_files, guarded, init_petsc, is_number
from ddsolve.solvers.checks import check_ranks, check_read, check_size

#: ddsolve's commands that hand options to PETSc.
PETSC_COMMANDS = ("solve", "sweep", "grow", "reference", "version")
#: Options-prefixes of the KSPs (what a misspelt option is compared with).
PREFIXES = {"solve": tuple(f"{spec.name}_" for spec in blocks(2)), "reference": ("reference_",)}  # any structure's
PREFIXES["sweep"] = PREFIXES["grow"] = PREFIXES["solve"]
#: Suffix of the files ``mesh -o`` writes (gmsh chooses the format by the suffix).
MESH_SUFFIX = ".msh"


def split_arguments(top: argparse.ArgumentParser, argv: list[str]) -> tuple[list[str], list[str]]:
    """(ddsolve's arguments, PETSc's options) of a command line (:func:`ddsolve.parallel.runtime.split_arguments`
    with the commands that take PETSc options)."""
    return runtime.split_arguments(top, argv, PETSC_COMMANDS)

def _root_print(*args, **kwargs) -> None:
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        print(*args, **kwargs, flush=True)


def _control_targets(text: str) -> float | tuple[float, ...]:
    """``--to``: one control factor, or a path of them separated by commas."""
    try:
        values = tuple(float(word) for word in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid control factor(s): {text!r} (a number, or numbers separated by "
                                         "commas)") from None
    return values[0] if len(values) == 1 else values


def _load_scene(args):
    """The scene of ``args`` (with its ``--set`` items, each of which the command must read)."""
    from ddsolve.problem import scene

    loaded = scene.load(args.scene, args.set or [])
    check_read(args.command, args.set or [], loaded)
    if args.command != "mesh":
        runtime.check_out_of_core(loaded.solver.out_of_core, args.petsc)
    return loaded


def _default_output(args) -> Path:
    return Path(args.output) if args.output is not None else Path(Path(args.scene).stem + ".h5")




def _inputs(args, scene) -> list[Path]:
    """The files a run reads: the scene file, its mesh or geometry file and the files that one reaches."""
    from ddsolve.io import inputs

    return inputs.of_scene(scene, args.scene)


def check_outputs(args, scene) -> Path:
    """The result file of ``solve``/``reference`` and its viewer files, checked before any work."""
    from ddsolve.io import hdf5

    output = _default_output(args)
    if not output.name:
        raise DDSolveError(f"-o {str(args.output)!r}: not a file name")
    hdf5.check_result(output, _inputs(args, scene))
    return output


# --- commands -------------------------------------------------------------------------------
def _launch(args, petsc_options: list[str], scene_checks: bool) -> None:
    """With ``-n N``: check what can be checked here (the rank count, the modules, and with
    ``scene_checks`` the scene, the mesh size and the output files), then run mpiexec running the same
    command on N ranks and end this process with its status (:func:`supervise`)."""
    if args.ranks is None:
        return
    scene = _load_scene(args) if scene_checks else None
    if not scene_checks:  # sweep and grow: plane only
        from ddsolve.solvers import sweep

        sweep.check_plane(args.scene, args.set or [])
    check_ranks(args.ranks, scene)
    check_petsc_files(petsc_options)
    for module in ("petsc4py", "mpi4py", "h5py"):  # if one is missing, one line here, not one per rank
        importlib.import_module(module)
    from ddsolve.io import viewer

    if scene is not None:
        check_size(scene, args.ranks, stacks=True, solid=args.command == "solve")
        output = check_outputs(args, scene)
        outputs = [output, *viewer.viewer_paths(output.parent, output.stem)]
    else:
        outputs = [_grow_output(args)] if args.command == "grow" else [_sweep_output(args)]
    forwarded = [arg for i, arg in enumerate(args.own) if i not in args.ranks_at]
    command = mpiexec_command(args.ranks, forwarded + (["--", *petsc_options] if petsc_options else []))
    sys.exit(supervise(command, {**os.environ, LAUNCHED: repr(time.time())}, outputs))  # start-up timing


def _sweep_output(args) -> Path:
    return Path(args.output) if args.output else Path(Path(args.scene).stem + "-sweep.h5")


def _grow_output(args) -> Path:
    return Path(args.output) if args.output else Path(Path(args.scene).stem + "-growth.h5")



def cmd_solve(args, petsc_options: list[str]) -> int:
    _launch(args, petsc_options, scene_checks=True)
    init_petsc(petsc_options)
    from mpi4py import MPI

    from ddsolve.parallel.exchange import collective
    from ddsolve.solvers import run, solid_lines

    comm = MPI.COMM_WORLD
    scene = comm.bcast(collective(comm, lambda: _load_scene(args), root_only=True), root=0)
    output = comm.bcast(collective(comm, lambda: check_outputs(args, scene), root_only=True), root=0)
    result = run.decomposition(scene, comm, output, progress=_root_print, gather=False)
    if result is not None and scene.geometry.dimension == 3:
        print(f"{result.scene.solver.method} (3-D): {result.steps} iterations, {result.closed} closed crack vertices, "
              f"energy {result.energy:.10g}, {3 * sum(len(u) for u in result.fields)} unknowns, {result.solves} "
              f"rounds of block solves, {result.timings['total']:.3f} s on {comm.size} ranks -> {output}", flush=True)
        print(solid_lines.phases_line(result.timings), flush=True)
        _print_front(result, output)
    elif result is not None and scene.geometry.above:  # no error estimate, reactions or viewer files yet
        print(f"{result.scene.solver.method}: {len(scene.geometry.sigmas)} interfaces, {result.iterations} "
              f"iterations, energy {result.energy:.10g}, {result.wall_time:.3f} s on {comm.size} ranks -> {output}")
        print("\n".join(result.fracture.lines()), flush=True)
    elif result is not None:
        print(f"{result.method}: converged after {result.iterations} iterations{active_set_part(result)}"
              f"{coulomb_part(result)}{bond_part(result)}, "
              f"{result.solves} rounds of block solves, {result.wall_time:.3f} s on {result.ranks} ranks -> {output}",
              flush=True)
        print(estimate_line(result), flush=True)
        print(launch_line(result), flush=True)
        _print_refinement(scene, result)
        _print_fracture(result)
    return 0


def active_set_part(result) -> str:
    """`` (S active-set steps[, T s each])`` when the method counts its active-set steps (and times them)."""
    steps = int(result.attrs.get("active_set_steps", 0))
    if not steps:
        return ""
    seconds = result.attrs.get("active_set_time")
    each = f", {float(seconds) / steps:.2g} s each" if seconds is not None else ""
    return f" ({steps} active-set step{'s' if steps > 1 else ''}{each})"


def coulomb_part(result) -> str:
    """``, Coulomb friction in N Tresca problems`` when the method iterated Coulomb's friction to its fixed point."""
    count = int(result.attrs.get("coulomb_iterations", 0))
    return f", Coulomb friction in {count} Tresca problem{'s' if count > 1 else ''}" if count else ""


def bond_part(result) -> str:
    """``, the bond in N linear problems on Σ`` when the scene has a bond law (``[interface]``)."""
    count = int(result.attrs.get("bond_solves", 0))
    return f", the bond in {count} linear problem{'s' if count > 1 else ''} on Σ" if count else ""


def launch_line(result) -> str:
    """The launch phase by phase (rank 0's clock, the result's ``/timings``) against its solve phase, and the
    largest peak memory of a rank."""
    from ddsolve.parallel.phases import PHASES

    timings = result.timings
    phases = [(name, timings[name]) for name in PHASES if name in timings]
    total = sum(seconds for _, seconds in phases)
    solve = result.wall_time
    if "adaptive" in timings:  # every level; the phases are the last level's
        levels = result.levels.get("solve_time", [solve]) if result.levels else [solve]
        phases = [("startup", timings.get("startup", 0.0)), (f"{len(levels)} levels", timings["adaptive"]),
                  *([("write", timings["write"])] if "write" in timings else [])]
        total, solve = sum(seconds for _, seconds in phases), float(sum(levels))
    peaks = result.attrs.get("peak_memory_mb")
    memory = f"; peak memory {max(peaks):.0f} MB (largest rank)" if peaks is not None and len(peaks) else ""
    ratio = f"{total / solve:.2f} x" if solve > 0 else "n/a:"
    return (f"launch {total:.2f} s = {ratio} the solve phase ({solve:.2f} s): "
            + ", ".join(f"{name} {seconds:.2f}" for name, seconds in phases) + memory)


def _print_refinement(scene, result) -> None:
    """For a mesh made by refining a coarse one: the levels and the fine mesh's real counts."""
    from ddsolve.mesh import geometry

    coarse, levels = geometry.refinement(scene)
    if levels and "min_angle" in result.attrs:
        made = (f" (gmsh: sigma_vertices {coarse.mesh.sigma_vertices}, boundary_vertices "
                f"{coarse.mesh.boundary_vertices})" if coarse.mesh.sigma_vertices is not None else "")
        print(f"mesh: a coarse mesh{made} refined by {levels} level{'s' if levels > 1 else ''}: "
              f"{result.attrs['sigma_vertices']} Σ vertices, {result.attrs['boundary_vertices']} boundary vertices, "
              f"smallest angle {result.attrs['min_angle']:.1f}°", flush=True)


def _print_fracture(result) -> None:
    """G at every crack tip (and why it is not split into modes, where it is not), the contact zones, where the
    faces slip and stick (with friction), then the reactions, after a solve."""
    from ddsolve.post import analysis, fracture, reactions

    lines = result.fracture.lines() if result.fracture is not None else []
    note = fracture.split_note(result.scene) if len(lines) else None
    for line in lines + ([note] if note else []) + analysis.friction_lines(result) + reactions.lines(result.reactions):
        print(line, flush=True)


def cmd_sweep(args, petsc_options: list[str]) -> int:
    _launch(args, petsc_options, scene_checks=False)
    init_petsc(petsc_options)
    import time

    from mpi4py import MPI

    from ddsolve.solvers import sweep

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


def cmd_grow(args, petsc_options: list[str]) -> int:
    _launch(args, petsc_options, scene_checks=False)
    init_petsc(petsc_options)
    import time

    from mpi4py import MPI

    from ddsolve.io.hdf5 import check_result
    from ddsolve.parallel.exchange import collective
    from ddsolve.solvers import bond_growth, grow, growth_files

    comm = MPI.COMM_WORLD
    started = time.perf_counter()
    scene = comm.bcast(collective(comm, lambda: _load_scene(args), root_only=True), root=0)
    output = _grow_output(args)
    collective(comm, lambda: check_result(output, _inputs(args, scene), viewer=False), root_only=True)
    if bond_growth.damaging(scene):
        steps = bond_growth.grow(scene, comm, args.limit, args.steps, progress=_root_print, output=output,
                                 pictures=args.pictures, inputs=_inputs(args, scene))
    else:
        steps = grow.grow(scene, comm, args.limit, args.steps, args.tolerance, progress=_root_print, output=output,
                          pictures=args.pictures, inputs=_inputs(args, scene))
    if steps is not None:
        files = growth_files.Outputs(output)
        unstable = sum(step.unstable for step in steps)
        for index, step in enumerate(steps):
            for event in step.events:
                print(f"event at step {index} (factor {step.state.control:.6g}): {event}", flush=True)
        print(f"grow: {len(steps)} steps written (the first at λ = 0), {sum(step.solves for step in steps)} solves"
              + (f", unstable growth at {unstable} steps" if unstable else ", stable growth") +
              f", {time.perf_counter() - started:.1f} s on {comm.size} ranks -> {output}, {files.csv}, "
              f"{files.curves}" + (f" and {args.pictures} step pictures" if args.pictures else ""), flush=True)
    return 0


def _print_front(result, output: Path | None) -> None:
    """G along a 3-D result's crack fronts in a line: its nodes, mean and range."""
    if result.fracture is not None and len(result.fracture.G):
        G = result.fracture.G
        print(f"G along the crack front ({len(G)} nodes, /fracture in {output}): mean {G.mean():.6g}, from "
              f"{G.min():.6g} to {G.max():.6g}", flush=True)


def cmd_reference(args, petsc_options: list[str]) -> int:
    init_petsc(petsc_options)
    from ddsolve.solvers import run, solid_lines

    scene = _load_scene(args)
    output = check_outputs(args, scene)
    result = run.reference(scene, output, progress=_root_print)
    if scene.geometry.dimension == 3:
        print(f"reference (3-D): {result.steps} active-set steps, {result.closed} closed crack vertices, energy "
              f"{result.energy:.10g}, {3 * sum(len(u) for u in result.fields)} unknowns, "
              f"{sum(result.timings.values()):.3f} s -> {output}", flush=True)
        print(solid_lines.phases_line(result.timings), flush=True)
        _print_front(result, output)
        return 0
    if scene.geometry.above:  # no error estimate, reactions or viewer files yet
        print(f"reference: {len(scene.geometry.sigmas)} interfaces, {result.iterations} active-set steps, energy "
              f"{result.energy:.10g}, {result.wall_time:.3f} s -> {output}")
        print("\n".join(result.fracture.lines()), flush=True)
        return 0
    print(f"reference: {result.iterations} active-set steps, {result.wall_time:.3f} s -> {output}")
    print(estimate_line(result))
    _print_refinement(scene, result)
    _print_fracture(result)
    return 0


def estimate_line(result) -> str:
    """The estimated discretization error of a result, in one line (a result written by the ranks, whose
    rank 0 holds no mesh: its unknowns from /memory, its degree from Σ)."""
    if result.mesh is None:
        unknowns, degree = result.memory["unknowns"], 1 if result.on_sigma.sigma.corner.all() else 2
    else:
        unknowns, degree = result.unknowns, result.mesh.degree
    return (f"estimated discretization error {100 * result.attrs['error_estimate']:.3g} % (relative, energy norm; "
            f"{unknowns} unknowns, P{degree})")


def cmd_compare(args, _petsc_options) -> int:
    from ddsolve.io import hdf5, solid
    from ddsolve.post import analysis, stack

    if solid.is_solid(args.result) and solid.is_solid(args.reference):
        from ddsolve.solvers.solid import comparison

        result, reference = solid.read(args.result), solid.read(args.reference)
        error, difference, largest = comparison(result, reference)
        print(f"relative energy-norm error {error:.3e}   max nodal difference {difference:.3e} (max |u| "
              f"{largest:.3e})   energies {result.energy:.10g} and {reference.energy:.10g}")
        return 0
    result, reference = hdf5.read(args.result), hdf5.read(args.reference)
    names = (args.result, args.reference)
    if isinstance(result, stack.StackResult) or isinstance(reference, stack.StackResult):
        comparison = stack.compare(result, reference, names)
        same = all(map(analysis.same_meshes, result.interfaces, reference.interfaces))
        tips = stack.tip_lines(result.fracture, reference.fracture, names)
    else:
        comparison, same, tips = analysis.compare(result, reference, names), analysis.same_meshes(result, reference), []
    print(f"relative energy-norm error {comparison.energy_error:.3e}   "
          f"max nodal difference {comparison.max_difference:.3e} (max |u| {comparison.max_displacement:.3e})"
          + ("" if same else "   (on the reference's mesh)"))
    for line in tips:
        print(line)
    return 0


def cmd_check(args, _petsc_options) -> int:
    from ddsolve.io import hdf5
    from ddsolve.post import analysis, stack

    result = hdf5.read(args.result)
    if isinstance(result, stack.StackResult):
        from ddsolve.solvers import stacked

        checked = list(zip(stacked.check(result), result.interfaces))
    else:
        checked = [(analysis.constraints(result), result)]
    failed = []
    for number, (c, view) in enumerate(checked, start=1):
        tolerance = analysis.tolerance_of(view)
        violations = c.violations(tolerance)
        scale = (f"max |u| = {c.max_displacement:.3e}" if c.displacement_scale <= c.max_displacement else
                 f"the data's displacement scale {c.displacement_scale:.3e} (max |u| = {c.max_displacement:.3e})")
        where = f"interface {number}: " if len(checked) > 1 else ""
        print(f"{where}{c.summary()}   (scale-free: relative to {scale}, max |mu|, ||K|| ||x||); "
              f"min mu_c {c.min_mu_c:.3e}")
        failed += [f"{where}{name}" for name in violations]
    claim = f"the file says converged = {str(result.converged).lower()}"
    if failed:
        raise NotConvergedError(f"{args.result}: KKT check failed: {', '.join(failed)} above the tolerance "
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


def _check_drawn(text: str, drawn: float) -> None:
    """Refuse ``--scale text`` if it draws the largest displacement at ``drawn`` > :data:`MAX_DRAWN` domain sizes."""
    if not drawn <= MAX_DRAWN:
        raise DDSolveError(f"--scale {text}: draws the largest displacement at {drawn:.3g} times the domain's size "
                           f"(at most {MAX_DRAWN:g}); leave --scale out to choose it from the data")


def cmd_plot(args, _petsc_options) -> int:
    import io as memory

    import numpy as np

    from ddsolve.io import hdf5
    from ddsolve.io import solid as solid_files
    from ddsolve.post import analysis, plots, stack

    scale = _scale(args.scale)
    if solid_files.is_solid(Path(args.result)):
        return _plot_solid(args, scale)
    result = hdf5.read(args.result)
    stem = Path(args.result).with_suffix("")
    broken = next((name for name, u in result.solution.items() if not np.isfinite(u).all()), None)
    if broken is not None:
        raise DDSolveError(f"{args.result}: /solution/{broken} holds values that are not finite numbers: "
                           "nothing to draw")
    several = isinstance(result, stack.StackResult)
    blocks = stack.drawn(result) if several else plots.drawn_blocks(result)
    if scale is not None:
        points = np.vstack([block.points for block in blocks])
        _check_drawn(args.scale, scale * analysis.largest_displacement(result.solution.values())
                     / np.ptp(points, axis=0).max())
    views = result.interfaces if several else [result]
    faces = [f"crack-faces-{number}" for number in range(1, len(views) + 1)] if several else ["crack-faces"]
    names = [Path(f"{stem}-{name}.png") for name in ("deformed", *faces, "convergence")]
    images = [memory.BytesIO() for _ in names]
    scale = plots.deformed_blocks(blocks, result.scene.layers, images[0],
                                  (plots.block_magnification(blocks) if several else plots.magnification(result))
                                  if scale is None else scale, plots.drawn_title(result))
    for view, image in zip(views, images[1:]):
        plots.crack_faces(view, image)
    plots.convergence([(views[0].method, views[0])], images[-1])
    safe.check_targets(names, [Path(args.result)])
    safe.replace_together({path: (lambda name, data=image.getvalue(): Path(name).write_bytes(data))
                         for path, image in zip(names, images)}, final=True)
    print(f"wrote {', '.join(map(str, names))} (displacements ×{scale:g})")
    return 0


def _plot_solid(args, scale: float | None) -> int:
    """``plot`` of a 3-D result: the opening map of Σ (of each Σ) and the deformed body."""
    import io as memory

    import numpy as np

    from ddsolve.io import solid as solid_files
    from ddsolve.post import solid_plots

    result = solid_files.read(args.result)
    if scale is not None:
        size = np.ptp(np.vstack([half.points for half in result.mesh.regions]), axis=0).max()
        _check_drawn(args.scale, scale * max(float(np.abs(u).max()) for u in result.fields) / size)
    scale = solid_plots.magnification(result) if scale is None else scale
    stem = Path(args.result).with_suffix("")
    count = len(result.pressures)  # several interfaces: an opening map of each, opening1 … bottom to top
    maps = ["opening"] if count == 1 else [f"opening{k}" for k in range(1, count + 1)]
    names = [Path(f"{stem}-{name}.png") for name in (*maps, "deformed")]
    images = [memory.BytesIO() for _ in names]
    for k, image in enumerate(images[:-1]):
        solid_plots.opening_map(result.interface(k), image)
    solid_plots.deformed_body(result, images[-1], scale)
    safe.check_targets(names, [Path(args.result)])
    safe.replace_together({path: (lambda name, data=image.getvalue(): Path(name).write_bytes(data))
                           for path, image in zip(names, images)}, final=True)
    print(f"wrote {', '.join(map(str, names))} (displacements ×{scale:g})")
    return 0


def cmd_export(args, _petsc_options) -> int:
    from ddsolve.io import hdf5
    from ddsolve.io import solid as solid_files
    from ddsolve.io import viewer
    from ddsolve.post.stack import StackResult

    solid = solid_files.is_solid(Path(args.result))
    if solid and args.format not in solid_files.VIEWER_FORMATS:
        raise DDSolveError(f"--format {args.format}: a 3-D result is exported as "
                           f"{' or '.join(solid_files.VIEWER_FORMATS)}")
    result = solid_files.read(args.result) if solid else hdf5.read(args.result)
    folder = Path(args.output) if args.output is not None else Path(args.result).parent
    if not folder.is_dir():
        raise DDSolveError(f"-o {folder}: " + ("is a file, not a folder: give -o the folder for the viewer files"
                                               if folder.exists() else "no such directory"))
    stem = Path(args.result).stem
    if solid or isinstance(result, StackResult):
        writers = (solid_files.viewer_writers(result, folder, stem, args.format) if solid else
                   viewer.stack_files(result, folder, stem, args.format))
        safe.check_targets(list(writers), [Path(args.result)])
        safe.replace_together(writers, final=True)
        written = list(writers)
    else:
        safe.check_targets(viewer.viewer_paths(folder, stem, args.format), [Path(args.result)])
        written = hdf5.write_viewer(result, folder, stem, args.format, final=True)
    print("wrote " + ", ".join(map(str, written)))
    return 0


def cmd_mesh(args, _petsc_options) -> int:
    from ddsolve.mesh import stack

    if args.output is not None and Path(args.output).suffix != MESH_SUFFIX:
        raise DDSolveError(f"-o {args.output}: the mesh command writes one format, gmsh MSH 4.1 with physical "
                           f"groups: give -o a file name with the suffix {MESH_SUFFIX} (e.g. halves{MESH_SUFFIX})")
    scene = _load_scene(args)
    if args.output is not None and scene.geometry.above:
        raise DDSolveError(f"-o {args.output}: the mesh of several interfaces is not written to a file")
    check_size(scene, solving=False)
    if args.output is not None:
        safe.check_targets([Path(args.output)], _inputs(args, scene))
    mesh = stack.build_any(scene)
    _print_mesh(scene, mesh)
    if args.output is not None:
        safe.atomic(Path(args.output), lambda name: gmsh_io.write_msh(mesh, Path(name)), final=True)
        groups = sorted(mesh.lower.boundaries.keys() | mesh.upper.boundaries.keys()
                        | mesh.lower.named_points.keys() | mesh.upper.named_points.keys())
        print(f"wrote {args.output} (gmsh, physical groups lower, upper, {', '.join(groups)})")
    return 0


def _print_mesh(scene, mesh) -> None:
    """The mesh command's table: each half (each region with several interfaces) as the paper's Table 1, Σ,
    the boundaries, the blocks."""
    from ddsolve.mesh import mesh as meshes

    width = max(6, *(len(region.name) for region in mesh.regions))
    print(f"{'half':{width}s} {'h_min':>8s} {'h_max':>8s} {'vertices':>9s} {'nodes':>9s} {'triangles':>10s} "
          f"{'min angle':>9s}")
    for half in mesh.regions:
        s = meshes.statistics(half)
        print(f"{half.name:{width}s} {s.h_min:8.4f} {s.h_max:8.4f} {s.vertices:9d} {len(half.points):9d} "
              f"{s.triangles:10d} {s.min_angle:9.1f}")
    sigma_vertices = ", ".join(str(int(line.corner.sum())) for line in mesh.sigmas)
    print(f"Σ vertices {sigma_vertices}{' (per interface, bottom to top)' if mesh.above else ''}, boundary vertices "
          f"{meshes.boundary_vertex_count(mesh)}, degree {mesh.degree}, boundaries: {', '.join(mesh.boundary_names())}")
    layers = len(scene.layers)
    if mesh.above:
        print(f"{layers} layer{'s' * (layers > 1)} on {len(mesh.regions)} regions: {layers * len(mesh.regions)} "
              f"blocks, {2 * layers * sum(len(region.points) for region in mesh.regions)} displacement unknowns")
        return
    specs = blocks(scene.geometry.layers)
    print(f"{layers} layer{'s' * (len(specs) > 2)}: blocks {', '.join(spec.name for spec in specs)}, "
          f"{2 * sum(len(mesh.half(spec.side).points) for spec in specs)} displacement unknowns")


def cmd_scenes(_args, _petsc_options) -> int:
    from ddsolve.problem import scene

    for name, text in sorted(scene.builtin_scenes().items()):
        print(f"{name:18s} {scene.loads(text).title}")
    return 0


def cmd_version(_args, petsc_options) -> int:
    init_petsc(petsc_options)
    from mpi4py import MPI
    from petsc4py import PETSc

    from ddsolve.parallel.blocks import default_factor_package

    petsc = ".".join(map(str, PETSc.Sys.getVersion()))
    print(f"ddsolve {__version__}; PETSc {petsc} (factorization: {default_factor_package()}); "
          f"{MPI.Get_library_version().replace(chr(0), '').splitlines()[0].strip()}")
    return 0


def parser() -> argparse.ArgumentParser:
    """The command line; ``ddsolve --help`` lists the commands (the epilog).  The experiments have their
    own (:mod:`experiments.commands`)."""
    from ddsolve.io import viewer

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
                   help="launch N ranks with mpiexec: 1, 2, 4 (a block per rank) or 4k (a block on k ranks); "
                   "a one-layer structure (geometry.layers = 1): 1, 2 or 2k; a 3-D box: any up to its blocks (some "
                   "ranks holding one more) or a multiple of them")
    p.add_argument("-o", dest="output", help="result file (default: SCENE.h5)")
    p = scene_command("sweep", "solves over ranges of scene values (--set KEY=START:STOP:COUNT), one launch, "
                      "one HDF5 file", cmd_sweep)
    p.add_argument("-n", dest="ranks", type=int, metavar="N", help="launch N ranks with mpiexec (as for solve)")
    p.add_argument("-o", dest="output", help="HDF5 file of every run (default: SCENE-sweep.h5)")
    p.add_argument("--zip", action="store_true",
                   help="take the ranges side by side (same COUNT) instead of every combination")
    p = scene_command("grow", "quasi-static growth of the cracks along Σ (Griffith, or the damage of an "
                      "[interface] bilinear bond) as a load or displacement factor rises; an HDF5 file, a CSV and a "
                      "PNG of the curve, pictures of steps", cmd_grow)
    p.add_argument("-n", dest="ranks", type=int, metavar="N", help="launch N ranks with mpiexec (as for solve)")
    p.add_argument("-o", dest="output", help="HDF5 file of every step (default: SCENE-growth.h5; the curve "
                   "goes to the same name with .csv and .png)")
    p.add_argument("--to", dest="limit", type=_control_targets, metavar="FACTOR[,FACTOR...]",
                   help="the control factor's last value (it multiplies the scene's loads or displacements; "
                   "default: 2 × the initiation factor; a bilinear bond needs it); a bilinear bond also takes a "
                   "path, targets in turn: 0.2,0.05,0.3 rises to 0.2, unloads to 0.05 (the damage kept, along the "
                   "secant) and reloads to 0.3")
    p.add_argument("--steps", type=int, default=20, help="equal control steps up to --to, 1 to 1000 (default 20; "
                   "the initiation factor is added; a bilinear bond's steps are at most (its largest) --to/--steps, "
                   "halved where "
                   "its damage moves fast)")
    p.add_argument("--tolerance", type=float, default=1e-4, help="|G/G_c − 1| at a growing tip, 1e-8 to 1 "
                   "(default 1e-4)")
    p.add_argument("--pictures", type=int, default=3, metavar="K", help="pictures of the deformed structure at K "
                   "steps spread over the run, the last included (OUT-step<k>.png; default 3, 0 for none, at "
                   "most 100)")
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
    p.add_argument("--format", choices=tuple(viewer.FORMATS), default="vtu", help="file format (default: vtu)")
    p.add_argument("-o", dest="output", metavar="DIR", help="folder for the files (default: the result's)")
    command("scenes", "list the built-in scenes", cmd_scenes)
    command("version", "versions of ddsolve, PETSc and MPI", cmd_version)

    width = max(len(name) for commands in listing.values() for name, _ in commands) + 2
    top.epilog = "\n\n".join(group + ":\n" + "\n".join(f"  {name:{width}s}{summary}" for name, summary in commands)
                              for group, commands in listing.items())
    top.epilog += ("\n\nPETSc options (solve, reference) may come anywhere after the scene: ddsolve solve SCENE "
                   "-u_minus_ksp_type cg -u_minus_pc_type gamg -log_view")
    return top



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
    args.own, args.petsc = own, petsc_options
    args.ranks_at = _ranks_positions(own)
    if args.command in READERS:  # a file anyone wrote: its numbers may overflow; what matters is checked
        import numpy as np

        with np.errstate(all="ignore"):
            return args.run(args, petsc_options)
    if args.command in PETSC_COMMANDS:
        return runtime.unused_options_reported(lambda: args.run(args, petsc_options), PREFIXES.get(args.command, ()))
    return args.run(args, petsc_options)


#: The commands that read result files: numpy's warnings about their numbers are not printed (the
#: commands check what they compute and say in one line what is wrong).
READERS = ("check", "plot", "compare", "export")


def _ranks_positions(own: list[str]) -> set[int]:
    """Where ``-n N`` (or ``-n4``) is in ddsolve's arguments (removed when the ranks are started).
    Given twice, a usage error: the one left behind would make every rank launch ranks again."""
    found = [{i, i + 1} if arg == "-n" else {i} for i, arg in enumerate(own)
             if arg == "-n" or (arg.startswith("-n") and is_number(arg[2:]))]
    if len(found) > 1:
        given = ", ".join(" ".join(own[j] for j in sorted(at)) for at in found)
        raise UsageError(f"-n given {len(found)} times ({given}): give the number of ranks once")
    return found[0] if found else set()



