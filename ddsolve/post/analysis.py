"""Numbers about results: error of one result against another, and the constraints' residuals."""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ddsolve.dd.constraints import Constraints, kkt, kkt_tolerance, scale_free_ratio
from ddsolve.dd.interface import Interface, for_mesh, friction_values
from ddsolve.dd.registry import METHODS
from ddsolve.errors import DDSolveError
from ddsolve.fem import assembly, supports
from ddsolve.mesh import element
from ddsolve.mesh.pieces import Piece
from ddsolve.post.result import OnSigma, Result
from ddsolve.problem import materials
from ddsolve.problem import scene as scenes


def elasticities(result: Result) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Block name -> (D, c) of the result's scene: the block's layer's material in its region (see
    :func:`ddsolve.problem.materials.elasticity`)."""
    scene = result.scene
    return {spec.name: assembly.elasticity(scene, spec.layer, spec.region) for spec in result.blocks}


def block_energies(result: Result, difference: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """‖x_b‖²_K per block (of ``result − difference`` when given: fields on the result's nodes, per
    block), with the result's materials."""
    laws = elasticities(result)
    out = []
    for spec in result.blocks:
        half = result.half(spec.name)
        field = result.solution[spec.name]
        if difference is not None:
            field = field - difference[spec.name]
        out.append(assembly.energy(half.points, half.cells, laws[spec.name][0], field))
    return np.array(out)


@dataclass(frozen=True)
class Comparison:
    energy_error: float  # sqrt(Σ‖a_b − b_b‖²) / sqrt(Σ‖b_b‖²), energy norms over the blocks
    max_difference: float  # max nodal |a − b|
    max_displacement: float  # max nodal |b|


def same_meshes(a: Result, b: Result) -> bool:
    """Whether two results are on the same meshes (nodes and cells of both halves)."""
    return all(half_a.points.shape == half_b.points.shape and np.array_equal(half_a.cells, half_b.cells)
               and np.abs(half_a.points - half_b.points).max() <= 1e-12
               for half_a, half_b in ((a.lower, b.lower), (a.upper, b.upper)))


def compare(a: Result, b: Result, names: tuple[str, str] = ("the result", "the reference")) -> Comparison:
    """Error of ``a`` against ``b`` (the reference).  On different meshes (a coarse solution against a
    fine one), ``a`` is first evaluated at ``b``'s nodes with its own shape functions; meshes of
    different domains (a node of one outside the other: see :func:`locate`) are refused, naming the
    results by ``names``; so are results of structures of different layers."""
    return combined(block_errors(a, b, names).values())


def block_errors(a: Result, b: Result, names: tuple[str, str] = ("the result", "the reference")
                 ) -> dict[str, np.ndarray]:
    """Per block of ``b``: (‖b‖²_K, ‖a − b‖²_K, max nodal |b|, max nodal |a − b|), ``a`` evaluated on ``b``'s
    nodes as :func:`compare` does (and refused where it refuses)."""
    if a.blocks != b.blocks:
        raise DDSolveError(f"{names[0]} and {names[1]} are results of different structures ({len(a.scene.layers)} "
                           f"and {len(b.scene.layers)} layers, geometry.layers): compare results of one structure")
    specs = b.blocks
    fields = {s.name: a.solution[s.name] for s in specs}
    if not same_meshes(a, b):
        for (mine, theirs), (me, them) in (((a, b), names), ((b, a), names[::-1])):
            for half, other in ((mine.lower, theirs.lower), (mine.upper, theirs.upper)):
                stray = int(np.count_nonzero(locate(half, other.points)[1]))
                if stray:
                    raise DDSolveError(f"{names[0]} and {names[1]} are results on different domains: {stray} nodes "
                                       f"of {them}'s {other.name} half lie outside {me}'s; compare results of one "
                                       "geometry (geometry.box, geometry.sigma, mesh.file)")
        fields = {s.name: interpolate(a.half(s.name), a.solution[s.name], b.half(s.name).points) for s in specs}
    reference, error = block_energies(b), block_energies(b, difference=fields)
    return {s.name: np.array([reference[k], error[k], np.abs(b.solution[s.name]).max(),
                              np.abs(fields[s.name] - b.solution[s.name]).max()]) for k, s in enumerate(specs)}


