"""3-D gmsh files (docs/geometry.md, "3-D files"): the physical groups read at the scene and their refusals, the
strip of docs/three-d-strip.geo (built as the box is) giving the box's tetrahedra and energy as a .geo and as
.msh 2.2 and 4.1, the quarter penny of docs/three-d-penny.geo giving the box ellipse's G, a crack off Σ and a
curved Σ refused, and the domain decomposition on 2 ranks equal to the file's reference."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ddsolve.errors import MeshError, SceneError
from ddsolve.problem.scene import load, loads
from experiments import three_d, three_d_front

DOCS = Path(__file__).resolve().parent.parent / "docs"
STRIP, PENNY = DOCS / "three-d-strip.toml", DOCS / "three-d-penny.toml"
#: The coarsest size the checks take: the strip's 837 unknowns.
SIZE = 0.3


def strip_text(geo: str = "three-d-strip.geo") -> str:
    """The strip's scene text naming ``geo`` as its file."""
    return STRIP.read_text().replace('"three-d-strip.geo"', f'"{geo}"')


@pytest.mark.unit
def test_the_scene_reads_the_file_s_groups_and_refuses_what_does_not_fit(tmp_path):
    geo = (DOCS / "three-d-strip.geo").read_text()
    scene = loads(strip_text(), base=DOCS)
    assert scene.geometry.dimension == 3 and scene.geometry.clamped == ("clamped",) and scene.geometry.layers == 1
    assert loads(scene.text).mesh.file == DOCS / "three-d-strip.geo"  # the text names the file wherever it is read
    bad = {"no-sigma": (geo.replace('Surface("sigma")', 'Surface("plane")'), "", "missing physical surface 'sigma'"),
           "core": (geo.replace('Volume("upper")', 'Volume("core")'), "",
                    "physical volume 'core': a 3-D file's volumes are lower and upper"),
           "box4": (geo, "[geometry]\nbox = [-1.0, 1.0, -1.0, 1.0]\n", "geometry.box: the file is a 3-D geometry"),
           "box6": (geo, "[geometry]\nbox = [-1.0, 1.0, -1.0, 1.0, 0.0, 0.5]\n", "geometry.box: the file is a 3-D"),
           "unsized": (geo, "", "mesh.grading: grades a .geo's tetrahedra from mesh.size"),
           "extruded": (geo, "", "mesh.extrude: a 3-D gmsh file is meshed"),
           "normal": (geo, "[displacements.layer1.bottom]\nnormal = 0.0\n",
                      "displacements.layer1.bottom.normal: on a 3-D file's surfaces give the x, y and z"),
           "lid": (geo, "", "loads.layer1.lid: no physical surface 'lid' in mesh.file (its boundaries: clamped, "
                            "bottom")}
    for name, (text, head, message) in bad.items():
        (tmp_path / f"{name}.geo").write_text(text)
        scene = strip_text(f"{name}.geo").replace("[loads.layer1.top]", "[loads.layer1.lid]" if name == "lid"
                                                  else "[loads.layer1.top]") + head
        mesh = {"unsized": "grading = true", "extruded": "size = 0.2\nextrude = 2"}.get(name)
        scene = scene.replace("size = 0.2", mesh) if mesh else scene
        with pytest.raises(SceneError, match=message.replace("(", r"\(")):
            loads(scene, base=tmp_path)
    (tmp_path / "plane.geo").write_text((DOCS / "example1.geo").read_text())
    with pytest.raises(SceneError, match=r"geometry.box: a 3-D box \(6 numbers\) is meshed by ddsolve, and mesh.file "
                                         r"plane.geo is plane \(no physical volumes\)"):
        loads('[geometry]\nbox = [-1.0, 1.0, -1.0, 1.0, 0.0, 0.5]\n[mesh]\nfile = "plane.geo"\n[materials.layer1]\n'
              'E = 1.0\nnu = 0.3\n', base=tmp_path)


def written_msh(geo: Path, size: float, version: float, target: Path) -> None:
    """``geo`` meshed by gmsh at ``size`` and written as MSH ``version`` to ``target`` (gmsh's own writer)."""
    from ddsolve.mesh.gmsh_io import session

    with session() as gmsh:
        gmsh.open(str(geo))
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(3)
        gmsh.option.setNumber("Mesh.MshFileVersion", version)
        gmsh.write(str(target))


