"""What a run produces: the same schema for the DD solve and the monolithic reference."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .mesh import HalfMesh


@dataclass
class Result:
    """Everything a run produces; the same schema for the DD solve and the reference."""

    scene: str
    method: str
    converged: bool
    iterations: int
    solves: int
    wall_time: float
    ranks: int
    lower: HalfMesh
    upper: HalfMesh
    solution: dict[str, np.ndarray]  # block name -> (n, 2) nodal displacements
    interface_x: np.ndarray
    crack: np.ndarray
    multipliers: dict[str, np.ndarray]
    history: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)
    message: str = ""
    attrs: dict = field(default_factory=dict)

    def half(self, block: str) -> HalfMesh:
        return self.lower if block.endswith("minus") else self.upper
