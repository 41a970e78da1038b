"""The toughness G_c and the critical load factor: the laws against hand values, bad keys refused in one line,
λ_c = √(G_c/G(1)) on Example 2 (a solve at λ_c gives G = G_c), the root solve with a temperature change kept
(G(λ_c) = G_c to 1e-8, by the reference and by the domain decomposition), the result file, the printed line."""
from __future__ import annotations

import math

import h5py
import numpy as np
import pytest
from conftest import ddsolve

from ddsolve.errors import SceneError
from ddsolve.io import hdf5, save
from ddsolve.mesh import geometry
from ddsolve.post import toughness
from ddsolve.problem import scene
from ddsolve.solvers import critical, reference, run

SMALL = ["mesh.sigma_vertices=25", "mesh.boundary_vertices=48"]
#: Example 2 heated: the layers' thermal mismatch closes the crack, the mechanical load opens it again.
HEATED = ["materials.layer1.alpha=2e-5", "materials.layer2.alpha=1e-5", "temperature.layer1=100.0",
          "temperature.layer2=100.0"]
BK = ['fracture.law="benzeggagh-kenane"', "fracture.G_Ic=1.0", "fracture.G_IIc=3.0", "fracture.eta=2.0"]
HS = ['fracture.law="hutchinson-suo"', "fracture.G_Ic=2.0", "fracture.lambda=0.3"]


def options(*items: str) -> scene.FractureOptions:
    return scene.load("full-opening", [*SMALL, *items]).fracture


def test_benzeggagh_kenane_by_hand():
    """G_c = G_Ic + (G_IIc − G_Ic)(G_II/G)^η at G_II/G = 0, 1 and ½ (η = 2: 1 + 2/4)."""
    G = np.array([4.0, 4.0, 4.0, 0.0])
    G_c = toughness.law(options(*BK), np.zeros(4, dtype=int), G, np.array([0.0, 4.0, 2.0, 0.0]), np.zeros(4))
    np.testing.assert_allclose(G_c[:3], [1.0, 3.0, 1.5], rtol=1e-15)
    assert np.isnan(G_c[3])  # G = 0: no mode mix


def test_hutchinson_suo_by_hand():
    """G_c(ψ) = G_Ic (1 + tan²((1 − λ)ψ)) at ψ = 0 and ±45°."""
    G_c = toughness.law(options(*HS), np.zeros(3, dtype=int), np.ones(3), np.zeros(3), np.array([0.0, 45.0, -45.0]))
    expected = 2.0 * (1.0 + math.tan(math.radians(0.7 * 45.0)) ** 2)
    np.testing.assert_allclose(G_c, [2.0, expected, expected], rtol=1e-15)


def test_one_toughness_for_every_tip_or_one_per_crack():
    crack = np.array([0, 0, 1, 1])
    one = toughness.law(options("fracture.toughness=2.5"), crack, np.ones(4), np.zeros(4), np.zeros(4))
    np.testing.assert_array_equal(one, 2.5)
    per_crack = scene.load("full-opening", [*SMALL, "geometry.cracks=[[-0.6, -0.2], [0.2, 0.6]]",
                                            "fracture.toughness=[1.0, 2.0]"]).fracture
    np.testing.assert_array_equal(toughness.law(per_crack, crack, np.ones(4), np.zeros(4), np.zeros(4)),
                                  [1.0, 1.0, 2.0, 2.0])
    assert np.isnan(toughness.law(options(), crack, np.ones(4), np.zeros(4), np.zeros(4))).all()
    assert not toughness.given(scene.load("full-opening", SMALL))
    assert toughness.given(scene.load("full-opening", [*SMALL, *HS]))


def test_critical_factor():
    """√(G_c/G) where G > 0, inf where G ≤ 0 (never grows), NaN where G or (for G > 0) G_c is NaN."""
    factor = toughness.critical_factor(np.array([4.0, 0.0, -1.0, np.nan, 1.0]), np.array([1.0, 1.0, 1.0, 1.0, np.nan]))
    np.testing.assert_array_equal(factor, [0.5, np.inf, np.inf, np.nan, np.nan])


