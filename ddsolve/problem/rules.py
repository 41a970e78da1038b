"""Rules between a scene's keys, checked after each key has been checked alone; they fill in the
defaults that depend on other keys (Σ's height, the cracks, the element degree of an adaptive run, ...)."""
from __future__ import annotations

import math
from typing import Sequence

from ddsolve.errors import SceneError
from ddsolve.problem import materials
from ddsolve.problem.method_options import OPTIONS
from ddsolve.problem.reading import FileStructure, printable
from ddsolve.problem.shapes import Ellipse
from ddsolve.problem.schema import (ADAPTIVE_DEGREE, DEFAULT_TOL, DEPTH_SIDES, GEOMETRIC_TOLERANCE, GRADING,
                                    LAWS, MAX_SPACING_RATIO, SIDES, PAPER_CRACK, STRUCTURE_KEYS, PerInterface, layer_material,
                                    region_names,
                                    layers_of)


def cross_checks(data: dict, raw: dict, origin: str, structure: FileStructure | None = None) -> None:
    """Rules between keys; fills in the defaults that depend on other keys (``structure``: that of a gmsh file of
    several interfaces, :func:`ddsolve.problem.reading.file_structure`)."""
    given = set(raw.get("geometry", {})) - set(STRUCTURE_KEYS) if isinstance(raw.get("geometry"), dict) else set()
    _plane_checks(data, origin)
    _geometry_checks(data["geometry"], given, origin)
    data["geometry"]["regions"] = structure.regions if structure else ()
    if structure:  # the file's interfaces: their lines and cracks are its curves (no heights here)
        data["geometry"]["above"] = [(data["geometry"]["sigma"], [])] * (structure.interfaces - 1)
    _several_interfaces_checks(data, raw, origin)
    _mesh_checks(data["mesh"], data["geometry"], raw, given, origin)
    _material_checks(data, origin)
    _load_checks(data, origin)
    _displacement_checks(data, origin)
    _temperature_checks(data, origin)
    solver_checks(data, origin)
    _radii_checks(data, origin)
    _toughness_checks(data, origin)
    _split_checks(data, origin)
    _reference_length_checks(data, origin)
    _friction_checks(data, origin)
    _bond_checks(data["interface"], origin)
    coulomb = data["contact"]["friction"]
    if data["interface"]["law"] is not None and coulomb is not None and max(
            coulomb if isinstance(coulomb, tuple) else (coulomb,), default=0.0) > 0.0:
        raise SceneError(f"{origin}: contact.friction (Coulomb) is not solved with interface.law: give the crack "
                         "faces Tresca's contact.slip_bound, or no friction")


def _plane_checks(data: dict, origin: str) -> None:
    """What only a 3-D box (``geometry.box`` of 6 numbers) takes is refused in a plane scene: rectangle cracks,
    ``mesh.extrude``, the front and back sides, z components."""
    geometry = data["geometry"]
    for key, pieces in (("crack", [geometry["crack"]] if geometry["crack"] else []),
                        ("cracks", _flat_pieces(geometry["cracks"]))):
        solid = next((piece for piece in pieces if isinstance(piece, Ellipse) or len(piece) == 4), None)
        if solid is not None:
            shape = "an ellipse crack" if isinstance(solid, Ellipse) else "a rectangle crack [a, b, c, d]"
            raise SceneError(f"{origin}: geometry.{key}: {shape} needs a 3-D box (geometry.box = [x0, x1, y0, y1, "
                             "z0, z1]); a plane crack is [a, b]")
    depth = [side for side in geometry["clamped"] if side in DEPTH_SIDES]
    if depth:
        raise SceneError(f"{origin}: geometry.clamped: {depth[0]!r} is a side of a 3-D box (geometry.box = "
                         "[x0, x1, y0, y1, z0, z1]); a plane box has " + ", ".join(SIDES))
    if data["solver"]["preconditioner"] == "lumped":
        raise SceneError(f"{origin}: solver.preconditioner = lumped: feti's lumped preconditioner is built for the "
                         "slabs of a 3-D box (geometry.box = [x0, x1, y0, y1, z0, z1]); a plane scene's feti takes "
                         "dirichlet")
    if data["solver"]["pieces"] != "auto":
        raise SceneError(f"{origin}: solver.pieces: cuts the halves of a 3-D box (geometry.box = [x0, x1, y0, y1, "
                         "z0, z1]) into slabs; a plane scene's blocks are its layers and halves")
    if data["mesh"]["extrude"] is not None:
        raise SceneError(f"{origin}: mesh.extrude: extrudes a plane section into a 3-D box (geometry.box = "
                         "[x0, x1, y0, y1, z0, z1]); a plane scene is not extruded")
    for section in ("loads", "displacements"):
        for layer, tables in data.get(section, {}).items():
            for name, table in tables.items():
                key = f"{section}.{layer}.{printable(name)}"
                if table["z"] is not None:
                    raise SceneError(f"{origin}: {key}.z: a plane scene has no z component (a 3-D box has: "
                                     "geometry.box = [x0, x1, y0, y1, z0, z1])")
                _refuse_depth([(f"{key}.{part}", value) for part, value in table.items() if part != "point"], origin)
    _refuse_depth([(f"temperature.{layer}", value) for layer, value in data.get("temperature", {}).items()], origin)


