"""Scene parsing, validation and overrides."""
import pytest
from conftest import MATERIALS

from ddsolve.errors import SceneError
from ddsolve.problem import scene

MINIMAL = """
[mesh]
sigma_vertices = 12
boundary_vertices = 32
""" + MATERIALS + """
[solver]
method = "uzawa"
theta = 65.0
"""


def test_builtin_scenes_are_the_papers_examples():
    shipped = scene.builtin_scenes()
    assert {"partial-closure", "full-opening", "linear"} <= set(shipped)
    ex1 = scene.load("partial-closure")
    assert ex1.geometry.cracks == ((-0.5, 0.5),) and ex1.nonpenetration
    assert ex1.geometry.box == (-1.0, 1.0, -1.0, 1.0) and ex1.geometry.sigma == 0.0
    assert ex1.geometry.clamped == ("left", "right") and ex1.model == "plane_strain"
    assert ex1.loads[("layer1", "bottom")].y.coefficients == (0.0, 0.078125)
    assert ex1.loads[("layer1", "top")].y.coefficients == (0.0, -0.078125)
    assert ("layer2", "bottom") not in ex1.loads  # no table: the boundary is not integrated
    assert (ex1.solver.method, ex1.solver.stop, ex1.solver.tol) == ("auto", "kkt", 1e-8)
    paper = scene.load("partial-closure", ["solver.method=uzawa"]).solver
    assert (paper.theta, paper.p, paper.tol, paper.stop) == (65.0, 1e7, 1e-6, "paper")
    assert ex1.materials["layer1"].E == 200.0 and ex1.materials["layer2"].nu == 0.32
    assert not scene.load("linear").nonpenetration
    assert scene.load("full-opening").loads[("layer1", "top")].y.coefficients == (0.078125,)


def test_defaults_and_round_trip():
    s = scene.loads(MINIMAL)
    assert s.geometry.cracks == ((-0.5, 0.5),) and s.nonpenetration and s.loads == {}
    assert s.solver.max_iterations == 20000 and s.solver.stop == "paper" and s.solver.p is None
    again = scene.loads(s.text)
    assert again == s


def test_overrides_are_typed_and_validated():
    s = scene.loads(MINIMAL, ["solver.stop=relative", "solver.tol=1e-11", "mesh.sigma_vertices=48",
                              "loads.layer2.top.x=[1, 2]", "geometry.crack=[]"])
    assert s.solver.stop == "relative" and s.solver.tol == 1e-11 and s.mesh.sigma_vertices == 48
    assert s.loads[("layer2", "top")].x.coefficients == (1.0, 2.0)
    assert s.geometry.cracks == ()
    assert "stop = \"relative\"" in s.text and "cracks = []" in s.text


