"""The files of a 3-D result: the HDF5 file (each half's nodes, tetrahedra and displacements; Σ's vertices,
triangles, opening and contact pressure; the scene's text and the solve's numbers as attributes) and a VTU
file per half (tetra or tetra10) and for Σ (triangles, 3 or 6 nodes) beside it, written together (:func:`ddsolve.io.safe.replace_together`)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ddsolve.io.safe import replace_together
from ddsolve.post.solid import SolidResult

#: The viewer files beside ``NAME.h5``: ``NAME-lower.vtu``, ``NAME-upper.vtu``, ``NAME-sigma.vtu``.
VIEWER_PARTS = ("lower", "upper", "sigma")


def viewer_paths(path: Path) -> list[Path]:
    """The VTU files written beside the result file ``path``."""
    return [path.with_name(f"{path.stem}-{part}.vtu") for part in VIEWER_PARTS]


def write(path: Path, result: SolidResult) -> list[Path]:
    """Write the result file ``path`` and its VTU files; the paths written."""
    path = Path(path)
    writers = {path: lambda temporary: _write_hdf5(temporary, result)}
    for target, part in zip(viewer_paths(path), VIEWER_PARTS):
        writers[target] = lambda temporary, part=part: _write_vtu(temporary, result, part)
    replace_together(writers, final=True)
    return list(writers)


def is_solid(path: Path) -> bool:
    """Whether ``path`` is the result file of a 3-D solve."""
    import h5py

    with h5py.File(path, "r") as file:
        return int(file.attrs.get("dimension", 2)) == 3


def read(path: Path) -> SolidResult:
    """A 3-D result file read back: its scene, halves (without their sides' faces), Σ, fields and numbers."""
    import h5py

    from ddsolve.mesh.solid import SigmaSurface, SolidHalf, SolidMesh
    from ddsolve.problem.scene import loads

    with h5py.File(path, "r") as file:
        halves = tuple(SolidHalf(name, file[name]["points"][()], file[name]["tetrahedra"][()], {},
                                 file[name]["sigma_nodes"][()]) for name in ("lower", "upper"))
        sigma = file["sigma"]
        surface = SigmaSurface(sigma["points"][()], sigma["triangles"][()], sigma["cracked"][()], sigma["front"][()])
        attrs = dict(file.attrs)
        return SolidResult(loads(str(attrs["scene"])), SolidMesh(halves, surface),
                           tuple(file[name]["displacement"][()] for name in ("lower", "upper")),
                           sigma["contact_pressure"][()], float(attrs["energy"]), int(attrs["active_set_steps"]),
                           int(attrs["solves"]), bool(attrs["converged"]), str(attrs["message"]))


def _write_hdf5(name: str, result: SolidResult) -> None:
    import h5py

    with h5py.File(name, "w") as out:
        for half, u in zip(result.mesh.halves, result.fields):
            group = out.create_group(half.name)
            group["points"], group["tetrahedra"], group["displacement"] = half.points, half.tetrahedra, u
            group["sigma_nodes"] = half.sigma_nodes
        sigma = out.create_group("sigma")
        surface = result.mesh.sigma
        sigma["points"], sigma["triangles"], sigma["weights"] = surface.points, surface.triangles, surface.weights
        sigma["cracked"], sigma["front"] = surface.cracked, surface.front
        sigma["opening"], sigma["contact_pressure"] = result.opening, result.pressure
        out.attrs.update({"dimension": 3, "scene": result.scene.text, "energy": result.energy,
                          "active_set_steps": result.steps, "solves": result.solves, "converged": result.converged,
                          "closed_vertices": result.closed, "message": result.message,
                          **{f"check_{key}": value for key, value in result.checks.items()},
                          **{f"time_{key}": value for key, value in result.timings.items()}})


def _write_vtu(name: str, result: SolidResult, part: str) -> None:
    import meshio

    if part == "sigma":
        surface = result.mesh.sigma
        mesh = meshio.Mesh(surface.points, [("triangle" if surface.triangles.shape[1] == 3 else "triangle6",
                                             surface.triangles)],
                           point_data={"opening": result.opening, "contact_pressure": result.pressure,
                                       "cracked": surface.cracked.astype(np.int8)})
    else:
        index = [half.name for half in result.mesh.halves].index(part)
        half = result.mesh.halves[index]
        mesh = meshio.Mesh(half.points, [("tetra" if half.tetrahedra.shape[1] == 4 else "tetra10", half.tetrahedra)],
                           point_data={"displacement": result.fields[index]})
    meshio.write(name, mesh, file_format="vtu")
