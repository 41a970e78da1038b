"""A 3-D gmsh file (``mesh.file``: a ``.geo`` meshed here, or a ``.msh`` in MSH 2.2 or 4.1) read and checked, and
the crack roles of its Σ: :func:`ddsolve.mesh.solid.from_surfaces` makes of it the
:class:`~ddsolve.mesh.solid.SolidMesh` a 3-D box makes, so that the reference, the decomposition, G along the
fronts and the outputs take it unchanged.

The contract is the plane one a dimension up: the physical volumes ``lower`` and ``upper`` (4-node tetrahedra;
``mesh.degree = 2`` puts a node in the middle of every edge, the edges straight), the physical surface ``sigma``
between them (the plane y = const, for now), ``crack`` (its part where the faces are separate, optional) and any
other named surface a boundary for loads and supports (``clamped``: fixed).  Each half takes its own copy of
Σ's nodes, so the crack's faces are apart; the crack front is the crack's boundary edges inside the body (those
not on Σ's own boundary, where Σ meets the body's surface).  A file of several interfaces names them ``sigma1``,
``sigma2`` … bottom to top (their cracks ``crack1`` …) and has a volume per region, any names, bottom to top
(:func:`ddsolve.problem.reading.file_structure`): it is read as the box of several interfaces is built.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from ddsolve.errors import MeshError
from ddsolve.mesh.mesh import CRACK, SIGMA, TOL
from ddsolve.mesh.sizing import node_positions
from ddsolve.problem.schema import REGIONS
from ddsolve.problem.scene import Scene

#: gmsh element types: 3- and 6-node triangles, 4- and 10-node tetrahedra.
TRIANGLES, TETRAHEDRA = (2, 9), (4, 11)
#: The edges of a triangle (v0 v1 v2) in the order of its mid-edge nodes 3, 4, 5 (m01 m12 m20).
TRIANGLE_EDGES = np.array([[0, 1], [1, 2], [2, 0]])


#: ``grade(gmsh, curves, size, mu, length)``: a background size field graded towards the model's ``curves``
#: (:func:`ddsolve.mesh.solid.build` gives the box's).
Grading = Callable[[object, list[int], float, float, float], None]


def read(scene: Scene, grade: Grading) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """The scene's 3-D gmsh file meshed (.geo, with ``mesh.size`` as the largest element, graded by ``grade``
    towards the crack fronts with ``mesh.grading``) or read (.msh) by gmsh in a child process, and checked
    (:func:`checked`): its nodes, its tetrahedra, the region each lies in (0 the lowest: ``lower``, or the first of
    the file's regions of several interfaces) and the triangles of every named physical surface."""
    from ddsolve.mesh.gmsh_io import apart

    path, options = scene.mesh.file, scene.mesh
    names = scene.geometry.regions or REGIONS
    sizes = (options.size, options.grading, grade) if options.kind == "geo" else None
    points, tetrahedra, region, surfaces = apart(_read, path, sizes, names)
    checked(points, tetrahedra, region, surfaces, names, str(path))
    return points, tetrahedra, region, surfaces


def interface_names(count: int) -> list[tuple[str, str]]:
    """The physical surfaces of each of ``count`` interfaces, bottom to top: (Σ, its cracks): ``sigma`` and
    ``crack`` for one, ``sigma1`` and ``crack1`` … for several."""
    return [(SIGMA, CRACK)] if count == 1 else [(f"{SIGMA}{k}", f"{CRACK}{k}") for k in range(1, count + 1)]


def _read(path: Path, sizes: tuple[float | None, float | None, Grading] | None, names: tuple[str, ...]
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """In gmsh: the file opened (a .geo meshed in 3-D with ``sizes``: :func:`_meshed`), its nodes, the tetrahedra of
    the volumes ``names`` (bottom to top), the region each lies in, and the triangles (vertices) of every named
    physical surface."""
    from ddsolve.mesh.gmsh_io import open_file, session

    where = str(path)
    with session() as gmsh:
        for name in ("General.NumThreads", "Mesh.MaxNumThreads2D", "Mesh.MaxNumThreads3D"):
            gmsh.option.setNumber(name, 1)  # the same mesh on every rank
        open_file(gmsh, path)
        groups: dict[tuple[int, str], list[int]] = {}
        for dim, tag in gmsh.model.getPhysicalGroups():
            groups.setdefault((dim, gmsh.model.getPhysicalName(dim, tag)), []).extend(
                int(entity) for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag))
        if sizes is not None:
            _meshed(gmsh, groups, *sizes, len(names) - 1, where)
        tags, coordinates, _ = gmsh.model.mesh.getNodes()
        position = node_positions(tags)
        cells = [_elements(gmsh, groups.get((3, name), []), 3, position, where) for name in names]
        surfaces = {name: _elements(gmsh, entities, 2, position, where) for (dim, name), entities in groups.items()
                    if dim == 2 and name}
    points = np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)
    region = np.repeat(np.arange(len(cells)), [len(c) for c in cells])
    return points, np.concatenate(cells), region, surfaces


