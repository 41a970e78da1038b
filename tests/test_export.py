"""Viewer files (VTU and XDMF, P1 and P2) read back by meshio and ParaView, and the set-of-files writer."""
from __future__ import annotations

import random
import re
import shutil
import subprocess
from pathlib import Path

import meshio
import numpy as np
import pytest
from conftest import SMALL, ddsolve, solved_reference

from ddsolve import cli
from ddsolve.errors import DDSolveError
from ddsolve.fem import assembly
from ddsolve.io import hdf5
from ddsolve.io import safe
from ddsolve.io import viewer
from ddsolve.io.viewer import ViewerMesh, merged_upper_nodes, write_vtu
from ddsolve.post import analysis
from ddsolve.problem import materials

P2 = ["--set", "mesh.degree=2"]
LAYER_ARRAYS = {"stress": 9, "strain": 9, "von_mises": 1, "energy_density": 1, "half": 1, "error_indicator": 1}
SIGMA_ARRAYS = {"jump": 3, "opening": 1, "contact_pressure": 1, "mu_g": 3, "mu_minus": 3, "mu_plus": 3,
                "normal": 3, "crack": 1, "x": 1, "arc_length": 1}


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """Reference results of Example 1 on a small mesh, P1 and P2, with their viewer files in both formats."""
    folder = tmp_path_factory.mktemp("export")
    out = {}
    for degree, extra in ((1, []), (2, P2)):
        path = folder / f"p{degree}.h5"
        solved_reference("partial-closure", *SMALL, *extra, "-o", str(path))
        ddsolve("export", str(path), "--format", "xdmf")
        out[degree] = path
    return out


def components(values: np.ndarray) -> int:
    return 1 if values.ndim == 1 else values.shape[1]


@pytest.mark.parametrize("cell_type, cells", [("triangle", [[0, 1, 2], [1, 3, 2]]),
                                              ("triangle6", [[0, 1, 2, 4, 5, 6], [1, 3, 2, 7, 8, 5]])])
def test_a_vtu_file_keeps_the_vtk_rules_for_its_cell_arrays(tmp_path, cell_type, cells):
    """The connectivity is one list (VTK refuses it with components), offsets and types one value per
    cell, and the file reads back as written."""
    points = np.random.default_rng(5).random((9, 3))
    cells = np.array(cells)
    mesh = ViewerMesh("t", points, cell_type, cells, {"displacement": points[:, :2] * 2.0},
                      {"stress": np.arange(18.0).reshape(2, 9)})
    path = tmp_path / "t.vtu"
    write_vtu(mesh, str(path))
    head = path.read_bytes().split(b"<AppendedData")[0].decode()
    tags = re.findall(r"<DataArray [^>]*>", head)
    arrays = {(re.findall(r'Name="(\w+)"', tag) or ["Points"])[0]: tag for tag in tags}
    assert "NumberOfComponents" not in arrays["connectivity"] + arrays["offsets"] + arrays["types"]
    assert 'NumberOfComponents="9"' in arrays["stress"] and 'NumberOfComponents="3"' in arrays["Points"]
    read = meshio.read(path)
    assert np.array_equal(read.cells[0].data, cells) and read.cells[0].type == cell_type
    assert np.array_equal(read.points, points) and np.array_equal(read.cell_data["stress"][0], mesh.cell_data["stress"])


