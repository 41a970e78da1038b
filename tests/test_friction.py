"""Friction on the crack faces in contact: the μ_t family and its bounds, the KKT check of the friction
conditions, Coulomb's fixed point, G with friction against the closed form, the methods against each other,
bad input."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from conftest import ddsolve, refused

from ddsolve.dd import friction
from ddsolve.dd.constraints import kkt
from ddsolve.dd.dual import Outcome
from ddsolve.dd.interface import Interface
from ddsolve.errors import DDSolveError, NotConvergedError, SceneError
from ddsolve.io import hdf5
from ddsolve.post import analysis
from ddsolve.problem import scene as scenes
from ddsolve.solvers import driver, reference

X = np.array([-1.0, -0.8, -0.5, -0.3, 0.0, 0.2, 0.5, 0.75, 1.0])
WEIGHTS = 0.5 * (X[2:] - X[:-2])
CRACK = (X[1:-1] > -0.5) & (X[1:-1] < 0.5)  # vertices 2, 3, 4
SCENE = Path(__file__).resolve().parents[1] / "docs" / "closed-crack.toml"


def tresca(g: float = 0.3) -> Interface:
    return Interface(WEIGHTS, CRACK, contact=True, friction=np.where(CRACK, g, 0.0))


@pytest.mark.unit
def test_friction_adds_a_tangential_row_per_crack_vertex_bounded_by_g_and_nothing_without_it():
    plain, frictional = Interface(WEIGHTS, CRACK, contact=True), tresca(0.3)
    assert not plain.friction and "mu_t" not in plain.slices and "mu_t" not in plain.split(np.zeros(plain.size))
    assert frictional.size == plain.size + 3
    rows = frictional.slices["mu_t"]
    assert np.array_equal(frictional.vertex[rows], [2, 3, 4]) and np.all(frictional.component[rows] == 0)
    lower, upper = frictional.bounds(None)
    assert np.all(upper[rows] == 0.3) and np.all(lower[rows] == -0.3)
    assert np.all(frictional.bounds(0.1)[1][rows] == 0.1)  # p caps g too
    common = slice(0, plain.size)  # the old rows keep their places and bounds
    assert np.array_equal(lower[common], plain.bounds(None)[0]) and np.array_equal(frictional.vertex[common], plain.vertex)
    rng = np.random.default_rng(1)  # the loads stay minus the weighted adjoint of the gap
    traces, lam = rng.standard_normal((4, frictional.trace_size)), rng.standard_normal(frictional.size)
    assert frictional.gap(traces) @ (frictional.row_weights * lam) == pytest.approx(
        -np.sum(traces * frictional.loads(lam)), rel=1e-13)
    assert np.allclose(frictional.multipliers(frictional.loads(lam)), lam)


@pytest.mark.unit
def test_coulomb_bounds_follow_the_contact_pressure_and_a_zero_coefficient_is_no_friction():
    coulomb = Interface(WEIGHTS, CRACK, contact=True, friction=np.where(CRACK, 0.5, 0.0), coulomb=True)
    rows = coulomb.slices["mu_t"]
    assert np.all(coulomb.bounds(None)[1][rows] == 0.0)  # no bound set yet: the faces slide freely
    lam = np.zeros(coulomb.size)
    lam[coulomb.slices["mu_c"]] = [2.0, -1.0, 4.0]
    assert np.allclose(coulomb.slip_bounds(lam), [1.0, 0.0, 2.0])
    assert np.allclose(coulomb.with_slip([0.1, 0.2, 0.3]).bounds(None)[1][rows], [0.1, 0.2, 0.3])
    assert not Interface(WEIGHTS, CRACK, contact=True, friction=np.zeros(len(WEIGHTS))).friction


def friction_check(interface: Interface, mu_t: float, slip: float):
    """The KKT residuals of a state with contact pressure 1 on the crack, μ_t and the slip (u⁻ − u⁺)·τ at vertex 3."""
    lam = np.zeros(interface.size)
    lam[interface.slices["mu_c"]] = 1.0
    lam[interface.slices["mu_t"].start + 1] = mu_t
    traces = np.zeros((4, interface.trace_size))
    traces[0, 2 * 3] = slip  # u⁻_x at vertex 3: the lower face moved along τ
    traces[2, 2 * 3] = slip  # v⁻ follows u⁻ (glued)
    return kkt(interface, traces, lam, None, np.zeros(4), 1.0)


@pytest.mark.unit
def test_kkt_checks_the_friction_conditions():
    interface = tresca(0.3)
    assert friction_check(interface, 0.3, 0.1).violations(1e-9) == []  # slips along μ_t at the bound
    assert friction_check(interface, -0.3, -0.1).violations(1e-9) == []
    assert friction_check(interface, 0.1, 0.0).violations(1e-9) == []  # sticks below it
    assert friction_check(interface, 0.3, -0.1).violations(1e-9) == ["gluing gap 1.00e-01"]  # slips against μ_t
    assert friction_check(interface, 0.1, 0.1).violations(1e-9) == ["gluing gap 1.00e-01"]  # slips below the bound
    assert friction_check(interface, 0.5, 0.1).violations(1e-9)[0].startswith("multiplier bounds")
    coulomb = Interface(WEIGHTS, CRACK, contact=True, friction=np.where(CRACK, 0.3, 0.0), coulomb=True)
    assert friction_check(coulomb, 0.3, 0.1).violations(1e-9) == []  # g = 0.3 × pressure 1
    assert friction_check(coulomb, 0.6, 0.1).violations(1e-9)[0].startswith("multiplier bounds")


@pytest.mark.unit
def test_coulomb_iterates_tresca_problems_from_the_last_multipliers_to_a_fixed_point():
    interface = Interface(WEIGHTS, CRACK, contact=True, friction=np.where(CRACK, 0.5, 0.0), coulomb=True)
    normal, starts, bounds = interface.slices["mu_c"], [], []

    def solve(problem: Interface, start):  # a pressure that grows with the friction bound: 1 + g/2
        starts.append(start)
        bounds.append(problem.slip.copy())
        lam = np.zeros(interface.size)
        lam[normal] = 1.0 + 0.5 * problem.slip
        return Outcome(lam, converged=True, iterations=3)

    outcome = friction.coulomb(interface, solve, 1e-10, "test")
    assert outcome.converged and starts[0] is None and starts[1] is not None
    assert np.allclose(bounds[-1], 0.5 / (1 - 0.25), rtol=1e-9)  # g = ½(1 + g/2)
    assert outcome.iterations == 3 * outcome.details["coulomb_iterations"]


@pytest.mark.unit
def test_coulomb_stops_where_the_bounds_change_stalls_at_the_tresca_solves_accuracy():
    """An iterative method's pressures scatter by about its tol: the changes stop falling above tol, and the fixed
    point ends there (a feti ENF at tol 1e-11 used to run all 50 Tresca problems and fail)."""
    interface = Interface(WEIGHTS, CRACK, contact=True, friction=np.where(CRACK, 0.5, 0.0), coulomb=True)
    normal, scatter = interface.slices["mu_c"], iter(5e-9 * np.array([1, -1, 1, -1, 1, -1] * 10))

    def solve(problem: Interface, start):
        lam = np.zeros(interface.size)
        lam[normal] = 1.0 + 0.5 * problem.slip + next(scatter)
        return Outcome(lam, converged=True, iterations=3)

    outcome = friction.coulomb(interface, solve, 1e-11, "test")
    assert outcome.converged and outcome.details["coulomb_iterations"] < 20
    assert np.allclose(interface.slip_bounds(outcome.lam), 0.5 / (1 - 0.25), rtol=1e-8)
    assert friction.stalled(1e-9, 5e-10, 1e-11) and not friction.stalled(5e-10, 1e-9, 1e-11)  # still falling
    assert not friction.stalled(1e-5, 1e-6, 1e-11)  # no floor above √tol: the iteration goes on


def scene(**overrides) -> scenes.Scene:
    return scenes.Scene.load(SCENE, overrides)


@pytest.mark.unit
@pytest.mark.parametrize("overrides, key", [
    ({"contact.friction": -0.5}, "contact.friction must be a number >= 0"),
    ({"contact.slip_bound": -1.0}, "contact.slip_bound must be a number >= 0"),
    ({"contact.friction": 0.5, "contact.nonpenetration": False}, "contact.friction needs contact.nonpenetration"),
    ({"contact.slip_bound": [0.5, 0.5]}, "contact.slip_bound lists 2 values for the 1 crack"),
    ({"contact.friction": 0.5, "contact.slip_bound": 0.5}, "contact.friction and contact.slip_bound exclude"),
])
def test_bad_friction_input_is_refused_in_one_line_naming_the_key(overrides, key):
    with pytest.raises(SceneError) as refused:
        scene(**overrides)
    assert key in str(refused.value) and "\n" not in str(refused.value)


@pytest.mark.unit
def test_zero_friction_is_no_friction():
    assert scene(**{"contact.friction": 0.0}).friction is None and scene().friction is None


# --- solves ------------------------------------------------------------------------------------------
#: G of the closed crack, per layer 2 (1 − ν²)(T − g)²πa/E × 2 layers with S = T = 1, a = 1, E = 100, ν = 0.3
CLOSED_FORM = 2 * (1 - 0.3 ** 2) * np.pi / 100.0
SMALL = {"mesh.size": 2.0, "mesh.degree": 1}  # for the methods' agreement
#: P2 graded at the tips, 15,392 unknowns: the finite square puts G 1.2 % above the infinite plane's
ACCURATE = {"mesh.size": 1.0}


def solved(**overrides):
    return driver.solve_decomposed(scene(**{**ACCURATE, **overrides}), MPI.COMM_SELF, None, progress=lambda line: None)


@pytest.mark.solve
@pytest.mark.parametrize("overrides, g", [({}, 0.0), ({"contact.friction": 0.5}, 0.5),
                                          ({"contact.slip_bound": 1.0}, 0.5), ({"contact.slip_bound": 0.5}, 0.25)])
def test_the_closed_crack_releases_the_closed_form_g_with_friction(overrides, g):
    """Tresca's g bounds μ_t, the traction both layers carry: per layer g/2 (Coulomb: μ S per layer)."""
    result = solved(**overrides)
    assert result.converged
    assert np.allclose(result.G, CLOSED_FORM * (1 - g) ** 2, rtol=0.03)
    assert np.allclose(result.fracture.G_II, result.G, rtol=1e-3)
    if overrides:
        zones = analysis.friction_zones(result)
        assert len(zones["slip"]) == 1 and not zones["stick"]


