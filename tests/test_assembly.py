"""Serial checks of the P1 plane-strain assembly."""
import numpy as np
import pytest

from ddsolve import assembly
from ddsolve.scene import Material, Traction

from conftest import structured_halves

STEEL = Material(E=200.0, nu=0.28)


def dense(points, cells, material=STEEL):
    rows, cols, values = assembly.stiffness(points, cells, material)
    n = 2 * len(points)
    indptr, indices, data = assembly.coo_to_csr(n, rows, cols, values)
    K = np.zeros((n, n))
    K[np.repeat(np.arange(n), np.diff(indptr)), indices] = data
    return K


@pytest.fixture(scope="module")
def half():
    lower, _ = structured_halves(6, 3, shear=0.4)
    return lower


def test_stiffness_is_symmetric_positive_semidefinite(half):
    K = dense(half.points, half.cells)
    assert np.abs(K - K.T).max() < 1e-12 * np.abs(K).max()
    assert np.linalg.eigvalsh(K).min() > -1e-10 * np.abs(K).max()


def test_rigid_body_modes_span_the_kernel(half):
    K = dense(half.points, half.cells)
    x, y = half.points.T
    modes = [np.column_stack([np.ones_like(x), 0 * x]), np.column_stack([0 * x, np.ones_like(x)]),
             np.column_stack([-y, x])]
    for mode in modes:
        assert np.abs(K @ mode.ravel()).max() < 1e-11 * np.abs(K).max()
    eigenvalues = np.linalg.eigvalsh(K)
    assert np.sum(eigenvalues < 1e-9 * eigenvalues.max()) == 3


def test_patch_test_reproduces_a_linear_field(half):
    """Prescribe a linear field on the boundary: the interior solution is that field exactly."""
    K = dense(half.points, half.cells)
    x, y = half.points.T
    exact = np.column_stack([0.01 + 0.002 * x - 0.003 * y, -0.02 + 0.004 * x + 0.001 * y]).ravel()
    boundary = np.unique(half.boundary_edges())
    fixed = assembly.element_dofs(boundary[:, None]).ravel()
    free = np.setdiff1d(np.arange(len(exact)), fixed)
    u = exact.copy()
    u[free] = np.linalg.solve(K[np.ix_(free, free)], -K[np.ix_(free, fixed)] @ exact[fixed])
    assert np.abs(u - exact).max() < 1e-12


def test_energy_matches_the_assembled_matrix(half):
    K = dense(half.points, half.cells)
    u = np.random.default_rng(1).standard_normal((len(half.points), 2))
    assert assembly.energy(half.points, half.cells, STEEL, u) == pytest.approx(u.ravel() @ K @ u.ravel(), rel=1e-12)


def test_uniform_strain_gives_the_plane_strain_stress():
    lower, _ = structured_halves(4, 2, shear=0.3)
    x, y = lower.points.T
    u = np.column_stack([1e-3 * x, 0 * x])  # εxx = 1e-3 only
    vm = assembly.von_mises(lower.points, lower.cells, STEEL, u)
    mu, lam = assembly.lame(STEEL)
    sxx, syy, szz = (lam + 2 * mu) * 1e-3, lam * 1e-3, lam * 1e-3
    expected = np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2))
    assert np.allclose(vm, expected, rtol=1e-12)


@pytest.mark.parametrize("coefficients", [(0.5,), (0.0, 0.078125), (1.0, -2.0, 3.0, 0.5)])
def test_traction_load_totals_equal_the_integrals(coefficients):
    lower, _ = structured_halves(7, 2, shear=0.2)
    edges = lower.edges_on_line(-1.0)
    load = assembly.traction_load(lower.points, edges, Traction(x=coefficients, y=coefficients[::-1]))
    poly = np.polynomial.Polynomial
    integral = lambda c: (poly(c).integ()(1.0) - poly(c).integ()(-1.0))  # noqa: E731
    x = lower.points[:, 0]
    assert load[0::2].sum() == pytest.approx(integral(coefficients), abs=1e-13)
    assert load[1::2].sum() == pytest.approx(integral(coefficients[::-1]), abs=1e-13)
    # first moment: exact for the consistent load of a polynomial of any degree
    assert load[0::2] @ x == pytest.approx(integral(np.convolve(coefficients, [0.0, 1.0])), abs=1e-13)
    assert np.all(load.reshape(-1, 2)[lower.points[:, 1] != -1.0] == 0.0)


def test_block_system_decouples_clamped_dofs_and_lists_the_trace():
    lower, _ = structured_halves(8, 4)
    system = assembly.block_system("u_minus", lower, STEEL, Traction(y=(1.0,)))
    n = system.size
    K = np.zeros((n, n))
    K[np.repeat(np.arange(n), np.diff(system.indptr)), system.indices] = system.data
    clamped = assembly.element_dofs(lower.clamped()[:, None]).ravel()
    off_diagonal = K[clamped].copy()
    off_diagonal[np.arange(len(clamped)), clamped] = 0.0
    assert np.all(off_diagonal == 0.0) and np.all(K[clamped, clamped] > 0)
    assert np.all(system.rhs[clamped] == 0.0)
    assert np.linalg.eigvalsh(K).min() > 0
    sigma = lower.sigma()[1:-1]
    assert np.array_equal(system.trace_dofs, np.column_stack([2 * sigma, 2 * sigma + 1]).ravel())
    assert np.all(np.diff(lower.points[sigma, 0]) > 0)


def test_interpolation_is_exact_for_linear_fields_and_errors_vanish_on_the_same_mesh():
    from ddsolve.analysis import interpolate

    coarse, _ = structured_halves(4, 2, shear=0.3)
    fine, _ = structured_halves(12, 6, shear=0.1)
    linear = lambda p: np.column_stack([1 + 2 * p[:, 0] - p[:, 1], 3 * p[:, 1]])  # noqa: E731
    assert np.allclose(interpolate(coarse, linear(coarse.points), fine.points), linear(fine.points), atol=1e-13)
