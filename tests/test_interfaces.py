"""Several interfaces in the box: ``geometry.sigma = [y1, y2, ...]`` with one crack list per interface
(``geometry.cracks = [[[a, b], ...], ...]``), regions ``region1`` ... ``regionR`` with their own materials; the
one-interface forms and names stay as they were; bad input is refused in one line naming the key."""
from __future__ import annotations

import re

import numpy as np
import pytest

import h5py
from conftest import ddsolve, refused

from ddsolve.errors import DDSolveError, MeshError, SceneError, UsageError
from ddsolve.io import hdf5
from ddsolve.post import fracture
from ddsolve.post.result import Fracture
from ddsolve.mesh import geometry, stack
from ddsolve.parallel import launch
from ddsolve.mesh.mesh import (CRACK, CRACK_ABOVE, SIGMA, SIGMA_ABOVE, HalfMesh, Mesh, facing_above, make_mesh,
                               make_stack, region_half)
from ddsolve.problem import materials, scene
from ddsolve.solvers import checks, reference
from ddsolve.solvers import stacked as stacked_solver

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


@pytest.mark.parametrize("override, key", [
    ("mesh.sigma_vertices=21", "mesh.sigma_vertices"), ("mesh.grading=true", "mesh.grading"),
    ("mesh.target_error=0.1", "mesh.target_error"), ("mesh.file='strip.msh'", "mesh.file"),
    ("displacements.layer1.pin.point=[2.0, 2.0]", "displacements.layer1.pin.point")])
def test_what_several_interfaces_do_not_take_is_refused_naming_the_key(override, key):
    assert refusal(override).startswith(f"strip.toml: {key}: ")


#: What a structure of several interfaces is refused, in one line.
NOT_YET = ("geometry.sigma: 2 interfaces: a structure of several interfaces is meshed (ddsolve mesh) and solved by the "
           "monolithic reference (ddsolve reference) and the domain decomposition (ddsolve solve), not yet by sweeps, "
           "growth or adaptivity")


@pytest.mark.parametrize("before_work", [geometry.build, lambda source: geometry.generate_half(source, 1),
                                         checks.check_size])
def test_what_is_not_done_for_several_interfaces_is_refused_in_one_line(before_work):
    with pytest.raises(SceneError, match=f"^{re.escape(NOT_YET)}$"):
        before_work(strip())


def test_a_scene_of_several_interfaces_is_written_out_and_read_back():
    source = strip("geometry.cracks=[[], [[0.5, 1.5], [2.0, 3.0]]]")
    assert "sigma = [1.0, 2.0]" in source.text.replace("[ ", "[").replace(" ]", "]")
    again = scene.loads(source.text)
    assert again.geometry == source.geometry and again.regions == source.regions


@pytest.fixture(scope="module")
def stacked() -> Mesh:
    return stack.build_any(strip("geometry.cracks=[[[1.0, 2.0]], [[3.0, 4.0]]]"))


def test_the_regions_of_the_strip_bottom_to_top(stacked):
    assert [region.name for region in stacked.regions] == ["region1", "region2", "region3"]
    assert [region.side for region in stacked.regions] == [-1, 1, 1]
    for region, (y0, y1) in zip(stacked.regions, [(0.0, 1.0), (1.0, 2.0), (2.0, 3.0)]):
        assert (region.points[:, 1].min(), region.points[:, 1].max()) == (y0, y1)
    assert stacked.boundary_names() == ["bottom", "clamped", "left", "right", "top"]
    assert (stacked.lower, stacked.upper, stacked.sigma) == (*stacked.regions[:2], stacked.sigmas[0])


