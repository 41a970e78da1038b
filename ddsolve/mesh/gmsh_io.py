"""gmsh: a session in a child process (gmsh does not return to Python while it meshes), geometries and
meshes with physical groups (.geo, .msh 2.2 and 4.1) read into a Mesh, and a Mesh written as .msh."""
from __future__ import annotations

import contextlib
import math
import multiprocessing
import os
import resource
import signal
from pathlib import Path
from typing import Callable, TypeVar

import numpy as np

from ddsolve.environment import end_with_parent
from ddsolve.errors import MeshError
from ddsolve.mesh.mesh import (CRACK, SIGMA, TOL, Mesh, elevate, make_half, make_mesh, merge_repeats, point_nodes,
                               with_named_points)
from ddsolve.mesh.sizing import SMALLEST, model_singular_points, node_positions, set_size_field
from ddsolve.problem.scene import Scene, readable

T = TypeVar("T")


#: Physical groups a gmsh geometry must have.
REQUIRED_GROUPS = {2: ("lower", "upper"), 1: (SIGMA,)}


#: gmsh element types: triangle, 6-node triangle, line, 3-node line, point.
GMSH_TRIANGLE, GMSH_TRIANGLE6, GMSH_LINE, GMSH_LINE3, GMSH_POINT = 2, 9, 1, 8, 15


# --- gmsh in a child process -------------------------------------------------------------------
def apart(work: Callable[..., T], *args) -> T:
    """``work(*args)`` in a forked child process; its value or exception comes back through a pipe.

    gmsh does not return to Python while it meshes (a minute for a large mesh), so in this process a
    signal handler would run only after it; here the parent waits in short steps, and on SIGTERM or
    Ctrl-C it kills the child and goes on with its own clean exit.  (The child touches no MPI.)  The
    child never outlives this process, however it ends (SIGKILL included): see :func:`_child`.  The
    first work goes to the child :func:`warm_up` started, if any (the work and its arguments pickled);
    the CPU seconds that child spent before its work came (importing gmsh) are :func:`warm_up_cpu`'s.
    """
    child = None
    if _warm:
        child, requests, receiver = _warm.pop()
        try:
            requests.send((work, args))
        except Exception:  # it has ended, or the work does not pickle: a child of its own instead
            _end(child, receiver)
            child = None
        finally:
            requests.close()
    if child is None:
        child, receiver = _fork(work, args)
    try:
        while not receiver.poll(0.05):
            if not child.is_alive() and not receiver.poll(0.05):
                break
        try:
            ok, value, waiting = receiver.recv()
        except EOFError:  # the child ended without an answer (gmsh aborted it)
            child.join()
            raise MeshError(f"gmsh stopped without a mesh (it aborted, exit status {child.exitcode}): change the element "
                            "sizes (mesh.size, mesh.grading, the sizes of a .geo) or the geometry") from None
    finally:
        _end(child, receiver)
    if waiting:  # a warm child's
        _warm_cpu.append(waiting)
    if not ok:
        raise value
    return value


#: The child :func:`warm_up` started, with the pipes to send it its work and to receive the answer.
_warm: list = []
#: CPU seconds the children of :func:`apart` spent before their work came, not yet taken.
_warm_cpu: list[float] = []


def warm_up_cpu() -> float:
    """CPU seconds the children of :func:`apart` that ended since the last call spent before their work came:
    the warm child's import of gmsh, done while this process started (its start-up's, not its meshing's)."""
    seconds = sum(_warm_cpu)
    _warm_cpu.clear()
    return seconds


def warm_up() -> None:
    """Fork the child for this process's first :func:`apart` now: it imports gmsh (0.15 s) while this
    process goes on starting (MPI, PETSc), and then waits for its work."""
    if not _warm:
        requests, sender = multiprocessing.get_context("fork").Pipe(duplex=False)
        child, receiver = _fork(None, requests)
        requests.close()
        _warm.append((child, sender, receiver))


