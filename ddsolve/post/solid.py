"""The result of a 3-D solve: the displacements of the two halves, the contact pressure on Σ, the energy, the
record of the solve, and what is read from them (the opening of Σ's faces)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ddsolve.mesh.solid import SolidMesh
from ddsolve.post.front import FrontRelease
from ddsolve.problem.scene import Scene


@dataclass(eq=False)
class SolidResult:
    """A 3-D box solved: ``fields`` the displacements ``(n, 3)`` of the lower and the upper half, ``pressure``
    the contact pressure μᶜ ≥ 0 at every Σ vertex (0 off the cracks), ``energy`` Π = ½ a(u, u) − L(u), the
    active-set ``steps`` of the crack's dual problem, the sparse ``solves``, the final check's verdict, the
    wall seconds per phase and G along the crack fronts (``fracture``, where computed)."""

    scene: Scene
    mesh: SolidMesh
    fields: tuple[np.ndarray, np.ndarray]
    pressure: np.ndarray
    energy: float
    steps: int
    solves: int
    converged: bool
    message: str = ""
    checks: dict[str, float] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    fracture: FrontRelease | None = None
    attrs: dict[str, float] = field(default_factory=dict)  # an adaptive run's: error_estimate, target_error, levels
    levels: dict[str, np.ndarray] = field(default_factory=dict)  # an adaptive run's level table, a column each

    @property
    def opening(self) -> np.ndarray:
        """u⁺ − u⁻ at every Σ vertex ``(s, 3)``: its y component opens the crack (0 where Σ is glued)."""
        lower, upper = (u[half.sigma_nodes] for u, half in zip(self.fields, self.mesh.halves))
        return upper - lower

    @property
    def normal_opening(self) -> np.ndarray:
        """[u]·ν at every Σ vertex, ν the lower half's outward normal of Σ's frame (negative: overlap)."""
        return np.einsum("sd,sd->s", self.opening, self.mesh.sigma.frames[:, 0])

    @property
    def closed(self) -> int:
        """The crack vertices in contact (a positive pressure)."""
        return int(np.count_nonzero(self.pressure > 0))
