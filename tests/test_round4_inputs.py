"""Issue 40, classes 1–3 and a first-use friction (inputs): prescribed displacements, expansion coefficients and
temperature changes beyond double precision, results that are not finite, temperature keys that do nothing or
cannot be integrated, prescribed displacements that push the crack faces through each other, and
``mesh.target_error`` alone on a box.

Each refusal is one line naming the key, exit status 1 before any work, the previous files byte-identical. The
hypothesis generators build each class's inputs over their whole range.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import SMALL, ddsolve, previous_set, refused, structured_mesh, unchanged
from hypothesis import given, settings
from hypothesis import strategies as st

from ddsolve.dd.constraints import kkt
from ddsolve.dd.interface import Interface
from ddsolve.errors import SceneError
from ddsolve.fem import assembly, supports
from ddsolve.post.result import Result
from ddsolve.problem import expressions, scene
from ddsolve.problem.scene import Geometry
from experiments.hostile4_inputs import DCB_GEO

FUZZ = settings(derandomize=True, max_examples=25, deadline=None)
#: The paper's square, heated, on the structured mesh (no crack): a scene for the range checks.
HEATED = """
[geometry]
clamped = ["left"]
[mesh]
sigma_vertices = 9
boundary_vertices = 16
[materials.layer1]
E = 200.0
nu = 0.28
alpha = 2e-5
[materials.layer2]
E = 112.0
nu = 0.32
alpha = 1e-5
[temperature]
layer1 = 100.0
layer2 = 100.0
"""
MESH = structured_mesh(8, 4)


def range_refusal(overrides: list[str]) -> str | None:
    """The message of check_range on HEATED with ``overrides`` (None: accepted)."""
    try:
        assembly.check_range(scene.loads(HEATED, overrides), MESH)
    except SceneError as error:
        message = str(error)
        assert "\n" not in message, message
        return message
    return None


# --- class 1: inputs that scale the answer have no range (no MPI) -----------------------------------------------
@pytest.mark.parametrize("overrides, fragment", [
    (["temperature.layer1=1e300"], "materials.layer1.alpha with temperature.layer1 up to 1e+300"),
    (["materials.layer2.alpha=1e300"], "materials.layer2.alpha with temperature.layer2 up to 100"),
    (["materials.layer1.alpha=1e-200", "temperature.layer1=1e-200", "temperature.layer2=0.0"],
     "materials.layer1.alpha with temperature"),
    (["displacements.layer2.top.y=1e160"], "displacements.layer2.top: prescribed values up to 1e+160"),
    (["displacements.layer2.top.y=1e-300", "temperature.layer1=0.0", "temperature.layer2=0.0"],
     "displacements.layer2.top: prescribed values"),
    (["displacements.layer1.top.x=\"1e160*x\""], "displacements.layer1.top: prescribed values up to 1e+160"),
    (["materials.layer1.E=1e250", "materials.layer2.E=1e250", "displacements.layer1.top.y=1e90"],
     "gives energies of order inf"),
])
def test_displacements_and_eigenstrains_enter_the_range_check(overrides, fragment):
    message = range_refusal(overrides)
    assert message is not None and fragment in message and "outside the range a double-precision solve" in message


def test_values_in_range_pass_and_a_tiny_part_beside_a_normal_one_is_negligible():
    """The layers are glued: the structure's displacement scale is the largest of what drives either layer."""
    assert range_refusal([]) is None
    assert range_refusal(["displacements.layer1.top.y=0.001"]) is None
    assert range_refusal(["displacements.layer1.top.y=1e-300"]) is None  # the eigenstrains drive the structure
    assert range_refusal(["displacements.layer2.top.y=1e-300", "temperature.layer2=0.0"]) is None  # layer 1 drives
    assert range_refusal(["materials.layer2.alpha=1e-300"]) is None


@FUZZ
@given(st.sampled_from(["displacements.layer1.top.y", "temperature.layer1", "materials.layer1.alpha"]),
       st.integers(-330, 308), st.sampled_from([1.0, -3.0, 7.5]))
