"""Result files: HDF5 (the layout of docs/usage.md) written atomically, and XDMF for ParaView."""
from __future__ import annotations

import functools
import os
import subprocess
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from .errors import DDSolveError
from .interface import BLOCKS
from .mesh import HalfMesh, Mesh, SigmaLine
from .result import Result

MULTIPLIERS = ("mu_c", "mu_g", "mu_minus", "mu_plus")
SIGMA_FIELDS = ("points", "normals", "weights", "crack", "tip", "clamped", "corner")


def atomic(path: Path, write) -> None:
    """Call ``write(temporary_path)`` then rename over ``path``: never a truncated file."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise DDSolveError(f"{path}: output directory {folder} does not exist")
    try:
        handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
        os.close(handle)
    except OSError as exc:
        raise DDSolveError(f"{path}: cannot write in {folder} ({exc.strerror})") from None
    try:
        write(temporary)
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    except OSError as exc:
        raise DDSolveError(f"{path}: cannot write ({exc.strerror or exc})") from None
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)


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


def write(path: Path, result: Result) -> None:
    """Write ``path`` (HDF5) and the XDMF file beside it, each atomically."""
    path = Path(path)
    atomic(path, lambda name: _write_hdf5(name, result))
    atomic(path.with_suffix(".xdmf"), lambda name: Path(name).write_text(xdmf(path.name, result)))


def _write_hdf5(name: str, result: Result) -> None:
    from .analysis import layer_stresses  # von Mises per cell for the ParaView fields

    started = time.perf_counter()
    with h5py.File(name, "w") as f:
        for key in ("converged", "iterations", "solves", "method", "wall_time", "ranks", "scene", "message"):
            f.attrs[key] = getattr(result, key)
        for key, value in result.attrs.items():
            f.attrs[key] = value
        timings = f.create_group("timings")
        for key, value in result.timings.items():
            timings.attrs[key] = value
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
        for name, values in result.indicators.items():
            f[f"error/indicator/{name}"] = values
        for name, values in result.levels.items():
            f[f"levels/{name}"] = values
        stresses = layer_stresses(result)
        for spec in BLOCKS:
            padded = np.zeros((len(result.solution[spec.name]), 3))
            padded[:, :2] = result.solution[spec.name]
            f[f"paraview/{spec.name}/displacement"] = padded
            f[f"paraview/{spec.name}/von_mises"] = stresses[spec.name]
        timings.attrs["write"] = time.perf_counter() - started


def xdmf(h5_name: str, result: Result) -> str:
    """XDMF 3 text: one grid per block (mesh of its half), displacement and von Mises stress."""
    grids = []
    for spec in BLOCKS:
        half = result.half(spec.name)
        n, (m, k) = len(half.points), half.cells.shape
        item = 'Format="HDF" Precision="8" NumberType="Float"'
        grids.append(f"""    <Grid Name="{spec.name}" GridType="Uniform">
      <Topology TopologyType="{'Triangle' if k == 3 else 'Triangle_6'}" NumberOfElements="{m}">
        <DataItem Dimensions="{m} {k}" NumberType="Int" Precision="8" Format="HDF">{h5_name}:/mesh/{half.name}/cells</DataItem>
      </Topology>
      <Geometry GeometryType="XY">
        <DataItem Dimensions="{n} 2" {item}>{h5_name}:/mesh/{half.name}/points</DataItem>
      </Geometry>
      <Attribute Name="displacement" AttributeType="Vector" Center="Node">
        <DataItem Dimensions="{n} 3" {item}>{h5_name}:/paraview/{spec.name}/displacement</DataItem>
      </Attribute>
      <Attribute Name="von_mises" AttributeType="Scalar" Center="Cell">
        <DataItem Dimensions="{m}" {item}>{h5_name}:/paraview/{spec.name}/von_mises</DataItem>
      </Attribute>
    </Grid>""")
    body = "\n".join(grids)
    return f"""<?xml version="1.0" ?>
<Xdmf Version="3.0">
  <Domain>
  <Grid Name="ddsolve" GridType="Collection" CollectionType="Spatial">
{body}
  </Grid>
  </Domain>
</Xdmf>
"""


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
                timings={k: float(v) for k, v in f["timings"].attrs.items()} if "timings" in f else {},
                message=str(f.attrs.get("message", "")),
                attrs={k: v for k, v in f.attrs.items() if k not in known},
                indicators={name: values[()] for name, values in f.get("error/indicator", {}).items()},
                levels={name: values[()] for name, values in f.get("levels", {}).items()},
            )
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise DDSolveError(f"{path}: not a ddsolve result file ({exc})") from None
