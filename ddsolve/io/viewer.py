"""Viewer files of a result, derived from it (the HDF5 result stays the one authoritative file).

For a result ``NAME.h5``: ``NAME-layer1`` and, with two layers, ``NAME-layer2`` (each layer as one mesh of both
halves: Σ nodes merged except on the cracks, whose faces keep a node each), ``NAME-sigma`` (the Σ
nodes as a polyline) in a registered format (:data:`FORMATS`: VTU, or XDMF with one Uniform grid per
file and its arrays in ``NAME-xdmf.h5``), and ``NAME-paraview.py``, a ParaView script that shows them.
P2 results give quadratic triangles and quadratic Σ edges.  Nothing here writes: :func:`viewer_files`
returns writers for :func:`ddsolve.io.safe.replace_together`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
import os
from importlib import resources
from pathlib import Path
from typing import Callable

import numpy as np

from ddsolve.errors import DDSolveError
from ddsolve.problem.schema import LAYERS
from ddsolve.post import analysis, plots
from ddsolve.post.result import OnSigma, Result
from ddsolve.post.stack import StackResult, block_names, cell_fields
from ddsolve.problem.scene import Friction

#: meshio cell type -> XDMF topology type.
_XDMF_TOPOLOGY = {"triangle": "Triangle", "triangle6": "Triangle_6", "line": "Polyline", "line3": "Edge_3"}


@dataclass(frozen=True)
class ViewerMesh:
    """One viewer file's content, in meshio's terms (points 3-D, one cell block), or a share of it: its
    point rows from ``first_point`` and cell rows from ``first_cell`` (cells numbered in the whole mesh)
    of ``total_points`` and ``total_cells`` (None: this share is the whole mesh)."""

    name: str
    points: np.ndarray
    cell_type: str
    cells: np.ndarray
    point_data: dict[str, np.ndarray]
    cell_data: dict[str, np.ndarray]
    first_point: int = 0
    first_cell: int = 0
    total_points: int | None = None
    total_cells: int | None = None


@dataclass(frozen=True)
class Glue:
    """What a half needs of the other half to take its share of a layer mesh (all Σ-sized): both halves'
    Σ nodes, the cracks, the node and cell counts of both halves (side -> count), and the other half's
    displacement of the layer at the Σ nodes ``(s, 2)``."""

    lower_sigma: np.ndarray
    upper_sigma: np.ndarray
    crack: np.ndarray
    nodes: dict[int, int]
    cells: dict[int, int]
    other: np.ndarray


def merged_upper_nodes(result: Result) -> tuple[np.ndarray, int]:
    """The layer-mesh node of every upper-half node (lower nodes keep their numbers), and the node
    count: a Σ node off the cracks is the lower half's node; crack nodes keep one node per face."""
    glue = glue_of(result, "layer1", 1)
    return layer_numbers(glue, np.arange(glue.nodes[1])), node_count(glue)


def layer_numbers(glue: Glue, nodes: np.ndarray) -> np.ndarray:
    """The layer-mesh number of each of the upper half's ``nodes``: a Σ node off the cracks is the lower
    half's node, the others follow the lower half's in their order."""
    glued = ~glue.crack
    upper, lower = glue.upper_sigma[glued], glue.lower_sigma[glued]
    order = np.argsort(upper)
    below = np.searchsorted(upper[order], nodes)  # glued upper nodes before each node
    out = glue.nodes[-1] + nodes - below
    merged = np.flatnonzero(below < len(upper))
    merged = merged[upper[order[below[merged]]] == nodes[merged]]
    out[merged] = lower[order[below[merged]]]
    return out


def node_count(glue: Glue) -> int:
    """Nodes of a layer mesh."""
    return glue.nodes[-1] + glue.nodes[1] - int(np.count_nonzero(~glue.crack))


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


