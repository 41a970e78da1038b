"""Crack shapes on a 3-D box's Σ besides the rectangle: the ellipse ``{center = [x, z], radii = [r1, r2]}``, its
axes along x and z.  The part inside the box is the crack (a centre on a side of the box gives half or a quarter of
it, the model of a symmetric crack)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Ellipse:
    """The ellipse ((x − cx)/r1)² + ((z − cz)/r2)² ≤ 1 on Σ."""

    center: tuple[float, float]
    radii: tuple[float, float]

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """Its bounding rectangle (a, b, c, d): a ≤ x ≤ b, c ≤ z ≤ d."""
        (x, z), (r1, r2) = self.center, self.radii
        return (x - r1, x + r1, z - r2, z + r2)

    def level(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """((x − cx)/r1)² + ((z − cz)/r2)²: below 1 inside, 1 on the front."""
        return ((x - self.center[0]) / self.radii[0]) ** 2 + ((z - self.center[1]) / self.radii[1]) ** 2

    def table(self) -> dict[str, list[float]]:
        """As a scene writes it."""
        return {"center": list(self.center), "radii": list(self.radii)}


def ellipse(value: object) -> Ellipse | None:
    """An ellipse from a table ``{center = [x, z], radii = [r1, r2]}`` of finite numbers with radii > 0, else None."""
    if not isinstance(value, dict) or set(value) != {"center", "radii"}:
        return None
    try:
        center, radii = (tuple(float(v) for v in value[key]) for key in ("center", "radii"))
    except (TypeError, ValueError):
        return None
    numbers = np.array(center + radii)
    if len(center) != 2 or len(radii) != 2 or not np.all(np.isfinite(numbers)) or min(radii) <= 0:
        return None
    return Ellipse(center, radii)


def bounds(crack) -> tuple[float, ...]:
    """A crack's bounding interval or rectangle: an interval or rectangle itself, an ellipse's box."""
    return crack.bounds if isinstance(crack, Ellipse) else tuple(crack)
