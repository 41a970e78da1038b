"""Result files: HDF5 (the layout of docs/usage.md) and the viewer files derived from it, written as
one set that replaces the previous one together or not at all."""
from __future__ import annotations

import errno
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping

import h5py
import numpy as np

from ddsolve.errors import ArgumentError, DDSolveError, SceneError
from ddsolve.io.viewer import FORMATS, Distributed, distributed_files, padded, viewer_files, viewer_paths
from ddsolve.io.safe import check_targets, hdf5_image, recover, replace_together, same_file
from ddsolve.mesh.mesh import HalfMesh, Mesh, SigmaLine, blocks, region_of
from ddsolve.post import analysis, stack
from ddsolve.post.result import OnSigma, Result
from ddsolve.post.stack import StackResult
from ddsolve.problem import scene as scenes

MULTIPLIERS = ("mu_c", "mu_g", "mu_minus", "mu_plus")
#: The multipliers of a one-layer structure (no layers to glue: its files have no mu_minus, mu_plus datasets).
ONE_LAYER_MULTIPLIERS = MULTIPLIERS[:2]
#: The friction multiplier (the tangential traction between the crack faces), written with friction only.
FRICTION = ("mu_t",)
#: A bond law's (``[interface]``) per multiplier node: its damage and whether its normal row is pressed (0 or 1).
BOND = ("damage", "pressed")
#: A dataset of a result file holds at most this many times the file's size (ddsolve does not
#: compress them): a larger claim is a damaged header, not read.
READ_LIMIT = 16
SIGMA_FIELDS = ("points", "normals", "weights", "crack", "tip", "clamped", "corner")


#: Suffixes of a result file (and of a sweep file).
RESULT_SUFFIXES = (".h5", ".hdf5")



def check_result(path: Path, inputs: Iterable[Path] | Mapping[Path, str] = (), viewer: bool | str = True,
                 named: str = "-o") -> None:
    """Refuse a result (or sweep) file ``path`` that is not an HDF5 name, or whose set (with its viewer
    files unless not ``viewer``; a string: their format) cannot be written or would replace one of the
    ``inputs``; ``named``: how the messages name the path's argument."""
    path = Path(path)
    if not path.name:
        raise DDSolveError(f"{named} {str(path)!r}: not a file name")
    if path.suffix.lower() not in RESULT_SUFFIXES:
        raise DDSolveError(f"{named} {path}: a result is an HDF5 file: give it the suffix .h5"
                           + (" (its viewer files are written beside it)" if viewer else "")
                           + ("; this name is an input of this run" if any(same_file(path, s) for s in inputs) else ""))
    fmt = viewer if isinstance(viewer, str) else "vtu"
    check_targets([path, *(viewer_paths(path.parent, path.stem, fmt) if viewer else [])], inputs, named)




def check_viewer(viewer: object, named: str = "--format") -> None:
    """Refuse a viewer format that is not one of :data:`ddsolve.io.viewer.FORMATS`."""
    if not isinstance(viewer, str) or viewer not in FORMATS:
        raise ArgumentError(f"{named} must be one of {', '.join(map(repr, FORMATS))} (got {viewer!r:.40})")


def write(path: Path, result: Result, viewer: str = "vtu", final: bool = False) -> list[Path]:
    """Write ``path`` (HDF5) and its viewer files (format ``viewer``, see :mod:`ddsolve.io.viewer`) beside
    it, as one set (``final``: as for :func:`replace_together`); returns the paths written."""
    path = Path(path)
    started = time.perf_counter()
    fields = analysis.cell_fields(result)
    part = result_part(result, fields)
    writers = {path: lambda name: write_part(name, part, since=started),
               **viewer_files(result, path.parent, path.stem, viewer, fields)}
    replace_together(writers, final)
    return list(writers)


def parallel_available(comm) -> bool:
    """Whether the ranks of ``comm`` can write one HDF5 file together (h5py built with MPI, more than
    one rank): :func:`write_distributed` then writes a result without gathering it."""
    return comm is not None and comm.size > 1 and bool(h5py.get_config().mpi)


