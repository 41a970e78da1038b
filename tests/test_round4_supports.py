"""Point supports (issue 40, first use): a point of a box scene (``point = [x, y]``) and gmsh physical points
in ``[displacements.LAYER.NAME]``; an ENF on point supports against corrected beam theory; G's noise level
(a closed tip's G reported as 0, G_I, G_II ≥ 0 summing to G)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from conftest import ROOT, ddsolve
from ddsolve.dd import kernels
from ddsolve.errors import SceneError
from ddsolve.fem import supports
from ddsolve.io import hdf5
from ddsolve.mesh import geometry
from ddsolve.mesh.gmsh_io import session, write_msh
from ddsolve.post.result import Fracture
from ddsolve.problem import scene
from ddsolve.solvers import reference
from experiments.hostile4_supports import STRIP as STRIP_SCENE

#: The strip of the point supports' examples, with a point support of layer 1 at {x}, {y}.
STRIP = STRIP_SCENE + """[displacements.layer1.spot]
point = [{x}, {y}]
y = 0.0
"""

#: Points on the box's lines (sides, Σ, corners, the crack tip, a crack face) and off the layer.
ON_LINES = st.one_of(
    st.tuples(st.sampled_from([0.25, 1.5, 2.75, 3.5]), st.sampled_from([-0.5, 0.0, 0.5])),  # bottom, Σ, top
    st.tuples(st.sampled_from([0.0, 4.0]), st.sampled_from([-0.5, -0.25, 0.25, 0.5])),  # the ends
    st.just((1.0, 0.0)), st.just((0.5, 0.0)), st.just((0.0, 0.0)))  # the tip, a crack face, the crack's mouth
OFF = st.one_of(st.tuples(st.sampled_from([1.3, 2.2]), st.sampled_from([-0.3, 0.2])),  # inside a layer
                st.tuples(st.sampled_from([-1.0, 4.5]), st.sampled_from([-0.5, 0.0])),  # outside the box
                st.tuples(st.sampled_from([1.0, 3.0]), st.sampled_from([0.75, -2.0])))


def strip(x: float, y: float, *items: str) -> scene.Scene:
    return scene.loads(STRIP.format(x=x, y=y), list(items))


@settings(derandomize=True, max_examples=10, deadline=None)
@given(ON_LINES)
def test_a_point_on_a_side_or_on_sigma_becomes_a_vertex_that_is_held(point):
    """The mesher puts a vertex at the point; the support prescribes that vertex alone, in every half whose
    boundary or Σ holds it, and the structure is supported."""
    source = strip(*point)
    mesh = geometry.build(source)
    table = supports.check(source, mesh)
    kernels.of_scene(source, mesh, table)
    displacement = source.displacements[("layer1", "spot")]
    found = [half.points[supports.displaced_nodes(half, displacement)] for half in mesh.halves]
    assert sum(len(f) for f in found) >= 1 and all(len(f) <= 1 for f in found)
    for where in found:
        assert np.allclose(where, point, atol=1e-12)
    if point[1] == 0.0:  # on Σ: both halves
        assert all(len(f) == 1 for f in found)


@settings(derandomize=True, max_examples=8, deadline=None)
@given(OFF)
def test_a_point_off_the_boundary_is_refused_naming_the_key(point):
    with pytest.raises(SceneError, match=r"displacements\.layer1\.spot\.point = .* (outside the box|inside a layer)"):
        strip(*point)


def test_a_point_has_no_normal_and_needs_a_name_of_its_own():
    with pytest.raises(SceneError, match=r"displacements\.layer1\.spot\.normal: a point has no normal"):
        strip(2.0, -0.5, "displacements.layer1.spot.normal=0.0")
    text = STRIP.format(x=2.0, y=-0.5).replace("[displacements.layer1.spot]", "[displacements.layer1.bottom]")
    source = scene.loads(text)
    with pytest.raises(SceneError, match=r"displacements\.layer1\.bottom: 'bottom' names a boundary"):
        supports.check(source, geometry.build(source))


def test_a_point_near_a_corner_or_a_tip_is_snapped_onto_it():
    """Within the meshing tolerance of a corner, Σ's end or a crack tip the point is that vertex."""
    assert strip(1.0 + 1e-10, 1e-10).displacements[("layer1", "spot")].point == (1.0, 0.0)
    assert strip(4.0 - 1e-10, -0.5).displacements[("layer1", "spot")].point == (4.0, -0.5)


