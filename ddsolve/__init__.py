"""ddsolve: domain decomposition for a two-layer elastic structure with a non-penetrating crack."""
from ddsolve.environment import find_petsc

__version__ = "0.1.0"

find_petsc()  # before any ddsolve module imports petsc4py
