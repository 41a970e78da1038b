"""Rules between the keys of a 3-D scene (``geometry.box = [x0, x1, y0, y1, z0, z1]``), checked after each key
alone: one body (``layer1``, its regions ``lower`` and ``upper`` below and above the plane Σ y = ``sigma``; or
``region1`` … between several interfaces, ``sigma = [y1, y2, ...]`` with one crack list per interface),
cracks on Σ as rectangles or ellipses, the box meshed with ``mesh.size``, isotropic or transversely isotropic materials,
temperature changes, loads and supports on the box's six sides; or a 3-D gmsh file's body (its volumes the regions,
its surfaces Σ, the cracks and the boundaries).  What the plane scenes have and 3-D does not yet is refused in one
line naming the key."""
from __future__ import annotations

import numpy as np

from ddsolve.errors import SceneError
from ddsolve.problem import materials
from ddsolve.problem.reading import NUMBERED_CRACK, NUMBERED_SIGMA, FileStructure, printable
from ddsolve.problem.rules import check_apart, crack_lists, solver_checks
from ddsolve.problem.shapes import Ellipse, bounds
from ddsolve.problem.schema import ADAPTIVE_DEGREE, DEPTH_SIDES, GRADING, REGIONS, SIDES, STRUCTURE_KEYS, layer_material

#: The boundaries a 3-D box names (loads and supports act on them).
SOLID_SIDES = SIDES + DEPTH_SIDES
#: The mesh keys a 3-D box takes: tetrahedra of about ``mesh.size`` (P1 or P2), graded towards the crack fronts,
#: or the plane mesh of the section extruded in ``mesh.extrude`` layers; or meshed again to ``mesh.target_error``.
SOLID_MESH_KEYS = ("size", "degree", "grading", "extrude", "target_error")
#: The mesh keys a 3-D gmsh file takes: the file, a .geo's largest element size and its grading, the degree.
SOLID_FILE_MESH_KEYS = ("file", "size", "degree", "grading")
#: A 3-D gmsh file's physical surfaces of fixed meaning: Σ (the plane y = const between the volumes lower and
#: upper), the cracks on it, and the clamped boundary.
SIGMA, CRACK, CLAMPED = "sigma", "crack", "clamped"
#: Elements per shortest side of the box when the scene gives no ``mesh.size``.
DEFAULT_ELEMENTS = 4
#: The fracture keys a 3-D box takes: θ's radii about the crack fronts (:mod:`ddsolve.post.front`).
FRONT_KEYS = ("inner", "outer")
#: Keys of the plane scenes that 3-D does not solve yet: (section, key) -> what they would need.
NOT_YET = {("interface", None): "a bond law on Σ is not solved in 3-D yet",
           ("contact", "friction"): "friction is not solved in 3-D yet",
           ("contact", "slip_bound"): "friction is not solved in 3-D yet"}


def solid_checks(data: dict, raw: dict, origin: str, groups: dict[int, list[str]] | None = None,
                 where: str = "", structure: FileStructure | None = None) -> None:
    """The rules of a 3-D scene; fills in Σ's height (the box's middle), the cracks as rectangles
    ``(a, b, c, d)`` (an interval [a, b] spans the depth), the interfaces above the first (``above``, as in the plane)
    and the mesh size.  ``groups``: a 3-D gmsh file's physical names by dimension (``where`` names the file), which
    give the body instead of the box; ``structure``: such a file's interfaces and regions when it has several
    (:func:`ddsolve.problem.reading.file_structure`)."""
    _refuse_plane_only(data, raw, origin, groups is not None)
    if groups is not None:
        _file_checks(data, raw, groups, where, structure)
        if structure is not None:
            _several_interfaces(data, raw, origin)
        _material_checks(data, origin)
        _boundary_checks(data, origin, _file_surfaces(groups))
        solver_checks(data, origin)
        return
    geometry = data["geometry"]
    x0, x1, y0, y1, z0, z1 = geometry["box"]
    heights = geometry["sigma"] if isinstance(geometry["sigma"], tuple) else (
        (0.5 * (y0 + y1),) if geometry["sigma"] is None else (geometry["sigma"],))
    outside = next((y for y in heights if not y0 < y < y1), None)
    if outside is not None:
        raise SceneError(f"{origin}: geometry.sigma = {outside:g} must lie strictly between the box's y0 = {y0:g} "
                         f"and y1 = {y1:g}")
    given = set(raw.get("geometry") or {})
    key = "geometry.crack" if geometry["crack"] is not None else "geometry.cracks"
    written = [[geometry["crack"]] if geometry["crack"] else []] if "crack" in given and len(heights) == 1 else \
        crack_lists(geometry, given, len(heights), origin)
    lists = [[piece if isinstance(piece, Ellipse) or len(piece) == 4 else (*piece, z0, z1) for piece in pieces]
             for pieces in written]
    for cracks in lists:
        _interface_checks(cracks, geometry["box"], data["mesh"], key, origin)
    check_apart([y0, *heights, y1], geometry["box"][:4], "geometry.sigma", "of the box's y range (interfaces, "
                "sides)" if len(heights) > 1 else "of the box's y range", "move Σ", origin)
    if len(heights) > 1:
        _several_interfaces(data, raw, origin)
    geometry.update(sigma=heights[0], cracks=lists[0], above=list(zip(heights[1:], lists[1:])), layers=1)
    del geometry["crack"]
    if data["mesh"]["size"] is None:
        data["mesh"]["size"] = min(x1 - x0, y1 - y0, z1 - z0) / DEFAULT_ELEMENTS
    _material_checks(data, origin)
    _boundary_checks(data, origin, SOLID_SIDES)
    solver_checks(data, origin)


