"""Issue 40, class 4: a structure whose exact displacement is zero is solved, not refused.

The fixture (:func:`experiments.hostile4_zero.clamped_plate`, measured for docs/robustness.md too):
the paper's square, both layers clamped on all four sides by ``[displacements.LAYER.SIDE]`` and heated
uniformly.  Then u ≡ 0, ε = 0, and each layer's stress is the eigenstress σ = −D ε₀ in every cell: in plane
strain the in-plane ε₀ is (1 + ν)αΔT in x and y (the out-of-plane constraint adds ναΔT), so
σxx = σyy = −E(1 + ν)αΔT / ((1 + ν)(1 − 2ν)) = −EαΔT / (1 − 2ν); in plane stress ε₀ = αΔT and
σxx = σyy = −EαΔT / (1 − ν); σxy = 0.  A crack under non-penetration changes nothing while the layers are
heated (its faces are pressed together).  Before the fix every method and the reference ended with status 3
or 4 ("too ill-conditioned", "diverged"): the checks divided gaps by max|u| and equilibrium residuals by
‖f + ℓ‖, both round-off here; they now measure against the data's scale (prescribed values, eigenstrains,
loads).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from conftest import ddsolve
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from launch_many import launch

from ddsolve.dd import constraints, dual, uzawa
from ddsolve.dd.interface import Interface
from experiments.hostile4_zero import LAYERS, PAPER_LAYERS, PRESSED_LAYERS, clamped_plate, pressed_plate
from ddsolve.fem import assembly
from ddsolve.io import hdf5
from ddsolve.mesh import geometry
from ddsolve.post import analysis
from ddsolve.problem import scene
from ddsolve.solvers import reference

(E, NU, ALPHA, DT), _ = PAPER_LAYERS
#: Σ's length in the square [-1, 1]²: the length the data's strains are multiplied by.
SIGMA_LENGTH = 2.0


def closed_form(model: str, modulus: float, poisson: float, alpha: float, change: float) -> float:
    """σxx = σyy of a layer clamped all round: −EαΔT/(1 − 2ν) (plane strain), −EαΔT/(1 − ν) (plane stress)."""
    return -modulus * alpha * change / ((1.0 - 2.0 * poisson) if model == "plane_strain" else (1.0 - poisson))


def stress_errors(result, model: str, layers) -> tuple[float, float]:
    """(the largest |σxx − σ|, |σyy − σ|, |σxy| over every cell of the four blocks, the largest |σ| of the
    closed forms), σ the closed form of each block's layer."""
    expected = {layer: closed_form(model, *values) for layer, values in zip(LAYERS, layers)}
    error = 0.0
    for name, fields in analysis.cell_fields(result).items():
        sigma = expected["layer1" if name.startswith("u") else "layer2"]
        error = max(error, float(np.abs(fields.stress[:, :2] - sigma).max()), float(np.abs(fields.stress[:, 2]).max()))
    return error, max(abs(value) for value in expected.values())


def data_scale(model: str, layers) -> float:
    """Σ's length × the largest eigenstrain |ε₀| of the layers (the data's displacement)."""
    return SIGMA_LENGTH * max(abs(alpha * change) * ((1.0 + poisson) if model == "plane_strain" else 1.0)
                              for _, poisson, alpha, change in layers)


# --- the data's scale and the criteria that use it ------------------------------------------------
def test_the_data_displacement_of_the_clamped_plate_is_its_eigenstrain_times_sigma():
    source = scene.loads(clamped_plate())
    mesh = geometry.build(source)
    assert assembly.data_displacement(source, mesh.halves, mesh.sigma) == pytest.approx(
        SIGMA_LENGTH * (1 + NU) * ALPHA * DT, rel=1e-12)
    unheated = scene.loads(clamped_plate().split("[temperature]")[0] + "[displacements.layer1.left]\nx = 0.003\n")
    assert assembly.data_displacement(unheated, mesh.halves, mesh.sigma) == pytest.approx(0.003)  # prescribed values
    empty = scene.loads(clamped_plate().split("[temperature]")[0] + "[displacements.layer1.left]\nx = 0.0\n")
    assert assembly.data_displacement(empty, mesh.halves, mesh.sigma) == 0.0  # no data: no scale


