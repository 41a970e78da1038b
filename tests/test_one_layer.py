"""One-layer structures (``geometry.layers = 1``, issue 36 item 2): one body cut by Σ, the blocks u⁻ and u⁺ coupled
on Σ only (μᶜ on the crack, μᵍ elsewhere).

Two identical sheets glued on Σ are one sheet of their summed stiffness: the two-layer structure whose layers have
the modulus E/2 and carry the tractions f/2 each has u = v = the one-layer structure's solution under E and f (its
energy is the mean of the two layers' one-layer energies, smallest when both take that solution, which every
constraint admits).  The tests hold every output to that, to round-off.
"""
from __future__ import annotations

import math
from pathlib import Path

import launch_many
import meshio
import numpy as np
import pytest
from conftest import ddsolve, refused, solved_reference
from test_mpi import TIGHT

from ddsolve.dd.interface import Interface
from ddsolve.errors import DDSolveError, SceneError, UsageError
from ddsolve.io import hdf5
from ddsolve.mesh.mesh import blocks, glued_layers
from ddsolve.parallel import launch
from ddsolve.post import analysis
from ddsolve.problem import scene as scenes

#: The paper's square with its crack and contact, on a small mesh; ``{materials}`` and ``{loads}`` per structure.
BOX = """title = "{title}"
[geometry]
crack = [-0.5, 0.5]
layers = {layers}
{geometry}
[mesh]
sigma_vertices = 25
boundary_vertices = 48
degree = {degree}
[contact]
nonpenetration = true
[solver]
theta = "auto"
[fracture]
toughness = 1e-6
{materials}
{loads}
"""
#: Layer 1's tractions of Example 1 (polynomial coefficients in x) and a shear on the top of the floating case.
PAPER_LOADS = {"bottom": {"y": [0.0, 0.078125]}, "top": {"y": [0.0, -0.078125]}}
FLOATING_LOADS = {"top": {"x": [0.004], "y": [0.0, -0.078125]}}


def structure(layers: int, degree: int = 1, loads: dict = PAPER_LOADS, geometry: str = "", upper: float | None = None
              ) -> str:
    """The one-layer structure (E = 200, ν = 0.28, the tractions ``loads``) or its two-layer twin (two layers of
    E/2, each with half the tractions); ``upper``: the modulus of the upper region where it differs."""
    share = 1.0 / layers
    names = [f"layer{n}" for n in range(1, layers + 1)]
    materials = "".join(f"[materials.{name}]\nE = {200.0 * share!r}\nnu = 0.28\n"
                        + ("" if upper is None else f"[materials.{name}.upper]\nE = {upper * share!r}\n")
                        for name in names)
    tractions = "".join(f"[loads.{name}.{side}]\n" + "".join(f"{part} = {[c * share for c in coefficients]!r}\n"
                                                            for part, coefficients in parts.items())
                        for name in names for side, parts in loads.items())
    return BOX.format(title=f"{layers} layers", layers=layers, geometry=geometry, degree=degree, materials=materials,
                      loads=tractions)


def reference(text: str):
    from ddsolve.mesh import geometry
    from ddsolve.solvers.reference import solve_monolithic

    scene = scenes.loads(text)
    return solve_monolithic(scene, geometry.build(scene))