def _interface_checks(cracks: list, box: tuple[float, ...], mesh: dict, key: str, origin: str) -> None:
    """One interface's cracks: each on its Σ (:func:`_check_on_sigma`), spanning the depth where ``mesh.extrude``
    extrudes a section, their edges apart from each other and from the box's ends along x and z."""
    x0, x1, _, _, z0, z1 = box
    for crack in cracks:
        _check_on_sigma(crack, box, key, origin)
        if mesh["extrude"] is not None and not (isinstance(crack, tuple) and crack[2:] == (z0, z1)):
            raise SceneError(f"{origin}: {key}: a crack that does not span the depth (a rectangle or an ellipse) is "
                             "not extruded, and mesh.extrude extrudes a plane section: give cracks [a, b], or leave "
                             "mesh.extrude out")
    edges = [bounds(crack) for crack in cracks]  # an ellipse's extremes beyond the box are no edges
    check_apart([x0, x1, *(v for edge in edges for v in edge[:2] if x0 < v < x1)], box[:4], key, "of Σ along x "
                "(crack edges, box ends)", "move or resize the crack", origin)
    check_apart([z0, z1, *(v for edge in edges for v in edge[2:] if z0 < v < z1)], box[:4], key, "of Σ along z "
                "(crack edges, box ends)", "move or resize the crack", origin)


def _several_interfaces(data: dict, raw: dict, origin: str) -> None:
    """A 3-D box of several interfaces is meshed by gmsh with mesh.size (mesh.grading, mesh.degree): no extruded
    section, no adaptive re-meshing; its decomposition's blocks are its regions (``solver.pieces`` = 1 or auto)."""
    written = raw.get("mesh", {}) if isinstance(raw.get("mesh"), dict) else {}
    other = next((name for name in ("extrude", "target_error") if name in written), None)
    if other is not None:
        raise SceneError(f"{origin}: mesh.{other}: a 3-D box of several interfaces (geometry.sigma a list) is meshed "
                         "by gmsh with mesh.size, mesh.grading and mesh.degree only, for now")
    if data["solver"]["pieces"] not in ("auto", 1):
        raise SceneError(f"{origin}: solver.pieces = {data['solver']['pieces']}: a 3-D box of several interfaces "
                         "is decomposed into its regions (one block each), not into slabs: solver.pieces = 1 or auto")


def _file_checks(data: dict, raw: dict, groups: dict[int, list[str]], where: str,
                 structure: FileStructure | None) -> None:
    """A 3-D gmsh file's groups: the volumes ``lower`` and ``upper`` and the surface ``sigma``, or (``structure``)
    the surfaces ``sigma1`` … and a volume per region; no box keys beside them.  Fills in the geometry a file gives:
    its ``clamped`` surface, if any, and its regions (Σ's heights and the cracks come with the mesh)."""
    given = [key for key in (raw.get("geometry") or {}) if key not in STRUCTURE_KEYS]
    if given:
        raise SceneError(f"{where}: geometry.{given[0]}: the file is a 3-D geometry (physical volumes), whose groups "
                         f"define the body, its Σ and its cracks: leave geometry.{given[0]} out")
    volumes, surfaces = groups[3], groups.get(2, [])
    if structure is None:
        _one_interface_groups(volumes, surfaces, where)
    data["geometry"].update(clamped=[CLAMPED] if CLAMPED in surfaces else [], sigma=0.0, cracks=[], layers=1,
                            above=[(0.0, [])] * (structure.interfaces - 1 if structure else 0),
                            regions=structure.regions if structure else (), solid_file=True)  # placeholders
    del data["geometry"]["crack"]