def write_distributed(path: Path, part: "Part", viewer: Distributed, comm, final: bool = False) -> list[Path]:
    """Every rank of ``comm`` writes its ``part`` of the result file ``path`` and its share of the VTU
    viewer files (``viewer``) into the same files, collectively (parallel HDF5); rank 0 commits the
    set as :func:`replace_together` does.  The file reads as :func:`write`'s."""
    path, started = Path(path), time.perf_counter()
    writers = {path: lambda name: write_part(name, part, comm, since=started),
               **distributed_files(viewer, path.parent, path.stem, comm)}
    replace_together(writers, final, comm)
    return list(writers)


def write_viewer(result: Result, folder: Path, stem: str, viewer: str = "vtu", final: bool = False) -> list[Path]:
    """(Re)write the viewer files of ``result`` as ``folder/stem-*``; returns the paths written."""
    writers = viewer_files(result, Path(folder), stem, viewer)
    replace_together(writers, final)
    return list(writers)


@dataclass(frozen=True)
class Slab:
    """The rows ``first:first + len(values)`` of a dataset of ``rows`` rows, the rest of which other ranks write."""

    values: np.ndarray
    first: int
    rows: int


@dataclass
class Part:
    """What one rank writes of a result file: datasets by path, whole (each held by one rank) or as
    :class:`Slab` (rows of it), and, on rank 0, the attributes by group ("" the root, "timings", "memory")."""

    datasets: dict[str, np.ndarray | Slab] = field(default_factory=dict)
    attrs: dict[str, dict] = field(default_factory=dict)


def half_datasets(half: HalfMesh, multiplier_nodes: np.ndarray, piece=None, skeleton: bool = True
                  ) -> dict[str, np.ndarray | Slab]:
    """``/mesh/<half>/...``: the points, cells, Σ nodes, interface nodes and boundaries of ``half`` (with
    ``piece``, a :class:`~ddsolve.mesh.pieces.Piece` of it: the slabs of its owned nodes and cells, and
    unless not ``skeleton`` Σ's nodes and the boundaries)."""
    group = f"mesh/{region_of(half.side)}"  # a region of several interfaces, too, as the half it is in its result
    out: dict[str, np.ndarray | Slab] = {}
    def numbered(local: np.ndarray) -> np.ndarray:  # the half's node numbers, as the half holds them
        return local if piece is None else piece.nodes[local].astype(local.dtype, copy=False)

    if piece is None:
        out = {f"{group}/points": half.points, f"{group}/cells": half.cells}
    else:
        out = {f"{group}/points": Slab(half.points[piece.owned_nodes], piece.first, piece.rows),
               f"{group}/cells": Slab(numbered(piece.owned_cells), piece.cell_first, piece.cell_rows)}
    if skeleton:
        sigma = numbered(half.sigma)
        out.update({f"{group}/sigma": sigma, f"{group}/interface": sigma[multiplier_nodes]})
        out.update({f"{group}/boundaries/{boundary}": numbered(edges) for boundary, edges in half.boundaries.items()})
        out.update({f"{group}/named_points/{name}": xy for name, xy in half.named_points.items()})
    return out


def block_datasets(block: str, u: np.ndarray, von_mises: np.ndarray, indicator: np.ndarray | None = None,
                   cell_data: dict[str, np.ndarray] | None = None, piece=None) -> dict[str, np.ndarray | Slab]:
    """A block's solution ``(n, 2)``, its viewer arrays, error indicators and per-cell data (with ``piece``:
    the slabs of its owned nodes and cells)."""
    def nodes(values):
        return values if piece is None else Slab(values, piece.first, piece.rows)

    def cells(values):
        return values if piece is None else Slab(values, piece.cell_first, piece.cell_rows)

    out = {f"solution/{block}": nodes(u), f"paraview/{block}/displacement": nodes(padded(u)),
           f"paraview/{block}/von_mises": cells(von_mises)}
    if indicator is not None:
        out[f"error/indicator/{block}"] = cells(indicator)
    out.update({f"cell_data/{name}/{block}": cells(values) for name, values in (cell_data or {}).items()})
    return out


