"""Parameter sweeps: many solves on one launch, one HDF5 file with every run.

``ddsolve sweep SCENE --set KEY=START:STOP:COUNT [--set KEY=START:STOP:COUNT:log ...] [--set KEY=VALUE ...]``
solves the scene for every combination of the ranges (``--zip``: for the ranges taken side by side;
they must then have the same COUNT); a ``--set`` whose value is not a range is a fixed override.  A
number in a key indexes a list: ``--set geometry.crack.0=-0.2:-0.8:7 --set geometry.crack.1=0.2:0.8:7
--zip`` lengthens the crack symmetrically.  With ``mesh.target_error`` every run is adaptive
(:mod:`ddsolve.solvers.adapt`; nothing is reused).  What cannot finish is refused before the first solve,
naming the ranges: more than ``MAX_RUNS`` runs (before their values are made), more than ``MAX_HOURS``
by an estimate from below of each run's cost from its mesh size (:func:`run_seconds`), or a mesh that
does not fit in memory.

Every rank loops over the runs; what does not change is reused: the mesh while the geometry and mesh
keys stay the same, the assembled and factored blocks while only loads change (new right-hand sides
only).  After each run rank 0 prints a progress line; when every run has ended it writes the output
file, replacing the previous one whole (an interrupted sweep leaves the previous file as it was;
``complete`` is always true, kept for files of earlier versions).  File layout (R runs,
T the most tips of a run, padded with NaN or −1):

- attributes: ``scene`` (as given), ``fixed`` (the fixed overrides), ``keys`` (the swept keys),
  ``mode`` (product or zip), ``runs``, ``complete``, provenance;
- ``parameters/KEY`` (R,) the value of each swept key;
- ``energy``, ``converged``, ``iterations``, ``rounds``, ``unknowns``, ``kkt_tolerance`` (of the final
  check, from solver.tol), ``mesh_reused``,
  ``factors_reused``, ``factors_out_of_core`` (MUMPS kept the factors on disk, ``solver.out_of_core``),
  ``time`` (the whole run), ``setup_time``, ``factorization_time``,
  ``solve_time`` (R,), ``message`` (R,) strings (empty when the run succeeded);
- ``tips/G``, ``tips/G_I``, ``tips/G_II``, ``tips/phase``, ``tips/contact``, ``tips/inner``, ``tips/outer``,
  ``tips/spacing``, ``tips/crack``, ``tips/toughness``, ``tips/critical_factor`` (R, T),
  ``tips/points``, ``tips/directions`` (R, T, 2): G at every crack tip (see ddsolve.post.fracture), G_c and
  the critical load factor (ddsolve.post.toughness; NaN without a toughness, and for a scene with a
  temperature change, whose factors need a root solve per run);
- ``contact_zones/run``, ``start``, ``end``, ``crack`` (Z,): every contact zone of every run, as arc
  length along Σ; ``overlap_zones/...`` the same where the faces overlap (a scene without non-penetration).
"""
from __future__ import annotations

import itertools
import math
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ddsolve.errors import DDSolveError, NotConvergedError, SceneError
from ddsolve.parallel import distribution

#: ``START:STOP:COUNT`` or ``START:STOP:COUNT:log`` (geometric spacing).
_RANGE = re.compile(r"^\s*([^:\s]+)\s*:\s*([^:\s]+)\s*:\s*([0-9]+)\s*(?::\s*(lin|log)\s*)?$")
#: The most runs of a sweep: every run's scene is checked before the first solve, and after every run
#: the output file is written again with all runs so far (the writing grows as the square of the runs).
MAX_RUNS = 10_000
#: The longest a sweep may take by :func:`run_seconds` (an estimate from below), in hours.
MAX_HOURS = 24.0
#: What a run costs at least (on two ranks; about a third of what was measured, 0.02-0.04 s for the
#: P = 13 mesh of 86 nodes and 0.3-0.8 s for P = 200, 10,000 nodes): seconds for a run that reuses the
#: mesh and the factorization, and seconds more per mesh node (P2 nodes counted); and, for writing the
#: file again after every run, seconds per run already in it.  A run whose blocks change also factors
#: them (:data:`ddsolve.dd.registry.COST_LAWS`).
RUN_SECONDS = 0.02
NODE_SECONDS = 1e-5
RECORD_SECONDS = 2e-5