def _one_interface_groups(volumes: list[str], surfaces: list[str], where: str) -> None:
    """A 3-D file of one interface has the volumes lower and upper and the surface sigma."""
    other = next((name for name in volumes if name not in REGIONS), None)
    if other is not None:
        raise SceneError(f"{where}: physical volume {printable(other)!r}: a 3-D file's volumes are lower and upper "
                         "(below and above the surface sigma), or with several interfaces (surfaces sigma1, sigma2, "
                         "... bottom to top) one volume per region")
    missing = next((name for name in (*REGIONS, SIGMA) if name not in (volumes if name in REGIONS else surfaces)),
                   None)
    if missing is not None:
        kind = "volume" if missing in REGIONS else "surface"
        raise SceneError(f"{where}: missing physical {kind} {missing!r} (a 3-D file needs the volumes lower and "
                         "upper and the surface sigma, the plane y = const between them; optional surfaces: crack, "
                         "clamped and names for loads and displacements)")


def _file_surfaces(groups: dict[int, list[str]]) -> tuple[str, ...]:
    """The boundaries a 3-D file names (its physical surfaces but Σ and the cracks): loads and supports act on them."""
    return tuple(name for name in groups.get(2, []) if name not in (SIGMA, CRACK)
                 and not NUMBERED_SIGMA.fullmatch(name) and not NUMBERED_CRACK.fullmatch(name))


def _refuse_plane_only(data: dict, raw: dict, origin: str, file: bool = False) -> None:
    """The keys a 3-D scene does not take (yet), each refused naming it (``file``: a 3-D gmsh file's scene)."""
    written = raw.get("mesh", {}) if isinstance(raw.get("mesh"), dict) else {}
    if "file" in written and not file:
        raise SceneError(f"{origin}: geometry.box: a 3-D box (6 numbers) is meshed by ddsolve, and mesh.file "
                         f"{printable(str(written['file']))} is plane (no physical volumes): give a 4-number box "
                         "with a plane mesh file, a 3-D gmsh file without geometry.box, or leave mesh.file out")
    keys = SOLID_FILE_MESH_KEYS if file else SOLID_MESH_KEYS
    other = next((name for name in written if name not in keys), None)
    if other is not None:
        raise SceneError(f"{origin}: mesh.{other}: a 3-D " + (
            "gmsh file is meshed (.geo) or read (.msh) with mesh.file, mesh.size, mesh.degree and mesh.grading only, "
            "for now"
            if file else "box is meshed with tetrahedra of about mesh.size (mesh.size, mesh.grading, mesh.degree, "
            "mesh.extrude and mesh.target_error only, for now)"))
    if data["mesh"]["target_error"] is not None:
        _adaptive_defaults(data["mesh"], written, origin)
    grading = data["mesh"]["grading"]
    data["mesh"]["grading"] = GRADING[data["mesh"]["degree"]] if grading is True else (None if grading is False else grading)
    if file and data["mesh"]["grading"] is not None and not (data["mesh"]["size"] and
                                                             str(data["mesh"]["file"]).lower().endswith(".geo")):
        raise SceneError(f"{origin}: mesh.grading: grades a .geo's tetrahedra from mesh.size towards the crack fronts: "
                         "give mesh.size with a .geo (a .msh is read as it is)")
    if data["materials"]["model"] != "plane_strain":
        raise SceneError(f"{origin}: materials.model: a 3-D body has no plane model (leave it out)")
    for (section, key), why in NOT_YET.items():
        table = raw.get(section)
        if isinstance(table, dict) and table and (key is None or key in table):
            named = f"{section}.{key}" if key else f"{section}.{next(iter(table))}"
            raise SceneError(f"{origin}: {printable(named)}: {why}")
    fracture = raw.get("fracture")
    other = next((name for name in fracture if name not in FRONT_KEYS), None) if isinstance(fracture, dict) else None
    if other is not None:
        raise SceneError(f"{origin}: fracture.{printable(other)}: G along a 3-D crack front takes fracture.inner and "
                         "fracture.outer only (θ's radii), for now")


def _adaptive_defaults(mesh: dict, written: dict, origin: str) -> None:
    """``mesh.target_error`` re-meshes the box with gmsh: not an extruded plane mesh; alone it chooses P2 and a
    first mesh graded towards the crack fronts, as in the plane."""
    if mesh["extrude"] is not None:
        raise SceneError(f"{origin}: mesh.target_error: a 3-D box is refined by meshing it again with gmsh, and "
                         "mesh.extrude extrudes a fixed plane section: leave one of them out")
    if "degree" not in written:
        mesh["degree"] = ADAPTIVE_DEGREE
    if "grading" not in written:
        mesh["grading"] = True