def test_each_interface_is_shared_by_its_two_regions_with_its_cracks(stacked):
    middle = stacked.regions[1]
    for line, height, below, above in [(stacked.sigmas[0], 1.0, stacked.regions[0].sigma, middle.sigma),
                                       (stacked.sigmas[1], 2.0, middle.sigma_above, stacked.regions[2].sigma)]:
        assert np.all(line.points[:, 1] == height) and np.all(np.diff(line.points[:, 0]) > 0)
        np.testing.assert_array_equal(line.points, stacked.regions[0].points[below] if height == 1.0
                                      else middle.points[below])
        upper = middle if height == 1.0 else stacked.regions[2]
        np.testing.assert_array_equal(line.points, upper.points[above])
        np.testing.assert_allclose(line.normals, np.tile([0.0, 1.0], (len(line.points), 1)), atol=1e-15)
    first, second = stacked.sigmas
    assert first.points[first.crack, 0].min() > 1.0 and first.points[first.crack, 0].max() < 2.0
    assert list(first.points[first.tip, 0]) == [1.0, 2.0]
    assert list(second.points[second.tip, 0]) == [3.0]  # an edge crack: its end on the free side is a crack node
    assert second.crack[-1] and second.points[-1, 0] == 4.0
    assert first.clamped[0] and second.clamped[0] and not first.clamped[-1]


def test_one_interface_meshes_as_before():
    source = scene.load("partial-closure", ["mesh.sigma_vertices=11", "mesh.boundary_vertices=24"])
    old, new = geometry.build(source), stack.build_any(source)
    assert new.above == () and new.regions == (new.lower, new.upper) and new.sigmas == (new.sigma,)
    np.testing.assert_array_equal(old.sigma.points, new.sigma.points)
    assert [half.name for half in new.regions] == ["lower", "upper"]


def test_p2_regions_share_their_sigma_nodes_midpoints_included():
    stacked = stack.build_any(strip("mesh.degree=2", "geometry.cracks=[[], [[0.5, 1.5]]]"))
    middle, top = stacked.regions[1:]
    assert stacked.degree == 2 and len(stacked.sigmas[1].points) == 2 * 16 + 1
    np.testing.assert_allclose(middle.points[middle.sigma_above], top.points[top.sigma], rtol=0, atol=1e-12)
    assert list(stacked.sigmas[1].points[stacked.sigmas[1].tip, 0]) == [0.5, 1.5]


def test_a_crack_on_an_upper_interface_may_not_reach_the_clamped_side():
    with pytest.raises(MeshError, match="a crack reaches the clamped boundary at \\(0, 2\\)"):
        stack.build_any(strip("geometry.cracks=[[], [[0.0, 1.0]]]"))


@pytest.mark.mpi
def test_the_mesh_command_prints_every_region_and_interface(tmp_path):
    path = tmp_path / "strip.toml"
    path.write_text(STRIP)
    lines = ddsolve("mesh", str(path)).stdout.splitlines()
    assert [line.split()[0] for line in lines[1:4]] == ["region1", "region2", "region3"]
    assert lines[4].startswith("Σ vertices 17, 17 (per interface, bottom to top)")
    assert lines[5].startswith("2 layers on 3 regions: 6 blocks")  # solved on 1, 2, 3, 6, 12 ranks: test_stack_dd


@pytest.mark.mpi
def test_the_reference_command_reports_g_at_every_tip_of_every_interface(tmp_path):
    path, output = tmp_path / "strip.toml", tmp_path / "strip.h5"
    path.write_text(STRIP)
    lines = ddsolve("reference", str(path), "-o", str(output), "--set", "loads.layer1.top.y=-0.05").stdout.splitlines()
    assert re.match(r"reference: 2 interfaces, \d+ active-set steps, energy -0\.0624312133\d*, ", lines[0])
    tips = [line for line in lines if line.startswith("G at tip")]
    assert [line.split(":")[0] for line in tips] == [
        "G at tip (1, 1) of crack 0 on interface 1", "G at tip (2, 1) of crack 0 on interface 1",
        "G at tip (2, 2) of crack 1 on interface 2", "G at tip (3, 2) of crack 1 on interface 2"]
    assert "on crack 0 on interface 1" in lines[-1] and "on crack 1 on interface 2" in lines[-1]
    with h5py.File(output) as f:
        assert list(f["fracture/interface"][()]) == [1, 1, 2, 2] and list(f["fracture/crack"][()]) == [0, 0, 1, 1]
        assert f.attrs["interfaces"] == 2 and f.attrs["converged"]
        assert sorted(f["solution"]) == ["u1", "u2", "u3", "v1", "v2", "v3"]


