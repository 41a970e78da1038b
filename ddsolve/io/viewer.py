"""Viewer files of a result, derived from it (the HDF5 result stays the one authoritative file).

For a result ``NAME.h5``: ``NAME-layer1`` and ``NAME-layer2`` (each layer as one mesh of both
halves: Σ nodes merged except on the cracks, whose faces keep a node each), ``NAME-sigma`` (the Σ
nodes as a polyline) as VTU or XDMF (one Uniform grid per file; its arrays in ``NAME-xdmf.h5``),
and ``NAME-paraview.py``, a ParaView script that shows them.  P2 results give quadratic triangles
and quadratic Σ edges.  Nothing here writes: :func:`viewer_files` returns writers for
:func:`ddsolve.io.safe.replace_together`.
"""
from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np

from ddsolve.errors import DDSolveError
from ddsolve.mesh.mesh import BLOCKS
from ddsolve.post import analysis, plots
from ddsolve.post.result import Result

FORMATS = ("vtu", "xdmf")
LAYER_TITLES = {"layer1": "layer 1 (u)", "layer2": "layer 2 (v)"}
#: meshio cell type -> XDMF topology type.
_XDMF_TOPOLOGY = {"triangle": "Triangle", "triangle6": "Triangle_6", "line": "Polyline", "line3": "Edge_3"}


@dataclass(frozen=True)
class ViewerMesh:
    """One viewer file's content, in meshio's terms (points 3-D, one cell block)."""

    name: str
    points: np.ndarray
    cell_type: str
    cells: np.ndarray
    point_data: dict[str, np.ndarray]
    cell_data: dict[str, np.ndarray]


def merged_upper_nodes(result: Result) -> tuple[np.ndarray, int]:
    """The layer-mesh node of every upper-half node (lower nodes keep their numbers), and the node
    count: a Σ node off the cracks is the lower half's node; crack nodes keep one node per face."""
    lower, upper, sigma = result.lower, result.upper, result.mesh.sigma
    glued = ~sigma.crack
    own = np.ones(len(upper.points), dtype=bool)
    own[upper.sigma[glued]] = False
    index = np.empty(len(upper.points), dtype=np.int64)
    index[own] = len(lower.points) + np.arange(own.sum())
    index[upper.sigma[glued]] = lower.sigma[glued]
    return index, len(lower.points) + int(own.sum())


def padded(values: np.ndarray) -> np.ndarray:
    """``(n, 2)`` -> ``(n, 3)`` with z = 0 (vectors and points as readers expect them)."""
    out = np.zeros((len(values), 3))
    out[:, :2] = values
    return out


def tensors(xx: np.ndarray, yy: np.ndarray, xy: np.ndarray, zz: np.ndarray) -> np.ndarray:
    """Symmetric 3×3 tensors with no xz, yz part as ``(m, 9)`` rows (xx xy xz yx yy yz zx zy zz)."""
    out = np.zeros((len(xx), 9))
    out[:, 0], out[:, 4], out[:, 8] = xx, yy, zz
    out[:, 1] = out[:, 3] = xy
    return out


def layer_mesh(result: Result, layer: str, fields: dict[str, analysis.CellFields]) -> ViewerMesh:
    """Both halves of ``layer`` as one mesh with its displacement and per-cell fields.

    A merged Σ node shows the mean of the two halves' displacements (equal up to the solver's
    tolerance).  Cells: the lower half's, then the upper half's (cell array ``half``: −1, +1).
    """
    minus, plus = (spec.name for spec in BLOCKS if spec.layer == layer)
    lower, upper = result.lower, result.upper
    index, count = merged_upper_nodes(result)
    points, displacement = np.zeros((count, 2)), np.zeros((count, 2))
    points[index], points[:len(lower.points)] = upper.points, lower.points
    displacement[index] = result.solution[plus]
    displacement[:len(lower.points)] = result.solution[minus]
    glued = ~result.mesh.sigma.crack
    merged = lower.sigma[glued]
    displacement[merged] = 0.5 * (result.solution[minus][merged] + result.solution[plus][upper.sigma[glued]])
    cells = np.vstack([lower.cells, index[upper.cells]])

    def both(per_block: dict[str, np.ndarray], name: str) -> np.ndarray:
        arrays = [np.asarray(per_block[block]) for block in (minus, plus)]
        for array, half in zip(arrays, (lower, upper)):
            if len(array) != len(half.cells):
                raise DDSolveError(f"cell data {name}: {len(array)} values for the {len(half.cells)} cells "
                                   f"of the {half.name} half")
        joined = np.concatenate(arrays)
        return joined if joined.dtype.kind in "iuf" else joined.astype(np.float64)  # e.g. flags as numbers

    low, up = fields[minus], fields[plus]
    strain = np.concatenate([low.strain, up.strain])
    stress = np.concatenate([low.stress, up.stress])
    cell_data = {
        "stress": tensors(*stress.T, np.concatenate([low.stress_zz, up.stress_zz])),
        "strain": tensors(strain[:, 0], strain[:, 1], 0.5 * strain[:, 2],
                          np.concatenate([low.strain_zz, up.strain_zz])),
        "von_mises": np.concatenate([low.von_mises, up.von_mises]),
        "energy_density": np.concatenate([low.energy_density, up.energy_density]),
        "half": np.repeat(np.array([-1, 1], dtype=np.int32), [len(lower.cells), len(upper.cells)]),
    }
    if result.indicators:
        cell_data["error_indicator"] = both(result.indicators, "error_indicator")
    for name, per_block in result.cell_data.items():
        if name in cell_data:
            raise DDSolveError(f"cell data {name}: the name of a field the viewer files already have")
        cell_data[name] = both(per_block, name)
    return ViewerMesh(layer, padded(points), "triangle" if cells.shape[1] == 3 else "triangle6", cells,
                      {"displacement": padded(displacement)}, cell_data)


