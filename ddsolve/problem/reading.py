"""Input text and files for messages and reading: text made printable for a one-line message, excerpts of
long text, a file checked readable before any reader opens it, UTF-8 text with its first bad byte named."""
from __future__ import annotations

import codecs
import os
import stat
from pathlib import Path

from ddsolve.errors import DDSolveError


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

