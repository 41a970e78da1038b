"""Result files: HDF5 (the layout of docs/usage.md) and the viewer files derived from it, written as
one set that replaces the previous one together or not at all."""
from __future__ import annotations

import os
import time
from pathlib import Path

import h5py
import numpy as np

from ddsolve.errors import DDSolveError, SceneError
from ddsolve.io import viewer as export
from ddsolve.io.safe import check_targets, hdf5_image, recover, replace_together, same_file
from ddsolve.mesh.mesh import BLOCKS, HalfMesh, Mesh, SigmaLine
from ddsolve.post import analysis
from ddsolve.post.result import Result
from ddsolve.problem import scene as scenes

MULTIPLIERS = ("mu_c", "mu_g", "mu_minus", "mu_plus")
#: A dataset of a result file holds at most this many times the file's size (ddsolve does not
#: compress them): a larger claim is a damaged header, not read.
READ_LIMIT = 16
SIGMA_FIELDS = ("points", "normals", "weights", "crack", "tip", "clamped", "corner")


#: Suffixes of a result file (and of a sweep file).
RESULT_SUFFIXES = (".h5", ".hdf5")



def check_result(path: Path, inputs: list[Path] = (), viewer: bool = True) -> None:
    """Refuse a result (or sweep) file ``path`` that is not an HDF5 name, or whose set (with its viewer
    files unless not ``viewer``) cannot be written or would replace one of the ``inputs``."""
    path = Path(path)
    if not path.name:
        raise DDSolveError(f"-o {str(path)!r}: not a file name")
    if path.suffix.lower() not in RESULT_SUFFIXES:
        raise DDSolveError(f"-o {path}: a result is an HDF5 file: give it the suffix .h5"
                           + (" (its viewer files are written beside it)" if viewer else "")
                           + ("; this name is an input of this run" if any(same_file(path, s) for s in inputs) else ""))
    check_targets([path, *(export.viewer_paths(path.parent, path.stem) if viewer else [])], inputs)




def write(path: Path, result: Result, viewer: str = "vtu", final: bool = False) -> list[Path]:
    """Write ``path`` (HDF5) and its viewer files (format ``viewer``, see :mod:`ddsolve.io.viewer`) beside
    it, as one set (``final``: as for :func:`replace_together`); returns the paths written."""
    path = Path(path)
    fields = analysis.cell_fields(result)
    writers = {path: lambda name: _write_hdf5(name, result, fields),
               **export.viewer_files(result, path.parent, path.stem, viewer, fields)}
    replace_together(writers, final)
    return list(writers)


def write_viewer(result: Result, folder: Path, stem: str, viewer: str = "vtu", final: bool = False) -> list[Path]:
    """(Re)write the viewer files of ``result`` as ``folder/stem-*``; returns the paths written."""
    writers = export.viewer_files(result, Path(folder), stem, viewer)
    replace_together(writers, final)
    return list(writers)


def _write_hdf5(name: str, result: Result, fields: dict[str, analysis.CellFields]) -> None:
    started = time.perf_counter()
    with hdf5_image(name) as f:
        for key in ("converged", "iterations", "solves", "method", "wall_time", "ranks", "scene", "message"):
            f.attrs[key] = getattr(result, key)
        for key, value in result.attrs.items():
            f.attrs[key] = value
        timings = f.create_group("timings")
        for key, value in result.timings.items():
            timings.attrs[key] = value
        if result.memory:
            memory = f.create_group("memory")
            for key, value in result.memory.items():
                memory.attrs[key] = value
        for half in (result.lower, result.upper):
            group = f.create_group(f"mesh/{half.name}")
            group["points"] = half.points
            group["cells"] = half.cells
            group["sigma"] = half.sigma
            group["interface"] = half.sigma[result.multiplier_nodes]
            for boundary, edges in half.boundaries.items():
                group[f"boundaries/{boundary}"] = edges
        sigma = result.mesh.sigma
        for key in SIGMA_FIELDS:
            f[f"sigma/{key}"] = getattr(sigma, key)
        for name, values in result.solution.items():
            f[f"solution/{name}"] = values
        f["interface/x"] = result.interface_x
        f["interface/points"] = result.interface_points
        f["interface/normal"] = result.normals
        f["interface/crack"] = result.crack
        for name in MULTIPLIERS:
            f[f"interface/{name}"] = result.multipliers[name]
        f["history/criterion"] = np.asarray(result.history, dtype=np.float64)
        f["history/active_set_changes"] = np.asarray(result.active_set_changes, dtype=np.int64)
        for name, per_block in result.cell_data.items():
            for block, values in per_block.items():
                f[f"cell_data/{name}/{block}"] = values
        for name, values in result.indicators.items():
            f[f"error/indicator/{name}"] = values
        for name, values in result.levels.items():
            f[f"levels/{name}"] = values
        _write_fracture(f, result)
        for spec in BLOCKS:
            f[f"paraview/{spec.name}/displacement"] = export.padded(result.solution[spec.name])
            f[f"paraview/{spec.name}/von_mises"] = fields[spec.name].von_mises
        timings.attrs["write"] = time.perf_counter() - started


