"""Prescribed displacements (rollers, pins, displaced faces) with their reactions, and thermal loads
(issue 18 items 1 and 3): closed forms, the reference against the derivative of the energy, the DD
methods against the reference, and one-line refusals."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import MATERIALS, both_layers, ddsolve

from ddsolve.errors import DDSolveError
from ddsolve.fem import assembly
from ddsolve.io import hdf5
from ddsolve.mesh import geometry
from ddsolve.mesh.element import TRIANGLE_RULES, element_geometry
from ddsolve.mesh.mesh import HalfMesh, make_mesh
from ddsolve.post import analysis, fracture
from ddsolve.problem import expressions, scene
from ddsolve.problem.scene import Load
from ddsolve.solvers import reference

E, NU, ALPHA, DT = 200.0, 0.3, 1e-5, 100.0

SQUARE = """
[geometry]
box = [-1.0, 1.0, -1.0, 1.0]
crack = [-0.5, 0.5]
clamped = %s
[mesh]
size = 0.25
[materials]
model = "%s"
[materials.layer1]
E = 200.0
nu = 0.3
alpha = %g
[materials.layer2]
E = 200.0
nu = 0.3
alpha = 1e-5
[temperature]
layer1 = 100.0
layer2 = 100.0
"""

#: A strip 20 × 2, Σ the mid-plane, an edge crack of length 6, clamped at x = 20; both layers' arm end
#: faces at x = 0 pulled apart by ±δ/2 in y (δ = 0.01).
DCB = """
[geometry]
box = [0.0, 20.0, -1.0, 1.0]
crack = [0.0, 6.0]
clamped = ["right"]
[mesh]
size = 0.5
[materials.layer1]
E = 100.0
nu = 0.3
[materials.layer2]
E = 100.0
nu = 0.3
[displacements.layer1.left]
y = "0.005 * y"
[displacements.layer2.left]
y = "0.005 * y"
"""


def solved(source: scene.Scene, mesh=None):
    return reference.solve_monolithic(source, mesh if mesh is not None else geometry.build(source))


def moved(mesh, tip, step: float):
    halves = [HalfMesh(h.points + step * fracture.theta(tip, mesh.sigma, h.points), h.cells, h.side, h.sigma,
                       h.boundaries) for h in mesh.halves]
    return make_mesh(*halves, "moved")


def load_resultants(result) -> np.ndarray:
    """Σ over both layers of the traction loads' resultants (x, y)."""
    source, total = result.scene, np.zeros(2)
    for (layer, name), load in source.loads.items():
        for half in result.mesh.halves:
            total += assembly.boundary_load(half.points, half.edges(name), load).reshape(-1, 2).sum(axis=0)
    return total


@pytest.mark.solve
@pytest.mark.parametrize("model, expected", [("plane_strain", -E * ALPHA * DT / (1 - 2 * NU)),
                                             ("plane_stress", -E * ALPHA * DT / (1 - NU))])
def test_clamped_layers_under_uniform_heating_carry_the_closed_form_stress(model, expected):
    """Fully clamped, σxx = σyy = −EαΔT/(1 − 2ν) (plane strain) or −EαΔT/(1 − ν) (plane stress) in every
    cell to 1e-10, σxy = 0, and the reactions balance (no load): each side pushes with |σ| × its length."""
    result = solved(scene.loads(SQUARE % ('["left", "right", "top", "bottom"]', model, ALPHA)))
    for fields in analysis.cell_fields(result).values():
        assert np.abs(fields.stress[:, :2] - expected).max() <= 1e-10 * abs(expected)
        assert np.abs(fields.stress[:, 2]).max() <= 1e-10 * abs(expected)
    for layer in ("layer1", "layer2"):
        assert result.reactions[layer]["left"][0] == pytest.approx(-2.0 * expected, rel=1e-10)
    assert np.abs(result.G).max() <= 1e-12 * abs(expected)


