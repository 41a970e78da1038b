"""Several interfaces in the box: ``geometry.sigma = [y1, y2, ...]`` with one crack list per interface
(``geometry.cracks = [[[a, b], ...], ...]``), regions ``region1`` ... ``regionR`` with their own materials; the
one-interface forms and names stay as they were; bad input is refused in one line naming the key."""
from __future__ import annotations

import re

import pytest

from ddsolve.errors import SceneError
from ddsolve.mesh import geometry
from ddsolve.problem import materials, scene
from ddsolve.solvers import checks

#: A strip of three regions: two interfaces, a crack on each, a stiffer middle region in layer 1.
STRIP = """
[geometry]
box = [0.0, 4.0, 0.0, 3.0]
sigma = [1.0, 2.0]
cracks = [[[1.0, 2.0]], [[2.0, 3.0]]]
clamped = ["left"]
[mesh]
size = 0.25
[materials.layer1]
E = 1.0
nu = 0.3
[materials.layer1.region2]
E = 2.0
[materials.layer2]
E = 1.0
nu = 0.3
[loads.layer1.right]
x = 0.1
"""


def strip(*overrides: str) -> scene.Scene:
    return scene.loads(STRIP, list(overrides), origin="strip.toml")


def refusal(*overrides: str) -> str:
    with pytest.raises(SceneError) as caught:
        strip(*overrides)
    message = str(caught.value)
    assert "\n" not in message
    return message


def test_the_interfaces_their_cracks_and_the_regions_bottom_to_top():
    geometry_ = strip().geometry
    assert geometry_.sigmas == (1.0, 2.0)
    assert geometry_.crack_lists == (((1.0, 2.0),), ((2.0, 3.0),))
    assert geometry_.region_names == ("region1", "region2", "region3")
    assert (geometry_.sigma, geometry_.cracks) == (1.0, ((1.0, 2.0),))


def test_a_region_overrides_its_layer_in_that_region_only():
    source = strip()
    assert source.material("layer1", "region2") == materials.Isotropic(E=2.0, nu=0.3)
    assert source.material("layer1", "region1") == source.material("layer1", "region3") == source.materials["layer1"]
    assert source.material_key("layer1", "region2") == "materials.layer1.region2"
    assert source.dissimilar_layers() == ["layer1"]
    assert strip("materials.layer1.region2.E=1.0").dissimilar_layers() == []


def test_an_interface_without_cracks_and_no_cracks_key():
    assert strip("geometry.cracks=[[], [[0.5, 1.5]]]").geometry.crack_lists == ((), ((0.5, 1.5),))
    text = STRIP.replace("cracks = [[[1.0, 2.0]], [[2.0, 3.0]]]\n", "")
    assert scene.loads(text).geometry.crack_lists == ((), ())


@pytest.mark.parametrize("sigma, cracks", [("0.5", "[[1.0, 2.0]]"), ("[0.5]", "[[1.0, 2.0]]"),
                                           ("[0.5]", "[[[1.0, 2.0]]]"), ("0.5", "[[[1.0, 2.0]]]")])
def test_one_interface_in_either_form_is_the_old_scene(sigma, cracks):
    old = scene.loads(STRIP.replace("sigma = [1.0, 2.0]", "sigma = 0.5").replace(
        "cracks = [[[1.0, 2.0]], [[2.0, 3.0]]]", "cracks = [[1.0, 2.0]]").replace("region2", "upper"))
    new = scene.loads(STRIP.replace("sigma = [1.0, 2.0]", f"sigma = {sigma}").replace(
        "cracks = [[[1.0, 2.0]], [[2.0, 3.0]]]", f"cracks = {cracks}").replace("region2", "upper"))
    assert new.geometry == old.geometry and new.geometry.above == ()
    assert new.geometry.region_names == ("lower", "upper")
    assert new.regions == old.regions