def read(path: Path) -> Result:
    """Read a result file written by :func:`write`, checking that its parts fit together (one line
    naming the file and the part otherwise)."""
    path = Path(path)
    recover([path])
    scenes.readable(path, "result file")
    try:
        with h5py.File(path, "r") as f:
            result = _read(f, path)
    except (OSError, KeyError, TypeError, ValueError, IndexError, AttributeError, RuntimeError, MemoryError) as exc:
        raise DDSolveError(f"{path}: not a ddsolve result file ({' '.join(str(exc).split())})") from None
    except DDSolveError as exc:
        raise DDSolveError(f"{path}: not a ddsolve result file ({exc})") from None
    return result


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
    if dataset.size * dataset.dtype.itemsize > READ_LIMIT * os.path.getsize(f.filename) + 2 ** 20:
        raise DDSolveError(f"{name} claims {dataset.shape} values, more than the file can hold")
    return dataset


def _indices(values: np.ndarray, count: int, name: str) -> np.ndarray:
    if values.size and (values.min() < 0 or values.max() >= count):
        raise DDSolveError(f"{name} refers to node {int(values.max() if values.max() >= count else values.min())} "
                           f"of {count}")
    return values.astype(np.int64)


def _read(f: h5py.File, path: Path) -> Result:
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
        halves.append(HalfMesh(points, cells, side, on_sigma, boundaries))
    mesh = Mesh(*halves, sigma, str(path))
    k = len(sigma.multiplier_nodes)
    solution = {spec.name: _array(f, f"solution/{spec.name}", "f", (len(mesh.half(spec.side).points), 2))
                for spec in BLOCKS}
    multipliers = {name: _array(f, f"interface/{name}", "f", (k,) if name == "mu_c" else (k, 2)) for name in MULTIPLIERS}
    for name, kind, shape in (("x", "f", (k,)), ("points", "f", (k, 2)), ("normal", "f", (k, 2)), ("crack", "b", (k,))):
        _array(f, f"interface/{name}", kind, shape)  # derived from the above: only their form is checked
    cell_data = {}
    for name, group in f.get("cell_data", {}).items():
        cell_data[name] = {}
        for block in group:
            half = mesh.half(-1 if block.endswith("minus") else 1)
            values = _dataset(f, f"cell_data/{name}/{block}")[()]
            if block not in {spec.name for spec in BLOCKS} or np.ndim(values) == 0 or len(values) != len(half.cells):
                raise DDSolveError(f"cell_data/{name}/{block} does not match the cells of its half")
            cell_data[name][block] = values
    scene_text = f.attrs["scene"]
    scene_text = scene_text.decode() if isinstance(scene_text, bytes) else str(scene_text)
    try:
        scenes.loads(scene_text, origin="its scene")
    except SceneError as exc:
        raise DDSolveError(str(exc)) from None
    known = {"converged", "iterations", "solves", "method", "wall_time", "ranks", "scene", "message"}
    return Result(
        scene=scene_text, method=str(f.attrs["method"]),
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
        indicators={spec.name: _array(f, f"error/indicator/{spec.name}", "f", (len(mesh.half(spec.side).cells),))
                    for spec in BLOCKS if spec.name in f.get("error/indicator", {})},
        levels={name: _array(f, f"levels/{name}", "f", (None,)) for name in f.get("levels", {})},
    )


# --- /fracture: G at the crack tips, crack faces and contact zones ------------------------------
#: Per-tip datasets of /fracture (the fields of ddsolve.post.result.Fracture), then the contact zones.
FRACTURE_FIELDS = ("points", "directions", "crack", "inner", "outer", "spacing", "G", "contact", "zones",
                   "zone_crack")
#: Per-tip datasets added later (the split into modes I and II): absent from older files, read as NaN.
MODE_FIELDS = ("G_I", "G_II", "phase", "symmetric")


def _write_fracture(f, result: Result) -> None:
    """/fracture/{G, points, ...} (tips), /fracture/{zones, zone_crack} (contact zones as arc length along
    Σ) and, over the multiplier nodes, /fracture/arclength, opening ([u]·ν) and pressure (μᶜ)."""
    from ddsolve.post.analysis import normal_jump

    if result.fracture is None:
        return
    group = f.create_group("fracture")
    for key in FRACTURE_FIELDS + MODE_FIELDS:
        group[key] = getattr(result.fracture, key)
    group["arclength"] = result.mesh.sigma.arclength[result.multiplier_nodes]
    group["opening"] = normal_jump(result)
    group["pressure"] = result.multipliers["mu_c"]


def _read_fracture(f):
    from ddsolve.post.result import Fracture

    if "fracture" not in f:
        return None
    return Fracture(**{key: _dataset(f, f"fracture/{key}")[()] for key in FRACTURE_FIELDS},
                    **{key: _dataset(f, f"fracture/{key}")[()] for key in MODE_FIELDS if f"fracture/{key}" in f})