def test_several_interfaces_number_their_cracks_bottom_to_top_and_one_interface_files_keep_their_shape():
    def tips(count: int, zones: int) -> Fracture:
        return Fracture(np.zeros((count, 2)), np.zeros((count, 2)), np.arange(count) // 2, np.ones(count),
                        np.ones(count), np.ones(count), np.arange(1.0, count + 1), np.zeros(count),
                        np.zeros((zones, 2)), np.zeros(zones, dtype=np.int64))
    joined = fracture.of_interfaces([tips(4, 1), tips(0, 0), tips(2, 1)], [2, 0, 1])
    assert list(joined.interface) == [1, 1, 1, 1, 3, 3] and list(joined.crack) == [0, 0, 1, 1, 2, 2]
    assert list(joined.zone_crack) == [0, 2] and list(joined.crack_interface) == [1, 1, 3]
    assert list(joined.G) == [1.0, 2.0, 3.0, 4.0, 1.0, 2.0]
    assert "fracture/interface" in hdf5.fracture_datasets(joined)
    assert not {"fracture/interface", "fracture/crack_interface"} & set(hdf5.fracture_datasets(tips(2, 0)))
    assert tips(2, 0).lines()[0].startswith("G at tip (0, 0) of crack 0: ")
    assert joined.lines()[4].startswith("G at tip (0, 0) of crack 2 on interface 3: ")


# --- the monolithic reference of several interfaces -------------------------------------------------------------
#: The strip of equal materials with fixed θ radii (so that G at a tip is the same integral in any structure).
EQUAL = STRIP.replace("[materials.layer1.region2]\nE = 2.0\n", "") + "[fracture]\ninner = 0.2\nouter = 0.4\n"


def equal(layers: int) -> str:
    """:data:`EQUAL` of one layer, or of two loaded alike: equal layers then move together, so that gluing them
    on one Σ more changes nothing."""
    if layers == 1:
        return EQUAL.replace("[materials.layer2]\nE = 1.0\nnu = 0.3\n", "").replace(
            "[geometry]\n", "[geometry]\nlayers = 1\n")
    return EQUAL + "[loads.layer2.right]\nx = 0.1\n"


def test_six_blocks_go_on_1_2_3_6_or_12_ranks():
    assert [size for size in range(1, 25) if launch.supported(size, 6)] == [1, 2, 3, 6, 12, 18, 24]
    assert [launch.leader(block, 3, 6) for block in range(6)] == [0, 1, 2, 0, 1, 2]  # rank r: region r+1's layers
    assert [launch.leader(block, 2, 6) for block in range(6)] == [0, 1, 0, 1, 0, 1]
    assert [launch.leader(block, 12, 6) for block in range(6)] == [0, 2, 4, 6, 8, 10]  # two ranks per block
    with pytest.raises(UsageError, match=r"^-n 4: unsupported number of ranks: use 1, 2, 3 or a multiple of 6$"):
        checks.check_ranks(4, 6)


def test_the_blocks_are_the_layers_on_every_region():
    assert stacked_solver.block_names(2, 3) == [("u1", "layer1", 0), ("u2", "layer1", 1), ("u3", "layer1", 2),
                                                ("v1", "layer2", 0), ("v2", "layer2", 1), ("v3", "layer2", 2)]
    assert stacked_solver.block_names(1, 3) == [("u1", "layer1", 0), ("u2", "layer1", 1), ("u3", "layer1", 2)]