@pytest.mark.solve
def test_the_closed_crack_sticks_where_friction_holds_the_shear():
    result = solved(**{"contact.friction": 1.5})
    assert result.converged and result.attrs["coulomb_iterations"] >= 2
    assert np.all(np.abs(result.G) <= 1e-3 * CLOSED_FORM)
    zones = analysis.friction_zones(result)
    assert len(zones["stick"]) == 1 and not zones["slip"]


@pytest.mark.solve
@pytest.mark.parametrize("method", ["schur", "feti"])
def test_a_coulomb_iteration_out_of_tresca_problems_is_a_result_not_converged(method, monkeypatch):
    """Every method reports an unsettled fixed point the same way: the result, marked not converged, and why."""
    from ddsolve.dd import friction, schur

    monkeypatch.setattr(friction, "MAX_FIXED_POINT", 2)
    monkeypatch.setattr(schur, "MAX_FIXED_POINT", 2)
    with pytest.raises(NotConvergedError, match=f"{method}: Coulomb's friction found no fixed point") as failed:
        solved(**{**SMALL, "contact.friction": 0.5, "solver.method": method})
    assert failed.value.result is not None and not failed.value.result.converged


@pytest.mark.solve
@pytest.mark.parametrize("overrides", [{"contact.slip_bound": 0.5}, {"contact.friction": 0.5}])
def test_every_method_gives_the_same_frictional_solution(overrides):
    common = {**overrides, **SMALL, "solver.tol": 1e-11}
    exact = solved(**common, **{"solver.method": "schur"})
    for method, more in (("feti", {}), ("mprgp", {}), ("fista", {}),
                         ("uzawa", {"solver.theta": "auto", "solver.stop": "kkt", "solver.tol": 1e-10})):
        other = solved(**{**common, "solver.method": method, **more})
        assert other.converged and analysis.compare(other, exact).energy_error < 1e-8, method
        assert np.allclose(other.multipliers["mu_t"], exact.multipliers["mu_t"], atol=1e-6)