def _refuse_depth(expressions: list, origin: str) -> None:
    """The (key, expression or None) pairs of a plane scene read x and y only."""
    for key, value in expressions:
        if value is not None and "z" in value.variables:
            raise SceneError(f"{origin}: {key}: a plane scene's expressions take x and y (z is a 3-D box's "
                             "coordinate: geometry.box = [x0, x1, y0, y1, z0, z1])")


def _flat_pieces(cracks) -> list:
    """Every crack of ``geometry.cracks`` (one list, or one list per interface), or none."""
    if not cracks:
        return []
    return [piece for group in cracks for piece in group] if isinstance(cracks, PerInterface) else list(cracks)


def _geometry_checks(geometry: dict, given: set[str], origin: str) -> None:
    """The box, the interfaces' heights and their cracks: Σ inside the box (its middle by default), one list of
    cracks per interface (the paper's crack with the paper's square), each on its Σ, farther apart than the meshing
    tolerance.  Leaves ``sigma`` and ``cracks`` (the first interface) and ``above`` (the others: (height, cracks))."""
    if "crack" in given and "cracks" in given:
        raise SceneError(f"{origin}: geometry.crack and geometry.cracks exclude each other (cracks = [[a, b], ...])")
    x0, x1, y0, y1 = geometry["box"]
    heights = geometry["sigma"] if isinstance(geometry["sigma"], tuple) else (
        (0.5 * (y0 + y1),) if geometry["sigma"] is None else (geometry["sigma"],))
    outside = [y for y in heights if not y0 < y < y1]
    if outside:
        raise SceneError(f"{origin}: geometry.sigma = {outside[0]:g} must lie strictly between the box's "
                         f"y0 = {y0:g} and y1 = {y1:g}")
    crack_key = "geometry.crack" if "crack" in given else "geometry.cracks"
    lists = crack_lists(geometry, given, len(heights), origin)
    for cracks in lists:
        _check_cracks(cracks, geometry["box"], crack_key, origin)
    check_apart([y0, *heights, y1], geometry["box"], "geometry.sigma", "of the box's y range (interfaces, sides)",
                 "move or remove an interface", origin)
    geometry["sigma"], geometry["cracks"] = heights[0], lists[0]
    geometry["above"] = list(zip(heights[1:], lists[1:]))
    del geometry["crack"]


#: The mesh keys a structure of several interfaces takes: its regions are meshed with pieces of about mesh.size
#: (a gmsh file's with its own sizes, or mesh.size where given).
STACK_MESH_KEYS = ("size", "degree")


def _several_interfaces_checks(data: dict, raw: dict, origin: str) -> None:
    """A structure of several interfaces is the built-in box meshed with ``mesh.size``, or a gmsh file, with no
    point supports."""
    if not data["geometry"]["above"]:
        return
    written = raw["mesh"] if isinstance(raw.get("mesh"), dict) else {}
    from_file = bool(data["geometry"]["regions"])
    other = next((key for key in written if key not in STACK_MESH_KEYS + ("file",) * from_file), None)
    if other is not None or data["mesh"]["size"] is None and not from_file:
        key = f"mesh.{other}" if other is not None else "mesh.size"
        raise SceneError(f"{origin}: {key}: " + ("the several interfaces of a gmsh file (sigma1, sigma2, ...) are "
                                                 "meshed from the file with mesh.size and mesh.degree only" if from_file
                                                 else "a structure of several interfaces (geometry.sigma = [y1, y2, "
                                                 "...]) is the built-in box meshed with mesh.size (and mesh.degree) "
                                                 "only"))
    points = [f"displacements.{layer}.{name}.point" for layer, tables in data.get("displacements", {}).items()
              for name, table in tables.items() if table["point"] is not None]
    if points:
        raise SceneError(f"{origin}: {points[0]}: point supports on a structure of several interfaces are not "
                         "available")


