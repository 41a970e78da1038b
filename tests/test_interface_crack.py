"""An interface crack between different materials: ε, the bimaterial tip fields, K by the interaction integral,
ψ at the reference length; the Griffith interface crack against its closed form; the DD against the reference."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SMALL, ddsolve, solved_reference

from ddsolve.errors import SceneError
from ddsolve.post import fracture, interface_crack
from ddsolve.problem import materials, scene
from ddsolve.problem.materials import Bimaterial

NU = 0.3
KAPPA = 3.0 - 4.0 * NU


def pair_of(ratio: float) -> Bimaterial:
    """Plane strain, ν = 0.3, the upper material ``ratio`` × stiffer than the lower (E = 1)."""
    return Bimaterial(lower=(1.0 / (2.0 * (1.0 + NU)), KAPPA), upper=(ratio / (2.0 * (1.0 + NU)), KAPPA))


def stresses(x, y, pair: Bimaterial, epsilon: float, side: int) -> np.ndarray:
    """``(2, ..., 3)`` Voigt stresses of the tip fields of K = 1 and K = i in the material on ``side``."""
    shear, kappa = pair.upper if side > 0 else pair.lower
    lame = shear * (3.0 - kappa) / (kappa - 1.0)
    D = np.array([[lame + 2 * shear, lame, 0.0], [lame, lame + 2 * shear, 0.0], [0.0, 0.0, shear]])
    grad = interface_crack.tip_gradients(x, y, shear, kappa, epsilon, side)
    strain = np.stack([grad[..., 0, 0], grad[..., 1, 1], grad[..., 0, 1] + grad[..., 1, 0]], axis=-1)
    return strain @ D.T


@pytest.mark.unit
def test_epsilon_is_the_dundurs_index_and_changes_sign_with_the_frame():
    pair = pair_of(10.0)
    mu_1, mu_2 = pair.upper[0], pair.lower[0]
    expected = math.log((KAPPA / mu_1 + 1.0 / mu_2) / (KAPPA / mu_2 + 1.0 / mu_1)) / (2.0 * math.pi)
    assert interface_crack.oscillation(pair) == pytest.approx(expected, rel=1e-14) == pytest.approx(-0.0758118, 1e-6)
    assert interface_crack.oscillation(pair, upper_first=False) == pytest.approx(-expected, rel=1e-14)
    assert interface_crack.oscillation(pair_of(1.0)) == 0.0
    # 2/E* = 1/Ē₁ + 1/Ē₂ with Ē = E/(1 − ν²)
    assert interface_crack.modulus(pair) == pytest.approx(2.0 / ((1.0 - NU ** 2) * (1.0 / 10.0 + 1.0)), rel=1e-14)


@pytest.mark.unit
def test_the_pair_of_the_layers_sums_proportional_sheets_and_refuses_the_rest():
    def D(E, nu=NU):
        return materials.elasticity(materials.Isotropic(E, nu))[0]

    pair = materials.interface_pair([D(1.0), D(3.0)], [D(10.0), D(30.0)])  # layer 2 = 3 × layer 1
    assert pair.lower[0] == pytest.approx(4.0 / (2.0 * 1.3)) and pair.upper[1] == pytest.approx(KAPPA)
    assert "not proportional" in materials.interface_pair([D(1.0), D(1.0)], [D(10.0), D(20.0)])
    assert "not proportional" in materials.interface_pair([D(1.0), D(1.0, 0.2)], [D(10.0), D(10.0, 0.2)])
    orthotropic = materials.elasticity(materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3))[0]
    assert "not isotropic" in materials.interface_pair([D(1.0), D(1.0)], [orthotropic, orthotropic])
    stress = materials.elasticity(materials.Isotropic(1.0, NU), "plane_stress")[0]
    assert materials.interface_pair([stress], [stress]).lower[1] == pytest.approx((3.0 - NU) / (1.0 + NU))


@pytest.mark.unit
@pytest.mark.parametrize("ratio", [1.0, 10.0, 100.0])
def test_the_tip_fields_load_the_interface_as_k_r_to_the_i_epsilon_and_leave_the_faces_free(ratio):
    pair = pair_of(ratio)
    epsilon = interface_crack.oscillation(pair)
    r = np.array([1e-3, 0.1, 1.0, 7.0])
    expected = r ** (1j * epsilon) / np.sqrt(2.0 * math.pi * r)
    for side in (1, -1):
        ahead = stresses(r, side * 1e-13 * r, pair, epsilon, side)
        for k, K in enumerate((1.0, 1j)):  # σ_yy + iσ_xy = K r^{iε}/√(2πr) on both sides of the interface
            assert np.allclose((ahead[k, :, 1] + 1j * ahead[k, :, 2]) / expected, K, atol=1e-9)
        faces = stresses(-r, side * 1e-12 * r, pair, epsilon, side)
        assert np.abs(faces[..., 1:]).max() < 1e-9 * np.abs(ahead).max()  # σ_yy = σ_xy = 0 on the faces
    shear, kappa = pair.upper
    above = np.stack(interface_crack.tip_field(r, 1e-15 * r, shear, kappa, epsilon, 1))
    below = np.stack(interface_crack.tip_field(r, -1e-15 * r, *pair.lower, epsilon, -1))
    assert np.allclose(above, below, atol=1e-12)  # the interface ahead stays bonded


@pytest.mark.unit
def test_at_epsilon_zero_the_tip_field_is_williams():
    shear, kappa = 0.4, KAPPA
    r, angle = 0.3, np.linspace(-3.0, 3.0, 13)
    x, y = r * np.cos(angle), r * np.sin(angle)
    sides = np.where(angle >= 0.0, 1, -1)
    opening = np.stack([interface_crack.tip_field(x[i], y[i], shear, kappa, 0.0, sides[i])[0] for i in range(13)])
    scale = math.sqrt(r / (2.0 * math.pi)) / (2.0 * shear)
    williams = scale * np.stack([np.cos(angle / 2) * (kappa - 1 + 2 * np.sin(angle / 2) ** 2),
                                 np.sin(angle / 2) * (kappa + 1 - 2 * np.cos(angle / 2) ** 2)], axis=-1)
    assert np.allclose(opening, williams, rtol=1e-12, atol=1e-14)


def annulus_integral(pair: Bimaterial, epsilon: float, K: complex, inner: float = 0.2, outer: float = 0.6) -> float:
    """The domain integral of G (θ = φ(r) e_x, φ linear from 1 at ``inner`` to 0 at ``outer``) of the tip field
    of ``K`` by Gauss quadrature in r and in the angle on each side."""
    nodes, weights = np.polynomial.legendre.leggauss(40)
    total = 0.0
    for side, (low, high) in ((1, (0.0, math.pi)), (-1, (-math.pi, 0.0))):
        r = inner + (outer - inner) * (nodes + 1) / 2
        angle = low + (high - low) * (nodes + 1) / 2
        R, A = np.meshgrid(r, angle, indexing="ij")
        x, y = R * np.cos(A), R * np.sin(A)
        grads = interface_crack.tip_gradients(x, y, *(pair.upper if side > 0 else pair.lower), epsilon, side)
        grad = K.real * grads[0] + K.imag * grads[1]
        unit = stresses(x, y, pair, epsilon, side)
        voigt = K.real * unit[0] + K.imag * unit[1]
        sigma = fracture.tensor(voigt)
        density = 0.5 * (voigt[..., 0] * grad[..., 0, 0] + voigt[..., 1] * grad[..., 1, 1]
                         + voigt[..., 2] * (grad[..., 0, 1] + grad[..., 1, 0]))
        slope = -1.0 / (outer - inner)
        dphi = np.stack([slope * x / R, slope * y / R], -1)  # φ_,j
        momentum = np.einsum("...ij,...i->...j", sigma, grad[..., :, 0])  # σ_ij u_i,1
        integrand = np.einsum("...j,...j->...", momentum, dphi) - density * dphi[..., 0]
        jacobian = R * (outer - inner) / 2 * (high - low) / 2
        total += float(np.einsum("i,j,ij->", weights, weights, integrand * jacobian))
    return total


@pytest.mark.unit
@pytest.mark.parametrize("ratio", [1.0, 10.0, 100.0])
def test_the_domain_integral_of_the_tip_field_is_its_known_g(ratio):
    """G = |K|²/(E* cosh²πε) of the tip field itself, and the cross term of two fields is 2 Re(K K̃*)/(E* cosh²πε):
    what the interaction integral reads K from."""
    pair = pair_of(ratio)
    epsilon = interface_crack.oscillation(pair)
    for K in (1.0 + 0j, 1j, 0.3 - 1.7j):
        assert annulus_integral(pair, epsilon, K) == pytest.approx(interface_crack.release(np.array([K]), epsilon,
                                                                                           pair)[0], rel=1e-9)
    K, other = 0.3 - 1.7j, 1.0 + 0j
    cross = annulus_integral(pair, epsilon, K + other) - annulus_integral(pair, epsilon, K) \
        - annulus_integral(pair, epsilon, other)
    assert interface_crack.intensity(np.array([cross, 0.0]), epsilon, pair).real == pytest.approx(K.real, rel=1e-9)


@pytest.mark.unit
def test_the_phase_turns_by_epsilon_ln_l():
    K, epsilon = 2.0 * np.exp(0.3j), -0.08
    assert interface_crack.phase(K, epsilon, 1.0) == pytest.approx(math.degrees(0.3))
    assert interface_crack.phase(K, epsilon, 2.0) == pytest.approx(math.degrees(0.3 + epsilon * math.log(2.0)))


@pytest.mark.unit
def test_the_reference_length_is_a_positive_key_and_a_law_needs_a_pair():
    text = _text(10.0, layers=2)
    assert interface_crack.reference_length(scene.loads(text)) == 1.0
    assert interface_crack.reference_length(scene.loads(text, ["fracture.reference_length=2.0"])) == 2.0
    with pytest.raises(SceneError, match="fracture.reference_length"):
        scene.loads(text, ["fracture.reference_length=-1.0"])
    law = ["fracture.law=hutchinson-suo", "fracture.G_Ic=1e-6", "fracture.lambda=0.3"]
    assert scene.loads(text, law).fracture.law == "hutchinson-suo"  # the pair's ψ: defined
    with pytest.raises(SceneError, match="not proportional"):
        scene.loads(text, [*law, "materials.layer2.upper.E=20.0"])


def _text(ratio: float, size: float = 4.0, layers: int = 1) -> str:
    from experiments import interface_crack as griffith

    return griffith.scene_text(ratio, size, layers=layers)


@pytest.mark.solve
@pytest.mark.parametrize("ratio", [10.0, 100.0])
def test_the_griffith_interface_crack_against_its_closed_form(ratio):
    """A coarse mesh (the tip's Σ edges 0.074a): G within 2 %, ψ(2a) within 1.5° of atan 2ε, and G from |K| (the
    interaction integral) within 1 % of the domain integral's G."""
    from experiments import interface_crack as griffith

    row = griffith.griffith(ratio, 4.0)
    assert abs(row["error"]) < 0.02 and abs(row["phase"] - row["phase_theory"]) < 1.5
    assert row["epsilon"] == pytest.approx(row["epsilon_theory"], rel=1e-12)
    assert row["G_of_K"] == pytest.approx(row["G"], rel=0.01)


