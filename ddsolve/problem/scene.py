"""Scene files: one problem (geometry, mesh, materials, loads, contact, solver) in TOML.

A scene is parsed into plain dataclasses after every key has been checked against ``SCHEMA``;
unknown keys, wrong types and out-of-range values raise :class:`SceneError` with a one-line
message naming the key.  ``--set section.key=value`` overrides are applied to the raw tables
before validation, so they are checked exactly like the file.
"""
from __future__ import annotations

import codecs
import dataclasses
import difflib
import math
import os
import re
import stat
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Callable, Sequence

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

from ddsolve.errors import DDSolveError, SceneError
from ddsolve.problem import expressions, materials
from ddsolve.problem.expressions import Expression
from ddsolve.problem.method_options import AUTO, OPTIONS

STOP_RULES = ("paper", "relative", "kkt")
#: Default tolerance of each stopping rule (a method's default rule: :mod:`ddsolve.problem.method_options`).
DEFAULT_TOL = {"paper": 1e-6, "relative": 1e-6, "kkt": 1e-8}
LAYERS = ("layer1", "layer2")
#: The sides of a box geometry, as boundary names.
SIDES = ("bottom", "top", "left", "right")
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
LAWS = {"benzeggagh-kenane": ("G_Ic", "G_IIc", "eta"), "hutchinson-suo": ("G_Ic", "lambda")}


@dataclass(frozen=True)
class Geometry:
    """A box (x0, x1, y0, y1) cut by Σ at height ``sigma``, cracks as x intervals on Σ, clamped sides.

    A ``.geo`` or ``.msh`` file with physical groups replaces all of it; ``given`` lists the keys the
    scene wrote, so that such a file can refuse them.
    """

    box: tuple[float, float, float, float] = PAPER_BOX
    sigma: float = 0.0
    cracks: tuple[tuple[float, float], ...] = (PAPER_CRACK,)
    clamped: tuple[str, ...] = ("left", "right")
    given: frozenset[str] = field(default=frozenset(), compare=False)


@dataclass(frozen=True)
class MeshOptions:
    """How the halves are meshed: the paper's family (P, M), a size, or a file; element degree.

    ``grading`` is the exponent μ of the grading towards the singular points (None: no grading);
    ``target_error`` the relative energy-norm error at which adaptive refinement stops (None: no
    adaptivity); ``refine`` the levels of uniform refinement of a coarse gmsh mesh that make the mesh
    (None: chosen by size, see :func:`ddsolve.mesh.geometry.refinement`; 0: gmsh makes the mesh itself).
    """

    file: Path | None = None
    sigma_vertices: int | None = None
    boundary_vertices: int | None = None
    size: float | None = None
    degree: int = 1
    grading: float | None = None
    target_error: float | None = None
    refine: int | None = None

    @property
    def kind(self) -> str:
        """``box`` (generated), ``geo`` (a gmsh script, meshed here) or ``file`` (a mesh to read)."""
        if self.file is None:
            return "box"
        return "geo" if self.file.suffix.lower() == ".geo" else "file"


@dataclass(frozen=True)
class Load:
    """A traction (x and y components) or a normal pressure on the boundary ``key`` names.

    Each part is an expression in x and y, or None (zero).  ``key`` is ``loads.LAYER.NAME``.
    """

    key: str
    x: Expression | None = None
    y: Expression | None = None
    pressure: Expression | None = None

    @property
    def boundary(self) -> str:
        return self.key.rsplit(".", 1)[1]


@dataclass(frozen=True)
class Displacement:
    """Prescribed displacement components on the boundary or named point ``key`` names
    (``displacements.LAYER.NAME``), or at ``point`` (x, y), a mesh vertex on the boundary or Σ: x and y,
    or the normal component (boundaries only); each an expression in x and y, or None (that component
    is free)."""

    key: str
    x: Expression | None = None
    y: Expression | None = None
    normal: Expression | None = None
    point: tuple[float, float] | None = None

    @property
    def boundary(self) -> str:
        return self.key.rsplit(".", 1)[1]

    @property
    def layer(self) -> str:
        return self.key.split(".")[1]


