"""The meshes of a 3-D box (``geometry.box = [x0, x1, y0, y1, z0, z1]``): the two halves below and above the plane
Σ (y = ``sigma``) as P1 tetrahedra, and Σ itself as the triangles both halves share.

gmsh (OpenCASCADE, in a child process: :func:`ddsolve.mesh.gmsh_io.apart`) meshes the two boxes and the crack
rectangles fragmented together, so that the mesh is conforming across Σ and along the cracks' edges: every Σ
vertex is a vertex of both halves (P2: a node in the middle of every edge, the edges straight), the same triangulation of Σ on both sides.  A half (:class:`SolidHalf`) holds
its own numbering of its nodes, its boundary triangles by side, and its node of each Σ vertex; Σ
(:class:`SigmaSurface`) holds its vertices with lumped weights, a normal frame per vertex, the crack vertices
(whose two faces are separate) and the crack front (the cracks' edges inside the box).  Conventions follow
meshio: ``points (n, 3)`` float64, ``tetrahedra (m, 4)`` or ``(m, 10)`` (tetra10: vertices, then the edges
01 12 02 03 13 23) int64 of positive volume, triangles ``(k, 3)`` or ``(k, 6)`` (v0 v1 v2 m01 m12 m20).

A box of several interfaces (``geometry.sigma = [y1, y2, ...]``) is the same one level up: its regions (``region1``
… bottom to top, the boxes between the interfaces) and a :class:`SigmaSurface` per interface, every Σ's vertices
shared by the regions below and above it (:meth:`SolidMesh.border`); :meth:`SolidMesh.interface` views one Σ with
its two regions as a box of one interface, and the two halves of one Σ are the case of two regions.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ddsolve.errors import MeshError
from ddsolve.mesh import solid_files
from ddsolve.mesh.mesh import TOL
from ddsolve.mesh.solid_sizing import SizeField, as_background
from ddsolve.problem.schema import DEPTH_SIDES, REGIONS, SIDES, region_names
from ddsolve.problem.scene import Scene
from ddsolve.problem.shapes import Ellipse

#: The sides of the box as planes: name -> (axis, which end of the box's range on that axis).
SIDE_PLANES = {"left": (0, 0), "right": (0, 1), "bottom": (1, 0), "top": (1, 1), "front": (2, 0), "back": (2, 1)}
#: The faces of a tetrahedron (v0 v1 v2 v3), each as the three vertices opposite one of them.
TETRA_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
#: The edges of a tetrahedron in the order of its mid-edge nodes 4 … 9 (meshio's and VTK's tetra10).
TETRA_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
#: Each node's share of a triangle's area in Σ's lumped weights: P1 (3 nodes) and P2 (6 nodes, HRZ).
LUMPED = {3: np.full(3, 1.0 / 3.0), 6: np.array([3.0, 3.0, 3.0, 16.0, 16.0, 16.0]) / 57.0}


@dataclass(frozen=True, eq=False)
class SolidHalf:
    """One half: ``name`` lower (y < sigma) or upper, or a region of several interfaces (``region1`` … bottom to
    top); its nodes, tetrahedra, boundary triangles by side name (the six sides' parts on it, and its Σ's:
    ``sigma``, or ``sigma1`` … of several interfaces, :func:`sigma_side`), and ``sigma_nodes``: its node of each
    vertex of the Σ it borders (a region between two: the lower Σ's vertices, then the upper's)."""

    name: str
    points: np.ndarray
    tetrahedra: np.ndarray
    faces: dict[str, np.ndarray]
    sigma_nodes: np.ndarray

    @property
    def dofs(self) -> int:
        """Its unknowns: three displacement components per node."""
        return 3 * len(self.points)


@dataclass(frozen=True, eq=False)
class SigmaSurface:
    """Σ: its vertices, triangles, lumped weights (a third of each triangle's area per vertex), the crack
    vertices (``cracked``: their faces are separate; the front's vertices are not among them) and the crack
    front's edges (``front``, pairs of Σ vertices)."""

    points: np.ndarray
    triangles: np.ndarray
    cracked: np.ndarray
    front: np.ndarray

    @cached_property
    def weights(self) -> np.ndarray:
        """The lumped weight of every node: a third of each P1 triangle's area per vertex; on 6-node triangles
        the diagonal of the consistent mass scaled to the area (HRZ: 1/19 per vertex, 16/57 per mid-edge node),
        positive at every node."""
        a, b, c = (self.points[self.triangles[:, k]] for k in range(3))
        areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        shares = LUMPED[self.triangles.shape[1]]
        return np.bincount(self.triangles.ravel(), (areas[:, None] * shares).ravel(), minlength=len(self.points))

    @property
    def frames(self) -> np.ndarray:
        """(s, 3, 3): at every vertex the rows ν (the lower half's outward normal, +y), then the tangents x and z."""
        return np.broadcast_to(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
                               (len(self.points), 3, 3))


@dataclass(frozen=True, eq=False)
class SolidMesh:
    """The regions of a 3-D box, bottom to top, and the interfaces Σ between them, bottom to top: one Σ between
    two halves (lower, upper), or several (``geometry.sigma = [y1, y2, …]``)."""

    regions: tuple[SolidHalf, ...]
    sigmas: tuple[SigmaSurface, ...]

    @property
    def halves(self) -> tuple[SolidHalf, SolidHalf]:
        """The two halves of a box of one Σ (a box of several: :meth:`interface`'s)."""
        self._one("halves")
        return self.regions

    @property
    def sigma(self) -> SigmaSurface:
        """The Σ of a box of one interface (a box of several: :attr:`sigmas`)."""
        self._one("sigma")
        return self.sigmas[0]

    def _one(self, what: str) -> None:
        if len(self.sigmas) != 1:
            raise MeshError(f"a 3-D box of {len(self.sigmas)} interfaces has no single {what}: take its regions "
                            "and sigmas, or one interface's view")

    def border(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Σ number ``k``'s vertices as nodes of the region below it and of the region above it."""
        count = len(self.sigmas[k].points)
        return self.regions[k].sigma_nodes[-count:], self.regions[k + 1].sigma_nodes[:count]

    def interface(self, k: int) -> SolidMesh:
        """Σ number ``k`` with the regions below and above it as a box of one interface (its halves ``lower``
        and ``upper``, their Σ nodes this Σ's; their faces the regions', Σ's named by :func:`sigma_side`); a box
        of one interface is its own."""
        if len(self.sigmas) == 1:
            return self
        halves = tuple(dataclasses.replace(region, name=name, sigma_nodes=nodes)
                       for region, name, nodes in zip(self.regions[k:k + 2], REGIONS, self.border(k)))
        return SolidMesh(halves, (self.sigmas[k],))

    @property
    def degree(self) -> int:
        """1 (4-node tetrahedra) or 2 (10-node)."""
        return 1 if self.regions[0].tetrahedra.shape[1] == 4 else 2

    @property
    def unknowns(self) -> int:
        return sum(region.dofs for region in self.regions)

    @cached_property
    def box(self) -> tuple[float, ...]:
        """The bounds of its nodes (x0, x1, y0, y1, z0, z1): a 3-D gmsh file's body's box (a built-in box's own
        numbers may differ from them in the last bit)."""
        points = np.vstack([region.points for region in self.regions])
        return tuple(float(v) for v in np.column_stack([points.min(axis=0), points.max(axis=0)]).ravel())


def sigma_side(k: int, count: int) -> str:
    """The face name of Σ number ``k`` of ``count`` in its regions: ``sigma`` for one interface, else ``sigma1`` …"""
    return "sigma" if count == 1 else f"sigma{k + 1}"


def build(scene: Scene, sizes: SizeField | None = None) -> SolidMesh:
    """The mesh of a 3-D box scene: gmsh in a child process, then the halves and Σ (:func:`assemble`); with
    ``mesh.extrude`` the plane section's mesh extruded (:mod:`ddsolve.mesh.extrude`); a 3-D gmsh file's
    (:mod:`ddsolve.mesh.solid_files`); with ``sizes``, the box's tetrahedra of those sizes (adaptive re-meshing)."""
    from ddsolve.mesh import extrude, gmsh_io  # both import the plane mesh modules

    geometry = scene.geometry
    if geometry.solid_file:
        return from_surfaces(*solid_files.read(scene, graded_towards), scene.mesh.degree, str(scene.mesh.file),
                             geometry.regions or REGIONS)
    if scene.mesh.extrude is not None:
        points, tetrahedra, upper = extrude.tetrahedra(scene)
        return assemble(points, tetrahedra, upper, geometry.box, geometry.sigma, geometry.cracks, scene.mesh.degree)
    points, tetrahedra, region = gmsh_io.apart(_tetrahedra, geometry.box, geometry.sigmas, geometry.crack_lists,
                                               scene.mesh.size, scene.mesh.grading, sizes)
    return assemble_regions(points, tetrahedra, region, geometry.box, geometry.sigmas, geometry.crack_lists,
                            scene.mesh.degree)


def _tetrahedra(box: tuple[float, ...], heights: tuple[float, ...], crack_lists: tuple[tuple, ...], size: float,
                grading: float | None, sizes: SizeField | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """In gmsh: the boxes between the interfaces Σ (y = ``heights``, bottom to top) and the crack rectangles on
    each (``crack_lists``, one per Σ) fragmented together and meshed with tetrahedra of about ``size`` (graded
    towards the crack fronts with exponent ``grading``, if given; of the ``sizes`` field, at most ``size``, if
    given); the nodes, the tetrahedra and the region (0 the lowest) each lies in."""
    from ddsolve.mesh.gmsh_io import session

    x0, x1, y0, y1, z0, z1 = box
    with session(deterministic=True) as gmsh:
        occ = gmsh.model.occ
        levels = (y0, *heights, y1)
        volumes = [occ.addBox(x0, low, z0, x1 - x0, high - low, z1 - z0) for low, high in zip(levels, levels[1:])]
        rectangles = []
        for sigma, cracks in zip(heights, crack_lists):
            for crack in cracks:  # made in the xy plane, then turned onto Σ: (x, y, 0) -> (x, sigma, y)
                tag = _crack_surface(occ, crack, (x0, x1, z0, z1))
                occ.rotate([(2, tag)], 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, np.pi / 2)
                occ.translate([(2, tag)], 0.0, sigma, 0.0)
                rectangles.append((2, tag))
        occ.fragment([(3, tag) for tag in volumes], rectangles)
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        front = [curve for sigma, cracks in zip(heights, crack_lists) for curve in _front_curves(gmsh, box, sigma,
                                                                                                 cracks)]
        if sizes is not None:
            as_background(gmsh, sizes)
        elif grading is not None and front:
            graded_towards(gmsh, front, size, grading, min(box[1] - box[0], box[3] - box[2]))
        try:
            gmsh.model.mesh.generate(3)
        except Exception as exc:  # gmsh raises a bare Exception with its last error
            raise MeshError(f"gmsh cannot mesh the 3-D box ({' '.join(str(exc).split())}): change mesh.size") from None
        tags, coordinates, _ = gmsh.model.mesh.getNodes()
        index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
        index[tags] = np.arange(len(tags))
        cells, region = [], []
        for _, volume in gmsh.model.getEntities(3):
            _, _, nodes = gmsh.model.mesh.getElements(3, volume)
            cells.append(index[np.asarray(nodes[0], dtype=np.int64)].reshape(-1, 4))
            centre_y = 0.5 * (gmsh.model.getBoundingBox(3, volume)[1] + gmsh.model.getBoundingBox(3, volume)[4])
            region.append(np.full(len(cells[-1]), np.searchsorted(heights, centre_y)))
    return np.asarray(coordinates, dtype=np.float64).reshape(-1, 3), np.concatenate(cells), np.concatenate(region)


def _crack_surface(occ, crack, plane: tuple[float, float, float, float]) -> int:
    """A crack's surface in the xy plane (z of Σ as y): a rectangle, or an ellipse's part inside the box's
    ``plane`` (x0, x1, z0, z1)."""
    if not isinstance(crack, Ellipse):
        a, b, c, d = crack
        return occ.addRectangle(a, c, 0.0, b - a, d - c)
    (x, z), (r1, r2) = crack.center, crack.radii
    disk = occ.addDisk(x, z, 0.0, max(r1, r2), min(r1, r2))  # gmsh takes the major radius first, along x
    if r1 < r2:
        occ.rotate([(2, disk)], x, z, 0.0, 0.0, 0.0, 1.0, np.pi / 2)
    x0, x1, z0, z1 = plane
    inside, _ = occ.intersect([(2, disk)], [(2, occ.addRectangle(x0, z0, 0.0, x1 - x0, z1 - z0))])
    return inside[0][1]


def _front_curves(gmsh, box: tuple[float, ...], sigma: float, cracks: tuple[tuple[float, ...], ...]) -> list[int]:
    """The model's curves along the crack front: on Σ, on a crack rectangle's edge that lies inside the box."""
    x0, x1, _, _, z0, z1 = box
    tolerance = TOL * max(np.ptp(np.reshape(box, (3, 2)), axis=1))
    lines = [(axis, value, crack) for crack in cracks if not isinstance(crack, Ellipse)
             for axis, value, end in ((0, crack[0], x0), (0, crack[1], x1), (2, crack[2], z0), (2, crack[3], z1))
             if abs(value - end) > tolerance]
    ellipses = [crack for crack in cracks if isinstance(crack, Ellipse)]
    found = []
    for _, curve in gmsh.model.getEntities(1):
        if ellipses and _on_ellipse(gmsh, curve, sigma, ellipses, tolerance):
            found.append(curve)
            continue
        low, high = np.reshape(gmsh.model.getBoundingBox(1, curve), (2, 3))
        for axis, value, (a, b, c, d) in lines:
            along = (2 if axis == 0 else 0)
            span = (c, d) if axis == 0 else (a, b)
            if (np.abs([low[1] - sigma, high[1] - sigma, low[axis] - value, high[axis] - value]).max() <= 1e3 * tolerance
                    and low[along] >= span[0] - 1e3 * tolerance and high[along] <= span[1] + 1e3 * tolerance):
                found.append(curve)
                break
    return found


def _on_ellipse(gmsh, curve: int, sigma: float, ellipses: list[Ellipse], tolerance: float) -> bool:
    """Whether the model's ``curve`` runs along one of the ``ellipses`` on Σ (its ends and middle on it)."""
    low, high = gmsh.model.getParametrizationBounds(1, curve)
    at = np.reshape(gmsh.model.getValue(1, curve, [low[0], 0.5 * (low[0] + high[0]), high[0]]), (3, 3))
    return bool(np.abs(at[:, 1] - sigma).max() <= 1e3 * tolerance and any(
        np.abs(crack.level(at[:, 0], at[:, 2]) - 1.0).max() <= 1e3 * tolerance / min(crack.radii)
        for crack in ellipses))


def graded_towards(gmsh, curves: list[int], size: float, mu: float, length: float) -> None:
    """The background size field h(r) = min(H, H ((r + r₀)/R)^(1−μ)) at distance r from the ``curves``
    (the plane grading, :func:`ddsolve.mesh.sizing.graded_size`, about a front instead of a tip)."""
    from ddsolve.mesh.sizing import GRADING_RADIUS, grading_offset

    radius = GRADING_RADIUS * length
    offset = grading_offset(size, mu, length)
    fields = gmsh.model.mesh.field
    distance = fields.add("Distance")
    fields.setNumbers(distance, "CurvesList", curves)
    fields.setNumber(distance, "NumPointsPerCurve", 200)
    graded = fields.add("MathEval")
    fields.setString(graded, "F", f"min({size!r}, {size!r} * ((F{distance} + {offset!r}) / {radius!r})^{1.0 - mu!r})")
    fields.setAsBackgroundMesh(graded)


def assemble(points: np.ndarray, tetrahedra: np.ndarray, upper: np.ndarray, box: tuple[float, ...], sigma: float,
             cracks: tuple[tuple[float, ...], ...], degree: int = 1) -> SolidMesh:
    """The halves and Σ of a conforming tetrahedral mesh of the box (``upper``: which tetrahedra lie above Σ), with
    a node in the middle of every edge for ``degree`` 2."""
    return assemble_regions(points, tetrahedra, np.asarray(upper, dtype=np.int64), box, (sigma,), (cracks,), degree)


def assemble_regions(points: np.ndarray, tetrahedra: np.ndarray, region: np.ndarray, box: tuple[float, ...],
                     heights: tuple[float, ...], crack_lists: tuple[tuple, ...], degree: int = 1) -> SolidMesh:
    """The regions and the interfaces Σ (y = ``heights``, their cracks ``crack_lists``) of a tetrahedral mesh of the
    box conforming across every Σ (``region``: each tetrahedron's, 0 the lowest), with a node in the middle of
    every edge for ``degree`` 2."""
    tolerance = TOL * max(np.ptp(np.reshape(box, (3, 2)), axis=1))
    tetrahedra = _positive(points, tetrahedra)
    points, cells, middle = elevated(points, tetrahedra) if degree == 2 else (points, tetrahedra, None)
    on = [np.flatnonzero(np.abs(points[:, 1] - height) <= tolerance) for height in heights]
    if not all(len(vertices) for vertices in on):
        raise MeshError("the 3-D mesh has no vertex on Σ")
    count = len(heights)
    regions = tuple(_half(name, points, cells[region == k], middle, box,
                          {sigma_side(j, count): (heights[j], on[j]) for j in (k - 1, k) if 0 <= j < count}, tolerance)
                    for k, name in enumerate(region_names(count + 1)))
    sigmas = []
    for k, (vertices, cracks) in enumerate(zip(on, crack_lists)):
        below = regions[k]
        sigma_of = np.full(len(below.points), -1, dtype=np.int64)
        sigma_of[below.sigma_nodes[-len(vertices):]] = np.arange(len(vertices))
        triangles = sigma_of[below.faces[sigma_side(k, count)]]
        cracked, front = _crack_roles(points[vertices], triangles, box, cracks, tolerance)
        sigmas.append(SigmaSurface(points[vertices], triangles, cracked, front))
    return SolidMesh(regions, tuple(sigmas))


def elevated(points: np.ndarray, tetrahedra: np.ndarray):
    """P1 → P2 with straight edges: the points with a node in the middle of every edge appended, the 10-node
    tetrahedra (:data:`TETRA_EDGES` order), and ``middle(a, b)``: the mid-edge nodes of the edges (a, b)."""
    edges = np.sort(tetrahedra[:, TETRA_EDGES].reshape(-1, 2), axis=1)
    keys = edges[:, 0] * len(points) + edges[:, 1]
    unique, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    numbers = len(points) + np.arange(len(unique))

    def middle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return numbers[np.searchsorted(unique, np.minimum(a, b) * len(points) + np.maximum(a, b))]
    middles = 0.5 * (points[edges[first, 0]] + points[edges[first, 1]])
    return (np.vstack([points, middles]), np.column_stack([tetrahedra, numbers[inverse].reshape(-1, 6)]), middle)


def _positive(points: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """The tetrahedra ordered to positive volume (two vertices swapped where negative); degenerate ones refused."""
    volumes = signed_volumes(points, tetrahedra)
    if np.any(np.abs(volumes) <= 1e-14 * np.abs(volumes).max(initial=1.0)):
        raise MeshError("the 3-D mesh has a degenerate tetrahedron: change mesh.size")
    flipped = tetrahedra.copy()
    flipped[volumes < 0] = flipped[volumes < 0][:, [1, 0, 2, 3]]
    return flipped


def signed_volumes(points: np.ndarray, tetrahedra: np.ndarray) -> np.ndarray:
    """Each tetrahedron's volume, negative where its vertices turn the other way."""
    a, b, c, d = (points[tetrahedra[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def _half(name: str, points: np.ndarray, cells: np.ndarray, middle, box: tuple[float, ...],
          borders: dict[str, tuple[float, np.ndarray]], tolerance: float) -> SolidHalf:
    """One region in its own numbering: its nodes, tetrahedra, boundary triangles by side (6-node, v0 v1 v2 m01 m12
    m20, with ``middle``) and Σ nodes (``borders``: the face name, height and vertices of each Σ it borders,
    bottom to top)."""
    used = np.unique(cells)
    local = np.full(len(points), -1, dtype=np.int64)
    local[used] = np.arange(len(used))
    faces = boundary_faces(cells[:, :4])
    if middle is not None:
        faces = np.column_stack([faces, *(middle(faces[:, i], faces[:, (i + 1) % 3]) for i in range(3))])
    centres = points[faces[:, :3]].mean(axis=1)
    planes = {**{side: (axis, box[2 * axis + end]) for side, (axis, end) in SIDE_PLANES.items()},
              **{key: (1, height) for key, (height, _) in borders.items()}}
    named = {side: local[faces[np.abs(centres[:, axis] - value) <= tolerance]] for side, (axis, value) in planes.items()}
    if sum(len(f) for f in named.values()) != len(faces):
        raise MeshError(f"the {name} half of the 3-D mesh has boundary faces off the box's sides and Σ")
    on_sigma = np.concatenate([vertices for _, vertices in borders.values()])
    if np.any(local[on_sigma] < 0):
        raise MeshError(f"the {name} half of the 3-D mesh misses vertices of Σ (the halves do not conform)")
    return SolidHalf(name, points[used], local[cells], named, local[on_sigma])


def boundary_faces(tetrahedra: np.ndarray) -> np.ndarray:
    """The triangles that bound exactly one tetrahedron, oriented outward (with positive tetrahedra)."""
    faces = tetrahedra[:, TETRA_FACES].reshape(-1, 3)
    keys = np.sort(faces, axis=1)
    _, first, counts = np.unique(keys, axis=0, return_index=True, return_counts=True)
    return faces[np.sort(first[counts == 1])]


def _crack_roles(points: np.ndarray, triangles: np.ndarray, box: tuple[float, ...],
                 cracks: tuple[tuple[float, ...], ...], tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """The Σ vertices whose faces are separate (inside a crack's rectangle, off its front), and the front's edges:
    the rectangles' edges inside the box (an edge on the box's side is free, not a front)."""
    x, z = points[:, 0], points[:, 2]
    cracked = np.zeros(len(points), dtype=bool)
    on_front = np.zeros(len(points), dtype=bool)
    edges = np.unique(np.sort(triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1), axis=0)  # vertices
    front = []
    for crack in cracks:
        if isinstance(crack, Ellipse):
            inside, arc, edges_along = _ellipse_roles(crack, x, z, edges, tolerance)
            front.append(edges_along)
            on_front |= arc
            cracked |= inside
            continue
        a, b, c, d = crack
        inside = (x >= a - tolerance) & (x <= b + tolerance) & (z >= c - tolerance) & (z <= d + tolerance)
        lines = [(coordinate, value) for coordinate, value, end in ((x, a, box[0]), (x, b, box[1]), (z, c, box[4]),
                                                                     (z, d, box[5])) if abs(value - end) > tolerance]
        here = np.zeros(len(points), dtype=bool)
        for coordinate, value in lines:
            line = inside & (np.abs(coordinate - value) <= tolerance)
            here |= line
            front.append(edges[line[edges].all(axis=1)])
        on_front |= here
        cracked |= inside
    front = np.concatenate(front) if front else np.zeros((0, 2), dtype=np.int64)
    on_front[_middles_of(triangles, front)] = True  # P2: a curved front's chords keep their middles glued
    return cracked & ~on_front, front


def _middles_of(triangles: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The mid-edge nodes of the vertex pairs ``edges`` in 6-node ``triangles`` (v0 v1 v2 m01 m12 m20); none for
    3-node ones."""
    if triangles.shape[1] != 6 or not len(edges):
        return np.zeros(0, dtype=np.int64)
    pairs = np.sort(triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    size = int(triangles.max()) + 1
    keys, first = np.unique(pairs[:, 0] * size + pairs[:, 1], return_index=True)
    wanted = np.sort(edges, axis=1)
    return triangles[:, 3:].reshape(-1)[first[np.searchsorted(keys, wanted[:, 0] * size + wanted[:, 1])]]


def _ellipse_roles(crack: Ellipse, x: np.ndarray, z: np.ndarray, edges: np.ndarray, tolerance: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An ellipse's Σ vertices inside it or on it, those on its front, and the front's edges: consecutive front
    vertices by their angle about the centre (the arc's mesh edges, never a chord)."""
    scaled = tolerance / min(crack.radii)
    level = crack.level(x, z)
    arc = np.abs(level - 1.0) <= 2.0 * scaled + 1e-9
    order = np.flatnonzero(arc)
    angles = np.arctan2((z[order] - crack.center[1]) / crack.radii[1], (x[order] - crack.center[0]) / crack.radii[0])
    order = order[np.argsort(angles)]
    pairs = np.sort(np.column_stack([order, np.roll(order, -1)]), axis=1)
    keys = edges[:, 0] * (len(x) + 1) + edges[:, 1]
    along = pairs[np.isin(pairs[:, 0] * (len(x) + 1) + pairs[:, 1], keys)]
    return level <= 1.0 + 2.0 * scaled + 1e-9, arc, along


def from_surfaces(points: np.ndarray, tetrahedra: np.ndarray, region: np.ndarray, surfaces: dict[str, np.ndarray],
                  degree: int, where: str, names: tuple[str, ...] = REGIONS) -> SolidMesh:
    """The regions and the interfaces Σ of a 3-D gmsh file's tetrahedra (``region``: the volume of ``names``,
    bottom to top, each lies in) and its named surfaces' triangles (:func:`ddsolve.mesh.solid_files.read`, checked
    there): each region's faces by the surface they lie on, each Σ its surface (``sigma``, or ``sigma1`` …), its
    crack vertices and front from its crack surface (:func:`ddsolve.mesh.solid_files.crack_roles`); P2 with
    ``degree`` 2."""
    tetrahedra = _positive(points, tetrahedra)
    points, cells, middle = elevated(points, tetrahedra) if degree == 2 else (points, tetrahedra, None)
    interfaces = solid_files.interface_names(len(names) - 1)
    cracks = {crack for _, crack in interfaces}
    named = {name: _with_middles(triangles, middle) for name, triangles in surfaces.items() if name not in cracks}
    on = [np.unique(named[sigma]) for sigma, _ in interfaces]
    regions, boundaries = [], []
    for k, name in enumerate(names):
        boundaries.append(_with_middles(boundary_faces(cells[region == k][:, :4]), middle))
        borders = [(interfaces[j][0], on[j]) for j in (k - 1, k) if 0 <= j < len(interfaces)]
        regions.append(_named_half(name, points, cells[region == k], boundaries[-1], named, borders, where))
    sigmas = []
    for k, ((sigma, crack), vertices) in enumerate(zip(interfaces, on)):
        if np.sum(solid_files.members(boundaries[k + 1], boundaries[k])) != len(named[sigma]):
            raise MeshError(f"{where}: the volumes {names[k]} and {names[k + 1]} touch off {sigma} (faces they share "
                            f"are not {sigma}'s): Σ must be all of their common boundary")
        sigma_of = np.full(len(points), -1, dtype=np.int64)
        sigma_of[vertices] = np.arange(len(vertices))
        faces = boundaries[k][solid_files.members(boundaries[k], named[sigma])]  # the region below's: ν = +y
        in_crack = solid_files.members(faces, surfaces.get(crack, np.zeros((0, 3), dtype=np.int64)))
        cracked, front = solid_files.crack_roles(sigma_of[faces], in_crack)
        sigmas.append(SigmaSurface(points[vertices], sigma_of[faces], cracked, front))
    return SolidMesh(tuple(regions), tuple(sigmas))


def _with_middles(triangles: np.ndarray, middle) -> np.ndarray:
    """The triangles with their mid-edge nodes (v0 v1 v2 m01 m12 m20) where ``middle`` gives them (P2)."""
    if middle is None:
        return triangles
    return np.column_stack([triangles, *(middle(triangles[:, a], triangles[:, (a + 1) % 3]) for a in range(3))])


def _named_half(name: str, points: np.ndarray, cells: np.ndarray, faces: np.ndarray, named: dict[str, np.ndarray],
                borders: list[tuple[str, np.ndarray]], where: str) -> SolidHalf:
    """One region of a file in its own numbering: its nodes, tetrahedra, its boundary ``faces`` (outward) on each
    named surface and its Σ nodes (``borders``: each Σ it borders, bottom to top, and its vertices); it must border
    all of each."""
    used = np.unique(cells)
    local = np.full(len(points), -1, dtype=np.int64)
    local[used] = np.arange(len(used))
    mine = {surface: faces[solid_files.members(faces, triangles)] for surface, triangles in named.items()}
    for sigma, _ in borders:
        missing = len(named[sigma]) - len(mine[sigma])
        if missing:
            raise MeshError(f"{where}: physical surface {sigma} is not all on the volume {name}'s boundary ({missing} "
                            f"of its {len(named[sigma])} triangles are not): Σ lies between the volumes below and "
                            "above it, their meshes conforming on it")
    on_sigma = np.concatenate([vertices for _, vertices in borders])
    return SolidHalf(name, points[used], local[cells], {surface: local[f] for surface, f in mine.items()},
                     local[on_sigma])
