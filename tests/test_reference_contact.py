"""The monolithic reference under contact (issue 39): one factorization whatever the active set, the contact
solved on the crack's dense dual problem, started from the unconstrained solution's penetrations; the same
answer as the old route (every active set tied and solved again) and as the DD."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from conftest import SMALL
from mpi4py import MPI
from test_floating import strip

from ddsolve.dd.interface import for_mesh
from ddsolve.fem import assembly, supports
from ddsolve.mesh import geometry
from ddsolve.parallel import distribution
from ddsolve.parallel.blocks import Block
from ddsolve.post import analysis
from ddsolve.problem import scene as scenes
from ddsolve.solvers import driver, reference

SIZES = [item for item in SMALL if item != "--set"]


def tied_solution(systems, interface) -> tuple[list[np.ndarray], np.ndarray]:
    """The old route, densely: the crack vertices in contact tie the faces' normal displacements, the active
    set from the unconstrained solution (all open) updated until it repeats, one dense solve of the whole
    glued system per step.  The blocks' displacements and the closed vertices."""
    contact = interface.slices["mu_c"]
    closed = np.zeros(contact.stop - contact.start, dtype=bool)
    for _ in range(50):
        numbers = reference.numbering(systems, interface, closed)
        merged = reference.merged_system(systems, numbers)
        K = np.zeros((merged.size, merged.size))
        K[np.repeat(np.arange(merged.size), np.diff(merged.indptr)), merged.indices] = merged.data
        x = np.linalg.solve(K, merged.rhs)
        fields = [x[number] for number in numbers]
        loads = np.array([assembly.csr_matvec(s, u)[s.trace_dofs] - s.rhs[s.trace_dofs]
                          for s, u in zip(systems, fields)])
        mu = interface.multipliers(loads)[contact]
        gap = interface.gap(np.array([u[s.trace_dofs] for s, u in zip(systems, fields)]))[contact]
        settled = np.where(closed, mu >= -1e-10 * np.abs(mu).max(initial=0.0), gap > 1e-12 * np.abs(x).max())
        if np.array_equal(settled, closed):
            return fields, closed
        closed = settled
    raise AssertionError("the tied active set did not settle")


def recording(calls: list, function, what):
    """``function`` that first appends ``what`` of its arguments to ``calls``."""
    def recorded(*args, **options):
        calls.append(what(*args, **options))
        return function(*args, **options)
    return recorded


def energy_error(systems, fields, expected) -> float:
    """‖u − v‖_K / ‖v‖_K over the four blocks."""
    def energy(values):
        return sum(u @ assembly.csr_matvec(s, u) for s, u in zip(systems, values))
    return float(np.sqrt(energy([u - v for u, v in zip(fields, expected)]) / energy(expected)))


def problem(source: scenes.Scene):
    mesh = geometry.build(source)
    table = supports.sigma_supports(source, mesh)
    return assembly.block_systems(source, mesh, table=table), for_mesh(mesh.sigma, source.nonpenetration, table.fixed)


@pytest.fixture(scope="module")
def floating_scene(tmp_path_factory) -> scenes.Scene:
    """The floating strip of test_floating: the upper half held only through Σ, the crack partly closed."""
    return scenes.load(str(strip(tmp_path_factory.mktemp("floating"))))


@pytest.mark.solve
@pytest.mark.parametrize("name", ["partial-closure", "full-closure", "strip-disbonds", "floating"])
def test_the_reference_equals_the_tied_route(name, floating_scene):
    source = floating_scene if name == "floating" else scenes.load(name, SIZES)
    systems, interface = problem(source)
    expected, closed = tied_solution(systems, interface)
    solved = reference.solve_glued(systems, interface)
    assert closed.any()
    assert np.array_equal(solved.y > 0.0, closed)
    assert energy_error(systems, solved.fields, expected) < 1e-10


@pytest.mark.solve
def test_the_reference_equals_the_dd_on_a_floating_half(floating_scene):
    mesh = distribution.build_mesh(floating_scene, MPI.COMM_SELF)
    expected = reference.solve_monolithic(floating_scene, mesh)
    solved = driver.solve_decomposed(floating_scene, MPI.COMM_SELF, None, progress=lambda line: None, mesh=mesh)
    assert expected.converged and expected.attrs["closed_vertices"] > 0
    assert analysis.compare(solved, expected).energy_error < 1e-10


@pytest.mark.solve
def test_one_factorization_whatever_the_active_set_steps(monkeypatch):
    factored, solves = [], []
    monkeypatch.setattr(Block, "factor", recording(factored, Block.factor, lambda block, *_, **__: block.name))
    monkeypatch.setattr(Block, "solve", recording(solves, Block.solve, lambda block, *_, **__: block.name))
    source = scenes.load("partial-closure")  # P = 96: five active-set steps
    result = reference.solve_monolithic(source, geometry.build(source))
    assert result.converged and result.iterations >= 3 and result.attrs["closed_vertices"] > 0
    assert factored == ["reference"]  # one factorization, with the Schur complement on the jumps
    assert len(solves) == result.solves == 2 + result.attrs["refined"]  # unconstrained, with the contact forces
    assert len(result.history) == len(result.active_set_changes) == result.iterations
    assert result.history[-1] == 0.0 and result.active_set_changes[-1] == 0
    assert set(result.timings) >= {"merge", "factorization", "solve", "total", "factorization_cpu"}


def face(count: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A random SPD Schur complement on ``count`` jumps, unconstrained jumps of both signs and the weights' roots."""
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((count, count))
    return M @ M.T + count * np.eye(count), rng.standard_normal(count), rng.uniform(0.5, 2.0, count)


def test_the_face_problem_starts_from_the_unconstrained_penetrations(monkeypatch):
    stiffness, unconstrained, sqrt_w = face(8, 1)
    starts = []
    monkeypatch.setattr(reference, "box_qp", recording(starts, reference.box_qp, lambda *_, start, **__: start))
    reference.FaceProblem(stiffness, unconstrained, sqrt_w).solve()
    assert np.array_equal(starts[0] > 0.0, unconstrained > 0.0)  # closed where the faces penetrate, open elsewhere
    apart = reference.FaceProblem(stiffness, -np.abs(unconstrained), sqrt_w)
    assert not apart.solve().any() and len(apart.changes) == 1  # nothing penetrates: one step, no contact


@pytest.mark.parametrize("seed", range(5))
def test_the_face_problem_is_the_best_of_every_active_set(seed):
    """Against every one of the 2ⁿ closed sets: the one whose solution is admissible (no penetration of an
    open vertex, no tension on a closed one)."""
    stiffness, unconstrained, sqrt_w = face(7, seed)
    flexibility = np.linalg.inv(stiffness)
    y = reference.FaceProblem(stiffness, unconstrained, sqrt_w).solve()
    for closed in itertools.product([False, True], repeat=len(sqrt_w)):
        closed = np.array(closed)
        mu = np.zeros(len(sqrt_w))  # jumps j⁰ − S⁻¹ W μ, zero where closed
        mu[closed] = np.linalg.solve(flexibility[np.ix_(closed, closed)], unconstrained[closed]) / sqrt_w[closed] ** 2
        jumps = unconstrained - flexibility @ (sqrt_w ** 2 * mu)
        if np.all(mu[closed] >= 0.0) and np.all(jumps[~closed] <= 1e-12):
            assert np.allclose(y / sqrt_w, mu, rtol=1e-10, atol=1e-12)
            return
    raise AssertionError("no admissible active set")
