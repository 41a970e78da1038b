"""Round 6, the 3-D surfaces of several interfaces: an ellipse crack on an interface above the first, 3-D gmsh files
that are not there, name no group, or name interfaces without volumes, and the options prefixes a misspelt PETSc
option is compared with (the blocks the run made: a 3-D box's regions, a file's volumes); a 3-D result where a plane
one is read (check, the Python API's load, compare against a plane result) said to be 3-D; 3-D moduli, loads,
prescribed values and eigenstrains beyond double precision refused naming their keys, as in the plane.

Each refusal is one line naming the key or the file, exit status 1 before any work, the previous files
byte-identical.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from conftest import ddsolve, previous_set, refused, unchanged

from ddsolve import load
from ddsolve.errors import DDSolveError, SceneError
from ddsolve.problem import scene

DOCS = Path(__file__).resolve().parent.parent / "docs"
BOX = DOCS / "three-d-interfaces.toml"
FILE_SCENE = (DOCS / "three-d-interfaces-file.toml").read_text()
GEO = (DOCS / "three-d-interfaces.geo").read_text()
ELLIPSE = "geometry.cracks=[[[1.0, 2.0]], [{center = [2.5, 0.5], radii = [0.3, 0.3]}]]"


@pytest.mark.unit
def test_an_ellipse_crack_on_an_upper_interface_is_read():
    loaded = scene.load(BOX, [ELLIPSE])
    (height, (crack,)), = loaded.geometry.above
    assert height == 2.0 and (crack.center, crack.radii) == ((2.5, 0.5), (0.3, 0.3))
    assert scene.loads(loaded.text).geometry == loaded.geometry


def _file_scene(folder: Path, geo: str | None) -> Path:
    """The 3-D file scene in ``folder``, its .geo holding ``geo`` (no .geo for None)."""
    if geo is not None:
        (folder / "three-d-interfaces.geo").write_text(geo)
    path = folder / "s.toml"
    path.write_text(FILE_SCENE)
    return path


NO_VOLUMES = "\n".join(line for line in GEO.splitlines() if "Physical Volume" not in line)


@pytest.mark.unit
@pytest.mark.parametrize("geo, expected", [
    (None, "materials.layer1.core: no region of that name (the regions of Ω, bottom to top: lower, upper); and "),
    ("", "mesh.file three-d-interfaces.geo: no named physical group: the file names its interfaces, cracks and "
         "regions"),
    (NO_VOLUMES, "mesh.file three-d-interfaces.geo: physical surface sigma1 and no physical volume: a 3-D file "
                 "names one volume per region, bottom to top"),
    (GEO.replace('Surface("sigma1")', 'Surface("sigma")'), "physical surfaces sigma and sigma2: name one interface "
                                                            "sigma"),
], ids=["missing", "empty", "no-volumes", "sigma-and-sigma2"])
def test_a_3d_file_that_names_no_structure_is_refused_naming_it(tmp_path, geo, expected):
    with pytest.raises(SceneError) as caught:
        scene.load(_file_scene(tmp_path, geo))
    message = str(caught.value)
    assert "\n" not in message and expected in message, message
    if geo is None:
        assert message.endswith("three-d-interfaces.geo: mesh file not found (its physical groups name the "
                                "structure)")


@pytest.mark.mpi
def test_a_missing_3d_file_keeps_the_previous_files(tmp_path):
    output = tmp_path / "r.h5"
    files = previous_set(output)
    refused(ddsolve("solve", "-n", "3", str(_file_scene(tmp_path, None)), "-o", str(output), check=False), 1,
            "materials.layer1.core", "three-d-interfaces.geo: mesh file not found")
    assert unchanged(files)


@pytest.mark.mpi
def test_an_ellipse_on_sigma2_solves_and_a_misspelt_option_lists_the_regions_prefixes(tmp_path):
    completed = ddsolve("solve", "-n", "3", str(BOX), "--set", ELLIPSE, "--set", "mesh.size=0.5",
                        "-upper_ksp_type", "preonly", "-o", str(tmp_path / "r.h5"))
    assert completed.stderr.strip() == ("ddsolve: warning: PETSc options not used (misspelt? the prefixes here are "
                                        "region1_, region2_, region3_): -upper_ksp_type preonly")
    with pytest.raises(DDSolveError, match=rf"^{tmp_path / 'r.h5'}: the result of a 3-D solve, where a plane one is "
                                           "read: plot and export read it, compare reads two of them; check and"):
        load(tmp_path / "r.h5")


@pytest.mark.mpi
@pytest.mark.parametrize("command, overrides, expected", [
    (["solve", "-n", "3"], ["temperature.layer1=1e301", "materials.layer1.region2.alpha=1e10"],
     "materials.layer1.region2.alpha with temperature.layer1 up to 1e+301 give eigenstrains of order inf"),
    (["reference"], ["loads.layer1.right.x=1e200"],
     "materials.layer1.E: the elastic matrix (largest entry 1.35) with loads.layer1.right up to 1e+200"),
], ids=["region-eigenstrain-solve", "load-reference"])
def test_3d_data_beyond_double_precision_is_refused_naming_its_keys(tmp_path, command, overrides, expected):
    output = tmp_path / "r.h5"
    files = previous_set(output)
    sets = [item for override in ["mesh.size=0.5", *overrides] for item in ("--set", override)]
    refused(ddsolve(*command, str(BOX), *sets, "-o", str(output), check=False), 1, expected)
    assert unchanged(files)


@pytest.mark.mpi
def test_schur_on_a_region_without_nodes_off_its_interfaces_names_the_block_and_the_methods(tmp_path):
    message = refused(ddsolve("solve", "-n", "3", str(BOX), "--set", "mesh.size=0.5", "--set",
                              "geometry.sigma=[1.0, 1.05]", "--set", 'solver.method="schur"', "-o",
                              str(tmp_path / "r.h5"), check=False), 1,
                      "block region2: solver setup failed: ")
    assert message.endswith("a block with few or no nodes off its interfaces (a region thinner than mesh.size): "
                            "use solver.method = feti or mprgp")
