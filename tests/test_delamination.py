"""The delamination experiment (issue 18 item 5): its beam-theory formulas against their closed forms and
compliances, and the cheap specimens on small graded P2 meshes: a DCB is mode I and near corrected beam
theory, an ENF (upper arm floating, faces in contact) mode II without penetration, the MMB mode ratio at
one lever length, and the ENF solved on 2 ranks equals the reference."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import ddsolve

from experiments import delamination as d
from ddsolve.io import hdf5

E, NU, P, H = 200.0, 0.28, 1e-3, 1.0


def derivative(compliance, a: float, step: float = 1e-4) -> float:
    return (compliance(a + step) - compliance(a - step)) / (2.0 * step)


@pytest.mark.parametrize("chi", [0.0, d.CHI_I, d.CHI_II])
def test_beam_theory_is_half_p_squared_times_the_compliance_derivative(chi):
    """G = P²/2 dC/da with the beams' compliances: DCB 8(a + χh)³/(E′h³) (both arms), ELS
    (3(a + χh)³ + ℓ³)/(2E′h³), ENF (3(a + χh)³ + 2L³)/(8E′h³); the opening form from the DCB compliance."""
    modulus, length = d.plane_strain_modulus(E, NU), 20.0
    for a in (5.0, 8.0):
        def dcb(s):
            return 8.0 * (s + chi * H) ** 3 / (modulus * H ** 3)

        def els(s):
            return (3.0 * (s + chi * H) ** 3 + length ** 3) / (2.0 * modulus * H ** 3)

        def enf(s):
            return (3.0 * (s + chi * H) ** 3 + 2.0 * (0.5 * length) ** 3) / (8.0 * modulus * H ** 3)

        assert d.dcb(P, a, H, modulus, chi) == pytest.approx(0.5 * P * P * derivative(dcb, a), rel=1e-8)
        assert d.els(P, a, H, modulus, chi) == pytest.approx(0.5 * P * P * derivative(els, a), rel=1e-8)
        assert d.enf(P, a, H, modulus, chi) == pytest.approx(0.5 * P * P * derivative(enf, a), rel=1e-8)
        delta = 0.01
        assert d.dcb_opening(delta, a, H, modulus, chi) == pytest.approx(
            d.dcb(delta / dcb(a), a, H, modulus, chi), rel=1e-12)


def test_two_identical_layers_are_twice_one_layer_at_half_the_load():
    """E₁′ + E₂′ with P summed over the layers is the sum of each layer's G under half the load."""
    modulus = d.plane_strain_modulus(E, NU)
    summed = d.summed_modulus([(E, NU), (E, NU)])
    assert summed == pytest.approx(2.0 * E / (1.0 - NU ** 2))
    assert d.dcb(P, 6.0, H, summed, d.CHI_I) == pytest.approx(2.0 * d.dcb(P / 2, 6.0, H, modulus, d.CHI_I))
    # the DCB of docs/fracture.md: 20 × 2, a = 6, t_y = 2e-3·y per layer (1e-3 per arm and layer), G = 4.9247e-6:
    # 0.12 % below corrected beam theory with the isotropic correction 0.677h
    assert 4.9247e-6 / d.dcb(2e-3, 6.0, H, summed, d.CHI_I) - 1 == pytest.approx(-0.0012, abs=5e-4)


def test_mmb_loads_are_the_levers_forces_and_the_mode_ratio_is_reeder_crews():
    """P_I, P_II put back the lever's pull P c/L on the upper arm and the lower support's reaction
    P(L − c)/(2L) (each arm carries ±P_I + P_II/4); c = L/3 is pure mode II; beam theory's ratio is
    (4/3)((3c − L)/(c + L))²."""
    L = 20.0
    for c in (0.6 * L, L, 2.0 * L):
        P_I, P_II = d.mmb_loads(P, c, L)
        pull, push = d.mmb_lever_forces(P, c, L)
        assert P_I + P_II / 4 == pytest.approx(pull) and push == pytest.approx(P_II)
        assert -P_I + P_II / 4 == pytest.approx(P * (L - c) / (2 * L))
        G_I, G_II = d.mmb(P, c, L, 6.0, H, 1.0)
        assert G_I / G_II == pytest.approx(4.0 / 3.0 * ((3 * c - L) / (c + L)) ** 2)
    assert d.mmb_loads(P, L / 3, L)[0] == pytest.approx(0.0, abs=1e-18)