def layer_share(layer: str, side: int, points: np.ndarray, u: np.ndarray, cells: np.ndarray,
                fields: analysis.CellFields, glue: Glue, indicator: np.ndarray | None = None,
                cell_data: dict[str, np.ndarray] | None = None, first_node: int = 0, first_cell: int = 0
                ) -> ViewerMesh:
    """A half's share of the mesh of ``layer`` (see :func:`layer_mesh`): of its nodes ``first_node`` on
    (``points`` and displacements ``u``) the upper half's own nodes only (merged Σ nodes are the lower
    half's), and its ``cells`` (the half's node numbers) from ``first_cell`` on with their fields."""
    glued = ~glue.crack
    lower_count = glue.nodes[-1]
    nodes = np.arange(first_node, first_node + len(points))
    if side < 0:
        displacement, first = u.copy(), first_node
        merged = glue.lower_sigma[glued]
        mine = (merged >= first_node) & (merged < first_node + len(points))
        displacement[merged[mine] - first_node] = 0.5 * (u[merged[mine] - first_node] + glue.other[glued][mine])
        first_cell_row = first_cell
    else:
        own = layer_numbers(glue, nodes) >= lower_count
        points, displacement, cells = points[own], u[own], layer_numbers(glue, cells.reshape(-1)).reshape(cells.shape)
        first = lower_count + first_node - int(np.count_nonzero(glue.upper_sigma[glued] < first_node))
        first_cell_row = glue.cells[-1] + first_cell
    cell_data_out = {**field_arrays(fields), "half": np.full(len(cells), side, dtype=np.int32)}
    extra = [("error_indicator", indicator)] if indicator is not None else []
    for name, values in extra + list((cell_data or {}).items()):
        if name in cell_data_out:
            raise DDSolveError(f"cell data {name}: the name of a field the viewer files already have")
        values = np.asarray(values)
        if np.ndim(values) == 0 or len(values) != len(cells):
            raise DDSolveError(f"cell data {name}: {np.size(values)} values for the {len(cells)} cells "
                               f"of the {'lower' if side < 0 else 'upper'} half")
        cell_data_out[name] = values if values.dtype.kind in "iuf" else values.astype(np.float64)
    return ViewerMesh(layer, padded(points), "triangle" if cells.shape[1] == 3 else "triangle6", cells,
                      {"displacement": padded(displacement)}, cell_data_out, first, first_cell_row,
                      node_count(glue), glue.cells[-1] + glue.cells[1])


def field_arrays(fields: analysis.CellFields) -> dict[str, np.ndarray]:
    """The per-cell arrays of a block's viewer mesh: stress and strain tensors, von Mises stress, energy density."""
    return {"stress": tensors(*fields.stress.T, fields.stress_zz),
            "strain": tensors(fields.strain[:, 0], fields.strain[:, 1], 0.5 * fields.strain[:, 2], fields.strain_zz),
            "von_mises": fields.von_mises, "energy_density": fields.energy_density}


def joined(shares: list[ViewerMesh]) -> ViewerMesh:
    """The whole mesh from its shares (in row order)."""
    first = shares[0]

    def stack(values: list[np.ndarray]) -> np.ndarray:
        return np.concatenate(values) if values[0].ndim == 1 else np.vstack(values)

    return ViewerMesh(first.name, stack([s.points for s in shares]), first.cell_type,
                      stack([s.cells for s in shares]),
                      {key: stack([s.point_data[key] for s in shares]) for key in first.point_data},
                      {key: stack([s.cell_data[key] for s in shares]) for key in first.cell_data})


def glue_of(result: Result, layer: str, side: int) -> Glue:
    """The :class:`Glue` of one half of ``layer`` in a whole result."""
    other = next(spec.name for spec in result.blocks if spec.layer == layer and spec.side == -side)
    return Glue(result.lower.sigma, result.upper.sigma, result.mesh.sigma.crack,
                {-1: len(result.lower.points), 1: len(result.upper.points)},
                {-1: len(result.lower.cells), 1: len(result.upper.cells)},
                result.solution[other][result.half(other).sigma])


def layer_mesh(result: Result, layer: str, fields: dict[str, analysis.CellFields]) -> ViewerMesh:
    """Both halves of ``layer`` as one mesh with its displacement and per-cell fields.

    A merged Σ node shows the mean of the two halves' displacements (equal up to the solver's
    tolerance).  Cells: the lower half's, then the upper half's (cell array ``half``: −1, +1).
    """
    shares = []
    for spec in (spec for spec in result.blocks if spec.layer == layer):  # the lower half's block first
        half = result.half(spec.name)
        shares.append(layer_share(layer, spec.side, half.points, result.solution[spec.name], half.cells,
                                  fields[spec.name], glue_of(result, layer, spec.side),
                                  result.indicators.get(spec.name),
                                  {name: per_block[spec.name] for name, per_block in result.cell_data.items()
                                   if spec.name in per_block}))
    return joined(sorted(shares, key=lambda share: share.first_point))


