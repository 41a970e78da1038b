"""Geometry: from a scene to a :class:`~ddsolve.mesh.mesh.Mesh`, by gmsh or from a file.

Three sources give the same thing:

- the built-in **box** ``geometry.box`` cut by Σ at ``geometry.sigma``, with cracks as x intervals
  on Σ and clamped sides; each half is meshed by gmsh on its own (so two ranks can mesh at once),
  with matching Σ nodes from the same transfinite curves.  Boundary names: ``bottom``, ``top``,
  ``left``, ``right``, ``sigma``, ``crack``, ``clamped``;
- a gmsh **.geo** script or **.msh** file with physical groups ``lower`` and ``upper`` (surfaces) and
  ``sigma``, ``clamped``, optionally ``crack`` and any other names (curves), see docs/geometry.md;
- any other **mesh file** meshio reads (or a .msh without those groups): triangles of the box, split
  into halves at Σ, boundaries named by the box's sides.

gmsh is imported only here, and only when a mesh is made.
"""
from __future__ import annotations

import contextlib
import io
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ddsolve.errors import MeshError, SceneError
from ddsolve.mesh import curves, refine
from ddsolve.mesh.gmsh_io import GMSH_TRIANGLE, apart, from_gmsh, has_halves, session
from ddsolve.mesh.mesh import (CLAMPED, CRACK, SIGMA, TOL, HalfMesh, Mesh, elevate, make_half, make_mesh, merge_repeats,
                               oriented)
from ddsolve.mesh.sizing import box_length, box_singular_points, node_positions, set_size_field
from ddsolve.problem.scene import Geometry, Scene, readable

#: Grading of the paper's mesh family: h(d) = h_Σ + (h_far − h_Σ)(d/H)^GRADING_EXPONENT at distance d
#: from Σ (H: the larger half height), h_far = FAR_FACTOR·perimeter/M.  Fitted so that the five meshes
#: of the paper's Table 1 have its vertex and triangle counts (±5 %).
GRADING_EXPONENT = 0.8
FAR_FACTOR = 1.2


def build(scene: Scene) -> Mesh:
    """The scene's mesh, from whichever source it names; always checked.  A coarse mesh refined when
    :func:`refinement` says so."""
    coarse, levels = refinement(scene)
    if levels:
        return refine.refine(build_coarse(coarse), levels, scene.mesh.degree, curves.projector(scene))
    return build_coarse(scene)


def build_coarse(scene: Scene) -> Mesh:
    """The scene's mesh as gmsh makes it or the file holds it, unrefined."""
    one_interface(scene)
    options = scene.mesh
    if options.kind == "box":
        return pair(scene, *(generate_half(scene, side) for side in (-1, 1)))
    if options.kind == "geo" or (options.file.suffix.lower() == ".msh" and has_halves(options.file)):
        return from_gmsh(scene)
    return read_box_file(scene)


def origin(scene: Scene) -> str:
    """How to name the scene's mesh in messages."""
    return str(scene.mesh.file) if scene.mesh.file is not None else "generated mesh"


def check_loads(scene: Scene, mesh: Mesh) -> None:
    """Every load names a boundary of the mesh that is not clamped (else a one-line SceneError)."""
    names = mesh.boundary_names()
    for (_, name), load in scene.loads.items():
        if name not in names:
            raise SceneError(f"{load.key}: no boundary named {name!r} in {mesh.origin} "
                             f"(boundaries: {', '.join(n for n in names if n != CLAMPED)})")
        if name == CLAMPED or all(_edge_set(half, name) <= _edge_set(half, CLAMPED) for half in mesh.regions):
            raise SceneError(f"{load.key}: boundary {name!r} is clamped (Γ_D), where no load can act")
        if all(np.isin(half.nodes(name), half.clamped()).all() for half in mesh.regions):
            raise SceneError(f"{load.key}: on this mesh every node of boundary {name!r} is clamped, so the load "
                             "would act on nothing (a mesh coarser than the geometry): use smaller elements "
                             "(mesh.size, or mesh.sigma_vertices and mesh.boundary_vertices) or mesh.degree = 2")


