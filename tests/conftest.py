"""Shared test helpers: small structured meshes and launching ddsolve under mpiexec."""
from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

from ddsolve.io import viewer
from ddsolve.mesh.geometry import split_box
from ddsolve.mesh.mesh import Mesh
from ddsolve.problem.scene import Geometry

ROOT = Path(__file__).resolve().parents[1]
#: The small mesh of the paper's square that most end-to-end tests solve (P = 13, M = 32).
SMALL = ["--set", "mesh.sigma_vertices=13", "--set", "mesh.boundary_vertices=32"]
#: The paper's two layers, as scene text.
MATERIALS = """
[materials.layer1]
E = 200.0
nu = 0.28
[materials.layer2]
E = 112.0
nu = 0.32
"""


def both_layers(name: str, body: str) -> str:
    """``[displacements.LAYER.NAME]`` with ``body`` for both layers, as scene text."""
    return "".join(f"[displacements.{layer}.{name}]\n{body}\n" for layer in ("layer1", "layer2"))


#: Programs whose start makes a test an end-to-end (``mpi``) test.
RUNNERS = ("python", "mpiexec", "mpirun", "pvpython", "xvfb-run", "run", "bash", "sh", "timeout")


#: The in-process solves of a whole structure (the monolithic reference, the DD driver): a test that calls
#: one is marked ``solve`` (or ``mpi``), which keeps ``-m unit`` the fast loop.
STRUCTURE_SOLVES = (("ddsolve.solvers.reference", "solve_monolithic"), ("ddsolve.solvers.driver", "solve_decomposed"),
                    ("ddsolve.solvers.stacked", "solve_stack"), ("ddsolve.solvers.stacked_dd", "solve"),
                    ("ddsolve.solvers.solid", "solve_solid"), ("ddsolve.solvers.solid_dd", "solve"))


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """A test is ``unit`` unless it is marked ``mpi`` or ``solve``: ``-m unit`` runs the serial numerics
    alone, without a whole structure solved."""
    for item in items:
        if item.get_closest_marker("mpi") is None and item.get_closest_marker("solve") is None:
            item.add_marker(pytest.mark.unit)


@contextlib.contextmanager
def no_solves_in_unit(item: pytest.Item):
    """While a ``unit`` test is set up and run, solving a whole structure in this process (the
    STRUCTURE_SOLVES, once imported) fails and asks for the ``solve`` mark."""
    if item.get_closest_marker("unit") is None:
        yield
        return
    replaced = []
    for module_name, name in STRUCTURE_SOLVES:
        module = sys.modules.get(module_name)
        if module is None:
            continue

        def refused(*_args, _where=f"{module_name}.{name}", **_options):
            raise AssertionError(f"{item.nodeid} solves a whole structure ({_where}): mark it pytest.mark.solve")
        replaced.append((module, name, getattr(module, name)))
        setattr(module, name, refused)
    try:
        yield
    finally:
        for module, name, original in replaced:
            setattr(module, name, original)


@contextlib.contextmanager
def no_runs_unless_mpi(item: pytest.Item):
    """While a test that is not marked ``mpi`` is set up (its fixtures too) and run, starting ddsolve,
    mpiexec or another Python fails and asks for the mark.  (Libraries' own helpers, such as ctypes
    asking ldconfig where a library is, are not runs.)"""
    if item.get_closest_marker("mpi") is not None:
        yield
        return
    popen = subprocess.Popen

    class Refused(popen):
        def __init__(self, args, *rest, **options):
            words = [str(word) for word in ([args] if isinstance(args, (str, Path)) else args)]
            if any(Path(word).name.startswith(RUNNERS) for word in words[:1]) or "ddsolve" in words:
                raise AssertionError(f"{item.nodeid} starts {' '.join(words[:4])}...: mark it pytest.mark.mpi")
            super().__init__(args, *rest, **options)
    subprocess.Popen = Refused
    try:
        yield
    finally:
        subprocess.Popen = popen


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item: pytest.Item):
    with no_runs_unless_mpi(item), no_solves_in_unit(item):
        yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item: pytest.Item):
    with no_runs_unless_mpi(item), no_solves_in_unit(item):
        yield