def combined(errors) -> Comparison:
    """The :class:`Comparison` of blocks' :func:`block_errors`: the energy norms summed over the blocks."""
    reference, error, largest, difference = np.array(list(errors)).T
    reference, error = reference.sum(), error.sum()
    if reference > 0:
        relative = np.sqrt(error / reference)
    else:  # a zero reference (no load): exact agreement or an infinite relative error
        relative = 0.0 if error == 0 else np.inf
    return Comparison(float(relative), float(difference.max()), float(largest.max()))


def local_traces(result: Result) -> np.ndarray:
    """``(blocks, 2k)``: each block's displacements at the multiplier nodes in their (tangent, normal) frames."""
    frames = result.mesh.sigma.frames[result.multiplier_nodes]
    return np.array([np.einsum("nab,nb->na", frames, result.solution[spec.name][result.interface_nodes(spec.name)])
                     .ravel() for spec in result.blocks])


def multiplier_vector(interface: Interface, multipliers: dict[str, np.ndarray], frames: np.ndarray) -> np.ndarray:
    """The λ of ``interface`` whose :meth:`~ddsolve.dd.interface.Interface.split` (in (x, y)) is ``multipliers``."""
    lam = np.zeros(interface.size)
    rows = interface.slices["mu_c"]
    lam[rows] = multipliers["mu_c"][interface.vertex[rows]]
    if interface.friction:
        rows = interface.slices["mu_t"]
        lam[rows] = multipliers["mu_t"][interface.vertex[rows]]
    for name in (name for name in interface.slices if name not in ("mu_c", "mu_t")):
        rows = interface.slices[name]
        local = np.einsum("nab,nb->na", frames, multipliers[name])
        lam[rows] = local[interface.vertex[rows], interface.component[rows]]
    return lam



def block_residual(system: assembly.BlockSystem, x: np.ndarray, load: np.ndarray) -> float:
    """‖K x − f − E ℓ‖∞ / (‖K‖∞‖x‖∞ + ‖f‖∞ + ‖ℓ‖∞) for a whole block system, its solution ``x`` and
    the interface load ``ℓ`` on its trace (all in the block's frames).  Each term is measured on its own: where
    the interface loads cancel the body loads (a heated plate clamped all round, x ≈ 0), f + E ℓ is round-off."""
    b = system.rhs.copy()
    b[system.trace_dofs] += load
    residual = float(np.abs(assembly.csr_matvec(system, x) - b).max(initial=0.0))
    rows = np.repeat(np.arange(system.size), np.diff(system.indptr))
    norm = float(np.bincount(rows, np.abs(system.data), minlength=system.size).max(initial=0.0))
    terms = [norm * np.abs(x).max(initial=0.0), np.abs(system.rhs).max(initial=0.0), np.abs(load).max(initial=0.0)]
    return scale_free_ratio(residual, float(sum(terms)))


def equilibrium_residuals(result: Result, scene: scenes.Scene, interface: Interface, lam: np.ndarray) -> np.ndarray:
    """:func:`block_residual` of each block of a result, the blocks assembled again."""
    sigma = result.mesh.sigma
    frames = sigma.frames[sigma.multiplier_nodes]
    out = []
    for spec, system, load in zip(interface.blocks, assembly.block_systems(scene, result.mesh), interface.loads(lam)):
        nodes = assembly.trace_nodes(result.mesh.half(spec.side), sigma)
        out.append(block_residual(system, assembly.rotate_vector(result.solution[spec.name].reshape(-1), nodes,
                                                                  frames), load))
    return np.array(out)



def constraints(result: Result, equilibrium: np.ndarray | None = None) -> Constraints:
    """The KKT residuals of a result (:func:`kkt`): the interface conditions from its displacements
    and multipliers, each block's equilibrium from assembling the blocks again (unless given)."""
    scene = result.scene
    interface = for_mesh(result.mesh.sigma, scene.nonpenetration,
                         supports.sigma_supports(scene, result.mesh).fixed, assembly.modulus(scene),
                         assembly.data_displacement(scene, result.mesh.halves, result.mesh.sigma), scene.friction,
                         result.blocks)
    frames = result.mesh.sigma.frames[result.multiplier_nodes]
    lam = multiplier_vector(interface, result.multipliers, frames)
    if equilibrium is None:
        equilibrium = equilibrium_residuals(result, scene, interface, lam)
    p = scene.solver.p if result.method in METHODS else None  # the reference (no contact method) has no bound
    return kkt(interface, local_traces(result), lam, p, equilibrium, largest_displacement(result.solution.values()))