def sigma_datasets(on: OnSigma, history: np.ndarray, active_set_changes: np.ndarray,
                   levels: dict[str, np.ndarray], fracture, reactions: dict[str, dict[str, np.ndarray]],
                   friction: scenes.Friction | None = None) -> dict[str, np.ndarray]:
    """What rank 0 writes: Σ, the interface, the history, the levels of an adaptive run, /fracture and
    /reactions; with ``friction`` the tangential traction ``interface/mu_t`` and ``interface/friction_state``
    (0 faces apart, 1 stick, 2 slip: :func:`ddsolve.post.analysis.friction_state`)."""
    sigma, nodes = on.sigma, on.sigma.multiplier_nodes
    out = {f"sigma/{key}": getattr(sigma, key) for key in SIGMA_FIELDS}
    out.update({"interface/x": sigma.points[nodes, 0], "interface/points": sigma.points[nodes],
                "interface/normal": sigma.normals[nodes], "interface/crack": sigma.crack[nodes],
                **{f"interface/{name}": on.multipliers[name] for name in MULTIPLIERS + FRICTION + BOND
                   if name in on.multipliers},
                **({"interface/friction_state": analysis.friction_state(on, friction)} if "mu_t" in on.multipliers else {}),
                "history/criterion": np.asarray(history, dtype=np.float64),
                "history/active_set_changes": np.asarray(active_set_changes, dtype=np.int64),
                **{f"levels/{name}": values for name, values in levels.items()}})
    out.update({f"reactions/{layer}/{name}": np.asarray(force, dtype=np.float64)
                for layer, named in reactions.items() for name, force in named.items()})
    if fracture is not None:
        out.update(fracture_datasets(fracture))
        out.update({"fracture/arclength": sigma.arclength[nodes], "fracture/opening": on.opening,
                    "fracture/pressure": on.multipliers["mu_c"]})
    return out


def fracture_datasets(fracture) -> dict[str, np.ndarray]:
    """``/fracture``: G and what goes with it at every tip, as reported too; each tip's and crack's interface
    with several interfaces only."""
    keys = FRACTURE_FIELDS + MODE_FIELDS + TOUGHNESS_FIELDS + OVERLAP_FIELDS + NOISE_FIELDS + INTERFACE_FIELDS
    out = {f"fracture/{key}": getattr(fracture, key) for key in keys}
    out.update({f"fracture/{key}": getattr(fracture, key) for key in STACK_FIELDS if getattr(fracture, key) is not None})
    out.update({f"fracture/reported/{key}": value for key, value in fracture.reported().items()})
    return out


def write_stack(path: Path, solved: StackResult) -> list[Path]:
    """Write a result of several interfaces (:class:`ddsolve.post.stack.StackResult`) to ``path``: each block's
    displacements (``/solution/u1`` ...), ``/fracture`` with each tip's interface, the energy and the check, and
    each interface's view as a one-interface result file's layout under ``/interfaces/N`` (N = 1 the lowest:
    its two regions' meshes, Σ, multipliers, history, G); no viewer files (``ddsolve export`` writes them)."""
    path = Path(path)
    datasets = {f"solution/{block}": u for block, u in solved.solution.items()}
    datasets.update(fracture_datasets(solved.fracture))
    attrs = {}
    for number, view in enumerate(solved.interfaces, start=1):
        part = result_part(view, analysis.cell_fields(view))
        datasets.update({f"interfaces/{number}/{key}": values for key, values in part.datasets.items()})
        attrs.update({f"interfaces/{number}/{group}".rstrip("/"): values for group, values in part.attrs.items()})
    root = {"converged": solved.converged, "method": solved.method, "scene": solved.scene.text,
            "message": solved.message, "energy": solved.energy, "interfaces": len(solved.interfaces),
            "iterations": solved.iterations, "wall_time": solved.wall_time}
    part = Part(datasets, {"": root, "timings": dict(solved.timings), **attrs})
    replace_together({path: lambda name: write_part(name, part)}, final=True)
    return [path]