def close(a, b, scale: float | None = None) -> float:
    """max |a − b| relative to ``scale`` (default: max |b|)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.abs(a - b).max(initial=0.0) / (scale or np.abs(b).max(initial=0.0) or 1.0))


def summed_reactions(result) -> dict[str, np.ndarray]:
    """Boundary -> the reaction summed over the layers."""
    out: dict[str, np.ndarray] = {}
    for named in result.reactions.values():
        for name, force in named.items():
            out[name] = out.get(name, np.zeros(2)) + force
    return out


CASES = {"the paper's box": {}, "P2": {"degree": 2}, "floating upper half": {
    "loads": FLOATING_LOADS, "geometry": 'clamped = ["bottom"]'}, "different regions": {"upper": 400.0}}


@pytest.mark.solve
@pytest.mark.parametrize("case", CASES)
def test_one_layer_is_two_identical_glued_layers_of_half_the_stiffness(case):
    one, two = (reference(structure(layers, **CASES[case])) for layers in (1, 2))
    assert [spec.name for spec in one.blocks] == ["u_minus", "u_plus"] and set(one.multipliers) == {"mu_c", "mu_g"}
    assert one.converged and two.converged and one.attrs["closed_vertices"] == two.attrs["closed_vertices"]
    assert close(one.energy, two.energy) < 1e-10
    largest = max(np.abs(u).max() for u in two.solution.values())
    for name in ("u_minus", "u_plus"):
        assert close(one.solution[name], two.solution[name], largest) < 1e-10
        assert close(two.solution["v" + name[1:]], two.solution[name], largest) < 1e-10  # the sheets move together
    assert close(one.multipliers["mu_c"], two.multipliers["mu_c"]) < 1e-9
    assert len(one.G) == len(two.G) == 2 and close(one.G, two.G) < 1e-9
    fracture, twin = one.fracture, two.fracture
    finite = np.isfinite(twin.critical_factor)  # inf: a tip that never grows
    assert np.array_equal(np.isfinite(fracture.critical_factor), finite) and finite.any()
    assert close(fracture.critical_factor[finite], twin.critical_factor[finite]) < 1e-9
    assert close(fracture.G_I, twin.G_I, max(one.G)) < 1e-9 and close(fracture.G_II, twin.G_II, max(one.G)) < 1e-9
    if case == "different regions":  # the interface crack's ε, K and ψ
        assert np.all(np.abs(fracture.epsilon) > 0.02) and close(fracture.epsilon, twin.epsilon) < 1e-12
        assert close(fracture.K, twin.K) < 1e-9 and close(fracture.phase, twin.phase) < 1e-9
    reactions, summed = one.reactions["layer1"], summed_reactions(two)
    assert list(one.reactions) == ["layer1"] and reactions.keys() == summed.keys()
    scale = max(np.abs(force).max() for force in summed.values())
    for name, force in summed.items():
        assert close(reactions[name], force, scale) < 1e-9


@pytest.mark.solve
def test_the_griffith_crack_in_one_layer():
    """A crack of length 2a = 1 in a square of side 20, pulled by σ = 1 on its top and bottom: G = πaσ²(1 − ν²)/E
    in plane strain for the infinite plate.  The finite width raises it by about sec(πa/W) − 1 = 0.3 % (Feddersen's
    correction, half-width W = 10; the finite height changes it a little too); with graded P2 elements G comes
    0.14 % above the infinite plate's value at both tips: within 0.5 % of it."""
    text = """[geometry]
layers = 1
box = [-10.0, 10.0, -10.0, 10.0]
crack = [-0.5, 0.5]
clamped = []
[mesh]
size = 1.0
grading = true
degree = 2
[materials.layer1]
E = 1.0
nu = 0.3
[loads.layer1.top]
y = 1.0
[loads.layer1.bottom]
y = -1.0
[displacements.layer1.pin]
point = [-10.0, 0.0]
x = 0.0
y = 0.0
[displacements.layer1.roller]
point = [10.0, 0.0]
y = 0.0
"""
    result = reference(text)
    closed = math.pi * 0.5 * (1.0 - 0.3 ** 2) / 1.0
    assert result.converged and np.all(np.abs(result.G / closed - 1.0) < 5e-3), result.G / closed
    assert np.all(np.abs(result.fracture.phase) < 0.5)  # mode I


METHODS = {**TIGHT, "auto": []}


@pytest.fixture(scope="module")
def one_layer(tmp_path_factory) -> tuple[Path, Path]:
    """The one-layer paper box's scene file and its reference result."""
    folder = tmp_path_factory.mktemp("one-layer")
    scene = folder / "one.toml"
    scene.write_text(structure(1))
    solved_reference(str(scene), "-o", str(folder / "reference.h5"))
    return scene, folder / "reference.h5"


@pytest.fixture(scope="module")
def every_method(one_layer) -> dict[tuple[str, int], Path]:
    """The one-layer box by each of METHODS on 1 and 2 ranks, one launch per rank count: the result paths."""
    scene, _ = one_layer
    folder = scene.parent
    paths = {(method, ranks): folder / f"{method}-{ranks}.h5" for method in METHODS for ranks in (1, 2)}
    for ranks in (1, 2):
        launch_many.launch([["solve", str(scene), *METHODS[method], "-o", str(paths[method, ranks])]
                            for method in METHODS], ranks, folder)
    return paths


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 2])
@pytest.mark.parametrize("method", METHODS)
def test_every_method_equals_the_reference(one_layer, every_method, method, ranks):
    result, expected = hdf5.read(every_method[method, ranks]), hdf5.read(one_layer[1])
    assert result.converged and result.ranks == ranks and len(result.blocks) == 2
    assert method == "auto" or result.method == method
    assert analysis.compare(result, expected).energy_error < 1e-8
    assert close(result.G, expected.G) < 1e-6
    assert close(result.fracture.critical_factor[0], expected.fracture.critical_factor[0]) < 1e-6
    checks = analysis.constraints(result)
    assert checks.gluing_gap < 1e-9 and checks.penetration < 1e-9 and checks.min_mu_c >= 0.0