def _check_on_sigma(crack: tuple[float, ...] | Ellipse, box: tuple[float, ...], key: str, origin: str) -> None:
    """A crack rectangle lies on Σ, inside the box's x and z ranges; an ellipse's centre lies on Σ (its part
    inside the box is the crack)."""
    x0, x1, _, _, z0, z1 = box
    if isinstance(crack, Ellipse):
        (x, z), (r1, r2) = crack.center, crack.radii
        if not (x0 <= x <= x1 and z0 <= z <= z1):
            raise SceneError(f"{origin}: {key}: the ellipse's centre ({x:g}, {z:g}) leaves Σ: it is not inside the "
                             f"box's x range [{x0:g}, {x1:g}] and z range [{z0:g}, {z1:g}]")
        if x - r1 <= x0 and x + r1 >= x1 or z - r2 <= z0 and z + r2 >= z1:
            raise SceneError(f"{origin}: {key}: the ellipse crosses Σ from side to side: give it as a strip "
                             "[a, b] or a rectangle")
        return
    a, b, c, d = crack
    for axis, (low, high), (start, end) in (("x", (a, b), (x0, x1)), ("z", (c, d), (z0, z1))):
        if low < start or high > end:
            raise SceneError(f"{origin}: {key}: the crack {[float(v) for v in crack]} leaves Σ: its {axis} range "
                             f"[{low:g}, {high:g}] is not inside the box's [{start:g}, {end:g}]")


def _material_checks(data: dict, origin: str) -> None:
    """The body's material, and its regions': isotropic, or a transversely isotropic ply about its fibre (``angle``
    about z as in the plane, or ``fibre = [x, y, z]``), with an elastic law double precision can factor."""
    table = data["materials"]["layer1"]
    given = [("materials.layer1", table)] + [(f"materials.layer1.{region}", inner)
                                             for region, inner in table.items() if isinstance(inner, dict)]
    for key, written in given:
        material = layer_material(written)
        if isinstance(material, materials.Orthotropic):
            _ply_checks(material, key, origin)
        elif not isinstance(material, materials.Isotropic):
            raise SceneError(f"{origin}: {key}: a 3-D body takes isotropic (E, nu) or orthotropic (E1, E2, G12, "
                             "nu12) materials: a plane matrix D has no law in 3-D")
        elif not (material.E > 0 and -1.0 < material.nu < 0.5):
            raise SceneError(f"{origin}: {key}: E > 0 and -1 < nu < 0.5 make a 3-D elastic law")


def _ply_checks(material: materials.Orthotropic, key: str, origin: str) -> None:
    """A ply is transversely isotropic about its fibre (E3 = E2, nu13 = nu12), its fibre a direction given once,
    its law positive definite."""
    for name, value, equal in (("E3", material.E3, material.E2), ("nu13", material.nu13, material.nu12)):
        if value is not None and value != equal:
            raise SceneError(f"{origin}: {key}.{name}: a 3-D ply is transversely isotropic about its fibre "
                             f"({name} = {'E2' if name == 'E3' else 'nu12'}): leave {name} out")
    if material.fibre is not None and (material.angle != 0.0 or not np.linalg.norm(material.fibre) > 0.0):
        raise SceneError(f"{origin}: {key}.fibre: " + ("a direction, not zero" if material.angle == 0.0 else
                                                       "give the fibre by fibre or by angle, not both"))
    try:
        materials.solid_stiffness(material)
    except materials.MaterialError as exc:
        raise SceneError(f"{origin}: {key}: {exc}") from None


def _boundary_checks(data: dict, origin: str, sides: tuple[str, ...]) -> None:
    """Loads and prescribed displacements act on the body's ``sides`` (a box's six, a file's named surfaces); a
    pressure excludes x, y and z, a normal displacement x, y and z; no point supports; no prescribed values on a
    clamped side."""
    clamped = set(data["geometry"]["clamped"])
    for section, exclusive in (("loads", "pressure"), ("displacements", "normal")):
        for layer, tables in data.get(section, {}).items():
            for name, table in tables.items():
                key = f"{section}.{layer}.{printable(name)}"
                if name not in sides:
                    raise SceneError(f"{origin}: {key}: " + (
                        f"a 3-D box's boundaries are its sides ({', '.join(SOLID_SIDES)})" if sides == SOLID_SIDES
                        else f"no physical surface {printable(name)!r} in mesh.file (its boundaries: "
                        f"{', '.join(map(printable, sides)) or 'none'})"))
                given = [part for part, value in table.items() if value is not None and part != "point"]
                if table.get("point") is not None:
                    raise SceneError(f"{origin}: {key}.point: point supports are not available in 3-D yet")
                if section == "displacements" and exclusive in given and sides != SOLID_SIDES:
                    raise SceneError(f"{origin}: {key}.normal: on a 3-D file's surfaces give the x, y and z "
                                     "components (a displacement along the surface's normal is not available yet)")
                if exclusive in given and len(given) > 1:
                    raise SceneError(f"{origin}: {key}: {exclusive} excludes x, y and z")
                if section == "displacements" and (name in clamped or not given):
                    raise SceneError(f"{origin}: {key}: " + ("give x, y, z or normal" if not given else
                                     f"boundary {name!r} is clamped (geometry.clamped)"))