@pytest.mark.solve
def test_the_strip_file_gives_the_box_s_tetrahedra_and_energy_as_geo_and_msh(tmp_path):
    """The .geo is built as the box is: at the same mesh.size the same tetrahedra, Σ, crack vertices and front, the
    same energy to round-off (also with the loads as pressures on the file's surfaces), graded towards the front
    too; gmsh's .msh of it (2.2 and 4.1) give the same energy (coordinates as printed)."""
    from ddsolve.mesh import solid
    from ddsolve.mesh.gmsh_io import apart
    from ddsolve.solvers import solid as solid_solver

    box = three_d.scene_of("partial closure", SIZE, 3)
    file = load(STRIP, [f"mesh.size={SIZE}"])
    meshes = [solid.build(scene) for scene in (box, file)]
    assert meshes[0].unknowns == meshes[1].unknowns  # 837
    for name in ("points", "triangles", "cracked"):
        assert np.array_equal(getattr(meshes[0].sigma, name), getattr(meshes[1].sigma, name)), name
    assert np.array_equal(*(np.unique(mesh.sigma.front, axis=0) for mesh in meshes))  # the same edges
    for half, other in zip(*(mesh.halves for mesh in meshes)):
        assert all(np.array_equal(np.unique(half.faces[side], axis=0), np.unique(other.faces[side], axis=0))
                   for side in ("bottom", "top", "front", "back"))
    pressed = loads(STRIP.read_text().replace("y = [0.0, 0.078125]", "pressure = [0.0, 0.078125]")
                    .replace("y = [0.0, -0.078125]", "pressure = [0.0, 0.078125]"), [f"mesh.size={SIZE}"], base=DOCS)
    energies = [solid_solver.solve_solid(scene, mesh) for scene, mesh in zip((box, file, pressed), meshes + meshes[1:])]
    assert all(result.converged and result.closed == 4 for result in energies)
    for result in energies[1:]:  # the pressures along the file's surfaces' normals are the box's tractions
        assert abs(result.energy - energies[0].energy) <= 1e-12 * abs(energies[0].energy)
    graded = [three_d.scene_of("partial closure", 0.2, 3).with_({"mesh.grading": True}),
              load(STRIP, ["mesh.size=0.2", "mesh.grading=true"])]  # the box's size field about the file's front
    results = [solid_solver.solve_solid(scene, solid.build(scene)) for scene in graded]
    assert results[0].mesh.unknowns == results[1].mesh.unknowns  # 1791 (1644 without grading)
    assert abs(results[1].energy - results[0].energy) <= 1e-12 * abs(results[0].energy)
    for version in (2.2, 4.1):
        target = tmp_path / f"strip-{version}.msh"
        apart(written_msh, DOCS / "three-d-strip.geo", SIZE, version, target)
        scene = load(STRIP, [f"mesh.file='{target}'"])
        result = solid_solver.solve_solid(scene, solid.build(scene))
        assert abs(result.energy - energies[0].energy) <= 1e-12 * abs(energies[0].energy), version


@pytest.mark.solve
def test_the_penny_file_gives_the_box_ellipse_s_g_and_a_crack_off_sigma_or_a_curved_sigma_is_refused(tmp_path):
    """The quarter penny (a disk crack on Σ) at P1: the box ellipse's front and G at every front node; a crack
    surface off Σ and a Σ that is not a plane y = const are refused naming the file."""
    from ddsolve.mesh import solid

    rows = []
    for scene in (three_d_front.penny_scene(SIZE).with_({"mesh.grading": False}), load(PENNY, [f"mesh.size={SIZE}"])):
        _, release, unknowns, _ = three_d_front.solved(scene)
        rows.append((unknowns, release.G))
    assert rows[0][0] == rows[1][0] and len(rows[1][1]) == 4
    assert np.allclose(rows[1][1], rows[0][1], rtol=1e-9, atol=0.0)
    geo = (DOCS / "three-d-strip.geo").read_text()
    crack = 'Physical Surface("crack") = Surface In BoundingBox{a - e, ys - e, z0 - e, b + e, ys + e, z1 + e};'
    (tmp_path / "off.geo").write_text(geo.replace(crack, crack.replace("a - e, ys - e", "x0 - e, y1 - e")
                                                  .replace("b + e, ys + e", "x1 + e, y1 + e")))  # the top face
    with pytest.raises(MeshError, match="off.geo: physical surface crack does not lie on sigma"):
        solid.build(loads(strip_text("off.geo"), base=tmp_path).with_({"mesh.size": 0.5}))
    fragments = "BooleanFragments{ Volume{1, 2}; Delete; }{ Surface{s}; Delete; }"
    turned = "Rotate {{0, 0, 1}, {0, 0, 0}, 0.1} { Volume{1, 2}; Surface{s}; }\n" + fragments  # Σ tilted by 0.1
    (tmp_path / "tilted.geo").write_text(geo.replace(fragments, turned).replace("e = 1e-6;", "e = 0.2;"))
    with pytest.raises(MeshError, match="tilted.geo: physical surface sigma is not a plane y = const"):
        solid.build(loads(strip_text("tilted.geo"), base=tmp_path).with_({"mesh.size": 0.5}))


@pytest.mark.mpi
def test_the_decomposition_of_a_3d_file_on_2_ranks_equals_its_reference(tmp_path):
    from conftest import ddsolve

    from ddsolve.io import solid as solid_files
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver

    scene = load(STRIP, [f"mesh.size={SIZE}"])
    reference = solid_solver.solve_solid(scene, solid.build(scene))
    solved = ddsolve("solve", str(STRIP), "--set", f"mesh.size={SIZE}", "-o", str(tmp_path / "dd.h5"), ranks=2)
    assert "(3-D):" in solved.stdout and "on 2 ranks" in solved.stdout
    assert solid_solver.energy_error(solid_files.read(tmp_path / "dd.h5"), reference) < 1e-8
