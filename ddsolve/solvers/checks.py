"""What is checked before any work: rank counts and mesh sizes this machine can hold, and keys a
command does not read (refused, naming them)."""
from __future__ import annotations

from ddsolve.environment import RANK_MEMORY, VERTEX_MEMORY, physical_memory
from ddsolve.errors import DDSolveError, SceneError, UsageError


def check_ranks(ranks: int, structure=None) -> None:
    """Refuse a rank count ddsolve cannot use on a structure (``structure``: its blocks, or its scene; None: any
    plane structure, one or two layers), or that this machine cannot start, before mpiexec."""
    from ddsolve.parallel.launch import supported

    counts, uneven, words = rank_rule(structure)
    if not any(supported(ranks, count, uneven) for count in counts):
        raise UsageError(f"-n {ranks}: unsupported number of ranks: use {words}")
    memory = ranks * RANK_MEMORY
    if memory > physical_memory():
        raise UsageError(f"-n {ranks}: {ranks} ranks need about {memory / 1e9:.3g} GB before any mesh "
                         f"(about {RANK_MEMORY / 1e6:g} MB each), more than this machine's "
                         f"{physical_memory() / 1e9:.3g} GB; for ranks on several machines start mpiexec yourself")


def rank_rule(structure=None) -> tuple[tuple[int, ...], bool, str]:
    """The block counts a structure's decomposition may take (``structure`` as for :func:`check_ranks`), whether a
    rank may hold more of them than another (a 3-D box's, :func:`ddsolve.parallel.launch.supported`), and the rank
    counts they take in words."""
    from ddsolve.parallel.launch import BLOCK_COUNT, usable

    if structure is None:
        return (2, BLOCK_COUNT), False, f"{usable(BLOCK_COUNT)} ({usable(2)} for a one-layer structure)"
    if isinstance(structure, int):
        return (structure,), False, usable(structure)
    if structure.geometry.dimension == 3:
        return solid_rule(structure)
    return rank_rule(structure.geometry.layers * len(structure.geometry.region_names))


def solid_rule(scene) -> tuple[tuple[int, ...], bool, str]:
    """:func:`rank_rule` of the 3-D box ``scene`` (:mod:`ddsolve.solvers.solid_dd`): its regions, a block each, with
    several interfaces, else its halves in ``solver.pieces`` slabs each (``auto``: any count the model considers);
    any rank count up to the blocks, or a multiple of them."""
    from ddsolve.dd.solid_costs import PIECES
    from ddsolve.parallel.launch import usable

    regions = len(scene.geometry.region_names)
    if regions > 2:
        return (regions,), True, f"{usable(regions, uneven=True)} (the {regions} regions of the 3-D box, a block each)"
    pieces = PIECES if scene.solver.pieces == "auto" else (scene.solver.pieces,)
    counts = tuple(2 * count for count in pieces)  # each a multiple of the first: the first's multiples hold theirs
    words = usable(counts[0], uneven=True) if len(counts) == 1 else f"1 to {counts[-1]} or a multiple of {counts[0]}"
    slabs = f"{', '.join(map(str, pieces[:-1]))} or {pieces[-1]}" if len(pieces) > 1 else str(pieces[0])
    return counts, True, f"{words} (the 3-D box's halves in {slabs} slab{'s' * (pieces != (1,))} each)"


def check_size(scene, ranks: int = 1, solving: bool = True, stacks: bool = False, solid: bool = False) -> None:
    """Refuse a mesh that cannot fit in this machine's memory, a ``mesh.refine`` its geometry cannot take
    (:func:`ddsolve.mesh.geometry.refinement`), or, ``solving``, a structure that cannot be solved yet, before
    it is made (``stacks``: the solve takes several interfaces, as the domain decomposition and the reference do;
    ``solid``: it takes a 3-D box, as they do)."""
    from ddsolve.mesh import geometry

    if scene.geometry.dimension == 3:
        if solid:
            return
        body = "mesh.file: a 3-D gmsh file" if scene.geometry.solid_file else "geometry.box: a 3-D box (6 numbers)"
        raise SceneError(f"{body} is solved by ddsolve solve and ddsolve reference only, for now; the other commands "
                         "are plane")
    if solving and not stacks:
        geometry.one_interface(scene)
    geometry.refinement(scene)
    vertices = geometry.estimated_vertices(scene)
    if vertices is None:
        return
    memory = ranks * RANK_MEMORY + vertices * VERTEX_MEMORY
    if memory > physical_memory():
        options = scene.mesh
        keys = (f"mesh.size = {options.size:g}" if options.size is not None else
                f"mesh.sigma_vertices = {options.sigma_vertices}, mesh.boundary_vertices = {options.boundary_vertices}")
        raise DDSolveError(f"{keys}: a mesh of about {vertices:.2g} vertices needs about {memory / 1e9:.2g} GB "
                           f"to solve (about {VERTEX_MEMORY / 1e3:g} kB per vertex), more than this machine's "
                           f"{physical_memory() / 1e9:.3g} GB")


