"""What ddsolve needs of its environment: where the PETSc stack comes from (one-line errors when a
part of it is missing), the machine's memory, and processes that end with their parent.

petsc4py, mpi4py, h5py and gmsh come from the system (Debian packages) or from conda-forge, not as
pip dependencies (see pyproject.toml).  Debian's petsc4py is importable only with
``PETSC_DIR`` set when Python starts (its ``petsc4py.pth`` reads it), so without ``PETSC_DIR``
ddsolve finds Debian's PETSc itself when the package is imported (:func:`find_petsc`).
"""
from __future__ import annotations

import contextlib
import ctypes
import importlib.util
import math
import os
import re
import signal
import sys
import sysconfig
from pathlib import Path
from typing import Iterator

from ddsolve.errors import DDSolveError

DEBIAN_PETSC_ROOT = Path("/usr/lib/petscdir")
#: Where a Debian PETSc directory keeps its petsc4py (the rule of Debian's petsc4py.pth).
PETSC4PY_SUBDIR = Path("lib/python3/dist-packages")

#: Third-party modules ddsolve imports -> (Debian package, conda-forge package).
PACKAGES = {
    "petsc4py": ("python3-petsc4py", "petsc4py"),
    "mpi4py": ("python3-mpi4py", "mpi4py"),
    "h5py": ("python3-h5py", "h5py"),
    "gmsh": ("python3-gmsh", "python-gmsh"),
    "numpy": ("python3-numpy", "numpy"),
    "meshio": ("python3-meshio", "meshio"),
    "matplotlib": ("python3-matplotlib", "matplotlib"),
    "scipy": ("python3-scipy", "scipy"),
    "tomli": ("python3-tomli", "tomli"),
}


class MissingDependencyError(DDSolveError):
    """A module ddsolve needs cannot be imported."""


def debian_petsc_dirs() -> list[Path]:
    """Debian's real-scalar PETSc directories that hold petsc4py: this machine's first, newest first."""
    native = f"{sysconfig.get_config_var('MULTIARCH')}-real"
    found = [d for d in DEBIAN_PETSC_ROOT.glob("petsc*/*-real") if (d / PETSC4PY_SUBDIR / "petsc4py").is_dir()]
    return sorted(found, key=lambda d: (d.name != native, [-int(n) for n in re.findall(r"\d+", d.parent.name)]))


def find_petsc() -> None:
    """In a Python that sees Debian's packages (its petsc4py.pth) but started without ``PETSC_DIR``,
    use Debian's PETSc: set ``PETSC_DIR`` (for this process and the ranks it starts) and put its
    petsc4py on ``sys.path``, as petsc4py.pth does when ``PETSC_DIR`` is set."""
    if os.environ.get("PETSC_DIR") or importlib.util.find_spec("petsc4py") is not None:
        return
    if not any(entry and Path(entry, "petsc4py.pth").is_file() for entry in sys.path):
        return  # another Python (pyenv, conda...): Debian's petsc4py is not built for it
    candidates = debian_petsc_dirs()
    if candidates:
        os.environ["PETSC_DIR"] = str(candidates[0])
        sys.path.append(str(candidates[0] / PETSC4PY_SUBDIR))


def _explain(module: str, error: ImportError) -> str:
    """One line: ``module`` (one of :data:`PACKAGES`) cannot be imported, and where to get it."""
    debian, conda = PACKAGES[module]
    missing = isinstance(error, ModuleNotFoundError) and error.name == module
    context = [] if missing else [str(error).partition("\n")[0]]
    if module == "petsc4py":
        petsc_dir = os.environ.get("PETSC_DIR")
        context.append(f"PETSC_DIR={petsc_dir}" if petsc_dir else "PETSC_DIR is unset")
    line = (f"{module} {'not found' if missing else 'cannot be imported'} by {sys.executable}"
            + (f" ({'; '.join(context)})" if context else "")
            + f": install {debian} (for Debian's python3, or a venv made from it with --system-site-packages)"
              f" or conda-forge's {conda}")
    return line + (", or set PETSC_DIR to a PETSc whose petsc4py is installed" if module == "petsc4py" else "")


@contextlib.contextmanager
def import_errors_explained() -> Iterator[None]:
    """Turn an ImportError of a module in :data:`PACKAGES` into a :class:`MissingDependencyError`."""
    try:
        yield
    except ImportError as error:
        module = (error.name or "").partition(".")[0]
        if module not in PACKAGES:
            raise
        raise MissingDependencyError(_explain(module, error)) from None


#: Where MUMPS writes out-of-core factors: the folder this variable names, else MUMPS's default folder.
OUT_OF_CORE_VARIABLE, OUT_OF_CORE_DEFAULT = "MUMPS_OOC_TMPDIR", "/tmp"


def check_out_of_core_folder(why: str) -> None:
    """Refuse, in one line naming ``MUMPS_OOC_TMPDIR`` and its folder, a folder where MUMPS could not
    create its out-of-core factor files (it would stop with its error -81 once the factorization has
    begun); ``why``: what asked for out-of-core factors."""
    import tempfile

    folder = os.environ.get(OUT_OF_CORE_VARIABLE) or OUT_OF_CORE_DEFAULT
    named = (f"{OUT_OF_CORE_VARIABLE}={folder}" if os.environ.get(OUT_OF_CORE_VARIABLE)
             else f"{OUT_OF_CORE_VARIABLE} is unset and MUMPS's default folder {folder}")
    try:
        if not os.path.isdir(folder):
            raise FileNotFoundError(0, "no such folder" if not os.path.exists(folder) else "not a folder")
        handle, probe = tempfile.mkstemp(prefix=".ddsolve-probe.", dir=folder)
        os.close(handle)
        os.unlink(probe)
    except OSError as exc:
        reason = (exc.strerror or type(exc).__name__).lower()
        raise DDSolveError(f"{named}: cannot hold MUMPS's out-of-core factors ({reason}), which {why} asks for: "
                           f"set {OUT_OF_CORE_VARIABLE} to a folder you can write") from None


#: Memory a rank needs before it holds any mesh (Python, numpy, PETSc, MPI), and per mesh vertex for
#: a solve (assembly, factorizations, Schur complements; measured with 4 ranks at P = 400, M = 512).
RANK_MEMORY = 100e6


VERTEX_MEMORY = 15e3


def physical_memory() -> float:
    try:
        return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return math.inf



#: Linux's prctl request: the signal the kernel sends a process when its parent ends.
PR_SET_PDEATHSIG = 1

#: This process's parent when ddsolve was first imported, before the long imports of a command: a rank's
#: launcher (mpiexec) even if it is killed meanwhile and the rank has been given to init.
PARENT_AT_START = os.getppid()


def end_with_parent(parent: int, signum: int = signal.SIGKILL) -> None:
    """Have the kernel send ``signum`` to this process when its parent (the process ``parent``) ends,
    and end at once if it has ended already.  SIGKILL of a parent cannot be caught, so this is the only
    way its children learn of it.  Linux only: elsewhere nothing is done."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_PDEATHSIG, int(signum), 0, 0, 0)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent ended before the request: nobody waits for this process
        os._exit(128 + int(signum))


def process_exists(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, dead but not yet reaped, does not: its files are closed and
    it writes nothing more); a process of another user counts as running."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except (OSError, IndexError):
        return True  # no /proc: what kill said
    return state not in ("Z", "X")