def largest_displacement(fields) -> float:
    """max nodal |u| over the ``(n, 2)`` fields."""
    return max(float(np.hypot(u[:, 0], u[:, 1]).max(initial=0.0)) for u in fields)


def tolerance_of(result: Result) -> float:
    """The tolerance the result's residuals are checked against (see :func:`kkt_tolerance`)."""
    return kkt_tolerance(result.scene.solver if result.method in METHODS else None)


#: A point within this fraction of a boundary edge's length outside a mesh still lies in its domain:
#: the nodes of a fine mesh on a curved line (an arc of Σ) lie just outside a coarse mesh's chords.
ON_BOUNDARY = 0.1


#: Buckets of point location along y at most (keys are x-bucket × this + y-bucket, in int64).
_BUCKET_ROWS = 2 ** 31


def _containing_cells(points: np.ndarray, corners: np.ndarray, queries: np.ndarray, boundary) -> np.ndarray:
    """The cell (straight triangle ``corners``) holding each of ``queries`` (q, 2), −1 for none.

    The cells are sorted into size classes, a class's square buckets twice as large as the one below
    and no smaller than its cells (so a cell lies in at most four of its class's buckets); a point is
    tested, by barycentric coordinates, against the cells of the bucket that holds it in each class.
    Exact on graded meshes too (the cells near a crack tip are small in a small class).  A point that no
    cell holds is outside the domain (even-odd rule on the edges ``boundary()`` gives) or, on a badly
    shaped mesh, found by matplotlib's trapezoid map."""
    cell = np.full(len(queries), -1, dtype=np.int64)
    if not len(queries):
        return cell
    # Only the cells whose bounding box meets the queries' can hold one (the mirror images of a tip's
    # disc, say, cover a part of the half).
    meets = np.ones(len(corners), dtype=bool)
    for axis in range(2):
        a, b, c = (points[corners[:, j], axis] for j in range(3))
        meets &= (np.minimum(np.minimum(a, b), c) <= queries[:, axis].max())
        meets &= (np.maximum(np.maximum(a, b), c) >= queries[:, axis].min())
    near = np.flatnonzero(meets)
    triangles = points[corners[near]]  # (m, 3, 2)
    origin = triangles[:, 0]
    first, second = triangles[:, 1] - origin, triangles[:, 2] - origin
    det = first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]
    low, high = triangles.min(axis=1), triangles.max(axis=1)
    base = np.minimum(queries.min(axis=0), low.min(axis=0, initial=np.inf))  # every coordinate counts from here
    region = float(np.max(np.maximum(queries.max(axis=0), high.max(axis=0, initial=-np.inf)) - base))
    extent = (high - low).max(axis=1)
    size = max(float(extent.min(initial=0.0)), 1e-9 * region, np.finfo(float).tiny)
    level = np.ceil(np.log2(np.maximum(extent, size) / size)).astype(np.int64)
    todo = np.arange(len(queries))
    for c in np.unique(level):
        if not len(todo):
            break
        members, bucket = np.flatnonzero(level == c), size * 2.0 ** c
        lo = np.floor((low[members] - base) / bucket).astype(np.int64)
        span = np.floor((high[members] - base) / bucket).astype(np.int64) - lo  # 0 or 1 (rounding aside)
        keys, owners = [], []
        for dx in range(int(span[:, 0].max()) + 1):
            for dy in range(int(span[:, 1].max()) + 1):
                used = (dx <= span[:, 0]) & (dy <= span[:, 1])
                keys.append((lo[used, 0] + dx) * _BUCKET_ROWS + lo[used, 1] + dy)
                owners.append(members[used])
        keys, owners = np.concatenate(keys), np.concatenate(owners)
        order = np.argsort(keys, kind="stable")
        keys, owners = keys[order], owners[order]
        at = np.floor((queries[todo] - base) / bucket).astype(np.int64)
        key = at[:, 0] * _BUCKET_ROWS + at[:, 1]
        start = np.searchsorted(keys, key, side="left")
        counts = np.searchsorted(keys, key, side="right") - start
        which = np.repeat(np.arange(len(todo)), counts)  # the point (in todo) of each candidate
        candidates = owners[np.arange(len(which)) - np.repeat(np.cumsum(counts) - counts - start, counts)]
        offset = queries[todo[which]] - origin[candidates]
        s = (offset[:, 0] * second[candidates, 1] - offset[:, 1] * second[candidates, 0]) / det[candidates]
        t = (first[candidates, 0] * offset[:, 1] - first[candidates, 1] * offset[:, 0]) / det[candidates]
        slack = -1e-12  # a point on an edge (a mirrored Σ node) belongs to either cell
        inside = (s >= slack) & (t >= slack) & (s + t <= 1.0 - slack)
        found, firsts = np.unique(which[inside], return_index=True)
        cell[todo[found]] = near[candidates[inside][firsts]]
        todo = np.delete(todo, found)
    todo = todo[_in_polygon(queries[todo], points, boundary()[0])] if len(todo) else todo
    if len(todo):  # inside the domain, yet in no cell (by rounding at an edge): a badly shaped mesh
        from matplotlib.tri import Triangulation

        finder = Triangulation(points[:, 0], points[:, 1], corners).get_trifinder()
        cell[todo] = finder(queries[todo, 0], queries[todo, 1])
    return cell