@dataclass(frozen=True)
class Solver:
    method: str
    theta: float | str | None  # Uzawa's step, or "auto"; the other methods need none
    p: float | None  # multiplier bound; None: μᶜ ≥ 0 only
    tol: float
    stop: str
    max_iterations: int
    out_of_core: bool = False  # MUMPS keeps the blocks' factors on disk


@dataclass(frozen=True)
class FractureOptions:
    """Radii of the θ field of the energy release rate (None: from the geometry, see ddsolve.post.fracture),
    and the toughness G_c (see :mod:`ddsolve.post.toughness`): ``toughness`` one value for every tip or one
    per crack in order along Σ, or a mode-dependent ``law`` (:data:`LAWS`) with its constants ``G_Ic``,
    ``G_IIc``, ``eta`` (Benzeggagh–Kenane) or ``G_Ic``, ``lambda_`` (Hutchinson–Suo; the key ``lambda``)."""

    inner: float | None = None
    outer: float | None = None
    toughness: float | tuple[float, ...] | None = None
    law: str | None = None
    G_Ic: float | None = None
    G_IIc: float | None = None
    eta: float | None = None
    lambda_: float | None = None


@dataclass(frozen=True)
class Scene:
    title: str
    geometry: Geometry
    mesh: MeshOptions
    materials: dict[str, materials.Material]
    model: str  # plane_strain | plane_stress
    loads: dict[tuple[str, str], Load]  # (layer, boundary name) -> load
    nonpenetration: bool
    solver: Solver
    fracture: FractureOptions = FractureOptions()
    #: (layer, boundary name) -> prescribed displacement; ``geometry.clamped`` is the shorthand for zero.
    displacements: dict[tuple[str, str], Displacement] = field(default_factory=dict)
    #: layer -> temperature change ΔT (an expression in x and y); absent: no thermal load.
    temperature: dict[str, Expression] = field(default_factory=dict)
    text: str = field(repr=False, default="")
    #: The text the scene was read from and the ``--set`` items applied to it, in order: what
    #: :meth:`with_` reads again, so that defaults that follow other keys follow the new values too.
    source: str = field(repr=False, default="", compare=False)
    overrides: tuple[str, ...] = field(repr=False, default=(), compare=False)
    #: Where the scene came from (named in messages) and the folder its file names are relative to.
    origin: str = field(repr=False, default="scene", compare=False)
    base: Path | None = field(repr=False, default=None, compare=False)

    @classmethod
    def load(cls, source: str | Path, overrides: dict[str, Any] | Sequence[str] = ()) -> Scene:
        """A scene from a file path or a built-in name (``ddsolve scenes``), with ``overrides``: dotted
        keys and values (``{"solver.tol": 1e-10}``) or ``KEY=VALUE`` items as ``--set`` takes them."""
        return load(source, override_items(overrides))

    def with_(self, overrides: dict[str, Any] | Sequence[str] = (), **more: Any) -> Scene:
        """This scene with some keys changed, validated as a scene file is:
        ``scene.with_({"materials.layer2.E": 20.0})`` or ``scene.with_(**{"solver.tol": 1e-10})``.
        The same scene as :meth:`load` with all the overrides: its source is read again with them, so a
        default that follows another key (``mesh.target_error`` chooses P2) follows the new value."""
        items = override_items(overrides) + override_items(more)
        return loads(self.source or self.text, [*self.overrides, *items], origin=self.origin, base=self.base)

    def scaled(self, factor: float) -> Scene:
        """This scene with every mechanical load (tractions, pressures, prescribed displacements) times
        ``factor``; the temperature change is kept.  The contact problem is positively homogeneous, so
        without a temperature change the solution scales by ``factor`` and G by its square.  ``text`` is
        the unscaled scene's: a scaled scene is solved, not saved."""
        def times(table, fields):
            return {key: dataclasses.replace(item, **{name: None if getattr(item, name) is None else
                                                      expressions.scaled(getattr(item, name), factor)
                                                      for name in fields})
                    for key, item in table.items()}

        return dataclasses.replace(self, loads=times(self.loads, ("x", "y", "pressure")),
                                   displacements=times(self.displacements, ("x", "y", "normal")))


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


