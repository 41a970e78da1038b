"""``./run interface``: the closed forms it checks against, a small closed crack solved as the page solves it
(against the closed form, a tolerance that can fail), and docs/interface.md assembled from a synthetic record."""
from __future__ import annotations

import re

import numpy as np
import pytest

from experiments import delamination, interface, stacks


@pytest.mark.unit
def test_the_closed_crack_releases_the_reduced_shear_and_nothing_once_it_sticks():
    free = interface.closed_crack_release(0.0)
    assert free == pytest.approx(2 * (1 - 0.3 ** 2) * np.pi / 100.0, rel=1e-14)
    assert interface.closed_crack_release(0.5) == pytest.approx(0.25 * free, rel=1e-14)
    assert interface.closed_crack_release(1.0) == 0.0 and interface.closed_crack_release(1.5) == 0.0
    # Coulomb's g is μS per layer; Tresca's slip_bound is what both layers carry together
    assert interface.friction_stress("Coulomb", 0.5, pressure=2.0) == 1.0
    assert interface.friction_stress("Tresca", 1.0) == 0.5 and interface.friction_stress("none", 7.0) == 0.0
    # the slip's ellipse: the energy the crack releases per layer, ½∫(T − g)·slip dx, is a·G per tip (dW/da = 2G)
    x = np.linspace(-1.0, 1.0, 200001)
    work = 0.5 * 0.75 * np.trapz(interface.closed_crack_slip(x, 0.25), x)
    assert work == pytest.approx(interface.closed_crack_release(0.25) / 2, rel=1e-4)


@pytest.mark.unit
def test_the_infinite_plane_is_the_richardson_limit_of_an_excess_falling_as_one_over_the_side_squared():
    exact, c = 3.0, 0.7
    assert interface.infinite_plane(exact * (1 + c / 20 ** 2), exact * (1 + c / 40 ** 2)) == pytest.approx(exact,
                                                                                                      rel=1e-14)


@pytest.mark.unit
def test_the_enf_friction_ratio_falls_from_one_to_a_quarter_at_the_stick_friction():
    a, h = 6.0, 1.0
    assert interface.enf_friction_ratio(0.0, a, h) == 1.0
    stick = interface.enf_stick_friction(a, h)
    assert stick == pytest.approx(4.5) and interface.enf_friction_ratio(stick, a, h) == pytest.approx(0.25)
    assert interface.enf_friction_ratio(10 * stick, a, h) == pytest.approx(0.25)
    # the tip's beam energies: both arms M = Ra/2 − Fh/2 and ∓F, the bonded part Ra (E = 1, unit width)
    R, mu = 1.0, 1.3
    F = mu * R / 2
    tip = 2 * (R * a / 2 - F * h / 2) ** 2 / (2 * h ** 3 / 12) + 2 * F ** 2 / (2 * h) - (R * a) ** 2 / (
        2 * (2 * h) ** 3 / 12)
    free = 2 * (R * a / 2) ** 2 / (2 * h ** 3 / 12) - (R * a) ** 2 / (2 * (2 * h) ** 3 / 12)
    assert tip / free == pytest.approx(interface.enf_friction_ratio(mu, a, h), rel=1e-12)
    E = delamination.plane_strain_modulus(200.0, 0.28)
    # the roller's reaction 1/2 of P = 1, each layer carrying P/2
    assert interface.enf_frictionless(a, 0.5) == pytest.approx(
        2 * delamination.enf(0.5, a + stacks.CHI_II * h, h, E), rel=1e-12)


@pytest.mark.unit
def test_the_larger_square_moves_its_supports_to_sigmas_ends():
    settings = interface.closed_crack_settings("Tresca", 1.0, side=40.0, size=0.5)
    assert settings["contact.slip_bound"] == 1.0 and settings["geometry.box"] == "[-20.0,20.0,-20.0,20.0]"
    assert settings["displacements.layer2.roller.point"] == "[20.0,0.0]"
    assert interface.closed_crack_settings("none", 0.0) == {"mesh.size": interface.SIZE}