def crack_lists(geometry: dict, given: set[str], interfaces: int, origin: str) -> list:
    """The cracks of each of the ``interfaces``, bottom to top, from ``geometry.crack`` or ``geometry.cracks``."""
    cracks = geometry["cracks"]
    if "crack" in given or "cracks" in given and not isinstance(cracks, PerInterface):
        if interfaces > 1:
            key = "geometry.crack" if "crack" in given else "geometry.cracks"
            raise SceneError(f"{origin}: {key}: with {interfaces} interfaces give one list of intervals per "
                             "interface, bottom to top: geometry.cracks = [[[a, b], ...], [[c, d], ...], ...]")
        if "crack" in given:
            return [[list(geometry["crack"])] if geometry["crack"] else []]
        return [list(cracks)]
    if "cracks" in given:
        if len(cracks) != interfaces:
            raise SceneError(f"{origin}: geometry.cracks lists {len(cracks)} crack list{'' if len(cracks) == 1 else 's'}"
                             f" for the {interfaces} interface{'' if interfaces == 1 else 's'} of geometry.sigma "
                             "(one list of intervals per interface, bottom to top; [] for none)")
        return [list(piece) for piece in cracks]
    # the paper's crack comes with the paper's square and one interface only
    return [[] if "box" in given or interfaces > 1 else [list(PAPER_CRACK)] for _ in range(interfaces)]


def _check_cracks(cracks: list, box: Sequence[float], key: str, origin: str) -> None:
    """One interface's cracks lie in the box's x range, their tips apart from each other and from its ends."""
    x0, x1, _, _ = box
    for a, b in cracks:
        if a < x0 or b > x1:
            raise SceneError(f"{origin}: {key}: the crack [{a:g}, {b:g}] leaves the box's x range [{x0:g}, {x1:g}]")
    check_apart([x0, x1, *(tip for piece in cracks for tip in piece)], box, key, "of Σ (crack tips, box ends)",
                 "lengthen, move or remove the crack", origin)


def check_apart(values: list[float], box: Sequence[float], key: str, what: str, remedy: str, origin: str) -> None:
    """The coordinates ``values`` (points ``what``) are farther apart than the meshing tolerance."""
    x0, x1, y0, y1 = box
    breaks = sorted(set(values))
    shortest = min(b - a for a, b in zip(breaks[:-1], breaks[1:]))
    feature = GEOMETRIC_TOLERANCE * max(x1 - x0, y1 - y0)
    if shortest <= feature:
        raise SceneError(f"{origin}: {key}: two points {what} are only {shortest:.2g} apart, within the meshing "
                         f"tolerance {feature:.2g} ({GEOMETRIC_TOLERANCE:g} × the box size): {remedy}")


def _mesh_checks(mesh: dict, geometry: dict, raw: dict, given: set[str], origin: str) -> None:
    """The mesh keys that exclude each other, the adaptive defaults, and the paper's family (P, M) with
    consistent spacings."""
    x0, x1, y0, y1 = geometry["box"]
    counts = (mesh["sigma_vertices"], mesh["boundary_vertices"])
    _adaptive_defaults(mesh, set(raw["mesh"]) if isinstance(raw.get("mesh"), dict) else set(), geometry)
    _mesh_refinement_checks(mesh, origin)
    if mesh["file"] is not None:
        extra = [name for name in ("sigma_vertices", "boundary_vertices") if mesh[name] is not None]
        if mesh["size"] is not None and not mesh["file"].lower().endswith(".geo"):
            extra.append("size")
        if extra:
            raise SceneError(f"{origin}: mesh.file excludes mesh.{extra[0]} (a .geo file takes mesh.size)")
        if mesh["file"].lower().endswith(".geo") and given:
            raise SceneError(f"{origin}: geometry.{sorted(given)[0]} does not apply to a .geo geometry "
                             "(its physical groups define it)")
    elif mesh["size"] is not None:
        if counts != (None, None):
            raise SceneError(f"{origin}: mesh.size excludes mesh.sigma_vertices and mesh.boundary_vertices")
    elif None in counts:
        missing = "mesh.sigma_vertices" if counts[0] is None else "mesh.boundary_vertices"
        raise SceneError(f"{origin}: missing key {missing} (or give mesh.size, mesh.file or mesh.target_error)")
    else:
        sigma_spacing = (x1 - x0) / (counts[0] - 1)
        boundary_spacing = 2.0 * ((x1 - x0) + (y1 - y0)) / counts[1]
        ratio = boundary_spacing / sigma_spacing
        if not 1.0 / MAX_SPACING_RATIO <= ratio <= MAX_SPACING_RATIO:
            raise SceneError(f"{origin}: mesh.boundary_vertices = {counts[1]} is inconsistent with "
                             f"mesh.sigma_vertices = {counts[0]}: the boundary spacing (perimeter/M) must be "
                             f"within a factor {MAX_SPACING_RATIO:g} of the Σ spacing (width/(P-1)), or the "
                             "corner triangles degenerate")


