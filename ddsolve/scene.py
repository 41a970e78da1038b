"""Scene files: one problem (geometry, mesh, materials, loads, contact, solver) in TOML.

A scene is parsed into plain dataclasses after every key has been checked against ``SCHEMA``;
unknown keys, wrong types and out-of-range values raise :class:`SceneError` with a one-line
message naming the key.  ``--set section.key=value`` overrides are applied to the raw tables
before validation, so they are checked exactly like the file.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Callable

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

from .errors import SceneError

METHODS = ("schur", "mprgp", "fista", "uzawa")
DEFAULT_METHOD = "schur"
STOP_RULES = ("paper", "relative", "kkt")
#: Default stopping rule of each method and default tolerance of each rule.
DEFAULT_STOP = {"uzawa": "paper", "schur": "kkt", "mprgp": "kkt", "fista": "kkt"}
DEFAULT_TOL = {"paper": 1e-6, "relative": 1e-6, "kkt": 1e-8}
LAYERS = ("layer1", "layer2")
MAX_SPACING_RATIO = 10.0
SIDES = ("bottom", "top")


@dataclass(frozen=True)
class Material:
    E: float
    nu: float


@dataclass(frozen=True)
class Traction:
    """t(x) = (sum x[j] s^j, sum y[j] s^j) on one boundary edge set, coefficients lowest degree first."""

    x: tuple[float, ...] = ()
    y: tuple[float, ...] = ()


@dataclass(frozen=True)
class Solver:
    method: str
    theta: float | None  # Uzawa's step; the other methods need none
    p: float | None  # multiplier bound; None: μᶜ ≥ 0 only
    tol: float
    stop: str
    max_iterations: int


@dataclass(frozen=True)
class Scene:
    title: str
    crack: tuple[float, float] | None
    sigma_vertices: int | None
    boundary_vertices: int | None
    mesh_file: Path | None
    materials: dict[str, Material]
    loads: dict[tuple[str, str], Traction]
    nonpenetration: bool
    solver: Solver
    text: str = field(repr=False, default="")

    @property
    def contact(self) -> bool:
        """True when the crack faces carry the non-penetration multiplier."""
        return self.nonpenetration and self.crack is not None


# ---------------------------------------------------------------------------------------------
# Schema: a leaf is (checker, default); REQUIRED marks keys without a default.
REQUIRED = object()


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
    return value


def _numbers(value: Any) -> tuple[float, ...]:
    if not isinstance(value, list):
        raise TypeError("a list of numbers")
    return tuple(_number(v) for v in value)


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


def _choice(options: tuple[str, ...]) -> Callable[[Any], str]:
    def checked(value: Any) -> str:
        value = _string(value)
        if value not in options:
            raise ValueError("one of " + ", ".join(options))
        return value
    return checked


def _crack(value: Any) -> tuple[float, ...]:
    values = _numbers(value)
    if not values:
        return values
    if len(values) != 2:
        raise ValueError("[a, b] or []")
    a, b = values
    if not -1.0 < a < b < 1.0:
        raise ValueError("[a, b] with -1 < a < b < 1 (the crack must stay off the clamped ends)")
    return values


def _vertex_count(minimum: int) -> Callable[[Any], int]:
    def checked(value: Any) -> int:
        value = _integer(value)
        if value < minimum:
            raise ValueError(f"at least {minimum}")
        return value
    return checked


_MATERIAL = {"E": (_positive(_number), REQUIRED), "nu": (_poisson, REQUIRED)}
_TRACTION = {"x": (_numbers, []), "y": (_numbers, [])}

SCHEMA: dict[str, Any] = {
    "title": (_string, ""),
    "geometry": {"crack": (_crack, [-0.5, 0.5])},
    "mesh": {
        "sigma_vertices": (_vertex_count(5), None),
        "boundary_vertices": (_vertex_count(8), None),
        "file": (_string, None),
    },
    "materials": {layer: dict(_MATERIAL) for layer in LAYERS},
    "loads": {layer: {side: dict(_TRACTION) for side in SIDES} for layer in LAYERS},
    "contact": {"nonpenetration": (_boolean, True)},
    "solver": {
        "method": (_choice(METHODS), DEFAULT_METHOD),
        "theta": (_positive(_number), None),
        "p": (_positive(_number), None),
        "tol": (_positive(_number), None),
        "stop": (_choice(STOP_RULES), None),
        "max_iterations": (_vertex_count(1), 20000),
    },
}
# Tables that exist only when the scene writes them (a boundary without a load is not integrated).
OPTIONAL_TABLES = {("loads",), *(("loads", layer) for layer in LAYERS),
                   *(("loads", layer, side) for layer in LAYERS for side in SIDES)}


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
        dotted = ".".join((*path, key))
        if isinstance(spec, dict):
            if key not in raw:
                if (*path, key) in OPTIONAL_TABLES:
                    continue
                sub = {}
            else:
                sub = raw[key]
                if not isinstance(sub, dict):
                    raise SceneError(f"{origin}: {dotted} must be a table")
            out[key] = _check_table(sub, spec, (*path, key), origin)
            continue
        check, default = spec
        if key not in raw:
            if default is REQUIRED:
                raise SceneError(f"{origin}: missing key {dotted}")
            out[key] = default if default is None else check(default)
            continue
        try:
            out[key] = check(raw[key])
        except (TypeError, ValueError) as exc:
            raise SceneError(f"{origin}: {dotted} must be {exc} (got {raw[key]!r})") from None
    return out


def _cross_checks(data: dict, origin: str) -> None:
    mesh = data["mesh"]
    counts = (mesh["sigma_vertices"], mesh["boundary_vertices"])
    if mesh["file"] is not None:
        if counts != (None, None):
            raise SceneError(f"{origin}: mesh.file excludes mesh.sigma_vertices and mesh.boundary_vertices")
    elif None in counts:
        missing = "mesh.sigma_vertices" if counts[0] is None else "mesh.boundary_vertices"
        raise SceneError(f"{origin}: missing key {missing} (or give mesh.file)")
    else:
        ratio = (8.0 / counts[1]) / (2.0 / (counts[0] - 1))
        if not 1.0 / MAX_SPACING_RATIO <= ratio <= MAX_SPACING_RATIO:
            raise SceneError(f"{origin}: mesh.boundary_vertices = {counts[1]} is inconsistent with "
                             f"mesh.sigma_vertices = {counts[0]}: the boundary spacing 8/M must be within a "
                             f"factor {MAX_SPACING_RATIO:g} of the Σ spacing 2/(P-1), or the corner triangles degenerate")
    solver = data["solver"]
    if solver["method"] == "uzawa" and solver["theta"] is None:
        raise SceneError(f"{origin}: solver.theta is required by method uzawa")
    if solver["stop"] is None:
        solver["stop"] = DEFAULT_STOP[solver["method"]]
    if solver["method"] != "uzawa" and solver["stop"] != "kkt":
        raise SceneError(f"{origin}: solver.stop = {solver['stop']} is available for method uzawa only "
                         f"(method {solver['method']} stops on kkt)")
    if solver["tol"] is None:
        solver["tol"] = DEFAULT_TOL[solver["stop"]]


def _to_scene(data: dict, text: str, base: Path | None) -> Scene:
    mesh = data["mesh"]
    mesh_file = None
    if mesh["file"] is not None:
        mesh_file = Path(mesh["file"])
        if not mesh_file.is_absolute() and base is not None:
            mesh_file = base / mesh_file
    loads = {
        (layer, side): Traction(**table)
        for layer, sides in data.get("loads", {}).items()
        for side, table in sides.items()
    }
    return Scene(
        title=data["title"],
        crack=data["geometry"]["crack"] or None,
        sigma_vertices=mesh["sigma_vertices"],
        boundary_vertices=mesh["boundary_vertices"],
        mesh_file=mesh_file,
        materials={layer: Material(**data["materials"][layer]) for layer in LAYERS},
        loads=loads,
        nonpenetration=data["contact"]["nonpenetration"],
        solver=Solver(**data["solver"]),
        text=text,
    )


# ---------------------------------------------------------------------------------------------
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
    return [p.strip() for p in path], parsed


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply ``--set`` items to a raw (unvalidated) scene table, in order."""
    for item in overrides:
        path, value = parse_override(item)
        table = raw
        for depth, part in enumerate(path[:-1]):
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                raise SceneError(f"--set {printable(item)}: {printable('.'.join(path[:depth + 1]))} is not a table")
        table[path[-1]] = value
    return raw


