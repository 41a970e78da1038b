"""``--set KEY=VALUE`` overrides, applied to a scene's raw tables before they are checked, and scene data
written back as TOML text."""
from __future__ import annotations

import re
from typing import Any, Sequence

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

from ddsolve.errors import SceneError
from ddsolve.problem.expressions import Expression
from ddsolve.problem.reading import excerpt, printable
from ddsolve.problem.shapes import Ellipse
from ddsolve.problem.schema import ANISOTROPIC, ISOTROPIC, NUMBERED_REGION, ORTHOTROPIC, REGIONS


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
        raise SceneError(f"--set {printable(excerpt(item, 1))}: arrays or tables nested too deeply") from None
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
    """The keys of the other material laws, which a key that fixes a layer's (or a region's) law replaces
    (``--set materials.layer1.E1=...`` makes an isotropic layer orthotropic; α keys decide nothing)."""
    if path[0] != "materials" or not (len(path) == 3 or len(path) == 4 and (path[2] in REGIONS or re.fullmatch(
            NUMBERED_REGION.format(r"\d+"), path[2]))):
        return ()
    laws = [ISOTROPIC, ORTHOTROPIC, ANISOTROPIC]
    mine = [law for law in laws if path[-1] in law and not path[-1].startswith("alpha")]
    return tuple(key for law in laws if mine and law is not mine[0] for key in law if key not in mine[0])


def _list_index(values: list, path: list[str], depth: int, item: str) -> int:
    """``path[depth]`` as an index into ``values`` (the list at ``path[:depth]``)."""
    part = path[depth]
    if not part.isdigit() or int(part) >= len(values):
        raise SceneError(f"--set {printable(item)}: {printable('.'.join(path[:depth]))} is a list of "
                         f"{len(values)}; {printable(part)} is not an index into it (0 to {len(values) - 1})")
    return int(part)


def _toml_value(value: Any) -> str:
    if isinstance(value, Expression):
        return _toml_value(list(value.coefficients) if value.coefficients is not None else value.text)
    if isinstance(value, Ellipse):
        return _toml_value(value.table())
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