@pytest.mark.mpi
@pytest.mark.parametrize("fmt", ["vtu", "xdmf"])
@pytest.mark.parametrize("degree", [1, 2])
def test_meshio_reads_every_viewer_file_with_its_named_arrays(results, degree, fmt):
    path = results[degree]
    result = hdf5.read(path)
    fields = analysis.cell_fields(result)
    for layer, (minus, plus) in (("layer1", ("u_minus", "u_plus")), ("layer2", ("v_minus", "v_plus"))):
        mesh = meshio.read(path.with_name(f"p{degree}-{layer}.{fmt}"))
        (block,) = mesh.cells
        assert block.type == ("triangle" if degree == 1 else "triangle6")
        assert len(block.data) == len(result.lower.cells) + len(result.upper.cells)
        assert set(mesh.cell_data) == set(LAYER_ARRAYS)
        for name, count in LAYER_ARRAYS.items():
            (values,) = mesh.cell_data[name]
            assert len(values) == len(block.data) and components(values) == count, name
        displacement = mesh.point_data["displacement"]
        assert displacement.shape == (len(mesh.points), 3) and np.all(displacement[:, 2] == 0.0)
        # lower nodes first, as in the result; the upper half's own nodes after them
        n = len(result.lower.points)
        assert np.allclose(displacement[:n, :2], result.solution[minus], rtol=0, atol=1e-14)
        index, _ = merged_upper_nodes(result)
        assert np.allclose(displacement[index, :2], result.solution[plus], rtol=0, atol=1e-12)
        (stress,), (strain,) = mesh.cell_data["stress"], mesh.cell_data["strain"]
        expected = np.concatenate([fields[minus].stress, fields[plus].stress])
        assert np.allclose(stress[:, [0, 4, 1]], expected) and np.array_equal(stress[:, 1], stress[:, 3])
        assert np.allclose(stress[:, 8], np.concatenate([fields[minus].stress_zz, fields[plus].stress_zz]))
        assert np.all(strain[:, 8] == 0.0)  # plane strain
        assert np.allclose(mesh.cell_data["von_mises"][0],
                           np.concatenate([fields[minus].von_mises, fields[plus].von_mises]))
    sigma = meshio.read(path.with_name(f"p{degree}-sigma.{fmt}"))
    (block,) = sigma.cells
    assert block.type == ("line" if degree == 1 else "line3")
    assert len(sigma.points) == len(result.mesh.sigma.points)
    assert {name: components(values) for name, values in sigma.point_data.items()} == SIGMA_ARRAYS
    nodes = result.multiplier_nodes
    assert np.allclose(sigma.point_data["opening"][nodes], analysis.normal_jump(result))
    assert np.array_equal(sigma.point_data["contact_pressure"][nodes], result.multipliers["mu_c"])
    assert np.array_equal(sigma.point_data["mu_g"][nodes, :2], result.multipliers["mu_g"])


@pytest.mark.mpi
def test_layer_mesh_is_one_mesh_with_separate_crack_faces(results):
    result = hdf5.read(results[1])
    mesh = meshio.read(results[1].with_name("p1-layer1.vtu"))
    sigma = result.mesh.sigma
    crack, glued = int(sigma.crack.sum()), int((~sigma.crack).sum())
    assert crack > 0
    assert len(mesh.points) == len(result.lower.points) + len(result.upper.points) - glued
    # every position occurs once, except the crack nodes: once per face
    _, counts = np.unique(np.round(mesh.points, 12), axis=0, return_counts=True)
    assert np.sum(counts == 2) == crack and counts.max() == 2
    # the two halves share the glued Σ nodes: cells of both use them
    cells = mesh.cells[0].data
    lower_cells = cells[mesh.cell_data["half"][0] == -1]
    upper_cells = cells[mesh.cell_data["half"][0] == 1]
    shared = np.intersect1d(lower_cells, upper_cells)
    assert len(shared) == glued


@pytest.mark.mpi
def test_energy_density_integrates_to_the_strain_energy(results):
    result = hdf5.read(results[2])
    fields = analysis.cell_fields(result)
    laws = analysis.elasticities(result)
    for name, half in (("u_minus", result.lower), ("v_plus", result.upper)):
        area, _ = assembly.cell_strains(half.points, half.cells, result.solution[name])
        energy = assembly.energy(half.points, half.cells, laws[name][0], result.solution[name])
        assert np.sum(fields[name].energy_density * area) == pytest.approx(0.5 * energy, rel=1e-12)


