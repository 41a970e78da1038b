"""Meshes of several interfaces.  gmsh files: physical curves sigma1, sigma2, ... with crack1, ..., a physical
surface per region listed bottom to top (its name keys its materials); such a file solves as the box of the same
geometry, and bad files are refused in one line.  The box: a region far thinner than mesh.size is meshed with
triangles of good shape, and one too thin (or a Σ piece too short) is refused naming the key."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_interfaces import STRIP

from ddsolve.errors import MeshError, SceneError
from ddsolve.mesh import mesh as meshes
from ddsolve.mesh import stack
from ddsolve.problem import scene
from ddsolve.solvers import stacked

#: The strip of test_interfaces (0, 4) × (0, 3) as a .geo: interfaces at y = 1 and 2, a crack on each.
GEO = """lc = 1.0;
Point(1) = {0, 0, 0, lc}; Point(2) = {4, 0, 0, lc};
Point(3) = {0, 1, 0, lc}; Point(4) = {1, 1, 0, lc}; Point(5) = {2, 1, 0, lc}; Point(6) = {4, 1, 0, lc};
Point(7) = {0, 2, 0, lc}; Point(8) = {2, 2, 0, lc}; Point(9) = {3, 2, 0, lc}; Point(10) = {4, 2, 0, lc};
Point(11) = {0, 3, 0, lc}; Point(12) = {4, 3, 0, lc};
Line(1) = {1, 2};
Line(2) = {3, 4}; Line(3) = {4, 5}; Line(4) = {5, 6};
Line(5) = {7, 8}; Line(6) = {8, 9}; Line(7) = {9, 10};
Line(8) = {11, 12};
Line(9) = {1, 3}; Line(10) = {3, 7}; Line(11) = {7, 11};
Line(12) = {2, 6}; Line(13) = {6, 10}; Line(14) = {10, 12};
Curve Loop(1) = {1, 12, -4, -3, -2, -9}; Plane Surface(1) = {1};
Curve Loop(2) = {2, 3, 4, 13, -7, -6, -5, -10}; Plane Surface(2) = {2};
Curve Loop(3) = {5, 6, 7, 14, -8, -11}; Plane Surface(3) = {3};
Physical Surface("bottom_ply") = {1};
Physical Surface("middle_ply") = {2};
Physical Surface("top_ply") = {3};
Physical Curve("sigma1") = {2, 3, 4};
Physical Curve("crack1") = {3};
Physical Curve("sigma2") = {5, 6, 7};
Physical Curve("crack2") = {6};
Physical Curve("left") = {9, 10, 11};
Physical Curve("clamped") = {9, 10, 11};
Physical Curve("right") = {12, 13, 14};
Physical Curve("top") = {8};
"""

#: The scene of the file: the strip's materials (the middle ply stiffer in layer 1) and loads.
SCENE = """[mesh]
file = "strip.geo"
size = 0.125
[materials.layer1]
E = 1.0
nu = 0.3
[materials.layer1.middle_ply]
E = 2.0
[materials.layer2]
E = 1.0
nu = 0.3
[loads.layer1.right]
x = 0.1
[loads.layer1.top]
y = -0.05
"""


def from_file(folder: Path, geo: str = GEO, text: str = SCENE) -> scene.Scene:
    (folder / "strip.geo").write_text(geo)
    return scene.loads(text, origin="strip.toml", base=folder)


@pytest.mark.solve
def test_the_file_solves_as_the_box_of_the_same_geometry(tmp_path):
    source = from_file(tmp_path)
    assert source.geometry.region_names == ("bottom_ply", "middle_ply", "top_ply")
    assert source.material("layer1", "middle_ply").E == 2.0 and source.material("layer1", "top_ply").E == 1.0
    mesh = stack.build_any(source)
    assert [region.name for region in mesh.regions] == ["bottom_ply", "middle_ply", "top_ply"]
    assert [float(line.points[0, 1]) for line in mesh.sigmas] == [1.0, 2.0]
    filed = stacked.solve_stack(source, mesh)
    box = scene.loads(STRIP, ["mesh.size=0.125", "loads.layer1.top.y=-0.05"], origin="strip.toml")
    boxed = stacked.solve_stack(box, stack.build_any(box))
    assert filed.converged and boxed.converged
    assert filed.energy == pytest.approx(boxed.energy, rel=1e-3)  # two meshes of one geometry
    np.testing.assert_allclose(filed.fracture.points, boxed.fracture.points)
    np.testing.assert_array_equal(filed.fracture.interface, [1, 1, 2, 2])
    np.testing.assert_allclose(filed.fracture.G, boxed.fracture.G, rtol=0.02)  # 15 % at size 0.25, 1 % at 0.125


@pytest.mark.parametrize("change, message", [
    (('"sigma1"', '"sigma3"'), 'physical curve sigma3 without sigma1: number the interfaces sigma1, sigma2, ...'),
    (('"crack1"', '"crack3"'), "physical curve crack3 lies on no interface (no sigma3)"),
    (('Physical Curve("top")', 'Physical Curve("sigma")'), "physical curves sigma and sigma1: name one interface sigma"),
    (('Physical Surface("top_ply") = {3};', ""), "2 interfaces (sigma1 ... sigma2) cut Ω into 3 regions, and the "
                                                 "file has 2 physical surfaces (bottom_ply, middle_ply)"),
])
def test_a_file_of_bad_names_is_refused_in_one_line_when_read(tmp_path, change, message):
    with pytest.raises(SceneError) as caught:
        from_file(tmp_path, GEO.replace(*change))
    assert str(caught.value).startswith("strip.toml: mesh.file strip.geo: ") and message in str(caught.value)
    assert "\n" not in str(caught.value)


#: The top ply lifted off the middle one (a gap from y = 2 to 2.5): it lies on no interface.
GAP = GEO.replace("Point(11) = {0, 3, 0, lc}; Point(12) = {4, 3, 0, lc};",
                  "Point(11) = {0, 3, 0, lc}; Point(12) = {4, 3, 0, lc}; Point(13) = {0, 2.5, 0, lc}; "
                  "Point(14) = {4, 2.5, 0, lc};").replace(
    "Curve Loop(3) = {5, 6, 7, 14, -8, -11};", "Line(15) = {13, 14}; Line(16) = {14, 12}; Line(17) = {13, 11};\n"
    "Curve Loop(3) = {15, 16, -8, -17};").replace(
    'Physical Curve("left") = {9, 10, 11};\nPhysical Curve("clamped") = {9, 10, 11};',
    'Physical Curve("left") = {9, 10, 17};\nPhysical Curve("clamped") = {9, 10, 17};').replace(
    'Physical Curve("right") = {12, 13, 14};', 'Physical Curve("right") = {12, 13, 16};')


@pytest.mark.parametrize("geo, message", [
    (GEO.replace('Physical Curve("sigma2") = {5, 6, 7};', 'Physical Curve("sigma2") = {5, 6, 7, 4};'),
     "physical curves sigma1 and sigma2 cross or touch: interfaces lie apart, bottom to top"),
    (GEO.replace('Physical Surface("bottom_ply") = {1};\nPhysical Surface("middle_ply") = {2};',
                 'Physical Surface("middle_ply") = {2};\nPhysical Surface("bottom_ply") = {1};'),
     "physical surface middle_ply lies on sigma1, sigma2, and region 1 from the bottom lies on sigma1: list the "
     "region surfaces bottom to top, each between its interfaces"),
    (GAP, "physical surface top_ply lies on no interface, and region 3 from the bottom lies on sigma2"),
], ids=["crossing", "order", "gap"])
def test_a_file_of_bad_geometry_is_refused_in_one_line_when_meshed(tmp_path, geo, message):
    source = from_file(tmp_path, geo)
    with pytest.raises(MeshError) as caught:
        stack.build_any(source)
    assert message in str(caught.value) and "\n" not in str(caught.value)


# --- the box: a region far thinner than mesh.size, a Σ piece far shorter -------------------------------------
def test_a_thin_region_and_its_neighbours_keep_the_shape_of_their_triangles():
    source = scene.loads(STRIP, ["geometry.sigma=[1.0, 1.01]"], origin="strip.toml")
    assert stack.line_spacings(source.geometry, 0.25) == pytest.approx([0.25, 0.01, 0.01, 0.25])  # bottom, Σ₁, Σ₂, top
    angles = [meshes.statistics(region).min_angle for region in stack.build_any(source).regions]
    assert min(angles) > 20.0  # 2.3° with every line divided by mesh.size (0° at 1e-4 thick)


@pytest.mark.parametrize("override, message", [
    ("geometry.sigma=[1.0, 1.001]", "strip.toml: geometry.sigma: region2 is 0.001 thick, less than mesh.size / 100 "
                                    "= 0.0025: give mesh.size at most 0.1, or a thicker region"),
    ("geometry.cracks=[[[1.0, 2.0]], [[2.0, 2.0000001]]]",
     "strip.toml: geometry.cracks: interface 2's piece [2, 2.0000001] of Σ between crack tips is 1e-07 long, less "
     "than 1/100 of its elements' size 0.25 (mesh.size): they would be slivers; refine (mesh.size) or lengthen the "
     "piece"),
])
def test_a_region_or_a_piece_too_thin_for_mesh_size_is_refused_naming_the_key(override, message):
    with pytest.raises(SceneError) as caught:
        stack.build_any(scene.loads(STRIP, [override], origin="strip.toml"))
    assert str(caught.value) == message


def test_one_interface_with_a_crack_far_shorter_than_its_elements_is_refused_naming_the_key():
    with pytest.raises(SceneError) as caught:
        stack.build_any(scene.load("linear", ["mesh.size=0.25", "geometry.cracks=[[0.0, 1e-7]]"]))
    assert str(caught.value) == ("linear: geometry.cracks: the piece [0, 1e-07] of Σ between crack tips is 1e-07 long, "
                                 "less than 1/100 of its elements' size 0.25 (mesh.size): they would be slivers; "
                                 "refine (mesh.size) or lengthen the piece")  # meshed with angles of 0° before
