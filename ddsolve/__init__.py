"""ddsolve: domain decomposition for a two-layer elastic structure with a non-penetrating crack.

The public face (docs/api.md): :class:`Scene` (load, change), :func:`solve`, :func:`reference`,
:func:`sweep`, :func:`grow`, :class:`Result`, :func:`save` and :func:`load`, and the errors, each with a one-line message.
The stages below it are subpackages (docs/architecture.md).  The face is imported on first use, so
``import ddsolve.mesh`` (or the command line's help) needs nothing but the standard library and numpy.
"""
import importlib

from ddsolve.environment import find_petsc
from ddsolve.errors import (ArgumentError, DDSolveError, DivergedError, MeshError, NotConvergedError, SceneError,
                            SolverError, UsageError)

__version__ = "0.1.0"

find_petsc()  # before any ddsolve module imports petsc4py

#: The API's names -> the module that defines them.
_FACE = {"Scene": "ddsolve.problem.scene", "Result": "ddsolve.post.result", "solve": "ddsolve.api",
         "reference": "ddsolve.api", "sweep": "ddsolve.api", "grow": "ddsolve.api",
         "load": "ddsolve.api", "save": "ddsolve.io"}

__all__ = [*_FACE, "DDSolveError", "ArgumentError", "SceneError", "MeshError", "SolverError", "DivergedError",
           "NotConvergedError", "UsageError", "__version__"]


def __getattr__(name: str):
    if name in _FACE:
        importlib.import_module("ddsolve.api")  # the face in use: an uncaught ddsolve error is its one line
        return getattr(importlib.import_module(_FACE[name]), name)
    raise AttributeError(f"module 'ddsolve' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