@pytest.mark.parametrize("override, message", [
    ("solver.thta=1", "unknown key solver.thta (did you mean solver.theta?)"),
    ("solver.theta=-1", "solver.theta must be a number > 0 or \"auto\""),
    ("solver.tol=0", "solver.tol must be > 0"),
    ("solver.method=newton", "solver.method must be one of"),
    ("solver.stop=sometimes", "solver.stop must be one of"),
    ("materials.layer1.E=0", "materials.layer1.E must be > 0"),
    ("materials.layer2.nu=0.5", "materials.layer2.nu must be in (-1, 0.5)"),
    ("materials.layer2.nu=-1", "materials.layer2.nu must be in (-1, 0.5)"),
    ("materials.layer1.E=\"hard\"", "materials.layer1.E must be a number"),
    ("geometry.crack=[0.5, -0.5]", "geometry.crack must be [a, b] with a < b, or []"),
    ("geometry.crack=[-2.0, 0.5]", "the crack [-2, 0.5] leaves the box's x range [-1, 1]"),
    ("geometry.crack=[0.1]", "geometry.crack must be [a, b] with a < b, or []"),
    ("geometry.cracks=[[0, 0.5], [0.4, 0.8]]", "disjoint [a, b] intervals (they overlap or touch)"),
    ("geometry.box=[0, 1, 2, 1]", "geometry.box must be [x0, x1, y0, y1] with x0 < x1 and y0 < y1"),
    ("geometry.sigma=3", "geometry.sigma = 3 must lie strictly between the box's y0 = -1 and y1 = 1"),
    ("geometry.clamped=[\"west\"]", "geometry.clamped must be a list of side names among bottom, top, left, right"),
    ("mesh.degree=3", "mesh.degree must be 1 (P1 triangles) or 2 (P2 triangles)"),
    ("materials.model=\"plane\"", "materials.model must be one of plane_strain, plane_stress"),
    ("materials.layer1={D = [[1, 2, 0], [2, 1, 0], [0, 0, 1]]}", "materials.layer1: D is not positive definite"),
    ("materials.layer1.D=[[1, 2, 0], [2, 1, 0], [0, 0, 1]]", "materials.layer1: D is not positive definite"),
    ("materials.layer1={E1 = -3, E2 = 1, G12 = 1, nu12 = 0.3}", "materials.layer1.E1 must be > 0"),
    ("materials.layer1={E1 = 3, E2 = 1, G12 = 1, nu12 = 3}", "materials.layer1: the orthotropic compliance"),
    ("loads.layer1.top.y=\"x + w\"", "loads.layer1.top.y: bad expression 'x + w': unknown name 'w'"),
    ("loads.layer1.top.y=\"x + z\"", "loads.layer1.top.y: a plane scene's expressions take x and y"),
    ("loads.layer1.top.y=\"(x\"", "loads.layer1.top.y: bad expression '(x': missing ')' for the '(' at position 1 at position 3"),
    ("loads.layer1.top={y = 1, pressure = 2}", "loads.layer1.top: pressure excludes x and y"),
    ("mesh.sigma_vertices=2", "mesh.sigma_vertices must be at least 5"),
    ("mesh.boundary_vertices=4", "mesh.boundary_vertices must be at least 8"),
    ("mesh.boundary_vertices=1000", "mesh.boundary_vertices = 1000 is inconsistent with mesh.sigma_vertices = 12"),
    ("mesh.sigma_vertices=12.5", "mesh.sigma_vertices must be an integer"),
    ("solver.theta=\"big\"", "solver.theta must be a number > 0 or \"auto\""),
    ("contact.nonpenetration=1", "contact.nonpenetration must be true or false"),
    ("loads.layer1.left.z=[1]", "loads.layer1.left.z: a plane scene has no z component"),
    ("loads.layer1.left.w=[1]", "unknown key loads.layer1.left.w"),
    ("materials=3", "materials must be a table"),
    ("solver.max_iterations=0", "solver.max_iterations must be at least 1"),
    ("nokey", "expected KEY=VALUE"),
])
def test_bad_values_name_the_key(override, message):
    with pytest.raises(SceneError) as error:
        scene.loads(MINIMAL, [override], origin="s.toml")
    assert message in str(error.value)
    assert str(error.value).startswith("s.toml: ") or "--set" in str(error.value)
    assert "\n" not in str(error.value)


def test_an_override_of_the_mesh_size_replaces_the_papers_family_and_back():
    sized = scene.loads(MINIMAL, ["mesh.size=0.1"])
    assert (sized.mesh.size, sized.mesh.sigma_vertices, sized.mesh.boundary_vertices) == (0.1, None, None)
    again = scene.loads(sized.text, ["mesh.sigma_vertices=24", "mesh.boundary_vertices=48"])
    assert (again.mesh.size, again.mesh.sigma_vertices, again.mesh.boundary_vertices) == (None, 24, 48)
    with pytest.raises(SceneError, match="mesh.size excludes mesh.sigma_vertices and mesh.boundary_vertices"):
        scene.loads(MINIMAL.replace("[mesh]", "[mesh]\nsize = 0.1"))  # both in one file
    with pytest.raises(SceneError, match="missing key mesh.boundary_vertices"):
        scene.loads(MINIMAL, ["mesh.size=0.1", "mesh.sigma_vertices=24"])  # the later override wins: half a family


