"""3-D gmsh files of several interfaces (docs/geometry.md, "3-D files"): the surfaces sigma1, sigma2, … (crack1, …)
and a volume per region read at the scene, the regions named by their volumes, and the file's refusals; the sample
docs/three-d-interfaces.geo (built as the box is) giving the tetrahedra and energy of docs/three-d-interfaces.toml,
its decomposition equal to its reference, and a file whose interfaces or volumes do not fit refused naming it."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ddsolve.errors import MeshError, SceneError
from ddsolve.problem.scene import load, loads

DOCS = Path(__file__).resolve().parent.parent / "docs"
BOX, FILE = DOCS / "three-d-interfaces.toml", DOCS / "three-d-interfaces-file.toml"
#: The coarsest size at which both cracks are shut in part (tests/test_solid_interfaces.py).
COARSE = ["mesh.size=0.45"]
CORE = 'Physical Volume("core") = Volume In BoundingBox{x0 - e, s1 - e, z0 - e, x1 + e, s2 + e, z1 + e};'
COVER = 'Physical Volume("cover") = Volume In BoundingBox{x0 - e, s2 - e, z0 - e, x1 + e, y1 + e, z1 + e};'
#: Groups a scene refuses when it is read: the .geo's text changed (old, new) -> the message.
REFUSED = {
    "skip": (('"sigma1"', '"sigma3"'), "physical surface sigma3 without sigma1: number the interfaces sigma1, sigma2"),
    "stray": (('"crack1"', '"crack3"'), "physical surface crack3 lies on no interface (no sigma3)"),
    "both": (('Surface("top")', 'Surface("sigma")'), "physical surfaces sigma and sigma1: name one interface sigma"),
    "count": ((COVER, ""), "2 interfaces (sigma1 ... sigma2) cut Ω into 3 regions, and the file has 2 physical "
                           "volumes (base, core): one per region, bottom to top"),
}


def file_text(geo: str) -> str:
    """The sample file's scene naming ``geo``."""
    return FILE.read_text().replace('"three-d-interfaces.geo"', f'"{geo}"')


@pytest.mark.unit
def test_the_scene_takes_the_file_s_regions_and_refuses_groups_that_do_not_fit(tmp_path):
    """The regions are the file's volumes, bottom to top, and name the materials; the numbered groups that do not
    make interfaces and regions are refused in one line naming the file (no meshing: the .geo's text)."""
    scene = load(FILE)
    assert scene.geometry.dimension == 3 and scene.geometry.region_names == ("base", "core", "cover")
    assert len(scene.geometry.sigmas) == 2 and scene.geometry.clamped == ("clamped",)
    assert scene.material("layer1", "core").E == 2.0 and scene.material("layer1", "cover").E == 1.0
    with pytest.raises(SceneError, match=r"materials.layer1.region2: no region of that name \(the regions of Ω, "
                                         r"bottom to top: base, core, cover\)"):
        loads(file_text("three-d-interfaces.geo") + "[materials.layer1.region2]\nE = 3.0\n", base=DOCS)
    with pytest.raises(SceneError, match="solver.pieces = 2: a 3-D box of several interfaces is decomposed into its "
                                         "regions"):
        loads(file_text("three-d-interfaces.geo") + "[solver]\npieces = 2\n", base=DOCS)
    geo = (DOCS / "three-d-interfaces.geo").read_text()
    assert CORE in geo and COVER in geo
    for name, ((old, new), message) in REFUSED.items():
        (tmp_path / f"{name}.geo").write_text(geo.replace(old, new))
        with pytest.raises(SceneError, match=f"mesh.file {name}.geo: {message}".replace("(", r"\(")
                           .replace(")", r"\)").replace(".", r"\.")):
            loads(file_text(f"{name}.geo"), base=tmp_path)


@pytest.mark.solve
def test_the_sample_file_gives_the_box_s_tetrahedra_energy_and_decomposition_and_bad_files_are_refused(tmp_path):
    """The .geo is built as the box is: at the same mesh.size the same regions and interfaces (Σ's points, crack
    vertices and front edges), the same energy and G at every front node to round-off; schur on one rank (in this
    process) equals the file's reference to 1e-8.  Interfaces that touch or are not bottom to top, a volume not
    between its interfaces, a tilted Σ and a crack off its Σ are refused naming the file and the group."""
    from mpi4py import MPI

    from ddsolve.mesh import solid, solid_files
    from ddsolve.solvers import solid as solid_solver, solid_dd

    scenes = [load(BOX, COARSE), load(FILE, COARSE)]
    meshes = [solid.build(scene) for scene in scenes]
    assert meshes[0].unknowns == meshes[1].unknowns  # 1527
    assert [region.name for region in meshes[1].regions] == ["base", "core", "cover"]
    for box_sigma, file_sigma in zip(meshes[0].sigmas, meshes[1].sigmas):
        assert np.array_equal(box_sigma.points, file_sigma.points)
        assert np.array_equal(box_sigma.cracked, file_sigma.cracked)
        assert np.array_equal(*(np.unique(np.sort(sigma.front, axis=1), axis=0) for sigma in (box_sigma, file_sigma)))
    results = [solid_solver.reference_on(scene, mesh) for scene, mesh in zip(scenes, meshes)]
    assert all(result.converged for result in results) and results[0].closed == results[1].closed > 0
    assert abs(results[1].energy - results[0].energy) <= 1e-12 * abs(results[0].energy)
    order = [np.lexsort(result.fracture.points.T) for result in results]  # the fronts listed in another order
    assert np.allclose(results[1].fracture.G[order[1]], results[0].fracture.G[order[0]], rtol=1e-9, atol=0.0)
    dd = solid_dd.solve(scenes[1], MPI.COMM_SELF, None, progress=lambda _line: None, mesh=meshes[1])
    assert dd.converged and solid_solver.energy_error(dd, results[1]) < 1e-8

    points, tetrahedra, region, surfaces = solid_files.read(scenes[1], solid.graded_towards)
    names = ("base", "core", "cover")

    def refused(message: str, points=points, region=region, **changed) -> None:
        with pytest.raises(MeshError, match=f"three-d-interfaces.geo: {message}".replace("(", r"\(")
                           .replace(")", r"\)")):
            solid_files.checked(points, tetrahedra, region, {**surfaces, **changed}, names, "three-d-interfaces.geo")
    refused("physical surfaces sigma1 (y = 1) and sigma2 (y = 1) cross or touch", sigma2=surfaces["sigma1"])
    refused("physical surfaces sigma1 (y = 2) and sigma2 (y = 1) are not bottom to top",
            sigma1=surfaces["sigma2"], sigma2=surfaces["sigma1"], crack1=surfaces["crack2"], crack2=surfaces["crack1"])
    refused("physical volume core does not lie between its interfaces (region 2 from the bottom: above sigma1 and "
            "below sigma2)", region=np.choose(region, [0, 2, 1]))
    refused("physical surface crack2 does not lie on sigma2 (", crack2=surfaces["crack1"])
    tilted = points.copy()
    tilted[surfaces["sigma1"][0, 0], 1] += 0.01
    refused("physical surface sigma1 is not a plane y = const", points=tilted)