def test_plane_stress_strain_zz_makes_sigma_zz_vanish():
    """εzz = e·ε + t ΔT zeroes σzz of the 3-D law with the eigenstrain α ΔT, and is α_zz ΔT under free
    expansion."""
    strain = np.array([[1.0e-3, -2.0e-4, 5.0e-4], [0.0, 3.0e-4, 0.0]])
    change = np.array([80.0, -30.0])
    isotropic = materials.Isotropic(E=200.0, nu=0.28, alpha=1e-5)
    e, t = materials.out_of_plane_strain(isotropic, "plane_stress")
    assert np.allclose(strain @ e + t * change, -0.28 / 0.72 * (strain[:, 0] + strain[:, 1] - 2e-5 * change)
                       + 1e-5 * change, rtol=1e-14, atol=0)
    e, t = materials.out_of_plane_strain(isotropic, "plane_strain")
    assert np.array_equal(e, np.zeros(3)) and t == 0.0
    orthotropic = materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3, angle=30.0, alpha1=-1e-6, alpha2=3e-5)
    e, t = materials.out_of_plane_strain(orthotropic, "plane_stress")
    C, alpha = materials.stiffness_3d(orthotropic), materials.expansion(orthotropic)
    full = np.zeros((2, 6))
    full[:, [0, 1, 5]] = strain
    full[:, 2] = strain @ e + t * change
    assert np.allclose(((full - np.outer(change, alpha)) @ C.T)[:, 2], 0.0, atol=1e-12)  # σzz = 0
    free = np.outer(change, materials.thermal_strain(orthotropic, "plane_stress")[0])
    assert np.allclose(free @ e + t * change, 3e-5 * change, rtol=1e-12, atol=0)  # εzz = α2 ΔT
    assert materials.out_of_plane_strain(materials.Anisotropic(D=((1, 0, 0), (0, 1, 0), (0, 0, 1))),
                                         "plane_stress") is None


@pytest.mark.mpi
def test_plane_stress_result_has_its_strain_zz(tmp_path):
    path = tmp_path / "ps.h5"
    solved_reference("orthotropic-plate", "--set", "mesh.size=0.25", "-o", str(path))
    (strain,) = meshio.read(tmp_path / "ps-layer1.vtu").cell_data["strain"]
    (stress,) = meshio.read(tmp_path / "ps-layer1.vtu").cell_data["stress"]
    assert np.all(stress[:, 8] == 0.0) and np.abs(strain[:, 8]).max() > 0.0


@pytest.mark.mpi
def test_per_cell_arrays_of_the_result_become_cell_arrays(results, tmp_path):
    result = hdf5.read(results[1])
    damage_values = {block: np.arange(len(result.half(block).cells), dtype=float) + (100 if block.endswith("plus") else 0)
                     for block in ("u_minus", "u_plus", "v_minus", "v_plus")}
    result.cell_data["damage"] = damage_values
    path = tmp_path / "with-cells.h5"
    hdf5.write(path, result)
    again = hdf5.read(path)
    assert np.array_equal(again.cell_data["damage"]["v_plus"], damage_values["v_plus"])
    hdf5.write_viewer(again, tmp_path, "with-cells", "xdmf")
    for fmt in ("vtu", "xdmf"):
        (estimated,) = meshio.read(tmp_path / f"with-cells-layer1.{fmt}").cell_data["error_indicator"]
        assert np.array_equal(estimated, np.concatenate([result.indicators["u_minus"], result.indicators["u_plus"]]))
        (values,) = meshio.read(tmp_path / f"with-cells-layer2.{fmt}").cell_data["damage"]
        assert np.array_equal(values, np.concatenate([damage_values["v_minus"], damage_values["v_plus"]]))
    result.cell_data["damage"] = {**damage_values, "u_plus": damage_values["u_plus"][:-1]}
    with pytest.raises(DDSolveError, match="cell data damage: .* upper half"):
        hdf5.write_viewer(result, tmp_path, "bad", "vtu")


@pytest.mark.mpi
def test_a_registered_viewer_format_is_offered_checked_and_written(results, tmp_path, monkeypatch):
    """A viewer format is a name and a writer in viewer.FORMATS: the command line's choices, the checks of
    the outputs and the writers of the result set come from there."""
    def write(meshes, folder, stem):
        names = viewer.viewer_names(stem, "txt")
        return {**{folder / names[mesh.name]: (lambda name, mesh=mesh: Path(name).write_text(mesh.name))
                   for mesh in meshes}, folder / f"{stem}-all.txt": lambda name: Path(name).write_text("all")}

    monkeypatch.setitem(viewer.FORMATS, "txt", viewer.ViewerFormat("txt", write, extra=("-all.txt",)))
    assert cli.parser().parse_args(["export", "r.h5", "--format", "txt"]).format == "txt"
    hdf5.check_viewer("txt")
    expected = [tmp_path / name for name in ("r-layer1.txt", "r-layer2.txt", "r-sigma.txt", "r-all.txt",
                                             "r-paraview.py")]
    assert viewer.viewer_paths(tmp_path, "r", "txt") == expected
    written = hdf5.write_viewer(hdf5.read(results[1]), tmp_path, "r", "txt")
    assert sorted(written) == sorted(expected) and (tmp_path / "r-sigma.txt").read_text() == "sigma"
    with pytest.raises(DDSolveError, match="^save: viewer must be one of 'vtu', 'xdmf', 'txt' "):
        hdf5.check_viewer("png", "save: viewer")