@pytest.mark.solve
def test_free_expansion_carries_no_stress():
    """Two identical layers, the same α, uniform ΔT, on rollers: the left side (u_x = 0) and the bottom
    (u_y = 0) hold both halves' rigid motions with the top displaced by the free expansion: zero stress
    (1e-12 of EαΔT) G = 0 and Π = 0."""
    strain = (1 + NU) * ALPHA * DT  # plane strain
    text = (SQUARE % ("[]", "plane_strain", ALPHA) + "\n" + both_layers("left", "x = 0.0")
            + both_layers("bottom", "y = 0.0") + both_layers("top", f"y = {2 * strain!r}"))
    result = solved(scene.loads(text))
    for fields in analysis.cell_fields(result).values():
        assert np.abs(fields.stress).max() <= 1e-12 * E * ALPHA * DT
    assert np.abs(result.G).max() <= 1e-12 * E * ALPHA * DT * ALPHA
    x, y = result.lower.points.T
    assert np.allclose(result.solution["u_minus"], np.column_stack([strain * (x + 1), strain * (y + 1)]),
                       rtol=0, atol=1e-14)
    # No stress, no traction: the potential energy (the mechanical one, ½ ∫ (ε − ε₀):D:(ε − ε₀)) vanishes.
    assert abs(result.energy) <= 1e-12 * E * strain ** 2 * 4.0


@pytest.mark.solve
@pytest.mark.parametrize("model, strain, strain_zz", [("plane_strain", (1 + NU) * ALPHA * DT, 0.0),
                                                      ("plane_stress", ALPHA * DT, ALPHA * DT)])
def test_free_expansion_has_the_total_out_of_plane_strain(model, strain, strain_zz):
    """Free expansion on rollers (left u_x = 0, bottom u_y = 0): in every cell εxx = εyy = (1 + ν)αΔT, εzz = 0
    (plane strain) or εxx = εyy = εzz = αΔT (plane stress: σzz = 0, the thermal part included), to 1e-12."""
    text = SQUARE % ("[]", model, ALPHA) + "\n" + both_layers("left", "x = 0.0") + both_layers("bottom", "y = 0.0")
    for fields in analysis.cell_fields(solved(scene.loads(text))).values():
        assert np.abs(fields.strain - [strain, strain, 0.0]).max() <= 1e-12 * strain
        assert np.abs(fields.strain_zz - strain_zz).max() <= 1e-12 * strain


@pytest.mark.solve
@pytest.mark.parametrize("degree, temperature", [(2, "100.0"), (2, '"50.0 + 30.0 * x * y"'),
                                                 (1, '"50.0 + 30.0 * x * y"')])
def test_energy_density_integrates_to_the_strain_energy_under_heating(degree, temperature):
    """A thermal mismatch between clamped sides, no traction: Σ energy_density × area over the cells equals
    ½ ∫ (ε − ε₀):D:(ε − ε₀) integrated from the fields, and Π, to 1e-10 (P2, or a ΔT varying in the
    cell)."""
    text = SQUARE % ('["left", "right"]', "plane_strain", 3e-5)
    text = text.replace("size = 0.25", f"size = 0.25\ndegree = {degree}")
    result = solved(scene.loads(text.replace("layer1 = 100.0", f"layer1 = {temperature}")))
    total = 0.0
    for name, fields in analysis.cell_fields(result).items():
        half = result.half(name)
        area, _ = assembly.cell_strains(half.points, half.cells, result.solution[name])
        total += float(fields.energy_density @ area)
    assert total == pytest.approx(mechanical_energy(result), rel=1e-10)
    assert total == pytest.approx(result.energy, rel=1e-10)


@pytest.mark.solve
def test_g_under_a_thermal_mismatch_is_the_derivative_of_the_energy():
    """Different α per layer, clamped sides: G at each tip equals −ΔΠ/Δa (moving the nodes by ±δθ) to 1 %."""
    source = scene.loads(SQUARE % ('["left", "right"]', "plane_strain", 3e-5))
    mesh = geometry.build(source)
    G = solved(source, mesh).fracture.G
    assert np.abs(G).max() > 0
    for tip, rate in zip(fracture.find_tips(mesh), G):
        energies = [solved(source, moved(mesh, tip, s)).attrs["energy"] for s in (1e-4, -1e-4)]
        assert -(energies[0] - energies[1]) / 2e-4 == pytest.approx(rate, rel=1e-2)


