"""Round 4 of `grow`: ranges of its options (class 1), its whole output set (class 5), growth that cannot go
on (class 8: a freed part, the critical-load search with a small toughness, G ≈ 0 under Hutchinson–Suo, the
step bound) and what an engineer reads (forces and displacements per boundary, the CSV, the default limit)."""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from conftest import SMALL, ddsolve, refused
from hypothesis import given, settings, strategies as st

from ddsolve.errors import DDSolveError, SceneError, SolverError, UsageError
from ddsolve.fem import assembly
from ddsolve.io import safe
from ddsolve.post import toughness
from ddsolve.post.result import Fracture
from ddsolve.problem.scene import Scene
from ddsolve.solvers import critical, grow, growth_files

FEW = settings(derandomize=True, max_examples=25, deadline=None)
PARTIAL = ["mesh.sigma_vertices=13", "mesh.boundary_vertices=16", "fracture.toughness=4.61e-7"]


def comm():
    from mpi4py import MPI

    return MPI.COMM_SELF


def quiet(_line: str) -> None:
    pass


# --- class 1: the options' ranges --------------------------------------------------------------------
@FEW
@given(limit=st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True), st.booleans()),
       steps=st.one_of(st.integers(-5, 10 ** 7), st.booleans(), st.floats(0, 10)),
       tolerance=st.floats(allow_nan=True, allow_infinity=True),
       pictures=st.one_of(st.integers(-5, 10 ** 4), st.floats(0, 5)))
def test_every_option_is_checked_before_work(limit, steps, tolerance, pictures):
    """Any value of the options either passes or gives one UsageError naming the option."""
    try:
        grow.check_controls(limit, steps, tolerance, pictures)
    except UsageError as exc:
        assert str(exc).startswith("grow: --")
        return
    assert limit is None or (0 < limit < math.inf and not isinstance(limit, bool))
    assert 1 <= steps <= grow.MAX_STEPS and 0 <= pictures <= grow.MAX_PICTURES


@pytest.fixture(scope="module")
def partial():
    return grow.Growth(Scene.load("partial-closure", PARTIAL), comm())


@settings(derandomize=True, max_examples=30, deadline=None)
@given(exponent=st.floats(-320, 308), steps=st.integers(1, grow.MAX_STEPS))
def test_a_limit_the_solve_cannot_represent_is_refused_before_work(partial, exponent, steps):
    """--to is refused where the scaled loads (its largest, or its first step) fall outside what
    assembly.check_range accepts; any other limit passes that check at both ends."""
    limit = 10.0 ** exponent
    if not limit > 0 or not math.isfinite(limit):
        return
    try:
        partial.check_limit(limit, steps, "--to")
    except UsageError as exc:
        assert "--to" in str(exc) and "double-precision" in str(exc)
        return
    for control in (limit, limit / steps):
        assembly.check_range(partial.scene.scaled(control), partial.base)


@pytest.mark.mpi
def test_out_of_range_limits_and_steps_are_one_line(tmp_path):
    before = tmp_path / "g.h5"
    before.write_bytes(b"earlier")
    for options, fragment in ((["--to", "1e160"], "--to 1e+160: scales loads"), (["--to", "1e-300"], "--to 1e-300 in 20"),
                              (["--to", "1", "--steps", "1000000"], "--steps 1000000")):
        completed = ddsolve("grow", "partial-closure", *SMALL, "--set", "fracture.toughness=4.61e-7", *options,
                            "-o", str(before), check=False, timeout=120)
        refused(completed, 2, fragment)
        assert before.read_bytes() == b"earlier"


# --- class 5: the whole output set ---------------------------------------------------------------------
@FEW
@given(obstacle=st.sampled_from(["directory", "fifo", "file", "none"]),
       name=st.sampled_from(["g.csv", "g.png", "g-step3.png", "g-step12.png", "g-stepx.png"]),
       scene_name=st.sampled_from(["g.png", "g.csv", "scene.toml", "g-step1.png"]))