def sigma_cells(result: Result) -> tuple[str, np.ndarray]:
    """Σ as line cells over its nodes: segments (P1) or quadratic edges (ends, midpoint) for P2."""
    count = len(result.mesh.sigma.points)
    if result.mesh.degree == 1:
        first = np.arange(count - 1)
        return "line", np.column_stack([first, first + 1])
    first = np.flatnonzero(result.mesh.sigma.corner)[:-1]
    return "line3", np.column_stack([first, first + 2, first + 1])


def sigma_mesh(result: Result) -> ViewerMesh:
    """The Σ nodes in order with the jump of layer 1, its normal part, the multipliers, the normals."""
    sigma = result.mesh.sigma
    jump = result.solution["u_plus"][result.upper.sigma] - result.solution["u_minus"][result.lower.sigma]
    nodes = result.multiplier_nodes
    on_sigma = {}
    for name, values in result.multipliers.items():  # clamped nodes carry none: 0 there
        on_sigma[name] = np.zeros((len(sigma.points),) + values.shape[1:])
        on_sigma[name][nodes] = values
    cell_type, cells = sigma_cells(result)
    return ViewerMesh("sigma", padded(sigma.points), cell_type, cells, {
        "jump": padded(jump),
        "opening": np.einsum("sd,sd->s", jump, sigma.normals),
        "contact_pressure": on_sigma["mu_c"],
        **{name: padded(on_sigma[name]) for name in ("mu_g", "mu_minus", "mu_plus")},
        "normal": padded(sigma.normals),
        "crack": sigma.crack.astype(np.int32),
        "x": sigma.points[:, 0],  # plain arrays to plot against (ParaView's XDMF reader has no Points_X)
        "arc_length": sigma.arclength,
    }, {})


# --- writers -----------------------------------------------------------------------------------
def write_vtu(mesh: ViewerMesh, name: str) -> None:
    """Binary, uncompressed: zlib would take most of a solve's output time for a third of the size."""
    import meshio

    meshio.write(name, meshio.Mesh(mesh.points, [(mesh.cell_type, mesh.cells)], point_data=mesh.point_data,
                                   cell_data={key: [values] for key, values in mesh.cell_data.items()}),
                 file_format="vtu", compression=None)


def _data_item(heavy: str, path: str, values: np.ndarray) -> str:
    kind = "Int" if np.issubdtype(values.dtype, np.integer) else "Float"
    dimensions = " ".join(str(d) for d in values.shape)
    return (f'<DataItem DataType="{kind}" Precision="{values.dtype.itemsize}" Dimensions="{dimensions}" '
            f'Format="HDF">{heavy}:{path}</DataItem>')


def _attribute_type(values: np.ndarray) -> str:
    components = 1 if values.ndim == 1 else values.shape[1]
    return {1: "Scalar", 3: "Vector", 9: "Tensor"}.get(components, "Matrix")


def xdmf_text(mesh: ViewerMesh, heavy: str) -> str:
    """XDMF 3 with one Uniform grid; its arrays are ``heavy:/<mesh name>/...``."""
    group = f"/{mesh.name}"
    topology = _XDMF_TOPOLOGY[mesh.cell_type]
    lines = ['<?xml version="1.0" ?>', '<Xdmf Version="3.0">', "  <Domain>",
             f'    <Grid Name="{mesh.name}" GridType="Uniform">',
             f'      <Topology TopologyType="{topology}" NumberOfElements="{len(mesh.cells)}" '
             f'NodesPerElement="{mesh.cells.shape[1]}">',
             f"        {_data_item(heavy, f'{group}/cells', mesh.cells)}", "      </Topology>",
             '      <Geometry GeometryType="XYZ">',
             f"        {_data_item(heavy, f'{group}/points', mesh.points)}", "      </Geometry>"]
    for center, data in (("Node", mesh.point_data), ("Cell", mesh.cell_data)):
        for key, values in data.items():
            lines += [f'      <Attribute Name="{key}" AttributeType="{_attribute_type(values)}" Center="{center}">',
                      f"        {_data_item(heavy, f'{group}/{key}', values)}", "      </Attribute>"]
    lines += ["    </Grid>", "  </Domain>", "</Xdmf>", ""]
    return "\n".join(lines)