@pytest.mark.parametrize("items, key", [
    (["fracture.toughness=0.0"], "fracture.toughness"),
    (["fracture.toughness=-1e-4"], "fracture.toughness"),
    (["fracture.toughness=nan"], "fracture.toughness"),
    (["fracture.toughness=inf"], "fracture.toughness"),
    (['fracture.toughness="tough"'], "fracture.toughness"),
    (["fracture.toughness=[1e-4, 0.0]"], "fracture.toughness"),
    (["fracture.toughness=[1e-4, 2e-4]"], "fracture.toughness lists 2 values for the 1 crack"),
    ([*BK, "fracture.toughness=1e-4"], "fracture.toughness and fracture.law exclude each other"),
    (['fracture.law="benzeggagh-kenane"', "fracture.G_Ic=1.0", "fracture.eta=2.0"], "fracture.G_IIc"),
    (['fracture.law="hutchinson-suo"', "fracture.G_Ic=1.0"], "fracture.lambda"),
    (['fracture.law="griffith"'], "fracture.law"),
    ([*BK[:3], "fracture.eta=0.0"], "fracture.eta"),
    ([*BK[:1], "fracture.G_Ic=nan", *BK[2:]], "fracture.G_Ic"),
    ([*HS[:2], "fracture.lambda=1.5"], "fracture.lambda"),
    ([*BK, "fracture.lambda=0.5"], "fracture.lambda does not apply"),
    (["fracture.G_IIc=1.0"], "fracture.G_IIc needs fracture.law"),
])
def test_bad_toughness_is_a_one_line_error_naming_the_key(items, key):
    with pytest.raises(SceneError) as caught:
        scene.load("full-opening", [*SMALL, *items])
    assert key in str(caught.value) and "\n" not in str(caught.value)


@pytest.mark.solve
def test_a_per_crack_toughness_is_checked_against_a_mesh_file(mesh_file):
    """A mesh file's cracks are counted on its mesh: a list of the wrong length is refused naming the key."""
    text = scene.builtin_scenes()["full-opening"].replace("sigma_vertices = 96\nboundary_vertices = 144",
                                                           f'file = "{mesh_file}"')
    source = scene.loads(text, ["fracture.toughness=[1e-4, 2e-4]"])
    with pytest.raises(SceneError, match=r"fracture.toughness lists 2 values for the 1 crack of the mesh"):
        reference.solve_monolithic(source, geometry.build(source))
    toughness.check_cracks(source, 2)


@pytest.mark.solve
def test_example_2_grows_at_the_square_root_of_the_toughness_ratio(tmp_path):
    """Proportional loading: λ_c = √(G_c/G(1)) at each tip, and a solve of the scene scaled by λ_c has
    G = G_c there to 1e-10; the file keeps G_c and λ_c (a file written before them reads NaN); the
    printed line gives G/G_c and λ_c."""
    source = scene.load("full-opening", [*SMALL, "fracture.toughness=1e-4"])
    mesh = geometry.build(source)
    result = reference.solve_monolithic(source, mesh)
    fracture = result.fracture
    np.testing.assert_array_equal(fracture.toughness, 1e-4)
    factors = np.sqrt(1e-4 / fracture.G)
    np.testing.assert_allclose(fracture.critical_factor, factors, rtol=1e-15)
    for tip, factor in enumerate(factors):
        assert reference.solve_monolithic(source.scaled(factor), mesh).fracture.G[tip] == pytest.approx(1e-4, rel=1e-10)
    path = tmp_path / "r.h5"
    save(result, path)
    back = hdf5.read(path).fracture
    np.testing.assert_array_equal(back.toughness, fracture.toughness)
    np.testing.assert_array_equal(back.critical_factor, fracture.critical_factor)
    with h5py.File(path, "r+") as f:
        del f["fracture/toughness"], f["fracture/critical_factor"]
    old = hdf5.read(path).fracture
    assert np.isnan(old.toughness).all() and np.isnan(old.critical_factor).all() and old.growth() == ["", ""]
    line = fracture.lines()[0]
    assert f"G/G_c = {fracture.G[0] / 1e-4:.6g}, grows at λ = {factors[0]:.6g}" in line


@pytest.mark.solve
def test_without_a_toughness_nothing_is_judged():
    fracture = reference.solve_monolithic(source := scene.load("full-opening", SMALL), geometry.build(source)).fracture
    assert np.isnan(fracture.toughness).all() and np.isnan(fracture.critical_factor).all()
    assert "G/G_c" not in fracture.lines()[0]