def test_a_failing_writer_keeps_the_previous_set_and_leaves_no_temporaries(tmp_path):
    first, second = tmp_path / "a.txt", tmp_path / "b.txt"
    safe.replace_together({first: lambda name: open(name, "w").write("old a"),
                         second: lambda name: open(name, "w").write("old b")})

    def fails(name):
        raise OSError(28, "No space left on device")

    with pytest.raises(DDSolveError, match="b.txt: cannot write .No space left on device"):
        safe.replace_together({first: lambda name: open(name, "w").write("new a"), second: fails})
    assert first.read_text() == "old a" and second.read_text() == "old b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]
    with pytest.raises(KeyboardInterrupt):
        safe.replace_together({first: lambda name: (_ for _ in ()).throw(KeyboardInterrupt())})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


@pytest.mark.mpi
def test_export_command(results, tmp_path):
    out = ddsolve("export", str(results[2]), "--format", "vtu", "-o", str(tmp_path)).stdout
    names = ["p2-layer1.vtu", "p2-layer2.vtu", "p2-sigma.vtu", "p2-paraview.py"]
    assert out.strip() == "wrote " + ", ".join(str(tmp_path / name) for name in names)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(names)
    completed = ddsolve("export", str(results[2]), "-o", str(tmp_path / "missing"), check=False)
    assert completed.returncode == 1
    assert completed.stderr.strip() == f"ddsolve: error: -o {tmp_path / 'missing'}: no such directory"
    completed = ddsolve("export", str(tmp_path / "p2-layer1.vtu"), check=False)
    assert completed.returncode == 1 and completed.stderr.count("\n") == 1
    assert "not a ddsolve result file" in completed.stderr


# --- ParaView (skipped where it is not installed) ----------------------------------------------------
PARAVIEW = shutil.which("pvpython") and shutil.which("xvfb-run")
needs_paraview = pytest.mark.skipif(not PARAVIEW, reason="ParaView (pvpython) or xvfb-run not installed")


def pvpython(*args: str, cwd=None) -> subprocess.CompletedProcess:
    """``xvfb-run -a pvpython ARGS``; the X display search starts at a random number, and a display
    another run took at the same moment (xvfb-run's race) is retried once."""
    for attempt in range(2):
        command = ["xvfb-run", "-a", "-n", str(random.randint(100, 4000)), "pvpython", *args]
        completed = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=cwd,
                                   stdin=subprocess.DEVNULL)
        if "bad X server connection" not in completed.stderr:
            break
    return completed


READ_IN_PARAVIEW = """
import sys
from paraview.simple import OpenDataFile, servermanager
for name in sys.argv[1:]:
    reader = OpenDataFile(name)
    reader.UpdatePipeline()
    data = servermanager.Fetch(reader)
    arrays = [data.GetPointData().GetArray(i) for i in range(data.GetPointData().GetNumberOfArrays())]
    arrays += [data.GetCellData().GetArray(i) for i in range(data.GetCellData().GetNumberOfArrays())]
    print(name, reader.GetXMLName(), data.GetNumberOfPoints(), data.GetNumberOfCells(), data.GetCellType(0),
          " ".join("%s:%d" % (a.GetName(), a.GetNumberOfComponents()) for a in arrays))
"""