@dataclass(frozen=True)
class Range:
    """A swept key and its values (``item``: the ``--set`` item it comes from)."""

    key: str
    values: tuple
    item: str = ""


def _range(item: str) -> tuple | None:
    """(key, (START, STOP) texts and numbers, COUNT, spacing) of a range item, None for a fixed value."""
    key, sep, value = item.partition("=")
    match = _RANGE.match(value) if sep else None
    if match is None:
        return None
    texts, digits, spacing = match.group(1, 2), match.group(3), match.group(4) or "lin"
    count = int(digits) if len(digits) <= 15 else float(digits)  # (huge counts are refused, not made)
    try:
        numbers = tuple(float(text) for text in texts)
    except ValueError:
        return None  # not numbers: a plain value that happens to contain colons
    return key.strip(), texts, numbers, count, spacing


def run_seconds(scene, ranks: int, factor: bool = True) -> float:
    """A lower estimate of one run's seconds on ``ranks`` ranks from the size of its mesh (when it can be
    known beforehand): the rounds, the error estimate and G, and with ``factor`` the factorization of the
    structure's blocks (each has about as many unknowns as the mesh has nodes)."""
    from ddsolve.dd.registry import COST_LAWS
    from ddsolve.mesh import geometry
    from ddsolve.mesh.mesh import blocks

    nodes = geometry.estimated_vertices(scene) or 0.0
    a, power = COST_LAWS["factor"]
    count = len(blocks(scene.geometry.layers))
    return RUN_SECONDS + NODE_SECONDS * nodes + (count * a * nodes ** power / ranks if factor else 0.0)


def sweep_seconds(solving: float, runs: float) -> float:
    """A lower estimate of a sweep's seconds: its runs' (``solving``, :func:`run_seconds` summed) and the
    writing of its file after every run."""
    return solving + RECORD_SECONDS * runs * (runs - 1) / 2


def _duration(seconds: float) -> str:
    for unit, length, up_to in (("s", 1, 120), ("min", 60, 7200), ("h", 3600, 3 * 86400), ("days", 86400, math.inf)):
        if seconds < up_to or unit == "days":
            value = seconds / length
            return f"{value:,.0f} {unit}" if 10 <= value < 1e5 else f"{value:.2g} {unit}"


def _too_many(named: str, runs: float, per_run: float | None) -> str:
    cost = (f"; at about {per_run:.2g} s a run they would take at least about "
            f"{_duration(sweep_seconds(runs * per_run, runs))}" if per_run else "")
    count = f"{runs:,}" if isinstance(runs, int) else f"about {runs:.3g}" if math.isfinite(runs) else "countless"
    return (f"{named}: {count} runs, more than the {MAX_RUNS:,} a sweep makes (all are checked before the first, "
            f"and the output file is written again after each){cost}: lower COUNT or split the sweep")


def parse(items: list[str], per_run: float | None = None) -> tuple[list[str], list[Range]]:
    """Split ``--set`` items into fixed overrides and ranges; raise SceneError for a bad range, or one of
    more than MAX_RUNS values (before making them; ``per_run``: the seconds of a run, for the message)."""
    fixed, ranges = [], []
    for item in items:
        parts = _range(item)
        if parts is None:
            fixed.append(item)
            continue
        key, texts, (start, stop), count, spacing = parts
        if count < 1:
            raise SceneError(f"--set {item}: COUNT must be at least 1")
        if count > MAX_RUNS:
            raise SceneError(_too_many(f"--set {item}", count, per_run))
        if spacing == "log":
            if start <= 0 or stop <= 0:
                raise SceneError(f"--set {item}: a log range needs START > 0 and STOP > 0")
            values = np.geomspace(start, stop, count)
        else:
            values = np.linspace(start, stop, count)
        integral = all(re.fullmatch(r"[+-]?[0-9]+", text) for text in texts)
        whole = np.isclose(values, np.round(values)) & integral  # integers stay integers (an integer key's too)
        values = tuple(int(round(v)) if is_whole else float(v) for v, is_whole in zip(values, whole))
        if any(r.key == key for r in ranges):
            raise SceneError(f"--set {item}: {key} is swept twice")
        ranges.append(Range(key, values, item))
    if not ranges:  # a value with colons that is not a range is a range mistyped, not a value to keep
        mistyped = next((item for item in fixed if ":" in item.partition("=")[2]), None)
        if mistyped is not None:
            raise SceneError(f"--set {mistyped}: not a range START:STOP:COUNT[:log] (START and STOP numbers, "
                             "COUNT a whole number)")
    return fixed, ranges


