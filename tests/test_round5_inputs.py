"""Round 5, the new input surfaces: friction values beyond double precision, friction and the interface crack's
reference length where they do nothing, a mesh's per-crack refusal on every rank, messages that say what a list
holds; several interfaces refused by every solving command.

Each refusal is one line naming the key, exit status 1 before any work, the previous files byte-identical. The
hypothesis generator builds friction values over their whole range (experiments/hostile5_inputs.py measures the
cases for docs/robustness.md).
"""
from __future__ import annotations

import math

import pytest
from conftest import ddsolve, previous_set, refused, unchanged
from hypothesis import given, settings
from hypothesis import strategies as st

from ddsolve.errors import SceneError
from ddsolve.problem import scene
from ddsolve.problem.scene import Friction
from ddsolve.problem.schema import MAX_FRICTION
from experiments.hostile5_inputs import NO_CRACK, ORTHOTROPIC_UPPER
from test_interfaces import STRIP

FUZZ = settings(derandomize=True, max_examples=60, deadline=None)
#: One body with an upper region of its own material (an interface crack with an isotropic pair).
ONE_LAYER = """
[geometry]
layers = 1
crack = [-0.5, 0.5]
[mesh]
sigma_vertices = 13
boundary_vertices = 32
[materials.layer1]
E = 200.0
nu = 0.28
[materials.layer1.upper]
E = 100.0
[loads.layer1.top]
y = -0.01
"""


def refusal(*overrides: str, text: str | None = None) -> str:
    """The one-line message of the scene error ``overrides`` raise (on Example 1, or on ``text``)."""
    with pytest.raises(SceneError) as caught:
        scene.loads(text, list(overrides)) if text else scene.load("partial-closure", list(overrides))
    message = str(caught.value)
    assert "\n" not in message, message
    return message


# --- class 301: friction values beyond double precision ---------------------------------------------------------
@pytest.mark.unit
@pytest.mark.parametrize("override", ["contact.friction=1e308", "contact.slip_bound=1e101",
                                      "contact.friction=[0.5, 1e200]", "contact.slip_bound=-1e-300"])
def test_friction_beyond_its_range_is_refused_naming_the_key(override):
    key = override.split("=")[0]
    assert f"{key} must be a number >= 0 up to 1e+100" in refusal(override)


@pytest.mark.unit
def test_the_largest_friction_is_accepted_and_negative_zero_is_none():
    assert scene.load("partial-closure", [f"contact.friction={MAX_FRICTION!r}"]).friction.values == MAX_FRICTION
    assert scene.load("partial-closure", ["contact.slip_bound=-0.0"]).friction is None
    assert scene.load("partial-closure", ["contact.friction=[-0.0]"]).friction is None


FRICTION_VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10, 10**400),
                            st.booleans(), st.text(max_size=3),
                            st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=3))


@pytest.mark.unit
@FUZZ
@given(value=FRICTION_VALUES, key=st.sampled_from(["friction", "slip_bound"]))
def test_any_friction_value_is_accepted_in_range_or_refused_in_one_line(value, key):
    try:
        source = scene.load("partial-closure", [f"contact.{key}={_toml(value)}"])
    except SceneError as error:
        assert "\n" not in str(error) and f"contact.{key}" in str(error)
        return
    values = source.friction.values if source.friction else 0.0
    for item in values if isinstance(values, tuple) else (values,):
        assert 0.0 <= item <= MAX_FRICTION and math.copysign(1.0, item) == 1.0


def _toml(value) -> str:
    if isinstance(value, list):
        return "[" + ", ".join(_toml(item) for item in value) + "]"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return repr(value)


# --- class 302: keys that do nothing ----------------------------------------------------------------------------
@pytest.mark.unit
@pytest.mark.parametrize("override", ["contact.friction=0.5", "contact.slip_bound=[0.1]"])
def test_friction_on_a_scene_without_cracks_is_refused(override):
    message = refusal("geometry.cracks=[]", override)
    key = override.split("=")[0]
    assert key in message and ("has no crack" in message or "lists 1 values for the 0 cracks" in message)
    assert scene.load("partial-closure", ["geometry.cracks=[]", "contact.friction=0.0"]).friction is None


