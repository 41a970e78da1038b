"""The files a run reads: the scene file, the mesh or geometry file it names, and every file those reach
(an XDMF mesh's heavy-data files, a ``.geo``'s ``Include``, ``Merge`` and ``ShapeFromFile`` files).  Each
is an input: no output may replace it (:func:`ddsolve.io.safe.check_targets`)."""
from __future__ import annotations

import re
import xml.etree.ElementTree as ElementTree
from pathlib import Path
from typing import Iterable

from ddsolve.problem.scene import Scene

#: The statements of a gmsh script that read another file, and the file's name (relative to the script).
GEO_FILES = re.compile(r"\b(?:Include|Merge|ShapeFromFile)\s*\(?\s*\"([^\"]+)\"")
#: XDMF data items whose text names another file (``FILE:/dataset`` for HDF, ``FILE`` for binary).
XDMF_FORMATS = ("hdf", "binary")
#: Suffixes of XDMF files.
XDMF_SUFFIXES = (".xdmf", ".xmf")


def scene_file(scene: Scene) -> Path | None:
    """The file ``scene`` was read from (None for a built-in scene, scene text or a result's scene)."""
    path = Path(scene.origin)
    return path if scene.base is not None and path.parent == scene.base and path.is_file() else None


def of_scene(scene: Scene, source: str | Path | None = None) -> dict[Path, str]:
    """Every existing file a run of ``scene`` reads, each with how it is read: its scene file (``source``
    when given as a path, else where ``scene`` was read from), its mesh or geometry file and the files
    that one reaches."""
    given = Path(source) if isinstance(source, (str, Path)) and Path(source).is_file() else scene_file(scene)
    found = {} if given is None else {given: "the scene file"}
    for path, how in reached(scene.mesh.file).items():
        found.setdefault(path, how)
    return found


def of_scenes(scenes: Iterable[Scene], source: str | Path | None = None) -> dict[Path, str]:
    """:func:`of_scene` over several scenes (a sweep's), each file once."""
    found: dict[Path, str] = {}
    for scene in scenes:
        for path, how in of_scene(scene, source).items():
            found.setdefault(path, how)
    return found


def reached(path: Path | None) -> dict[Path, str]:
    """``path`` (the mesh file) and every file it reads, followed through the files each names (each
    once), with how each is read."""
    found: dict[Path, str] = {}
    pending = [] if path is None else [(Path(path), "the mesh file")]
    while pending:
        current, how = pending.pop()
        if current in found or not current.is_file():
            continue
        found[current] = how
        pending += [(named, f"read through {current}") for named in named_by(current)]
    return found


def named_by(path: Path) -> list[Path]:
    """The files a mesh or geometry file names (relative names are relative to its folder); none for a
    file that names none or cannot be read (its reader reports that)."""
    suffix = path.suffix.lower()
    try:
        if suffix == ".geo":
            names = GEO_FILES.findall(path.read_text(encoding="utf-8", errors="replace"))
        elif suffix in XDMF_SUFFIXES:
            names = xdmf_files(path.read_bytes())
        else:
            return []
    except OSError:
        return []
    return [path.parent / name for name in names if name]


def xdmf_files(text: bytes) -> list[str]:
    """The files an XDMF document names: its HDF and binary data items' files and its XIncludes."""
    try:
        root = ElementTree.fromstring(text)
    except (ElementTree.ParseError, ValueError):
        return []
    names = []
    for element in root.iter():
        tag = str(element.tag).rpartition("}")[2]
        if tag == "DataItem" and element.get("Format", "").lower() in XDMF_FORMATS and element.text:
            names.append(element.text.strip().split(":")[0])
        elif tag == "include" and element.get("href"):
            names.append(element.get("href").split("#")[0])
    return names