@pytest.mark.solve
def test_the_reference_refuses_friction_in_one_line():
    with pytest.raises(DDSolveError) as refused:
        reference.refuse_friction(scene(**{"contact.friction": 0.5}))
    assert "contact.friction" in str(refused.value) and "\n" not in str(refused.value)


@pytest.mark.solve
def test_the_result_file_keeps_the_tangential_traction_and_the_slip_zones(tmp_path):
    result = solved(**{"contact.friction": 0.5})
    path = tmp_path / "closed.h5"
    hdf5.write(path, result)
    back = hdf5.read(path)
    assert np.array_equal(back.multipliers["mu_t"], result.multipliers["mu_t"])
    assert analysis.friction_zones(back) == analysis.friction_zones(result)
    assert analysis.constraints(back).violations(1e-7) == []


@pytest.mark.unit
def test_a_tresca_bound_makes_the_solution_no_longer_proportional_to_the_loads():
    assert scene().proportional and scene(**{"contact.friction": 0.5}).proportional  # Coulomb scales with the loads
    assert not scene(**{"contact.slip_bound": 0.5}).proportional  # a given traction does not: critical factors by root solve


@pytest.mark.unit
def test_a_per_crack_list_of_another_length_than_the_mesh_cracks_is_refused_naming_the_key():
    with pytest.raises(SceneError, match=r"^contact.friction lists 2 values for the 3 cracks of the mesh"):
        scenes.Friction(True, (0.5, 0.2)).per_crack(3)
    assert scenes.Friction(False, 0.5).per_crack(2) == (0.5, 0.5)