@pytest.mark.parametrize("formula", ["corrected", "wang_williams"])
def test_corrected_mmb_is_the_corrected_dcb_and_enf(formula):
    """The MMB's corrected G_I is the DCB's under P_I with the mode I correction, its G_II the ENF's under
    P_II with the mode II one, and their ratio (4/3)((3c − L)/(c + L))² ((a + χ_I h)/(a + χ_II h))²; with
    χ = 0 both are beam theory's."""
    chi, L, a, modulus = d.CORRECTIONS[formula], 20.0, 6.0, d.plane_strain_modulus(E, NU)
    for c in (0.6 * L, L, 2.0 * L):
        P_I, P_II = d.mmb_loads(P, c, L)
        G_I, G_II = d.mmb(P, c, L, a, H, modulus, chi["DCB"], chi["ENF"])
        assert G_I == pytest.approx(d.dcb(P_I, a, H, modulus, chi["DCB"]), rel=1e-14)
        assert G_II == pytest.approx(d.enf(P_II, a, H, modulus, chi["ENF"]), rel=1e-14)
        assert G_I / G_II == pytest.approx(4.0 / 3.0 * ((3 * c - L) / (c + L)) ** 2
                                           * ((a + chi["DCB"] * H) / (a + chi["ENF"] * H)) ** 2, rel=1e-12)
        assert d.mmb(P, c, L, a, H, modulus, 0.0, 0.0) == pytest.approx(d.mmb(P, c, L, a, H, modulus))


def test_the_corrections_of_each_beam_theory():
    """Beam theory has no tip correction; corrected beam theory for isotropic arms takes Bao et al.'s
    0.677h (mode I) and 0.206h (mode II); the composite one Kanninen's 6^(−1/4)h with Wang and Williams'
    0.49 (ELS) and 0.42 (ENF); every case's theory is its formula with these corrections."""
    assert set(d.CORRECTIONS["simple"].values()) == {0.0}
    assert d.CORRECTIONS["corrected"] == {"DCB": 0.677, "ELS": 0.206, "ENF": 0.206}
    composite = d.CORRECTIONS["wang_williams"]
    assert composite["DCB"] ** 4 == pytest.approx(1 / 6) and composite["DCB"] == pytest.approx(0.6389, abs=1e-4)
    assert composite["ELS"] == pytest.approx(0.49 * composite["DCB"]) and \
        composite["ENF"] == pytest.approx(0.42 * composite["DCB"])
    modulus = d.summed_modulus(d.LAYERS["identical"])
    for specimen, formula in (("DCB", d.dcb), ("ELS", d.els), ("ENF", d.enf)):
        theory = d.Case(specimen, "identical", 8.0).theory()
        for name, chi in d.CORRECTIONS.items():
            assert theory[name] == pytest.approx(formula(d.LOAD, 8.0, H, modulus, chi[specimen]), rel=1e-14)
    theory = d.Case("DCB-displacement", "identical", 6.0).theory(2e-3)
    assert theory["corrected"] == pytest.approx(d.dcb_opening(d.OPENING, 6.0, H, modulus, d.CHI_I), rel=1e-14)
    assert theory["from_reaction"] == pytest.approx(d.dcb(2e-3, 6.0, H, modulus, d.CHI_I), rel=1e-14)


def test_mismatch_stress_makes_the_layers_strain_alike():
    """σ₁/E₁′ + m₁ = −σ₁/E₂′ + m₂ (one strain along Σ, equal and opposite forces)."""
    layers, alphas, dT = [(200.0, 0.28), (112.0, 0.32)], (2e-5, 1e-5), 100.0
    s = d.mismatch_stress(layers, alphas, dT)
    strain1 = s / d.plane_strain_modulus(*layers[0]) + (1 + 0.28) * alphas[0] * dT
    strain2 = -s / d.plane_strain_modulus(*layers[1]) + (1 + 0.32) * alphas[1] * dT
    assert strain1 == pytest.approx(strain2, rel=1e-12) and s < 0