# --- the page ------------------------------------------------------------------------------------------
def synthetic_records(seed: int = 0) -> dict:
    """Records shaped as the sections' ``measure`` return them."""
    rng = np.random.default_rng(seed)

    def solved(**keys) -> dict:
        return {"unknowns": int(rng.integers(1e4, 3e5)), "method": "schur", "iterations": 5,
                "coulomb_iterations": 3, "seconds": rng.uniform(1, 9), "solve_seconds": 0.3, "slip": "[-1, 1]",
                "stick": "none", **keys}

    def crack(law: str, value: float, side: float = 20.0, size: float = 0.5) -> dict:
        g = interface.friction_stress(law, value)
        theory = interface.closed_crack_release(g)
        return solved(law=law, value=value, g=g, side=side, size=size, theory=theory, tips=1e-8,
                      G=(theory or 1e-12) * (1.0 + 6.28 / side ** 2), G_II=theory)

    cases = [("none", 0.0)] + [("Coulomb", mu) for mu in interface.COULOMB] + [("Tresca", g) for g in interface.TRESCA]
    profile = {key: list(rng.uniform(0.1, 1.0, 9)) for key in ("x", "traction", "slip", "pressure", "state")}
    closed = {"sweep": [crack(*case) for case in cases], "profile": profile, "commit": "0123456789abcdef",
              "box": [crack(law, value, side, size) for side, size in ((40.0, 0.5), (20.0, 0.25))
                      for law, value in (("none", 0.0), interface.PROFILED)]}

    def enf(a: float, mu: float, size: float = 0.2) -> dict:
        estimate = interface.enf_friction_ratio(mu, a)
        return solved(a=a, mu=mu, size=size, G=1e-8 * estimate, G_II=1e-8 * estimate, G_I=1e-12, reaction=5e-4,
                      ratio=estimate + 1e-3, estimate=estimate, theory=1e-8 * estimate, contact="[0, 0.43]")

    rows = [enf(a, mu) for a in interface.ENF_CRACKS for mu in interface.ENF_FRICTION]
    methods = [{**enf(5.0, mu), "schur_G": 1e-8, "schur_seconds": 1.0, "energy_error": 3e-10}
               for mu in interface.ENF_CHECKED]
    return {"closed_crack": closed, "enf": {"rows": rows, "refined": [enf(5.0, mu, 0.1) for mu in interface.ENF_REFINED],
                                            "methods": methods, "profile": profile, "commit": "0123456789abcdef"},
            "cohesive": synthetic_cohesive(), "enf_cohesive": synthetic_enf_cohesive()}


def synthetic_curve(strength: float, start: float = 4.0) -> dict:
    """A bond run's curve: linear, a peak rounded by the strength, then Griffith's branch P ∝ δ^(−½); its crack
    grows from δ = 0.12, its process zone (E′G_c/σ_c²)^¼ h^¾ / 3."""
    opening = np.linspace(0.0, 0.2, 21)
    griffith = np.where(opening < 0.12, 0.48 * opening, 0.48 * 0.12 * np.sqrt(0.12 / np.maximum(opening, 1e-9)))
    load = griffith * (1.0 - 0.001 * (opening > 0.05) / strength ** 0.5)
    tip = np.where(opening > 0.12, start + 10.0 * (opening - 0.12), start if start else 0.0)
    zone = interface.slender_length(strength * 200.0) / 3.0 * (opening > 0.05)
    return {"opening": opening.tolist(), "load": load.tolist(), "griffith": griffith.tolist(), "tip": tip.tolist(),
            "process_zone": zone.tolist(), "newton": [0] + [5] * 20, "solves": [0] + [3] * 20, "seconds": 60.0,
            "unknowns": 12345}


def synthetic_cohesive() -> dict:
    """A record shaped as ``measure_cohesive`` returns it."""
    runs = {}
    for strength, size in interface.BOND_RUNS:
        curve = synthetic_curve(strength)
        runs[interface.run_name(strength, size)] = {"strength": strength, "size": size, **curve,
                                                     "before_damage": 4e-4 if strength > 0.003 else np.nan, "grown": 9e-3, "steps": 20,
                                                     "irreversible": True, "elements_per_zone": 6.0}
    griffith = {f"size {size:g}": {**synthetic_curve(0.005), "load": synthetic_curve(0.005)["griffith"], "size": size}
                for size in sorted({size for _, size in interface.BOND_RUNS})}
    free = synthetic_curve(0.005, start=0.0)
    opened = {**free, "damage_starts": 0.002, "breaks": 0.004, "peak": 0.36, "peak_opening": 0.0044, "beyond": 0.012,
              "zone": 0.3}
    return {"runs": runs, "griffith": griffith, "opened": opened, "commit": "0123456789abcdef"}


def synthetic_enf_cohesive() -> dict:
    """A record shaped as ``measure_enf_cohesive`` returns it."""
    runs = {f"{strength:g}": {"strength": strength, **synthetic_curve(strength, start=9.0), "before_damage": 2e-3,
                              "grown": 2e-2 if strength > 0.002 else np.nan, "steps": 20, "irreversible": True,
                              "elements_per_zone": 4.0}
            for strength in interface.ENF_STRENGTHS}  # the weakest's crack has not grown
    curve = synthetic_curve(0.005, start=9.0)
    griffith = {"opening": curve["opening"], "load": curve["griffith"], "tip": curve["tip"], "solves": curve["solves"],
                "seconds": 40.0, "unknowns": 21256}
    return {"runs": runs, "griffith": griffith, "commit": "0123456789abcdef"}