def _meshed(gmsh, groups: dict[tuple[int, str], list[int]], size: float | None, grading: float | None,
            grade: Grading, interfaces: int, where: str) -> None:
    """The .geo meshed in 3-D: elements of at most ``size``, graded towards the crack fronts (the curves bounding
    an interface's crack surface but not the interface's own) with exponent ``grading`` by ``grade``."""
    if size is not None:
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    if grading is not None:
        def bounding(name: str) -> set[int]:
            entities = [(2, entity) for entity in groups.get((2, name), [])]
            return {abs(tag) for _, tag in gmsh.model.getBoundary(entities, combined=True, oriented=False)} \
                if entities else set()
        front = sorted(set().union(*(bounding(crack) - bounding(sigma) for sigma, crack in
                                     interface_names(interfaces))))
        corners = np.array([gmsh.model.getValue(0, tag, []) for _, tag in gmsh.model.getEntities(0)])
        extent = np.ptp(corners, axis=0)  # the span of its points (OpenCASCADE's bounding boxes are padded)
        if front:
            grade(gmsh, front, size, grading, float(min(extent[0], extent[1])))
    try:
        gmsh.model.mesh.generate(3)
    except Exception as exc:  # gmsh raises a bare Exception with its last error
        raise MeshError(f"{where}: gmsh cannot mesh it ({' '.join(str(exc).split())})") from None


def _elements(gmsh, entities: list[int], dim: int, position: np.ndarray, where: str) -> np.ndarray:
    """The vertices of the tetrahedra (``dim`` 3) or triangles (2) of the model's ``entities``, each element once
    (a MSH 2.2 file lists an element once per physical group); a 10-node tetrahedron or another element in a
    volume is refused."""
    linear, quadratic = TETRAHEDRA if dim == 3 else TRIANGLES
    corners = dim + 1
    found = [np.zeros((0, corners), dtype=np.int64)]
    for entity in dict.fromkeys(entities):
        for kind, nodes in zip(*gmsh.model.mesh.getElements(dim, entity)[::2]):
            if kind == linear or kind == quadratic and dim == 2:
                width = corners if kind == linear else 6
                found.append(np.asarray(nodes, dtype=np.int64).reshape(-1, width)[:, :corners])
            else:
                raise MeshError(f"{where}: " + (
                    f"the volumes must hold 4-node tetrahedra only (found gmsh element type {kind}): give the file's "
                    "P1 tetrahedra, and mesh.degree = 2 for P2" if dim == 3 else
                    f"the physical surfaces must hold triangles only (found gmsh element type {kind})"))
    elements = position[np.concatenate(found)]
    _, first = np.unique(np.sort(elements, axis=1), axis=0, return_index=True)
    return elements[np.sort(first)]


