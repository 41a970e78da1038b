"""The result of a 3-D solve: the displacements of the regions (two halves, or the regions of several
interfaces), the contact pressure on each Σ, the energy, the record of the solve, and what is read from them
(the opening of Σ's faces; each interface seen as a box of one, :meth:`SolidResult.interface`)."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ddsolve.errors import DDSolveError
from ddsolve.mesh.solid import SolidMesh
from ddsolve.post.front import FrontRelease
from ddsolve.problem.schema import REGIONS
from ddsolve.problem.scene import Scene


@dataclass(eq=False)
class SolidResult:
    """A 3-D box solved: ``fields`` the displacements ``(n, 3)`` of its regions bottom to top (the lower and the
    upper half), ``pressures`` the contact pressure μᶜ ≥ 0 at every vertex of each Σ (0 off the cracks),
    ``energy`` Π = ½ a(u, u) − L(u), the active-set ``steps`` of the crack's dual problem, the sparse
    ``solves``, the final check's verdict, the wall seconds per phase and G along the crack fronts
    (``fracture``, where computed; of several interfaces, their rows joined, ``fracture_interface`` naming each
    row's Σ, 1 the lowest)."""

    scene: Scene
    mesh: SolidMesh
    fields: tuple[np.ndarray, ...]
    pressures: tuple[np.ndarray, ...]
    energy: float
    steps: int
    solves: int
    converged: bool
    message: str = ""
    checks: dict[str, float] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    fracture: FrontRelease | None = None
    # an adaptive run's error_estimate, target_error, levels; the decomposition's solver (solid_dd.solver_record)
    attrs: dict[str, float | int | str] = field(default_factory=dict)
    levels: dict[str, np.ndarray] = field(default_factory=dict)  # an adaptive run's level table, a column each
    fracture_interface: np.ndarray | None = None

    @property
    def pressure(self) -> np.ndarray:
        """The contact pressure at every vertex of the Σ of a box of one interface."""
        if len(self.pressures) != 1:
            raise DDSolveError(f"a 3-D box of {len(self.pressures)} interfaces has a pressure per Σ: take pressures")
        return self.pressures[0]

    @property
    def opening(self) -> np.ndarray:
        """u⁺ − u⁻ at every Σ vertex ``(s, 3)`` of a box of one interface: its y component opens the crack (0
        where Σ is glued)."""
        lower, upper = (u[half.sigma_nodes] for u, half in zip(self.fields, self.mesh.halves))
        return upper - lower

    @property
    def normal_opening(self) -> np.ndarray:
        """[u]·ν at every Σ vertex, ν the lower half's outward normal of Σ's frame (negative: overlap)."""
        return np.einsum("sd,sd->s", self.opening, self.mesh.sigma.frames[:, 0])

    @property
    def closed(self) -> int:
        """The crack vertices in contact (a positive pressure), on every Σ."""
        return sum(int(np.count_nonzero(pressure > 0)) for pressure in self.pressures)

    def interface(self, k: int) -> SolidResult:
        """Σ number ``k`` (0 the lowest) and the regions below and above it as the result of a box of one
        interface (:meth:`ddsolve.mesh.solid.SolidMesh.interface`, :func:`view_scene`); the result itself where it
        has one Σ."""
        if len(self.pressures) == 1:
            return self
        return dataclasses.replace(self, scene=view_scene(self.scene, k), mesh=self.mesh.interface(k),
                                   fields=self.fields[k:k + 2], pressures=(self.pressures[k],), fracture=None,
                                   fracture_interface=None)


def view_scene(scene: Scene, k: int) -> Scene:
    """The scene of a 3-D box's interface ``k`` alone: its Σ and cracks, the box between the interfaces below and
    above it (θ about its fronts stays inside its two regions), its regions' materials as those of ``lower`` and
    ``upper``."""
    shape = scene.geometry
    levels = (shape.box[2], *shape.sigmas, shape.box[3])
    box = (*shape.box[:2], levels[k], levels[k + 2], *shape.box[4:])
    names = shape.region_names[k:k + 2]
    return dataclasses.replace(
        scene, geometry=dataclasses.replace(shape, box=box, sigma=shape.sigmas[k], cracks=shape.crack_lists[k],
                                            above=()),
        regions={("layer1", region): scene.material("layer1", name) for region, name in zip(REGIONS, names)})
