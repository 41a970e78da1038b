"""The built-in box of several interfaces (``geometry.sigma = [y1, y2, ...]``): each region meshed by gmsh on its
own, in a child process, with ``mesh.size``; neighbouring regions share their Σ's vertices (every Σ piece between
crack tips is divided the same way from both sides), and :func:`ddsolve.mesh.mesh.make_stack` pairs them.  A gmsh
file of several interfaces (curves ``sigma1`` ..., ``crack1`` ..., a physical surface per region) is meshed as
one and its regions taken apart along its curves.

Region k (``region1`` ... bottom to top) has the box's bottom (region 1), the Σ below it named ``sigma`` and its
cracks ``crack`` (regions 2 ...), the Σ above it named ``sigma`` in region 1 and ``sigma_above`` with
``crack_above`` in a middle region, the box's top (the last region), and the sides ``left`` and ``right``.
"""
from __future__ import annotations

import math
import re

import numpy as np

from ddsolve.mesh.element import outer_edges
from ddsolve.mesh.geometry import FINEST, build, check_pieces, local_origin, origin, translated
from ddsolve.errors import MeshError, SceneError
from ddsolve.mesh.gmsh_io import GMSH_TRIANGLE, apart, group_elements, meshed, session
from ddsolve.mesh.mesh import (CLAMPED, CRACK, CRACK_ABOVE, SIGMA, SIGMA_ABOVE, TOL, HalfMesh, Mesh, elevate,
                               make_stack, oriented, region_half)
from ddsolve.mesh.sizing import node_positions
from ddsolve.problem.scene import Geometry, Scene

#: A gmsh file's curves of several interfaces: ``sigma1`` ..., ``crack1`` ...
NUMBERED = re.compile(r"(sigma|crack)\d+")


def build_any(scene: Scene) -> Mesh:
    """The scene's mesh: the regions of several interfaces paired (:func:`make_stack`; a gmsh file's:
    :func:`_from_file`; the box's lines divided as :func:`check_spacing` allows), else
    :func:`ddsolve.mesh.geometry.build`'s."""
    if not scene.geometry.above:
        return build(scene)
    if scene.mesh.file is not None:
        return apart(_from_file, scene)
    count = len(scene.geometry.sigmas) + 1
    check_spacing(scene)
    return make_stack(tuple(apart(_mesh_region, scene, index) for index in range(count)), origin(scene))


def _from_file(scene: Scene) -> Mesh:
    """A gmsh file of several interfaces: its region surfaces (``geometry.regions``, bottom to top) meshed or read,
    each with its Σ lines and cracks named as the box's regions name them (:func:`_region_curves`)."""
    where, names = str(scene.mesh.file), scene.geometry.regions
    lines = tuple(f"sigma{k}" for k in range(1, len(names)))
    with session() as gmsh:
        groups, points, position = meshed(gmsh, scene, {2: names, 1: lines})
        surfaces, curves = group_elements(gmsh, groups, names, position, where)
    _check_apart(curves, lines, where)
    regions = []
    for index, name in enumerate(names):
        cells = surfaces[name]
        if cells.shape[1] == 6 and scene.mesh.degree == 1:
            raise MeshError(f"{where}: the file has 6-node (P2) triangles: set mesh.degree = 2")
        used = np.zeros(len(points), dtype=bool)
        used[cells] = True
        mine = _region_curves({curve: edges[used[edges].all(axis=1)] for curve, edges in curves.items()}, index,
                              len(lines), f"{where}: physical surface {name}")
        own = points
        if cells.shape[1] == 3 and scene.mesh.degree == 2:
            own, cells, mine = elevate(points, cells, {key: edges[:, :2] for key, edges in mine.items()})
        regions.append(region_half(own, cells, name, index == 0, mine, where))
    heights = [float(np.mean(region.points[np.unique(region.cells), 1])) for region in regions]
    if any(low >= high for low, high in zip(heights, heights[1:])):
        raise MeshError(f"{where}: the physical surfaces {', '.join(names)} are not listed bottom to top (their "
                        f"mean heights {', '.join(f'{y:.4g}' for y in heights)}): list the regions bottom to top")
    return make_stack(tuple(regions), where)


def _check_apart(curves: dict[str, np.ndarray], lines: tuple[str, ...], where: str) -> None:
    """Refuse interfaces that cross or touch (share a node) in one line."""
    nodes = [set(np.unique(curves[line]).tolist()) for line in lines]
    for k, mine in enumerate(nodes):
        other = next((j for j in range(k + 1, len(lines)) if mine & nodes[j]), None)
        if other is not None:
            raise MeshError(f"{where}: physical curves {lines[k]} and {lines[other]} cross or touch: interfaces "
                            "lie apart, bottom to top")