@pytest.mark.unit
def test_friction_on_a_mesh_without_cracks_is_refused_naming_the_key():
    with pytest.raises(SceneError, match=r"^contact.friction: the mesh has no crack"):
        Friction(True, 0.5).per_crack(0)
    assert Friction(False, (0.1, 0.2)).per_crack(2) == (0.1, 0.2)


@pytest.mark.unit
def test_the_reference_length_needs_an_interface_crack_with_a_pair():
    assert "no layer has a region of its own material" in refusal("fracture.reference_length=0.5")
    assert "a region's material is not isotropic" in refusal(ORTHOTROPIC_UPPER, "fracture.reference_length=0.5")
    assert scene.loads(ONE_LAYER, ["fracture.reference_length=0.5"]).fracture.reference_length == 0.5


# --- class 304: what a list holds ---------------------------------------------------------------------------------
@pytest.mark.unit
@pytest.mark.parametrize("overrides, expected", [
    (['geometry.sigma=["a", 0.1]'], "geometry.sigma must be a number or a list [y1, y2, ...] of heights, each a number"),
    (["geometry.sigma=[0.1, inf]"], "of heights, each a finite number"),
    (["geometry.sigma=[-0.1, 0.1]", "geometry.cracks=[[[nan, 0.2]], []]"],
     "each a list of [a, b] intervals of finite numbers with a < b"),
    (["geometry.sigma=[-0.1, 0.1]", 'geometry.cracks=[[["a", 0.2]], []]'], "intervals of finite numbers"),
    (["geometry.cracks=[[0.1, 0.2, 0.3]]"], "geometry.cracks must be a list of [a, b] intervals of finite numbers"),
])
def test_a_list_of_the_wrong_items_says_what_each_must_be(overrides, expected):
    assert expected in refusal(*overrides)


# --- classes 302, 303 and several interfaces, end to end (one mesh and four short runs) ---------------------------
@pytest.mark.mpi
def test_refusals_on_every_rank_are_one_line_and_keep_the_previous_files(tmp_path):
    ddsolve("mesh", "partial-closure", "--set", "geometry.cracks=[]", "-o", str(tmp_path / "nocrack.msh"))
    for name, friction in (("scalar", "0.5"), ("list", "[0.5]")):
        (tmp_path / f"{name}.toml").write_text(NO_CRACK.format(friction=friction))
    output = tmp_path / "f.h5"
    files = previous_set(output)
    for name, ranks in (("scalar", 2), ("list", 4)):
        refused(ddsolve("solve", "-n", str(ranks), str(tmp_path / f"{name}.toml"), "-o", str(output), check=False),
                1, "contact.friction: the mesh has no crack")
    assert unchanged(files)
    (tmp_path / "strip.toml").write_text(STRIP)
    for command in (["sweep", "-n", "2", "--set", "materials.layer1.E=1:2:2"], ["grow", "--set",
                                                                                "fracture.toughness=1.0"]):
        refused(ddsolve(command[0], str(tmp_path / "strip.toml"), *command[1:], "-o", str(output), check=False),
                1, "geometry.sigma: 2 interfaces: a structure of several interfaces is meshed")
    assert unchanged(files)


# --- class 304: a file of many runs given where one result is read ------------------------------------------------
@pytest.mark.unit
@pytest.mark.parametrize("kind", ["growth", "sweep"])
def test_the_file_of_a_growth_or_a_sweep_is_named_as_such(tmp_path, kind):
    import h5py

    from ddsolve import load
    from ddsolve.errors import DDSolveError

    path = tmp_path / f"{kind}.h5"
    with h5py.File(path, "w") as f:
        if kind == "growth":
            f.create_group("growth")
        else:
            f.attrs["keys"] = ["materials.layer1.E"]
            f["parameters"] = [[1.0], [2.0]]
    with pytest.raises(DDSolveError, match=rf"^{path}: the file of a {kind} \(.*\), not one solve's result: give a "
                                           "result file written by solve or reference$"):
        load(path)