@pytest.mark.solve
def test_equal_materials_keep_the_classical_split_and_epsilon_zero():
    from ddsolve.mesh import geometry
    from ddsolve.solvers import reference

    source = scene.loads(_text(1.0))
    result = reference.solve_monolithic(source, geometry.build(source)).fracture
    assert interface_crack.interface_pair(source) is None and result.symmetric[0] and result.epsilon[0] == 0.0
    assert np.isnan(result.K).all() and abs(result.phase[0]) < 0.5  # pure mode I up to the coarse mesh


@pytest.mark.mpi
def test_dd_equals_the_reference_for_an_interface_crack(tmp_path):
    """partial-closure with both layers the same pair, the upper region 10× stiffer: energies, G, K and ψ."""
    options = [*SMALL]
    for item in ("materials.layer2.E=200.0", "materials.layer2.nu=0.28", "materials.layer1.upper.E=2000.0",
                 "materials.layer2.upper.E=2000.0", "fracture.reference_length=0.5"):
        options += ["--set", item]
    ddsolve("solve", "partial-closure", *options, "-o", str(tmp_path / "dd.h5"), ranks=4)
    solved_reference("partial-closure", *options, "-o", str(tmp_path / "reference.h5"))
    from ddsolve.io import hdf5
    from ddsolve.post import analysis

    result, exact = hdf5.read(tmp_path / "dd.h5"), hdf5.read(tmp_path / "reference.h5")
    assert result.converged and analysis.compare(result, exact).energy_error < 1e-8
    dd, ref = result.fracture, exact.fracture
    assert dd.reference_length == 0.5 and np.all(np.isfinite(ref.K[ref.released()]))
    assert np.allclose(dd.G, ref.G, rtol=1e-6) and np.allclose(dd.epsilon, ref.epsilon, rtol=1e-12)
    assert np.allclose(dd.K, ref.K, rtol=1e-5, atol=1e-8 * np.abs(ref.K).max())
    assert np.allclose(dd.phase[ref.released()], ref.phase[ref.released()], atol=1e-4)