@pytest.mark.solve
def test_a_per_crack_list_puts_friction_on_its_crack_only():
    from ddsolve.dd.interface import for_mesh
    from ddsolve.parallel import distribution

    two = scene(**{"geometry.cracks": [[-4.0, -2.0], [1.0, 3.0]], "contact.slip_bound": [0.5, 0.0], **SMALL})
    sigma = distribution.build_mesh(two, MPI.COMM_SELF).sigma
    interface = for_mesh(sigma, True, friction=two.friction)
    x = sigma.points[sigma.multiplier_nodes, 0][interface.vertex[interface.slices["mu_t"]]]
    assert len(x) > 0 and np.all((x > -4.0) & (x < -2.0))
    assert np.all(interface.bounds(None)[1][interface.slices["mu_t"]] == 0.5)


@pytest.mark.mpi
def test_the_command_line_says_the_coulomb_problems_and_where_the_faces_slip_and_the_reference_refuses(tmp_path):
    out = ddsolve("solve", str(SCENE), "--set", "contact.friction=0.5", "--set", "mesh.size=2.0", "-o",
                  str(tmp_path / "closed.h5")).stdout
    assert re.search(r"schur: converged after \d+ iterations \(\d+ active-set steps, [^)]*\), "
                     r"Coulomb friction in \d+ Tresca problems", out)
    assert "crack faces slip (contact.friction; arc length along Σ): [9" in out
    refused(ddsolve("reference", str(SCENE), "--set", "contact.slip_bound=0.5", check=False), 1, "contact.slip_bound",
            "reference")