def _material_checks(data: dict, origin: str) -> None:
    """Each layer's constants, and each region's that override them, make an elastic matrix that double
    precision can factor."""
    model = data["materials"]["model"]
    for layer in layers_of(data):
        table = data["materials"][layer]
        given = [(f"materials.{layer}", table)] + [(f"materials.{layer}.{region}", inner)
                                                   for region, inner in table.items() if isinstance(inner, dict)]
        for key, material in given:
            if material.get("fibre") is not None:
                raise SceneError(f"{origin}: {key}.fibre: a fibre direction in 3-D (a 6-number geometry.box); in the "
                                 "plane give angle")
            try:
                D, _ = materials.elasticity(layer_material(material), model)
            except materials.MaterialError as exc:
                raise SceneError(f"{origin}: {key}: {exc}") from None
            _check_conditioning(D, material, model, f"{origin}: {key}")


def acting_tables(data: dict, layer: str) -> dict[str, tuple[str, dict]]:
    """Region -> the key and the checked table of the material that acts there in ``layer``: the region's
    own table where the scene gives one, else the layer's."""
    table = data["materials"][layer]
    return {region: (f"materials.{layer}.{region}", table[region]) if region in table else
            (f"materials.{layer}", table) for region in _regions(data)}


def _regions(data: dict) -> tuple[str, ...]:
    """The regions of Ω of a scene whose geometry is checked, bottom to top (a gmsh file's own names)."""
    return tuple(data["geometry"].get("regions", ())) or region_names(len(data["geometry"]["above"]) + 2)


def dissimilar_layers(data: dict, thermal: bool = True) -> list[str]:
    """The layers whose regions have different plane laws (stiffness, and with ``thermal`` thermal strain)."""
    return materials.differing({layer: [layer_material(table) for _, table in acting_tables(data, layer).values()]
                                for layer in layers_of(data)}, data["materials"]["model"], thermal)


def _reference_length_checks(data: dict, origin: str) -> None:
    """``fracture.reference_length`` sets the phase of an interface crack between different materials that have an
    effective isotropic pair: a scene whose layers have no region of their own material (``materials.LAYER.REGION``)
    has no such crack (ψ = arg K at any length), and regions without a pair leave G unsplit."""
    if data["fracture"]["reference_length"] is None:
        return
    if not any(isinstance(inner, dict) for layer in layers_of(data) for inner in data["materials"][layer].values()):
        raise SceneError(f"{origin}: fracture.reference_length: no layer has a region of its own material "
                         "(materials.LAYER.lower or .upper), so no crack lies between different materials and the "
                         "phase ψ is the same at every length: leave it out")
    unpaired = _unpaired_regions(data)
    if unpaired is not None:
        raise SceneError(f"{origin}: fracture.reference_length: the regions of materials.{unpaired[0]} (below and "
                         f"above Σ) differ where {unpaired[1]}, so G is not split into modes and has no phase: "
                         "leave it out")


def _unpaired_regions(data: dict) -> tuple[str, str] | None:
    """A layer whose regions on the two sides of an interface have different elastic laws without an effective
    isotropic pair (:func:`ddsolve.problem.materials.interface_pair`), and why; None where every pair exists."""
    dissimilar = dissimilar_layers(data, thermal=False)
    if not dissimilar:
        return None
    model = data["materials"]["model"]
    laws = {region: [materials.elasticity(layer_material(acting_tables(data, layer)[region][1]), model)[0]
                     for layer in layers_of(data)] for region in _regions(data)}
    for lower, upper in zip(list(laws), list(laws)[1:]):
        pair = materials.interface_pair(laws[lower], laws[upper])
        if isinstance(pair, str):
            return dissimilar[0], pair
    return None