def test_the_kkt_check_measures_a_zero_solution_against_the_data():
    """Two Σ nodes (one glued, one on a crack); traces of round-off size 1e-19 with gaps of 1e-20: against
    max|u| alone the gluing gap is 0.1 (the bug), against the data's displacement 1e-3 it is 1e-15.  A
    solution larger than DATA_FLOOR × the data is measured as before."""
    traces = np.zeros((4, 4))
    traces[:, 0] = 1e-19
    traces[0, 0] += 1e-20  # u⁻ off u⁺ and v⁻ at the glued node
    bare = Interface(np.array([0.5, 0.5]), np.array([False, True]), True)
    lam = np.zeros(bare.size)
    without = constraints.kkt(bare, traces, lam, None, np.zeros(4), 1.1e-19)
    assert without.gluing_gap == pytest.approx(1e-20 / 1.1e-19)
    data = Interface(np.array([0.5, 0.5]), np.array([False, True]), True, modulus=200.0, data=1e-3)
    scaled = constraints.kkt(data, traces, lam, None, np.zeros(4), 1.1e-19)
    assert scaled.gluing_gap == pytest.approx(1e-20 / (constraints.DATA_FLOOR * 1e-3))
    assert scaled.displacement_scale == constraints.DATA_FLOOR * 1e-3 and scaled.max_displacement == 1.1e-19
    large = constraints.kkt(data, traces * 1e15, lam, None, np.zeros(4), 1.1e-4)
    assert large.gluing_gap == pytest.approx(1e-20 / 1.1e-19)  # max|u| = 1.1e-4 > 1e-5: unchanged


def test_the_stopping_rules_take_the_same_floor_and_stay_zero_without_data():
    interface = Interface(np.array([0.5, 0.5]), np.array([False, True]), True, modulus=200.0, data=1e-3)
    floor = constraints.DATA_FLOOR * 1e-3 * np.sqrt(interface.row_weights.sum())
    assert dual.gap_scale(interface, np.zeros(interface.size)) == pytest.approx(floor)
    gap = np.full(interface.size, 1.0)
    assert dual.gap_scale(interface, gap) == pytest.approx(np.linalg.norm(np.sqrt(interface.row_weights)))
    assert dual.gap_scale(Interface(np.array([0.5, 0.5]), np.array([False, True]), True),
                             np.zeros(interface.size)) == 0.0  # zero load: the criterion is exactly 0
    # uzawa's block rule: a block at ‖x‖ = 0 that moved is measured against the data's energy, not ∞
    energy_floor = uzawa.energy_floor(interface)
    assert energy_floor == pytest.approx(200.0 * (constraints.DATA_FLOOR * 1e-3) ** 2)
    steps, energies = np.array([1e-30, 0, 0, 0]), np.zeros(4)
    assert uzawa.block_criterion("relative", steps, energies) == np.inf
    floored = uzawa.block_criterion("relative", steps, energies, energy_floor)
    assert floored == pytest.approx(1e-15 / np.sqrt(energy_floor))
    assert uzawa.block_criterion("relative", np.zeros(4), energies, energy_floor) == 0.0


def test_the_equilibrium_residual_measures_body_and_interface_loads_each_on_its_own():
    """K = I, f = (1, 0), the interface load −1 on dof 0 cancels it: x = 1e-17 is round-off, so is
    K x − f − ℓ; against ‖f + ℓ‖ = 0 the ratio was 1, against ‖f‖ + ‖ℓ‖ it is 5e-18."""
    system = assembly.BlockSystem("u_minus", np.array([0, 1, 2]), np.array([0, 1]), np.ones(2), np.array([1.0, 0.0]),
                                  np.array([0]), 2)
    assert analysis.block_residual(system, np.array([1e-17, 0.0]), np.array([-1.0])) == pytest.approx(1e-17 / 2.0)