@pytest.mark.unit
def test_the_page_is_its_sections_in_order_with_a_summary_row_per_case():
    page = interface.page(synthetic_records())
    assert re.findall(r"^## (.*)$", page, re.M) == ["Summary", "The closed crack",
                                                     "The ENF with friction between the arms",
                                                     "The DCB with the bilinear law against Griffith growth",
                                                     "The process-zone length", "A bond with no initial crack",
                                                     "Speed of the cohesive runs",
                                                     "The ENF with the bilinear law against Griffith growth"]
    assert "(0123456789)" in page and "\n\n\n" not in page and not re.search(r"\bnan\b", page.lower())
    summary = page[page.index("## Summary"):page.index("## The closed crack")]
    cases = 1 + len(interface.COULOMB) + len(interface.TRESCA) + len(interface.ENF_CRACKS) * len(interface.ENF_FRICTION)
    assert summary.count("\n| ") == cases + 3 + 1  # the cohesive DCB's, the bond with no crack's, the cohesive
    # ENF's, and the header
    assert "\\|G\\|/G₀" in summary  # the stuck faces' G against the frictionless one
    assert "none: the first step damages" in page  # the weakest bond has no undamaged step to compare
    assert "no growth by δ = 0.2" in page  # the weakest ENF bond's crack
    # the square's excess divided out: the synthetic G is 1.57 % above at side 20, a quarter of it at 40
    assert re.search(r"closed crack, Coulomb μ = 0\.5 \| 1\.429425e-02 \| 1\.451867e-02 \| [+-]0\.000 %", summary)


@pytest.mark.unit
def test_every_table_row_is_as_wide_as_its_header():
    page = interface.page(synthetic_records())
    for table in re.findall(r"(?:^\|.*\|\n?)+", page, re.M):
        widths = {len(re.split(r"(?<!\\)\|", row)) for row in table.splitlines() if not row.startswith("|---")}
        assert len(widths) == 1, table


@pytest.mark.unit
def test_a_section_is_what_the_page_lists():
    only = [interface.SECTIONS[0]]
    page = interface.page({"closed_crack": synthetic_records()["closed_crack"]}, only)
    assert "## The closed crack" in page and "ENF" not in page


@pytest.mark.mpi
@pytest.mark.solve
def test_a_small_closed_crack_with_coulomb_friction_gives_the_closed_form(tmp_path):
    """The page's solve on a coarse mesh: G within 3 % of 2(1 − ν²)(T − μS)²πa/E, the whole crack slipping."""
    row, _ = interface.closed_crack_case("Coulomb", 0.5, tmp_path, size=1.0)
    assert row["G"] == pytest.approx(interface.closed_crack_release(0.5), rel=0.03)
    assert row["slip"] != "none" and row["stick"] == "none" and row["coulomb_iterations"] >= 2
    stuck, _ = interface.closed_crack_case("Coulomb", 1.5, tmp_path, size=1.0)
    assert abs(stuck["G"]) <= 1e-3 * interface.closed_crack_release(0.0) and stuck["slip"] == "none"


@pytest.mark.unit
def test_the_cohesive_pictures_are_drawn_from_the_record(tmp_path, monkeypatch):
    monkeypatch.setattr(interface, "DOCS", tmp_path)
    interface.cohesive_plot(synthetic_cohesive())
    assert (tmp_path / "interface-cohesive.png").stat().st_size > 10_000
    interface.enf_cohesive_plot(synthetic_enf_cohesive())
    assert (tmp_path / "interface-enf-cohesive.png").stat().st_size > 10_000


@pytest.mark.unit
def test_the_process_zone_estimates_and_the_fitted_slope():
    strength = 1.0
    hillerborg = interface.hillerborg_length(strength)
    assert hillerborg == pytest.approx(200.0 / (1 - 0.28 ** 2) * 2e-3, rel=1e-14)
    assert interface.slender_length(strength, h=2.0) == pytest.approx(hillerborg ** 0.25 * 2.0 ** 0.75, rel=1e-14)
    # the synthetic zones follow the slender arm's σ_c^−½ exactly
    assert interface.zone_exponent(synthetic_cohesive()) == pytest.approx(-0.5, abs=1e-9)
    tips = interface.tips(np.array([[[np.nan, np.nan]], [[0.0, 0.5]], [[0.0, 1.5]]]), 0.0)
    assert tips.tolist() == [0.0, 0.5, 1.5]