def sigma_cells(sigma, degree: int) -> tuple[str, np.ndarray]:
    """Σ as line cells over its nodes: segments (P1) or quadratic edges (ends, midpoint) for P2."""
    count = len(sigma.points)
    if degree == 1:
        first = np.arange(count - 1)
        return "line", np.column_stack([first, first + 1])
    first = np.flatnonzero(sigma.corner)[:-1]
    return "line3", np.column_stack([first, first + 2, first + 1])


def sigma_mesh(on: OnSigma, degree: int, friction: Friction | None = None) -> ViewerMesh:
    """The Σ nodes in order with the jump of layer 1, its normal part, the multipliers, the normals
    (``on``: :attr:`ddsolve.post.result.Result.on_sigma`; ``degree`` of the elements); with ``friction`` the
    tangential traction, the slip (u⁻ − u⁺)·τ and the friction state (0 apart, 1 stick, 2 slip)."""
    sigma = on.sigma
    jump = on.traces["u_plus"] - on.traces["u_minus"]
    nodes = sigma.multiplier_nodes
    on_sigma = {}
    for name, values in on.multipliers.items():  # clamped nodes carry none: 0 there
        on_sigma[name] = np.zeros((len(sigma.points),) + values.shape[1:])
        on_sigma[name][nodes] = values
    cell_type, cells = sigma_cells(sigma, degree)
    return ViewerMesh("sigma", padded(sigma.points), cell_type, cells, {
        "jump": padded(jump),
        "opening": np.einsum("sd,sd->s", jump, sigma.normals),
        "contact_pressure": on_sigma["mu_c"],
        **{name: padded(on_sigma[name]) for name in ("mu_g", "mu_minus", "mu_plus") if name in on_sigma},
        **(friction_arrays(on, friction) if "mu_t" in on.multipliers else {}),
        "normal": padded(sigma.normals),
        "crack": sigma.crack.astype(np.int32),
        "x": sigma.points[:, 0],  # plain arrays to plot against (ParaView's XDMF reader has no Points_X)
        "arc_length": sigma.arclength,
    }, {})


def friction_arrays(on: OnSigma, friction: Friction | None) -> dict[str, np.ndarray]:
    """The friction's point arrays on Σ: ``tangential_traction`` μ_t, ``slip`` (u⁻ − u⁺)·τ of layer 1 and
    ``friction_state`` (:func:`ddsolve.post.analysis.friction_state`), 0 at clamped nodes."""
    sigma, nodes = on.sigma, on.sigma.multiplier_nodes
    out = {name: np.zeros(len(sigma.points)) for name in ("tangential_traction", "slip")}
    out["tangential_traction"][nodes] = on.multipliers["mu_t"]
    out["slip"][nodes] = np.einsum("kd,kd->k", on.gap, sigma.frames[nodes, 0])
    out["friction_state"] = np.zeros(len(sigma.points), dtype=np.int8)
    out["friction_state"][nodes] = analysis.friction_state(on, friction)
    return out


# --- writers -----------------------------------------------------------------------------------
#: VTK cell type numbers of the meshio cell types the viewer files use.
_VTK_TYPES = {"triangle": 5, "triangle6": 22, "line": 3, "line3": 21}
_VTK_NUMBERS = {"f8": "Float64", "f4": "Float32", "i8": "Int64", "i4": "Int32", "u1": "UInt8", "i1": "Int8"}


def _share_arrays(share: ViewerMesh, totals: tuple[int, int]) -> list[tuple[str, str, np.ndarray, int]]:
    """(section, name, rows, first row) of every array of a share of a mesh of ``totals`` (points, cells; a
    share knows the whole mesh's), in file order; the connectivity and offsets are 32-bit integers when
    the mesh's numbers fit."""
    k = share.cells.shape[1]
    cells = np.arange(share.first_cell, share.first_cell + len(share.cells))
    index = np.int32 if max(totals[0], k * totals[1]) <= np.iinfo(np.int32).max else np.int64
    return ([("Points", "Points", share.points, share.first_point),
             ("Cells", "connectivity", share.cells.astype(index), share.first_cell),
             ("Cells", "offsets", (k * (cells + 1)).astype(index), share.first_cell),
             ("Cells", "types", np.full(len(cells), _VTK_TYPES[share.cell_type], dtype=np.uint8), share.first_cell)]
            + [("PointData", key, values, share.first_point) for key, values in share.point_data.items()]
            + [("CellData", key, values, share.first_cell) for key, values in share.cell_data.items()])