# --- the reference --------------------------------------------------------------------------------
@pytest.mark.solve
@pytest.mark.parametrize("model", ["plane_strain", "plane_stress"])
def test_the_reference_solves_the_clamped_plate(model):
    """Converged (it said "too ill-conditioned for double precision"), the closed-form stress to 1e-12 of
    itself, max|u| below 1e-13 of the data's displacement (measured 1e-16)."""
    layers = PAPER_LAYERS
    source = scene.loads(clamped_plate(model))
    result = reference.solve_monolithic(source, geometry.build(source))
    assert result.converged, result.message
    error, stress = stress_errors(result, model, layers)
    assert error <= 1e-12 * stress
    assert analysis.largest_displacement(result.solution.values()) <= 1e-13 * data_scale(model, layers)
    assert not analysis.constraints(result).violations(analysis.tolerance_of(result))


MODELS = st.sampled_from(["plane_strain", "plane_stress"])
LAYER = st.tuples(st.floats(1.0, 1e4), st.sampled_from([0.0, 0.2, 0.3, 0.45]), st.floats(1e-7, 1e-3),
                  st.floats(1e-2, 1e3))


@pytest.mark.solve
@settings(derandomize=True, max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(model=MODELS, layers=st.tuples(LAYER, LAYER), cracked=st.booleans(), cooled=st.booleans())
def test_generated_zero_solutions_are_solved_by_the_reference(model, layers, cracked, cooled):
    """Any moduli, Poisson ratios (0 too), expansions and temperature changes per layer, with or without a
    crack (heated only with one: cooling would open it): converged, each layer at its closed form."""
    if not cracked and cooled:
        layers = tuple((*values[:3], -values[3]) for values in layers)
    source = scene.loads(clamped_plate(model, layers, "[-0.5, 0.5]" if cracked else "[]"))
    result = reference.solve_monolithic(source, geometry.build(source))
    assert result.converged, result.message
    error, stress = stress_errors(result, model, layers)
    assert error <= 1e-10 * stress
    assert analysis.largest_displacement(result.solution.values()) <= 1e-12 * data_scale(model, layers)


# --- every method, end to end ---------------------------------------------------------------------
def solved(folder: Path, text: str, method: str, *extra: str, ranks: int = 1):
    """``solve`` the scene ``text`` with ``method`` (``reference`` for the reference); exit 0 and the result."""
    path, output = folder / "plate.toml", folder / f"{method}.h5"
    path.write_text(text)
    options = [] if method == "reference" else ["--set", f"solver.method={method}", *extra]
    command = "reference" if method == "reference" else "solve"
    completed = ddsolve(command, str(path), *options, "-o", str(output), ranks=None if ranks == 1 else ranks)
    assert "Traceback" not in completed.stderr and completed.returncode == 0
    return hdf5.read(output)


#: (method, options, ranks, stress bound, displacement bound): exact solves to round-off, the iterative ones to
#: their tolerance (kkt 1e-8 by default; measured stress errors 4e-9 to 2e-8 of |σ|, max|u| 6e-10 to 1.3e-9 of the
#: data's displacement).
METHODS = [("schur", [], 2, 1e-12, 1e-13), ("auto", [], 1, 1e-12, 1e-13), ("reference", [], 1, 1e-12, 1e-13),
           ("mprgp", [], 1, 1e-6, 1e-7), ("fista", [], 1, 1e-6, 1e-7), ("feti", [], 2, 1e-6, 1e-7),
           ("uzawa", ["--set", "solver.theta=auto"], 1, 1e-6, 1e-7),
           ("uzawa", ["--set", "solver.theta=auto", "--set", "solver.stop=kkt"], 1, 1e-6, 1e-7)]


@pytest.mark.mpi
@pytest.mark.parametrize("method, extra, ranks, stress_bound, displacement_bound", METHODS,
                         ids=[f"{m[0]}{'-' + m[1][-1].split('=')[1] if len(m[1]) > 2 else ''}" for m in METHODS])
def test_every_method_solves_the_clamped_heated_plate(tmp_path, method, extra, ranks, stress_bound, displacement_bound):
    """Exit 0, converged after the final check, σxx = σyy = −EαΔT/(1 − 2ν) = −0.5 (plane strain) in each cell
    and max|u| ≈ 0 to the bounds of METHODS; uzawa's kkt rule, relative to the uncoupled blocks' gap, goes on
    with a lower tol when the final check (relative to the data's displacement here) finds it short."""
    layers = PAPER_LAYERS
    result = solved(tmp_path, clamped_plate(), method, *extra, ranks=ranks)
    assert result.converged, result.message
    error, stress = stress_errors(result, "plane_strain", layers)
    assert stress == pytest.approx(0.5) and error <= stress_bound * stress
    largest = analysis.largest_displacement(result.solution.values())
    assert largest <= displacement_bound * data_scale("plane_strain", layers)
    assert not analysis.constraints(result).violations(analysis.tolerance_of(result))


@pytest.mark.mpi
def test_the_check_command_passes_a_zero_solution(tmp_path):
    solved(tmp_path, clamped_plate(), "mprgp")
    completed = ddsolve("check", str(tmp_path / "mprgp.h5"))
    assert "KKT check passed" in completed.stdout and "the data's displacement scale 2.600e-05" in completed.stdout


@pytest.mark.mpi
@pytest.mark.parametrize("method", ["schur", "feti"])
def test_floating_blocks_held_by_a_pressure_that_cancels_the_expansion(tmp_path, method):
    """The floating blocks' equilibrium residual (f and the interface loads cancel) passes: it said 1e-2."""
    result = solved(tmp_path, pressed_plate(), method, ranks=2)
    assert result.converged, result.message
    error, stress = stress_errors(result, "plane_strain", PRESSED_LAYERS)
    assert error <= (1e-12 if method == "schur" else 1e-6) * stress


@pytest.mark.mpi
@settings(derandomize=True, max_examples=5, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(model=MODELS, layers=st.tuples(LAYER, LAYER), method=st.sampled_from(["schur", "mprgp", "fista", "feti"]))
def test_generated_zero_solutions_are_solved_by_every_method(model, layers, method):
    """Generated clamped heated plates (a crack pressed shut): every method ends with status 0, converged, each
    layer's stress at its closed form to 1e-6 of the largest and max|u| below 1e-6 of the data's displacement."""
    with tempfile.TemporaryDirectory() as folder:
        result = solved(Path(folder), clamped_plate(model, layers), method)
    assert result.converged, result.message
    error, stress = stress_errors(result, model, layers)
    assert error <= 1e-6 * stress
    assert analysis.largest_displacement(result.solution.values()) <= 1e-6 * data_scale(model, layers)


@pytest.mark.mpi
@pytest.mark.parametrize("method", ["mprgp", "feti"])
def test_the_stopping_rule_of_a_zero_solution_stays_scale_free(tmp_path, method):
    """α × 2^-40 and 2^-20 (exact in floating point): the same iterations, the stress scaled exactly as much."""
    powers = (0, -20, -40)
    for power in powers:
        layers = tuple((modulus, poisson, alpha * 2.0 ** power, change)
                       for modulus, poisson, alpha, change in PAPER_LAYERS)
        (tmp_path / f"plate{power}.toml").write_text(clamped_plate(layers=layers))
    launch([["solve", str(tmp_path / f"plate{power}.toml"), "--set", f"solver.method={method}", "-o",
             str(tmp_path / f"{power}.h5")] for power in powers], 1, tmp_path)  # one process: exit 0 or it fails
    results = {power: hdf5.read(tmp_path / f"{power}.h5") for power in powers}
    assert len({result.iterations for result in results.values()}) == 1
    reference_stress = analysis.cell_fields(results[0])["u_minus"].stress
    for power, result in results.items():
        stress = analysis.cell_fields(result)["u_minus"].stress
        assert np.abs(stress * 2.0 ** -power - reference_stress).max() <= 1e-12 * 0.5