def attributes(result: Result) -> dict[str, dict]:
    """The attributes of a result file by group: the root's, /timings, /materials (each block's: the key that
    gives it and its constants) and /memory."""
    root = {key: getattr(result, key) for key in ("converged", "iterations", "solves", "method", "wall_time",
                                                    "ranks", "scene", "message")}
    root["scene"] = result.scene.text  # the scene's canonical TOML text
    scene = result.scene
    blocks = {spec.name: f"{scene.material_key(spec.layer, spec.region)}: {scene.material(spec.layer, spec.region)!r}"
              for spec in result.blocks}
    return {"": {**root, **result.attrs}, "timings": dict(result.timings), "materials": blocks,
            **({"memory": dict(result.memory)} if result.memory else {})}


def result_part(result: Result, fields: dict[str, analysis.CellFields]) -> Part:
    """The whole result file as one process writes it."""
    datasets = {}
    for half in (result.lower, result.upper):
        datasets.update(half_datasets(half, result.multiplier_nodes))
    for spec in result.blocks:
        datasets.update(block_datasets(spec.name, result.solution[spec.name], fields[spec.name].von_mises,
                                       result.indicators.get(spec.name),
                                       {name: per_block[spec.name] for name, per_block in result.cell_data.items()
                                        if spec.name in per_block}))
    datasets.update(sigma_datasets(result.on_sigma, result.history, result.active_set_changes, result.levels,
                                   result.fracture, result.reactions, result.scene.friction))
    return Part(datasets, attributes(result))


def write_part(name: str, part: Part, comm=None, since: float | None = None) -> None:
    """Write the result file ``name``: in memory and in one piece (:func:`hdf5_image`), or with ``comm``
    (more than one rank, h5py with MPI) collectively, every rank its own datasets.  Every rank creates
    every dataset (shapes and types gathered first) and writes the attributes (rank 0's);
    ``/timings`` gets the seconds this took as ``write``, counted from ``since`` (``time.perf_counter()``
    when the files written with it began, :func:`ddsolve.io.safe.replace_together` writing it last)."""
    started = time.perf_counter() if since is None else since
    shapes = {key: ((values.rows,) + values.values.shape[1:], values.values.dtype.str) if isinstance(values, Slab)
              else (np.shape(values), np.asarray(values).dtype.str) for key, values in part.datasets.items()}
    attrs = part.attrs
    if comm is not None and comm.size > 1:
        shapes = {key: shape for mine in comm.allgather(shapes) for key, shape in mine.items()}
        attrs = comm.bcast(attrs, root=0)
        needed = sum(int(np.prod(shape)) * np.dtype(dtype).itemsize for shape, dtype in shapes.values())
        if not comm.bcast(_room(Path(name).parent, needed) if comm.rank == 0 else None, root=0):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # on every rank, before HDF5 writes a byte
        opened = h5py.File(name, "w", driver="mpio", comm=comm)
    else:
        opened = hdf5_image(name)
    try:
        with opened as f:
            created = {key: f.create_dataset(key, shape=shape, dtype=dtype)
                       for key, (shape, dtype) in sorted(shapes.items())}
            for key, values in part.datasets.items():
                if isinstance(values, Slab):
                    if len(values.values):
                        created[key][values.first:values.first + len(values.values)] = values.values
                elif np.size(values):
                    created[key][...] = values
            for group, values in attrs.items():
                target = f.require_group(group) if group else f
                for key, value in values.items():
                    target.attrs[key] = value
            elapsed = time.perf_counter() - started
            f.require_group("timings").attrs["write"] = comm.bcast(elapsed, root=0) if comm is not None else elapsed
    except RuntimeError as exc:  # h5py closing a file whose writes failed
        raise OSError(errno.EIO, " ".join(str(exc).split())) from None


#: Bytes a result file needs beyond its datasets' at most (groups, attributes, the scene's text).
HDF5_OVERHEAD = 1 << 20


def _room(folder: Path, needed: int) -> bool:
    """Whether ``folder``'s file system has room for a result file of ``needed`` bytes of datasets: checked
    before a parallel write, which the MPI-IO layer would report on every rank, in many lines, if it ran
    out of space (the serial write builds the file in memory and writes it whole)."""
    try:
        stats = os.statvfs(folder)
    except OSError:
        return True  # nothing known: the write says what fails
    if stats.f_blocks == 0:  # a file system that reports no sizes
        return True
    return stats.f_bavail * stats.f_frsize >= needed + HDF5_OVERHEAD