def boundary_edges(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edges ``(e, 2)`` of the triangles ``corners`` that belong to one triangle only (oriented as in
    it) and that triangle ``(e,)``."""
    positions = element.outer_edge_positions(corners)
    return element.cell_edges(corners)[positions], positions // 3


def _in_polygon(queries: np.ndarray, points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Whether each of ``queries`` lies inside the region bounded by ``edges`` (even-odd rule, holes too)."""
    start, end = points[edges[:, 0]], points[edges[:, 1]]
    inside = np.zeros(len(queries), dtype=bool)
    for chunk in np.array_split(np.arange(len(queries)), max(1, len(queries) * len(edges) // 1_000_000)):
        x, y = queries[chunk, 0, None], queries[chunk, 1, None]
        crosses = (start[:, 1] > y) != (end[:, 1] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            at = start[:, 0] + (y - start[:, 1]) * (end[:, 0] - start[:, 0]) / (end[:, 1] - start[:, 1])
        inside[chunk] = np.count_nonzero(crosses & (x < at), axis=1) % 2 == 1
    return inside


def locate(half, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The cell of ``half`` (straight triangles of its corners) holding each of ``points`` (q, 2) --
    for a point just outside it (within ON_BOUNDARY of the nearest boundary edge's length), the cell
    of that edge -- and whether each point lies outside the half's domain."""
    corners = half.corners
    boundary = functools.cache(lambda: boundary_edges(corners))  # made once, and only when a point is missed
    cell, miss = nearest_cells(half.points, corners, points, boundary)
    return cell, miss > ON_BOUNDARY


def nearest_cells(points: np.ndarray, corners: np.ndarray, queries: np.ndarray, boundary, snap=None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The cell of ``corners`` holding each of ``queries`` (q, 2) and 0, or for a point that none holds the
    cell of the nearest of the edges ``snap()`` gives (edges, their cells; default: the cells' outline,
    ``boundary()``) and the point's distance to it over the edge's length (inf without edges)."""
    cell = _containing_cells(points, corners, queries, boundary)
    miss = np.zeros(len(queries))
    missed = np.flatnonzero(cell < 0)
    if len(missed):
        edges, edge_cells = (snap or boundary)()
        miss[missed] = np.inf
        if not len(edges):
            return cell, miss
        start = points[edges[:, 0]]
        along = points[edges[:, 1]] - start
        length = np.hypot(along[:, 0], along[:, 1])
        for chunk in np.array_split(missed, max(1, len(missed) * len(edges) // 1_000_000)):
            offset = queries[chunk, None, :] - start  # (q, e, 2)
            t = np.clip(np.einsum("qed,ed->qe", offset, along) / length ** 2, 0.0, 1.0)
            distance = np.linalg.norm(offset - t[..., None] * along, axis=2)
            nearest = np.argmin(distance, axis=1)
            cell[chunk] = edge_cells[nearest]
            miss[chunk] = distance[np.arange(len(chunk)), nearest] / length[nearest]
    return cell, miss


def owned_values_at(piece: Piece, values: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The field ``values`` (n, c) of ``piece`` at ``points`` (q, 2) from the cells it owns, and how far each
    point is from them (:func:`nearest_cells`, snapped to the half's own boundary edges only).  The pieces of
    a half's ranks together answer as :func:`locate` does: per point, the answer with the smallest miss,
    outside the half beyond ON_BOUNDARY."""
    owned = piece.owned_half
    outline = functools.cache(lambda: boundary_edges(owned.corners))
    n = len(piece.points)

    def snap() -> tuple[np.ndarray, np.ndarray]:
        edges, cells = outline()
        keep = np.isin(element.edge_keys(edges, n), element.edge_keys(piece.outer_edges[:, :2], n))
        return edges[keep], cells[keep]

    cell, miss = nearest_cells(owned.points, owned.corners, points, outline, snap)
    out = np.full((len(points), values.shape[1]), np.nan)
    found = cell >= 0
    out[found] = evaluate(owned, values, cell[found], points[found])
    return out, miss


def owned_box(piece: Piece) -> np.ndarray:
    """``(2, 2)``: the low and high corners of the box where :func:`owned_values_at` may find a point: around
    the piece's owned cells, widened by what a point may lie off them and still be snapped to one."""
    corners = piece.points[piece.owned_cells[:, :3]]
    if not len(corners):
        return np.array([[np.inf, np.inf], [-np.inf, -np.inf]])
    sides = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    margin = ON_BOUNDARY * float(sides.max())
    return np.array([corners.min(axis=(0, 1)) - margin, corners.max(axis=(0, 1)) + margin])


def nearest_answer(count: int, answers: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> np.ndarray | None:
    """Per point of ``count``, the value of the :func:`owned_values_at` answer with the smallest miss
    (``answers``: the points asked, by index, their values and misses); None if a point lies outside the half
    (every miss beyond ON_BOUNDARY, or none asked)."""
    values, miss = np.full((count, 2), np.nan), np.full(count, np.inf)
    for asked, found, missed in answers:
        better = missed < miss[asked]
        values[asked[better]], miss[asked[better]] = found[better], missed[better]
    return None if np.any(miss > ON_BOUNDARY) else values


def interpolate(half, values: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Evaluate the field ``values`` (n, c) of ``half`` at ``points`` (q, 2) inside that half with the
    element's own shape functions (P1, or isoparametric P2: the reference coordinates of a point are
    found by Newton's method from those in the straight triangle of its corners)."""
    cell, outside = locate(half, points)
    if np.any(outside):
        raise DDSolveError(f"{int(np.sum(outside))} points lie outside the {half.name} mesh")
    return evaluate(half, values, cell, points)


def evaluate(half, values: np.ndarray, cell: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The field ``values`` (n, c) of ``half`` at ``points`` (q, 2), each in (or by) its ``cell``."""
    p = half.points[half.corners[cell]]  # (q, 3, 2)
    d1, d2, d = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], points - p[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    xi = np.column_stack([(d[:, 0] * d2[:, 1] - d[:, 1] * d2[:, 0]) / det,
                          (d1[:, 0] * d[:, 1] - d1[:, 1] * d[:, 0]) / det])
    nodes = half.points[half.cells[cell]]  # (q, k, 2)
    k = half.cells.shape[1]
    for _ in range(8 if k == 6 else 0):  # Newton on x(ξ) = points
        shapes, gradients = element.shape_functions(k, xi)
        residual = np.einsum("qk,qkd->qd", shapes, nodes) - points
        jacobian = np.einsum("qkd,qke->qde", nodes, gradients)
        xi = xi - np.linalg.solve(jacobian, residual[..., None])[..., 0]
    shapes, _ = element.shape_functions(k, xi)
    return np.einsum("qk,qkc->qc", shapes, values[half.cells[cell]])


def energy_error(energy: float, exact: float) -> float:
    """Relative energy-norm error sqrt((Π(u_h) − Π(u)) / (−Π(u))) of a conforming solution with total
    potential energy Π(u_h) = ``energy`` against the exact Π(u) = ``exact`` (‖u − u_h‖²_E = 2(Π(u_h) − Π(u))
    for the linear problem, ‖u‖²_E = −2Π(u)); 0 if ``energy`` is below ``exact``."""
    return float(np.sqrt(max(energy - exact, 0.0) / -exact))


@dataclass(frozen=True)
class CellFields:
    """Per-cell fields of one block from each cell's mean strain and ΔT, but the energy density, integrated;
    Voigt order (xx, yy, xy)."""

    strain: np.ndarray  # (m, 3) εxx, εyy, γxy = 2 εxy
    strain_zz: np.ndarray  # (m,) total: 0 in plane strain; from σzz = 0 in plane stress, thermal part included
    # (NaN if the law is not known)
    stress: np.ndarray  # (m, 3) σxx, σyy, σxy
    stress_zz: np.ndarray  # (m,) from the plane model (0 in plane stress)
    von_mises: np.ndarray  # (m,)
    energy_density: np.ndarray  # (m,) strain energy per unit area: ½ ∫ σ:(ε − ε₀) over the cell / its area


def cell_fields(result: Result) -> dict[str, CellFields]:
    """Block name -> its per-cell strains, stresses, von Mises stress and energy density."""
    return {spec.name: block_cell_fields(result.scene, spec.layer, spec.region, result.half(spec.name).points,
                                         result.half(spec.name).cells, result.solution[spec.name])
            for spec in result.blocks}


def block_cell_fields(scene: scenes.Scene, layer: str, region: str, points: np.ndarray, cells: np.ndarray,
                      u: np.ndarray) -> CellFields:
    """The :class:`CellFields` of one block's ``cells`` (a half's, or those a rank owns of it): displacements
    ``u`` ``(n, 2)`` of ``layer`` in ``region`` at ``points``, with that block's material; stresses are
    mechanical, σ = D (ε − ε₀), with the thermal eigenstrain ε₀."""
    material = scene.material(layer, region)
    D, c = assembly.elasticity(scene, layer, region)
    expansion, relieved = materials.thermal_strain(material, scene.model)
    out_of_plane = materials.out_of_plane_strain(material, scene.model)
    volume, strains, change = assembly.quadrature_fields(scene, layer, region, points, cells, u)
    area, strain = assembly.cell_means(volume, strains)
    mean_change = np.einsum("mq,mq->m", volume, change) / area
    eigenstrain = mean_change[:, None] * expansion
    stress, stress_zz = assembly.cell_stresses(D, c, strain - eigenstrain)
    stress_zz = stress_zz + eigenstrain @ c - mean_change * relieved
    strain_zz = (strain @ out_of_plane[0] + out_of_plane[1] * mean_change if out_of_plane is not None
                 else np.full(len(strain), np.nan))
    energy_density = 0.5 * assembly.integrated_energies(volume, strains - change[..., None] * expansion, D) / area
    return CellFields(strain=strain, strain_zz=strain_zz, stress=stress, stress_zz=stress_zz,
                      von_mises=materials.von_mises(stress, stress_zz), energy_density=energy_density)


def layer_stresses(result: Result) -> dict[str, np.ndarray]:
    """Per-cell von Mises stress of each block."""
    return {name: fields.von_mises for name, fields in cell_fields(result).items()}


def normal_jump(result: Result) -> np.ndarray:
    """[u]·ν = (u⁺ − u⁻)·ν of layer 1 at the k multiplier nodes (negative: overlap)."""
    return result.on_sigma.opening


def sigma_is_graph(result: Result | OnSigma) -> bool:
    """Whether Σ is a graph over x (x increases along it): Σ quantities are then plotted against x."""
    sigma = (result.on_sigma if isinstance(result, Result) else result).sigma
    points = sigma.points[sigma.multiplier_nodes]
    return len(points) < 2 or bool(np.all(np.diff(points[:, 0]) > 0))


def along_sigma(result: Result) -> tuple[np.ndarray, str]:
    """The coordinate to plot Σ quantities against: x if Σ is a graph over x, else the arc length."""
    if sigma_is_graph(result):
        return result.interface_points[:, 0], "x on Σ"
    return result.mesh.sigma.arclength[result.multiplier_nodes], "arc length along Σ"


#: Openings within this fraction of max |u| of zero: the crack faces touch (a negative one beyond it: they overlap).
TOUCHING = 1e-9


def contact_zones(result: Result | OnSigma, tolerance: float = TOUCHING) -> list[tuple[int, int]]:
    """Runs ``[first, last]`` of multiplier nodes where the crack faces touch: crack nodes that carry a
    contact pressure μᶜ > 0 (every method leaves it exactly 0 where the faces are apart, the reference
    too) or whose opening [u]·ν is at most ``tolerance`` × max |u| (faces touching without pressure).  An
    iterative method's openings where the faces press are its tolerance, not 0: μᶜ decides there.
    Meaningful with non-penetration only: without it the faces do not touch but pass through each other
    (:func:`overlap_zones`)."""
    on = result.on_sigma if isinstance(result, Result) else result
    pressed = on.multipliers["mu_c"] > 0.0
    touching = on.sigma.crack[on.sigma.multiplier_nodes] & ((on.opening <= tolerance * on.largest) | pressed)
    return on.sigma.pieces(touching)


#: A friction multiplier within this fraction of its bound g slides (its faces slip); below it they stick.
SLIDING = 1e-6
#: :func:`friction_state`'s values: faces apart or without friction, sticking, slipping.
FREE, STICK, SLIP = 0, 1, 2


def friction_state(on: OnSigma, friction: scenes.Friction | None) -> np.ndarray:
    """``(k,)`` per multiplier node: :data:`SLIP` where the crack faces press (μᶜ > 0) and the tangential traction
    μ_t is at its bound g (Tresca's given g, Coulomb's μ μᶜ; within :data:`SLIDING`), :data:`STICK` where they press
    below it, else :data:`FREE` (faces apart, or no friction)."""
    nodes = on.sigma.multiplier_nodes
    state = np.full(len(nodes), FREE, dtype=np.int8)
    if friction is None or "mu_t" not in on.multipliers:
        return state
    pressure = on.multipliers["mu_c"]
    bound = friction_values(on.sigma, friction)[nodes] * (np.maximum(pressure, 0.0) if friction.coulomb else 1.0)
    held = on.sigma.crack[nodes] & (pressure > 0.0) & (bound > 0.0)
    slipping = np.abs(on.multipliers["mu_t"]) >= (1.0 - SLIDING) * bound
    state[held] = np.where(slipping[held], SLIP, STICK)
    return state


def friction_zones(result: Result) -> dict[str, list[tuple[int, int]]]:
    """Runs ``[first, last]`` of multiplier nodes where the crack faces slip and where they stick
    (:func:`friction_state`), by ``"slip"`` and ``"stick"``; both empty without friction."""
    on = result.on_sigma
    state = friction_state(on, result.scene.friction)
    return {"slip": on.sigma.pieces(state == SLIP), "stick": on.sigma.pieces(state == STICK)}


def friction_lines(result: Result) -> list[str]:
    """Where the crack faces slip and where they stick, as arc length along Σ (none without friction)."""
    if result.scene.friction is None:
        return []
    on = result.on_sigma
    arc = on.sigma.arclength[on.sigma.multiplier_nodes]
    return [f"crack faces {kind} ({result.scene.friction.key}; arc length along Σ): "
            + (", ".join(f"[{arc[a]:.4g}, {arc[b]:.4g}]" for a, b in runs) or "nowhere")
            for kind, runs in friction_zones(result).items()]


def overlap_zones(result: Result | OnSigma, tolerance: float = TOUCHING) -> list[tuple[int, int]]:
    """Runs ``[first, last]`` of multiplier nodes where the crack faces overlap: crack nodes whose opening
    [u]·ν is below −``tolerance`` × max |u|.  What a scene without non-penetration has instead of contact."""
    on = result.on_sigma if isinstance(result, Result) else result
    return on.sigma.pieces(on.sigma.crack[on.sigma.multiplier_nodes] & (on.opening < -tolerance * on.largest))