def builtin_scenes() -> dict[str, str]:
    """Names of the scenes shipped with ddsolve -> their TOML text."""
    folder = resources.files("ddsolve") / "scenes"
    return {entry.name[:-5]: entry.read_text() for entry in folder.iterdir() if entry.name.endswith(".toml")}


def load(source: str | Path, overrides: list[str] = ()) -> Scene:
    """Read a scene from a file path or a built-in name, apply overrides, validate."""
    path = Path(source)
    base = None
    if path.is_file():
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise SceneError(f"{source}: cannot read scene file ({exc.__class__.__name__})") from None
        base = path.parent
    else:
        shipped = builtin_scenes()
        if str(source) not in shipped:
            names = ", ".join(sorted(shipped))
            raise SceneError(f"{printable(str(source))}: no such scene file or built-in scene (built-in: {names})")
        text = shipped[str(source)]
    return loads(text, overrides, origin=str(source), base=base)


def loads(text: str, overrides: list[str] = (), origin: str = "scene", base: Path | None = None) -> Scene:
    """Parse and validate scene text."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: malformed TOML: {' '.join(str(exc).split())}") from None
    apply_overrides(raw, list(overrides))
    data = _check_table(raw, SCHEMA, (), origin)
    _cross_checks(data, origin)
    return _to_scene(data, dumps(data), base)


# ---------------------------------------------------------------------------------------------
def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} as TOML")


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