#: The sections of a scene that ``mesh`` does not read, besides mesh.target_error.
NOT_MESHING = ("title", "materials", "loads", "displacements", "temperature", "contact", "solver", "fracture",
               "interface")


#: Material keys that give only the out-of-plane stress or strain (``plane_stress``: E3, nu13 and nu23;
#: ``plane_strain``: Dzz), which a sweep file does not keep.
OUT_OF_PLANE = {"plane_stress": ("E3", "nu13", "nu23", "Dzz"), "plane_strain": ("Dzz",)}


def unread(command: str, path: list[str], scene) -> str | None:
    """Why ``command`` would not read the key ``path`` of ``scene`` (None: it does)."""
    from ddsolve.dd import registry
    from ddsolve.problem.method_options import OPTIONS

    section, leaf = path[0], path[2:][-1:]  # a material's key: materials.LAYER.KEY or materials.LAYER.REGION.KEY
    if command == "mesh":
        if section == "displacements" and _point_support(scene, path):
            return None  # the mesh carries a vertex at the point, named as the support is
        if section in NOT_MESHING or path[:2] == ["mesh", "target_error"]:
            return "mesh makes the starting mesh only (solve, reference and sweep read the key)"
        return None
    if section == "interface" and command == "reference" and scene.bond is not None and scene.bond.law != "elastic":
        return ("the monolithic reference solves the elastic law only (solve and sweep solve the bilinear law's "
                "damage)")
    if section == "solver" and command == "reference" and path[1:] != ["out_of_core"]:
        return ("it sets how solve and sweep iterate and bound their multipliers, and reference solves the discrete "
                "problem exactly, without a bound")
    if section == "materials" and leaf == ["Dzz"] and scene.model == "plane_stress":
        return "Dzz gives the out-of-plane stress of plane strain, and materials.model = plane_stress has none"
    if command == "sweep" and (section == "title" or section == "materials" and leaf
                               and leaf[0] in OUT_OF_PLANE[scene.model]):
        return ("a sweep file keeps no title" if section == "title" else "it gives only the out-of-plane stress or "
                "strain, which a sweep file does not keep (solve and reference write it)")
    if section == "solver":
        method = OPTIONS[scene.solver.method]
        if path[1:] == ["theta"] and not method.step:
            return f"it is the step of method {_listed(registry.stepping_methods())}, and method {method.name} takes none"
        if path[1:] == ["max_iterations"] and not method.iterates:
            return (f"method {method.name} is exact in a few rounds and iterates no further "
                    f"({_listed(registry.iterating_methods())} do)")
    return None


def _listed(names: list[str]) -> str:
    """``a, b and c``."""
    return " and ".join([", ".join(names[:-1]), names[-1]] if len(names) > 1 else names)


def _point_support(scene, path: list[str]) -> bool:
    """Whether ``path`` is a key of a point support's table (``displacements.LAYER.NAME`` with a point)."""
    displacement = scene.displacements.get(tuple(path[1:3])) if len(path) >= 3 else None
    return displacement is not None and displacement.point is not None


def check_read(command: str, items: list[str], scene) -> None:
    """Refuse a ``--set`` item whose key (or a key of the table it sets) ``command`` would not read
    (:func:`unread`): every key a command is given is honoured or refused."""
    from ddsolve.problem.scene import parse_override, printable

    def leaves(path: list[str], value) -> list[list[str]]:
        if isinstance(value, dict) and value:
            return [leaf for key, sub in value.items() for leaf in leaves([*path, key], sub)]
        return [path]

    for item in items:
        for path in leaves(*parse_override(item)):
            why = unread(command, path, scene)
            if why is not None:
                raise SceneError(f"--set {printable(item)}: {printable('.'.join(path))} is not read by {command}: "
                                 f"{why}; leave it out")


def nodes_in_memory(ranks: int) -> float:
    """The most mesh nodes a solve on ``ranks`` ranks holds in this machine's memory (as in check_size)."""
    return max(physical_memory() - ranks * RANK_MEMORY, 0.0) / VERTEX_MEMORY