def _edge_set(half: HalfMesh, name: str) -> set[tuple[int, int]]:
    return set(map(tuple, np.sort(half.edges(name)[:, :2], axis=1).tolist()))


def pair(scene: Scene, lower: HalfMesh, upper: HalfMesh) -> Mesh:
    """The mesh of two halves made separately (box geometry)."""
    return make_mesh(lower, upper, origin(scene))


# --- the built-in box -----------------------------------------------------------------------------
def apportion(total: int, lengths) -> np.ndarray:
    """Split ``total`` segments among pieces in proportion to their lengths (≥ 1 each, exact sum)."""
    lengths = np.asarray(lengths, dtype=float)
    ideal = total * lengths / lengths.sum()
    count = np.maximum(np.floor(ideal).astype(np.int64), 1)
    while count.sum() > total:
        count[int(np.argmax(np.where(count > 1, count - ideal, -np.inf)))] -= 1
    while count.sum() < total:
        count[int(np.argmax(ideal - count))] += 1
    return count


def generate_half(scene: Scene, side: int) -> HalfMesh:
    """One half of the box meshed by gmsh (:func:`_mesh_half`) in a child process (:func:`apart`)."""
    one_interface(scene)
    if scene.mesh.grading is None:  # Σ divided uniformly between crack tips (a graded mesh refines at the tips)
        x0, x1, _, _ = scene.geometry.box
        size = scene.mesh.size
        check_pieces(scene, size or (x1 - x0) / (scene.mesh.sigma_vertices - 1),
                     "mesh.size" if size else "mesh.sigma_vertices")
    return apart(_mesh_half, scene, side)


#: The shortest piece of a Σ between crack tips (or its ends) a box takes: its elements' size over this.
FINEST = 100.0


def check_pieces(scene: Scene, spacing: float, key: str) -> None:
    """Refuse, naming ``geometry.cracks``, a piece of a Σ between crack tips (or its ends) shorter than ``spacing``
    (the Σ elements' size, set by ``key``, or the box's width or height where it is smaller: no element is larger
    than the box) / :data:`FINEST`: it would be one element among far longer ones, its triangles slivers."""
    x0, x1, y0, y1 = scene.geometry.box
    if spacing > min(x1 - x0, y1 - y0):
        spacing, key = min(x1 - x0, y1 - y0), f"{key}, bounded by the box"
    finest = spacing / FINEST
    several = len(scene.geometry.sigmas) > 1
    for number, cracks in enumerate(scene.geometry.crack_lists, start=1):
        tips = sorted({x0, *(tip for piece in cracks for tip in piece if x0 < tip < x1), x1})
        short = next(((a, b) for a, b in zip(tips[:-1], tips[1:]) if b - a < finest), None)
        if short is not None:
            which = f"interface {number}'s" if several else "the"
            raise SceneError(f"{scene.origin}: geometry.cracks: {which} piece "
                             f"[{short[0]:.10g}, {short[1]:.10g}] of Σ between crack tips is {short[1] - short[0]:.3g} "
                             f"long, less than 1/{FINEST:g} of its elements' size {spacing:.3g} ({key}): they would be "
                             f"slivers; refine ({key}) or lengthen the piece")


def one_interface(scene: Scene) -> None:
    """Refuse, in one line, to do with a structure of several interfaces what is done for one interface only: it is
    read, checked and meshed (:func:`ddsolve.mesh.stack.build_any`, the ``mesh`` command) and solved by the
    monolithic reference (:mod:`ddsolve.solvers.stacked`) and the domain decomposition
    (:mod:`ddsolve.solvers.stacked_dd`), not yet by sweeps, growth or adaptivity."""
    if scene.geometry.above:
        raise SceneError(f"geometry.sigma: {len(scene.geometry.sigmas)} interfaces: a structure of several "
                         "interfaces is meshed (ddsolve mesh) and solved by the monolithic reference (ddsolve "
                         "reference) and the domain decomposition (ddsolve solve), not yet by sweeps, growth or "
                         "adaptivity")