@pytest.mark.mpi
def test_floating_blocks_and_four_ranks(tmp_path):
    """The upper half held only through Σ (u⁺ floats) on 2 ranks, and two ranks per block on 4 (the ranks write
    the files together where h5py can)."""
    scene = tmp_path / "floating.toml"
    scene.write_text(structure(1, loads=FLOATING_LOADS, geometry='clamped = ["bottom"]'))
    solved_reference(str(scene), "-o", str(tmp_path / "reference.h5"))
    expected = hdf5.read(tmp_path / "reference.h5")
    runs = {2: ("schur", "feti"), 4: ("schur",)}  # one launch per rank count
    for ranks, methods in runs.items():
        launch_many.launch([["solve", str(scene), *TIGHT[method], "-o", str(tmp_path / f"{method}-{ranks}.h5")]
                            for method in methods], ranks, tmp_path)
    for method, ranks in (("schur", 2), ("feti", 2), ("schur", 4)):
        result = hdf5.read(tmp_path / f"{method}-{ranks}.h5")
        assert result.converged and result.ranks == ranks
        assert analysis.compare(result, expected).energy_error < 1e-8 and close(result.G, expected.G) < 1e-6
    refused(ddsolve("solve", str(scene), "-n", "3", "-o", str(tmp_path / "three.h5"), check=False), 2,
            "-n 3: unsupported number of ranks: use 1 or a multiple of 2")


@pytest.mark.mpi
def test_outputs_growth_sweeps_and_adaptivity(tmp_path, one_layer):
    """The result set of a one-layer solve (no mu_minus, mu_plus datasets, no layer2 viewer file) read back; the
    grow, sweep and adaptive commands on a one-layer structure."""
    scene, _ = one_layer
    output = tmp_path / "one.h5"
    ddsolve("solve", str(scene), "-o", str(output), ranks=2)
    result = hdf5.read(output)
    assert set(result.multipliers) == {"mu_c", "mu_g"} and set(result.solution) == {"u_minus", "u_plus"}
    assert sorted(path.name for path in tmp_path.iterdir()) == ["one-layer1.vtu", "one-paraview.py",
                                                                 "one-sigma.vtu", "one.h5"]
    layer = meshio.read(tmp_path / "one-layer1.vtu")
    assert len(layer.points) == len(result.lower.points) + len(result.upper.points) - (~result.mesh.sigma.crack).sum()
    assert "mu_minus" not in meshio.read(tmp_path / "one-sigma.vtu").point_data
    compile((tmp_path / "one-paraview.py").read_text(), "paraview", "exec")
    exported = tmp_path / "xdmf"
    exported.mkdir()
    ddsolve("export", str(output), "--format", "xdmf", "-o", str(exported))
    assert sorted(path.name for path in exported.iterdir()) == ["one-layer1.xdmf", "one-paraview.py",
                                                               "one-sigma.xdmf", "one-xdmf.h5"]
    ddsolve("plot", str(output))
    assert (tmp_path / "one-deformed.png").stat().st_size > 0

    sweep = ddsolve("sweep", str(scene), "--set", "materials.layer1.E=150:250:2", "-o", str(tmp_path / "sweep.h5"),
                    ranks=2)
    assert "2 runs (2 converged)" in sweep.stdout

    adaptive = tmp_path / "adaptive.toml"
    adaptive.write_text(scene.read_text().replace("sigma_vertices = 25\nboundary_vertices = 48\ndegree = 1",
                                                  "target_error = 0.01"))
    ddsolve("solve", str(adaptive), "-o", str(tmp_path / "adaptive.h5"), ranks=2)
    refined = hdf5.read(tmp_path / "adaptive.h5")
    assert refined.error_estimate <= 0.01 and len(refined.levels["unknowns"]) > 1
    assert refined.levels["unknowns"][-1] == refined.unknowns == 2 * (len(refined.lower.points)
                                                                      + len(refined.upper.points))


DCB = """title = "one-layer DCB"
[geometry]
layers = {layers}
box = [0.0, 6.0, -0.5, 0.5]
crack = [0.0, 2.0]
clamped = ["right"]
[mesh]
size = 0.25
{materials}
[fracture]
toughness = 1e-3
"""