def test_every_magnitude_is_solved_in_range_or_refused_naming_its_key(key, exponent, mantissa):
    """Generator of class 1: one input over the whole range of doubles; the layer's displacement scale (the
    largest of eigenstrain × size and the prescribed value) is inside 1e-100 … 1e100 or the run is refused
    naming the key that drives it."""
    value = mantissa * 10.0 ** exponent
    others = {"temperature.layer1": 100.0, "materials.layer1.alpha": 2e-5, "displacements.layer1.top.y": 0.0,
              "temperature.layer2": 0.0}
    others[key] = value
    strain = abs(others["materials.layer1.alpha"] * others["temperature.layer1"]) * 1.28  # (1 + ν) α ΔT
    scale = max(strain * 2.0, abs(others["displacements.layer1.top.y"]))
    low, high = assembly.DISPLACEMENT_RANGE
    message = range_refusal([f"{name}={value!r}" for name, value in others.items()])
    inside = low <= scale <= high and 200.0 * scale * scale <= assembly.ENERGY_RANGE[1]
    if inside and low * 10 <= scale <= high / 10:
        assert message is None, (key, value, message)
    elif not (low / 10 <= scale <= high * 10):
        assert message is not None and key.split(".")[0] in message, (key, value, message)


def finished(energy: float, G: float = 1.0, u: float = 0.0) -> Result:
    result = Result(scene=scene.load("partial-closure"), method="reference", converged=True, iterations=1, solves=1, wall_time=0.0, ranks=1,
                    mesh=None, solution={"u_minus": np.full((3, 2), u)}, multipliers={"mu_c": np.zeros(2)},
                    history=np.zeros(0), attrs={"energy": energy})
    result.fracture = type("Tips", (), {"G": np.array([G])})()
    return result


@FUZZ
@given(st.sampled_from(["energy", "G", "u"]), st.sampled_from([math.nan, math.inf, -math.inf, 1.0, 0.0]))
def test_a_result_that_is_not_finite_is_never_converged(what, value):
    """Generator of class 1's backstop: a NaN or inf in the energy, G or a field withdraws the claim."""
    result = finished(**{"energy": 1.0, what: value})
    message = result.claim()
    assert result.converged == math.isfinite(value)
    assert bool(message) != math.isfinite(value) and ("not finite" in message or not message)


# --- class 2: keys that do nothing, fields that cannot be integrated (no MPI) ------------------------------------
ANISOTROPIC = "materials.layer1={D=[[280.0, 100.0, 0.0], [100.0, 280.0, 0.0], [0.0, 0.0, 90.0]]}"
ORTHOTROPIC = "materials.layer1={E1=200.0, E2=100.0, G12=60.0, nu12=0.3}"


@pytest.mark.parametrize("overrides, fragment", [
    (["materials.layer1={E=200.0, nu=0.28}"], "materials.layer1 has no expansion coefficient"),
    ([ORTHOTROPIC], "give materials.layer1.alpha1 or alpha2"),
    ([ANISOTROPIC], "materials.layer1 is given by its matrix D"),
])
def test_a_temperature_change_on_a_layer_without_expansion_is_refused(overrides, fragment):
    with pytest.raises(SceneError) as error:
        scene.loads(HEATED, overrides, origin="s.toml")
    assert str(error.value).startswith("s.toml: temperature.layer1: ") and fragment in str(error.value)


def test_a_zero_temperature_change_and_a_given_expansion_are_accepted():
    scene.loads(HEATED, ["materials.layer1={E=200.0, nu=0.28}", "temperature.layer1=0.0"])
    scene.loads(HEATED, [ORTHOTROPIC[:-1] + ", alpha2=1e-5}"])


def extent(text: str) -> float:
    return max(assembly.field_extent(half.points, half.cells, expressions.parse(text), "temperature.layer1")
               for half in MESH.halves)


@pytest.mark.parametrize("text", ["1/(x - 0.0301)", "-1e6*x + 1/(x - 0.0301)", "1/((x - 0.031)^2 + (y - 0.42)^2)",
                                  "3/(y - 0.013)^2", "exp(1/(x - 0.4101))", "(x - 0.0301)^-1"])
def test_a_temperature_change_unbounded_inside_the_layer_is_refused(text):
    with pytest.raises(SceneError, match=r"^temperature.layer1: the temperature change (is not finite|grows without "
                                         r"bound)"):
        extent(text)


@pytest.mark.parametrize("text, largest", [("1/(x - 1.03)", 1 / 0.03), ("100*exp(-x*x)*sin(3*y)", 100.0),
                                           ("50 + 10*x*y", 60.0), ("1/(x*x + 1)", 1.0)])
def test_a_bounded_temperature_change_gives_its_largest_value(text, largest):
    assert extent(text) == pytest.approx(largest, rel=0.02)


@FUZZ
@given(st.floats(-0.97, 0.97), st.floats(-0.97, 0.97), st.sampled_from(["1/(x - A)", "B/((x - A)^2 + (y - C)^2)",
                                                                          "5*x + 1/(y - C)", "exp(1/(x - A))"]),
       st.booleans())