def test_missing_and_malformed():
    with pytest.raises(SceneError, match="missing key materials.layer1.E"):
        scene.loads(MINIMAL.replace("E = 200.0", ""))
    with pytest.raises(SceneError, match="solver.theta is required by method uzawa"):
        scene.loads(MINIMAL.replace("theta = 65.0", ""))
    with pytest.raises(SceneError, match="missing key mesh.boundary_vertices"):
        scene.loads(MINIMAL.replace("boundary_vertices = 32", ""))
    with pytest.raises(SceneError, match="mesh.file excludes mesh.sigma_vertices"):
        scene.loads(MINIMAL.replace("boundary_vertices = 32", 'boundary_vertices = 32\nfile = "x.msh"'))
    with pytest.raises(SceneError, match="geometry.crack and geometry.cracks exclude each other"):
        scene.loads(MINIMAL + "[geometry]\ncrack = [0, 0.5]\ncracks = [[0, 0.5]]\n")
    with pytest.raises(SceneError, match="solver.stop = paper is available for method uzawa only"):
        scene.loads(MINIMAL, ["solver.stop=paper", "solver.method=mprgp"])
    with pytest.raises(SceneError, match="malformed TOML"):
        scene.loads("[mesh\nsigma_vertices = 3")
    with pytest.raises(SceneError, match="no such scene file or built-in scene"):
        scene.load("no-such-scene")


def test_an_override_replaces_the_keys_it_excludes():
    s = scene.loads(MINIMAL, ["mesh.size=0.1", "geometry.cracks=[[0.1, 0.2], [0.4, 0.6]]"])
    assert (s.mesh.size, s.mesh.sigma_vertices, s.mesh.boundary_vertices) == (0.1, None, None)
    assert s.geometry.cracks == ((0.1, 0.2), (0.4, 0.6))
    s = scene.loads(s.text, ["mesh.sigma_vertices=24", "mesh.boundary_vertices=48", "geometry.crack=[]"])
    assert (s.mesh.size, s.mesh.sigma_vertices) == (None, 24) and s.geometry.cracks == ()
    assert scene.loads(MINIMAL, ["mesh.file=m.vtu"]).mesh.file.name == "m.vtu"


def test_bare_words_are_strings_and_mesh_files_resolve_against_the_scene(tmp_path):
    assert scene.parse_override("solver.stop=relative") == (["solver", "stop"], "relative")
    assert scene.parse_override("solver.tol=1e-8") == (["solver", "tol"], 1e-8)
    path = tmp_path / "s.toml"
    path.write_text(MINIMAL.replace("sigma_vertices = 12\nboundary_vertices = 32", 'file = "m.vtu"'))
    (tmp_path / "m.vtu").write_text("")  # load refuses a mesh file it cannot open
    assert scene.load(path).mesh.file == tmp_path / "m.vtu"


def test_an_override_of_another_material_law_replaces_the_layers_law():
    """--set materials.layer1.D=... on an isotropic layer makes it anisotropic (E and nu go), E1 makes it
    orthotropic and asks for the keys that law needs; an α override keeps the law."""
    from ddsolve.problem import materials

    D = "[[270.2, 105.1, 0.0], [105.1, 270.2, 0.0], [0.0, 0.0, 78.1]]"
    assert isinstance(scene.load("partial-closure", [f"materials.layer1.D={D}"]).materials["layer1"],
                      materials.Anisotropic)
    with pytest.raises(SceneError, match="missing key materials.layer1.E2$"):
        scene.load("partial-closure", ["materials.layer1.E1=200.0"])
    heated = scene.load("partial-closure", ["materials.layer1.alpha=1e-5"]).materials["layer1"]
    assert heated.E == 200.0 and heated.alpha == 1e-5
