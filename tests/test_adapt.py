"""Dörfler marking and the size map of the next mesh (serial)."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import structured_mesh

from ddsolve.errors import DDSolveError
from ddsolve.mesh import sizing
from ddsolve.mesh.mesh import BLOCKS
from ddsolve.post.result import Result
from ddsolve.problem.scene import Geometry
from ddsolve.solvers import adapt


def _indicators(mesh, hot):
    """Indicators: 1e-3 everywhere, 1 in the cells of the lower half listed in ``hot`` (block u_minus)."""
    out = {spec.name: np.full(len(mesh.half(spec.side).cells), 1e-3) for spec in BLOCKS}
    out["u_minus"][hot] = 1.0
    return out


def test_dorfler_marks_the_fewest_cells_carrying_half_the_estimate_and_halves_them():
    mesh = structured_mesh(8, 4, degree=2, geometry=Geometry())
    hot = np.array([0, 5])
    sizes, growth = adapt.refined_sizes(mesh, _indicators(mesh, hot))
    lower = mesh.lower
    corners = lower.points[lower.corners]
    h = np.linalg.norm(corners - corners[:, [1, 2, 0]], axis=2).mean(axis=1)
    wanted = sizes.sizes[:len(lower.cells)]
    for cell in hot:  # the marked cells get half their size at their corners
        assert np.allclose(wanted[cell], 0.5 * h[cell])
    far = np.setdiff1d(np.arange(len(lower.cells)), hot)
    untouched = ~np.isin(lower.corners[far], lower.corners[hot]).any(axis=1)
    assert np.all(wanted[far[untouched]] > 0.9 * h[far[untouched]].min())  # elsewhere the present size
    # Four times as many cells where marked: 2 of 128 cells.
    assert growth == pytest.approx((len(mesh.lower.cells) + len(mesh.upper.cells) + 2 * 3) /
                                   (len(mesh.lower.cells) + len(mesh.upper.cells)))
    # Σ vertices have one size, whichever half the map is read from.
    positions = {tuple(p): s for p, s in zip(sizes.corners.reshape(-1, 2).round(12).tolist(), sizes.sizes.ravel())}
    lower_sigma = mesh.lower.points[mesh.lower.sigma[mesh.sigma.corner]]
    for point in lower_sigma.round(12).tolist():
        values = [s for p, s in zip(sizes.corners.reshape(-1, 2).round(12).tolist(), sizes.sizes.ravel())
                  if p == point]
        assert np.ptp(values) == 0.0 and positions[tuple(point)] == values[0]


def test_the_loop_stops_at_the_target_the_level_limit_or_the_size_limit(monkeypatch):
    mesh = structured_mesh(8, 4, degree=1, geometry=Geometry())
    result = Result(scene="", method="schur", converged=True, iterations=1, solves=3, wall_time=0.0, ranks=1,
                    mesh=mesh, solution={}, multipliers={}, history=np.zeros(0),
                    attrs={"error_estimate": 0.05}, indicators=_indicators(mesh, np.array([3])))
    assert adapt.next_level(result, 0.1, 0) == (True, None, "")
    done, sizes, message = adapt.next_level(result, 0.01, 0)
    assert not done and isinstance(sizes, sizing.SizeMap) and message == ""
    done, _, message = adapt.next_level(result, 0.01, adapt.MAX_LEVELS - 1)
    assert done and message == (f"mesh.target_error = 0.01 not reached in {adapt.MAX_LEVELS} levels "
                                "(estimated error 0.05)")
    monkeypatch.setattr(adapt, "MAX_UNKNOWNS", 100)  # 360 unknowns need about 9000 for the target
    with pytest.raises(DDSolveError, match=r"mesh.target_error = 0.01 refused: it needs about 9e\+03 unknowns"):
        adapt.next_level(result, 0.01, 0)
    done, _, message = adapt.next_level(result, 0.01, 1)
    assert done and "not reached, and out of reach: it needs about 9e+03 unknowns" in message
    monkeypatch.setattr(adapt, "PREDICTION_MARGIN", 1e6)
    done, _, message = adapt.next_level(result, 0.01, 1)
    assert done and "the next mesh would have about" in message