def test_every_path_of_the_set_is_checked_before_work(tmp_path_factory, obstacle, name, scene_name):
    """A directory or FIFO at any name of the set (an earlier run's step pictures included), or an input
    at one, is refused before the run; anything else passes."""
    folder = tmp_path_factory.mktemp("set")
    scene = folder / scene_name
    scene.write_text("[geometry]\n")
    target = folder / name
    if obstacle == "directory" and target != scene:
        target.mkdir()
    elif obstacle == "fifo" and target != scene:
        os.mkfifo(target)
    elif obstacle == "file" and target != scene:
        target.write_text("earlier")
    files = growth_files.Outputs(folder / "g.h5")
    named = {files.csv.name, files.curves.name} | {p.name for p in files.step_pictures()}
    bad = (obstacle in ("directory", "fifo") and name in named and target != scene) or scene.name in named
    try:
        files.check([scene])
    except DDSolveError:
        assert bad
        return
    assert not bad


def test_a_set_replaces_its_files_and_removes_the_ones_it_no_longer_has(tmp_path):
    old = [tmp_path / name for name in ("g.h5", "g-step1.png", "g-step7.png")]
    for path in old:
        path.write_text("old")
    safe.replace_together({old[0]: lambda name: Path(name).write_text("new"),
                           old[1]: lambda name: Path(name).write_text("new")}, remove=[old[2]])
    assert old[0].read_text() == old[1].read_text() == "new" and not old[2].exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g-step1.png", "g.h5"]


@pytest.mark.mpi
def test_the_set_is_checked_first_and_written_whole(tmp_path):
    """A directory at a step picture's name and a scene named like the curves are refused before any work
    (the earlier set byte-identical); a run writes h5, CSV, curves and its pictures, and a rerun with
    fewer pictures removes the step pictures it no longer has.  Without --to the limit is 2 × initiation."""
    out = tmp_path / "g.h5"
    run = ["grow", "partial-closure", *SMALL, "--set", "fracture.toughness=4.61e-7", "--steps", "2", "-o", str(out)]
    done = ddsolve(*run, "--pictures", "3")
    assert "(2 × initiation)" in done.stdout and "event at step" in done.stdout
    first = sorted(p.name for p in tmp_path.iterdir())
    assert {"g.h5", "g.csv", "g.png"} <= set(first) and sum("-step" in name for name in first) == 3
    data = growth_files.read(out)
    initiation = next(c for c, e in zip(data["control"], data["events"]) if e.startswith("initiation"))
    assert math.isclose(data["attrs"]["limit"], grow.DEFAULT_MULTIPLE * initiation, rel_tol=1e-12)
    for forces in data["boundaries"].values():
        assert forces["force"].shape == forces["displacement"].shape == (len(data["control"]), 2)
    header = (tmp_path / "g.csv").read_text().splitlines()[0]
    assert header.startswith("step,control,load,displacement,layer1.") and header.endswith("energy,unstable,events")
    picture = sorted(tmp_path.glob("g-step*.png"))[-1]
    saved = {p: p.read_bytes() for p in tmp_path.iterdir()}
    picture.unlink()
    picture.mkdir()
    refused(ddsolve(*run, check=False), 1, picture.name)
    picture.rmdir()
    assert all(p.read_bytes() == data for p, data in saved.items() if p != picture)
    ddsolve(*run, "--pictures", "1")
    assert sum("-step" in p.name for p in tmp_path.iterdir()) == 1
    scene = tmp_path / "s.png"  # a scene named like the curves of its output
    scene.write_text(Scene.load("partial-closure").text)
    refused(ddsolve("grow", str(scene), *run[2:-2], "-o", str(tmp_path / "s.h5"), check=False), 1, "input")
    assert not (tmp_path / "s.h5").exists()