def _fork(*work) -> tuple:
    """A forked child running :func:`_child` on ``work``, and the pipe its answer comes through."""
    context = multiprocessing.get_context("fork")
    receiver, sender = context.Pipe(duplex=False)
    child = context.Process(target=_child, args=(os.getpid(), sender, *work), daemon=True)
    # An interrupt inside fork's hooks (logging's lock release) would be printed as "Exception ignored":
    # it waits, blocked, until the child exists, and then reaches this process's handler as usual.
    interrupts = {signal.SIGINT, signal.SIGTERM}
    signal.pthread_sigmask(signal.SIG_BLOCK, interrupts)
    try:
        child.start()
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, interrupts)
    sender.close()
    return child, receiver


def _end(child, receiver) -> None:
    receiver.close()
    if child.is_alive():
        child.kill()
    child.join()


def _child(parent: int, sender, work, args) -> None:
    # The kernel kills this process when its parent ends; SIGINT and SIGTERM end it at once (gmsh does
    # not return to Python for them), and they no longer wake the parent's watchdog through the
    # inherited wakeup fd: the parent, which gets them too, cleans up and kills this child itself.
    end_with_parent(parent)
    signal.set_wakeup_fd(-1)
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})  # blocked across the fork
    quiet = os.open(os.devnull, os.O_WRONLY)  # gmsh writes its aborts to standard error: the parent reports
    os.dup2(quiet, 2)
    os.close(quiet)
    waiting = 0.0
    try:
        if work is None:  # warm (warm_up): gmsh first, then the work from the pipe ``args``
            import gmsh  # noqa: F401

            try:
                work, args = args.recv()
            except EOFError:  # the parent needed no mesh
                return
            used = resource.getrusage(resource.RUSAGE_SELF)
            waiting = used.ru_utime + used.ru_stime
        outcome = (True, work(*args), waiting)
    except BaseException as exc:  # every error goes back to the parent, which raises it
        outcome = (False, exc, waiting)
    sender.send(outcome)
    sender.close()


# --- gmsh geometries with physical groups --------------------------------------------------------
def has_halves(path: Path) -> bool:
    """Whether a .msh file has the physical surfaces ``lower`` and ``upper`` (else it is a box file)."""
    readable(path, "mesh file", MeshError)
    with session() as gmsh:
        open_file(gmsh, path)
        names = {gmsh.model.getPhysicalName(dim, tag) for dim, tag in gmsh.model.getPhysicalGroups(2)}
    return {"lower", "upper"} <= names


#: gmsh's options in every session: nothing on the terminal.
QUIET = {"General.Terminal": 0, "General.Verbosity": 0}
#: More options for meshes that must not depend on timing: one thread, one algorithm, sizes only from the
#: size field (a half is the same whether it is meshed alone in a process or after the other one).
DETERMINISTIC = {"General.NumThreads": 1, "Mesh.MaxNumThreads2D": 1, "Mesh.Algorithm": 5,
                 "Mesh.MeshSizeFromPoints": 0, "Mesh.MeshSizeExtendFromBoundary": 0, "Mesh.MeshSizeFromCurvature": 0}


@contextlib.contextmanager
def session(deterministic: bool = False):
    """gmsh, initialized without the user's configuration files and quiet (``deterministic``: with the
    options of :data:`DETERMINISTIC` too), finalized however the block ends; yields the gmsh module."""
    import gmsh  # imported here: importing gmsh changes the SIGINT handler until finalize

    gmsh.initialize([], readConfigFiles=False)
    try:
        for name, value in {**QUIET, **(DETERMINISTIC if deterministic else {})}.items():
            gmsh.option.setNumber(name, value)
        yield gmsh
    finally:
        gmsh.finalize()


def open_file(gmsh, path: Path) -> None:
    try:
        gmsh.open(str(path))
    except Exception as exc:  # gmsh raises a bare Exception with its last error
        raise MeshError(f"{path}: gmsh cannot read it ({' '.join(str(exc).split())})") from None


