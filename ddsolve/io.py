"""Result files: HDF5 (the layout of docs/usage.md) and the viewer files derived from it, written as
one set that replaces the previous one together or not at all."""
from __future__ import annotations

import functools
import os
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Callable

import h5py
import numpy as np

from . import analysis, export
from .errors import DDSolveError
from .interface import BLOCKS
from .mesh import HalfMesh, Mesh, SigmaLine
from .result import Result

MULTIPLIERS = ("mu_c", "mu_g", "mu_minus", "mu_plus")
SIGMA_FIELDS = ("points", "normals", "weights", "crack", "tip", "clamped", "corner")


def replace_together(writers: dict[Path, Callable[[str], None]]) -> None:
    """Write a set of files so that they replace the previous ones together or not at all.

    Each ``write(temporary)`` writes its file under a temporary name in the target's folder; only
    when every one has succeeded are they renamed over their targets.  On any failure or interrupt
    the temporary files are removed and the previous files are left as they were.
    """
    temporaries: dict[Path, str] = {}
    try:
        for path, write in writers.items():
            path = Path(path)
            folder = path.parent
            if not folder.is_dir():
                raise DDSolveError(f"{path}: output directory {folder} does not exist")
            try:
                handle, temporaries[path] = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
                os.close(handle)
            except OSError as exc:
                raise DDSolveError(f"{path}: cannot write in {folder} ({exc.strerror})") from None
            try:
                write(temporaries[path])
                os.chmod(temporaries[path], 0o644)
            except OSError as exc:
                raise DDSolveError(f"{path}: cannot write ({exc.strerror or exc})") from None
        for path, temporary in temporaries.items():
            try:
                os.replace(temporary, path)
            except OSError as exc:
                raise DDSolveError(f"{path}: cannot replace ({exc.strerror or exc})") from None
    finally:
        for temporary in temporaries.values():
            if os.path.exists(temporary):
                os.unlink(temporary)


def atomic(path: Path, write: Callable[[str], None]) -> None:
    """Call ``write(temporary_path)`` then rename over ``path``: never a truncated file."""
    replace_together({Path(path): write})


@functools.lru_cache(maxsize=None)
def provenance() -> dict[str, str]:
    """What produced a file: ddsolve version and git commit, PETSc, MPI, Python, PETSc options.

    Computed once per process (it asks git); do not modify the returned dict.
    """
    import platform

    from petsc4py import PETSc
    from mpi4py import MPI

    from . import __version__

    checkout = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "-C", str(checkout), "rev-parse", "HEAD"], capture_output=True,
                                text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(checkout), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit, dirty = "", ""
    options = PETSc.Options().getAll()
    return {
        "version": __version__,
        "git_commit": (commit + ("-modified" if dirty else "")) or "unknown",
        "petsc": ".".join(map(str, PETSc.Sys.getVersion())),
        "mpi": MPI.Get_library_version().replace("\x00", "").splitlines()[0].strip(),
        "python": platform.python_version(),
        "petsc_options": " ".join(f"-{k} {v}".strip() for k, v in sorted(options.items())),
    }


def write(path: Path, result: Result, viewer: str = "vtu") -> list[Path]:
    """Write ``path`` (HDF5) and its viewer files (format ``viewer``, see :mod:`ddsolve.export`) beside
    it, as one set; returns the paths written."""
    path = Path(path)
    fields = analysis.cell_fields(result)
    writers = {path: lambda name: _write_hdf5(name, result, fields),
               **export.viewer_files(result, path.parent, path.stem, viewer, fields)}
    replace_together(writers)
    return list(writers)


def write_viewer(result: Result, folder: Path, stem: str, viewer: str = "vtu") -> list[Path]:
    """(Re)write the viewer files of ``result`` as ``folder/stem-*``; returns the paths written."""
    writers = export.viewer_files(result, Path(folder), stem, viewer)
    replace_together(writers)
    return list(writers)


def _write_hdf5(name: str, result: Result, fields: dict[str, analysis.CellFields]) -> None:
    started = time.perf_counter()
    with h5py.File(name, "w") as f:
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
        _write_fracture(f, result)
        for spec in BLOCKS:
            f[f"paraview/{spec.name}/displacement"] = export.padded(result.solution[spec.name])
            f[f"paraview/{spec.name}/von_mises"] = fields[spec.name].von_mises
        timings.attrs["write"] = time.perf_counter() - started


def read(path: Path) -> Result:
    """Read a result file written by :func:`write`."""
    path = Path(path)
    if not path.is_file():
        raise DDSolveError(f"{path}: result file not found")
    try:
        with h5py.File(path, "r") as f:
            halves = []
            for side, name in ((-1, "lower"), (1, "upper")):
                group = f[f"mesh/{name}"]
                boundaries = {key: edges[()] for key, edges in group.get("boundaries", {}).items()}
                halves.append(HalfMesh(group["points"][()], group["cells"][()], side, group["sigma"][()], boundaries))
            sigma = SigmaLine(**{key: f[f"sigma/{key}"][()] for key in SIGMA_FIELDS})
            known = {"converged", "iterations", "solves", "method", "wall_time", "ranks", "scene", "message"}
            return Result(
                scene=str(f.attrs["scene"]), method=str(f.attrs["method"]),
                converged=bool(f.attrs["converged"]), iterations=int(f.attrs["iterations"]),
                solves=int(f.attrs["solves"]), wall_time=float(f.attrs["wall_time"]),
                ranks=int(f.attrs["ranks"]), mesh=Mesh(*halves, sigma, str(path)),
                solution={spec.name: f[f"solution/{spec.name}"][()] for spec in BLOCKS},
                multipliers={name: f[f"interface/{name}"][()] for name in MULTIPLIERS},
                history=f["history/criterion"][()],
                active_set_changes=f["history/active_set_changes"][()] if "history/active_set_changes" in f
                else np.zeros(0, dtype=np.int64),
                cell_data={name: {block: values[()] for block, values in group.items()}
                           for name, group in f.get("cell_data", {}).items()},
                timings={k: float(v) for k, v in f["timings"].attrs.items()} if "timings" in f else {},
                memory=dict(f["memory"].attrs.items()) if "memory" in f else {},
                message=str(f.attrs.get("message", "")),
                attrs={k: v for k, v in f.attrs.items() if k not in known},
                fracture=_read_fracture(f),
            )
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise DDSolveError(f"{path}: not a ddsolve result file ({exc})") from None


# --- /fracture: G at the crack tips, crack faces and contact zones ------------------------------
#: Per-tip datasets of /fracture (the fields of ddsolve.fracture.Fracture), then the contact zones.
FRACTURE_FIELDS = ("points", "directions", "crack", "inner", "outer", "spacing", "G", "contact", "zones",
                   "zone_crack")


def _write_fracture(f, result: Result) -> None:
    """/fracture/{G, points, ...} (tips), /fracture/{zones, zone_crack} (contact zones as arc length along
    Σ) and, over the multiplier nodes, /fracture/arclength, opening ([u]·ν) and pressure (μᶜ)."""
    from .analysis import normal_jump

    if result.fracture is None:
        return
    group = f.create_group("fracture")
    for key in FRACTURE_FIELDS:
        group[key] = getattr(result.fracture, key)
    group["arclength"] = result.mesh.sigma.arclength[result.multiplier_nodes]
    group["opening"] = normal_jump(result)
    group["pressure"] = result.multipliers["mu_c"]


def _read_fracture(f):
    from .fracture import Fracture

    if "fracture" not in f:
        return None
    return Fracture(**{key: f[f"fracture/{key}"][()] for key in FRACTURE_FIELDS})