def _split_checks(data: dict, origin: str) -> None:
    """A mode-dependent toughness law needs G's split into modes, which regions of different elastic laws on the two
    sides of Σ leave undefined unless they have an effective isotropic pair (an interface crack: its phase ψ,
    :func:`ddsolve.problem.materials.interface_pair`)."""
    law = data["fracture"]["law"]
    unpaired = None if law is None else _unpaired_regions(data)
    if unpaired is not None:
        raise SceneError(f"{origin}: fracture.law = {law} needs G's split into modes I and II, which is not "
                         f"defined between the different materials of the regions of materials.{unpaired[0]} "
                         f"(below and above Σ) where {unpaired[1]}: give one toughness, fracture.toughness")


def _load_checks(data: dict, origin: str) -> None:
    """A pressure acts along the normal: it excludes x and y on its boundary."""
    for layer, tables in data.get("loads", {}).items():
        for name, table in tables.items():
            if table["pressure"] is not None and (table["x"] is not None or table["y"] is not None):
                raise SceneError(f"{origin}: loads.{layer}.{printable(name)}: pressure excludes x and y "
                                 "(a pressure acts along the normal)")


def solver_checks(data: dict, origin: str) -> None:
    """The method's step, its stopping rule and the rule's tolerance."""
    solver, method = data["solver"], OPTIONS[data["solver"]["method"]]
    if method.step and solver["theta"] is None:
        raise SceneError(f"{origin}: solver.theta is required by method {method.name}")
    if solver["stop"] is None:
        solver["stop"] = method.stops[0]
    if solver["stop"] not in method.stops:
        takers = " and ".join(name for name, other in OPTIONS.items() if solver["stop"] in other.stops)
        raise SceneError(f"{origin}: solver.stop = {solver['stop']} is available for method {takers} only "
                         f"(method {method.name} stops on {' or '.join(method.stops)})")
    if solver["tol"] is None:
        solver["tol"] = DEFAULT_TOL[solver["stop"]]
    if solver["coarse_degree"] not in ("auto", 0) and method.name not in ("feti", "auto"):
        raise SceneError(f"{origin}: solver.coarse_degree = {solver['coarse_degree']}: feti's coarse directions; "
                         f"method {method.name} takes none (solver.method = feti, or coarse_degree = 0)")


def _radii_checks(data: dict, origin: str) -> None:
    """The θ field's inner radius is below its outer one."""
    radii = data["fracture"]
    if None not in (radii["inner"], radii["outer"]) and radii["inner"] >= radii["outer"]:
        raise SceneError(f"{origin}: fracture.inner = {radii['inner']:g} must be below fracture.outer = "
                         f"{radii['outer']:g}")


def _toughness_checks(data: dict, origin: str) -> None:
    """``fracture.toughness`` and ``fracture.law`` exclude each other; a law has its keys and no other; a
    per-crack toughness has one value per crack of a box (a mesh file's cracks are counted on its mesh)."""
    options = data["fracture"]
    constants = sorted({key for keys in LAWS.values() for key in keys})
    given = [key for key in constants if options[key] is not None]
    law = options["law"]
    if options["toughness"] is not None and law is not None:
        raise SceneError(f"{origin}: fracture.toughness and fracture.law exclude each other (one G_c, or a "
                         "mode-dependent law)")
    if law is None:
        if given:
            raise SceneError(f"{origin}: fracture.{given[0]} needs fracture.law (" + " or ".join(LAWS) + ")")
    else:
        missing = [key for key in LAWS[law] if options[key] is None]
        if missing:
            raise SceneError(f"{origin}: fracture.law = {law} needs fracture.{missing[0]} ("
                             + ", ".join(f"fracture.{key}" for key in LAWS[law]) + ")")
        extra = [key for key in given if key not in LAWS[law]]
        if extra:
            raise SceneError(f"{origin}: fracture.{extra[0]} does not apply to fracture.law = {law} (it takes "
                             + ", ".join(f"fracture.{key}" for key in LAWS[law]) + ")")
    _check_per_crack(data, options["toughness"], "fracture.toughness", origin)