def _region_curves(curves: dict[str, np.ndarray], index: int, count: int, where: str) -> dict[str, np.ndarray]:
    """Region ``index``'s boundary curves (of ``count`` interfaces) as the box's regions name them: the Σ below it
    and its cracks ``sigma`` and ``crack``, the Σ above it ``sigma`` (the lowest region) or ``sigma_above`` with
    ``crack_above``; the file's other curves by their names.  A region that does not lie on the interfaces
    below and above it (and on no other) is refused in one line."""
    touched = [k for k in range(1, count + 1) if len(curves.get(f"sigma{k}", ())) ]
    expected = [k for k in (index, index + 1) if 1 <= k <= count]
    if touched != expected:
        raise MeshError(f"{where} lies on {', '.join(f'sigma{k}' for k in touched) or 'no interface'}, and region "
                        f"{index + 1} from the bottom lies on {' and '.join(f'sigma{k}' for k in expected)}: list the "
                        "region surfaces bottom to top, each between its interfaces")
    renamed = {f"sigma{index}": SIGMA, f"crack{index}": CRACK}
    if index == 0:
        renamed.update({"sigma1": SIGMA, "crack1": CRACK})
    else:
        renamed.update({f"sigma{index + 1}": SIGMA_ABOVE, f"crack{index + 1}": CRACK_ABOVE})
    numbered = {name for name in curves if NUMBERED.fullmatch(name)}
    return {renamed.get(name, name): edges for name, edges in curves.items()
            if len(edges) and (name in renamed or name not in numbered)}


def _mesh_region(scene: Scene, index: int) -> HalfMesh:
    """Region ``index`` (0: the bottom one) triangulated by gmsh: every line divided into pieces of about
    ``mesh.size`` (each Σ piece between crack tips on its own), the size ``mesh.size`` inside; beside a region
    thinner than that, its thickness along the line (:func:`line_spacings`), growing away from it."""
    shift = local_origin(scene.geometry.box)  # gmsh meshes the box about a nearby origin
    geometry = translated(scene.geometry, -shift)
    x0, x1, _, _ = geometry.box
    lines = _lines(geometry, index)
    h = scene.mesh.size
    spacings = line_spacings(geometry, h)
    with session(deterministic=True) as gmsh:
        geo = gmsh.model.geo
        bottom, top = ([(x, lines[name][0]) for x in lines[name][1]] for name in ("bottom", "top"))
        made = {xy: geo.addPoint(xy[0], xy[1], 0.0) for xy in (*bottom, *top)}

        def chain(points: list) -> list[tuple[int, float]]:
            """Lines through ``points``, left to right or bottom to top (as a neighbouring region's same line,
            so that both divide it alike), with their lengths."""
            return [(geo.addLine(made[a], made[b]), math.dist(a, b)) for a, b in zip(points[:-1], points[1:])]

        below, right, above, left = chain(bottom), chain([bottom[-1], top[-1]]), chain(top), chain([bottom[0], top[0]])
        curves = [*below, *right, *above, *left]
        loop = [*(c for c, _ in below), *(c for c, _ in right), *(-c for c, _ in above[::-1]), *(-c for c, _ in left)]
        surface = geo.addPlaneSurface([geo.addCurveLoop(loop)])
        geo.synchronize()
        low, high = spacings[index], spacings[index + 1]
        uniform = low == high == h  # else the sides follow the size field, which grows away from a fine line
        for pieces, size in [(below, low), (above, high)] + ([(right, h), (left, h)] if uniform else []):
            for curve, length in pieces:
                gmsh.model.mesh.setTransfiniteCurve(curve, max(1, math.ceil(length / size - 1e-9)) + 1)
        field = gmsh.model.mesh.field.add("MathEval")
        graded = (f"Min({h:.17g}, Min({low:.17g} + {GROWTH:g} * (y - {bottom[0][1]:.17g}), {high:.17g} + "
                  f"{GROWTH:g} * ({top[0][1]:.17g} - y)))")
        gmsh.model.mesh.field.setString(field, "F", f"{h:.17f}" if uniform else graded)
        gmsh.model.mesh.field.setAsBackgroundMesh(field)
        gmsh.model.mesh.generate(2)
        tags, coordinates, _ = gmsh.model.mesh.getNodes()
        points = np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)[:, :2]
        _, nodes = gmsh.model.mesh.getElementsByType(GMSH_TRIANGLE, surface)
        cells = node_positions(tags)[np.asarray(nodes, dtype=np.int64).reshape(-1, 3)]
    points = _snap(points, geometry)
    where = origin(scene)
    name = geometry.region_names[index]
    cells = oriented(points, cells, f"{where}: {name}")
    boundaries = _boundaries(points, cells, geometry, lines)
    if scene.mesh.degree == 2:
        points, cells, boundaries = elevate(points, cells, boundaries)
    return region_half(points + shift, cells, name, index == 0, boundaries, where)