def test_the_paper_scenes_keep_their_geometry():
    paper = scene.load("partial-closure")
    assert (paper.geometry.sigmas, paper.geometry.crack_lists) == ((0.0,), (((-0.5, 0.5),),))
    assert paper.geometry.region_names == ("lower", "upper")


@pytest.mark.parametrize("override, expected", [
    ("geometry.sigma=[2.0, 1.0]", r"geometry.sigma: interfaces 1 and 2 cross or touch \(y = 2 and 1\)"),
    ("geometry.sigma=[1.0, 1.0]", r"geometry.sigma: interfaces 1 and 2 cross or touch"),
    ("geometry.sigma=[1.0, 5.0]", r"geometry.sigma = 5 must lie strictly between"),
    ("geometry.sigma=[]", r"geometry.sigma must be a number or a list"),
    ("geometry.cracks=[[[1.0, 2.0]]]", r"geometry.cracks lists 1 crack list for the 2 interfaces of geometry.sigma"),
    ("geometry.cracks=[[[1.0, 2.0]], [], []]", r"geometry.cracks lists 3 crack lists for the 2 interfaces"),
    ("geometry.cracks=[[1.0, 2.0]]", r"geometry.cracks: with 2 interfaces give one list of intervals per interface"),
    ("geometry.crack=[1.0, 2.0]", r"geometry.crack: with 2 interfaces give one list of intervals per interface"),
    ("geometry.cracks=[[[1.0, 5.0]], []]", r"geometry.cracks: the crack \[1, 5\] leaves the box's x range"),
    ("geometry.cracks=[[[1.0, 2.0]], 5]", r"geometry.cracks must be one list of intervals per interface"),
    ("materials.layer1.region4.E=3.0", r"materials.layer1.region4: no region of that name \(the regions of Ω, "
                                       r"bottom to top: region1, region2, region3\)"),
    ("materials.layer1.lower.E=3.0", r"materials.layer1.lower: no region of that name"),
    ("contact.friction=[0.1]", r"contact.friction lists 1 values for the 2 cracks of geometry.cracks \(one per "
                               r"crack, interface by interface, bottom to top\)"),
])
def test_bad_input_is_refused_in_one_line_naming_the_key(override, expected):
    assert re.search(expected, refusal(override))


def test_the_one_interface_crack_form_with_several_interfaces_is_refused():
    text = STRIP.replace("cracks = [[[1.0, 2.0]], [[2.0, 3.0]]]", "crack = [1.0, 2.0]")
    with pytest.raises(SceneError, match=r"geometry.crack: with 2 interfaces give one list of intervals"):
        scene.loads(text)


def test_a_numbered_region_with_one_interface_is_unknown():
    with pytest.raises(SceneError, match=r"materials.layer1.region2: no region of that name \(the regions of Ω, "
                                         r"bottom to top: lower, upper\)"):
        scene.load("partial-closure", ["materials.layer1.region2.E=3.0"])


def test_a_point_support_on_the_upper_interface_is_snapped_onto_its_crack_tip():
    source = strip("displacements.layer1.pin.point=[2.0, 2.0000000000001]", "displacements.layer1.pin.x=0.0")
    assert source.displacements["layer1", "pin"].point == (2.0, 2.0)


@pytest.mark.parametrize("before_work", [geometry.build, lambda source: geometry.generate_half(source, 1),
                                         checks.check_size])
def test_meshing_several_interfaces_is_refused_in_one_line(before_work):
    with pytest.raises(SceneError, match=r"^geometry.sigma: 2 interfaces: a structure of several interfaces can be "
                                         r"described but not yet meshed or solved$"):
        before_work(strip())


def test_a_scene_of_several_interfaces_is_written_out_and_read_back():
    source = strip("geometry.cracks=[[], [[0.5, 1.5], [2.0, 3.0]]]")
    assert "sigma = [1.0, 2.0]" in source.text.replace("[ ", "[").replace(" ]", "]")
    again = scene.loads(source.text)
    assert again.geometry == source.geometry and again.regions == source.regions