def _mesh_half(scene: Scene, side: int) -> HalfMesh:
    """Unstructured triangulation of one half of the box (side −1: lower, +1: upper) with gmsh.

    With (P, M): Σ gets P vertices (ends and crack tips included), uniform on each Σ piece; the outer
    boundary gets M vertices in proportion to length; inside, the size grows from the Σ spacing to
    ``FAR_FACTOR`` × the boundary spacing (the paper's family).  With ``mesh.size`` h: every curve is
    divided into pieces of about h and the size is h throughout.  With ``mesh.grading`` the size field
    alone (:func:`set_size_field`) sizes every curve and the inside.  One thread, deterministic: a half is the same whether it is
    meshed alone in a process or after the other one, and the Σ vertices of both halves come from the
    same curves meshed with the same size field.
    """
    options = scene.mesh
    shift = local_origin(scene.geometry.box)  # gmsh meshes the box about a nearby origin
    geometry = translated(scene.geometry, -shift)
    x0, x1, y0, y1 = geometry.box
    ys = geometry.sigma
    stops = box_stops(scene, -shift)
    cracks = [tip for piece in geometry.cracks for tip in piece if x0 < tip < x1]
    sigma_x = sorted({x0, *cracks, *stops["sigma"], x1})
    width, below, above = x1 - x0, ys - y0, y1 - ys
    lengths = [width, width, below, below, above, above]  # bottom, top, the four half-sides
    sides = {"bottom": [(x, y0) for x in [x0, *stops["bottom"], x1]],
             "top": [(x, y1) for x in [x1, *stops["top"][::-1], x0]],
             "right_lower": [(x1, y) for y in [y0, *stops["right_lower"], ys]],
             "left_lower": [(x0, y) for y in [ys, *stops["left_lower"][::-1], y0]],
             "right_upper": [(x1, y) for y in [ys, *stops["right_upper"], y1]],
             "left_upper": [(x0, y) for y in [y1, *stops["left_upper"][::-1], ys]]}
    pieces = [np.linalg.norm(np.diff(np.array(chain), axis=0), axis=1) for chain in sides.values()]
    if options.size is None:
        P, M = options.sigma_vertices, options.boundary_vertices
        h_sigma = width / (P - 1)
        slope = FAR_FACTOR * 2.0 * (width + below + above) / M - h_sigma
        counts = [*apportion(P - 1, np.diff(sigma_x)),
                  *(count for total, piece in zip(apportion(M, lengths), pieces)
                    for count in apportion(max(int(total), len(piece)), piece))]
        size_field = (f"{h_sigma:.17f} {'+' if slope >= 0 else '-'} {abs(slope):.17f} * "
                      f"({_distance_to_sigma(ys, max(below, above))})^{GRADING_EXPONENT:.17f}")
    else:
        h = options.size
        counts = [max(1, math.ceil(length / h - 1e-9)) for length in [*np.diff(sigma_x), *np.concatenate(pieces)]]
        size_field = f"{h:.17f}"
    with session(deterministic=True) as gmsh:
        geo = gmsh.model.geo
        made: dict[tuple[float, float], int] = {}

        def chain(coordinates) -> list[int]:
            """The lines through ``coordinates`` in order (their points made once)."""
            for xy in coordinates:
                if xy not in made:
                    made[xy] = geo.addPoint(xy[0], xy[1], 0.0)
            return [geo.addLine(made[a], made[b]) for a, b in zip(coordinates[:-1], coordinates[1:])]

        sigma = chain([(x, ys) for x in sigma_x])
        lines = {name: chain(coordinates) for name, coordinates in sides.items()}
        if side < 0:
            loop = [*lines["bottom"], *lines["right_lower"], *[-c for c in sigma[::-1]], *lines["left_lower"]]
        else:
            loop = [*sigma, *lines["right_upper"], *lines["top"], *lines["left_upper"]]
        surface = geo.addPlaneSurface([geo.addCurveLoop(loop)])
        bottom, top = lines["bottom"], lines["top"]
        edges = [lines[name] for name in ("right_lower", "left_lower", "right_upper", "left_upper")]
        geo.synchronize()
        if options.grading is None:
            for curve, count in zip([*sigma, *bottom, *top, *(c for piece in edges for c in piece)], counts):
                gmsh.model.mesh.setTransfiniteCurve(curve, int(count) + 1)
            field = gmsh.model.mesh.field.add("MathEval")
            gmsh.model.mesh.field.setString(field, "F", size_field)
            gmsh.model.mesh.field.setAsBackgroundMesh(field)
        else:
            set_size_field(gmsh, options, box_singular_points(geometry), box_length(geometry))
        gmsh.model.mesh.generate(2)
        tags, coordinates, _ = gmsh.model.mesh.getNodes()
        points = np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)[:, :2]
        position = node_positions(tags)
        _, nodes = gmsh.model.mesh.getElementsByType(GMSH_TRIANGLE, surface)
        cells = position[np.asarray(nodes, dtype=np.int64).reshape(-1, 3)]
    half = _box_half(points, cells, side, geometry, options.degree, origin(scene))
    return replace(half, points=half.points + shift)