def plan(ranges: list[Range], paired: bool, per_run: float | None = None) -> list[dict]:
    """The runs: key -> value for every combination of the ranges (the last varying fastest), or for
    the ranges side by side when ``paired``.  Raises SceneError for more than MAX_RUNS runs (before
    making them; ``per_run``: the seconds of a run, for the message)."""
    if not ranges:
        raise SceneError("sweep: no range to sweep; give --set KEY=START:STOP:COUNT")
    if paired:
        counts = {len(r.values) for r in ranges}
        if len(counts) > 1:
            raise SceneError("--zip: the ranges must have the same COUNT (" +
                             ", ".join(f"{r.key}: {len(r.values)}" for r in ranges) + ")")
        combinations = zip(*(r.values for r in ranges))
    elif math.prod(len(r.values) for r in ranges) > MAX_RUNS:
        raise SceneError(_too_many(" x ".join(f"--set {r.item or r.key}" for r in ranges),
                                   math.prod(len(r.values) for r in ranges), per_run))
    else:
        combinations = itertools.product(*(r.values for r in ranges))
    return [dict(zip((r.key for r in ranges), combination)) for combination in combinations]


def overrides(run: dict) -> list[str]:
    from ddsolve.problem.scene import override_items

    return override_items(run)


def given_range(key: str, values) -> Range:
    """The range of the Python API's ``{key: values}``: a non-empty list (or array) of values."""
    values = values.tolist() if hasattr(values, "tolist") else values
    if isinstance(values, (str, bytes)) or not hasattr(values, "__len__") or len(values) == 0:
        raise SceneError(f"{key}: a sweep takes a non-empty list of values (got {values!r})")
    return Range(key, tuple(values))


def describe(run: dict) -> str:
    return " ".join(f"{key}={value:.6g}" if isinstance(value, float) else f"{key}={value}"
                    for key, value in run.items())


def scene_with(source, items: list[str]):
    """The scene ``source`` (a Scene, a file or a built-in name) with the ``KEY=VALUE`` items."""
    from ddsolve.problem.scene import Scene

    return source.with_(items) if isinstance(source, Scene) else Scene.load(source, items)


def load_scenes(source, fixed: list[str], runs: list[dict]) -> list:
    """Every run's scene, checked before anything is solved (errors name the run)."""
    out = []
    for number, run in enumerate(runs, 1):
        try:
            out.append(scene_with(source, fixed + overrides(run)))
        except SceneError as exc:
            raise SceneError(f"sweep run {number} ({describe(run)}): {exc}") from None
    return out


def _base_seconds(source, fixed: list[str], ranks: int) -> float | None:
    """:func:`run_seconds` of the scene with the fixed overrides, its factorization reused (None if the
    scene is not valid without the ranges)."""
    try:
        return run_seconds(scene_with(source, fixed), ranks, factor=False)
    except SceneError:
        return None


def check_plane(source, items: list[str]) -> None:
    """Refuse a 3-D scene in its own line where a command solves plane ones only (sweep, grow), before the ranks
    are counted by the plane's rule: ``source`` a scene file or a built-in name, with the ``--set`` ``items`` that
    are not ranges (a scene that does not load without its ranges is left to the command)."""
    from ddsolve.solvers.checks import check_size

    try:
        scene = scene_with(source, parse(items)[0])
    except DDSolveError:
        return
    if scene.geometry.dimension == 3:
        check_size(scene, solving=False)