def checked(points: np.ndarray, tetrahedra: np.ndarray, region: np.ndarray, surfaces: dict[str, np.ndarray],
            names: tuple[str, ...], where: str) -> None:
    """A file's volumes (``names``, bottom to top; ``region``: each tetrahedron's) and surfaces as a 3-D body cut by
    its interfaces: each Σ (``sigma``, or ``sigma1`` …) a plane y = const, above the one before it, each volume
    between the interfaces below and above it, each crack on its Σ."""
    empty = next((name for k, name in enumerate(names) if not np.any(region == k)), None)
    if empty is not None:
        raise MeshError(f"{where}: physical volume {empty} has no tetrahedra")
    tolerance = TOL * float(np.ptp(points[np.unique(tetrahedra)], axis=0).max())
    interfaces = interface_names(len(names) - 1)
    heights = [_height(points, surfaces, sigma, tolerance, where) for sigma, _ in interfaces]
    for (lower, _), (upper, _), below, above in zip(interfaces, interfaces[1:], heights, heights[1:]):
        if above <= below + tolerance:
            raise MeshError(f"{where}: physical surfaces {lower} (y = {below:g}) and {upper} (y = {above:g}) "
                            + ("cross or touch" if abs(above - below) <= tolerance else "are not bottom to top")
                            + ": number the interfaces sigma1, sigma2, ... bottom to top, apart")
    levels = (-np.inf, *heights, np.inf)
    for k, name in enumerate(names):
        y = points[tetrahedra[region == k], 1]
        if y.min() < levels[k] - tolerance or y.max() > levels[k + 1] + tolerance:
            raise MeshError(f"{where}: " + (
                f"the volume lower must lie below sigma (y = {heights[0]:g}) and upper above it" if len(names) == 2
                else f"physical volume {name} does not lie between its interfaces (region {k + 1} from the bottom: "
                f"{_between(interfaces, k)}): list the volumes bottom to top, each between its interfaces"))
    for (sigma, crack), height in zip(interfaces, heights):
        triangles = surfaces.get(crack, np.zeros((0, 3), dtype=np.int64))
        off = int(np.sum(~members(triangles, surfaces[sigma])))
        if off:
            raise MeshError(f"{where}: physical surface {crack} does not lie on {sigma} ({off} of its "
                            f"{len(triangles)} triangles are not {sigma}'s): the cracks are parts of Σ "
                            f"(y = {height:g})")


def _between(interfaces: list[tuple[str, str]], k: int) -> str:
    """Which interfaces bound region ``k`` (0 the lowest) of a file of several, in words."""
    sides = [f"above {interfaces[k - 1][0]}"] * (k > 0) + [f"below {interfaces[k][0]}"] * (k < len(interfaces))
    return " and ".join(sides)


def _height(points: np.ndarray, surfaces: dict[str, np.ndarray], sigma: str, tolerance: float, where: str) -> float:
    """The height of the file's interface ``sigma``: the plane y = const."""
    if not len(surfaces.get(sigma, ())):
        raise MeshError(f"{where}: physical surface {sigma} has no triangles")
    y = points[np.unique(surfaces[sigma]), 1]
    if np.ptp(y) > tolerance:
        raise MeshError(f"{where}: physical surface {sigma} is not a plane y = const (its y from {y.min():g} to "
                        f"{y.max():g}): a curved or tilted Σ is not solved in 3-D yet")
    height = float(np.mean(y))
    return 0.0 if abs(height) <= tolerance else height  # gmsh's rotated planes: y within round-off of 0


def members(triangles: np.ndarray, among: np.ndarray) -> np.ndarray:
    """Whether each of ``triangles`` is one of ``among``: the same three vertices (the first three columns), in
    any order."""
    keys = [np.sort(t[:, :3], axis=1) for t in (among, triangles)]
    numbers = np.unique(np.vstack(keys), axis=0, return_inverse=True)[1].ravel()
    return np.isin(numbers[len(keys[0]):], numbers[:len(keys[0])])


def crack_roles(triangles: np.ndarray, in_crack: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """From Σ's triangles (3 or 6 nodes) and which are the crack's: the nodes whose faces are separate (the crack's
    nodes off its front) and the front's edges (pairs of vertices): the crack's boundary edges that are not on Σ's
    boundary (where Σ meets the body's surface the crack's edge is free, not a front)."""
    count = int(triangles.max(initial=-1)) + 1
    crack = triangles[in_crack]
    edges = np.sort(crack[:, :3][:, TRIANGLE_EDGES], axis=2)  # (c, 3, 2): each crack triangle's edges
    keys = edges[..., 0] * count + edges[..., 1]
    sigma_keys = np.sort(triangles[:, :3][:, TRIANGLE_EDGES], axis=2) @ np.array([count, 1])
    crack_unique, crack_counts = np.unique(keys, return_counts=True)
    sigma_unique, sigma_counts = np.unique(sigma_keys, return_counts=True)
    front_keys = np.setdiff1d(crack_unique[crack_counts == 1], sigma_unique[sigma_counts == 1])
    on_front = np.isin(keys, front_keys)  # (c, 3): the crack triangles' edges on the front
    front_nodes = edges[on_front].ravel()
    if crack.shape[1] == 6:
        front_nodes = np.concatenate([front_nodes, crack[:, 3:][on_front]])
    cracked = np.zeros(count, dtype=bool)
    cracked[crack.ravel()] = True
    cracked[front_nodes] = False
    front = np.column_stack([front_keys // count, front_keys % count])
    return cracked, front
