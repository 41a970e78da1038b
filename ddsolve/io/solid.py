"""The files of a 3-D result: the HDF5 file (each half's nodes, tetrahedra and displacements; Σ's vertices,
triangles, opening and contact pressure; G along the crack fronts under ``/fracture``; the scene's text and the
solve's numbers as attributes) and a VTU file per half (tetra or tetra10) and for Σ (triangles, 3 or 6 nodes)
beside it, written together (:func:`ddsolve.io.safe.replace_together`); the result file read back (:func:`read`)
and its viewer files, VTU or XDMF, written anywhere (:func:`viewer_writers`, for ``ddsolve export``).

A box of several interfaces (attribute ``interfaces``) has a group per region (``region1`` … bottom to top), each
Σ's group under ``/interfaces/N/sigma`` (N = 1 the lowest, as the plane stacked files keep each interface under
``/interfaces/N``), ``/fracture`` every interface's rows with ``/fracture/interface`` naming each row's Σ, a VTU
file per region and per Σ (``STEM-region1.vtu`` …, ``STEM-sigma1.vtu`` …) and the ParaView script.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ddsolve.errors import DDSolveError
from ddsolve.io.safe import replace_together
from ddsolve.mesh.solid import SigmaSurface, SolidHalf, SolidMesh, sigma_side
from ddsolve.post.front import FrontRelease
from ddsolve.post.solid import SolidResult
from ddsolve.problem.schema import REGIONS

#: The viewer files beside ``NAME.h5`` of one interface: ``NAME-lower.vtu``, ``NAME-upper.vtu``, ``NAME-sigma.vtu``
#: (and the ParaView script ``NAME-paraview.py``).
VIEWER_PARTS = ("lower", "upper", "sigma")
#: The viewer formats of a 3-D result and meshio's options for each: XDMF with its arrays inline (one file per
#: part, no HDF5 beside it, so that each file is written whole and replaced with the others).
VIEWER_FORMATS = {"vtu": {}, "xdmf": {"data_format": "XML"}}


def viewer_parts(result: SolidResult) -> tuple[str, ...]:
    """The viewer files' parts of ``result``: :data:`VIEWER_PARTS`, or of several interfaces each region (by
    name) and each Σ (``sigma1`` … bottom to top)."""
    count = len(result.pressures)
    if count == 1:
        return VIEWER_PARTS
    return (*(region.name for region in result.mesh.regions), *(sigma_side(k, count) for k in range(count)))


def viewer_writers(result: SolidResult, folder: Path, stem: str, fmt: str = "vtu") -> dict:
    """Path -> writer of each viewer file of ``result`` in format ``fmt`` (:data:`VIEWER_FORMATS`,
    :func:`viewer_parts`) and of the ParaView script ``STEM-paraview.py`` that shows them, for
    :func:`replace_together`."""
    parts = viewer_parts(result)
    paths = [Path(folder) / f"{stem}-{part}.{fmt}" for part in parts]
    writers = {target: (lambda temporary, part=part: _write_part(temporary, result, part, fmt))
               for target, part in zip(paths, parts)}
    text = paraview_script(result, folder, {part: path.name for part, path in zip(parts, paths)})
    return {**writers, Path(folder) / f"{stem}-paraview.py":
            lambda temporary: Path(temporary).write_text(text, encoding="utf-8")}


def paraview_script(result: SolidResult, folder: Path, files: dict[str, str]) -> str:
    """The ParaView script (:func:`ddsolve.io.viewer.paraview_script`) of a 3-D result's viewer ``files`` (part ->
    name in ``folder``): the halves (regions) warped by :func:`ddsolve.post.solid_plots.magnification`, coloured by
    the displacement's magnitude up to its largest, Σ (each Σ) by the opening over their range."""
    from ddsolve.io import viewer
    from ddsolve.post import solid_plots

    largest = max(float(np.linalg.norm(u, axis=1).max(initial=0.0)) for u in result.fields)
    openings = [result.interface(k).normal_opening for k in range(len(result.pressures))]
    return viewer.paraview_script(result.scene.title, folder, files,
                                  {region.name: largest for region in result.mesh.regions},
                                  solid_plots.magnification(result), stacked=False, graph=False,
                                  opening=(min(float(o.min(initial=0.0)) for o in openings),
                                           max(float(o.max(initial=0.0)) for o in openings)))


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
            attributes = dict(f.attrs)
            scene = loads(str(attributes["scene"]), origin=f"{path}: /scene")
            count = int(attributes.get("interfaces", 1))
            names = REGIONS if count == 1 else scene.geometry.region_names
            regions = tuple(SolidHalf(name, f[name]["points"][()], f[name]["tetrahedra"][()], {},
                                      f[name]["sigma_nodes"][()]) for name in names)
            groups = [f["sigma"]] if count == 1 else [f[f"interfaces/{k}/sigma"] for k in range(1, count + 1)]
            surfaces = tuple(SigmaSurface(sigma["points"][()], sigma["triangles"][()], sigma["cracked"][()],
                                          sigma["front"][()]) for sigma in groups)
            return SolidResult(scene, SolidMesh(regions, surfaces),
                               tuple(f[name]["displacement"][()] for name in names),
                               tuple(sigma["contact_pressure"][()] for sigma in groups),
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
        for half, u in zip(result.mesh.regions, result.fields):
            group = out.create_group(half.name)
            group["points"], group["tetrahedra"], group["displacement"] = half.points, half.tetrahedra, u
            group["sigma_nodes"] = half.sigma_nodes
        count = len(result.pressures)
        for k in range(count):
            _write_sigma(out.create_group("sigma" if count == 1 else f"interfaces/{k + 1}/sigma"), result.interface(k))
        if result.fracture is not None:
            _write_fracture(out.create_group("fracture"), result.fracture)
            if result.fracture_interface is not None:
                out["fracture/interface"] = result.fracture_interface
        if count > 1:
            out.attrs["interfaces"] = count
        out.attrs.update({"dimension": 3, "scene": result.scene.text, "energy": result.energy,
                          "active_set_steps": result.steps, "solves": result.solves, "converged": result.converged,
                          "closed_vertices": result.closed, "message": result.message,
                          **{f"check_{key}": value for key, value in result.checks.items()},
                          **{f"time_{key}": value for key, value in result.timings.items()}, **result.attrs})
        for column, values in result.levels.items():
            out[f"levels/{column}"] = values


def _write_sigma(group, view: SolidResult) -> None:
    """Σ of a result of one interface (or one interface's view): its vertices, triangles, lumped weights, crack
    vertices, front, opening and contact pressure."""
    surface = view.mesh.sigma
    group["points"], group["triangles"], group["weights"] = surface.points, surface.triangles, surface.weights
    group["cracked"], group["front"] = surface.cracked, surface.front
    group["opening"], group["contact_pressure"] = view.opening, view.pressure


def _write_fracture(group, fracture: FrontRelease) -> None:
    """G along the fronts: one row per front node (``points``, ``tangents``, ``normals`` (n, 3); ``front``, the
    chain it belongs to; ``arclength``; G, G_I, G_II, G_III per unit length; ``phase`` ψ and ``phase_III`` φ in
    degrees; θ's radii ``inner``, ``outer``)."""
    for field in dataclasses.fields(fracture):
        group[field.name] = getattr(fracture, field.name)


def _write_part(name: str, result: SolidResult, part: str, fmt: str) -> None:
    import meshio

    sides = [sigma_side(k, len(result.pressures)) for k in range(len(result.pressures))]
    if part in sides:
        view = result.interface(sides.index(part))
        surface = view.mesh.sigma
        mesh = meshio.Mesh(surface.points, [("triangle" if surface.triangles.shape[1] == 3 else "triangle6",
                                             surface.triangles)],
                           point_data={"opening": view.opening, "normal_opening": view.normal_opening,
                                       "contact_pressure": view.pressure,
                                       "cracked": surface.cracked.astype(np.int32)})
    else:
        index = [half.name for half in result.mesh.regions].index(part)
        half = result.mesh.regions[index]
        mesh = meshio.Mesh(half.points, [("tetra" if half.tetrahedra.shape[1] == 4 else "tetra10", half.tetrahedra)],
                           point_data={"displacement": result.fields[index]})
    meshio.write(name, mesh, file_format=fmt, **VIEWER_FORMATS[fmt])