def check_cost(items: list[str], scenes: list, runs: list[dict], ranges: list[Range], ranks: int) -> None:
    """Refuse a sweep given a key it does not read (:func:`ddsolve.cli.check_read`), or that cannot
    finish: one whose largest mesh does not fit in this machine's memory (:func:`ddsolve.cli.check_size`),
    whose runs take more than MAX_HOURS by :func:`sweep_seconds`, or whose out-of-core factors have no
    folder (:func:`ddsolve.parallel.runtime.check_out_of_core`)."""
    from ddsolve.mesh import geometry
    from ddsolve.parallel.runtime import check_out_of_core
    from ddsolve.solvers.checks import check_read, check_size

    check_out_of_core(any(scene.solver.out_of_core for scene in scenes))
    check_read("sweep", items, scenes[0])

    nodes = [geometry.estimated_vertices(scene) or 0.0 for scene in scenes]
    largest = int(np.argmax(nodes))
    try:
        check_size(scenes[largest], ranks)
    except DDSolveError as exc:
        raise DDSolveError(f"sweep run {largest + 1} ({describe(runs[largest])}): {exc}") from None
    seconds, previous = [], None
    for scene in scenes:  # what the loop below reuses: the factorization while only loads change
        reused = previous is not None and scene.mesh.target_error is None and \
            (_mesh_key(scene), _blocks_key(scene)) == (_mesh_key(previous), _blocks_key(previous))
        seconds.append(run_seconds(scene, ranks, factor=not reused))
        previous = scene
    total = sweep_seconds(sum(seconds), len(runs))
    if total > 3600 * MAX_HOURS:
        raise SceneError(f"{' x '.join(f'--set {r.item or r.key}' for r in ranges)}: {len(runs):,} runs would take "
                         f"at least about {_duration(total)} (up to {max(seconds):.2g} s a run on meshes of up to "
                         f"about {max(nodes):.2g} nodes), more than the {MAX_HOURS:g} h a sweep may take: lower COUNT, "
                         "coarsen the mesh or split the sweep")


def sweep(source, items: list[str], paired: bool, output: Path | None, comm, progress=print,
          values: dict | None = None, named: str = "-o") -> list[dict] | None:
    """Run the sweep of ``source`` (a Scene, a scene file or a built-in name) on ``comm`` (every rank):
    ``items`` are ``--set`` items (ranges and fixed values), ``values`` more swept keys with their values
    given (key -> sequence).  Writes ``output`` (if given; ``named``: how messages name it) on rank 0 at
    the end; it may be none of the files the scenes read.

    Returns the records on rank 0 (None elsewhere).
    """
    from ddsolve.mesh import geometry
    from ddsolve.parallel.exchange import collective
    from ddsolve.solvers import adapt, driver

    runs, scenes, header = planned(source, items, paired, output, comm, values, named)
    records: list[dict] = []
    mesh = setup = previous = None
    try:
        for number, (run, scene) in enumerate(zip(runs, scenes), 1):
            started = time.perf_counter()
            same_mesh = previous is not None and mesh is not None and _mesh_key(scene) == _mesh_key(previous)
            same_blocks = same_mesh and setup is not None and _blocks_key(scene) == _blocks_key(previous)
            if setup is not None and not same_blocks:
                setup.destroy()
                setup = None
            previous = scene
            record = {"parameters": run, "mesh_reused": same_mesh, "factors_reused": same_blocks}
            try:
                adaptive = scene.mesh.target_error is not None  # its levels are meshed and factored anew
                if same_mesh:
                    collective(comm, lambda: geometry.check_loads(scene, mesh), root_only=True)
                else:
                    mesh = None
                    mesh = None if adaptive else distribution.build_mesh(scene, comm)
                if same_blocks:
                    driver.reload(setup, scene)
                elif not adaptive:
                    setup = driver.prepare(scene, comm, mesh)
                try:
                    result = (adapt.solve_adaptively(scene, comm, None, progress=lambda line: None) if adaptive else
                              driver.solve_decomposed(scene, comm, None, progress=lambda line: None, setup=setup))
                except NotConvergedError as exc:
                    result = getattr(exc, "result", None)
                    record["message"] = str(exc)
            except DDSolveError as exc:
                if not exc.collective:
                    raise
                result = None
                record["message"] = str(exc)
            record["time"] = time.perf_counter() - started
            if comm.rank == 0:
                record.update(_numbers(result))
                records.append(record)
                progress(_line(number, len(runs), record))
        if output is not None:
            collective(comm, lambda: _write(output, header, records), root_only=True)
    finally:
        if setup is not None:
            setup.destroy()
    return records if comm.rank == 0 else None