def structured_square(nx: int, ny: int, shear: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated (−1,1)² with nx cells across and ny cells per half; y = 0 is a grid line.

    ``shear`` moves interior vertices sideways (an unstructured-looking but valid mesh).
    """
    x = np.linspace(-1.0, 1.0, nx + 1)
    y = np.linspace(-1.0, 1.0, 2 * ny + 1)
    X, Y = np.meshgrid(x, y)
    points = np.column_stack([X.ravel(), Y.ravel()])
    inner = (np.abs(points[:, 0]) < 1) & (np.abs(points[:, 1]) < 1) & (points[:, 1] != 0)
    points[inner, 0] += shear * (1.0 / nx) * np.sin(7.0 * points[inner, 1] + 3.0 * points[inner, 0])
    v = np.arange((nx + 1) * (2 * ny + 1)).reshape(2 * ny + 1, nx + 1)
    a, b, c, d = v[:-1, :-1].ravel(), v[:-1, 1:].ravel(), v[1:, 1:].ravel(), v[1:, :-1].ravel()
    cells = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return points, cells


#: The paper's square without its crack.
UNCRACKED = Geometry(cracks=())


def structured_mesh(nx: int = 8, ny: int = 4, shear: float = 0.0, degree: int = 1,
                    geometry: Geometry = UNCRACKED) -> Mesh:
    """The paper's square (uncracked unless ``geometry`` says otherwise) on a structured mesh, P1 or P2."""
    points, cells = structured_square(nx, ny, shear)
    return split_box(points, cells, geometry, degree, "test mesh")


@pytest.fixture
def mesh_file(tmp_path) -> Path:
    """A small structured mesh of the square in a meshio-readable file (crack tips ±0.5 on vertices)."""
    points, cells = structured_square(8, 4, shear=0.3)
    path = tmp_path / "square.vtu"
    meshio.write(path, meshio.Mesh(points, [("triangle", cells)]))
    return path


#: Open MPI's libevent may warn on standard error when ranks end on an error (a known race in its I/O
#: forwarding, not ddsolve's output): «[warn] Epoll MOD(1) on fd 29 failed. ... Bad file descriptor».
OPEN_MPI_NOISE = re.compile(r"^\[warn\] Epoll [A-Z]+\(\d+\) on fd \d+ failed\..*\n?", re.M)


def without_open_mpi_noise(completed: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    """``completed`` with Open MPI's libevent warnings removed from its standard error."""
    completed.stderr = OPEN_MPI_NOISE.sub("", completed.stderr)
    return completed


def ddsolve(*args: str, ranks: int | None = None, check: bool = True, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``python -m ddsolve ARGS`` (under mpiexec with ``ranks``), capturing output."""
    command = [sys.executable, "-m", "ddsolve", *args]
    if ranks is not None:
        from ddsolve.cli import mpiexec_command

        command = mpiexec_command(ranks, list(args))
    completed = without_open_mpi_noise(subprocess.run(command, capture_output=True, text=True, timeout=timeout,
                                                      stdin=subprocess.DEVNULL, env={**os.environ, "MPLBACKEND": "Agg"}))
    if check and completed.returncode != 0:
        raise AssertionError(f"{' '.join(command)} failed ({completed.returncode}):\n"
                             f"{completed.stdout}\n{completed.stderr}")
    return completed


def solved_reference(*args: str) -> Path:
    """``ddsolve reference ARGS`` (a scene, ``--set`` items, ``-o`` a result file) solved in this process,
    for a test that reads the reference as data: the same scene and result set without a process started;
    returns the result file."""
    import ddsolve as api
    from ddsolve.cli import parser

    parsed = parser().parse_args(["reference", *args])
    api.reference(api.Scene.load(parsed.scene, parsed.set or []), parsed.output)
    return Path(parsed.output)


def paper_references(folder: Path, *options: str) -> dict[str, Path]:
    """Reference results of the paper's three scenes with ``options``, in ``folder``."""
    return {name: solved_reference(name, *options, "-o", str(folder / f"{name}.h5"))
            for name in ("partial-closure", "full-opening", "linear")}


def refused(completed: subprocess.CompletedProcess, status: int, *fragments: str) -> str:
    """The run failed with ``status`` and one line on standard error holding every fragment."""
    assert completed.returncode == status, (completed.returncode, completed.stderr)
    assert "Traceback" not in completed.stdout + completed.stderr
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ddsolve: error: "), completed.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


def previous_set(output: Path) -> dict[Path, bytes]:
    """Stand-ins for a previous result set at ``output`` (the .h5 and its viewer files)."""
    files = {path: f"previous {path.name}".encode() for path in
             [output, *viewer.viewer_paths(output.parent, output.stem)]}
    for path, data in files.items():
        path.write_bytes(data)
    return files


def unchanged(files: dict[Path, bytes]) -> bool:
    return all(path.is_file() and path.read_bytes() == data for path, data in files.items())