# --- class 8: growth that cannot go on ---------------------------------------------------------------
@pytest.mark.solve
def test_merging_cracks_that_free_a_part_end_the_run_with_its_steps(tmp_path):
    """Two cracks that would crack the whole of Σ free the upper part: the run ends there with its steps,
    saying what moves, and a part that can move every way is not said to rotate about a far point."""
    path = tmp_path / "detach.toml"
    path.write_text("""
[geometry]
box = [0.0, 6.0, -0.5, 0.5]
cracks = [[0.0, 2.8], [3.2, 6.0]]
clamped = ["bottom"]
[mesh]
size = 0.25
[materials.layer1]
E = 200.0
nu = 0.28
[materials.layer2]
E = 112.0
nu = 0.32
[loads.layer1.top]
y = "1e-3*exp(-20*(x - 3)^2)"
[loads.layer2.top]
y = "1e-3*exp(-20*(x - 3)^2)"
[fracture]
toughness = 1e-9
""")
    steps = grow.grow(Scene.load(path), comm(), 1.0, 2, 1e-3, progress=quiet, output=tmp_path / "d.h5")
    last = steps[-1].events[-1]
    assert last.startswith("end: the cracks would meet as (0, 6) and free a part: blocks u_plus, v_plus can "
                           "translate and rotate freely"), last
    assert len(growth_files.read(tmp_path / "d.h5")["control"]) == len(steps)


def fracture(G: np.ndarray) -> Fracture:
    n = len(G)
    return Fracture(points=np.zeros((n, 2)), directions=np.ones((n, 2)), crack=np.zeros(n, dtype=int),
                    inner=np.ones(n), outer=np.ones(n), spacing=np.ones(n), G=G, contact=np.zeros(n),
                    zones=np.zeros((0, 2)), zone_crack=np.zeros(0, dtype=int), G_I=G, G_II=0 * G, phase=0 * G)


@settings(derandomize=True, max_examples=40, deadline=None)
@given(thermal=st.floats(-1e-6, 0.0), mechanical=st.floats(1e-9, 1e-3), noise=st.floats(0.0, 1e-10),
       exponent=st.floats(-14, -8))
def test_the_critical_load_search_settles_with_a_small_toughness(thermal, mechanical, noise, exponent):
    """G(λ) = G_T + λ² G_M at a tip, another tip at G = 1e-5, the solve's noise relative to the largest G:
    the search finds λ_c = √((G_c − G_T)/G_M) to what the noise allows, whatever the toughness (it failed
    on strip-disbonds heated with G_c = 1e-12: "no λ in 40 solves", "G/G_c − 1 jumps")."""
    G_c = 10.0 ** exponent
    scene = Scene.load("partial-closure", [f"fracture.toughness={G_c!r}", "materials.layer1.alpha=1e-5",
                                           "temperature.layer1=1.0"])
    rng = np.random.default_rng(0)
    largest = 1e-5

    def evaluate(lam: float) -> Fracture:
        exact = thermal + lam ** 2 * mechanical
        return fracture(np.array([exact + noise * largest * rng.uniform(-1.0, 1.0), largest]))

    try:
        found = critical.search(scene, evaluate)[0]
    except SolverError as exc:
        pytest.fail(str(exc))
    expected = math.sqrt((G_c - thermal) / mechanical)
    if expected > critical.MAX_FACTOR:
        assert found == math.inf
        return
    off = max(critical.TOLERANCE * G_c, critical.RELEASE * max(-thermal, G_c), noise * largest) * 1.01
    assert abs(found - expected) <= off / (2 * mechanical * expected) + 2 * critical.RESOLUTION * expected


@FEW
@given(G=st.lists(st.one_of(st.floats(-1e-12, 1e-12), st.just(0.0)), min_size=1, max_size=4),
       phase_defined=st.booleans())
def test_hutchinson_suo_at_G_near_zero_is_never_nan(G, phase_defined):
    """A tip with G ≈ 0 has no phase angle: Hutchinson–Suo gives G_Ic there, so its critical factor is a
    number or inf, and the initiation (the smallest factor) is never NaN."""
    scene = Scene.load("partial-closure", ['fracture.law="hutchinson-suo"', "fracture.G_Ic=2.0", "fracture.lambda=0.3"])
    G = np.array(G)
    phase = np.where(phase_defined, 10.0, np.nan) * np.ones_like(G)
    G_c = toughness.law(scene.fracture, np.zeros(len(G), dtype=int), G, 0 * G, phase)
    assert np.isfinite(G_c).all() and (G_c >= 2.0).all()
    factors = toughness.critical_factor(G, G_c)
    assert not np.isnan(factors).any() and not math.isnan(np.min(factors))