def _friction_checks(data: dict, origin: str) -> None:
    """``contact.friction`` (Coulomb) and ``contact.slip_bound`` (Tresca) exclude each other and need
    non-penetration; a per-crack list has one value per crack of a box (a mesh file's are counted on its mesh)."""
    contact = data["contact"]
    given = [key for key in ("friction", "slip_bound") if contact[key] is not None]
    if len(given) == 2:
        raise SceneError(f"{origin}: contact.friction and contact.slip_bound exclude each other (Coulomb's "
                         "coefficient, or Tresca's bound on the tangential traction)")
    if given and not contact["nonpenetration"]:
        raise SceneError(f"{origin}: contact.{given[0]} needs contact.nonpenetration = true (friction acts "
                         "on crack faces in contact)")
    if given:
        _check_per_crack(data, contact[given[0]], f"contact.{given[0]}", origin)
        values = contact[given[0]] if isinstance(contact[given[0]], tuple) else (contact[given[0]],)
        if _crack_count(data) == 0 and data["mesh"]["file"] is None and any(values):
            raise SceneError(f"{origin}: contact.{given[0]}: the scene has no crack (geometry.cracks), so there are "
                             "no crack faces for friction to act on: leave it out, or give the crack")


def _crack_count(data: dict) -> int:
    """The cracks of a box scene's geometry, on every interface."""
    geometry = data["geometry"]
    return len(geometry["cracks"]) + sum(len(more) for _, more in geometry["above"])


def _check_per_crack(data: dict, values, key: str, origin: str) -> None:
    """A per-crack list (``values`` at ``key``) has one value per crack of a box: interface by interface,
    bottom to top, in order along each (a mesh file's cracks are counted on its mesh)."""
    geometry, cracks = data["geometry"], _crack_count(data)
    if isinstance(values, tuple) and data["mesh"]["file"] is None and len(values) != cracks:
        order = "in order along Σ" if not geometry["above"] else "interface by interface, bottom to top"
        raise SceneError(f"{origin}: {key} lists {len(values)} values for the {cracks} crack"
                         f"{'' if cracks == 1 else 's'} of geometry.cracks (one per crack, {order})")


#: The bilinear law's default initial slope makes the opening at the peak this fraction of the opening where the
#: traction vanishes (δ₀ = BOND_OPENING δ_f, δ_f = 2G_c/σ_c): k = σ_c²/(2 BOND_OPENING G_c).
BOND_OPENING = 1e-3


def _bond_checks(bond: dict, origin: str) -> None:
    """``[interface]``: a law and the keys it needs (elastic: stiffness; bilinear: strength and toughness, the
    stiffness by default from :data:`BOND_OPENING`; the mixed-mode rule with G_IIc, eta and shear_strength), and no
    key without a law that reads it."""
    given = [key for key, value in bond.items() if value is not None and key != "law"]
    law = bond["law"]
    needs = {None: (), "elastic": ("stiffness",), "bilinear": ("strength", "toughness")}[law]
    reads = {None: (), "elastic": ("stiffness",), "bilinear": tuple(key for key in bond if key != "law")}[law]
    if bond["mode_mix"] is not None:
        needs += ("G_IIc", "eta", "shear_strength")
    for key in needs:
        if bond[key] is None:
            raise SceneError(f"{origin}: interface.{key} is needed by interface.law = \"{law}\""
                             + (f" with interface.mode_mix" if key in ("G_IIc", "eta", "shear_strength") else ""))
    for key in given:
        if key not in reads or (key in ("G_IIc", "eta", "shear_strength") and bond["mode_mix"] is None):
            raise SceneError(f"{origin}: interface.{key} is not read " + (
                "without interface.law (\"elastic\" or \"bilinear\")" if law is None else
                f"by interface.law = \"{law}\"" + ("" if law == "elastic" else " without interface.mode_mix")))
    if law == "bilinear" and bond["stiffness"] is None:
        bond["stiffness"] = bond["strength"] ** 2 / (2.0 * BOND_OPENING * bond["toughness"])
    if law == "bilinear" and bond["strength"] ** 2 / bond["stiffness"] >= 2.0 * bond["toughness"]:
        raise SceneError(f"{origin}: interface.stiffness = {bond['stiffness']:g} is too small for the strength and "
                         "toughness: the elastic opening at the peak must be below the opening 2 G_c/σ_c where the "
                         f"traction vanishes (stiffness > {bond['strength'] ** 2 / (2.0 * bond['toughness']):g})")


