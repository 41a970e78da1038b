"""The multiplier layout and its maps."""
import numpy as np
import pytest

from ddsolve.dd.interface import Interface

X = np.array([-1.0, -0.8, -0.5, -0.3, 0.0, 0.2, 0.5, 0.75, 1.0])
WEIGHTS = 0.5 * (X[2:] - X[:-2])  # inner vertices; the ends are clamped
CRACK = (X[1:-1] > -0.5) & (X[1:-1] < 0.5)  # the tips ±0.5 are glued


@pytest.fixture
def interface():
    return Interface(WEIGHTS, CRACK, contact=True)


def test_layout(interface):
    k = len(X) - 2
    assert np.array_equal(interface.crack, [False, False, True, True, True, False, False])  # tips are glued
    assert interface.size == 3 + 2 * 4 + 2 * k + 2 * k
    assert np.allclose(interface.row_weights, WEIGHTS[interface.vertex])
    lower, upper = interface.bounds(10.0)
    assert np.all(lower[interface.slices["mu_c"]] == 0) and np.all(lower[interface.slices["mu_g"]] == -10)
    assert np.all(upper == 10)
    assert np.all(interface.bounds(None)[1] == np.inf)


def test_no_contact_means_no_mu_c():
    linear = Interface(WEIGHTS, CRACK, contact=False)
    uncracked = Interface(WEIGHTS, np.zeros(len(WEIGHTS), dtype=bool), contact=True)
    assert linear.slices["mu_c"].stop == 0 and not linear.contact
    assert linear.size == 2 * 4 + 4 * 7  # the crack faces are free
    assert uncracked.size == 2 * 7 * 3 and not uncracked.crack.any()


def test_loads_are_minus_the_weighted_adjoint_of_the_gap(interface):
    rng = np.random.default_rng(0)
    traces = rng.standard_normal((4, interface.trace_size))
    lam = rng.standard_normal(interface.size)
    lhs = interface.gap(traces) @ (interface.row_weights * lam)
    rhs = -np.sum(traces * interface.loads(lam))
    assert lhs == pytest.approx(rhs, rel=1e-13)
    dense = np.zeros((4, interface.size, interface.trace_size))
    for b, coupling in enumerate(interface.couplings):
        dense[b, coupling.rows, coupling.trace] = coupling.sign
    assert np.allclose(np.einsum("bij,bj->i", dense, traces), interface.gap(traces))


def test_signs_match_the_paper(interface):
    """gap rows: (u⁻ − u⁺)·ν on the crack, u⁻ − u⁺ glued, u⁻ − v⁻, u⁺ − v⁺."""
    traces = np.zeros((4, interface.trace_size))
    traces[0, 2 * 2 + 1] = 1.0  # u⁻_y at the first crack vertex
    gap = interface.split(interface.gap(traces))
    assert gap["mu_c"][2] == 1.0 and gap["mu_minus"][2, 1] == 1.0 and gap["mu_plus"].sum() == 0
    traces[:] = 0.0
    traces[1, 0] = 1.0  # u⁺_x at the first (glued) vertex
    gap = interface.split(interface.gap(traces))
    assert gap["mu_g"][0, 0] == -1.0 and gap["mu_plus"][0, 0] == 1.0


def test_multipliers_invert_loads_and_split_keeps_every_value(interface):
    lam = np.random.default_rng(2).standard_normal(interface.size)
    assert np.allclose(interface.multipliers(interface.loads(lam)), lam, rtol=1e-13, atol=1e-14)
    parts = interface.split(lam)
    assert sum(np.count_nonzero(values) for values in parts.values()) == interface.size
    assert np.isclose(sum(values.sum() for values in parts.values()), lam.sum())