def test_a_pole_inside_the_layer_is_refused_and_one_outside_is_not(a, c, form, inside):
    """Generator of class 2: poles placed inside the square (refused) or at least 0.02 outside it (bounded);
    at least 3e-7 off the mesh's lines (a pole within the resolution of doubles of a sample looks finite)."""
    a, c = round(a, 6) + 3.7e-7, round(c, 6) + 3.7e-7
    if not inside:
        a, c = math.copysign(1.02 + abs(a), a), math.copysign(1.02 + abs(c), c)
    text = form.replace("A", repr(a)).replace("B", "0.5").replace("C", repr(c))
    if inside:
        with pytest.raises(SceneError, match="temperature.layer1: the temperature change"):
            extent(text)
    else:
        assert math.isfinite(extent(text))


# --- class 3: prescribed displacements that push the crack faces through each other (no MPI) ---------------------
CRACKED = structured_mesh(8, 4, geometry=Geometry(cracks=((-0.5, 0.5),)))
PLAIN = scene.loads(HEATED)


def crack_table(lower: np.ndarray, upper: np.ndarray) -> supports.SigmaSupports:
    """The Σ supports of CRACKED with the crack nodes' normal components prescribed: ``lower`` on u⁻ and v⁻,
    ``upper`` on u⁺ and v⁺ (NaN: free)."""
    k = len(CRACKED.sigma.multiplier_nodes)
    fixed, values = np.zeros((4, 2 * k), dtype=bool), np.zeros((4, 2 * k))
    normal = 2 * np.flatnonzero(CRACKED.sigma.crack[CRACKED.sigma.multiplier_nodes]) + 1
    for blocks, prescribed in (((0, 2), lower), ((1, 3), upper)):
        for block in blocks:
            fixed[block, normal] = ~np.isnan(prescribed)
            values[block, normal] = np.nan_to_num(prescribed)
    return supports.SigmaSupports(fixed, values)


@FUZZ
@given(st.data())
def test_prescribed_faces_that_overlap_are_refused_before_work(data):
    """Generator of class 3: both faces' normal displacements prescribed at the crack nodes; refused exactly
    where the lower face moves further along the normal than the upper one."""
    count = int(CRACKED.sigma.crack[CRACKED.sigma.multiplier_nodes].sum())
    values = st.floats(-1e-2, 1e-2, allow_nan=False)
    lower = np.array(data.draw(st.lists(values, min_size=count, max_size=count)))
    upper = lower + np.array(data.draw(st.lists(st.sampled_from([-1e-3, 0.0, 1e-3]), min_size=count, max_size=count)))
    table = crack_table(lower, upper)
    if (lower > upper).any():
        with pytest.raises(SceneError, match="push the crack faces through each other"):
            supports.check_prescribed_contact(PLAIN, CRACKED, table)
    else:
        supports.check_prescribed_contact(PLAIN, CRACKED, table)
    supports.check_prescribed_contact(scene.loads(HEATED, ["contact.nonpenetration=false"]), CRACKED, table)


def test_the_kkt_check_measures_the_penetration_of_prescribed_crack_nodes():
    nodes = CRACKED.sigma.multiplier_nodes
    count = int(CRACKED.sigma.crack[nodes].sum())
    table = crack_table(np.full(count, 0.01), np.full(count, -0.01))
    interface = Interface(CRACKED.sigma.weights[nodes], CRACKED.sigma.crack[nodes], True, table.fixed, 200.0)
    assert len(interface.prescribed_contact) == count and interface.slices["mu_c"].stop == 0
    checked = kkt(interface, table.values, np.zeros(interface.size), None, np.zeros(4), 0.01)
    assert checked.penetration == pytest.approx(2.0)
    opened = kkt(interface, crack_table(np.full(count, -0.01), np.full(count, 0.01)).values,
                 np.zeros(interface.size), None, np.zeros(4), 0.01)
    assert opened.penetration == 0.0


