"""Meshes graded towards the singular points: scene keys, where the points are, what the sizes are."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import MATERIALS

from ddsolve.errors import SceneError
from ddsolve.mesh import geometry, gmsh_io
from ddsolve.mesh import mesh as meshes
from ddsolve.mesh import sizing
from ddsolve.problem import scene

BOX = """
[geometry]
crack = [-0.5, 0.5]
[mesh]
size = 0.2
""" + MATERIALS


def test_grading_true_chooses_the_exponent_of_the_element_degree():
    assert scene.loads(BOX).mesh.grading is None
    assert scene.loads(BOX, ["mesh.grading=true"]).mesh.grading == scene.GRADING[1] == 0.4
    assert scene.loads(BOX, ["mesh.grading=true", "mesh.degree=2"]).mesh.grading == scene.GRADING[2] == 0.2
    assert scene.loads(BOX, ["mesh.grading=false"]).mesh.grading is None
    graded = scene.loads(BOX, ["mesh.grading=0.3", "mesh.target_error=0.01"])
    assert (graded.mesh.grading, graded.mesh.target_error) == (0.3, 0.01)
    assert scene.loads(graded.text) == graded  # written out and read back


@pytest.mark.parametrize("overrides, message", [
    (["mesh.grading=1.5"], "mesh.grading must be true, false or a grading exponent μ with 0 < μ < 1"),
    (["mesh.target_error=2"], "mesh.target_error must be a relative error between 0 and 1"),
    (["mesh.grading=true", "mesh.size=0", ], "mesh.size must be > 0"),
])
def test_bad_grading_and_target_values(overrides, message):
    with pytest.raises(SceneError, match=message):
        scene.loads(BOX, overrides)


def test_grading_needs_a_size_and_both_need_a_geometry():
    with pytest.raises(SceneError, match="mesh.grading needs mesh.size"):
        scene.load("partial-closure", ["mesh.grading=true"])
    for key in ("grading=true", "target_error=0.01"):
        with pytest.raises(SceneError, match=f"mesh.{key.split('=')[0]} needs a geometry to mesh .* is a fixed mesh"):
            scene.loads(BOX.replace("size = 0.2", 'file = "halves.vtu"'), [f"mesh.{key}"])


def test_singular_points_of_the_box():
    paper = sizing.box_singular_points(scene.load("partial-closure").geometry)
    expected = {(-1, -1), (-1, 0), (-1, 1), (-0.5, 0), (0.5, 0), (1, -1), (1, 0), (1, 1)}
    assert set(map(tuple, paper.tolist())) == expected  # tips, Σ's ends, clamped-free corners
    strip = sizing.box_singular_points(scene.load("strip-disbonds").geometry)  # clamped on the left only
    assert set(map(tuple, strip.tolist())) == {(0, -0.5), (0, 0.5), (0, 0), (8, 0), (1, 0), (2, 0), (3.5, 0),
                                                (4.5, 0), (6, 0), (7, 0)}


def _model_points(path):
    with gmsh_io.session() as gmsh:
        gmsh_io.open_file(gmsh, path)
        return set(map(tuple, sizing.model_singular_points(gmsh, gmsh_io.physical_groups(gmsh, str(path)))
                       .round(6).tolist()))


def test_singular_points_of_gmsh_geometries():
    corners = {(-1, -1), (1, -1), (1, 1), (-1, 1), (-1, 0), (1, 0)}
    scenes = scene.builtin_folder()
    # The arc's centre is a geometry point too, but on no curve: not singular.
    assert _model_points(scenes / "arc-bond.geo") == corners | {(-0.5, 0.151470), (0.5, 0.151470)}
    # The kink inside the crack is a re-entrant corner of the upper half.
    assert _model_points(scenes / "kinked-bond.geo") == corners | {(-0.4, 0.18), (0.4, 0.18), (0, 0.3)}


L_SHAPE = """
// An L-shaped lower half (re-entrant corner at (0, -0.5)) under a rectangular upper half; Σ is y = 0.
Point(1) = {-1, -1, 0}; Point(2) = {0, -1, 0}; Point(3) = {0, -0.5, 0}; Point(4) = {1, -0.5, 0};
Point(5) = {1, 0, 0}; Point(6) = {1, 1, 0}; Point(7) = {-1, 1, 0}; Point(8) = {-1, 0, 0};
Line(1) = {1, 2}; Line(2) = {2, 3}; Line(3) = {3, 4}; Line(4) = {4, 5}; Line(5) = {5, 8};
Line(6) = {8, 1}; Line(7) = {5, 6}; Line(8) = {6, 7}; Line(9) = {7, 8};
Curve Loop(1) = {1, 2, 3, 4, 5, 6}; Plane Surface(1) = {1};
Curve Loop(2) = {-5, 7, 8, 9}; Plane Surface(2) = {2};
Physical Surface("lower") = {1}; Physical Surface("upper") = {2};
Physical Curve("sigma") = {5}; Physical Curve("clamped") = {6, 9};
Physical Curve("free") = {1, 2, 3, 4, 7, 8};
"""


def test_a_reentrant_corner_is_singular_and_convex_corners_are_not(tmp_path):
    path = tmp_path / "l.geo"
    path.write_text(L_SHAPE)
    # (0, -0.5) re-entrant; (±1, 0) Σ meets the boundary; (-1, ±1) clamped meets free; (0, -1), (1, -0.5),
    # (1, 1) are convex corners between free sides.
    assert _model_points(path) == {(0, -0.5), (-1, 0), (1, 0), (-1, -1), (-1, 1)}


def test_graded_meshes_follow_the_size_field_and_their_halves_match():
    size = 0.05
    graded = scene.loads(BOX, [f"mesh.size={size}", "mesh.grading=true"])
    mesh = geometry.build(graded)  # two gmsh sessions, one per half: make_mesh checks that Σ matches
    points = sizing.box_singular_points(graded.geometry)
    length = 2.0
    for half in mesh.halves:
        corners = half.points[half.corners]
        centres = corners.mean(axis=1)
        longest = np.linalg.norm(corners - corners[:, [1, 2, 0]], axis=2).max(axis=1)
        distance = np.linalg.norm(centres[:, None, :] - points[None, :, :], axis=2).min(axis=1)
        wanted = sizing.graded_size(distance, size, 0.4, length)
        ratio = longest / wanted
        assert np.median(ratio) == pytest.approx(1.0, abs=0.25)  # gmsh follows the field ...
        assert ratio.max() < 2.0  # ... everywhere
    at_points = sizing.graded_size(0.0, size, 0.4, length)
    assert at_points < size / 10
    assert 0.5 * at_points < meshes.statistics(mesh.lower).h_min < 2.0 * at_points
    tips = mesh.sigma.points[mesh.sigma.tip]
    assert np.allclose(np.sort(tips[:, 0]), [-0.5, 0.5])


def test_graded_p2_meshes_of_curved_geometries_are_valid():
    """Tiny triangles at tips on a curved Σ (gmsh's default random perturbation folds them)."""
    mesh = geometry.build(scene.load("arc-bond", ["mesh.grading=true", "mesh.degree=2"]))
    assert mesh.degree == 2 and mesh.sigma.tip.sum() == 2
    assert meshes.statistics(mesh.upper).h_min < 1e-3