def _choice(options: tuple[str, ...]) -> Callable[[Any], str]:
    def checked(value: Any) -> str:
        value = _string(value)
        if value not in options:
            raise ValueError("one of " + ", ".join(options))
        return value
    return checked


def _interval(value: Any) -> tuple[float, ...]:
    values = _numbers(value)
    if values and (len(values) != 2 or not values[0] < values[1]):
        raise ValueError("[a, b] with a < b, or []")
    return values


def _intervals(value: Any) -> tuple[tuple[float, float], ...]:
    if not isinstance(value, list):
        raise TypeError("a list of [a, b] intervals")
    pieces = []
    for item in value:
        piece = _numbers(item) if isinstance(item, list) else None
        if piece is None or len(piece) != 2 or not piece[0] < piece[1]:
            raise ValueError("a list of [a, b] intervals with a < b")
        pieces.append(piece)
    pieces.sort()
    for (_, b), (a, _) in zip(pieces[:-1], pieces[1:]):
        if a <= b:
            raise ValueError("a list of disjoint [a, b] intervals (they overlap or touch)")
    return tuple(pieces)


def _sides(value: Any) -> tuple[str, ...]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise TypeError("a list of side names (" + ", ".join(SIDES) + ")")
    unknown = [v for v in value if v not in SIDES]
    if unknown:
        raise ValueError("a list of side names among " + ", ".join(SIDES) + f" ({unknown[0]!r} is not one)")
    return tuple(dict.fromkeys(value))


def _box(value: Any) -> tuple[float, ...]:
    values = _fixed_numbers(4)(value)
    if not (values[0] < values[1] and values[2] < values[3]):
        raise ValueError("[x0, x1, y0, y1] with x0 < x1 and y0 < y1")
    return values


def _count(minimum: int) -> Callable[[Any], int]:
    def checked(value: Any) -> int:
        value = _integer(value)
        if value < minimum:
            raise ValueError(f"at least {minimum}")
        return value
    return checked


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
            raise Invalid(f"bad expression {printable(_excerpt(value, exc.position))!r}: {exc}") from None
    if isinstance(value, list):
        if len(value) > expressions.MAX_DEGREE + 1:
            raise Invalid(f"{len(value)} polynomial coefficients, more than the {expressions.MAX_DEGREE + 1} of "
                          f"degree {expressions.MAX_DEGREE} (the highest that quadrature integrates exactly)")
        return expressions.polynomial_in_x(_numbers(value))
    try:
        return expressions.constant(_number(value))
    except (TypeError, ValueError):
        raise TypeError("a number, a list of coefficients in x or an expression string") from None


_ISOTROPIC = {"E": (_positive(_number), REQUIRED), "nu": (_poisson, REQUIRED), "alpha": (_number, None)}
_ORTHOTROPIC = {"E1": (_positive(_number), REQUIRED), "E2": (_positive(_number), REQUIRED),
                "G12": (_positive(_number), REQUIRED), "nu12": (_number, REQUIRED), "angle": (_angle, 0.0),
                "E3": (_positive(_number), None), "nu13": (_number, None), "nu23": (_number, None),
                "alpha1": (_number, None), "alpha2": (_number, None)}
_ANISOTROPIC = {"D": (_matrix3, REQUIRED), "Dzz": (_fixed_numbers(3), [0.0, 0.0, 0.0])}


def _material_schema(raw: dict) -> dict:
    """The material's kind follows from its keys: D (a matrix), E1, E2, ... (orthotropic) or E, nu."""
    if "D" in raw:
        return _ANISOTROPIC
    if any(key in _ORTHOTROPIC and key not in _ISOTROPIC and not key.startswith("alpha") for key in raw):
        return _ORTHOTROPIC
    return _ISOTROPIC


_LOAD = {"x": (_load_value, None), "y": (_load_value, None), "pressure": (_load_value, None)}
_DISPLACEMENT = {"x": (_load_value, None), "y": (_load_value, None), "normal": (_load_value, None),
                 "point": (_fixed_numbers(2), None)}