def box_stops(scene: Scene, offset: np.ndarray) -> dict[str, list[float]]:
    """Where the box's point supports (``[displacements.LAYER.NAME] point``, moved by ``offset``) cut its
    lines, so that the mesh has a vertex at each: line name -> sorted coordinates along it (x on Σ, bottom
    and top; y on the half-sides), its ends excluded."""
    geometry = translated(scene.geometry, offset)
    x0, x1, y0, y1 = geometry.box
    ys = geometry.sigma
    out: dict[str, set[float]] = {name: set() for name in ("sigma", "bottom", "top", "right_lower", "left_lower",
                                                           "right_upper", "left_upper")}
    for displacement in scene.displacements.values():
        if displacement.point is None:
            continue
        x, y = (float(v) for v in np.asarray(displacement.point) + offset)
        if y in (ys, y0, y1) and x0 < x < x1:
            out["sigma" if y == ys else "bottom" if y == y0 else "top"].add(x)
        elif x in (x0, x1) and y0 < y < y1 and y != ys:
            out[f"{'left' if x == x0 else 'right'}_{'lower' if y < ys else 'upper'}"].add(y)
    return {name: sorted(values) for name, values in out.items()}


def local_origin(box) -> np.ndarray:
    """The point about which the box is meshed: the multiple of a power of two (at least 64 box sizes)
    nearest the box's centre.  It is (0, 0) for a box near the origin; for a box far away, coordinates
    relative to it are exact (a box at x = 1e9 is meshed as one at x = 0: gmsh fails on the former)."""
    x0, x1, y0, y1 = box
    unit = 2.0 ** math.ceil(math.log2(64.0 * max(x1 - x0, y1 - y0)))
    return np.array([round(0.5 * (x0 + x1) / unit) * unit, round(0.5 * (y0 + y1) / unit) * unit])


def translated(geometry: Geometry, offset: np.ndarray) -> Geometry:
    """The box geometry moved by ``offset`` (dx, dy)."""
    dx, dy = (float(v) for v in offset)
    x0, x1, y0, y1 = geometry.box

    def moved(cracks):
        return tuple((a + dx, b + dx) for a, b in cracks)

    return replace(geometry, box=(x0 + dx, x1 + dx, y0 + dy, y1 + dy), sigma=geometry.sigma + dy,
                   cracks=moved(geometry.cracks),
                   above=tuple((height + dy, moved(cracks)) for height, cracks in geometry.above))