class ThreeDimensional(Exception):
    """A 3-D result met by the plane reader (:func:`read` refuses it in one line)."""


def read(path: Path) -> Result | StackResult:
    """Read a result file written by :func:`write` (or, of several interfaces, by :func:`write_stack`: a
    :class:`~ddsolve.post.stack.StackResult`), checking that its parts fit together (one line naming the file
    and the part otherwise)."""
    path = Path(path)
    recover([path])
    scenes.readable(path, "result file")
    try:
        with h5py.File(path, "r") as f:
            if int(f.attrs.get("dimension", 2)) == 3:
                raise ThreeDimensional
            runs, interfaces = _runs(f), int(f.attrs.get("interfaces", 1))
            if interfaces > 1 and "interfaces" not in f:
                raise DDSolveError(f"a result of {interfaces} interfaces written before such files were read back "
                                   "(no /interfaces): solve it again (ddsolve reference or solve)")
            result = None if runs else _read_stack(f, path) if "interfaces" in f else _read(f, path)
    except ThreeDimensional:
        raise DDSolveError(f"{path}: the result of a 3-D solve, where a plane one is read: plot and export read it, "
                           "compare reads two of them; check and the Python API's load take plane results only, "
                           "for now") from None
    except (OSError, KeyError, TypeError, ValueError, IndexError, AttributeError, RuntimeError, MemoryError) as exc:
        raise DDSolveError(f"{path}: not a ddsolve result file ({' '.join(str(exc).split())})") from None
    except DDSolveError as exc:
        raise DDSolveError(f"{path}: not a ddsolve result file ({exc})") from None
    if runs:
        raise DDSolveError(f"{path}: the file of a {runs}, not one solve's result: give a result file written by "
                           "solve or reference")
    return result


def _runs(f: h5py.File) -> str | None:
    """What ``f`` is if it is the file of a growth (``/growth``) or a sweep (its runs' ``parameters``), which hold
    many solves and no one result; None for any other file."""
    if "growth" in f:
        return "growth (its steps under /growth, docs/growth.md)"
    return "sweep (its runs' outcomes, docs/usage.md)" if "parameters" in f and "keys" in f.attrs else None


def _array(f: h5py.File, name: str, kind: str, shape: tuple) -> np.ndarray:
    """Dataset ``name`` as an array of ``kind`` (numpy kinds: "f" numbers, "i" integers, "b" flags)
    and ``shape`` (None: any length), checked before it is read (a damaged header may claim any size)."""
    dataset = _dataset(f, name)
    if dataset.dtype.kind not in {"f": "fiu", "i": "iu", "b": "biu"}[kind]:
        raise DDSolveError(f"{name} holds {dataset.dtype}, not {({'f': 'numbers', 'i': 'integers', 'b': 'flags'})[kind]}")
    got = dataset.shape or ()
    if len(got) != len(shape) or any(want is not None and size != want for size, want in zip(got, shape)):
        expected = tuple("n" if want is None else want for want in shape)
        raise DDSolveError(f"{name} has shape {got}, expected {expected}".replace("'", ""))
    values = dataset[()]
    if kind == "f" and not np.all(np.isfinite(values)) and name.startswith(("mesh/", "sigma/")):
        raise DDSolveError(f"{name} holds values that are not finite")
    return values.astype(bool) if kind == "b" else values


def _dataset(f: h5py.File, name: str) -> h5py.Dataset:
    """Dataset ``name``, if its size is one the file can hold."""
    dataset = f[name]
    if not isinstance(dataset, h5py.Dataset):
        raise DDSolveError(f"{name} is not a dataset")
    if dataset.size * dataset.dtype.itemsize > READ_LIMIT * os.path.getsize(f.file.filename) + 2 ** 20:
        raise DDSolveError(f"{name} claims {dataset.shape} values, more than the file can hold")
    return dataset


def _indices(values: np.ndarray, count: int, name: str) -> np.ndarray:
    if values.size and (values.min() < 0 or values.max() >= count):
        raise DDSolveError(f"{name} refers to node {int(values.max() if values.max() >= count else values.min())} "
                           f"of {count}")
    return values.astype(np.int64)


