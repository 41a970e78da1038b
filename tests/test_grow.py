"""Crack growth along Σ (ddsolve.solvers.grow): DCB and ENF against corrected beam theory, stability,
the step size, merging cracks, the file, bad input, and the command on two ranks."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import MATERIALS, ddsolve, refused

from ddsolve.errors import SceneError, UsageError
from experiments import delamination as beams
from experiments import growth as experiment
from ddsolve.post import toughness
from ddsolve.problem import expressions
from ddsolve.problem.scene import Scene
from ddsolve.solvers import grow, growth_files

#: Coarse P2 strips: the DCB's stable branch still follows corrected beam theory to well under 1 %.
SIZE = 0.25
MODULUS = beams.summed_modulus(beams.LAYERS["identical"])


def comm():
    from mpi4py import MPI

    return MPI.COMM_SELF


def quiet(_line: str) -> None:
    pass


def test_scaled_scene_scales_every_mechanical_action():
    scene = Scene.load("partial-closure", ["mesh.sigma_vertices=13", "mesh.boundary_vertices=16"])
    scaled = scene.scaled(2.5)
    x, y = np.linspace(-1, 1, 7), np.linspace(-1, 1, 7)
    for key, load in scene.loads.items():
        for name in ("x", "y", "pressure"):
            part = getattr(load, name)
            if part is not None:
                assert np.allclose(getattr(scaled.loads[key], name)(x, y), 2.5 * part(x, y), rtol=1e-15)
    assert expressions.scaled(expressions.parse("x^2 + y"), 3.0).degree == 2


@pytest.mark.solve
def test_dcb_opening_grows_stably_on_corrected_beam_theory(tmp_path):
    scene = experiment.dcb(tmp_path, SIZE, "displacement")
    limit = experiment.dcb_opening(9.0, MODULUS, experiment.G_IC)
    steps = grow.grow(scene, comm(), limit, 6, 1e-4, progress=quiet, output=tmp_path / "dcb.h5")
    grown = [s for s in steps if s.state.cracks[0][1] > experiment.DCB_CRACK + 1e-9]
    assert len(grown) >= 3 and not any(s.unstable for s in steps)
    for s in grown:
        a = s.state.cracks[0][1]
        assert abs(s.state.G[0] / experiment.G_IC - 1) <= 1e-4
        assert abs(s.state.load / experiment.dcb_load(a, MODULUS, experiment.G_IC) - 1) < 0.01
        assert abs(a / experiment.dcb_length(s.state.displacement, MODULUS, experiment.G_IC) - 1) < 0.01
    # the initiation step equals the critical factor a plain solve gives
    from ddsolve.solvers import driver

    result = driver.solve_decomposed(scene, comm(), None, progress=quiet)
    factor = toughness.critical_factor(result.fracture.G, toughness.resistance(scene, result.fracture))
    initiation = next(s for s in steps if s.events and s.events[0].startswith("initiation"))
    assert initiation.state.control == pytest.approx(float(factor.min()), rel=1e-6)
    data = growth_files.read(tmp_path / "dcb.h5")
    count = len(steps)
    assert data["control"].shape == data["load"].shape == data["energy"].shape == (count,)
    assert data["cracks"].shape == (count, 1, 2) and data["G"].shape == (count, 1)
    assert data["attrs"]["control_kind"] == "displacement"
    # work: the energy is ½ load·displacement (Clapeyron, displacement control: Π = U)
    assert np.allclose(data["energy"], 0.5 * data["load"] * data["displacement"], rtol=1e-6, atol=0.0)


@pytest.mark.solve
def test_dcb_under_load_runs_away_at_initiation(tmp_path):
    scene = experiment.dcb(tmp_path, SIZE, "load")
    limit = 1.5 * experiment.dcb_load(experiment.DCB_CRACK, MODULUS, experiment.G_IC)
    steps = grow.grow(scene, comm(), limit, 3, 1e-4, progress=quiet)
    initiation = next(s for s in steps if s.events and s.events[0].startswith("initiation"))
    assert initiation.unstable and initiation.events == ["initiation (unstable)"]
    assert initiation.state.load == pytest.approx(experiment.dcb_load(experiment.DCB_CRACK, MODULUS,
                                                                       experiment.G_IC), rel=0.01)
    assert any("a support at arc length 20 ahead" in event for event in steps[-1].events)
    assert steps[-1].events[-1] == "end: every tip has stopped before a support or the end of Σ"


@pytest.mark.solve
def test_the_step_size_does_not_move_the_branch(tmp_path):
    scene = experiment.dcb(tmp_path, SIZE, "displacement")
    limit = experiment.dcb_opening(8.0, MODULUS, experiment.G_IC)
    ends = [grow.grow(scene, comm(), limit, steps, 1e-5, progress=quiet)[-1].state for steps in (2, 5)]
    assert ends[0].control == ends[1].control
    assert ends[0].cracks[0][1] == pytest.approx(ends[1].cracks[0][1], rel=1e-4)


@pytest.mark.solve
@pytest.mark.slow
@pytest.mark.parametrize("ratio, unstable", [(0.5, True), (0.8, False)])
def test_enf_is_unstable_below_a_over_L_0_7(tmp_path, ratio, unstable):
    scene = experiment.enf(tmp_path, ratio, SIZE)
    a = ratio * 0.5 * beams.SPAN
    limit = 1.2 * experiment.enf_deflection_guess(a, MODULUS)
    steps = grow.grow(scene, comm(), limit, 2, 1e-4, progress=quiet)
    initiation = next(s for s in steps if s.events and s.events[0].startswith("initiation"))
    assert initiation.unstable == unstable
    assert steps[-1].state.cracks[0][1] > a
    assert abs(initiation.state.G_I[0]) <= 1e-3 * initiation.state.G[0]  # mode II, faces in contact


def strip_with_disbonds(path, cracks: str, pressure: str, toughness: float) -> Scene:
    """A clamped strip 6 × 1 with the disbonds ``cracks`` on Σ, both layers' tops under ``pressure``."""
    path.write_text(f"""
[geometry]
box = [0.0, 6.0, -0.5, 0.5]
cracks = {cracks}
clamped = ["left", "right"]
[mesh]
size = 0.1
{MATERIALS}
[loads.layer1.top]
pressure = {pressure}
[loads.layer2.top]
pressure = {pressure}
[fracture]
toughness = {toughness}
""")
    return Scene.load(path)


