"""The scene file's schema: every key's checker and default (``SCHEMA``), the constants scenes are
checked against, and :func:`check_table`, which validates a raw table against its schema."""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Any, Callable

from ddsolve.errors import SceneError
from ddsolve.problem import expressions, materials
from ddsolve.problem.expressions import Expression
from ddsolve.problem.method_options import AUTO, OPTIONS
from ddsolve.problem.reading import excerpt, printable
from ddsolve.problem.shapes import Ellipse, bounds, ellipse

STOP_RULES = ("paper", "relative", "kkt")
#: Default tolerance of each stopping rule (a method's default rule: :mod:`ddsolve.problem.method_options`).
DEFAULT_TOL = {"paper": 1e-6, "relative": 1e-6, "kkt": 1e-8}
#: The layers of a structure, bottom to top of the stack: a structure has the first ``geometry.layers`` of them.
LAYERS = ("layer1", "layer2")
#: The tables that hold a table per layer (a one-layer structure has none of layer2).
LAYERED_TABLES = ("materials", "loads", "displacements", "temperature")
#: The geometry keys that say what the structure is rather than where the box lies: a mesh file takes them too.
STRUCTURE_KEYS = ("layers",)
#: The regions of Ω, bottom to top: below Σ and above it (a gmsh file's physical surfaces of these names).
REGIONS = ("lower", "upper")
#: The name of region k (1, 2, ... bottom to top) of a structure of several interfaces (:func:`region_names`).
NUMBERED_REGION = "region{}"
#: The sides of a box geometry, as boundary names.
SIDES = ("bottom", "top", "left", "right")
#: The sides a 3-D box (``geometry.box = [x0, x1, y0, y1, z0, z1]``) adds: z = z0 and z = z1.
DEPTH_SIDES = ("front", "back")
#: The paper's geometry: the square, Σ at y = 0, the crack (−1/2, 1/2), clamped at x = ±1.
PAPER_BOX = (-1.0, 1.0, -1.0, 1.0)
PAPER_CRACK = (-0.5, 0.5)
MAX_SPACING_RATIO = 10.0
#: Points of a generated geometry closer than this fraction of the box's size cannot be meshed
#: (gmsh's geometric tolerance).
GEOMETRIC_TOLERANCE = 1e-8
#: The grading exponent μ that ``mesh.grading = true`` chooses for each element degree p: mesh size
#: h ∝ r^(1−μ) at distance r from a singular point, with μ below ½/p so that an r^½ singularity costs
#: no convergence rate (see docs/accuracy.md).
GRADING = {1: 0.4, 2: 0.2}
#: The element degree of an adaptive run (``mesh.target_error``) whose scene does not set ``mesh.degree``:
#: P2 converges as N^-1 on adapted meshes, P1 as N^-½ (docs/accuracy.md).
ADAPTIVE_DEGREE = 2
#: The mode-dependent toughness laws (``fracture.law``) and the keys each needs (docs/fracture.md).
#: The traction–separation laws of ``[interface]`` on the bonded part of Σ, and their mixed-mode rules.
BOND_LAWS = ("elastic", "bilinear")
MODE_MIXES = ("benzeggagh-kenane",)
LAWS = {"benzeggagh-kenane": ("G_Ic", "G_IIc", "eta"), "hutchinson-suo": ("G_Ic", "lambda")}


# ---------------------------------------------------------------------------------------------
# Schema: a leaf is (checker, default); REQUIRED marks keys without a default.  A table is a dict,
# a Tables (free names, each a table of one schema) or a function choosing the schema from the raw table.
REQUIRED = object()


class Invalid(ValueError):
    """A value that is wrong in a way a ``must be ...`` phrase does not describe."""


@dataclass(frozen=True)
class Tables:
    schema: dict