def _scene(f: h5py.File) -> scenes.Scene:
    """The scene a result file holds (its canonical TOML text)."""
    text = f.attrs["scene"]
    try:
        return scenes.loads(text.decode() if isinstance(text, bytes) else str(text), origin="its scene")
    except SceneError as exc:
        raise DDSolveError(str(exc)) from None


def _read(f: h5py.File, path: Path) -> Result:
    """The result in ``f`` (a file, or a group of one laid out alike)."""
    sigma_count = len(_array(f, "sigma/points", "f", (None, 2)))
    sigma = SigmaLine(**{key: _array(f, f"sigma/{key}", "f" if key in ("points", "normals", "weights") else "b",
                                     (sigma_count, 2) if key in ("points", "normals") else (sigma_count,))
                         for key in SIGMA_FIELDS})
    halves = []
    for side, name in ((-1, "lower"), (1, "upper")):
        group = f"mesh/{name}"
        points = _array(f, f"{group}/points", "f", (None, 2))
        cells = _indices(_array(f, f"{group}/cells", "i", (None, None)), len(points), f"{group}/cells")
        if cells.shape[1] not in (3, 6):
            raise DDSolveError(f"{group}/cells has {cells.shape[1]} nodes per cell, expected 3 or 6")
        on_sigma = _indices(_array(f, f"{group}/sigma", "i", (sigma_count,)), len(points), f"{group}/sigma")
        boundaries = {key: _indices(_array(f, f"{group}/boundaries/{key}", "i", (None, None)), len(points),
                                    f"{group}/boundaries/{key}") for key in f[group].get("boundaries", {})}
        named_points = {key: _array(f, f"{group}/named_points/{key}", "f", (None, 2))
                        for key in f[group].get("named_points", {})}
        halves.append(HalfMesh(points, cells, side, on_sigma, boundaries, named_points))
    mesh = Mesh(*halves, sigma, str(path))
    k = len(sigma.multiplier_nodes)
    scene = _scene(f)
    specs = blocks(scene.geometry.layers)
    solution = {spec.name: _array(f, f"solution/{spec.name}", "f", (len(mesh.half(spec.side).points), 2))
                for spec in specs}
    multipliers = {name: _array(f, f"interface/{name}", "f", (k,) if name == "mu_c" else (k, 2))
                   for name in (MULTIPLIERS if len(specs) == 4 else ONE_LAYER_MULTIPLIERS)}
    multipliers.update({name: _array(f, f"interface/{name}", "f", (k,)) for name in FRICTION + BOND
                        if f"interface/{name}" in f})
    for name, kind, shape in (("x", "f", (k,)), ("points", "f", (k, 2)), ("normal", "f", (k, 2)), ("crack", "b", (k,))):
        _array(f, f"interface/{name}", kind, shape)  # derived from the above: only their form is checked
    cell_data = {}
    for name, group in f.get("cell_data", {}).items():
        cell_data[name] = {}
        for block in group:
            half = mesh.half(-1 if block.endswith("minus") else 1)
            values = _dataset(f, f"cell_data/{name}/{block}")[()]
            if block not in {spec.name for spec in specs} or np.ndim(values) == 0 or len(values) != len(half.cells):
                raise DDSolveError(f"cell_data/{name}/{block} does not match the cells of its half")
            cell_data[name][block] = values
    known = {"converged", "iterations", "solves", "method", "wall_time", "ranks", "scene", "message"}
    return Result(
        scene=scene, method=str(f.attrs["method"]),
        converged=bool(f.attrs["converged"]), iterations=int(f.attrs["iterations"]),
        solves=int(f.attrs["solves"]), wall_time=float(f.attrs["wall_time"]),
        ranks=int(f.attrs["ranks"]), mesh=mesh, solution=solution, multipliers=multipliers,
        history=_array(f, "history/criterion", "f", (None,)),
        active_set_changes=_array(f, "history/active_set_changes", "i", (None,))
        if "history/active_set_changes" in f else np.zeros(0, dtype=np.int64),
        cell_data=cell_data,
        timings={k: float(v) for k, v in f["timings"].attrs.items()} if "timings" in f else {},
        memory=dict(f["memory"].attrs.items()) if "memory" in f else {},
        message=str(f.attrs.get("message", "")),
        attrs={k: v for k, v in f.attrs.items() if k not in known},
        fracture=_read_fracture(f),
        reactions={layer: {name: _array(f, f"reactions/{layer}/{name}", "f", (2,)) for name in f[f"reactions/{layer}"]}
                   for layer in f.get("reactions", {})},
        indicators={spec.name: _array(f, f"error/indicator/{spec.name}", "f", (len(mesh.half(spec.side).cells),))
                    for spec in specs if spec.name in f.get("error/indicator", {})},
        levels={name: _array(f, f"levels/{name}", "f", (None,)) for name in f.get("levels", {})},
    )