def enf_scene(tmp_path: Path, mesh_file: str | None = None, *items: str) -> scene.Scene:
    folder = ROOT / "docs"
    text = (folder / "enf-points.toml").read_text()
    (tmp_path / "enf-points.geo").write_text((folder / "enf-points.geo").read_text())
    if mesh_file is not None:
        text = text.replace('file = "enf-points.geo"\nsize = 0.25\n', f'file = "{mesh_file}"\n')
    path = tmp_path / "enf.toml"
    path.write_text(text)
    return scene.Scene.load(path, list(items))


def test_physical_points_of_a_geo_and_of_msh_files_hold_the_enf(tmp_path):
    """enf-points.geo's physical points pin and roller are vertices; written as MSH 4.1 and as MSH 2.2 they
    come back as named points, and the ENF is supported by them alone (the upper arm floating)."""
    source = enf_scene(tmp_path, None, "mesh.size=1.0", "mesh.degree=1")
    mesh = geometry.build(source)
    assert sorted(mesh.named_points) == ["pin", "roller"]
    assert np.allclose(mesh.named_points["pin"], [[0.0, -1.0]]) and np.allclose(mesh.named_points["roller"],
                                                                                  [[40.0, -1.0]])
    write_msh(mesh, tmp_path / "enf41.msh")
    with session() as gmsh:
        gmsh.open(str(tmp_path / "enf41.msh"))
        gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
        gmsh.write(str(tmp_path / "enf22.msh"))
    for name in ("enf41.msh", "enf22.msh"):
        read = enf_scene(tmp_path, name, "mesh.degree=1")
        again = geometry.build(read)
        assert {key: value.tolist() for key, value in again.named_points.items()} == \
               {key: value.tolist() for key, value in mesh.named_points.items()}
        kernels.of_scene(read, again, supports.check(read, again))
        for half, count in zip(again.halves, (1, 0)):  # the pin is the lower arm's corner
            assert len(supports.displaced_nodes(half, read.displacements[("layer1", "pin")])) == count


def test_a_physical_point_with_a_normal_or_an_unknown_name_is_refused(tmp_path):
    source = enf_scene(tmp_path, None, "mesh.size=1.0", "mesh.degree=1", "displacements.layer1.roller={normal = 0.0}")
    with pytest.raises(SceneError, match=r"displacements\.layer1\.roller\.normal: 'roller' is a point, which has no normal"):
        supports.check(source, geometry.build(source))
    source = enf_scene(tmp_path, None, "mesh.size=1.0", "mesh.degree=1", "displacements.layer1.pln.y=0.0")
    with pytest.raises(SceneError, match=r"displacements\.layer1\.pln: no boundary named 'pln' .*points: pin, roller"):
        supports.check(source, geometry.build(source))


#: Corrected beam theory of the ENF (ASTM D7905 with the isotropic crack-tip correction χ_II = 0.206 h, Bao,
#: Ho, Suo and Fan 1992): G = 9 P² (a + χ_II h)² / (16 (E₁′ + E₂′) h³) per unit width, E′ = E/(1 − ν²)
#: (plane strain), P summed over the layers (docs/delamination.md).
def enf_beam_theory(P: float = 1e-3, a: float = 10.0, h: float = 1.0, E: float = 200.0, nu: float = 0.28) -> float:
    return 9.0 * P * P * (a + 0.206 * h) ** 2 / (16.0 * 2.0 * E / (1.0 - nu * nu) * h ** 3)