def test_each_interface_glues_its_two_regions_and_each_region_its_layers_on_both_its_sigma_lines(stacked):
    source = strip("geometry.cracks=[[[1.0, 2.0]], [[3.0, 4.0]]]")
    systems, joints, seen = stacked_solver.assemble(source, stacked)
    assert [joint.blocks for joint in joints] == [(0, 1, 3, 4), (1, 2, 4, 5)]  # u⁻ u⁺ v⁻ v⁺ of each interface
    assert [list(joint.interface.slices) for joint in joints] == [["mu_c", "mu_g", "mu_minus", "mu_plus"]] * 2
    middle = systems[1]
    np.testing.assert_array_equal(joints[0].dofs[1], middle.trace_dofs)  # u2's trace on Σ₁ is its assembled trace
    below, above = (stacked.regions[1].points[joint.dofs[index][::2] // 2]
                    for joint, index in zip(joints, (1, 0)))
    assert np.all(below[:, 1] == 1.0) and np.all(above[:, 1] == 2.0)  # ... and it is glued on Σ₂ as well
    assert [part.material("layer1", "upper") for part, _ in seen] == [
        source.material("layer1", "region2"), source.material("layer1", "region3")]


@pytest.mark.parametrize("overrides, motion", [
    (["geometry.clamped=[]"], "the structure can translate in x"),
    (["geometry.clamped=[\"bottom\"]", "geometry.cracks=[[[0.0, 4.0]], []]"],
     "blocks u2, u3, v2, v3 can translate and rotate freely relative to the rest")])
def test_a_structure_of_several_interfaces_that_can_move_is_refused_naming_the_motion(overrides, motion):
    source = strip(*overrides)
    with pytest.raises(SceneError, match=f"^{re.escape(motion)}: add a support "):
        stacked_solver.assemble(source, stack.build_any(source))


def merged(base: HalfMesh, other: HalfMesh, base_nodes: np.ndarray, other_nodes: np.ndarray) -> HalfMesh:
    """``base`` and ``other`` as one half, ``other``'s nodes ``other_nodes`` being ``base``'s ``base_nodes``; its Σ
    (and cracks) are ``base``'s."""
    number = np.full(len(other.points), -1, dtype=np.int64)
    number[other_nodes] = base_nodes
    own = number < 0
    number[own] = len(base.points) + np.arange(own.sum())
    inner = (SIGMA_ABOVE, CRACK_ABOVE)
    names = (set(base.boundaries) | set(other.boundaries)) - {*inner, SIGMA, CRACK}
    boundaries = {name: np.concatenate([base.edges(name), number[other.edges(name)]]) for name in names}
    boundaries |= {name: edges for name, edges in base.boundaries.items() if name in (SIGMA, CRACK)}
    return HalfMesh(np.concatenate([base.points, other.points[own]]), np.concatenate([base.cells, number[other.cells]]),
                    base.side, base.sigma, {name: edges for name, edges in boundaries.items() if len(edges)})


def two_regions(three: Mesh, cracked: int) -> Mesh:
    """The three regions' mesh as a mesh of one interface, ``cracked`` (0 or 1): the other Σ's two regions made one
    half with the same nodes and triangles."""
    bottom, middle, top = three.regions
    if cracked == 0:
        return make_mesh(bottom, merged(middle, top, middle.sigma_above, top.sigma), "merged")
    return make_mesh(merged(facing_above(middle), bottom, middle.sigma, bottom.sigma), top, "merged")


def one_interface(cracked: int, layers: int, *overrides: str) -> scene.Scene:
    text = equal(layers).replace("sigma = [1.0, 2.0]", f"sigma = {1.0 + cracked}").replace(
        "cracks = [[[1.0, 2.0]], [[2.0, 3.0]]]", "cracks = [[1.0, 2.0]]")
    return scene.loads(text, list(overrides))


@pytest.mark.solve
@pytest.mark.parametrize("cracked", [0, 1])
@pytest.mark.parametrize("layers", [1, 2])
@pytest.mark.parametrize("closing, degree", [(False, 1), (True, 1), (True, 2)], ids=["open", "closing", "closing P2"])
def test_an_interface_without_crack_between_equal_regions_is_the_structure_of_one_interface(cracked, layers, closing,
                                                                                              degree):
    """Exact: the two-region mesh has the three regions' nodes and triangles, the uncracked Σ's regions made one."""
    load = [f"mesh.degree={degree}"]
    load += [f"loads.layer{layer}.top.y=-0.05" for layer in range(1, layers + 1)] if closing else []
    cracks = "[[[1.0, 2.0]], []]" if cracked == 0 else "[[], [[1.0, 2.0]]]"
    three = scene.loads(equal(layers), [f"geometry.cracks={cracks}", *load])
    mesh = stack.build_any(three)
    several = stacked_solver.solve_stack(three, mesh)
    one = reference.solve_monolithic(one_interface(cracked, layers, *load), two_regions(mesh, cracked))
    assert several.converged and one.converged
    assert several.energy == pytest.approx(one.attrs["energy"], rel=1e-10, abs=0.0)
    np.testing.assert_allclose(several.interfaces[cracked].fracture.G, one.fracture.G, rtol=1e-8, atol=0.0)
    assert several.interfaces[1 - cracked].fracture.G.size == 0  # no tips on the uncracked interface
    if closing:
        assert one.attrs["closed_vertices"] > 0 and several.interfaces[cracked].multipliers["mu_c"].max() > 0


def mirrored(mesh: Mesh, height: float) -> Mesh:
    """The structure reflected about y = ``height`` / 2, the same nodes and triangles: its top region the bottom
    one, a middle region's Σ below and above swapped."""
    count = len(mesh.regions)
    swapped = {SIGMA: SIGMA_ABOVE, CRACK: CRACK_ABOVE, SIGMA_ABOVE: SIGMA, CRACK_ABOVE: CRACK}
    regions = []
    for index, region in enumerate(reversed(mesh.regions)):
        rename = {"top": "bottom", "bottom": "top", **(swapped if 0 < index < count - 1 else {})}
        regions.append(region_half(region.points * [1.0, -1.0] + [0.0, height], region.cells, f"region{index + 1}",
                                   index == 0, {rename.get(name, name): edges for name, edges in
                                                region.boundaries.items()}, "mirrored"))
    return make_stack(tuple(regions), "mirrored")


@pytest.mark.solve
@pytest.mark.parametrize("closing", [False, True], ids=["open", "closing"])
def test_a_crack_on_interface_2_of_a_symmetric_strip_mirrors_the_same_crack_on_interface_1(closing):
    """Exact: the second structure is the first reflected, node for node."""
    load = ["loads.layer1.top.y=-0.05", "loads.layer1.bottom.y=0.05"] if closing else []
    lower = scene.loads(EQUAL, ["geometry.cracks=[[[1.0, 2.0]], []]", *load])
    upper = scene.loads(EQUAL, ["geometry.cracks=[[], [[1.0, 2.0]]]", *load])
    mesh = stack.build_any(lower)
    first, second = stacked_solver.solve_stack(lower, mesh), stacked_solver.solve_stack(upper, mirrored(mesh, 3.0))
    assert first.converged and second.converged
    assert first.energy == pytest.approx(second.energy, rel=1e-10, abs=0.0)
    G = first.interfaces[0].fracture.G
    assert len(G) == 2 and (closing or np.all(G > 0))  # closing: the faces touch, G is near 0 (± its noise)
    np.testing.assert_allclose(second.interfaces[1].fracture.G, G, rtol=1e-8, atol=0.0)
    assert list(second.fracture.interface) == [2, 2] and list(first.fracture.interface) == [1, 1]
    if closing:
        assert first.interfaces[0].multipliers["mu_c"].max() > 0


@pytest.mark.solve
def test_the_same_crack_on_either_interface_of_a_symmetric_strip_has_the_same_g():
    """G at every tip of both interfaces at once; the regions' own meshes are not mirror images, so the two agree
    as h falls."""
    differences = []
    for size in (0.25, 0.125):
        source = scene.loads(EQUAL.replace("[fracture]\ninner = 0.2\nouter = 0.4\n", ""),
                             ["geometry.cracks=[[[1.0, 2.0]], [[1.0, 2.0]]]", f"mesh.size={size}"])
        solved = stacked_solver.solve_stack(source, stack.build_any(source))
        assert solved.converged
        first, second = (part.fracture.G for part in solved.interfaces)
        assert len(first) == len(second) == 2 and np.all(first > 0)
        differences.append(np.abs(first - second).max() / first.max())
    assert differences[1] < 0.05 and differences[1] < differences[0] / 4
