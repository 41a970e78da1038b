"""feti's polynomial coarse directions (``solver.coarse_degree``): the directions joint by joint, the subspace that
starts from them and keeps them, the multi-column round that applies A to them, and the decomposition with them
equal to the monolithic reference (contact active, floating slabs, 1, 2 and 4 ranks)."""
from __future__ import annotations

import numpy as np
import pytest

from ddsolve.dd import feti
from ddsolve.dd.interface import Interface
from ddsolve.errors import SceneError
from ddsolve.mesh.mesh import blocks
from ddsolve.problem.scene import loads
from experiments import three_d

#: The 3-D page's partly shut crack in two slabs per half (feti, lumped), as in tests/test_slabs.py.
CLOSURE = three_d.scene_of("partial closure", 0.14, 3).with_({"solver.method": "feti", "solver.pieces": 2})


def plane_interface(contact: bool = True) -> Interface:
    """Σ the plane y = 0 of a 3-D box sampled on a 5 × 4 grid, the first 6 vertices cracked."""
    x, z = np.meshgrid(np.linspace(-1.0, 1.0, 5), np.linspace(0.0, 0.5, 4))
    points = np.column_stack([x.ravel(), np.zeros(x.size), z.ravel()])
    crack = np.arange(len(points)) < 6
    return Interface(np.full(len(points), 0.1), crack, contact, specs=blocks(1), components=3, points=points)


@pytest.mark.unit
def test_polynomial_directions_span_each_joints_polynomials_off_the_bounded_rows():
    """Degree 2 on a plane joint: per component the six monomials of the plane's two coordinates (y, constant, is
    dropped), orthonormal, zero on the contact rows; degree 0 or no points: no direction."""
    interface = plane_interface()
    Z = feti.polynomial_directions(interface, 2)
    assert Z.shape == (interface.size, 3 * 6)
    assert np.allclose(Z.T @ Z, np.eye(Z.shape[1]), atol=1e-12)
    assert not Z[interface.is_contact].any()
    sqrt_w = np.sqrt(interface.row_weights)
    rows = np.flatnonzero(~interface.is_contact & (interface.component == 2))
    x = interface.points[interface.vertex[rows], 0]
    target = np.zeros(interface.size)
    target[rows] = sqrt_w[rows] * (1.0 + x - 0.5 * x ** 2)  # a quadratic in x on the z-component rows: in the span
    assert np.allclose(Z @ (Z.T @ target), target, atol=1e-12)
    assert feti.polynomial_directions(interface, 0).shape == (interface.size, 0)
    no_points = Interface(interface.weights, interface.crack, True, specs=blocks(1), components=3)
    assert feti.polynomial_directions(no_points, 3).shape == (no_points.size, 0)


@pytest.mark.unit
def test_column_loads_and_gaps_are_those_of_each_column():
    """Interface.column_loads / column_gap give, column by column, what loads / gap give for one vector."""
    interface = plane_interface()
    rng = np.random.default_rng(3)
    lam = rng.standard_normal((interface.size, 4))
    lam[:, 3] = 0.0  # a column that loads no block
    pieces = interface.column_loads(lam)
    for block, (taken, load) in enumerate(pieces):
        assert list(taken) == [0, 1, 2]
        for j, column in enumerate(taken):
            assert np.allclose(load[:, j], interface.loads(lam[:, column])[block])
    traces = rng.standard_normal((2, interface.trace_size, 3))
    gap = interface.column_gap([(taken, traces[block]) for block, (taken, _) in enumerate(pieces)], 4)
    for j in range(3):
        assert np.allclose(gap[:, j], interface.gap(traces[:, :, j]))
    assert not gap[:, 3].any()


class DenseProblem:
    """A dual problem ½yᵀAy − bᵀy with a dense SPD A and no bounds, counting its applications of A."""

    def __init__(self, A: np.ndarray, b: np.ndarray):
        self.A, self.b = A, b
        self.lower, self.upper = np.full(len(b), -np.inf), np.full(len(b), np.inf)
        self.applied = self.applied_many = 0

    def apply(self, y):
        self.applied += 1
        return self.A @ y

    def apply_many(self, Y):
        self.applied_many += 1
        return self.A @ Y


@pytest.mark.unit
def test_a_subspace_seeded_with_the_solutions_span_holds_the_minimizer_and_keeps_its_seeds():
    """Seeded with directions that span A⁻¹b (and a dependent copy of one, dropped), the subspace's point is the
    minimizer at once, for one multi-column application of A; a rebase keeps the seeds, A-orthonormal."""
    rng = np.random.default_rng(7)
    M = rng.standard_normal((30, 30))
    A = M @ M.T + 30.0 * np.eye(30)
    Z = rng.standard_normal((30, 3))
    b = A @ (Z @ np.array([1.0, -2.0, 0.5]))
    problem = DenseProblem(A, b)
    space = feti.Subspace(problem, np.zeros(30), -b, 50, lambda v: v)
    kept = space.seed(np.column_stack([Z, 2.0 * Z[:, 0]]))
    assert kept == 3 and problem.applied_many == 1 and problem.applied == 0
    y, g = space.point()
    assert np.allclose(y, np.linalg.solve(A, b)) and np.allclose(g, A @ y - b)
    space.add(rng.standard_normal(30))
    space.rebase(y, g)
    assert space.V.shape[1] == 3 and np.allclose(space.V.T @ A @ space.V, np.eye(3))
    assert np.allclose(space.AV, A @ space.V)