def test_steps_are_bounded_like_sweeps():
    with pytest.raises(UsageError, match="--steps 1000000: .*at most 1,000"):
        grow.check_controls(1.0, 1_000_000, 1e-4, 3)


def test_without_a_limit_there_must_be_an_initiation():
    assert grow.default_limit(1.5) == grow.DEFAULT_MULTIPLE * 1.5
    for initiation in (math.inf, 0.0):
        with pytest.raises(UsageError, match="give --to"):
            grow.default_limit(initiation)
    with pytest.raises(SceneError):
        grow.control_kind(Scene.load("partial-closure", ["loads={}"]))


@FEW
@given(free=st.lists(st.sampled_from(["x", "y", "rotation"]), min_size=1, max_size=3, unique=True),
       block=st.integers(0, 3), mixing=st.floats(-2.0, 2.0))
def test_the_free_motion_of_a_part_is_named_from_the_whole_kernel(free, block, mixing):
    """A part that can move in several ways is named by all of them (a freed part said to "rotate about
    (−181, −0.2)" could translate): every motion, both translations, or the one motion it has."""
    from ddsolve.dd import kernels
    from ddsolve.mesh.mesh import blocks

    frame = kernels.Frame(np.array([0.0, 0.0]), 2.0)
    modes = np.eye(3)[[("x", "y", "rotation").index(name) for name in free]].T  # (3, m)
    if modes.shape[1] > 1:  # any basis of the same span
        modes = modes @ (np.eye(modes.shape[1]) + mixing * np.triu(np.ones((modes.shape[1],) * 2), 1))
    whole = np.zeros((12, modes.shape[1]))
    whole[3 * block:3 * block + 3] = modes
    text = kernels.describe(whole, frame)
    assert text.startswith(f"blocks {blocks(2)[block].name} can ")
    if len(free) == 3:
        assert "translate and rotate freely" in text
    elif set(free) == {"x", "y"}:
        assert "translate in x and y" in text
    elif free == ["rotation"]:
        assert "rotate about (0, 0)" in text
    elif len(free) == 1:
        assert f"translate along ({float(free == ['x']):.3g}, {float(free == ['y']):.3g})" in text


@pytest.mark.unit
@pytest.mark.parametrize("overrides, keys", [
    ({}, []), ({"fracture.toughness": 1e-7}, []), ({"fracture.toughness": [1e-7, 2e-7, 3e-7]}, ["fracture.toughness"]),
    ({"contact.friction": [0.1, 0.2, 0.3]}, ["contact.friction"]), ({"contact.slip_bound": 0.5}, []),
    ({"contact.slip_bound": [0.1, 0.2, 0.3], "fracture.toughness": [1e-7, 2e-7, 3e-7]},
     ["fracture.toughness", "contact.slip_bound"])])
def test_the_keys_a_merged_crack_has_no_value_of_end_a_growth_there(overrides, keys):
    """A per-crack list of toughness or friction has no value for two cracks that meet: growth ends there
    (as measured: strip-disbonds grown with contact.friction = [0.1, 0.2, 0.3] stopped with an error and no file)."""
    assert grow.per_crack_keys(Scene.load("strip-disbonds", overrides)) == keys


@pytest.mark.unit
def test_the_table_of_a_growth_takes_steps_before_any_crack():
    """A bond with no initial crack has steps with no crack yet: their rows are empty, not a failure to write
    (as measured: every such growth failed when its file was written, after all its steps)."""
    def state(cracks) -> grow.State:
        tips = np.zeros(2 * len(cracks))
        return grow.State(cracks=cracks, control=0.1, tips=tips, heading=tips, spacing=tips, G=tips, G_I=tips,
                          G_II=tips, G_c=tips, energy=0.0, load=0.0, displacement=0.0)

    steps = [grow.Step(state(())), grow.Step(state(((0.0, 0.5),)))]
    data = growth_files.table(Scene.load("partial-closure"), "displacement", 1.0, 1e-3, steps)
    assert data["cracks"].shape == (2, 1, 2) and np.isnan(data["cracks"][0]).all()
    assert data["cracks"][1, 0].tolist() == [0.0, 0.5]