@pytest.mark.solve
def test_displacement_controlled_dcb_matches_the_load_controlled_one():
    """The displaced arms' reactions, as a traction (the polynomial in y whose consistent nodal loads equal
    them), give the load-controlled DCB with the same solution: G equal to 1e-8; the reactions balance."""
    controlled = solved(scene.loads(DCB))
    reaction = {layer: controlled.reactions[layer] for layer in ("layer1", "layer2")}
    for layer in ("layer1", "layer2"):
        total = reaction[layer]["left"] + reaction[layer]["right"]
        assert np.abs(total).max() <= 1e-10 * 100.0 * 0.005  # to 1e-10 of E δ (no load: they balance)
    traction = reaction_traction(controlled)
    loaded = solved(scene.loads(DCB.split("[displacements")[0] + f"""
[loads.layer1.left]
y = "{traction}"
[loads.layer2.left]
y = "{traction}"
"""))
    assert loaded.G == pytest.approx(controlled.G, rel=1e-8)
    assert np.abs(controlled.G).max() > 0


def reaction_traction(result) -> str:
    """A polynomial traction t_y(y) on ``left`` whose consistent nodal loads are layer 1's nodal reactions there."""
    source = result.scene
    from ddsolve.post import reactions

    rows, forces = [], []
    count = sum(len(h.nodes("left")) for h in result.mesh.halves)
    for b, half in ((0, result.lower), (1, result.upper)):
        nodes = half.nodes("left")
        r = reactions.residual(source, half, "layer1", result.solution["u_minus" if b == 0 else "u_plus"], nodes)
        forces.append(r[nodes, 1])
        rows.append(np.column_stack([assembly.boundary_load(half.points, half.edges("left"), Load(
            "loads.layer1.left", y=expressions.parse(f"y^{j}"))).reshape(-1, 2)[nodes, 1] for j in range(count)]))
    coefficients = np.linalg.solve(np.vstack(rows), np.concatenate(forces))
    return " + ".join(f"({c!r})*y^{j}" for j, c in enumerate(coefficients))


#: Rollers (the left side in x, the bottom in y: Σ's end on the left is a roller node), the top displaced,
#: and a thermal mismatch: the crack opens and closes, every multiplier family works.
ROLLERS = (SQUARE % ("[]", "plane_strain", 3e-5) + "\n" + both_layers("left", "x = 0.0")
           + both_layers("bottom", "y = 0.0") + """[displacements.layer1.top]
y = "0.001 * x"
[displacements.layer2.top]
normal = 0.002
""")


#: No load: the right side clamped, both layers' left side displaced by one vector G_LEFT (Σ's left end, a
#: glued vertex, displaced with it).
DISPLACED = """
[geometry]
box = [-1.0, 1.0, -1.0, 1.0]
crack = [-0.5, 0.5]
clamped = ["right"]
[mesh]
size = 0.25
degree = %d
[materials.layer1]
E = 200.0
nu = 0.3
[materials.layer2]
E = 50.0
nu = 0.2
[displacements.layer1.left]
x = 0.01
y = -0.02
[displacements.layer2.left]
x = 0.01
y = -0.02
"""
G_LEFT = np.array([0.01, -0.02])

#: ROLLERS with a traction on the right side, whose top corner node is prescribed in y (a load f_P on a
#: prescribed dof).
PULLED = ROLLERS + """
[loads.layer1.right]
y = 0.5
"""


@pytest.mark.solve
@pytest.mark.parametrize("degree", [1, 2])
def test_energy_with_a_displaced_boundary_is_half_the_work_of_the_reactions(degree):
    """No load (Clapeyron): Π = ½ a(u, u) = ½ Σ g·R over the supports (only the displaced side moves) to 1e-10,
    and ½ Σ_b ∫ ε(u_b)ᵀ D ε(u_b) element by element agrees."""
    result = solved(scene.loads(DISPLACED % degree))
    work = 0.5 * sum(G_LEFT @ result.reactions[layer]["left"] for layer in ("layer1", "layer2"))
    assert work > 0
    assert result.energy == pytest.approx(work, rel=1e-10)
    assert result.energy == pytest.approx(0.5 * analysis.block_energies(result).sum(), rel=1e-10)


