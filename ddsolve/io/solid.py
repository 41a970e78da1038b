"""The files of a 3-D result: the HDF5 file (each half's nodes, tetrahedra and displacements; Σ's vertices,
triangles, opening and contact pressure; G along the crack fronts under ``/fracture``; the scene's text and the solve's numbers as attributes) and a VTU
file per half (tetra or tetra10) and for Σ (triangles, 3 or 6 nodes) beside it, written together
(:func:`ddsolve.io.safe.replace_together`); the result file read back (:func:`read`) and its viewer files, VTU or
XDMF, written anywhere (:func:`viewer_writers`, for ``ddsolve export``)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ddsolve.errors import DDSolveError
from ddsolve.io.safe import replace_together
from ddsolve.mesh.solid import SigmaSurface, SolidHalf, SolidMesh
from ddsolve.post.front import FrontRelease
from ddsolve.post.solid import SolidResult
from ddsolve.problem.schema import REGIONS

#: The viewer files beside ``NAME.h5``: ``NAME-lower.vtu``, ``NAME-upper.vtu``, ``NAME-sigma.vtu``.
VIEWER_PARTS = ("lower", "upper", "sigma")
#: The viewer formats of a 3-D result and meshio's options for each: XDMF with its arrays inline (one file per
#: part, no HDF5 beside it, so that each file is written whole and replaced with the others).
VIEWER_FORMATS = {"vtu": {}, "xdmf": {"data_format": "XML"}}


def viewer_paths(folder: Path, stem: str, fmt: str = "vtu") -> list[Path]:
    """The viewer files of the result ``stem`` in ``folder``: ``STEM-lower.FMT``, ``STEM-upper.FMT``,
    ``STEM-sigma.FMT`` and the ParaView script ``STEM-paraview.py`` that shows them."""
    return [Path(folder) / f"{stem}-{part}.{fmt}" for part in VIEWER_PARTS] + [Path(folder) / f"{stem}-paraview.py"]


def viewer_writers(result: SolidResult, folder: Path, stem: str, fmt: str = "vtu") -> dict:
    """Path -> writer of each viewer file of ``result`` in format ``fmt`` (:data:`VIEWER_FORMATS`,
    :func:`viewer_paths`), for :func:`replace_together`."""
    *parts, script = viewer_paths(folder, stem, fmt)
    text = paraview_script(result, folder, {part: path.name for part, path in zip(VIEWER_PARTS, parts)})
    return {**{target: (lambda temporary, part=part: _write_part(temporary, result, part, fmt))
               for target, part in zip(parts, VIEWER_PARTS)},
            script: lambda temporary: Path(temporary).write_text(text, encoding="utf-8")}


def paraview_script(result: SolidResult, folder: Path, files: dict[str, str]) -> str:
    """The ParaView script (:func:`ddsolve.io.viewer.paraview_script`) of a 3-D result's viewer ``files`` (part ->
    name in ``folder``): the halves warped by :func:`ddsolve.post.solid_plots.magnification`, coloured by the
    displacement's magnitude up to its largest, Σ by the opening over its range."""
    from ddsolve.io import viewer
    from ddsolve.post import solid_plots

    largest = max(float(np.linalg.norm(u, axis=1).max(initial=0.0)) for u in result.fields)
    opening = result.normal_opening
    return viewer.paraview_script(result.scene.title, folder, files, {part: largest for part in VIEWER_PARTS[:2]},
                                  solid_plots.magnification(result), stacked=False, graph=False,
                                  opening=(float(opening.min(initial=0.0)), float(opening.max(initial=0.0))))


def write(path: Path, result: SolidResult) -> list[Path]:
    """Write the result file ``path`` and its VTU files beside it; the paths written."""
    path = Path(path)
    writers = {path: lambda temporary: _write_hdf5(temporary, result), **viewer_writers(result, path.parent, path.stem)}
    replace_together(writers, final=True)
    return list(writers)


