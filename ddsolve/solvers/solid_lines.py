"""The progress lines of a 3-D solve, as the plane solves print theirs on rank 0: the mesh's counts once it is
built, the assembly's and factorization's seconds, and G along the crack fronts once it is computed (the
methods' iteration lines are the plane methods' own)."""
from __future__ import annotations

import numpy as np

from ddsolve.mesh.solid import SolidMesh
from ddsolve.post.front import FrontRelease


def mesh_line(mesh: SolidMesh, seconds: float) -> str:
    """The mesh's tetrahedra, nodes, Σ vertices (on the cracks, on the fronts) and unknowns, and its seconds."""
    regions = "two halves" if len(mesh.regions) == 2 else f"{len(mesh.regions)} regions"
    vertices = sum(len(sigma.points) for sigma in mesh.sigmas)
    cracked = sum(int(np.count_nonzero(sigma.cracked)) for sigma in mesh.sigmas)
    fronts = sum(len(np.unique(sigma.front)) for sigma in mesh.sigmas)
    surfaces = "Σ vertices" if len(mesh.sigmas) == 1 else f"vertices on {len(mesh.sigmas)} interfaces Σ"
    return (f"mesh: {sum(len(region.tetrahedra) for region in mesh.regions):,} tetrahedra (P{mesh.degree}) in "
            f"{regions}, {sum(len(region.points) for region in mesh.regions):,} nodes, {vertices:,} {surfaces} "
            f"({cracked:,} on cracks, {fronts:,} on crack fronts), {mesh.unknowns:,} unknowns, {seconds:.1f} s")


def factored_line(what: str, timings: dict[str, float]) -> str:
    """``what`` assembled and factored, with the seconds of each (``timings``' assembly or merge, and
    factorization)."""
    assembly = timings.get("assembly", timings.get("merge", 0.0))
    return f"{what}: assembled in {assembly:.1f} s, factored in {timings['factorization']:.1f} s"


def front_line(fracture: FrontRelease, seconds: float) -> str:
    """How many front nodes on how many fronts G was computed at, and its seconds."""
    return (f"G along the crack fronts: {len(fracture.G):,} nodes on {len(np.unique(fracture.front))} "
            f"front{'s' if len(np.unique(fracture.front)) != 1 else ''}, {seconds:.1f} s")


#: The phases of a 3-D solve in the order they run (the reference's merge, factorization and solve; the
#: decomposition's setup, assembly and factorization).
PHASE_ORDER = ("meshing", "setup", "merge", "assembly", "factorization", "solve", "fracture")


def phases_line(timings: dict[str, float]) -> str:
    """The solve's phases in the order they ran, in seconds (rank 0's clock), as the plane launch line lists its."""
    names = sorted((name for name in timings if name != "total"),
                   key=lambda name: PHASE_ORDER.index(name) if name in PHASE_ORDER else len(PHASE_ORDER))
    return "phases (s): " + ", ".join(f"{name} {timings[name]:.2f}" for name in names)