def mechanical_energy(result) -> float:
    """½ Σ_b ∫ (ε(u_b) − ε₀)ᵀ D (ε(u_b) − ε₀) − the work of the tractions, element by element from the fields."""
    source, total = result.scene, 0.0
    xi, weights = TRIANGLE_RULES[6]
    for spec in result.blocks:
        half, u = result.mesh.half(spec.side), result.solution[spec.name].reshape(-1)
        D, _ = assembly.elasticity(source, spec.layer, spec.region)
        det, gradients = element_geometry(half.points, half.cells, xi)
        strain = np.einsum("mqij,mj->mqi", assembly.strain_operator(gradients), u[assembly.element_dofs(half.cells)])
        thermal = assembly.thermal_of(source, spec.layer, spec.region)  # ε₀ = e ΔT at the points
        elastic = strain - (assembly.cell_temperatures(half.points, half.cells, thermal[1], xi)[..., None] * thermal[0]
                            if thermal is not None else 0.0)
        total += 0.5 * np.einsum("mq,q,mqi,ij,mqj->", det, weights, elastic, D, elastic)
        for load in assembly.layer_loads(source, spec.layer, half):
            total -= assembly.boundary_load(half.points, half.edges(load.boundary), load) @ u
    return float(total)


@pytest.mark.solve
@pytest.mark.parametrize("text", [ROLLERS, PULLED], ids=["rollers", "pulled"])
def test_energy_is_the_mechanical_energy_less_the_work_of_the_tractions(text):
    """Prescribed values (x, y and normal, at Σ too) and a thermal mismatch, with and without a traction:
    the result's Π equals ½ ∫ (ε − ε₀):D:(ε − ε₀) − ∫ t·u integrated from the fields, to 1e-10."""
    result = solved(scene.loads(text))
    assert result.energy == pytest.approx(mechanical_energy(result), rel=1e-10)


@pytest.mark.mpi
@pytest.mark.parametrize("method, ranks", [("schur", 4), ("schur", 8), ("feti", 4), ("mprgp", 1), ("fista", 1),
                                          ("uzawa", 1)])
def test_every_method_agrees_with_the_reference_under_displacement_control(method, ranks, tmp_path):
    """Rollers, a displaced and a normally displaced side, a thermal mismatch: each method's displacements equal
    the reference's (1e-8 of the largest for the exact schur, 1e-5 for the iterative ones), and so do the
    reactions, printed one line per boundary and layer and read back from the file, and the potential
    energy (1e-10 for schur, on 8 ranks with distributed blocks too; 1e-6 for the iterative ones at their
    default tolerances, measured 2e-10 to 4e-8)."""
    path = tmp_path / "rollers.toml"
    path.write_text(ROLLERS)
    expected = solved(scene.load(path))
    extra = ["--set", "solver.theta=auto"] if method == "uzawa" else []
    completed = ddsolve("solve", str(path), "--set", f"solver.method={method}", *extra,
                        "-o", str(tmp_path / "x.h5"), ranks=ranks, timeout=600)
    got = hdf5.read(tmp_path / "x.h5")
    scale = max(np.abs(u).max() for u in expected.solution.values())
    tolerance = 1e-8 if method == "schur" else 1e-5
    for name, u in expected.solution.items():
        assert np.abs(got.solution[name] - u).max() <= tolerance * scale, name
    for layer, named in expected.reactions.items():
        for name, force in named.items():
            assert np.abs(got.reactions[layer][name] - force).max() <= 1e2 * tolerance * np.abs(force).max() + 1e-12
            assert f"reaction on {layer} at {name}: " in completed.stdout
    assert got.energy == pytest.approx(expected.energy, rel=1e-10 if method == "schur" else 1e-6)