@pytest.mark.unit
def test_the_split_at_l_sums_to_g_and_a_closed_tip_slides_only():
    from types import SimpleNamespace

    source = scene.loads(_text(10.0), ["fracture.reference_length=2.0"])
    pair = interface_crack.interface_pair(source)
    tips = [SimpleNamespace(node=0, direction=np.array([1.0, 0.0])), SimpleNamespace(node=0, direction=np.array(
        [-1.0, 0.0]))]
    sigma = SimpleNamespace(normals=np.array([[0.0, 1.0]]))
    epsilon = interface_crack.oscillation(pair)
    K = -1.0 + 2.0j
    scale = 2.0 / (interface_crack.modulus(pair) * math.cosh(math.pi * epsilon) ** 2)
    interaction = np.array([[scale * K.real, scale * K.imag]] * 2)
    G = np.array([3.0, 3.0])
    split = interface_crack.interface_split(tips, G, interaction, sigma, source, np.array([False, True]))
    assert split["epsilon"] == pytest.approx([epsilon, -epsilon])  # the left tip's frame has material 1 below
    assert split["K"][0] == pytest.approx([K.real, K.imag])
    psi = math.degrees(np.angle(K * 2.0 ** (1j * epsilon)))
    assert split["phase"][0] == pytest.approx(psi) and split["G_I"][0] + split["G_II"][0] == pytest.approx(3.0)
    assert split["G_I"][0] == pytest.approx(3.0 * math.cos(math.radians(psi)) ** 2)
    assert split["G_I"][1] == 0.0 and split["G_II"][1] == 3.0 and abs(split["phase"][1]) == 90.0
