"""A material per region: ``[materials.LAYER.lower]`` and ``[materials.LAYER.upper]``, read, checked, and used
by every block of the region (assembly, thermal loads, fields, G; no mode split between different laws)."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import SMALL, ddsolve, solved_reference

from ddsolve.errors import SceneError
from ddsolve.fem import assembly
from ddsolve.mesh import geometry
from ddsolve.post import analysis, fracture
from ddsolve.problem import materials, scene

#: Layer 1 soft below Σ, layer 2 orthotropic at 30° above it: every block's law its own.
DISSIMILAR = ["materials.layer1.lower.E=20.0", "materials.layer2.upper.E1=140.0", "materials.layer2.upper.E2=10.0",
              "materials.layer2.upper.G12=5.0", "materials.layer2.upper.nu12=0.3",
              "materials.layer2.upper.angle=30.0"]


#: SMALL as --set items.
SMALL_SET = [item for item in SMALL if item != "--set"]


def refusal(*overrides: str) -> str:
    with pytest.raises(SceneError) as caught:
        scene.load("partial-closure", list(overrides))
    message = str(caught.value)
    assert "\n" not in message
    return message


def test_a_region_overrides_the_keys_it_gives_and_keeps_the_others():
    source = scene.load("partial-closure", ["materials.layer1.alpha=1e-5", "materials.layer1.upper.E=70.0"])
    assert source.material("layer1", "upper") == materials.Isotropic(E=70.0, nu=0.28, alpha=1e-5)
    assert source.material("layer1", "lower") == source.materials["layer1"] == materials.Isotropic(200.0, 0.28, 1e-5)
    assert source.material_key("layer1", "upper") == "materials.layer1.upper"
    assert source.material_key("layer1", "lower") == "materials.layer1"
    assert source.dissimilar_layers() == ["layer1"]
    fibres = scene.load("orthotropic-plate", ["materials.layer1.lower.angle=90.0"])
    assert fibres.material("layer1", "lower") == dataclasses.replace(fibres.materials["layer1"], angle=90.0)


def test_a_region_of_another_kind_is_a_whole_material():
    source = scene.load("partial-closure", DISSIMILAR[1:])
    assert source.material("layer2", "upper") == materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3,
                                                                     angle=30.0)
    message = refusal("materials.layer2.upper.E1=140.0")
    assert message.endswith("materials.layer2.upper: names keys of an orthotropic material, not the layer's kind, "
                            "so it must be a whole material: missing E2, G12, nu12")
    assert "materials.layer1.lower: names keys of a matrix material" in refusal("materials.layer1.lower.Dzz=[1, 2, 3]")
    whole = scene.load("partial-closure", ["materials.layer1.upper.D=[[300, 100, 0], [100, 300, 0], [0, 0, 100]]"])
    assert isinstance(whole.material("layer1", "upper"), materials.Anisotropic)


@pytest.mark.parametrize("overrides, fragment", [
    (["materials.layer1.middle.E=3.0"], "materials.layer1.middle: no region of that name (the regions of Ω, bottom "
                                        "to top: lower, upper)"),
    (["materials.layer1.upper.lower.E=3.0"], "materials.layer1.upper.lower: a region's table holds a material's keys"),
    (["materials.layer1.upper.alpha1=1e-5"], "unknown key materials.layer1.upper.alpha1"),
    (["materials.layer1.upper=3"], "materials.layer1.upper must be a table"),
    (["materials.model={upper = 3}"], "materials.model must be"),
    (["materials.layer1.E={upper = 20.0}"], "materials.layer1.E must be"),
    (["materials.layer2.upper.nu=0.6"], "materials.layer2.upper.nu must be in (-1, 0.5)"),
    (["materials.layer1.upper.nu=0.4999999999999"], "materials.layer1.upper"),
])
def test_bad_regions_are_refused_naming_the_key(overrides, fragment):
    assert fragment in refusal(*overrides)


def test_a_regions_stiffness_out_of_range_is_refused_naming_its_key():
    source = scene.load("partial-closure", [*SMALL_SET, "materials.layer1.upper.E=1e300"])
    with pytest.raises(SceneError, match=r"^materials\.layer1\.upper\.E: the elastic matrix has entries of"):
        assembly.check_range(source, geometry.build(source))


def test_a_heated_layer_needs_an_expansion_in_some_region():
    heated = scene.load("partial-closure", ["temperature.layer1=50.0", "materials.layer1.upper.alpha=1e-5"])
    assert heated.material("layer1", "lower").alpha == 0.0 and heated.material("layer1", "upper").alpha == 1e-5
    assert "temperature.layer1: materials.layer1 has no expansion coefficient" in refusal("temperature.layer1=50.0")


def test_a_mode_dependent_law_needs_regions_of_equal_stiffness():
    law = ["fracture.law=hutchinson-suo", "fracture.G_Ic=1e-6", "fracture.lambda=0.3"]
    assert "fracture.law = hutchinson-suo needs G's split into modes I and II, which is not defined between the " \
           "different materials of the regions of materials.layer1" in refusal(*law, DISSIMILAR[0])
    expanding = scene.load("partial-closure", [*law, "materials.layer1.upper.alpha=1e-5"])  # ε = 0: split defined
    assert expanding.dissimilar_layers() == ["layer1"] and expanding.dissimilar_layers(thermal=False) == []
    assert fracture.split_note(expanding) is None
    note = fracture.split_note(scene.load("partial-closure", DISSIMILAR))
    assert note.startswith("G is not split into modes I and II: layer1 and layer2 have different elastic laws")


def test_the_scene_text_writes_the_regions_whole_and_reads_back_the_same():
    source = scene.load("partial-closure", ["materials.layer1.alpha=1e-5", *DISSIMILAR])
    assert "[materials.layer1.lower]\nE = 20.0\nnu = 0.28\nalpha = 1e-05\n" in source.text
    again = scene.loads(source.text)
    assert again.regions == source.regions and again.materials == source.materials


def systems(source):
    return assembly.block_systems(source, geometry.build(source))


def same_systems(first, second) -> bool:
    return all(np.array_equal(getattr(a, name), getattr(b, name)) for a, b in zip(first, second)
               for name in ("data", "indices", "indptr", "rhs"))


def test_a_region_with_the_layers_own_values_changes_nothing():
    base = scene.load("partial-closure", [*SMALL_SET, "materials.layer1.alpha=1e-5", "temperature.layer1=40.0"])
    same = base.with_(["materials.layer1.upper.E=200.0", "materials.layer1.lower.nu=0.28",
                       "materials.layer2.upper.E=112.0"])
    assert same.regions and same_systems(systems(base), systems(same))


def test_the_regions_swap_with_the_layer_default():
    """Layer 1 = A with B below Σ is layer 1 = B with A above it, block by block, bit for bit."""
    first = scene.load("partial-closure", [*SMALL_SET, "materials.layer1.lower.E=20.0",
                                           "materials.layer1.lower.nu=0.3"])
    second = scene.load("partial-closure", [*SMALL_SET, "materials.layer1.E=20.0", "materials.layer1.nu=0.3",
                                            "materials.layer1.upper.E=200.0", "materials.layer1.upper.nu=0.28"])
    assert same_systems(systems(first), systems(second))
    assert not same_systems(systems(first), systems(scene.load("partial-closure", SMALL_SET)))


@pytest.mark.solve
def test_dissimilar_regions_report_g_without_its_split():
    from ddsolve.solvers import reference

    source = scene.load("partial-closure", [*SMALL_SET, *DISSIMILAR])
    result = reference.solve_monolithic(source, geometry.build(source))
    assert np.all(np.isfinite(result.fracture.G)) and result.fracture.G[0] > 0
    assert np.all(np.isnan(result.fracture.G_I)) and np.all(np.isnan(result.fracture.phase))
    fields, laws = analysis.cell_fields(result), analysis.elasticities(result)  # each block with its own law
    assert not np.array_equal(laws["u_minus"][0], laws["u_plus"][0])
    for name, cell_fields in fields.items():
        half, u = result.half(name), result.solution[name]
        area, _ = assembly.cell_strains(half.points, half.cells, u)
        energy = assembly.energy(half.points, half.cells, laws[name][0], u)
        assert np.sum(cell_fields.energy_density * area) == pytest.approx(0.5 * energy, rel=1e-12)


@pytest.mark.solve
def test_a_bimaterial_dcb_against_beam_theory():
    """Moment-loaded, the upper arm 10× stiffer: G = M²/2 Σ 1/(E′I), each arm its own (exact for a/h ≥ 3)."""
    from experiments import regions

    row = regions.dcb(6.0, 0.25)
    assert abs(row["error"]) < 0.02 and row["opening"] > 0 and 0.0 < row["G_I"] <= row["G"]
    kappa = 3.0 - 4.0 * 0.28  # the upper arm, material 1 of the tip, 10× stiffer: ε < 0
    assert row["epsilon"] == pytest.approx(math.log((kappa / 10.0 + 1.0) / (kappa + 0.1)) / (2.0 * math.pi), rel=1e-9)


@pytest.mark.solve
def test_a_thermal_bilayer_bends_as_timoshenkos_bimetal():
    from experiments import regions

    row = regions.bimetal(0.25)
    assert row["curvature"] < 0 and abs(row["error"]) < 0.01  # the upper strip expands more: Σ arches up


@pytest.mark.mpi
def test_dd_equals_the_reference_between_different_materials(tmp_path):
    options = [*SMALL, *(part for item in DISSIMILAR for part in ("--set", item))]
    ddsolve("solve", "partial-closure", *options, "-o", str(tmp_path / "dd.h5"), ranks=4)
    solved_reference("partial-closure", *options, "-o", str(tmp_path / "reference.h5"))
    from ddsolve.io import hdf5

    result, exact = hdf5.read(tmp_path / "dd.h5"), hdf5.read(tmp_path / "reference.h5")
    assert result.converged and analysis.compare(result, exact).energy_error < 1e-8
    assert np.allclose(result.fracture.G, exact.fracture.G, rtol=1e-6)
    import h5py

    with h5py.File(tmp_path / "dd.h5") as f:
        assert f["materials"].attrs["u_minus"] == "materials.layer1.lower: Isotropic(E=20.0, nu=0.28, alpha=0.0)"
        assert f["materials"].attrs["v_minus"] == "materials.layer2: Isotropic(E=112.0, nu=0.32, alpha=0.0)"