@pytest.mark.solve
def test_two_disbonds_merge(tmp_path):
    scene = strip_with_disbonds(tmp_path / "disbonds.toml", "[[0.5, 2.8], [3.2, 5.5]]",
                                '"-1e-3*exp(-20*(x - 3)^2)"', 1e-9)
    steps = grow.grow(scene, comm(), 1.0, 2, 1e-3, progress=quiet)
    assert any("merge" in event for s in steps for event in s.events)
    assert len(steps[-1].state.cracks) == 1


@pytest.mark.solve
def test_a_tip_at_a_support_stops_and_the_others_grow_on(tmp_path):
    """A tip that reaches a support above G_c stops there (one Σ edge before it); the run goes on with the
    other tips, and ends once every tip has stopped."""
    scene = strip_with_disbonds(tmp_path / "two.toml", "[[0.6, 1.4], [3.0, 4.5]]",
                                '"-1e-3*exp(-8*(x - 1)^2) - 0.7e-3*exp(-8*(x - 3.75)^2)"', 1e-8)
    steps = grow.grow(scene, comm(), 1.0, 1, 1e-3, progress=quiet)
    events = [event for step in steps for event in step.events]
    stopped = next(i for i, event in enumerate(events) if "stops at 0.1: a support at arc length 0 ahead" in event)
    assert any("merge" in event for event in events[stopped:])  # crack 0's other tip grew on, into crack 1
    assert any("stops at 5.9: a support at arc length 6 ahead" in event for event in events[stopped:])
    assert events[-1] == "end: every tip has stopped before a support or the end of Σ"
    assert np.allclose(steps[-1].state.cracks, [(0.1, 5.9)])