@pytest.mark.solve
@pytest.mark.parametrize("law", [["fracture.toughness=1e-4"], HS[:1] + ["fracture.G_Ic=1e-4", "fracture.lambda=0.3"]])
def test_a_temperature_change_kept_by_the_root_solve(law):
    """Heated Example 2 (its thermal mismatch closes the crack until the load opens it: G(λ) is no
    quadratic through λ = 0): the root solve finds λ_c with G(λ_c) = G_c(ψ(λ_c)) to 1e-8 at every tip; the
    shear load makes the Hutchinson–Suo toughness depend on λ."""
    source = scene.load("full-opening", [*SMALL, *HEATED, "loads.layer1.top.x=0.02", *law])
    mesh = geometry.build(source)
    result = run.reference(source, progress=lambda line: None)
    factors = result.fracture.critical_factor
    assert np.all(np.isfinite(factors)) and np.all(factors > 2.0)
    unheated = math.sqrt(result.fracture.toughness[0] / result.fracture.G[0])
    assert abs(factors[0] - unheated) > 0.1 * factors[0]  # not the proportional λ_c
    for tip, factor in enumerate(factors):
        at = reference.solve_monolithic(source.scaled(factor), mesh).fracture
        assert abs(at.G[tip] / toughness.resistance(source, at)[tip] - 1.0) <= 1e-8


@pytest.mark.solve
def test_the_domain_decomposition_finds_the_reference_factors():
    """critical.factors on one rank (the driver, blocks factored once) gives the reference's factors."""
    from mpi4py import MPI

    source = scene.load("full-opening", [*SMALL, *HEATED, "fracture.toughness=1e-4"])
    mesh = geometry.build(source)
    lines = []
    found = critical.factors(source, MPI.COMM_SELF, mesh, lines.append)
    expected = critical.search(source, lambda lam: reference.solve_monolithic(source.scaled(lam), mesh).fracture)
    np.testing.assert_allclose(found, expected, rtol=1e-8)
    assert len(lines) == 1 and "solves of the scaled scene" in lines[0]


@pytest.mark.mpi
def test_solve_on_two_ranks_prints_and_writes_the_critical_factor(tmp_path):
    """``ddsolve solve -n 2`` of heated Example 2 with a toughness: the printed G lines give G/G_c and λ_c,
    the file holds the reference's factors, and its timings the whole launch, the search included."""
    items = [*SMALL, *HEATED, "fracture.toughness=1e-4"]
    output = tmp_path / "t.h5"
    completed = ddsolve("solve", "-n", "2", "full-opening", *(w for item in items for w in ("--set", item)),
                        "-o", str(output))
    result = hdf5.read(output)
    fracture = result.fracture
    assert all(result.timings[phase] > 0 for phase in ("startup", "meshing", "factorization", "critical_factors"))
    assert "critical_factors" in next(line for line in completed.stdout.splitlines() if line.startswith("launch "))
    expected = run.reference(scene.load("full-opening", items), progress=lambda line: None).fracture
    np.testing.assert_allclose(fracture.critical_factor, expected.critical_factor, rtol=1e-7)
    for factor in fracture.critical_factor:
        assert f"grows at λ = {factor:.6g}" in completed.stdout
    assert completed.stdout.count("G/G_c = ") == 2


@pytest.mark.solve
def test_an_adaptive_solve_finds_the_factors_on_its_last_mesh_factored_once(monkeypatch):
    """Adaptive heated Example 2 with a toughness: the search on the last mesh prepares (assembles and
    factors) its blocks once, not once per solve of the scaled scene, and finds the reference's factors."""
    from mpi4py import MPI

    from ddsolve.solvers import adapt, driver

    source = scene.load("full-opening", [*SMALL, *HEATED, "fracture.toughness=1e-4", "mesh.target_error=0.05"])
    prepared, prepare = [], driver.prepare
    monkeypatch.setattr(driver, "prepare", lambda *args, **kwargs: prepared.append(1) or prepare(*args, **kwargs))
    result = adapt.solve_adaptively(source, MPI.COMM_SELF, None, progress=lambda line: None)
    assert len(prepared) == len(result.levels["unknowns"]) + 1 and result.timings["critical_factors"] > 0
    expected = critical.search(source, lambda lam: reference.solve_monolithic(source.scaled(lam), result.mesh).fracture)
    np.testing.assert_allclose(result.fracture.critical_factor, expected, rtol=1e-7)