SCHEMA: dict[str, Any] = {
    "title": (_string, ""),
    "geometry": {
        "box": (_box, list(PAPER_BOX)),
        "sigma": (_number, None),
        "crack": (_interval, None),
        "cracks": (_intervals, None),
        "clamped": (_sides, ["left", "right"]),
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
    },
    "materials": {
        "model": (_choice(materials.MODELS), "plane_strain"),
        **{layer: _material_schema for layer in LAYERS},
    },
    "loads": {layer: Tables(_LOAD) for layer in LAYERS},
    "displacements": {layer: Tables(_DISPLACEMENT) for layer in LAYERS},
    "temperature": {layer: (_load_value, None) for layer in LAYERS},
    "contact": {"nonpenetration": (_boolean, True)},
    "solver": {
        "method": (_choice(tuple(OPTIONS)), AUTO.name),
        "theta": (_step, None),
        "p": (_positive(_number), None),
        "tol": (_positive(_number), None),
        "stop": (_choice(STOP_RULES), None),
        "max_iterations": (_count(1), 20000),
        "out_of_core": (_boolean, False),
    },
    "fracture": {"inner": (_positive(_number), None), "outer": (_positive(_number), None),
                 "toughness": (_toughness, None), "law": (_choice(tuple(LAWS)), None),
                 "G_Ic": (_positive(_number), None), "G_IIc": (_positive(_number), None),
                 "eta": (_positive(_number), None), "lambda": (_unit, None)},
}
# Tables that exist only when the scene writes them (a boundary without a load is not integrated).
OPTIONAL_TABLES = {("loads",), *(("loads", layer) for layer in LAYERS), ("displacements",),
                   *(("displacements", layer) for layer in LAYERS), ("temperature",)}


