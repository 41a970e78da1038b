"""Input text and files for messages and reading: text made printable for a one-line message, excerpts of
long text, a file checked readable before any reader opens it, UTF-8 text with its first bad byte named, the
structure a gmsh file of several interfaces gives a scene (its physical groups' names)."""
from __future__ import annotations

import codecs
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from ddsolve.errors import DDSolveError, SceneError


def excerpt(text: str, position: int, width: int = 60) -> str:
    """``text`` for a message: whole if short, else the ``width`` characters around ``position`` (1-based)."""
    if len(text) <= width:
        return text
    start = max(0, min(position - 1 - width // 2, len(text) - width))
    return (f"{'...' if start else ''}{text[start:start + width]}{'...' if start + width < len(text) else ''}"
            f" ({len(text)} characters)")


def printable(text: str) -> str:
    """``text`` for a one-line message: as is if printable, else escaped."""
    return text if text.isprintable() else repr(text)[1:-1]


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



#: A gmsh file's physical groups of several interfaces: curves ``sigma1``, ``sigma2``, ... and ``crack1``, ...
NUMBERED_SIGMA, NUMBERED_CRACK = re.compile(r"sigma(\d+)"), re.compile(r"crack(\d+)")
#: The kind of a physical group of each dimension, as messages name it.
GROUP_KINDS = ("point", "curve", "surface", "volume")
#: Physical group kinds of a .geo file by dimension.
GEO_GROUPS = re.compile(r'Physical\s+(Point|Line|Curve|Surface|Volume)\s*\(\s*"([^"]*)"')


@dataclass(frozen=True)
class FileStructure:
    """A gmsh file of several interfaces: their number and its region surfaces, bottom to top."""

    interfaces: int
    regions: tuple[str, ...]


def physical_names(path: Path, where: str) -> dict[int, list[str]] | None:
    """The physical groups' names of a gmsh file by dimension, in the file's order: a .geo's ``Physical Curve("name")``
    ... (its text), a .msh's ``$PhysicalNames`` (by tag); None for a file that cannot be read.  A file that names no
    group, or names interfaces as surfaces (a 3-D file's) without a volume, is refused in one line naming it
    (``where``): the scene would otherwise be read as another structure's and refused for keys it does not need."""
    try:
        data = readable(path, "mesh file").read_bytes()  # a FIFO or a folder is not read (its checks say so)
    except (DDSolveError, OSError):
        return None
    names: dict[int, list[str]] = {}
    if Path(path).suffix.lower() == ".geo":
        dims = {"Point": 0, "Line": 1, "Curve": 1, "Surface": 2, "Volume": 3}
        for kind, name in GEO_GROUPS.findall(data.decode("utf-8", "replace")):
            names.setdefault(dims[kind], []).append(name)
    else:
        start, stop = data.find(b"$PhysicalNames"), data.find(b"$EndPhysicalNames")
        rows = [line.split(maxsplit=2) for line in data[start:stop].decode("utf-8", "replace").splitlines()[2:]]
        for dim, tag, name in sorted((int(row[0]), int(row[1]), row[2].strip().strip('"')) for row in rows
                                     if len(row) == 3 and row[0].isdigit() and row[1].isdigit()):
            names.setdefault(dim, []).append(name)
    if not names:
        raise SceneError(f"{where}: no named physical group: the file names its interfaces, cracks and regions "
                         "(docs/geometry.md)")
    sides = [name for name in names.get(2, []) if name == "sigma" or NUMBERED_SIGMA.fullmatch(name)]
    if sides and 3 not in names and 1 not in names:
        raise SceneError(f"{where}: physical surface {sides[0]} and no physical volume: a 3-D file names one volume "
                         "per region, bottom to top")
    return names


def file_structure(names: dict[int, list[str]], where: str, dimension: int = 2) -> FileStructure | None:
    """The structure of a gmsh file with interfaces ``sigma1`` ... ``sigmaN`` (and ``crack1`` ...), its regions listed
    bottom to top, from its physical ``names`` (:func:`physical_names`): in the plane the interfaces are curves and the
    regions surfaces, in 3-D (``dimension`` 3) surfaces and volumes; None for a file of one interface (``sigma``).  A
    file that mixes the forms, skips a number, names a crack of no interface or has another count of regions than
    N + 1 is refused in one line."""
    side, body = GROUP_KINDS[dimension - 1], GROUP_KINDS[dimension]
    curves, surfaces = names.get(dimension - 1, []), names.get(dimension, [])
    numbered = sorted(int(match[1]) for match in map(NUMBERED_SIGMA.fullmatch, curves) if match)
    if not numbered:
        return None
    if "sigma" in curves or "crack" in curves:
        raise SceneError(f"{where}: physical {side}s {'sigma' if 'sigma' in curves else 'crack'} and "
                         f"sigma{numbered[0]}: name "
                         "one interface sigma (and crack), several sigma1, sigma2, ... (and crack1, ...)")
    missing = next((k for k in range(1, numbered[-1] + 1) if k not in numbered), None)
    if missing is not None:
        raise SceneError(f"{where}: physical {side} sigma{numbered[-1]} without sigma{missing}: number the "
                         "interfaces sigma1, sigma2, ... bottom to top")
    stray = next((name for name in curves if (match := NUMBERED_CRACK.fullmatch(name))
                  and int(match[1]) not in numbered), None)
    if stray is not None:
        raise SceneError(f"{where}: physical {side} {stray} lies on no interface (no sigma{stray[5:]})")
    if len(surfaces) != len(numbered) + 1:
        raise SceneError(f"{where}: {len(numbered)} interfaces (sigma1 ... sigma{len(numbered)}) cut Ω into "
                         f"{len(numbered) + 1} regions, and the file has {len(surfaces)} physical {body}s "
                         f"({', '.join(map(printable, surfaces))}): one per region, bottom to top")
    return FileStructure(len(numbered), tuple(surfaces))