#: Paper-family meshes with more Σ vertices than this are a coarse gmsh mesh refined (the paper's Table 1
#: meshes and P = 400 stay gmsh meshes); so are ``mesh.size`` boxes of more estimated vertices than
#: REFINE_VERTICES.
REFINE_SIGMA_VERTICES = 400
REFINE_VERTICES = 50000
#: The automatic choice refines until the coarse mesh has at most this many vertices (both halves; gmsh
#: makes it in a few hundredths of a second) ...
COARSE_VERTICES = 4000
#: ... while every Σ piece and every side of the box keeps at least this many coarse segments.
COARSE_SEGMENTS = 2


def refinement(scene: Scene) -> tuple[Scene, int]:
    """The scene of the coarse mesh and the levels of uniform refinement that make ``scene``'s mesh
    (0 levels: the scene's own mesh, made by gmsh or read).

    ``mesh.refine = k`` asks for k levels: the paper's family (P, M) is then made from (P_c, M_c) =
    (round((P − 1)/2^k) + 1, round(M/2^k)), so that the fine mesh has 2^k·(P_c − 1) + 1 Σ vertices, a
    ``mesh.size`` h from the size 2^k·h, a .geo without a size and a mesh file from their own mesh.  Left
    unset, a box above REFINE_SIGMA_VERTICES or REFINE_VERTICES without grading or a target error gets the
    fewest levels that bring the coarse mesh to COARSE_VERTICES, within COARSE_SEGMENTS per Σ piece and side.
    """
    options = scene.mesh
    if options.refine is not None:
        levels = options.refine
        if levels and options.kind == "box" and coarse_segments(scene, levels) < COARSE_SEGMENTS:
            raise SceneError(f"mesh.refine = {levels}: the coarse mesh would have fewer than {COARSE_SEGMENTS} "
                             "segments on a Σ piece or a side of the box; lower mesh.refine")
        return (coarsened(scene, levels), levels) if levels else (scene, 0)
    if options.kind != "box" or options.grading is not None or options.target_error is not None:
        return scene, 0
    large = (options.sigma_vertices > REFINE_SIGMA_VERTICES if options.size is None
             else estimated_vertices(scene) > REFINE_VERTICES)
    levels = 0
    while large and coarse_segments(scene, levels + 1) >= COARSE_SEGMENTS:
        levels += 1
        if estimated_vertices(coarsened(scene, levels)) <= COARSE_VERTICES:
            break
    return (coarsened(scene, levels), levels) if levels else (scene, 0)


def coarsened(scene: Scene, levels: int) -> Scene:
    """The P1 scene whose mesh, refined ``levels`` times, is (about) ``scene``'s (see :func:`refinement`)."""
    options, factor = scene.mesh, 2 ** levels
    if options.sigma_vertices is not None:
        options = replace(options, sigma_vertices=max(2, round((options.sigma_vertices - 1) / factor)) + 1,
                          boundary_vertices=max(4, round(options.boundary_vertices / factor)))
    elif options.size is not None:
        options = replace(options, size=options.size * factor)
    return replace(scene, mesh=replace(options, degree=1, refine=0))


def coarse_segments(scene: Scene, levels: int) -> int:
    """The fewest segments on a Σ piece or a side of the box in the coarse mesh for ``levels`` levels."""
    options = coarsened(scene, levels).mesh
    x0, x1, y0, y1 = scene.geometry.box
    ys = scene.geometry.sigma
    sigma_x = sorted({x0, *(tip for piece in scene.geometry.cracks for tip in piece if x0 < tip < x1), x1})
    sides = [x1 - x0, x1 - x0, ys - y0, ys - y0, y1 - ys, y1 - ys]
    if options.size is None:
        counts = [*apportion(options.sigma_vertices - 1, np.diff(sigma_x)),
                  *apportion(options.boundary_vertices, sides)]
    else:
        counts = [math.ceil(length / options.size - 1e-9) for length in [*np.diff(sigma_x), *sides]]
    return int(min(counts))