def write_vtu(mesh: ViewerMesh, name: str, comm=None) -> None:
    """A VTU file with its arrays appended raw (uncompressed: zlib would take most of a solve's output
    time for a third of the size).  With ``comm``, ``mesh`` is this rank's share (or None) and the ranks
    write the one file together: rank 0 its header and layout, then every rank its rows in place."""
    shares = [mesh] if mesh is not None else []
    totals = (0, 0)
    if shares:
        totals = (mesh.total_points if mesh.total_points is not None else len(mesh.points),
                  mesh.total_cells if mesh.total_cells is not None else len(mesh.cells))
    pieces = [_share_arrays(share, totals) for share in shares]
    layout = [(section, key, values.dtype.str[1:], values.shape[1:]) for piece in pieces
              for section, key, values, _ in piece]
    if comm is not None and comm.size > 1:
        gathered = comm.allgather((layout, totals))
        totals = max(t for _, t in gathered)
        layout = [entry for entries, _ in gathered for entry in entries]
    arrays: dict[tuple[str, str], tuple[str, tuple]] = {}
    for section, key, dtype, shape in layout:  # the first share that has an array fixes its place
        arrays.setdefault((section, key), (dtype, shape))
    offsets, position = {}, 0
    for entry, (dtype, shape) in arrays.items():
        rows = totals[0] if entry[0] in ("Points", "PointData") else totals[1]
        size = rows * int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
        offsets[entry] = (position, size)
        position += 8 + size
    head = _vtu_head(arrays, offsets, totals).encode()
    tail = b"\n</AppendedData>\n</VTKFile>\n"
    rank, failed = comm.rank if comm is not None else 0, None
    if rank == 0:
        try:
            with open(name, "wb") as out:
                out.write(head)
                for start, size in offsets.values():
                    out.seek(len(head) + start)
                    out.write(np.uint64(size).tobytes())
                out.seek(len(head) + position)
                out.write(tail)
        except OSError as exc:  # a full disk: every rank stops here, none waits for the others' rows
            failed = exc
    if comm is not None and comm.size > 1:
        failed = comm.bcast(failed, root=0)
    if failed is not None:
        raise failed
    if pieces:
        handle = os.open(name, os.O_WRONLY)
        try:
            for piece in pieces:
                for section, key, values, row in piece:
                    data = np.ascontiguousarray(values)
                    if data.nbytes:
                        row_bytes = data.nbytes // len(data)
                        _write_at(handle, data, len(head) + offsets[(section, key)][0] + 8 + row * row_bytes)
        finally:
            os.close(handle)


def _write_at(handle: int, data: np.ndarray, position: int) -> None:
    """Write the contiguous array ``data`` at ``position`` of the open file (no copy; pwrite may write less
    than asked: the rest follows)."""
    view = memoryview(data.reshape(-1)).cast("B")
    while len(view):
        written = os.pwrite(handle, view, position)
        view, position = view[written:], position + written


def _vtu_head(arrays: dict, offsets: dict, totals: tuple[int, int]) -> str:
    lines = ['<?xml version="1.0"?>',
             '<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">',
             "<UnstructuredGrid>", f'<Piece NumberOfPoints="{totals[0]}" NumberOfCells="{totals[1]}">']
    for section in ("Points", "Cells", "PointData", "CellData"):
        lines.append(f"<{section}>")
        for (where, key), (dtype, shape) in arrays.items():
            if where == section:
                name = "" if section == "Points" else f' Name="{key}"'
                # the connectivity is one list of the cells' nodes (VTK refuses it with components)
                components = f' NumberOfComponents="{int(np.prod(shape))}"' if shape and key != "connectivity" else ""
                lines.append(f'<DataArray type="{_VTK_NUMBERS[dtype]}"{name}{components} '
                             f'format="appended" offset="{offsets[(where, key)][0]}"/>')
        lines.append(f"</{section}>")
    lines += ["</Piece>", "</UnstructuredGrid>", '<AppendedData encoding="raw">', "_"]
    return "\n".join(lines[:-1]) + "\n_"


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


def vtu_files(meshes: list[ViewerMesh], folder: Path, stem: str) -> dict[Path, Callable[[str], None]]:
    """A VTU file per viewer mesh."""
    return {folder / file_name(stem, mesh.name, "vtu"): (lambda name, mesh=mesh: write_vtu(mesh, name))
            for mesh in meshes}


