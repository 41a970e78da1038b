"""``./run stacks``: the closed forms it checks against, small solved versions of each case (tolerances that can
fail), and docs/stacks.md's section written from a record."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from experiments import delamination, interface_crack, regions, stacks


@pytest.mark.unit
def test_the_bonded_bilayer_bends_as_timoshenkos_bimetal_and_stores_its_energy():
    state = stacks.bilayer_state(regions.BIMETAL_REGIONS, regions.HEATING, 1.0)
    assert state["curvature"] == pytest.approx(regions.bimetal_curvature(regions.BIMETAL_REGIONS, regions.HEATING,
                                                                         1.0), rel=1e-12)
    same = {region: (200.0, 0.3, 1e-5) for region in ("lower", "upper")}  # one material: free, no energy
    free = stacks.bilayer_state(same, 100.0, 1.0)
    assert free["energy"] == pytest.approx(0.0, abs=1e-15) and free["strain"] == pytest.approx(1.3e-3, rel=1e-12)
    stiff = {"lower": (200.0, 0.3, 0.0), "upper": (1e-9, 0.3, 1e-5)}  # a film that cannot strain its substrate
    E = delamination.plane_strain_modulus(200.0, 0.3)
    assert stacks.bilayer_state(stiff, 100.0, 1.0)["energy"] == pytest.approx(0.0, abs=1e-12 * E)


@pytest.mark.unit
def test_the_enf_formula_of_equal_arms_is_the_standard_enf():
    E = delamination.plane_strain_modulus(200.0, 0.28)
    P, a, h = 1e-3, 7.0, 1.0
    assert stacks.composite_rigidity({"lower": E, "upper": E}, h) == pytest.approx(E * (2 * h) ** 3 / 12.0)
    assert stacks.enf_release(0.5 * P * a, h, {"lower": E, "upper": E}) == pytest.approx(
        delamination.enf(P, a, h, E), rel=1e-12)
    moduli = {"lower": 20.0, "upper": 200.0}  # the neutral axis moves into the stiff arm: G between the bounds
    bent = stacks.enf_release(1.0, h, moduli)
    assert 0.0 < bent < 0.5 * 12.0 / (220.0 * h ** 3)


@pytest.mark.unit
def test_the_griffith_scene_takes_its_layers_as_a_parameter():
    one, two = interface_crack.scene_text(10.0, 4.0), interface_crack.scene_text(10.0, 4.0, layers=2)
    assert "[loads.layer2.top]" not in one and "\nlayers = 1\n" in one
    assert "[loads.layer2.top]" in two and "layers =" not in two
    assert interface_crack.closed_form(10.0, layers=2)["G"] == pytest.approx(
        2.0 * interface_crack.closed_form(10.0)["G"], rel=1e-14)


@pytest.mark.solve
def test_the_strip_bent_by_a_couple_is_the_bimaterial_enf_formula():
    row = stacks.bending_enf(5.0, 0.2)
    assert abs(row["error"]) < 1e-3 and row["contact"] == 0.0  # the arms slide without pressing


@pytest.mark.solve
def test_the_three_point_enf_has_the_arms_stiffness_and_a_constant_tip_correction():
    rows = [stacks.enf(a, 0.3) for a in (5.0, 10.0)]
    assert all(row["reaction"] == pytest.approx(0.5 * stacks.ENF_LOAD, rel=1e-6) for row in rows)
    assert stacks.slope_error(rows) < 0.01
    assert rows[0]["implied_chi"] == pytest.approx(rows[1]["implied_chi"], abs=0.03)


@pytest.mark.solve
def test_the_force_loaded_dcb_approaches_kanninen_at_large_a_over_h():
    row = regions.dcb(20.0, 0.3, loading="force", length=30.0, chi=stacks.CHI_KANNINEN)
    assert abs(row["error"]) < 0.02


@pytest.mark.solve
def test_a_long_edge_delamination_releases_the_bonded_bilayers_energy():
    long, short = stacks.edge(4.0, 0.2), stacks.edge(0.25, 0.2)
    assert abs(long["error"]) < 2e-3 and short["G"] < 0.9 * short["theory"]


# --- the page ------------------------------------------------------------------------------------------
def synthetic_record(seed: int = 0) -> dict:
    """A record shaped as :func:`experiments.stacks.measurements` returns it."""
    rng = np.random.default_rng(seed)

    def row(**keys) -> dict:
        G = rng.uniform(1e-6, 1e-4)
        return {"G": G, "theory": G * rng.uniform(0.9, 1.1), "error": rng.uniform(-0.05, 0.05),
                "unknowns": int(rng.integers(1e4, 3e5)), "seconds": rng.uniform(0.1, 9.0),
                "phase": rng.uniform(-90, 90), **keys}

    griffith = [row(ratio=r, size=s, spacing=rng.uniform(1e-4, 0.1), epsilon=-0.07, epsilon_theory=-0.07,
                    phase_theory=-8.6, G_of_K=math.nan if r == 1.0 else 1e-5)
                for r in stacks.RATIOS for s in (stacks.GRIFFITH_SIZES if r in stacks.REFINED else (2.0,))]
    dcb = [row(a=a, size=s, loading=loading, epsilon=-0.07, implied_chi=0.5, simple=1e-5 * a * a)
           for s in stacks.BEAM_SIZES for loading, cracks in (("moment", stacks.MOMENT_CRACKS),
                                                              ("force", stacks.FORCE_CRACKS)) for a in cracks]
    return {"provenance": {"git_commit": "0123456789abcdef"}, "griffith": griffith, "dcb": dcb,
            "bending": [row(a=a, size=s, gap=1e-2, contact=0.0) for s in stacks.BEAM_SIZES
                        for a in stacks.MOMENT_CRACKS],
            "enf": [row(a=a, size=s, arms=arms, gap=1e-3, contact=0.2, implied_chi=0.6, simple=1e-6 * a * a,
                        reaction=5e-4) for arms in stacks.ARMS for s in stacks.BEAM_SIZES for a in stacks.ENF_CRACKS],
            "curvature": [row(size=s, curvature=-1e-3) for s in stacks.BEAM_SIZES],
            "edge": [row(crack=c, size=stacks.EDGE_SIZE, zones=1) for c in stacks.EDGE_CRACKS]}


@pytest.mark.unit
def test_the_section_has_every_part_in_order_and_a_summary_row_per_case():
    section = stacks.text(synthetic_record())
    assert re.findall(r"^### (.*)$", section, re.M) == [
        "Summary", "The Griffith interface crack", "Bi-material DCB", "Bi-material ENF", "Thermal bilayer"]
    assert section.startswith("Generated by `./run stacks` (0123456789).") and "\n\n\n" not in section
    summary = section[section.index("### Summary"):section.index("### The Griffith")]
    cases = len(stacks.RATIOS) + len(stacks.REFINED) + len(stacks.MOMENT_CRACKS) + len(stacks.FORCE_CRACKS) \
        + len(stacks.MOMENT_CRACKS) + len(stacks.ARMS) * len(stacks.ENF_CRACKS) + 2
    assert summary.count("\n| ") == cases + 1  # and the header
    assert "(ε = 0)" in section and "nan" not in section.lower().replace("nanoseconds", "")


@pytest.mark.unit
def test_every_table_row_is_as_wide_as_its_header():
    section = stacks.text(synthetic_record())
    for table in re.findall(r"(?:^\|.*\|\n?)+", section, re.M):
        widths = {len(re.split(r"(?<!\\)\|", row)) for row in table.splitlines() if not row.startswith("|---")}
        assert len(widths) == 1, table