def estimated_vertices(scene: Scene) -> float | None:
    """About how many vertices :func:`generate_half` makes for both halves of the box (the paper's
    family integrated over its size field, or a uniform ``mesh.size``; P2 nodes counted as vertices of
    the halved size); None for geometries from files and 3-D boxes (:mod:`ddsolve.mesh.solid`)."""
    options = scene.mesh
    if options.kind != "box" or scene.geometry.dimension == 3:
        return None
    x0, x1, y0, y1 = scene.geometry.box
    width, below, above = x1 - x0, scene.geometry.sigma - y0, y1 - scene.geometry.sigma
    if options.size is not None:
        count = 2.0 / math.sqrt(3.0) * width * (below + above) / options.size ** 2
    else:
        h_sigma = width / (options.sigma_vertices - 1)
        slope = FAR_FACTOR * 2.0 * (width + below + above) / options.boundary_vertices - h_sigma
        count = 0.0
        for height in (below, above):
            distance = np.linspace(0.0, height, 401)
            size = h_sigma + slope * (distance / max(below, above)) ** GRADING_EXPONENT
            density = 2.0 / (math.sqrt(3.0) * size ** 2)
            count += width * float(np.sum(0.5 * (density[1:] + density[:-1]) * np.diff(distance)))
    return count * options.degree ** 2


def _distance_to_sigma(ys: float, height: float) -> str:
    """gmsh MathEval text for |y − ys| / height (written out so the paper's square gives Fabs(y))."""
    shifted = "y" if ys == 0.0 else f"(y {'-' if ys > 0 else '+'} {abs(ys):.17f})"
    return f"Fabs({shifted})" if height == 1.0 else f"Fabs({shifted}) / {height:.17f}"



def snap(points: np.ndarray, geometry: Geometry) -> np.ndarray:
    """Coordinates within TOL (relative) of the box's lines or of Σ put exactly on them."""
    x0, x1, y0, y1 = geometry.box
    scale = max(x1 - x0, y1 - y0)
    points = np.array(points, dtype=np.float64)
    for column, values in ((0, (x0, x1)), (1, (y0, geometry.sigma, y1))):
        for value in values:
            near = np.abs(points[:, column] - value) <= TOL * scale
            points[near, column] = value
    return points


def _box_half(points: np.ndarray, cells: np.ndarray, side: int, geometry: Geometry, degree: int,
              where: str) -> HalfMesh:
    """A half of the box from P1 triangles: boundaries named by the sides they lie on."""
    points = snap(points, geometry)
    cells = oriented(points, cells, f"{where}: {'lower' if side < 0 else 'upper'} half")
    boundaries = box_boundaries(points, cells, geometry, where)
    if degree == 2:
        points, cells, boundaries = elevate(points, cells, boundaries)
    half, _ = make_half(points, cells, side, boundaries, where)
    return half