def _read_stack(f: h5py.File, path: Path) -> StackResult:
    """A file of :func:`write_stack`: each interface's view read as a one-interface result (its scene the
    view's: :func:`ddsolve.post.stack.view_scene`), the structure's mesh made of theirs, the blocks' fields."""
    scene = _scene(f)
    count = len(scene.geometry.sigmas)
    if int(f.attrs["interfaces"]) != count or sorted(f["interfaces"]) != [str(n) for n in range(1, count + 1)]:
        raise DDSolveError(f"/interfaces holds {sorted(f['interfaces'])}, not the scene's {count} interfaces")
    views = [_read(f[f"interfaces/{number}"], path) for number in range(1, count + 1)]
    counts = [len(view.mesh.sigma.pieces(view.mesh.sigma.crack)) for view in views]
    for index, (view, cracks) in enumerate(zip(views, stack.crack_slices(counts))):
        view.scene = stack.view_scene(scene, index, cracks)
    mesh = stack.mesh_of_views(scene, views, str(path))
    solution = {name: _array(f, f"solution/{name}", "f", (len(mesh.regions[region].points), 2))
                for name, _, region in stack.block_names(scene.geometry.layers, len(mesh.regions))}
    fracture = _read_fracture(f)
    return StackResult(scene, mesh, solution, float(f.attrs["energy"]), views, fracture, bool(f.attrs["converged"]),
                       str(f.attrs.get("message", "")), int(f.attrs["iterations"]),
                       {k: float(v) for k, v in f["timings"].attrs.items()})


# --- /fracture: G at the crack tips, crack faces and contact zones ------------------------------
#: Per-tip datasets of /fracture (the fields of ddsolve.post.result.Fracture), then the contact zones.
FRACTURE_FIELDS = ("points", "directions", "crack", "inner", "outer", "spacing", "G", "contact", "zones",
                   "zone_crack")
#: Per-tip datasets added later (the split into modes I and II): absent from older files, read as NaN.
MODE_FIELDS = ("G_I", "G_II", "phase", "symmetric")
#: Per-tip datasets added with the toughness (G_c and the critical load factor): absent from older files, read as NaN.
TOUGHNESS_FIELDS = ("toughness", "critical_factor")
#: Where the faces overlap, without non-penetration: absent from older files, read as none.
OVERLAP_FIELDS = ("overlaps", "overlap_crack")
#: G's noise level: absent from older files, read as NaN.
NOISE_FIELDS = ("noise",)
#: An interface crack between different materials: ε, K (t, 2) and the reference length of ψ; absent from
#: older files, read as NaN (and l = 1).
INTERFACE_FIELDS = ("epsilon", "K", "reference_length")
#: With several interfaces: each tip's interface and each crack's (1 the lowest); absent with one.
STACK_FIELDS = ("interface", "crack_interface")


def _read_fracture(f):
    from ddsolve.post.result import Fracture

    if "fracture" not in f:
        return None
    return Fracture(**{key: _dataset(f, f"fracture/{key}")[()] for key in FRACTURE_FIELDS},
                    **{key: _dataset(f, f"fracture/{key}")[()] for key in MODE_FIELDS + TOUGHNESS_FIELDS
                       + OVERLAP_FIELDS + NOISE_FIELDS + INTERFACE_FIELDS + STACK_FIELDS if f"fracture/{key}" in f})