@pytest.mark.unit
def test_coarse_degree_is_refused_in_one_line_naming_the_key():
    """A degree that is no integer >= 0, and a degree for a method other than feti."""
    for value in ("-1", '"two"', "1.5", "5", "1000000"):
        with pytest.raises(SceneError, match=r"solver\.coarse_degree"):
            loads(CLOSURE.text, [f"solver.coarse_degree={value}"])
    with pytest.raises(SceneError, match=r"solver\.coarse_degree = 2: feti's coarse directions; method schur"):
        loads(CLOSURE.text, ["solver.coarse_degree=2", 'solver.method="schur"'])
    assert loads(CLOSURE.text, ["solver.coarse_degree=2"]).solver.coarse_degree == 2


@pytest.mark.solve
def test_the_slabs_with_coarse_directions_equal_the_reference_in_fewer_iterations():
    """Two slabs per half, contact active: feti with coarse directions of degree 1 and 2 (lumped and Dirichlet
    preconditioners) gives the reference's solution to 1e-8 at solver.tol 1e-10, the same crack vertices shut, in
    fewer iterations than without; the directions cost one round."""
    from mpi4py import MPI

    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver, solid_dd
    from ddsolve.solvers.solid import energy_error

    mesh = solid.build(CLOSURE)
    reference = solid_solver.solve_solid(CLOSURE, mesh)
    for preconditioner in ("lumped", "dirichlet"):
        iterations = {}
        for degree in (0, 1, 2):
            scene = CLOSURE.with_({"solver.tol": 1e-10, "solver.preconditioner": preconditioner,
                                   "solver.coarse_degree": degree})
            result = solid_dd.solve(scene, MPI.COMM_SELF, None, progress=lambda _line: None, mesh=mesh)
            assert result.converged and result.closed == reference.closed, (preconditioner, degree)
            assert energy_error(result, reference) < 1e-8, (preconditioner, degree)
            iterations[degree] = result.steps
        assert iterations[2] < iterations[0] and iterations[1] < iterations[0], (preconditioner, iterations)


@pytest.mark.mpi
def test_coarse_directions_on_2_and_8_ranks_equal_the_reference(tmp_path):
    """ddsolve solve -n 2 and -n 8 (four blocks: two a rank; a block on two ranks, its multi-column solve distributed)
    with two slabs per half and the default coarse directions (degree 1) hold the reference's solution to 1e-8 with
    contact active, and the result records the directions."""
    import h5py
    from conftest import ddsolve

    from ddsolve.io import solid as solid_files
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver

    path = tmp_path / "closure.toml"
    path.write_text(CLOSURE.text)
    reference = solid_solver.solve_solid(CLOSURE, solid.build(CLOSURE))
    for ranks in (2, 8):
        output = tmp_path / f"{ranks}.h5"
        solved = ddsolve("solve", str(path), "-o", str(output), "--set", "solver.tol=1e-10", ranks=ranks)
        assert "feti (3-D):" in solved.stdout and f"on {ranks} ranks" in solved.stdout
        with h5py.File(output, "r") as ran:
            assert (ran.attrs["method"], ran.attrs["coarse_degree"]) == ("feti", 1) and ran.attrs["coarse_directions"] > 0
        assert solid_solver.energy_error(solid_files.read(output), reference) < 1e-8


@pytest.mark.mpi
def test_coarse_directions_in_the_plane_give_the_same_solution_in_fewer_iterations(tmp_path):
    """The plane's partly closed crack by feti on 2 ranks with degree 0 (the plane's auto) and 2 (Σ's and no other
    joint, the multipliers quadratic along it): the same solution to 1e-8 in energy norm, in fewer iterations."""
    from conftest import ddsolve

    from ddsolve.io import hdf5
    from ddsolve.post import analysis

    results = {}
    for degree in (0, 2):
        output = tmp_path / f"{degree}.h5"
        ddsolve("solve", "partial-closure", "-o", str(output), "--set", 'solver.method="feti"', "--set",
                f"solver.coarse_degree={degree}", "--set", "solver.tol=1e-10", ranks=2)
        results[degree] = hdf5.read(output)
    assert all(result.converged for result in results.values())
    assert analysis.compare(results[2], results[0]).energy_error < 1e-8
    assert results[2].iterations < results[0].iterations


@pytest.mark.solve
def test_coarse_directions_on_floating_blocks_cost_no_extra_iterations():
    """The quarter penny (its slabs and halves float in y; four crack vertices, open): with the directions the
    halves whole take at most one iteration more than without, and 3 slabs per half fewer, both the reference's
    solution to 1e-8.  Starting the iterate at the directions' own minimizer made the halves whole flicker their
    contact rows into active-set steps (33 iterations against 10)."""
    from mpi4py import MPI

    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver, solid_dd
    from ddsolve.solvers.solid import energy_error
    from experiments import three_d_front

    penny = loads(three_d_front.PENNY.format(L=2, size=0.3, grading=0.2))
    mesh = solid.build(penny)
    reference = solid_solver.solve_solid(penny, mesh)
    for pieces in (1, 3):
        iterations = {}
        for degree in (0, 1):
            scene = penny.with_({"solver.method": "feti", "solver.pieces": pieces, "solver.tol": 1e-11,
                                 "solver.coarse_degree": degree})
            result = solid_dd.solve(scene, MPI.COMM_SELF, None, progress=lambda _line: None, mesh=mesh)
            assert result.converged and energy_error(result, reference) < 1e-8, (pieces, degree)
            iterations[degree] = result.steps
        assert iterations[1] <= iterations[0] + (1 if pieces == 1 else -1), (pieces, iterations)