# --- first use: mesh.target_error alone on a box (no MPI) ---------------------------------------------------------
@FUZZ
@given(st.floats(0.1, 100.0), st.floats(0.05, 10.0), st.floats(0.1, 0.9))
def test_target_error_alone_on_a_box_starts_from_a_coarse_mesh(width, height, where):
    """Generator of the first-use friction: any box and Σ, no mesh size: a coarse graded P2 first mesh."""
    text = (f"[geometry]\nbox = [0.0, {width!r}, 0.0, {height!r}]\nsigma = {where * height!r}\n[mesh]\n"
            "target_error = 0.05\n[materials.layer1]\nE = 1.0\nnu = 0.3\n[materials.layer2]\nE = 1.0\nnu = 0.3\n")
    mesh = scene.loads(text).mesh
    expected = min(width / 20, min(where, 1 - where) * height / 2)
    assert mesh.size == pytest.approx(expected) and mesh.degree == 2 and mesh.grading is not None
    with pytest.raises(SceneError, match="missing key mesh.sigma_vertices"):
        scene.loads(text.replace("target_error = 0.05", "degree = 2"))


# --- end to end: the command line (MPI) ---------------------------------------------------------------------------
#: A double cantilever whose arms' ends are pushed through each other (δ = 0.02).
CLOSING = """[mesh]
file = "dcb.geo"
size = 0.5
[materials.layer1]
E = 100.0
nu = 0.3
[materials.layer2]
E = 100.0
nu = 0.3
""" + "".join(f"[displacements.{layer}.left_{face}]\ny = {value}\n" for layer in ("layer1", "layer2")
              for face, value in (("lower", 0.01), ("upper", -0.01)))


def write_dcb(folder: Path) -> Path:
    (folder / "dcb.geo").write_text(DCB_GEO)
    path = folder / "closing.toml"
    path.write_text(CLOSING)
    return path


@pytest.mark.mpi
@pytest.mark.parametrize("command, arguments, fragment", [
    ("solve", ["partial-closure", *SMALL, "--set", "materials.layer1.alpha=1e-5", "--set", "temperature.layer1=1e300"],
     "materials.layer1.alpha with temperature.layer1 up to 1e+300"),
    ("reference", ["partial-closure", *SMALL, "--set", "geometry.clamped=[\"left\"]", "--set",
                   "displacements.layer2.right.y=1e160"], "displacements.layer2.right: prescribed values up to 1e+160"),
    ("solve", ["partial-closure", *SMALL, "--set", "temperature.layer2=100.0"], "temperature.layer2: materials.layer2 "
     "has no expansion coefficient"),
    ("solve", ["partial-closure", *SMALL, "--set", "materials.layer1.alpha=1e-5", "--set",
               "temperature.layer1=\"1/(x - 0.0301)\""], "temperature.layer1: the temperature change"),
    ("reference", ["DCB"], "the prescribed displacements push the crack faces through each other at (0, 0)"),
])
def test_the_commands_refuse_before_work_and_keep_the_previous_files(tmp_path, command, arguments, fragment):
    arguments = [str(write_dcb(tmp_path)) if word == "DCB" else word for word in arguments]
    output = tmp_path / "r.h5"
    before = previous_set(output)
    refused(ddsolve(command, *arguments, "-o", str(output), check=False), 1, fragment)
    assert unchanged(before)


@pytest.mark.mpi
def test_target_error_alone_solves_a_box_scene(tmp_path):
    path = tmp_path / "adaptive.toml"
    path.write_text("[geometry]\nbox = [0.0, 4.0, -0.5, 0.5]\ncrack = [0.0, 1.5]\nclamped = [\"right\"]\n[mesh]\n"
                    "target_error = 0.2\n[materials.layer1]\nE = 100.0\nnu = 0.3\n[materials.layer2]\nE = 100.0\n"
                    "nu = 0.3\n[loads.layer1.top]\ny = 0.001\n")
    completed = ddsolve("solve", str(path), "-o", str(tmp_path / "a.h5"))
    assert "level 0: 2,480 unknowns" in completed.stdout
    from ddsolve.io import hdf5

    result = hdf5.read(tmp_path / "a.h5")
    assert result.converged and result.scene.mesh.size == pytest.approx(0.2)


@pytest.mark.solve
def test_the_reference_writes_a_result_that_is_not_finite_as_not_converged(tmp_path, monkeypatch):
    """The claim is withdrawn where the run finishes its result, before the file is written: status 3."""
    from ddsolve.errors import NotConvergedError
    from ddsolve.io import hdf5
    from ddsolve.solvers import run

    monkeypatch.setattr(Result, "not_finite", lambda self: ["the energy"])
    with pytest.raises(NotConvergedError, match="reference: not converged: the energy is not finite") as error:
        run.reference(scene.loads(HEATED), tmp_path / "r.h5", progress=lambda line: None)
    assert error.value.exit_status == 3 and not error.value.result.converged
    assert not hdf5.read(tmp_path / "r.h5").converged