@pytest.mark.solve
@pytest.mark.parametrize("override, message", [
    ("displacements.layer1.side.y=0.0", "displacements.layer1.side: no boundary named 'side'"),
    ("temperature.layer3=1.0", "unknown key temperature.layer3"),
    ("displacements.layer1.top={normal = 0.0, x = 0.0}", "displacements.layer1.top: normal excludes x and y"),
    ("loads.layer1.top.y=1.0", "displacements.layer1.top.y: boundary 'top' of layer1 is also loaded in that "
                               "direction (loads.layer1.top.y)"),
    ("displacements.layer1.left.x=0.0", "displacements.layer1.left: boundary 'left' is clamped"),
    ("materials.layer1={D = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], alpha = 1e-5}",
     "unknown key materials.layer1.alpha"),
    ("materials.layer1.alpha1=1e-5", "unknown key materials.layer1.alpha1 (did you mean materials.layer1.alpha?)"),
    ("materials.layer2={E1 = 100.0, E2 = 50.0, G12 = 20.0, nu12 = 0.3, alpha = 1e-5}",
     "unknown key materials.layer2.alpha (did you mean materials.layer2.alpha2?)"),
])
def test_bad_supports_and_thermal_keys_are_refused_naming_the_key(override, message):
    text = SQUARE % ('["left", "right"]', "plane_strain", ALPHA) + "[displacements.layer1.top]\ny = 0.001\n"
    with pytest.raises(DDSolveError) as caught:
        source = scene.loads(text, [override])
        solved(source)
    assert message in str(caught.value) and "\n" not in str(caught.value)


@pytest.mark.solve
def test_a_half_on_one_roller_floats_and_is_solved():
    """The upper half on one roller (u_y = 0 on top) can translate in x on its own: its blocks float, held
    through Σ, and the structure is solved; the roller carries no force along itself."""
    text = SQUARE % ('["bottom"]', "plane_strain", ALPHA) + "[displacements.layer1.top]\ny = 0.0\n" \
        "[displacements.layer2.top]\ny = 0.0\n"
    floating = solved(scene.loads(text))
    assert floating.converged
    for layer in ("layer1", "layer2"):
        assert abs(floating.reactions[layer]["top"][0]) <= 1e-12 * E * ALPHA * DT  # a roller carries no x force
        assert floating.reactions[layer]["top"][1] != 0.0


#: A 4 × 2 bar without a crack pulled in x on rollers: x = 0 on the left (both layers), y = 0 on layer 1's
#: bottom; the rollers meet at the corner (0, −1).
BAR = """
[geometry]
box = [0.0, 4.0, -1.0, 1.0]
cracks = []
clamped = []
[mesh]
size = 0.25
degree = 1
[loads.layer1.right]
x = 0.01
[loads.layer2.right]
x = 0.01
""" + MATERIALS + both_layers("left", "x = 0.0") + "[displacements.layer1.bottom]\ny = 0.0\n"

#: Clamped sides and a roller (y = 0) on layer 2's bottom between them, under a thermal mismatch alone:
#: at the bottom corners Γ_D wins.
HEATED = SQUARE % ('["left", "right"]', "plane_strain", 3e-5) + "[displacements.layer2.bottom]\ny = 0.0\n"


@pytest.mark.solve
@pytest.mark.parametrize("text, along", [
    (BAR, [("layer1", "left", 1), ("layer2", "left", 1), ("layer1", "bottom", 0)]),
    (HEATED, [("layer2", "bottom", 0)]),
], ids=["rollers", "clamped"])
def test_each_boundary_reports_only_the_directions_it_prescribes(text, along):
    """Where two supported boundaries meet, each counts the force of the shared node only in the directions
    it prescribes there: a roller reports exactly 0 along itself, and the reactions balance the loads in x
    and y to round-off."""
    result = solved(scene.loads(text))
    for layer, name, direction in along:
        assert result.reactions[layer][name][direction] == 0.0
    forces = [force for named in result.reactions.values() for force in named.values()]
    largest = max(np.abs(force).max() for force in forces)
    assert largest > 0 and np.abs(sum(forces) + load_resultants(result)).max() <= 1e-12 * largest