def test_the_strip_geo_names_every_piece():
    """The .geo has the halves, Σ with the crack, and the named pieces of ENF's supports and load."""
    text = d.Case("ENF", "identical", 6.0).geo()
    for name in ("lower", "upper", "sigma", "crack", "pin", "roller", "load", "left_lower", "left_upper",
                 "right_lower", "right_upper", "bottom", "top"):
        assert f'("{name}")' in text


def small(case: d.Case, tmp_path):
    case.size = 0.2
    return d.measure(case, d.solve_case(case.scene(tmp_path, "case")), 0.0)


@pytest.mark.solve
def test_dcb_is_mode_one_near_corrected_beam_theory(tmp_path):
    """DCB, a/h = 6, identical layers, size 0.2: G within 2 % of corrected beam theory with the isotropic
    correction 0.677h (measured −0.3 %), G_II/G ≤ 0.5 %, G_I + G_II within 0.5 % of G."""
    row = small(d.Case("DCB", "identical", 6.0), tmp_path)
    assert row["G"] == pytest.approx(row["corrected"], rel=2e-2)
    assert abs(row["G_II"]) <= 5e-3 * row["G"]
    assert row["G_I"] + row["G_II"] == pytest.approx(row["G"], rel=5e-3)


@pytest.mark.solve
def test_enf_is_mode_two_with_the_faces_in_contact(tmp_path):
    """ENF, a/h = 6, identical layers (the upper half floating), size 0.2: G_I/G ≤ 0.5 %, G_I + G_II within
    0.5 % of G, no penetration beyond 1e-10·max|u|, faces in contact; G above beam theory and within 2 % of
    corrected beam theory with the isotropic correction 0.206h (measured −1.2 %; −3.1 % from Wang and
    Williams' composite correction)."""
    row = small(d.Case("ENF", "identical", 6.0), tmp_path)
    assert abs(row["G_I"]) <= 5e-3 * row["G"]
    assert row["G_I"] + row["G_II"] == pytest.approx(row["G"], rel=5e-3)
    assert row["penetration"] <= 1e-10 and row["contact_zones"] > 0
    assert row["simple"] < row["G"]
    assert row["G"] == pytest.approx(row["corrected"], rel=2e-2)


@pytest.mark.solve
def test_mmb_mode_ratio_at_one_lever_length(tmp_path):
    """MMB, c = L, a/h = 6, identical layers, size 0.2: G_I/G_II within 4 % of corrected beam theory,
    (4/3)((3c − L)/(c + L))² ((a + 0.677h)/(a + 0.206h))² (measured +2.9 % on this coarse mesh; the
    acceptance's 3 % is checked at size 0.1 in docs/delamination.md), above simple beam theory's; G_I + G_II
    within 0.5 % of G."""
    case = d.Case("MMB", "identical", d.MMB_CRACK, 0.5 * d.SPAN)
    row = small(case, tmp_path)
    assert row["G_I"] / row["G_II"] == pytest.approx(row["corrected_I"] / row["corrected_II"], rel=4e-2)
    assert row["G_I"] / row["G_II"] > row["simple_I"] / row["simple_II"]
    assert row["G_I"] + row["G_II"] == pytest.approx(row["G"], rel=5e-3)


@pytest.mark.mpi
def test_enf_on_two_ranks_equals_the_reference(tmp_path):
    """The ENF's upper half floats: `solve -n 2` (schur) gives the reference's G to 1e-8."""
    case = d.Case("ENF", "identical", 6.0, size=0.25)
    expected = d.solve_case(case.scene(tmp_path, "enf"))
    ddsolve("solve", str(tmp_path / "enf.toml"), "-o", str(tmp_path / "enf.h5"), ranks=2)
    got = hdf5.read(tmp_path / "enf.h5").fracture
    assert got.G[0] == pytest.approx(expected.fracture.G[0], rel=1e-8)
    assert math.isfinite(got.G_II[0]) and np.isclose(got.G_II[0], expected.fracture.G_II[0], rtol=1e-6)