def _number(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError("a number")
    if not math.isfinite(value):
        raise ValueError("a finite number")
    return float(value)


def _integer(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError("an integer")
    return value


def _boolean(value: Any) -> bool:
    if not isinstance(value, bool):
        raise TypeError("true or false")
    return value


def _string(value: Any) -> str:
    if not isinstance(value, str):
        raise TypeError("a string")
    return _storable(value)


def _storable(text: str) -> str:
    """``text`` if every file format ddsolve writes can hold it: UTF-8 without NUL characters."""
    if "\x00" in text:
        raise ValueError("text without NUL characters (\\u0000)")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise ValueError("valid Unicode text (it holds a lone surrogate or bytes that are not UTF-8)") from None
    return text


def _numbers(value: Any) -> tuple[float, ...]:
    if not isinstance(value, list):
        raise TypeError("a list of numbers")
    return tuple(_number(v) for v in value)


def _fixed_numbers(count: int) -> Callable[[Any], tuple[float, ...]]:
    def checked(value: Any) -> tuple[float, ...]:
        values = _numbers(value)
        if len(values) != count:
            raise ValueError(f"a list of {count} numbers")
        return values
    return checked


def _matrix3(value: Any) -> tuple[tuple[float, ...], ...]:
    if not isinstance(value, list) or len(value) != 3:
        raise TypeError("a 3x3 matrix [[..], [..], [..]]")
    try:
        return tuple(_fixed_numbers(3)(row) for row in value)
    except (TypeError, ValueError):
        raise TypeError("a 3x3 matrix [[..], [..], [..]] of finite numbers") from None


def _positive(check: Callable[[Any], Any]) -> Callable[[Any], Any]:
    def checked(value: Any) -> Any:
        value = check(value)
        if value <= 0:
            raise ValueError("> 0")
        return value
    return checked


def _poisson(value: Any) -> float:
    value = _number(value)
    if not -1.0 < value < 0.5:
        raise ValueError("in (-1, 0.5)")
    return value


def _step(value: Any) -> float | str:
    if value == "auto":
        return value
    try:
        return _positive(_number)(value)
    except (TypeError, ValueError):
        raise ValueError('a number > 0 or "auto" (2/λmax estimated by power iteration, with a margin)') from None


#: feti's preconditioners: Dirichlet's (a Dirichlet solve per block), lumped (the blocks' stiffness on their traces,
#: no solve), or auto: lumped on a 3-D box cut into slabs, Dirichlet's elsewhere.
PRECONDITIONERS = ("auto", "dirichlet", "lumped")

def _pieces(value: Any) -> int | str:
    if value == "auto":
        return value
    try:
        return _count(1)(value)
    except (TypeError, ValueError):
        raise ValueError('an integer >= 1 or "auto" (chosen from the size of the 3-D box\'s halves)') from None


#: feti's largest coarse degree: a joint's columns grow as its square (three components of C(d + 2, 2) monomials on a
#: plane), and already degree 3 costs more rounds' worth than it saves on the bench box (docs/methods.md).
MAX_COARSE_DEGREE = 4


def _coarse_degree(value: Any) -> int | str:
    if value == "auto":
        return value
    try:
        degree = _count(0)(value)
    except (TypeError, ValueError):
        degree = None
    if degree is None or degree > MAX_COARSE_DEGREE:
        raise ValueError(f'an integer from 0 (no polynomial coarse directions) to {MAX_COARSE_DEGREE}, or "auto" '
                         "(by the structure)") from None
    return degree


def _choice(options: tuple[str, ...]) -> Callable[[Any], str]:
    def checked(value: Any) -> str:
        value = _string(value)
        if value not in options:
            raise ValueError("one of " + ", ".join(options))
        return value
    return checked


def _interval(value: Any) -> tuple[float, ...] | Ellipse:
    """A crack: [a, b] along x (through the depth of a 3-D box), [a, b, c, d] the rectangle a < x < b, c < z < d
    of a 3-D box's Σ, an ellipse ``{center = [x, z], radii = [r1, r2]}`` on it, or [] for none."""
    if isinstance(value, dict):
        if ellipse(value) is None:
            raise ValueError("an ellipse {center = [x, z], radii = [r1, r2]} of finite numbers with radii > 0")
        return ellipse(value)
    values = _numbers(value)
    if values and _piece(values) is None:
        raise ValueError("[a, b] with a < b, or [] (a 3-D box also takes [a, b, c, d] with c < d and "
                         "{center = [x, z], radii = [r1, r2]})")
    return values


def _piece(values: tuple[float, ...]) -> tuple[float, ...] | None:
    """An interval [a, b] (a < b) or a rectangle [a, b, c, d] (a < b, c < d) of finite numbers, or None."""
    if len(values) not in (2, 4) or not all(low < high for low, high in zip(values[::2], values[1::2])):
        return None
    return values


def _heights(value: Any) -> float | tuple[float, ...]:
    """Σ's height, or the heights of several interfaces bottom to top (``[y1, y2, ...]``, strictly increasing)."""
    if not isinstance(value, list):
        return _number(value)
    try:
        heights = _numbers(value)
    except (TypeError, ValueError) as exc:
        raise type(exc)(f"a number or a list [y1, y2, ...] of heights, each {exc}") from None
    if not heights:
        raise ValueError("a number or a list [y1, y2, ...] of at least one height")
    crossing = next((k for k in range(1, len(heights)) if not heights[k - 1] < heights[k]), None)
    if crossing is not None:
        raise Invalid(f"interfaces {crossing} and {crossing + 1} cross or touch (y = {heights[crossing - 1]:g} and "
                      f"{heights[crossing]:g}): give the heights bottom to top, strictly increasing")
    return heights


class PerInterface(tuple):
    """``geometry.cracks`` given as one list of intervals per interface, bottom to top."""


def _crack_lists(value: Any) -> tuple[tuple[float, float], ...] | PerInterface:
    """The cracks of one interface (``[[a, b], ...]``), or a list of them per interface (``[[[a, b], ...], ...]``;
    an interface without cracks has ``[]``)."""
    nested = isinstance(value, list) and any(
        item == [] or isinstance(item, list) and isinstance(item[0], (list, dict)) for item in value)
    if not nested:
        return _intervals(value)
    try:
        return PerInterface(_intervals(item) for item in value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"one list of intervals per interface, each {exc}") from None


def _crack_piece(item: Any) -> tuple[float, ...] | Ellipse | None:
    """An interval [a, b], a 3-D rectangle [a, b, c, d] of finite numbers (:func:`_piece`) or an ellipse
    (:func:`ddsolve.problem.shapes.ellipse`), or None."""
    if isinstance(item, dict):
        return ellipse(item)
    try:
        return _piece(_numbers(item)) if isinstance(item, list) else None
    except (TypeError, ValueError):
        return None


def _intervals(value: Any) -> tuple[tuple[float, ...], ...]:
    """Disjoint cracks along x: [a, b] intervals, or in 3-D [a, b, c, d] rectangles (disjoint in x too)."""
    if not isinstance(value, list):
        raise TypeError("a list of [a, b] intervals")
    pieces = []
    for item in value:
        piece = _crack_piece(item)
        if piece is None:
            raise ValueError("a list of [a, b] intervals of finite numbers with a < b (in 3-D also [a, b, c, d] "
                             "rectangles with c < d and ellipses {center = [x, z], radii = [r1, r2]})")
        pieces.append(piece)
    pieces.sort(key=bounds)
    for first, second in zip(pieces[:-1], pieces[1:]):
        if bounds(second)[0] <= bounds(first)[1]:
            raise ValueError("a list of disjoint [a, b] intervals (they overlap or touch)")
    return tuple(pieces)


def _sides(value: Any) -> tuple[str, ...]:
    """Side names of a box (a 3-D box's front and back too: the rules refuse them in the plane)."""
    names = SIDES + DEPTH_SIDES
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise TypeError("a list of side names (" + ", ".join(names) + ")")
    unknown = [v for v in value if v not in names]
    if unknown:
        raise ValueError("a list of side names among " + ", ".join(names) + f" ({unknown[0]!r} is not one)")
    return tuple(dict.fromkeys(value))


def _box(value: Any) -> tuple[float, ...]:
    """[x0, x1, y0, y1], or [x0, x1, y0, y1, z0, z1] for a 3-D box; each range increasing."""
    values = _numbers(value)
    if len(values) not in (4, 6):
        raise ValueError("a list of 4 numbers [x0, x1, y0, y1] (or 6 for a 3-D box: [x0, x1, y0, y1, z0, z1])")
    if not all(low < high for low, high in zip(values[::2], values[1::2])):
        raise ValueError("[x0, x1, y0, y1] with x0 < x1 and y0 < y1 (3-D: [x0, x1, y0, y1, z0, z1], z0 < z1)")
    return values


def _count(minimum: int) -> Callable[[Any], int]:
    def checked(value: Any) -> int:
        value = _integer(value)
        if value < minimum:
            raise ValueError(f"at least {minimum}")
        return value
    return checked


def _layers(value: Any) -> int:
    value = _integer(value)
    if value not in (1, 2):
        raise ValueError("1 (one body) or 2 (two sheets glued on Σ)")
    return value


def _degree(value: Any) -> int:
    value = _integer(value)
    if value not in (1, 2):
        raise ValueError("1 (P1 triangles) or 2 (P2 triangles)")
    return value


def _grading(value: Any) -> bool | float:
    """true (μ for the element degree, resolved later), false, or μ itself in (0, 1)."""
    if isinstance(value, bool):
        return value
    value = _number(value)
    if not 0.0 < value < 1.0:
        raise ValueError("true, false or a grading exponent μ with 0 < μ < 1")
    return value


def _toughness(value: Any) -> float | tuple[float, ...]:
    """G_c > 0 for every tip, or a list of them, one per crack."""
    try:
        return _positive(_number)(value) if not isinstance(value, list) else tuple(_positive(_number)(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError("a number > 0 (every tip) or a list of numbers > 0 (one per crack)") from None


#: The largest friction coefficient or slip bound: far beyond it the faces stick wherever they touch, and the
#: bounds (μ times the contact pressure, over the rows' norms) leave double precision.
MAX_FRICTION = 1e100


def _per_crack(value: Any) -> float | tuple[float, ...]:
    """A value in [0, MAX_FRICTION] for every crack, or a list of them, one per crack in order along Σ."""
    def checked(item: Any) -> float:
        item = _number(item)
        if not 0.0 <= item <= MAX_FRICTION:
            raise ValueError
        return abs(item)  # -0.0 is 0
    try:
        return checked(value) if not isinstance(value, list) else tuple(checked(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"a number >= 0 up to {MAX_FRICTION:g} (every crack) or a list of them (one per crack); "
                         f"long before {MAX_FRICTION:g} the faces stick wherever they touch") from None


def _unit(value: Any) -> float:
    value = _number(value)
    if not 0.0 <= value <= 1.0:
        raise ValueError("in [0, 1]")
    return value


#: The largest fibre angle in degrees (a double places it within 1e-10 degree; beyond, the angle loses meaning).
MAX_ANGLE = 1e6


def _angle(value: Any) -> float:
    value = _number(value)
    if abs(value) > MAX_ANGLE:
        raise ValueError(f"an angle in degrees of magnitude at most {MAX_ANGLE:g} (a double cannot place a "
                         "larger one: give it modulo 360)")
    return value


def _fraction(value: Any) -> float:
    value = _number(value)
    if not 0.0 < value < 1.0:
        raise ValueError("a relative error between 0 and 1 (0.01 is 1 %)")
    return value


def _load_value(value: Any) -> Expression:
    """A number, a list of polynomial coefficients in x (lowest degree first), or an expression string."""
    if isinstance(value, str):
        try:
            return expressions.parse(value)
        except expressions.ExpressionError as exc:
            raise Invalid(f"bad expression {printable(excerpt(value, exc.position))!r}: {exc}") from None
    if isinstance(value, list):
        if len(value) > expressions.MAX_DEGREE + 1:
            raise Invalid(f"{len(value)} polynomial coefficients, more than the {expressions.MAX_DEGREE + 1} of "
                          f"degree {expressions.MAX_DEGREE} (the highest that quadrature integrates exactly)")
        return expressions.polynomial_in_x(_numbers(value))
    try:
        return expressions.constant(_number(value))
    except (TypeError, ValueError):
        raise TypeError("a number, a list of coefficients in x or an expression string") from None


ISOTROPIC = {"E": (_positive(_number), REQUIRED), "nu": (_poisson, REQUIRED), "alpha": (_number, None)}
ORTHOTROPIC = {"E1": (_positive(_number), REQUIRED), "E2": (_positive(_number), REQUIRED),
                "G12": (_positive(_number), REQUIRED), "nu12": (_number, REQUIRED), "angle": (_angle, 0.0),
                "E3": (_positive(_number), None), "nu13": (_number, None), "nu23": (_number, None),
                "alpha1": (_number, None), "alpha2": (_number, None), "fibre": (_fixed_numbers(3), None)}
ANISOTROPIC = {"D": (_matrix3, REQUIRED), "Dzz": (_fixed_numbers(3), [0.0, 0.0, 0.0])}


#: The kinds of material in the order their keys decide (a matrix first), with the noun messages use.
_NAMING = ((ANISOTROPIC, "a matrix"), (ORTHOTROPIC, "an orthotropic"), (ISOTROPIC, "an isotropic"))


def _kind(raw: dict) -> dict | None:
    """The kind (schema) a material table's keys name: the first kind of which it has a key no other kind has
    (the expansion coefficients name none); None when they name none (only α keys, or no key)."""
    for kind, _ in _NAMING:
        others = {key for other, _ in _NAMING if other is not kind for key in other}
        if any(key in kind and key not in others and not key.startswith("alpha") for key in raw):
            return kind
    return None


def region_names(count: int) -> tuple[str, ...]:
    """The names of the ``count`` regions of Ω, bottom to top: :data:`REGIONS` (``lower``, ``upper``) for one
    interface, ``region1`` ... ``regionR`` for several."""
    return REGIONS if count == len(REGIONS) else tuple(NUMBERED_REGION.format(k) for k in range(1, count + 1))


def _material_schema(regions: tuple[str, ...]) -> Callable[[dict], dict]:
    """The schema of a layer's material: its kind follows from its keys (D: a matrix; E1, E2, ...: orthotropic;
    else E, nu), and each region of Ω (``regions``) may override its keys in a table of that name."""
    def schema(raw: dict) -> dict:
        kind = _kind(raw) or ISOTROPIC
        return {**kind, **{region: _region_schema(raw, kind) for region in regions}}
    return schema


def _region_schema(layer: dict, kind: dict) -> Callable[[dict], dict]:
    """The schema of a region's table in a ``layer`` table of ``kind``: of the same kind (its keys name no other),
    the layer's keys are its defaults; of another kind it is a whole material (no key comes from the layer)."""
    def schema(raw: dict) -> dict:
        own = _kind(raw) or kind
        if own is kind:
            return {key: (check, layer.get(key, default)) for key, (check, default) in kind.items()}
        missing = [key for key, (_, default) in own.items() if default is REQUIRED and key not in raw]
        if missing:
            noun = next(noun for other, noun in _NAMING if other is own)
            raise Invalid(f"names keys of {noun} material, not the layer's kind, so it must be a whole material: "
                          f"missing {', '.join(missing)}")
        return own
    return schema


_LOAD = {"x": (_load_value, None), "y": (_load_value, None), "z": (_load_value, None), "pressure": (_load_value, None)}
_DISPLACEMENT = {"x": (_load_value, None), "y": (_load_value, None), "z": (_load_value, None),
                 "normal": (_load_value, None),
                 "point": (_fixed_numbers(2), None)}

SCHEMA: dict[str, Any] = {
    "title": (_string, ""),
    "geometry": {
        "box": (_box, list(PAPER_BOX)),
        "sigma": (_heights, None),
        "crack": (_interval, None),
        "cracks": (_crack_lists, None),
        "clamped": (_sides, ["left", "right"]),
        "layers": (_layers, 2),
    },
    "mesh": {
        "file": (_string, None),
        "sigma_vertices": (_count(5), None),
        "boundary_vertices": (_count(8), None),
        "size": (_positive(_number), None),
        "degree": (_degree, 1),
        "grading": (_grading, None),
        "target_error": (_fraction, None),
        "refine": (_count(0), None),
        "extrude": (_count(1), None),
    },
    "materials": {
        "model": (_choice(materials.MODELS), "plane_strain"),
        **{layer: _material_schema(REGIONS) for layer in LAYERS},
    },
    "loads": {layer: Tables(_LOAD) for layer in LAYERS},
    "displacements": {layer: Tables(_DISPLACEMENT) for layer in LAYERS},
    "temperature": {layer: (_load_value, None) for layer in LAYERS},
    "contact": {"nonpenetration": (_boolean, True), "friction": (_per_crack, None),
                "slip_bound": (_per_crack, None)},
    "solver": {
        "method": (_choice(tuple(OPTIONS)), AUTO.name),
        "theta": (_step, None),
        "p": (_positive(_number), None),
        "tol": (_positive(_number), None),
        "stop": (_choice(STOP_RULES), None),
        "max_iterations": (_count(1), 20000),
        "out_of_core": (_boolean, False),
        "pieces": (_pieces, "auto"),
        "preconditioner": (_choice(PRECONDITIONERS), "auto"),
        "coarse_degree": (_coarse_degree, "auto"),
    },
    "fracture": {"inner": (_positive(_number), None), "outer": (_positive(_number), None),
                 "toughness": (_toughness, None), "law": (_choice(tuple(LAWS)), None),
                 "G_Ic": (_positive(_number), None), "G_IIc": (_positive(_number), None),
                 "eta": (_positive(_number), None), "lambda": (_unit, None),
                 "reference_length": (_positive(_number), None)},
    "interface": {"law": (_choice(BOND_LAWS), None), "stiffness": (_positive(_number), None),
                  "strength": (_positive(_number), None), "toughness": (_positive(_number), None),
                  "mode_mix": (_choice(MODE_MIXES), None), "G_IIc": (_positive(_number), None),
                  "eta": (_positive(_number), None), "shear_strength": (_positive(_number), None)},
}
# Tables that exist only when the scene writes them (a boundary without a load is not integrated).
# A region's table in a layer's material (materials.LAYER.REGION) is optional too (:func:`_optional`).
OPTIONAL_TABLES = {("loads",), *(("loads", layer) for layer in LAYERS), ("displacements",),
                   *(("displacements", layer) for layer in LAYERS), ("temperature",)}


def _optional(path: tuple[str, ...]) -> bool:
    """Whether the table at ``path`` exists only when the scene writes it."""
    return path in OPTIONAL_TABLES or path[:1] == ("materials",) and len(path) == 3


def is_solid(raw: dict) -> bool:
    """Whether a raw scene is three-dimensional: its ``geometry.box`` has six numbers (one body, one layer)."""
    geometry = raw.get("geometry")
    box = geometry.get("box") if isinstance(geometry, dict) else None
    return isinstance(box, list) and len(box) == 6


def region_count(raw: dict) -> int:
    """The regions of Ω a raw scene describes: one more than its interfaces (``geometry.sigma`` as a list), 2
    otherwise (its value is checked with the rest of the table)."""
    geometry = raw.get("geometry")
    heights = geometry.get("sigma") if isinstance(geometry, dict) else None
    return len(heights) + 1 if isinstance(heights, list) and heights else len(REGIONS)


def structure_schema(raw: dict, origin: str, regions: tuple[str, ...] = (), solid: bool = False) -> dict:
    """The schema of the structure the raw scene describes: :data:`SCHEMA` with two layers and two regions; with
    one layer (``geometry.layers = 1``), without layer2's tables, and a layer2 table or key in the scene is refused;
    with several interfaces, the layers' region tables are ``region1`` ... (:func:`region_names`), or ``regions``
    (a gmsh file's region surfaces); ``solid``: a 3-D body (a 6-number box or a 3-D gmsh file), one layer."""
    solid = solid or is_solid(raw)
    geometry = raw.get("geometry")
    written = {"layers": geometry["layers"]} if isinstance(geometry, dict) and "layers" in geometry else (
        {"layers": 1} if solid else {})
    layers = check_table(written, {"layers": SCHEMA["geometry"]["layers"]}, ("geometry",), origin)["layers"]
    if layers != 1 and solid:
        raise SceneError(f"{origin}: geometry.layers: a 3-D box is one body (layers = 1): the plane's layers are "
                         "sheets over the same plane domain, stacked through a thickness that a 3-D body meshes itself; "
                         "its regions below and above Σ take materials.layer1.lower and materials.layer1.upper")
    regions = regions or region_names(region_count(raw))
    schema = SCHEMA if regions == REGIONS else {
        **SCHEMA, "materials": {**SCHEMA["materials"], **{layer: _material_schema(regions) for layer in LAYERS}}}
    if layers == len(LAYERS):
        return schema
    for section in LAYERED_TABLES:
        table = raw.get(section)
        extra = [layer for layer in LAYERS[layers:] if isinstance(table, dict) and layer in table]
        if extra:
            inner = table[extra[0]]
            region = next((key for key in inner if key in regions), None) if isinstance(inner, dict) else None
            key = ".".join((section, extra[0], *((region,) if region else ())))
            raise SceneError(f"{origin}: {key}: a structure of {layers} layer (geometry.layers = {layers}) has no "
                             f"{extra[0]}")
    return {**schema, **{section: {key: spec for key, spec in schema[section].items() if key not in LAYERS[layers:]}
                         for section in LAYERED_TABLES}}


def check_table(raw: dict, schema: dict, path: tuple[str, ...], origin: str) -> dict:
    """Validate one table against its schema; return the checked values (defaults filled in)."""
    for key in raw:
        if key not in schema:
            dotted = printable(".".join((*path, key)))
            if isinstance(raw[key], dict) and path[:1] == ("materials",) and len(path) in (2, 3):
                regions = [name for name, spec in schema.items() if not isinstance(spec, tuple)]
                raise SceneError(f"{origin}: {dotted}: " + (
                    f"no region of that name (the regions of Ω, bottom to top: {', '.join(regions)})"
                    if len(path) == 2 else "a region's table holds a material's keys, not another table (the "
                    "regions' tables sit in their layer's: materials.LAYER.REGION)"))
            close = difflib.get_close_matches(key, list(schema), n=1)
            hint = f" (did you mean {'.'.join((*path, close[0]))}?)" if close else ""
            valid = ", ".join(sorted(schema))
            raise SceneError(f"{origin}: unknown key {dotted}{hint}; valid here: {valid}")
    out = {}
    for key, spec in schema.items():
        dotted = printable(".".join((*path, key)))
        if not isinstance(spec, tuple):  # a table
            if key not in raw:
                if _optional((*path, key)):
                    continue
                sub = {}
            else:
                sub = raw[key]
                if not isinstance(sub, dict):
                    raise SceneError(f"{origin}: {dotted} must be a table")
            if isinstance(spec, Tables):
                out[key] = {}
                for name, table in sub.items():
                    if not isinstance(table, dict):
                        raise SceneError(f"{origin}: {printable('.'.join((*path, key, name)))} must be a table")
                    out[key][name] = check_table(table, spec.schema, (*path, key, name), origin)
            else:
                out[key] = check_table(sub, spec if isinstance(spec, dict) else _chosen(spec, sub, dotted, origin),
                                       (*path, key), origin)
            continue
        check, default = spec
        if key not in raw:
            if default is REQUIRED:
                raise SceneError(f"{origin}: missing key {dotted}")
            out[key] = default if default is None else check(default)
            continue
        try:
            out[key] = check(raw[key])
        except Invalid as exc:
            raise SceneError(f"{origin}: {dotted}: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise SceneError(f"{origin}: {dotted} must be {exc} (got {printable(repr(raw[key]))})") from None
    return out


def _chosen(spec: Callable[[dict], dict], raw: dict, dotted: str, origin: str) -> dict:
    """The schema ``spec`` chooses for the table ``raw`` (at ``dotted``), its refusal as a scene error."""
    try:
        return spec(raw)
    except Invalid as exc:
        raise SceneError(f"{origin}: {dotted}: {exc}") from None


def layer_material(table: dict) -> materials.Material:
    """A layer's (or a region's) material from its checked table (its kind follows from its keys; the regions'
    tables in it are left out)."""
    table = {key: value for key, value in table.items()
             if not isinstance(value, dict) and not (key.startswith("alpha") and value is None)}
    if "D" in table:
        return materials.Anisotropic(D=table["D"], Dzz=table["Dzz"])
    if "E1" in table:
        return materials.Orthotropic(**table)
    return materials.Isotropic(**table)


def region_materials(tables: dict) -> dict[tuple[str, str], materials.Material]:
    """(layer, region) -> the material of each region that a checked ``materials`` table overrides."""
    return {(layer, region): layer_material(table) for layer in LAYERS if layer in tables
            for region, table in tables[layer].items() if isinstance(table, dict)}


def layers_of(data: dict) -> tuple[str, ...]:
    """The layers of a checked scene's structure (``geometry.layers`` of :data:`LAYERS`)."""
    return LAYERS[:data["geometry"]["layers"]]