#: How fast the element size grows away from a line divided finer than mesh.size (beside a thin region).
GROWTH = 0.5


def line_spacings(geometry: Geometry, h: float) -> list[float]:
    """The element size along each horizontal line, bottom to top (the box's bottom, each Σ, its top): ``h``
    (mesh.size), or the thickness of a thinner region beside the line, so that a thin region's triangles keep
    their shape."""
    _, _, y0, y1 = geometry.box
    thickness = np.diff([y0, *geometry.sigmas, y1])
    return [min(h, *thickness[max(k - 1, 0):k + 1]) for k in range(len(thickness) + 1)]


def check_spacing(scene: Scene) -> None:
    """Refuse, naming the key, a region thinner than mesh.size / FINEST (its lines would be divided into too many
    elements) or a Σ piece between crack tips shorter than that (:func:`ddsolve.mesh.geometry.check_pieces`)."""
    geometry, h = scene.geometry, scene.mesh.size
    _, _, y0, y1 = geometry.box
    finest = h / FINEST
    heights = [y0, *geometry.sigmas, y1]
    for name, low, high in zip(geometry.region_names, heights[:-1], heights[1:]):
        if high - low < finest:
            raise SceneError(f"{scene.origin}: geometry.sigma: {name} is {high - low:.3g} thick, less than mesh.size "
                             f"/ {FINEST:g} = {finest:.3g}: give mesh.size at most {FINEST * (high - low):.3g}, or a "
                             "thicker region")
    check_pieces(scene, h, "mesh.size")


def _lines(geometry: Geometry, index: int) -> dict[str, tuple]:
    """Region ``index``'s bottom and top lines: height, the x of their vertices (ends and crack tips), the
    boundary name, its cracks' name and the cracks."""
    x0, x1, y0, y1 = geometry.box
    count = len(geometry.sigmas) + 1

    def line(interface: int, name: str, crack: str) -> tuple:
        cracks = geometry.crack_lists[interface]
        tips = sorted({x0, *(tip for piece in cracks for tip in piece if x0 < tip < x1), x1})
        return geometry.sigmas[interface], tips, name, crack, cracks

    bottom = (y0, [x0, x1], "bottom", "", ()) if index == 0 else line(index - 1, SIGMA, CRACK)
    top = ((y1, [x0, x1], "top", "", ()) if index == count - 1 else
           line(index, SIGMA, CRACK) if index == 0 else line(index, SIGMA_ABOVE, CRACK_ABOVE))
    return {"bottom": bottom, "top": top}


def _snap(points: np.ndarray, geometry: Geometry) -> np.ndarray:
    """Coordinates within TOL (relative) of the box's lines or of a Σ put exactly on them."""
    x0, x1, y0, y1 = geometry.box
    scale = max(x1 - x0, y1 - y0)
    points = np.array(points, dtype=np.float64)
    for column, values in ((0, (x0, x1)), (1, (y0, *geometry.sigmas, y1))):
        for value in values:
            points[np.abs(points[:, column] - value) <= TOL * scale, column] = value
    return points


def _boundaries(points: np.ndarray, cells: np.ndarray, geometry: Geometry, lines: dict) -> dict[str, np.ndarray]:
    """A region's boundary edges by name: its bottom and top lines, the sides, the cracks on its Σ lines, Γ_D."""
    x0, x1, _, _ = geometry.box
    outer = outer_edges(cells)
    ends = points[outer]
    named = {"left": outer[np.all(ends[:, :, 0] == x0, axis=1)], "right": outer[np.all(ends[:, :, 0] == x1, axis=1)]}
    scale = x1 - x0
    for height, _, name, crack, cracks in lines.values():
        edges = outer[np.all(ends[:, :, 1] == height, axis=1)]
        named[name] = edges
        x = points[edges, 0]
        on_crack = np.zeros(len(edges), dtype=bool)
        for a, b in cracks:
            on_crack |= np.all((x >= a - TOL * scale) & (x <= b + TOL * scale), axis=1)
        if crack:
            named[crack] = edges[on_crack]
    clamped = [named[side] for side in geometry.clamped if side in named]
    named[CLAMPED] = np.concatenate(clamped) if clamped else np.zeros((0, 2), dtype=np.int64)
    return {name: edges for name, edges in named.items() if len(edges)}