def from_gmsh(scene: Scene) -> Mesh:
    """A .geo meshed or a .msh read by gmsh (:func:`_from_gmsh`) in a child process (:func:`apart`)."""
    return apart(_from_gmsh, scene)


def _from_gmsh(scene: Scene) -> Mesh:
    """Mesh a .geo (honouring ``mesh.size`` and ``mesh.grading``) or read a .msh, both with physical groups."""
    options, where = scene.mesh, str(scene.mesh.file)
    with session() as gmsh:
        groups, points, position = meshed(gmsh, scene, REQUIRED_GROUPS)
        surfaces, curves = group_elements(gmsh, groups, ("lower", "upper"), position, where)
        normals = _curve_normals(gmsh, groups[(1, SIGMA)], position, len(points)) if options.kind == "geo" else None
        named_points = _named_points(gmsh, groups, points, position)
    cells = surfaces["lower"]
    if cells.shape[1] == 6 and options.degree == 1:
        raise MeshError(f"{where}: the file has 6-node (P2) triangles: set mesh.degree = 2, without mesh.refine "
                        "(a mesh file is refined from its 3-node triangles: give it as P1 to refine it)")
    halves, renumbered = [], []
    for side, name in ((-1, "lower"), (1, "upper")):
        cells = surfaces[name]
        used = np.zeros(len(points), dtype=bool)
        used[cells] = True
        mine = {curve: edges[used[edges].all(axis=1)] for curve, edges in curves.items()}
        half_points = points
        if cells.shape[1] == 3 and options.degree == 2:
            half_points, cells, mine = elevate(points, cells, {k: v[:, :2] for k, v in mine.items()})
        half, renumber = make_half(half_points, cells, side, mine, where)
        halves.append(half)
        renumbered.append(renumber)
    exact = None
    if normals is not None:
        lower = halves[0]
        old = np.full(len(lower.points), -1, dtype=np.int64)
        old[renumbered[0][renumbered[0] >= 0]] = np.flatnonzero(renumbered[0] >= 0)
        exact = normals[old[lower.sigma]]
    return with_named_points(make_mesh(*halves, where, exact_normals=exact), named_points)


def meshed(gmsh, scene: Scene, required: dict[int, tuple[str, ...]]) -> tuple[dict, np.ndarray, np.ndarray]:
    """The scene's gmsh file opened in the session ``gmsh`` (its physical groups checked: ``required``) and, for a
    .geo, meshed (``mesh.size``, ``mesh.grading``, ``mesh.degree``): its groups (:func:`physical_groups`), its nodes
    ``(n, 2)`` and the position of each node tag among them."""
    path, options = scene.mesh.file, scene.mesh
    where = str(path)
    if scene.geometry.given:
        raise MeshError(f"{where}: geometry.{sorted(scene.geometry.given)[0]} does not apply to a geometry "
                        "with physical groups (they define it)")
    readable(path, "mesh file", MeshError)
    if options.kind == "geo":
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.MaxNumThreads2D", 1)
    open_file(gmsh, path)
    groups = physical_groups(gmsh, where, required)
    if options.kind == "geo":
        if options.size is not None:
            gmsh.option.setNumber("Mesh.MeshSizeMax", options.size)
        low, high = np.reshape(gmsh.model.getBoundingBox(-1, -1), (2, 3))
        length = float(np.min((high - low)[:2]))
        _bounded_curves(gmsh, groups, options.degree, length, where)
        if options.grading is not None:
            set_size_field(gmsh, options, model_singular_points(gmsh, groups), length)
        try:
            gmsh.model.mesh.generate(2)
            if options.degree == 2:
                gmsh.model.mesh.setOrder(2)
        except Exception as exc:
            raise MeshError(f"{where}: gmsh cannot mesh it ({' '.join(str(exc).split())})") from None
    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    points = np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)
    if np.abs(points[:, 2]).max(initial=0.0) > TOL * max(np.ptp(points[:, :2], axis=0).max(), 1e-300):
        raise MeshError(f"{where}: the geometry is not planar (z != 0)")
    return groups, points[:, :2], node_positions(tags)