def write_heavy_data(meshes: list[ViewerMesh], name: str) -> None:
    """The arrays of every XDMF file, one group per mesh, compressed (gzip level 1 after shuffling
    bytes: about half the size, several times faster than VTU's zlib)."""
    from ddsolve.io.safe import hdf5_image

    with hdf5_image(name) as f:
        for mesh in meshes:
            group = f.create_group(mesh.name)
            for key, values in {"points": mesh.points, "cells": mesh.cells, **mesh.point_data,
                                **mesh.cell_data}.items():
                options = {"compression": "gzip", "compression_opts": 1, "shuffle": True} if values.size else {}
                group.create_dataset(key, data=values, **options)


# --- the ParaView script -----------------------------------------------------------------------
def paraview_script(result: Result, folder: Path, files: dict[str, str],
                    fields: dict[str, analysis.CellFields]) -> str:
    """A pvpython script showing the layers side by side (warped, coloured by von Mises stress) and
    the opening along Σ; ``files``: layer1, layer2, sigma -> file names in ``folder``, beside the script."""
    ceilings = {layer: plots.stress_ceiling(np.concatenate([fields[spec.name].von_mises for spec in BLOCKS
                                                            if spec.layer == layer]))
                for layer in LAYER_TITLES}
    graph = analysis.sigma_is_graph(result)
    settings = {
        "TITLE": result.parsed_scene.title, "FILES": files, "WRITTEN_TO": str(Path(folder).resolve()), "SCALE": plots.magnification(result),
        "CEILINGS": ceilings, "TITLES": LAYER_TITLES,
        "STACKED": plots.one_above_the_other(np.vstack([result.lower.points, result.upper.points])),
        "PERCENTILE": plots.STRESS_PERCENTILE,
        "SIGMA_X": "x" if graph else "arc_length",
        "SIGMA_X_LABEL": f"{'x on Sigma' if graph else 'arc length along Sigma'} ({plots.LENGTH})",
    }
    values = "\n".join(f"{key} = {value!r}" for key, value in settings.items())
    template = resources.files("ddsolve.io").joinpath("paraview-view.py").read_text(encoding="utf-8")
    return template.replace("@SETTINGS@", values)


# --- the set of files ---------------------------------------------------------------------------
VIEWER_MESHES = (*LAYER_TITLES, "sigma")


def viewer_paths(folder: Path, stem: str, fmt: str = "vtu") -> list[Path]:
    """Every file :func:`viewer_files` writes for ``folder/stem`` in format ``fmt``."""
    names = [f"{stem}-{mesh}.{fmt}" for mesh in VIEWER_MESHES] + ([f"{stem}-xdmf.h5"] if fmt == "xdmf" else [])
    return [Path(folder) / name for name in names + [f"{stem}-paraview.py"]]


def viewer_files(result: Result, folder: Path, stem: str, fmt: str = "vtu",
                 fields: dict[str, analysis.CellFields] | None = None) -> dict[Path, Callable[[str], None]]:
    """Path -> writer (called with a temporary name) for every viewer file of ``result``; ``fields``:
    :func:`ddsolve.post.analysis.cell_fields` of the result if already computed."""
    if fmt not in FORMATS:
        raise DDSolveError(f"--format {fmt}: expected one of {', '.join(FORMATS)}")
    folder = Path(folder)
    fields = analysis.cell_fields(result) if fields is None else fields
    meshes = [layer_mesh(result, layer, fields) for layer in LAYER_TITLES] + [sigma_mesh(result)]
    names = {mesh.name: f"{stem}-{mesh.name}.{fmt}" for mesh in meshes}
    script = paraview_script(result, folder, names, fields)
    writers: dict[Path, Callable[[str], None]] = {}
    if fmt == "vtu":
        for mesh in meshes:
            writers[folder / names[mesh.name]] = lambda name, mesh=mesh: write_vtu(mesh, name)
    else:
        heavy = f"{stem}-xdmf.h5"
        writers[folder / heavy] = lambda name: write_heavy_data(meshes, name)
        for mesh in meshes:
            text = xdmf_text(mesh, heavy)
            writers[folder / names[mesh.name]] = lambda name, text=text: Path(name).write_text(text, encoding="utf-8")
    writers[folder / f"{stem}-paraview.py"] = lambda name: Path(name).write_text(script, encoding="utf-8")
    return writers