@pytest.mark.mpi
def test_enf_on_point_supports_matches_corrected_beam_theory(tmp_path):
    """docs/enf-points.toml (pin and roller physical points, P2, 0.02 at the tip) on 2 ranks at mesh.size
    = 0.5: G within 0.2 % of corrected beam theory (measured −0.045 %; 2 % asked), mode II, G_I + G_II = G."""
    output = tmp_path / "enf.h5"
    ddsolve("solve", str(ROOT / "docs" / "enf-points.toml"), "--set", "mesh.size=0.5", "-o", str(output), ranks=2)
    result = hdf5.read(output)
    G = result.fracture.G[0]
    assert G == pytest.approx(enf_beam_theory(), rel=2e-3)
    assert result.fracture.noise[0] < 1e-3 * G
    shown = result.fracture.reported()
    assert shown["G"][0] == G and shown["G_I"][0] >= 0.0 and shown["G_II"][0] >= 0.0
    assert shown["G_I"][0] + shown["G_II"][0] == pytest.approx(G, rel=1e-12)
    assert shown["G_II"][0] > 0.99 * G
    assert result.reactions["layer1"]["pin"][1] + result.reactions["layer2"]["pin"][1] == pytest.approx(5e-4, rel=2e-3)


@pytest.mark.solve
def test_a_closed_tip_is_reported_as_zero_with_its_noise_level():
    """Example 1 (P = 13): the closed tip's G lies within its noise and is printed as 0; the open tip's is
    above it; G_I, G_II ≥ 0 and their sum is G at the open tip."""
    source = scene.load("partial-closure", ["mesh.sigma_vertices=13", "mesh.boundary_vertices=32"])
    result = reference.solve_monolithic(source, geometry.build(source))
    found = result.fracture
    assert np.all(np.isfinite(found.noise)) and np.all(found.noise >= 0.0)
    assert found.within_noise().tolist() == [False, True] and abs(found.G[1]) <= found.noise[1]
    shown = found.reported()
    assert shown["G"].tolist() == [found.G[0], 0.0]
    assert "0 (G ≈ 0: computed" in found.lines()[1] and "within the discretization noise" in found.lines()[1]
    assert "ψ undefined" in found.lines()[1] and f"± {found.noise[0]:.2g}" in found.lines()[0]
    assert np.all(shown["G_I"] >= 0.0) and np.all(shown["G_II"] >= 0.0) and shown["G_I"][1] == shown["G_II"][1] == 0
    assert shown["G_I"][0] + shown["G_II"][0] == pytest.approx(found.G[0], rel=1e-12)
    assert found.G_I[0] > found.G[0]  # as computed, the split overshoots G by 4.7 % on this mesh


SPLITS = st.tuples(st.floats(-1e-9, 1e-6), st.floats(0.0, 1e-8), st.floats(-0.1, 1.1), st.floats(-0.03, 0.03))


@settings(derandomize=True, max_examples=60, deadline=None)
@given(st.lists(SPLITS, min_size=1, max_size=4))
def test_the_split_is_non_negative_and_sums_to_g(tips):
    """For any G, noise and split (a mode I share and a drift of up to 3 %), as reported: G is 0 within its noise
    and kept above it; G_I, G_II ≥ 0, summing to G to rounding where G is not 0, both 0 where it is."""
    G, noise, share, drift = (np.array(column, dtype=float) for column in zip(*tips))
    count = len(G)
    out = Fracture(points=np.zeros((count, 2)), directions=np.zeros((count, 2)), crack=np.zeros(count, dtype=int),
                   inner=np.ones(count), outer=np.ones(count), spacing=np.ones(count), G=G, contact=np.zeros(count),
                   zones=np.zeros((0, 2)), zone_crack=np.zeros(0, dtype=int), G_I=share * G * (1 + drift),
                   G_II=(1 - share) * G * (1 + drift), noise=noise)
    shown = out.reported()
    zero = shown["G"] == 0.0
    assert np.all(shown["G_I"] >= 0.0) and np.all(shown["G_II"] >= 0.0)
    assert np.allclose((shown["G_I"] + shown["G_II"])[~zero], G[~zero], rtol=1e-12, atol=0.0)
    assert np.all(shown["G_I"][zero] == 0.0) and np.all(shown["G_II"][zero] == 0.0)
    assert np.all(G[zero] <= np.maximum(noise[zero], 1e-6 * np.abs(G).max()))
    assert np.all(shown["G"][~zero] == G[~zero])
