"""What the plots draw: the data handed to matplotlib, its scales and its labels."""
from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from conftest import SMALL, ddsolve, solved_reference
from launch_many import launch

from ddsolve.io import hdf5
from ddsolve.post import plots

matplotlib.use("Agg")
from matplotlib.figure import Figure  # noqa: E402

METHODS = ("schur", "mprgp", "fista", "uzawa")


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """Example 1 on a small mesh by every method (one rank, one launch), and by the reference."""
    folder = tmp_path_factory.mktemp("plots")
    launch([["solve", "partial-closure", *SMALL, "--set", f"solver.method={method}", "-o", str(folder / f"{method}.h5")]
            for method in METHODS], 1, folder)
    out = {method: hdf5.read(folder / f"{method}.h5") for method in METHODS}
    path = folder / "reference.h5"
    # On the paper's mesh (P = 96) the reference's active set moves for five steps; on the small mesh its first
    # step, from the unconstrained solution's penetrations, is already the contact zone.
    solved_reference("partial-closure", "-o", str(path))
    out["reference"] = hdf5.read(path)
    return out


@pytest.fixture
def figures(monkeypatch):
    """The figures the plotting functions save, kept for inspection."""
    saved = []
    original = Figure.savefig

    def keep(self, *args, **kwargs):
        saved.append(self)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", keep)
    return saved


def visible_lines(ax):
    """(x, y) of every line of ``ax`` with at least one point its scale can show."""
    out = []
    for line in ax.get_lines():
        x, y = (np.asarray(v, dtype=float) for v in line.get_data())
        shown = np.isfinite(x) & np.isfinite(y) & ((y > 0) if ax.get_yscale() == "log" else True)
        if shown.any():
            out.append((x, y))
    return out


@pytest.mark.mpi
@pytest.mark.parametrize("method", METHODS + ("reference",))
def test_every_method_has_a_finite_history_per_iteration(results, method):
    result = results[method]
    assert result.iterations >= 1 and len(result.history) == result.iterations
    assert np.all(np.isfinite(result.history)) and np.all(result.history >= 0.0)
    if method in ("schur", "reference"):
        assert len(result.active_set_changes) == result.iterations
        assert result.active_set_changes[-1] == 0 and result.active_set_changes[0] > 0
        assert result.history[0] > 1e-6 > result.history[-1]  # a wrong active set, then the solution
    else:
        assert len(result.active_set_changes) == 0
    if method != "reference":  # the last entry is the value the stopping rule accepted
        tol = float(result.attrs["tol"])
        assert result.history[-1] < tol
        if method != "schur":
            assert np.all(result.history[:-1] >= tol)


@pytest.mark.mpi
@pytest.mark.parametrize("method", METHODS + ("reference",))
def test_the_convergence_plot_of_every_method_shows_labelled_curves(results, method, figures, tmp_path):
    result = results[method]
    curves = plots.convergence([(method, result)], tmp_path / "c.png")
    (figure,) = figures
    axes = figure.axes
    assert len(axes) == (2 if method in ("schur", "reference") else 1)
    for ax, curve in zip(axes, curves):
        assert ax.get_ylabel() == curve.axis and "(" in ax.get_ylabel()  # named, with its unit
        (x, y), = visible_lines(ax)
        assert len(x) == result.iterations and np.all(np.isfinite(y))
        assert np.array_equal(y, curve.y)
    assert axes[-1].get_xlabel().startswith("iteration")
    assert np.array_equal(curves[0].y, result.history)
    assert curves[0].axis == plots.CRITERION_AXIS
    if method in ("schur", "reference"):
        assert curves[1].axis == plots.CHANGES_AXIS and np.array_equal(curves[1].y, result.active_set_changes)
        assert axes[0].get_yscale() in ("log", "symlog")


@pytest.mark.mpi
def test_zero_entries_stay_visible(results, figures, tmp_path):
    reference = results["reference"]
    assert reference.history[-1] == 0.0  # the reference's last step violates nothing at all
    plots.convergence([("reference", reference)], tmp_path / "c.png")
    ax = figures[0].axes[0]
    assert ax.get_yscale() == "symlog"
    (x, y), = visible_lines(ax)
    assert len(y) == reference.iterations


@pytest.mark.mpi
def test_several_methods_in_one_plot(results, figures, tmp_path):
    curves = plots.convergence([(m, results[m]) for m in METHODS], tmp_path / "c.png")
    assert [c.label for c in curves] == list(METHODS) + ["schur"]
    assert len(visible_lines(figures[0].axes[0])) == len(METHODS)


@pytest.mark.mpi
def test_deformed_layers_and_crack_faces_are_labelled(results, figures, tmp_path):
    result = results["schur"]
    scale = plots.deformed_layers(result, tmp_path / "d.png")
    assert scale == plots.magnification(result) and scale > 1.0
    plots.deformed_layers(result, tmp_path / "d.png", scale=7.0)
    assert figures[-1].axes[0].get_title().endswith("displacements ×7")
    plots.crack_faces(result, tmp_path / "c.png")
    for figure in figures:
        for ax in figure.axes:
            if ax.get_label() == "<colorbar>":
                assert "von Mises stress (unit of E" in ax.get_ylabel()
                continue
            assert ax.get_ylabel() and "(" in ax.get_ylabel()
    crack = figures[-1].axes
    assert "(length unit" in crack[-1].get_xlabel()
    (x, opening), = [line.get_data() for line in crack[0].get_lines() if len(line.get_xdata()) > 2]
    assert len(x) == len(result.crack) and np.all(np.isfinite(opening))


@pytest.mark.mpi
def test_magnification_draws_the_largest_displacement_at_a_fixed_fraction(results):
    result = results["reference"]
    scale = plots.magnification(result)
    largest = max(np.abs(u).max() for u in result.solution.values())
    assert 0.05 <= scale * largest / 2.0 <= 0.12  # 8 % of the square's side, to one significant digit


@pytest.mark.mpi
@pytest.mark.parametrize("value", ["nan", "inf", "-1", "0", "abc"])
def test_scale_must_be_a_finite_positive_number(tmp_path, results, value):
    completed = ddsolve("plot", "nothing.h5", f"--scale={value}", check=False)
    assert completed.returncode == 1
    assert completed.stderr.strip() == f"ddsolve: error: --scale {value}: must be a finite positive number"
