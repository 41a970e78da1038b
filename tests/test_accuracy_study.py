"""The accuracy study's arithmetic: the exact energy from three levels, errors and rates."""
import numpy as np
import pytest

from experiments import accuracy
from ddsolve.post.analysis import energy_error


def test_three_levels_give_the_limit_and_the_exponent():
    n = np.array([1e3, 4e3, 1.6e4, 6.4e4])
    energies = -2.0 + 3.0 * n ** -1.7
    exact, alpha, uncertainty = accuracy.extrapolate(n, energies)
    assert exact == pytest.approx(-2.0, abs=1e-12) and alpha == pytest.approx(1.7, abs=1e-6)
    assert uncertainty > 0  # the two-point extrapolation with alpha = 2 differs
    assert accuracy.extrapolate(n, -2.0 + 3.0 * n ** -2.0)[2] == pytest.approx(0.0, abs=1e-12)


def test_energy_errors_and_rates():
    assert energy_error(-0.99, -1.0) == pytest.approx(0.1)
    assert energy_error(-1.01, -1.0) == 0.0  # below the extrapolated limit: no error to measure
    rows = [{"unknowns": n, "error": 2.0 * n ** -0.5} for n in (1e3, 1e4, 1e5, 1e6)]
    assert accuracy.rate(rows, floor=0.0) == pytest.approx(0.5)
    assert accuracy.rate(rows[2:], floor=0.0) == pytest.approx(0.5)  # two levels: their slope
    assert accuracy.rate(rows, floor=0.0, start=10 ** 6) is None  # one level: no slope
