"""The rank-0 algorithms on small dense problems (no MPI, no PETSc)."""
import numpy as np
import pytest

from ddsolve.dd.dual import kkt_criterion, largest_eigenvalue, projected_gradient
from ddsolve.dd import registry
from ddsolve.dd.schur import box_qp
from ddsolve.problem.method_options import AUTO, OPTIONS


def random_problem(seed: int, n: int = 12):
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, n))
    A = X @ X.T + 0.5 * np.eye(n)
    b = rng.standard_normal(n) * 3
    lower = np.where(rng.random(n) < 0.5, 0.0, -np.inf)
    upper = np.where(rng.random(n) < 0.3, 0.5, np.inf)
    return A, b, lower, upper


@pytest.mark.parametrize("seed", range(8))
def test_box_qp_satisfies_the_kkt_conditions(seed):
    A, b, lower, upper = random_problem(seed)
    y, steps = box_qp(A, b, lower, upper)
    assert np.all(y >= lower - 1e-12) and np.all(y <= upper + 1e-12)
    gradient = A @ y - b
    assert np.abs(projected_gradient(y, gradient, lower, upper)).max() < 1e-10
    # and it is the minimizer: projected gradient descent from anywhere ends there
    z, step = np.zeros_like(b), 1.0 / np.linalg.eigvalsh(A).max()
    for _ in range(20000):
        z = np.clip(z - step * (A @ z - b), lower, upper)
    assert np.allclose(y, z, atol=1e-8)


@pytest.mark.parametrize("seed", range(4))
def test_box_qp_steps_through_the_inverse_when_few_rows_are_active_and_a_warm_start_settles_at_once(seed):
    """Few active rows among many: the steps through H = A⁻¹ reach the minimizer projected gradient descent
    finds; started from its own solution the method checks it in one step."""
    rng = np.random.default_rng(seed)
    n = 80
    X = rng.standard_normal((n, n))
    A = X @ X.T + 0.5 * np.eye(n)
    y_star = rng.standard_normal(n)
    b = A @ y_star
    lower = np.full(n, -np.inf)
    lower[rng.choice(n, 6, replace=False)] = 0.5  # a few bounds, some of them active
    upper = np.full(n, np.inf)
    seen = []
    y, steps = box_qp(A, b, lower, upper, observe=lambda y, changed: seen.append(changed))
    assert steps >= 2 and seen[-1] == 0
    assert np.abs(projected_gradient(y, A @ y - b, lower, upper)).max() < 1e-9 * np.abs(b).max()
    again, one = box_qp(A, b, lower, upper, start=y)
    assert one == 1 and np.allclose(again, y, rtol=1e-10, atol=1e-10)


def test_kkt_criterion_is_scale_free_and_zero_for_nothing_to_do():
    A, b, lower, upper = random_problem(3)
    y = np.zeros_like(b)
    gradient = A @ y - b
    value = kkt_criterion(y, gradient, lower, upper, np.linalg.norm(b))
    assert kkt_criterion(1e12 * y, 1e12 * gradient, 1e12 * lower, 1e12 * upper, 1e12 * np.linalg.norm(b)) == \
        pytest.approx(value, rel=1e-12)
    assert kkt_criterion(y, 0 * gradient, lower, upper, 0.0) == 0.0


def test_power_iteration_finds_the_largest_eigenvalue():
    A, *_ = random_problem(5, n=30)
    estimate = largest_eigenvalue(lambda v: A @ v, 30, iterations=500, tolerance=1e-12)
    assert estimate == pytest.approx(np.linalg.eigvalsh(A).max(), rel=1e-6)


def test_every_method_a_scene_names_is_described_once_in_the_registry():
    assert [AUTO.name, *registry.METHODS] == list(OPTIONS)
    assert all(method.options is OPTIONS[name] for name, method in registry.METHODS.items())
    assert set(registry.floating_methods()) <= set(registry.METHODS)


def test_auto_takes_schur_on_the_measured_structures_and_feti_where_the_dense_interface_outgrows_the_blocks():
    """The ENF and the closed strip of ``./run bench contact`` (2 ranks, P2: block unknowns, Σ nodes, crack rows)
    take ``schur``; contact adds ``schur``'s active-set steps; a Σ of 20,000 nodes on small blocks, or blocks on
    several ranks with a long Σ, take ``feti``."""
    assert registry.choose(2, 51_360, 1077, 250) == "schur"  # the ENF, size 0.1
    assert registry.choose(2, 43_300, 801, 641) == "schur"  # the closed strip, size 0.05
    free, pressed = (registry.predicted_costs(2, 51_360, 1077, rows) for rows in (0, 250))
    assert pressed["feti"] == free["feti"] and pressed["schur"] > free["schur"]
    assert registry.choose(2, 400_000, 20_000, 0) == "feti"
    assert registry.choose(8, 2_000_000, 4_000, 2_000) == "feti"


def test_least_squares_of_a_singular_interface_stiffness_is_the_least_norm_solution():
    """schur's t⁰ of a floating block: S⁺ g by one shifted Cholesky factorization, as by an SVD; zero off the
    entries the block holds."""
    from ddsolve.dd.schur import least_squares

    rng = np.random.default_rng(3)
    kernel = rng.standard_normal((40, 3))
    basis = np.linalg.qr(np.hstack([kernel, rng.standard_normal((40, 37))]))[0][:, 3:]
    S = basis @ np.diag(rng.uniform(1.0, 1e4, 37)) @ basis.T
    g = rng.standard_normal(40)
    assert np.allclose(least_squares(S, g, kernel), np.linalg.lstsq(S, g, rcond=None)[0], rtol=1e-9, atol=1e-12)
    assert np.allclose(least_squares(S[:3, :3] + np.eye(3), g[:3], np.zeros((3, 0))),
                       np.linalg.solve(S[:3, :3] + np.eye(3), g[:3]))
    padded = np.zeros((45, 45))  # a block's S on a structure's trace: zero off the entries it holds
    padded[5:, 5:] = S
    t = least_squares(padded, np.r_[np.zeros(5), g], np.vstack([np.zeros((5, 3)), kernel]))
    assert not t[:5].any() and np.allclose(t[5:], np.linalg.lstsq(S, g, rcond=None)[0], rtol=1e-9, atol=1e-12)