def box_boundaries(points: np.ndarray, cells: np.ndarray, geometry: Geometry, where: str) -> dict[str, np.ndarray]:
    """Boundary edges of one half of the box by name: the sides, Σ, the cracks on Σ, Γ_D."""
    x0, x1, y0, y1 = geometry.box
    pairs = cells[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    keys = np.minimum(pairs[:, 0], pairs[:, 1]) * len(points) + np.maximum(pairs[:, 0], pairs[:, 1])
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    outer = pairs[counts[inverse] == 1]
    ends = points[outer]
    lines = {"bottom": (1, y0), "top": (1, y1), "left": (0, x0), "right": (0, x1), SIGMA: (1, geometry.sigma)}
    named = {name: outer[np.all(ends[:, :, column] == value, axis=1)] for name, (column, value) in lines.items()}
    covered = sum(len(edges) for edges in named.values())
    if covered != len(outer):
        raise MeshError(f"{where}: {len(outer) - covered} boundary edges lie inside the box (holes or "
                        "non-conforming cells)")
    sigma_x = points[named[SIGMA], 0]
    scale = x1 - x0
    on_crack = np.zeros(len(sigma_x), dtype=bool)
    for a, b in geometry.cracks:
        for tip in (a, b):
            if x0 < tip < x1 and np.abs(sigma_x - tip).min(initial=np.inf) > TOL * scale:
                raise MeshError(f"{where}: crack tip x = {tip:g} is not a Σ vertex")
        on_crack |= np.all((sigma_x >= a - TOL * scale) & (sigma_x <= b + TOL * scale), axis=1)
    named[CRACK] = named[SIGMA][on_crack]
    named[CLAMPED] = np.concatenate([named[name] for name in geometry.clamped]) if geometry.clamped \
        else np.zeros((0, 2), dtype=np.int64)
    return {name: edges for name, edges in named.items() if len(edges)}



# --- files of the box (any format meshio reads) ---------------------------------------------------
def read_box_file(scene: Scene) -> Mesh:
    """A triangle mesh of the box from a file (any format meshio reads)."""
    points, cells = _read_triangles(scene.mesh.file)
    return split_box(points, cells, scene.geometry, scene.mesh.degree, origin(scene))


def split_box(points: np.ndarray, cells: np.ndarray, geometry: Geometry, degree: int = 1,
              where: str = "mesh") -> Mesh:
    """The mesh of P1 triangles of the box: split at Σ by the side each cell lies on."""
    points = snap(points, geometry)
    y = points[cells, 1] - geometry.sigma
    crossing = np.any(y < 0, axis=1) & np.any(y > 0, axis=1)
    if crossing.any():
        raise MeshError(f"{where}: {crossing.sum()} triangles cross Σ (y = {geometry.sigma:g}); Σ must be made "
                        "of mesh edges")
    lower = np.any(y < 0, axis=1)
    flat = ~lower & ~np.any(y > 0, axis=1)
    if flat.any():
        raise MeshError(f"{where}: {flat.sum()} degenerate triangles lie on Σ")
    halves = [_box_half(points, cells[lower if side < 0 else ~lower], side, geometry, degree, where)
              for side in (-1, 1)]
    return make_mesh(*halves, where)


def _read_triangles(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Points ``(n, 2)`` and triangles of a mesh file meshio reads; every failure is a MeshError."""
    import meshio

    readable(path, "mesh file", MeshError)
    chatter = io.StringIO()
    try:
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            mesh = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many kinds (even SystemExit): all mean unreadable
        reason = str(exc) if not isinstance(exc, SystemExit) else chatter.getvalue()
        reason = " ".join(reason.split()) or exc.__class__.__name__
        raise MeshError(f"{path}: cannot read mesh ({reason})") from None
    physical = mesh.cell_data.get("gmsh:physical", [None] * len(mesh.cells))
    blocks = [(block.data, tags) for block, tags in zip(mesh.cells, physical) if block.type == "triangle"]
    if not blocks:
        raise MeshError(f"{path}: no triangle cells")
    cells = np.concatenate([data for data, _ in blocks]).astype(np.int64)
    # A MSH 2.2 file lists a triangle once per physical group: one triangle (a repeat in one group stays).
    groups = np.concatenate([np.zeros(len(data)) if tags is None else np.ravel(tags) for data, tags in blocks])
    cells = merge_repeats(cells, groups.astype(np.int64))
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"{path}: points must have 2 or 3 coordinates")
    if not np.all(np.isfinite(points)):
        raise MeshError(f"{path}: non-finite point coordinates")
    if points.shape[1] == 3:
        if np.abs(points[:, 2]).max(initial=0.0) > TOL * max(np.ptp(points[:, :2], axis=0).max(), 1e-300):
            raise MeshError(f"{path}: the mesh is not planar (z != 0)")
        points = points[:, :2]
    if cells.min() < 0 or cells.max() >= len(points):
        raise MeshError(f"{path}: cells refer to missing points")
    return points, cells