def planned(source, items: list[str], paired: bool, output: Path | None, comm, values: dict | None,
            named: str) -> tuple[list[dict], list, dict]:
    """What :func:`sweep` will run, checked before the first solve, the same on every rank: the runs, their
    scenes and the output file's header."""
    from ddsolve.parallel.exchange import collective
    from ddsolve.problem.scene import Scene

    def arrange():
        per_run = _base_seconds(source, [item for item in items if _range(item) is None], comm.size)
        fixed, ranges = parse(items, per_run)
        ranges += [given_range(key, value) for key, value in (values or {}).items()]
        return fixed, ranges, plan(ranges, paired, per_run)

    fixed, ranges, runs = collective(comm, arrange)  # the same on every rank, errors included

    def check():
        from ddsolve.io import inputs
        from ddsolve.io.hdf5 import check_result

        scenes = load_scenes(source, fixed, runs)
        if output is not None:
            check_result(output, inputs.of_scenes(scenes, None if isinstance(source, Scene) else source),
                         viewer=False, named=named)
        return scenes

    scenes = comm.bcast(collective(comm, check, root_only=True), root=0)
    collective(comm, lambda: check_cost(items, scenes, runs, ranges, comm.size), root_only=True)
    header = {"scene": source.origin if isinstance(source, Scene) else str(source), "fixed": " ".join(fixed), "keys": [r.key for r in ranges],
              "mode": "zip" if paired else "product"}
    return runs, scenes, header


def _mesh_key(scene) -> tuple:
    """What the mesh depends on: the geometry and mesh keys, and the point supports (the box has a vertex at each)."""
    return (scene.geometry, scene.mesh, sorted(d.point for d in scene.displacements.values() if d.point is not None))


def _blocks_key(scene) -> tuple:
    """What the assembled and factored blocks depend on besides the mesh (loads excluded; prescribed
    displacements decide which dofs the blocks hold, and their values the Σ supports)."""
    return (scene.materials, scene.regions, scene.model, scene.nonpenetration, scene.solver.method,
            scene.solver.out_of_core, scene.displacements)


def _numbers(result) -> dict:
    """What a run's record keeps of its result (NaN when the run failed)."""
    if result is None:
        return {"converged": False, "energy": math.nan, "iterations": 0, "rounds": 0, "unknowns": 0,
                "setup_time": math.nan, "factorization_time": math.nan, "solve_time": math.nan, "fracture": None,
                "kkt_tolerance": math.nan, "factors_out_of_core": False}
    timings = result.timings
    return {
        "converged": bool(result.converged), "energy": float(result.attrs.get("energy", math.nan)),
        "iterations": int(result.iterations), "rounds": int(result.solves),
        "unknowns": result.unknowns,
        "setup_time": float(timings.get("setup", math.nan)),
        "factorization_time": float(timings.get("factorization", math.nan)),
        "solve_time": float(timings.get("iterations", math.nan)), "fracture": result.fracture,
        "kkt_tolerance": float(result.attrs.get("kkt_tolerance", math.nan)),
        "factors_out_of_core": bool(result.attrs.get("factors_out_of_core", False)),
    }