def _temperature_checks(data: dict, origin: str) -> None:
    """A temperature change acts through the layer's expansion coefficients: a layer heated (ΔT not zero) must
    give them (``alpha``, or ``alpha1`` or ``alpha2``); a layer given by its matrix D takes none."""
    for layer, change in data.get("temperature", {}).items():
        if change is None or (change.constant and change(0.0, 0.0) == 0.0):
            continue
        acting = list(acting_tables(data, layer).values())
        if any(table.get(key) is not None for _, table in acting for key in ("alpha", "alpha1", "alpha2")):
            continue
        key, table = next(((key, table) for key, table in acting if "D" not in table), acting[0])
        if "D" in table:
            raise SceneError(f"{origin}: temperature.{layer}: {key} is given by its matrix D, which takes "
                             "no thermal expansion, so the temperature change would do nothing: give the layer by "
                             "its constants with alpha, or leave the temperature change out")
        names = "alpha" if "E" in table else "alpha1 or alpha2"
        raise SceneError(f"{origin}: temperature.{layer}: {key} has no expansion coefficient, so the "
                         f"temperature change would do nothing: give {key}.{names}, or leave the "
                         "temperature change out")


#: Components of a load and of a displacement on one boundary that act in the same direction.
SAME_COMPONENT = {"x": ("x",), "y": ("y",), "normal": ("pressure", "x", "y")}


def _displacement_checks(data: dict, origin: str) -> None:
    """A displacement gives x and y, or normal; it is not on a clamped side, nor on a boundary loaded in
    the same component (a pressure acts along the normal; a normal displacement with x or y loads, or a
    pressure with x or y displacements, mixes frames: refused too)."""
    clamped = set(data["geometry"]["clamped"]) if data["mesh"]["file"] is None else set()
    for layer, tables in data.get("displacements", {}).items():
        for name, table in tables.items():
            key = f"displacements.{layer}.{printable(name)}"
            given = [component for component, value in table.items() if value is not None and component != "point"]
            if table.get("point") is not None:
                _point_checks(data, table, key, given, origin)
            if not given:
                raise SceneError(f"{origin}: {key}: give x, y or normal")
            if "normal" in given and len(given) > 1:
                raise SceneError(f"{origin}: {key}: normal excludes x and y (give the normal component, or x "
                                 "and y)")
            if name in clamped or name == "clamped":
                raise SceneError(f"{origin}: {key}: boundary {printable(name)!r} is clamped (geometry.clamped); "
                                 "remove it there to prescribe other values")
            load = data.get("loads", {}).get(layer, {}).get(name)
            for component in given if load is not None else ():
                loaded = [part for part in SAME_COMPONENT[component] if load[part] is not None]
                if component != "normal" and load["pressure"] is not None:
                    loaded.append("pressure")
                if loaded:
                    raise SceneError(f"{origin}: {key}.{component}: boundary {printable(name)!r} of {layer} is "
                                     f"also loaded in that direction (loads.{layer}.{printable(name)}.{loaded[0]})")


def _point_checks(data: dict, table: dict, key: str, given: list[str], origin: str) -> None:
    """A point support (``point = [x, y]``) fixes x and/or y (a point has no normal) and, in the box, lies
    on its sides or on Σ (the mesher puts a vertex there; a file's mesh must have one).  A box point is
    snapped onto its line and onto a corner, Σ's end or a crack tip within the meshing tolerance."""
    if "normal" in given:
        raise SceneError(f"{origin}: {key}.normal: a point has no normal; give x and/or y at the point")
    if data["mesh"]["file"] is not None:
        return
    x, y = table["point"]
    box = x0, x1, y0, y1 = data["geometry"]["box"]
    sigma = data["geometry"]["sigma"]
    feature = GEOMETRIC_TOLERANCE * max(x1 - x0, y1 - y0)
    inside = x0 - feature <= x <= x1 + feature and y0 - feature <= y <= y1 + feature
    tips = [x0, x1, *(tip for piece in data["geometry"]["cracks"] for tip in piece)]
    lines = [(1, y0, [x0, x1]), (1, y1, [x0, x1]), (1, sigma, tips), (0, x0, [y0, sigma, y1]),
             (0, x1, [y0, sigma, y1])]
    point = [x, y]
    for axis, value, stops in lines:
        if inside and abs(point[axis] - value) <= feature:
            point[axis] = value
            along = min(stops, key=lambda stop: abs(point[1 - axis] - stop))
            if abs(point[1 - axis] - along) <= feature:
                point[1 - axis] = along
            table["point"] = tuple(point)
            return
    where = "outside the box" if not inside else "inside a layer, off its boundary"
    raise SceneError(f"{origin}: {key}.point = [{x:g}, {y:g}] is {where}: a point support must lie on a side of "
                     f"geometry.box = {[float(v) for v in box]} or on Σ (y = {sigma:g})")