@pytest.mark.solve
def test_growth_of_a_one_layer_dcb_is_that_of_its_two_layer_twin():
    """The DCB's arms opened at their ends (displacement control): initiation at the same factor as the two-layer
    twin of half the stiffness per layer, and stable growth beyond it."""
    from mpi4py import MPI

    from ddsolve.solvers import grow

    def dcb(layers: int) -> scenes.Scene:
        names = [f"layer{n}" for n in range(1, layers + 1)]
        materials = "".join(f"[materials.{name}]\nE = {100.0 / layers!r}\nnu = 0.3\n"
                            f"[displacements.{name}.opener]\npoint = [0.0, 0.5]\ny = 0.01\n"
                            f"[displacements.{name}.closer]\npoint = [0.0, -0.5]\ny = -0.01\n" for name in names)
        return scenes.loads(DCB.format(layers=layers, materials=materials))

    runs = [grow.grow(dcb(layers), MPI.COMM_SELF, 8.0, 3, 1e-6, progress=lambda _: None) for layers in (1, 2)]
    initiations = [next(step for step in steps if step.events and step.events[0].startswith("initiation"))
                   for steps in runs]
    assert close(initiations[0].state.control, initiations[1].state.control) < 1e-6
    assert runs[0][-1].state.cracks[0][1] > 2.3 and abs(runs[0][-1].state.cracks[0][1]
                                                        - runs[1][-1].state.cracks[0][1]) < 1e-4


# --- bad input and the pieces -----------------------------------------------------------------------
ONE = structure(1)


@pytest.mark.parametrize("value", ["0", "3", '"1"', "1.0"])
def test_layers_other_than_1_or_2_are_refused_naming_the_key(value):
    with pytest.raises(SceneError, match=r"geometry\.layers must be") as error:
        scenes.loads(ONE.replace("layers = 1", f"layers = {value}"))
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("extra, key", [
    ("[materials.layer2]\nE = 100.0\nnu = 0.3\n", "materials.layer2"),
    ("[materials.layer2.lower]\nE = 100.0\n", "materials.layer2.lower"),
    ("[loads.layer2.top]\ny = 1.0\n", "loads.layer2"),
    ("[displacements.layer2.top]\ny = 0.0\n", "displacements.layer2"),
    ("[temperature]\nlayer2 = 10.0\n", "temperature.layer2")])
def test_a_layer2_table_on_one_layer_is_refused_naming_it(extra, key):
    with pytest.raises(SceneError) as error:
        scenes.loads(ONE + extra)
    message = str(error.value)
    assert "\n" not in message and f": {key}" in message and "geometry.layers = 1" in message
    with pytest.raises(SceneError, match="materials.layer2: a structure of 1 layer"):  # an override too
        scenes.loads(ONE, ["materials.layer2.E=1.0"])


def test_a_one_layer_scene_has_one_material_and_keeps_its_key_through_its_text():
    scene = scenes.loads(ONE)
    assert scene.geometry.layers == 1 and scene.layers == ("layer1",) and list(scene.materials) == ["layer1"]
    assert scenes.loads(scene.text).geometry.layers == 1
    assert scenes.loads(structure(2)).layers == ("layer1", "layer2")


def test_the_interface_of_one_layer_has_the_sigma_families_only():
    specs = blocks(1)
    assert [spec.name for spec in specs] == ["u_minus", "u_plus"] and glued_layers(specs) == []
    assert glued_layers(blocks(2)) == [(0, 2), (1, 3)]
    crack = np.array([False, True, True, False])
    one = Interface(np.full(4, 0.5), crack, True, specs=specs)
    assert list(one.slices) == ["mu_c", "mu_g"] and one.size == 2 + 2 * 2
    assert one.trace_unknowns().shape == (2, 8)
    lam = np.arange(1.0, one.size + 1.0)
    assert np.allclose(one.multipliers(one.loads(lam)), lam)
    traces = np.random.default_rng(0).normal(size=(2, 8))
    assert np.allclose(one.gap(traces) @ (one.row_weights * lam), -np.sum(one.loads(lam) * traces))
    split = one.split(lam)
    assert set(split) == {"mu_c", "mu_g"}


def test_the_ranks_two_blocks_use():
    """1 and 2 ranks hold whole blocks, 2k ranks share each block among k; 3 cannot be used (one line)."""
    assert [launch.supported(size, 2) for size in (1, 2, 3, 4, 6)] == [True, True, False, True, True]
    assert [launch.leader(1, size, 2) for size in (1, 2, 4, 6)] == [0, 1, 2, 3]
    assert [launch.leader(1, size) for size in (1, 2, 4, 8)] == [0, 1, 1, 2]  # four blocks: as before
    assert launch.usable(2) == "1 or a multiple of 2" and launch.usable(4) == "1, 2 or a multiple of 4"
    from ddsolve.solvers.checks import check_ranks

    with pytest.raises(UsageError, match=r"^-n 3: unsupported number of ranks: use 1 or a multiple of 2$"):
        check_ranks(3, 2)
    check_ranks(6, 2)
    with pytest.raises(UsageError, match="multiple of 4"):
        check_ranks(6, 4)


@pytest.mark.solve
def test_results_of_different_structures_are_not_compared():
    one, two = reference(structure(1)), reference(structure(2))
    with pytest.raises(DDSolveError, match="different structures"):
        analysis.compare(one, two)