def is_solid(path: Path) -> bool:
    """Whether ``path`` is the result file of a 3-D solve (its ``dimension`` attribute is 3); False for any file
    that is not, or that HDF5 cannot open (the plane reader then says why)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return int(f.attrs.get("dimension", 2)) == 3
    except (OSError, TypeError, ValueError):
        return False


def read(path: Path) -> SolidResult:
    """The 3-D result in the file ``path`` (:func:`write`): its scene, halves (without their sides' faces), Σ,
    displacements, contact pressure and the solve's numbers; one line naming the file if a part is missing."""
    import h5py

    from ddsolve.problem.scene import loads

    try:
        with h5py.File(path, "r") as f:
            halves = tuple(SolidHalf(name, f[name]["points"][()], f[name]["tetrahedra"][()], {},
                                     f[name]["sigma_nodes"][()]) for name in REGIONS)
            sigma = f["sigma"]
            surface = SigmaSurface(sigma["points"][()], sigma["triangles"][()], sigma["cracked"][()],
                                   sigma["front"][()])
            attributes = dict(f.attrs)
            return SolidResult(loads(str(attributes["scene"]), origin=f"{path}: /scene"), SolidMesh(halves, surface),
                               tuple(f[name]["displacement"][()] for name in REGIONS), sigma["contact_pressure"][()],
                               energy=float(attributes["energy"]), steps=int(attributes["active_set_steps"]),
                               solves=int(attributes["solves"]), converged=bool(attributes["converged"]),
                               message=str(attributes["message"]),
                               checks={key[6:]: float(value) for key, value in attributes.items()
                                       if key.startswith("check_")},
                               timings={key[5:]: float(value) for key, value in attributes.items()
                                        if key.startswith("time_")})
    except (OSError, KeyError, TypeError, ValueError) as exc:
        raise DDSolveError(f"{path}: not a 3-D result file ({' '.join(str(exc).split())})") from None


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
        if result.fracture is not None:
            _write_fracture(out.create_group("fracture"), result.fracture)
        out.attrs.update({"dimension": 3, "scene": result.scene.text, "energy": result.energy,
                          "active_set_steps": result.steps, "solves": result.solves, "converged": result.converged,
                          "closed_vertices": result.closed, "message": result.message,
                          **{f"check_{key}": value for key, value in result.checks.items()},
                          **{f"time_{key}": value for key, value in result.timings.items()}, **result.attrs})
        for column, values in result.levels.items():
            out[f"levels/{column}"] = values


def _write_fracture(group, fracture: FrontRelease) -> None:
    """G along the fronts: one row per front node (``points``, ``tangents``, ``normals`` (n, 3); ``front``, the
    chain it belongs to; ``arclength``; G, G_I, G_II, G_III per unit length; ``phase`` ψ and ``phase_III`` φ in
    degrees; θ's radii ``inner``, ``outer``)."""
    for field in dataclasses.fields(fracture):
        group[field.name] = getattr(fracture, field.name)


def _write_part(name: str, result: SolidResult, part: str, fmt: str) -> None:
    import meshio

    if part == "sigma":
        surface = result.mesh.sigma
        mesh = meshio.Mesh(surface.points, [("triangle" if surface.triangles.shape[1] == 3 else "triangle6",
                                             surface.triangles)],
                           point_data={"opening": result.opening, "normal_opening": result.normal_opening,
                                       "contact_pressure": result.pressure,
                                       "cracked": surface.cracked.astype(np.int32)})
    else:
        index = [half.name for half in result.mesh.halves].index(part)
        half = result.mesh.halves[index]
        mesh = meshio.Mesh(half.points, [("tetra" if half.tetrahedra.shape[1] == 4 else "tetra10", half.tetrahedra)],
                           point_data={"displacement": result.fields[index]})
    meshio.write(name, mesh, file_format=fmt, **VIEWER_FORMATS[fmt])