#: The largest ratio of the largest to the smallest eigenvalue of a layer's elastic matrix: 2/√ε, which
#: for an isotropic layer in plane strain (ratio 2/(1 − 2ν)) is 1 − 2ν ≥ √ε.  Measured with schur on
#: partial-closure: 1 − 2ν = 2e-10 solves (P = 13 and 96), 2e-12 does not; 2e-16 fails in MUMPS.
CONDITIONING = 2.0 / math.sqrt(2.0 ** -52)


def _check_conditioning(D, table: dict, model: str, where: str) -> None:
    """Refuse an elastic matrix so ill-conditioned (nearly incompressible) that its element matrices
    cannot be factored in double precision, naming the key and its usable range."""
    import numpy as np

    if not np.all(np.isfinite(D)):
        raise SceneError(f"{where}: the elastic matrix overflows a double (entries beyond 1.8e308): change the "
                         "unit of stress")
    eigenvalues = np.linalg.eigvalsh(D)
    ratio = float(eigenvalues[-1] / eigenvalues[0])
    if ratio <= CONDITIONING:
        return
    if "nu" not in table:
        raise SceneError(f"{where}: the elastic matrix is too ill-conditioned for double precision (largest / "
                         f"smallest eigenvalue {ratio:.2g}, at most {CONDITIONING:.2g}): the layer is nearly "
                         "incompressible or nearly without stiffness in some direction")
    nu = table["nu"]
    limit = (f"at most {0.5 - 1.0 / CONDITIONING:.10f}" if nu > 0 else
             f"at least {(1.0 - CONDITIONING) / (1.0 + CONDITIONING):.10f}")
    raise SceneError(f"{where}.nu = {nu!r} is too close to {0.5 if nu > 0 else -1.0:g} for double precision in "
                     f"{model} (the elastic matrix's largest / smallest eigenvalue is {ratio:.2g}, at most "
                     f"{CONDITIONING:.2g}): use nu {limit}")


def _adaptive_defaults(mesh: dict, given: set[str], geometry: dict) -> None:
    """``mesh.target_error`` alone chooses P2 elements, on a box without a mesh size a coarse first mesh
    (:func:`coarse_size`), and, where a size is given (the box or a .geo file with ``mesh.size``), a graded
    first mesh; keys the scene writes stay."""
    if mesh["target_error"] is None:
        return
    if "degree" not in given:
        mesh["degree"] = ADAPTIVE_DEGREE
    if mesh["file"] is None and mesh["size"] is None and (mesh["sigma_vertices"], mesh["boundary_vertices"]) == (
            None, None):
        mesh["size"] = coarse_size(geometry["box"], [geometry["sigma"], *(height for height, _ in geometry["above"])])
    if "grading" not in given and mesh["size"] is not None:
        mesh["grading"] = True


#: The first mesh of an adaptive run on a box that gives no mesh size: elements of the box's width over
#: COARSE[0], and at least COARSE[1] through the thinner half, whichever is smaller (the paper's square: 0.1).
COARSE = (20, 2)


def coarse_size(box: Sequence[float], sigma: float | Sequence[float]) -> float:
    """The element size of an adaptive run's first mesh on ``box`` cut at ``sigma`` (a height, or the heights of
    several interfaces) (:data:`COARSE`): through its thinnest region."""
    x0, x1, y0, y1 = box
    levels = [y0, *([sigma] if isinstance(sigma, (int, float)) else sigma), y1]
    return min((x1 - x0) / COARSE[0], min(b - a for a, b in zip(levels[:-1], levels[1:])) / COARSE[1])


def _mesh_refinement_checks(mesh: dict, origin: str) -> None:
    """mesh.grading and mesh.target_error need a geometry gmsh can mesh again; grading needs mesh.size."""
    fixed = mesh["file"] is not None and not mesh["file"].lower().endswith(".geo")
    if mesh["grading"] is True:
        mesh["grading"] = GRADING[mesh["degree"]]
    elif mesh["grading"] is False:
        mesh["grading"] = None
    for key in ("grading", "target_error"):
        if mesh[key] is not None and fixed:
            raise SceneError(f"{origin}: mesh.{key} needs a geometry to mesh (the built-in box or a .geo file); "
                             f"mesh.file = {printable(mesh['file'])} is a fixed mesh")
    if mesh["grading"] is not None and mesh["size"] is None:
        raise SceneError(f"{origin}: mesh.grading needs mesh.size, the mesh size away from the singular points "
                         "(the paper's family (P, M) has a grading of its own)")

