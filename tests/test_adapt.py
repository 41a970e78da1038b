"""The adaptive loop's marking (a refined mesh aimed at the target) and its decisions (serial)."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import structured_mesh

from ddsolve.errors import DDSolveError
from ddsolve.mesh import bisection
from ddsolve.mesh.mesh import Mesh, blocks
from ddsolve.post.result import Result
from ddsolve.problem import scene
from ddsolve.problem.scene import Geometry
from ddsolve.solvers import adapt, reference


def _indicators(mesh, hot):
    """Indicators: 1e-3 everywhere, 1 in the cells of the lower half listed in ``hot`` (block u_minus)."""
    out = {spec.name: np.full(len(mesh.half(spec.side).cells), 1e-3) for spec in blocks(2)}
    out["u_minus"][hot] = 1.0
    return out


def _result(mesh, estimate, indicators):
    return Result(scene=scene.load("partial-closure"), method="schur", converged=True, iterations=1, solves=3, wall_time=0.0, ranks=1,
                  mesh=mesh, solution={}, multipliers={}, history=np.zeros(0),
                  attrs={"error_estimate": estimate}, indicators=indicators)


def test_the_plan_refines_where_the_indicators_are_and_predicts_the_target():
    mesh = structured_mesh(8, 4, degree=2, geometry=Geometry(cracks=()))
    hot = np.array([10, 11])
    indicators = _indicators(mesh, hot)
    estimate, target = 0.05, 0.005
    tri, predicted = adapt.plan(mesh, indicators, estimate, target, limit=1e7)
    aim = target / adapt.SAFETY
    assert aim / 2 < predicted <= aim  # reached, and not by refining far past it
    refined = bisection.to_mesh(tri)
    centres = refined.lower.points[refined.lower.corners].mean(axis=1)
    areas, first = refined.lower.areas(), mesh.lower.areas()[0]
    distance = np.linalg.norm(centres - mesh.lower.points[mesh.lower.corners[hot]].mean(axis=(0, 1)), axis=1)
    assert np.any(areas < first / 4) and distance[areas < first / 4].max() < 0.35  # the hot cells, bisected
    assert np.allclose(areas[distance > 0.7], first)  # cold cells far away stay
    assert adapt.planned_unknowns(tri) == adapt.unknowns(refined)


def test_the_loop_stops_at_the_target_the_level_limit_or_the_size_limit(monkeypatch):
    mesh = structured_mesh(8, 4, degree=1, geometry=Geometry())
    result = _result(mesh, 0.05, _indicators(mesh, np.array([3])))
    assert adapt.next_level(result, 0.1, 0) == (True, None, "")
    done, refined, message = adapt.next_level(result, 0.01, 0)
    assert not done and isinstance(refined, Mesh) and message == ""
    assert adapt.unknowns(refined) > adapt.unknowns(mesh)
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
    assert done and "mesh.target_error = 0.01 not reached: the next mesh would have about" in message


def test_target_error_alone_chooses_p2_and_grading():
    assert scene.load("partial-closure", ["mesh.target_error=0.01"]).mesh.degree == 2
    assert scene.load("partial-closure", ["mesh.target_error=0.01", "mesh.degree=1"]).mesh.degree == 1
    assert scene.load("partial-closure").mesh.degree == 1
    graded = scene.load("arc-bond", ["mesh.target_error=0.01"]).mesh
    assert graded.grading == scene.GRADING[2]
    assert scene.load("arc-bond", ["mesh.target_error=0.01", "mesh.grading=false"]).mesh.grading is None
    assert scene.load("partial-closure", ["mesh.target_error=0.01"]).mesh.grading is None  # the paper's family


@pytest.mark.solve
@pytest.mark.parametrize("name", ["partial-closure", "linear"])
def test_energies_decrease_monotonically_under_refinement(name):
    source = scene.load(name, ["mesh.target_error=0.01"])
    mesh = structured_mesh(8, 4, geometry=Geometry())
    energies = []
    for round_ in range(4):
        result = reference.solve_monolithic(source, mesh)
        energies.append(float(result.attrs["energy"]))
        marked = adapt.cell_indicators(mesh, result.indicators)
        marked = marked > np.quantile(marked, 0.6)
        mesh = bisection.refine(mesh, marked, longest_edge=round_ == 0)
    assert all(b < a for a, b in zip(energies, energies[1:])), energies


def test_the_decision_after_a_level_is_taken_once_inside_its_solve_or_after_it(monkeypatch):
    """NextLevel takes next_level's decision when the solve asks (the level is refined next exactly when it
    is not done, and then leaves out G), keeps a refusal for every rank, and decides after the solve for a
    level that did not ask (the reference's)."""
    mesh = structured_mesh(8, 4, degree=1, geometry=Geometry())
    result = _result(mesh, 0.05, _indicators(mesh, np.array([3])))
    for target, level in ((0.1, 0), (0.01, 0), (0.01, adapt.MAX_LEVELS - 1)):
        asked, after = adapt.NextLevel(target, level, None), adapt.NextLevel(target, level, None)
        done = adapt.next_level(result, target, level)[0]
        assert asked.refined_next(result) == (not done)
        assert asked.taken(result)[0::2] == after.taken(result)[0::2] == adapt.next_level(result, target, level)[0::2]
    monkeypatch.setattr(adapt, "MAX_UNKNOWNS", 100)
    refused = adapt.NextLevel(0.01, 0, None)
    assert not refused.refined_next(result)  # the solve finishes the level; every rank then sees the refusal
    with pytest.raises(DDSolveError, match="refused"):
        refused.taken(result)
    monkeypatch.setattr(adapt, "PREDICTION_MARGIN", 1e6)
    past_limit = adapt.NextLevel(0.01, 1, None)
    assert not past_limit.refined_next(result)  # a plan past the size limit: this level is the result, whole
    assert "the next mesh would have about" in past_limit.taken(result)[2]