def xdmf_files(meshes: list[ViewerMesh], folder: Path, stem: str) -> dict[Path, Callable[[str], None]]:
    """The arrays of every mesh in ``stem-xdmf.h5``, then an XDMF file per viewer mesh."""
    heavy = f"{stem}-xdmf.h5"
    writers = {folder / heavy: lambda name: write_heavy_data(meshes, name)}
    for mesh in meshes:
        text = xdmf_text(mesh, heavy)
        writers[folder / file_name(stem, mesh.name, "xdmf")] = lambda name, text=text: Path(name).write_text(text, encoding="utf-8")
    return writers


# --- the registry of formats -------------------------------------------------------------------
@dataclass(frozen=True)
class ViewerFormat:
    """A viewer file format, as meshio registers one: its ``name`` (the suffix of its files) and ``write``,
    which gives path -> writer (called with a temporary name) of the viewer meshes' files in ``folder``
    (one per mesh, :func:`viewer_names`, and ``extra``: the endings after the stem of any other file)."""

    name: str
    write: Callable[[list[ViewerMesh], Path, str], dict[Path, Callable[[str], None]]]
    extra: tuple[str, ...] = ()


#: Format name -> its :class:`ViewerFormat`: what ``save``, ``ddsolve export --format`` and the checks of
#: the outputs offer.
FORMATS: dict[str, ViewerFormat] = {}


def register(viewer_format: ViewerFormat) -> ViewerFormat:
    """Add a viewer format to :data:`FORMATS`."""
    FORMATS[viewer_format.name] = viewer_format
    return viewer_format


register(ViewerFormat("vtu", vtu_files))
register(ViewerFormat("xdmf", xdmf_files, extra=("-xdmf.h5",)))


def viewer_format(fmt: str) -> ViewerFormat:
    """The registered format ``fmt``."""
    if fmt not in FORMATS:
        raise DDSolveError(f"--format {fmt}: expected one of {', '.join(FORMATS)}")
    return FORMATS[fmt]


# --- the ParaView script -----------------------------------------------------------------------
def paraview_script(title: str, folder: Path, files: dict[str, str], ceilings: dict[str, float], scale: float,
                    stacked: bool, graph: bool, opening: tuple[float, float] | None = None) -> str:
    """A pvpython script showing the layers side by side (warped by ``scale``, coloured by von Mises
    stress up to ``ceilings`` per layer) and the opening along Σ (against x if Σ is a ``graph``);
    ``files``: each layer (layer1, and layer2 with two layers), sigma -> file names in ``folder``, beside the
    script.  With the ``opening``'s range, a 3-D box: ``files`` of its halves (lower, upper) and Σ, the halves
    coloured by the displacement's magnitude up to ``ceilings``, Σ by the opening."""
    settings = {
        "TITLE": title, "FILES": files, "WRITTEN_TO": str(Path(folder).resolve()), "SCALE": scale,
        "CEILINGS": ceilings, "TITLES": plots.LAYER_TITLES, "STACKED": stacked, "PERCENTILE": plots.STRESS_PERCENTILE,
        "SIGMA_X": "x" if graph else "arc_length",
        "SIGMA_X_LABEL": f"{'x on Sigma' if graph else 'arc length along Sigma'} ({plots.LENGTH})",
        "SOLID": opening is not None, "OPENING": opening,
    }
    values = "\n".join(f"{key} = {value!r}" for key, value in settings.items())
    template = resources.files("ddsolve.io").joinpath("paraview-view.py").read_text(encoding="utf-8")
    return template.replace("@SETTINGS@", values)


def result_script(result: Result, folder: Path, files: dict[str, str], fields: dict[str, analysis.CellFields]) -> str:
    """:func:`paraview_script` of a whole result."""
    ceilings = {layer: plots.stress_ceiling(np.concatenate([fields[spec.name].von_mises for spec in result.blocks
                                                            if spec.layer == layer]))
                for layer in result.scene.layers}
    points = np.vstack([result.lower.points, result.upper.points])
    return paraview_script(result.scene.title, folder, files, ceilings, plots.magnification(result),
                           plots.one_above_the_other(points), analysis.sigma_is_graph(result))


# --- the set of files ---------------------------------------------------------------------------
VIEWER_MESHES = (*LAYERS, "sigma")