def test_bad_input_is_one_line(tmp_path):
    scene = experiment.dcb(tmp_path, SIZE, "displacement")
    for limit, steps, tolerance, fragment in ((0.0, 4, 1e-4, "--to"), (math.nan, 4, 1e-4, "--to"),
                                              (1.0, 0, 1e-4, "--steps"), (1.0, 2.5, 1e-4, "--steps 2.5: a whole"),
                                              (1.0, 4, 2.0, "--tolerance")):
        with pytest.raises(UsageError, match=fragment):
            grow.grow(scene, comm(), limit, steps, tolerance, progress=quiet)
    with pytest.raises(SceneError, match="no toughness"):
        grow.Growth(Scene.load("partial-closure", ["mesh.sigma_vertices=13", "mesh.boundary_vertices=16"]),
                    comm())
    mixed = Scene.load(tmp_path / "dcb-displacement-0.25.toml",
                       ["loads.layer1.top.y=1.0"])
    with pytest.raises(SceneError, match="loads.layer1.top.*displacements"):
        grow.control_kind(mixed)


@pytest.mark.mpi
def test_grow_command_on_two_ranks(tmp_path):
    experiment.dcb(tmp_path, SIZE, "displacement")  # writes the scene and its .geo
    limit = experiment.dcb_opening(7.5, MODULUS, experiment.G_IC)
    output = tmp_path / "dcb.h5"
    completed = ddsolve("grow", "-n", "2", str(tmp_path / "dcb-displacement-0.25.toml"), "--to", repr(limit),
                        "--steps", "3", "--pictures", "2", "-o", str(output))
    assert "initiation" in completed.stdout and "stable growth" in completed.stdout
    assert output.with_suffix(".png").stat().st_size > 0
    assert len(list(tmp_path.glob("dcb-step*.png"))) == 2
    data = growth_files.read(output)
    assert data["cracks"][-1, 0, 1] > experiment.DCB_CRACK
    bad = ddsolve("grow", str(tmp_path / "dcb-displacement-0.25.toml"), "--to", "-1", check=False)
    refused(bad, 2, "--to")
    bad = ddsolve("grow", "-n", "2", str(tmp_path / "dcb-displacement-0.25.toml"), "--to", "1", "--steps", "0",
                  check=False)  # every rank finds it: one line, not one per rank
    refused(bad, 2, "grow: --steps 0: a whole number of steps")


@pytest.mark.solve
def test_a_temperature_change_is_kept_while_the_opening_rises(tmp_path):
    """With a fixed temperature change the initiation factor comes from the root solve over scaled scenes
    (the prescribed opening's Σ values scaled with it); a fresh solve there is critical, and growth follows."""
    experiment.dcb(tmp_path, SIZE, "displacement")
    text = (tmp_path / "dcb-displacement-0.25.toml").read_text()
    text = text.replace("nu = 0.28\n", "nu = 0.28\nalpha = 1e-5\n", 1) + "[temperature]\nlayer1 = 2.0\nlayer2 = 0.0\n"
    (tmp_path / "thermal.toml").write_text(text)
    scene = Scene.load(tmp_path / "thermal.toml")
    steps = grow.grow(scene, comm(), experiment.dcb_opening(7.0, MODULUS, experiment.G_IC), 2, 1e-4, progress=quiet)
    initiation = next(s for s in steps if s.events and s.events[0].startswith("initiation"))
    assert 0.0 < initiation.state.control and abs(initiation.state.ratio[0] - 1.0) <= 1e-6
    assert steps[-1].state.cracks[0][1] > experiment.DCB_CRACK


@pytest.mark.solve
def test_cracks_with_their_own_toughness_end_the_run_where_they_meet():
    """fracture.toughness with one value per crack does not say which G_c a merged crack has: where two
    cracks meet the run ends (its steps kept), instead of failing the merged configuration's checks."""
    source = Scene.load("strip-disbonds", ["fracture.toughness=[1e-6, 1.2e-6, 5e-6]"])
    steps = grow.grow(source, comm(), 2.0, 4, progress=quiet)
    last = steps[-1]
    assert last.events[-1].startswith("end: cracks meet") and "one value per crack" in last.events[-1]
    assert len(last.state.cracks) == 3  # the configuration before they met