@pytest.mark.mpi
@needs_paraview
def test_paraview_reads_every_viewer_file(results, tmp_path):
    script = tmp_path / "read.py"
    script.write_text(READ_IN_PARAVIEW)
    files = [str(results[degree].with_name(f"p{degree}-{part}.{fmt}")) for degree in (1, 2)
             for part in ("layer1", "layer2", "sigma") for fmt in ("vtu", "xdmf")]
    completed = pvpython(str(script), *files)
    assert completed.returncode == 0, completed.stderr
    lines = {line.split()[0]: line.split()[1:] for line in completed.stdout.splitlines() if line.startswith("/")}
    assert sorted(lines) == sorted(files)
    vtk_cell_types = {("layer", 1): 5, ("layer", 2): 22, ("sigma", 1): (3, 4), ("sigma", 2): 21}
    for name, (reader, points, cells, cell_type, *arrays) in lines.items():
        mesh = meshio.read(name)
        assert reader == ("XMLUnstructuredGridReader" if name.endswith(".vtu") else "Xdmf3ReaderS")
        assert (int(points), int(cells)) == (len(mesh.points), len(mesh.cells[0].data))
        degree = 1 if "/p1-" in name else 2
        expected = vtk_cell_types["sigma" if "sigma" in name else "layer", degree]
        assert int(cell_type) in np.atleast_1d(expected)
        found = dict(array.split(":") for array in arrays)
        wanted = SIGMA_ARRAYS if "sigma" in name else {"displacement": 3, **LAYER_ARRAYS}
        assert {key: int(value) for key, value in found.items()} == wanted


@pytest.mark.mpi
@needs_paraview
@pytest.mark.parametrize("fmt", ["vtu", "xdmf"])
def test_the_paraview_script_renders_both_layers_and_sigma(tmp_path, fmt):
    path = tmp_path / "example1.h5"
    ddsolve("reference", "partial-closure", "-o", str(path))
    if fmt == "xdmf":
        ddsolve("export", str(path), "--format", "xdmf")
    picture = tmp_path / "picture.png"
    completed = pvpython(str(tmp_path / "example1-paraview.py"), "--png", str(picture), cwd=tmp_path)
    assert completed.returncode == 0, completed.stderr
    assert f"wrote {picture}" in completed.stdout
    assert "ERR|" not in completed.stderr, completed.stderr
    from matplotlib.image import imread

    image = imread(picture)[:, :, :3]
    assert image.shape[:2] == (1000, 1600)
    height = int(1000 * 0.62)
    left, right = image[:height, :800], image[:height, 800:]
    for panel in (left, right):  # a coloured (viridis) layer in each half of the top row
        coloured = np.ptp(panel, axis=2) > 0.25
        assert coloured.mean() > 0.15
    chart = image[height:]
    blue = (chart[:, :, 2] > 0.6) & (chart[:, :, 0] < 0.3)  # the opening's line
    red = (chart[:, :, 0] > 0.7) & (chart[:, :, 1] < 0.3)  # the contact pressure's line
    assert blue.sum() > 300 and red.sum() > 300


#: A 3-D box, coarse, the crack pulled open (tests/test_three_d.py's scene).
SOLID_BOX = """
[geometry]
box = [-1, 1, -1, 1, 0, 0.5]
crack = [-0.5, 0.5]
[mesh]
size = 0.3
[materials.layer1]
E = 200.0
nu = 0.3
[loads.layer1.top]
y = [0.1]
[loads.layer1.bottom]
y = [-0.1]
"""


@pytest.mark.mpi
@needs_paraview
def test_the_paraview_script_renders_a_3d_box_and_the_opening_over_sigma(tmp_path):
    """The script written beside a 3-D result's XDMF files (``ddsolve export --format xdmf``) draws the warped halves
    on the left and Σ's opening map on the right."""
    scene = tmp_path / "box.toml"
    scene.write_text(SOLID_BOX)
    ddsolve("reference", str(scene), "-o", str(tmp_path / "box.h5"))
    ddsolve("export", str(tmp_path / "box.h5"), "--format", "xdmf")
    assert "box-sigma.xdmf" in (tmp_path / "box-paraview.py").read_text()
    picture = tmp_path / "picture.png"
    completed = pvpython(str(tmp_path / "box-paraview.py"), "--png", str(picture), cwd=tmp_path)
    assert completed.returncode == 0 and "ERR|" not in completed.stderr, completed.stderr
    from matplotlib.image import imread

    image = imread(picture)[:, :, :3]
    assert image.shape[:2] == (1000, 1600)
    for panel in (image[:, :800], image[:, 900:]):  # viridis colours in both views
        assert (np.ptp(panel, axis=2) > 0.25).mean() > 0.1