def group_elements(gmsh, groups: dict[tuple[int, str], list[int]], surfaces: tuple[str, ...], position: np.ndarray,
                   where: str) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The triangles of the physical ``surfaces`` and the edges of every physical curve, by name (node indices)."""
    return ({name: _elements(gmsh, groups[(2, name)], (GMSH_TRIANGLE, GMSH_TRIANGLE6), position, where)
             for name in surfaces},
            {name: _elements(gmsh, entities, (GMSH_LINE, GMSH_LINE3), position, where)
             for (dim, name), entities in groups.items() if dim == 1})


def _named_points(gmsh, groups: dict[tuple[int, str], list[int]], points: np.ndarray, position: np.ndarray
                  ) -> dict[str, np.ndarray]:
    """The physical points: name -> the coordinates ``(k, 2)`` of the nodes of its point elements (a support
    where a ``[displacements.LAYER.NAME]`` names it)."""
    out = {}
    for (dim, name), entities in groups.items():
        if dim == 0:
            tags = [np.asarray(nodes, dtype=np.int64) for entity in dict.fromkeys(entities)
                    for nodes in gmsh.model.mesh.getElements(0, entity)[2]]
            found = np.unique(np.concatenate(tags)) if tags else np.zeros(0, dtype=np.int64)
            out[name] = np.unique(points[position[found]], axis=0).reshape(-1, 2)
    return out


def _bounded_curves(gmsh, groups: dict[tuple[int, str], list[int]], degree: int, length: float, where: str) -> None:
    """Refuse a .geo whose own sizes (its points' sizes, Mesh.MeshSizeFactor, mesh.size) ask gmsh for more
    than it can do: elements below ``SMALLEST`` × the geometry's length, or a mesh too large to solve in
    this machine's memory.  Its curves are meshed without the factor and with sizes of at least that
    floor (a bounded amount of work), measured, and the mesh cleared; the smallest size asked is the
    shortest edge times the factor, the number of vertices is estimated from the nodes on each surface's
    boundary (divided by the factor).  gmsh itself, asked for too many nodes on a curve, makes one
    element of it without a word, or asks on the terminal whether to go on."""
    from ddsolve.environment import RANK_MEMORY, VERTEX_MEMORY, physical_memory

    floor = SMALLEST["geo"] * length
    saved = {name: gmsh.option.getNumber(name) for name in ("Mesh.MeshSizeFactor", "Mesh.MeshSizeMin")}
    factor = saved["Mesh.MeshSizeFactor"]
    gmsh.option.setNumber("Mesh.MeshSizeFactor", 1.0)
    gmsh.option.setNumber("Mesh.MeshSizeMin", max(saved["Mesh.MeshSizeMin"], floor))
    try:
        gmsh.model.mesh.generate(1)
    except Exception as exc:
        raise MeshError(f"{where}: gmsh cannot mesh it ({' '.join(str(exc).split())})") from None
    finally:
        for name, value in saved.items():
            gmsh.option.setNumber(name, value)
    tags, coordinates, _ = gmsh.model.mesh.getNodes()
    points = np.asarray(coordinates, dtype=np.float64).reshape(-1, 3)[node_positions(tags)[
        np.asarray(gmsh.model.mesh.getElementsByType(GMSH_LINE)[1], dtype=np.int64)]].reshape(-1, 2, 3)
    shortest = factor * float(np.linalg.norm(points[:, 1] - points[:, 0], axis=1).min(initial=math.inf))
    vertices = 0.0
    for surface in (entity for (dim, _), entities in groups.items() if dim == 2 for entity in entities):
        curves = {abs(tag) for _, tag in gmsh.model.getBoundary([(2, surface)], combined=False)}
        boundary = sum(len(gmsh.model.mesh.getNodes(1, curve, includeBoundary=True)[0]) for curve in curves)
        vertices += VERTICES_PER_BOUNDARY_NODE_SQUARED * (boundary / min(factor, 1.0)) ** 2 * degree ** 2
    gmsh.model.mesh.clear()
    if shortest <= 1.5 * floor:
        raise MeshError(f"{where}: the file asks gmsh for elements of size {min(shortest, floor):.2g} or less (its points' "
                        f"sizes times Mesh.MeshSizeFactor = {factor:g}), below what gmsh meshes reliably "
                        f"({SMALLEST['geo']:g} × the geometry's size {length:.3g}): enlarge them")
    memory = RANK_MEMORY + vertices * VERTEX_MEMORY
    if memory > physical_memory():
        raise MeshError(f"{where}: its sizes (its points' sizes, Mesh.MeshSizeFactor = {factor:g}, mesh.size) give a "
                        f"mesh of about {vertices:.2g} vertices, which needs about {memory / 1e9:.2g} GB to solve, more "
                        f"than this machine's {physical_memory() / 1e9:.3g} GB: enlarge them")


#: Vertices of a uniform mesh of a surface per square of the number of nodes on its boundary: 0.072 for a
#: square, 0.092 for a disc (2/√3 vertices per h², boundary length/h nodes).
VERTICES_PER_BOUNDARY_NODE_SQUARED = 0.08


def physical_groups(gmsh, where: str, required: dict[int, tuple[str, ...]] = REQUIRED_GROUPS
                    ) -> dict[tuple[int, str], list[int]]:
    """(dim, name) -> entity tags (points, curves, surfaces); the ``required`` groups must exist."""
    groups: dict[tuple[int, str], list[int]] = {}
    for dim, tag in gmsh.model.getPhysicalGroups():
        name = gmsh.model.getPhysicalName(dim, tag)
        if dim in (0, 1, 2) and name:
            groups.setdefault((dim, name), []).extend(int(e) for e in gmsh.model.getEntitiesForPhysicalGroup(dim, tag))
    for dim, names in required.items():
        for name in names:
            if (dim, name) not in groups:
                kind = "surface" if dim == 2 else "curve"
                raise MeshError(f"{where}: missing physical {kind} {name!r} (required: surfaces lower, upper; "
                                "curve sigma; optional: clamped, crack and names for loads and displacements)")
    return groups


def _elements(gmsh, entities: list[int], types: tuple[int, int], position: np.ndarray, where: str) -> np.ndarray:
    """Node indices of the elements of ``entities`` (of the linear or the quadratic type), each once
    (:func:`~ddsolve.mesh.mesh.merge_repeats`: a MSH 2.2 file lists an element once per physical group)."""
    dim = 2 if types[0] == GMSH_TRIANGLE else 1
    width = {GMSH_TRIANGLE: 3, GMSH_TRIANGLE6: 6, GMSH_LINE: 2, GMSH_LINE3: 3}
    found = {t: [] for t in types}
    for entity in dict.fromkeys(entities):
        element_types, _, node_tags = gmsh.model.mesh.getElements(dim, entity)
        in_groups = len(gmsh.model.getPhysicalGroupsForEntity(dim, entity))
        for kind, nodes in zip(element_types, node_tags):
            if kind in found:
                found[kind].append(merge_repeats(np.asarray(nodes, dtype=np.int64).reshape(-1, width[kind]), in_groups))
            elif dim == 2:
                raise MeshError(f"{where}: the surfaces must hold triangles only (found gmsh element type {kind})")
    kind = types[1] if found[types[1]] else types[0]
    nodes = np.concatenate(found[kind]) if found[kind] else np.zeros((0, width[kind]), dtype=np.int64)
    return position[nodes]


def _curve_normals(gmsh, entities: list[int], position: np.ndarray, count: int) -> np.ndarray:
    """Unit normals of Σ's curves at their nodes from gmsh's parametrization (NaN where unknown).

    Inside a curve the normal is exact; at a point where curves meet it is exact when the curves
    meeting there have the same tangent, and unknown at a kink (the caller averages the edges).
    """
    found: dict[int, list[np.ndarray]] = {}
    for entity in entities:
        tags, coordinates, _ = gmsh.model.mesh.getNodes(1, entity, includeBoundary=True, returnParametricCoord=False)
        if len(tags) == 0:
            continue
        # Parameters recomputed from the coordinates: those stored with the nodes are less accurate.
        parameters = gmsh.model.getParametrization(1, entity, coordinates)
        derivative = np.asarray(gmsh.model.getDerivative(1, entity, parameters), dtype=float).reshape(-1, 3)[:, :2]
        length = np.linalg.norm(derivative, axis=1)
        for tag, d, size in zip(np.asarray(tags, dtype=np.int64), derivative, length):
            if size > 0:
                found.setdefault(int(tag), []).append(np.array([-d[1], d[0]]) / size)
    normals = np.full((count, 2), np.nan)
    for tag, candidates in found.items():
        first = candidates[0]
        if all(abs(abs(first @ other) - 1.0) < 1e-10 for other in candidates):  # one tangent line: no kink
            normals[position[tag]] = first
    return normals


def write_msh(mesh: Mesh, path: Path) -> None:
    """Write ``mesh`` as a gmsh .msh file with the physical groups :func:`from_gmsh` reads.

    The Σ nodes of the two halves become one node each, so the file describes one domain.
    """
    lower, upper = mesh.lower, mesh.upper
    offset = len(lower.points)
    upper_numbers = offset + np.arange(len(upper.points))
    upper_numbers[upper.sigma] = lower.sigma  # shared Σ nodes
    keep = np.ones(len(upper.points), dtype=bool)
    keep[upper.sigma] = False
    points = np.vstack([lower.points, upper.points[keep]])
    compact = np.cumsum(np.concatenate([np.ones(offset, dtype=bool), keep])) - 1
    numbers = {-1: np.arange(offset), 1: compact[upper_numbers]}
    element = {3: (GMSH_TRIANGLE, GMSH_LINE), 6: (GMSH_TRIANGLE6, GMSH_LINE3)}[lower.cells.shape[1]]
    with session() as gmsh:
        gmsh.model.add("ddsolve")
        entity = gmsh.model.addDiscreteEntity(0)
        gmsh.model.mesh.addNodes(0, entity, np.arange(1, len(points) + 1),
                                 np.column_stack([points, np.zeros(len(points))]).ravel())
        next_element = 1
        for half in (lower, upper):
            surface = gmsh.model.addDiscreteEntity(2)
            cells = numbers[half.side][half.cells] + 1
            gmsh.model.mesh.addElementsByType(surface, element[0], np.arange(next_element, next_element + len(cells)),
                                              cells.ravel())
            next_element += len(cells)
            gmsh.model.setPhysicalName(2, gmsh.model.addPhysicalGroup(2, [surface]), half.name)
        for name in sorted(set(lower.boundaries) | set(upper.boundaries)):
            halves = (lower,) if name in (SIGMA, CRACK) else (lower, upper)  # Σ edges are shared
            edges = np.concatenate([numbers[half.side][half.edges(name)] for half in halves]) + 1
            curve = gmsh.model.addDiscreteEntity(1)
            gmsh.model.mesh.addElementsByType(curve, element[1], np.arange(next_element, next_element + len(edges)),
                                              edges.ravel())
            next_element += len(edges)
            gmsh.model.setPhysicalName(1, gmsh.model.addPhysicalGroup(1, [curve]), name)
        for name, where in sorted(mesh.named_points.items()):
            nodes = np.unique(np.concatenate([point_nodes(points, xy) for xy in where])) + 1
            if len(nodes):
                spot = gmsh.model.addDiscreteEntity(0)
                gmsh.model.mesh.addElementsByType(spot, GMSH_POINT, np.arange(next_element, next_element + len(nodes)),
                                                  nodes)
                next_element += len(nodes)
                gmsh.model.setPhysicalName(0, gmsh.model.addPhysicalGroup(0, [spot]), name)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(str(path))