def _line(number: int, total: int, record: dict) -> str:
    fracture = record["fracture"]
    if fracture is None:
        outcome = "failed: " + record.get("message", "")
    else:
        rates = ", ".join(f"{g:.4e} at ({x:.4g}, {y:.4g})" for g, (x, y) in zip(fracture.G, fracture.points))
        outcome = (f"energy {record['energy']:.6e}" + (f"; G = {rates}" if rates else "; no crack tip") +
                   ("" if record["converged"] else "; NOT converged"))
    reused = [name for name, key in (("mesh", "mesh_reused"), ("factorization", "factors_reused")) if record[key]]
    return (f"sweep {number}/{total} {describe(record['parameters'])}: {outcome}; {record['rounds']} rounds, "
            f"{record['time']:.2f} s" + (f" ({' and '.join(reused)} reused)" if reused else ""))


SCALARS = ("energy", "converged", "iterations", "rounds", "unknowns", "mesh_reused", "factors_reused", "time",
           "setup_time", "factorization_time", "solve_time", "kkt_tolerance", "factors_out_of_core")
TIP_FIELDS = {"G": np.nan, "contact": np.nan, "inner": np.nan, "outer": np.nan, "spacing": np.nan, "crack": -1,
              "G_I": np.nan, "G_II": np.nan, "phase": np.nan, "toughness": np.nan, "critical_factor": np.nan}


def _write(path: Path, header: dict, records: list[dict]) -> None:
    import h5py

    from ddsolve.io.safe import atomic
    from ddsolve.parallel.launch import provenance

    count = max((len(r["fracture"].G) for r in records if r["fracture"] is not None), default=0)

    def tips(field: str, width: tuple = ()) -> np.ndarray:
        fill = TIP_FIELDS.get(field, np.nan)
        out = np.full((len(records), count, *width), fill, dtype=np.int64 if field == "crack" else np.float64)
        for i, record in enumerate(records):
            if record["fracture"] is not None:
                values = getattr(record["fracture"], field)
                out[i, :len(values)] = values
        return out

    def write(name: str) -> None:
        with h5py.File(name, "w") as f:
            for key, value in {**provenance(), **header, "runs": len(records), "complete": True}.items():
                f.attrs[key] = value
            for key in header["keys"]:
                f[f"parameters/{key}"] = np.array([r["parameters"][key] for r in records])
            for key in SCALARS:
                f[key] = np.array([r[key] for r in records])
            f["message"] = np.array([r.get("message", "") for r in records], dtype=h5py.string_dtype())
            for field in TIP_FIELDS:
                f[f"tips/{field}"] = tips(field)
            f["tips/points"] = tips("points", (2,))
            f["tips/directions"] = tips("directions", (2,))
            for group, spans, cracks in (("contact_zones", "zones", "zone_crack"),
                                         ("overlap_zones", "overlaps", "overlap_crack")):
                zones = [(i, start, end, crack) for i, r in enumerate(records) if r["fracture"] is not None
                         for (start, end), crack in zip(getattr(r["fracture"], spans), getattr(r["fracture"], cracks))]
                columns = np.array(zones, dtype=np.float64).reshape(-1, 4)
                f[f"{group}/run"] = columns[:, 0].astype(np.int64)
                f[f"{group}/start"] = columns[:, 1]
                f[f"{group}/end"] = columns[:, 2]
                f[f"{group}/crack"] = columns[:, 3].astype(np.int64)

    atomic(path, write, final=True)


def read(path: Path) -> dict:
    """A sweep file as a dict: attributes under ``attrs``, datasets by their path (``tips/G``, ...)."""
    import h5py

    from ddsolve.problem.scene import readable

    path = readable(path, "sweep file")
    out: dict = {}
    try:
        with h5py.File(path, "r") as f:
            out["attrs"] = dict(f.attrs)
            f.visititems(lambda name, item: out.__setitem__(name, item[()]) if isinstance(item, h5py.Dataset)
                         else None)
    except OSError as exc:
        raise DDSolveError(f"{path}: not a sweep file ({exc})") from None
    out["message"] = np.array([m.decode() if isinstance(m, bytes) else m for m in out.get("message", [])])
    return out
