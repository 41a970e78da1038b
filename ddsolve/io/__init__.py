"""Files: HDF5 results, viewer files, safe replacement of file sets.

The stage's face is :func:`save` (a result's set of files) and :func:`ddsolve.io.hdf5.read`; importing the
package imports neither HDF5 nor the result, so the command line's checks can use :mod:`ddsolve.io.safe`
alone."""
from __future__ import annotations

from pathlib import Path

from ddsolve.errors import ArgumentError


def save(result, path: str | Path, viewer: str = "vtu") -> list[Path]:
    """Write the result set of ``result`` (a :class:`ddsolve.post.result.Result`): the HDF5 file ``path`` and
    its viewer files (a format of :data:`ddsolve.io.viewer.FORMATS`) beside it, replaced together (never over
    a file the run read: ``result.inputs``); returns the paths written and notes ``path`` as ``result.path``."""
    from ddsolve.io.hdf5 import check_result, check_viewer, write
    from ddsolve.post.result import Result

    if not isinstance(result, Result):
        raise ArgumentError(f"save: result must be a Result (got {type(result).__name__})")
    if not isinstance(path, (str, Path)):
        raise ArgumentError(f"save: path must be a file's path (got {type(path).__name__})")
    check_viewer(viewer, "save: viewer")
    check_result(Path(path), result.inputs, viewer=viewer, named="save path")
    written = write(Path(path), result, viewer)
    result.path = Path(path)
    return written