def file_name(stem: str, mesh: str, fmt: str) -> str:
    """The file of viewer mesh ``mesh`` of the result ``stem`` in format ``fmt``."""
    return f"{stem}-{mesh}.{fmt}"


def viewer_names(stem: str, fmt: str = "vtu", layers: tuple[str, ...] = LAYERS) -> dict[str, str]:
    """Viewer mesh -> its file name, for a structure of ``layers`` (a one-layer structure has no layer2 file)."""
    return {mesh: file_name(stem, mesh, fmt) for mesh in (*layers, "sigma")}


def viewer_paths(folder: Path, stem: str, fmt: str = "vtu", layers: tuple[str, ...] = LAYERS) -> list[Path]:
    """Every file :func:`viewer_files` writes for ``folder/stem`` in format ``fmt`` for a structure of ``layers``
    (by default those of any structure)."""
    names = list(viewer_names(stem, fmt, layers).values()) + [stem + ending for ending in viewer_format(fmt).extra]
    return [Path(folder) / name for name in names + [f"{stem}-paraview.py"]]


def viewer_files(result: Result, folder: Path, stem: str, fmt: str = "vtu",
                 fields: dict[str, analysis.CellFields] | None = None) -> dict[Path, Callable[[str], None]]:
    """Path -> writer (called with a temporary name) for every viewer file of ``result``; ``fields``:
    :func:`ddsolve.post.analysis.cell_fields` of the result if already computed."""
    write = viewer_format(fmt).write
    folder = Path(folder)
    fields = analysis.cell_fields(result) if fields is None else fields
    meshes = [layer_mesh(result, layer, fields) for layer in result.scene.layers] + [
        sigma_mesh(result.on_sigma, result.mesh.degree, result.scene.friction)]
    names = viewer_names(stem, fmt, result.scene.layers)
    script = result_script(result, folder, names, fields)
    writers = write(meshes, folder, stem)
    writers[folder / f"{stem}-paraview.py"] = lambda name: Path(name).write_text(script, encoding="utf-8")
    return writers


def stack_files(stacked: StackResult, folder: Path, stem: str, fmt: str = "vtu"
                ) -> dict[Path, Callable[[str], None]]:
    """Path -> writer of the viewer files of a result of several interfaces: a mesh per block (``stem-u1`` ...:
    its region's cells, its displacement and per-cell fields) and per interface Σ (``stem-sigma1`` ...); no
    ParaView script."""
    fields = cell_fields(stacked)
    meshes = []
    for name, _, region in block_names(stacked.scene.geometry.layers, len(stacked.mesh.regions)):
        half = stacked.mesh.regions[region]
        meshes.append(ViewerMesh(name, padded(half.points), "triangle" if half.degree == 1 else "triangle6",
                                 half.cells, {"displacement": padded(stacked.solution[name])},
                                 field_arrays(fields[name])))
    for number, view in enumerate(stacked.interfaces, start=1):
        meshes.append(dataclasses.replace(sigma_mesh(view.on_sigma, view.mesh.degree), name=f"sigma{number}"))
    return viewer_format(fmt).write(meshes, Path(folder), stem)


@dataclass(frozen=True)
class Distributed:
    """A rank's part of the VTU viewer files of a result the ranks write together: its shares of the
    viewer meshes (mesh name -> :func:`layer_share`, or Σ's :func:`sigma_mesh` on rank 0) and, on
    rank 0, the ParaView script's text; ``layers``: the structure's, one file each."""

    shares: dict[str, ViewerMesh]
    script: str = ""
    layers: tuple[str, ...] = LAYERS


def distributed_files(viewer: Distributed, folder: Path, stem: str, comm) -> dict[Path, Callable[[str], None]]:
    """Path -> collective writer (every rank of ``comm`` calls it with the same temporary name) of the
    VTU viewer files; each rank writes its shares into the one file of each mesh."""
    folder = Path(folder)
    writers: dict[Path, Callable[[str], None]] = {
        folder / file: (lambda name, mesh=mesh: write_vtu(viewer.shares.get(mesh), name, comm))
        for mesh, file in viewer_names(stem, layers=viewer.layers).items()}

    def script(name: str) -> None:
        if comm.rank == 0:
            Path(name).write_text(viewer.script, encoding="utf-8")

    writers[folder / f"{stem}-paraview.py"] = script
    return writers