def _excerpt(text: str, position: int, width: int = 60) -> str:
    """``text`` for a message: whole if short, else the ``width`` characters around ``position`` (1-based)."""
    if len(text) <= width:
        return text
    start = max(0, min(position - 1 - width // 2, len(text) - width))
    return (f"{'...' if start else ''}{text[start:start + width]}{'...' if start + width < len(text) else ''}"
            f" ({len(text)} characters)")


def printable(text: str) -> str:
    """``text`` for a one-line message: as is if printable, else escaped."""
    return text if text.isprintable() else repr(text)[1:-1]


def _check_table(raw: dict, schema: dict, path: tuple[str, ...], origin: str) -> dict:
    """Validate one table against its schema; return the checked values (defaults filled in)."""
    for key in raw:
        if key not in schema:
            dotted = printable(".".join((*path, key)))
            close = difflib.get_close_matches(key, list(schema), n=1)
            hint = f" (did you mean {'.'.join((*path, close[0]))}?)" if close else ""
            valid = ", ".join(sorted(schema))
            raise SceneError(f"{origin}: unknown key {dotted}{hint}; valid here: {valid}")
    out = {}
    for key, spec in schema.items():
        dotted = printable(".".join((*path, key)))
        if not isinstance(spec, tuple):  # a table
            if key not in raw:
                if (*path, key) in OPTIONAL_TABLES:
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
                    out[key][name] = _check_table(table, spec.schema, (*path, key, name), origin)
            else:
                out[key] = _check_table(sub, spec if isinstance(spec, dict) else spec(sub), (*path, key), origin)
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


def _cross_checks(data: dict, raw: dict, origin: str) -> None:
    """Rules between keys; fills in the defaults that depend on other keys."""
    geometry, mesh = data["geometry"], data["mesh"]
    given = set(raw.get("geometry", {})) if isinstance(raw.get("geometry"), dict) else set()
    if "crack" in given and "cracks" in given:
        raise SceneError(f"{origin}: geometry.crack and geometry.cracks exclude each other (cracks = [[a, b], ...])")
    x0, x1, y0, y1 = geometry["box"]
    if geometry["sigma"] is None:
        geometry["sigma"] = 0.5 * (y0 + y1)
    elif not y0 < geometry["sigma"] < y1:
        raise SceneError(f"{origin}: geometry.sigma = {geometry['sigma']:g} must lie strictly between the box's "
                         f"y0 = {y0:g} and y1 = {y1:g}")
    if "crack" in given:
        geometry["cracks"] = [list(geometry["crack"])] if geometry["crack"] else []
    elif "cracks" not in given:  # the paper's crack comes with the paper's square only
        geometry["cracks"] = [] if "box" in given else [list(PAPER_CRACK)]
    del geometry["crack"]
    crack_key = "geometry.crack" if "crack" in given else "geometry.cracks"
    for a, b in geometry["cracks"]:
        if a < x0 or b > x1:
            raise SceneError(f"{origin}: {crack_key}: the crack [{a:g}, {b:g}] leaves the box's "
                             f"x range [{x0:g}, {x1:g}]")
    breaks = sorted({x0, x1, *(tip for piece in geometry["cracks"] for tip in piece)})
    shortest = min(b - a for a, b in zip(breaks[:-1], breaks[1:]))
    feature = GEOMETRIC_TOLERANCE * max(x1 - x0, y1 - y0)
    if shortest <= feature:
        raise SceneError(f"{origin}: {crack_key}: two points of Σ (crack tips, box ends) are only {shortest:.2g} "
                         f"apart, within the meshing tolerance {feature:.2g} ({GEOMETRIC_TOLERANCE:g} × the box "
                         "size): lengthen, move or remove the crack")
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
    model = data["materials"]["model"]
    for layer in LAYERS:
        try:
            D, _ = materials.elasticity(_material(data["materials"][layer]), model)
        except materials.MaterialError as exc:
            raise SceneError(f"{origin}: materials.{layer}: {exc}") from None
        _check_conditioning(D, data["materials"][layer], model, f"{origin}: materials.{layer}")
    for layer, tables in data.get("loads", {}).items():
        for name, table in tables.items():
            if table["pressure"] is not None and (table["x"] is not None or table["y"] is not None):
                raise SceneError(f"{origin}: loads.{layer}.{printable(name)}: pressure excludes x and y "
                                 "(a pressure acts along the normal)")
    _displacement_checks(data, origin)
    _temperature_checks(data, origin)
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
    radii = data["fracture"]
    if None not in (radii["inner"], radii["outer"]) and radii["inner"] >= radii["outer"]:
        raise SceneError(f"{origin}: fracture.inner = {radii['inner']:g} must be below fracture.outer = "
                         f"{radii['outer']:g}")
    _toughness_checks(data, origin)


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
    values = options["toughness"]
    cracks = len(data["geometry"]["cracks"])
    if isinstance(values, tuple) and data["mesh"]["file"] is None and len(values) != cracks:
        raise SceneError(f"{origin}: fracture.toughness lists {len(values)} values for the {cracks} crack"
                         f"{'' if cracks == 1 else 's'} of geometry.cracks (one per crack, in order along Σ)")


def _temperature_checks(data: dict, origin: str) -> None:
    """A temperature change acts through the layer's expansion coefficients: a layer heated (ΔT not zero) must
    give them (``alpha``, or ``alpha1`` or ``alpha2``); a layer given by its matrix D takes none."""
    for layer, change in data.get("temperature", {}).items():
        if change is None or (change.constant and change(0.0, 0.0) == 0.0):
            continue
        table = data["materials"][layer]
        if "D" in table:
            raise SceneError(f"{origin}: temperature.{layer}: materials.{layer} is given by its matrix D, which takes "
                             "no thermal expansion, so the temperature change would do nothing: give the layer by "
                             "its constants with alpha, or leave the temperature change out")
        given = [key for key in ("alpha", "alpha1", "alpha2") if table.get(key) is not None]
        if not given:
            names = "alpha" if "E" in table else "alpha1 or alpha2"
            raise SceneError(f"{origin}: temperature.{layer}: materials.{layer} has no expansion coefficient, so the "
                             f"temperature change would do nothing: give materials.{layer}.{names}, or leave the "
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
        mesh["size"] = coarse_size(geometry["box"], geometry["sigma"])
    if "grading" not in given and mesh["size"] is not None:
        mesh["grading"] = True


#: The first mesh of an adaptive run on a box that gives no mesh size: elements of the box's width over
#: COARSE[0], and at least COARSE[1] through the thinner half, whichever is smaller (the paper's square: 0.1).
COARSE = (20, 2)


def coarse_size(box: Sequence[float], sigma: float) -> float:
    """The element size of an adaptive run's first mesh on ``box`` cut at ``sigma`` (:data:`COARSE`)."""
    x0, x1, y0, y1 = box
    return min((x1 - x0) / COARSE[0], min(sigma - y0, y1 - sigma) / COARSE[1])


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


def _material(table: dict) -> materials.Material:
    table = {key: value for key, value in table.items() if not (key.startswith("alpha") and value is None)}
    if "D" in table:
        return materials.Anisotropic(D=table["D"], Dzz=table["Dzz"])
    if "E1" in table:
        return materials.Orthotropic(**table)
    return materials.Isotropic(**table)


def _to_scene(data: dict, raw: dict, text: str, base: Path | None, origin: str, source: str,
              overrides: tuple[str, ...]) -> Scene:
    mesh = dict(data["mesh"])
    if mesh["file"] is not None:
        mesh["file"] = Path(mesh["file"])
        if not mesh["file"].is_absolute() and base is not None:
            mesh["file"] = base / mesh["file"]
    geometry = data["geometry"]
    given = frozenset(raw.get("geometry", {})) if isinstance(raw.get("geometry"), dict) else frozenset()
    loads = {
        (layer, name): Load(key=f"loads.{layer}.{name}", **table)
        for layer, tables in data.get("loads", {}).items()
        for name, table in tables.items()
    }
    displacements = {
        (layer, name): Displacement(key=f"displacements.{layer}.{name}", **table)
        for layer, tables in data.get("displacements", {}).items()
        for name, table in tables.items()
    }
    temperature = {layer: value for layer, value in data.get("temperature", {}).items() if value is not None}
    return Scene(
        title=data["title"],
        geometry=Geometry(box=tuple(geometry["box"]), sigma=geometry["sigma"],
                          cracks=tuple(tuple(piece) for piece in geometry["cracks"]),
                          clamped=tuple(geometry["clamped"]), given=given),
        mesh=MeshOptions(**mesh),
        materials={layer: _material(data["materials"][layer]) for layer in LAYERS},
        model=data["materials"]["model"],
        loads=loads,
        nonpenetration=data["contact"]["nonpenetration"],
        solver=Solver(**data["solver"]),
        fracture=FractureOptions(**{"lambda_" if key == "lambda" else key: value
                                    for key, value in data["fracture"].items()}),
        displacements=displacements,
        temperature=temperature,
        text=text,
        source=source,
        overrides=overrides,
        origin=origin,
        base=base,
    )



def override_items(overrides: dict[str, Any] | Sequence[str]) -> list[str]:
    """``KEY=VALUE`` items from a dict of dotted keys and Python values (numbers, booleans, text, lists,
    numpy scalars and arrays) or from items already written so (a list of them, or one)."""
    if isinstance(overrides, str):
        return [overrides]
    if not isinstance(overrides, (dict, list, tuple)):
        raise SceneError(f"overrides: a dict of dotted keys and values, or KEY=VALUE items (got "
                         f"{type(overrides).__name__})")
    wrong = [item for item in overrides if not isinstance(item, str)]
    if wrong:
        raise SceneError(f"overrides: {printable(repr(wrong[0]))[:40]} is not a " +
                         ("dotted key (text such as 'solver.tol')" if isinstance(overrides, dict) else
                          "KEY=VALUE item (text such as 'solver.tol=1e-10')"))
    if not isinstance(overrides, dict):
        return list(overrides)
    items = []
    for key, value in overrides.items():
        value = value.tolist() if hasattr(value, "tolist") else value  # numpy scalars and arrays
        try:
            items.append(f"{key}={_toml_value(value)}")
        except TypeError:
            raise SceneError(f"{printable(str(key))}: {type(value).__name__} is not a scene value "
                             "(a number, a boolean, a string, or a list or table of them)") from None
    return items


def parse_override(item: str) -> tuple[list[str], Any]:
    """``section.key=value`` -> (["section", "key"], value); value read as TOML, else a string."""
    key, sep, value = item.partition("=")
    path = key.strip().split(".")
    if not sep or not all(p.strip() for p in path):
        raise SceneError(f"--set {printable(item)}: expected KEY=VALUE with a dotted key, e.g. solver.tol=1e-8")
    try:
        parsed = tomllib.loads(f"value = {value.strip()}")["value"]
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    except RecursionError:  # tomllib's parser recurses into arrays and tables
        raise SceneError(f"--set {printable(_excerpt(item, 1))}: arrays or tables nested too deeply") from None
    return [p.strip() for p in path], parsed


#: An override replaces the keys that exclude the one it sets (``--set mesh.size=0.1`` on a scene
#: with P and M means: use a size instead).
REPLACES = {
    ("geometry", "crack"): ("cracks",), ("geometry", "cracks"): ("crack",),
    ("mesh", "size"): ("sigma_vertices", "boundary_vertices"),
    ("mesh", "file"): ("sigma_vertices", "boundary_vertices"),
    ("mesh", "sigma_vertices"): ("size", "file"), ("mesh", "boundary_vertices"): ("size", "file"),
}


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply ``--set`` items to a raw (unvalidated) scene table, in order.

    A number in the key indexes a list the scene has: ``geometry.crack.1=0.6`` moves the crack's end.
    """
    for item in overrides:
        path, value = parse_override(item)
        table = raw
        for depth, part in enumerate(path[:-1]):
            if isinstance(table, list):
                table = table[_list_index(table, path, depth, item)]
            elif part not in table and path[depth + 1].isdigit():
                raise SceneError(f"--set {printable(item)}: the scene has no {printable('.'.join(path[:depth + 1]))} "
                                 "to index; set the whole list")
            else:
                table = table.setdefault(part, {})
            if not isinstance(table, (dict, list)):
                raise SceneError(f"--set {printable(item)}: {printable('.'.join(path[:depth + 1]))} is not a table")
        if isinstance(table, list):
            table[_list_index(table, path, len(path) - 1, item)] = value
            continue
        for replaced in REPLACES.get(tuple(path), ()) or _other_laws(path):
            table.pop(replaced, None)
        table[path[-1]] = value
    return raw


def _other_laws(path: list[str]) -> tuple[str, ...]:
    """The keys of the other material laws, which a key that fixes a layer's law replaces
    (``--set materials.layer1.E1=...`` makes an isotropic layer orthotropic; α keys decide nothing)."""
    if len(path) != 3 or path[0] != "materials":
        return ()
    laws = [_ISOTROPIC, _ORTHOTROPIC, _ANISOTROPIC]
    mine = [law for law in laws if path[2] in law and not path[2].startswith("alpha")]
    return tuple(key for law in laws if mine and law is not mine[0] for key in law if key not in mine[0])


def _list_index(values: list, path: list[str], depth: int, item: str) -> int:
    """``path[depth]`` as an index into ``values`` (the list at ``path[:depth]``)."""
    part = path[depth]
    if not part.isdigit() or int(part) >= len(values):
        raise SceneError(f"--set {printable(item)}: {printable('.'.join(path[:depth]))} is a list of "
                         f"{len(values)}; {printable(part)} is not an index into it (0 to {len(values) - 1})")
    return int(part)


def builtin_folder() -> Path:
    """Where the scenes shipped with ddsolve (and their .geo files) are."""
    return Path(str(resources.files("ddsolve.problem") / "scenes"))


def builtin_scenes() -> dict[str, str]:
    """Names of the scenes shipped with ddsolve -> their TOML text."""
    return {entry.stem: entry.read_text() for entry in builtin_folder().iterdir() if entry.suffix == ".toml"}


def readable(path: str | Path, what: str, error: type[DDSolveError] = DDSolveError, missing: str = "") -> Path:
    """``path``, if it opens for reading as a regular file; else ``error`` in one line naming it and
    the reason: ``missing`` (default: WHAT not found), or cannot read WHAT (permission denied, is a
    directory, ...).  Every input file (scene, mesh or geometry, result) goes through here before
    it is read, so that no reader meets an OS error of its own."""
    try:
        handle = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # no wait on a FIFO
    except FileNotFoundError:
        raise error(f"{printable(str(path))}: {missing or what + ' not found'}") from None
    except OSError as exc:
        raise error(f"{printable(str(path))}: cannot read {what} ({(exc.strerror or type(exc).__name__).lower()})") \
            from None
    try:
        mode = os.fstat(handle).st_mode
    finally:
        os.close(handle)
    if not stat.S_ISREG(mode):
        kind = "is a directory" if stat.S_ISDIR(mode) else "not a regular file"
        raise error(f"{printable(str(path))}: cannot read {what} ({kind})")
    return Path(path)


def utf8_text(path: Path, what: str, error: type[DDSolveError] = DDSolveError) -> str:
    """The text of ``path`` (UTF-8; a byte-order mark, as some editors write, is dropped); else ``error``
    in one line naming the file and, for bytes that are not UTF-8, where the first one is."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise error(f"{printable(str(path))}: cannot read {what} ({(exc.strerror or type(exc).__name__).lower()})") \
            from None
    start = len(codecs.BOM_UTF8) if data.startswith(codecs.BOM_UTF8) else 0
    try:
        return data[start:].decode("utf-8")
    except UnicodeDecodeError as exc:
        at = start + exc.start
        line, column = data.count(b"\n", 0, at) + 1, at - data.rfind(b"\n", 0, at)
        raise error(f"{printable(str(path))}: {what} is not UTF-8 text: byte 0x{data[at]:02x} at line {line}, "
                    f"column {column} (byte offset {at}); save it as UTF-8") from None


def load(source: str | Path, overrides: list[str] = ()) -> Scene:
    """Read a scene from a file path or a built-in name, apply overrides, validate; the scene file
    and its mesh file must be readable (:func:`readable`)."""
    path = Path(source)
    shipped = builtin_scenes()
    if str(source) in shipped and not os.path.isfile(path):
        text, base = shipped[str(source)], builtin_folder()
    else:
        names = ", ".join(sorted(shipped))
        readable(path, "scene file", SceneError, f"no such scene file or built-in scene (built-in: {names})")
        text = utf8_text(path, "scene file", SceneError)
        base = path.parent
    scene = loads(text, overrides, origin=str(source), base=base)
    if scene.mesh.file is not None:
        readable(scene.mesh.file, "mesh file", SceneError)  # the scene names it: a scene error
    return scene


def loads(text: str, overrides: list[str] = (), origin: str = "scene", base: Path | None = None) -> Scene:
    """Parse and validate scene text."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: malformed TOML: {' '.join(str(exc).split())}") from None
    except RecursionError:  # tomllib's parser recurses into arrays and tables
        raise SceneError(f"{origin}: malformed TOML: arrays or tables nested too deeply") from None
    apply_overrides(raw, list(overrides))
    data = _check_table(raw, SCHEMA, (), origin)
    _cross_checks(data, raw, origin)
    if data["mesh"]["file"] is not None and data["mesh"]["file"].lower().endswith(".geo"):
        written = {key: value for key, value in data.items() if key != "geometry"}
    else:
        written = data
    return _to_scene(data, raw, dumps(written), base, origin, text, tuple(overrides))


# ---------------------------------------------------------------------------------------------
def _toml_value(value: Any) -> str:
    if isinstance(value, Expression):
        return _toml_value(list(value.coefficients) if value.coefficients is not None else value.text)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):  # a TOML basic string: control characters escaped
        return '"' + "".join(f"\\u{ord(c):04x}" if ord(c) < 0x20 or c in '"\\\x7f' else c for c in value) + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):  # a table, as --set 'materials.layer1={E = 70.0, nu = 0.33}' gives one
        return "{" + ", ".join(f"{_toml_key(str(k))} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {value!r} as TOML")


def _toml_key(key: str) -> str:
    """A TOML key: bare when it can be, else a basic string."""
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _toml_value(key)


def dumps(data: dict, path: tuple[str, ...] = ()) -> str:
    """Write checked scene data as TOML (keys without a value are left out)."""
    lines = [f"{key} = {_toml_value(value)}" for key, value in data.items()
             if not isinstance(value, dict) and value is not None]
    text = ""
    if lines:
        text = ("[" + ".".join(path) + "]\n" if path else "") + "\n".join(lines) + "\n"
    for key, value in data.items():
        if isinstance(value, dict):
            sub = dumps(value, (*path, key))
            text += ("\n" if text and sub else "") + sub
    return text
