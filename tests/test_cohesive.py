"""The bond on Σ (``[interface]``): the laws, the compliance on the dual problem and its KKT check, the damage's
irreversibility, the methods against each other and the rigid bond, the DCB against Griffith, bad input."""
from __future__ import annotations

import numpy as np
import pytest

from ddsolve.dd import cohesive
from ddsolve.dd.constraints import kkt
from ddsolve.dd.interface import BROKEN, Interface
from ddsolve.errors import DDSolveError, SceneError
from ddsolve.problem import scene as scenes
from ddsolve.problem.scene import Bond

X = np.array([-1.0, -0.8, -0.5, -0.3, 0.0, 0.2, 0.5, 0.75, 1.0])
WEIGHTS = 0.5 * (X[2:] - X[:-2])
CRACK = (X[1:-1] > -0.5) & (X[1:-1] < 0.5)  # vertices 2, 3, 4
BILINEAR = Bond("bilinear", stiffness=1e4, strength=1.0, toughness=0.01)  # δ₀ = 1e-4, δ_f = 0.02
MIXED = Bond("bilinear", stiffness=1e4, strength=1.0, toughness=0.01, mode_mix="benzeggagh-kenane", G_IIc=0.03,
             eta=2.0, shear_strength=2.0)

MATERIALS = "".join(f"[materials.{layer}]\nE = 200.0\nnu = 0.3\n" for layer in ("layer1", "layer2"))


def bonded(bond: Bond = BILINEAR) -> Interface:
    return Interface(WEIGHTS, CRACK, contact=True, bond=bond)


@pytest.mark.unit
def test_bilinear_law_peaks_at_the_strength_and_encloses_the_toughness():
    openings = np.linspace(0.0, 0.025, 200001)
    damage = cohesive.damage_of(BILINEAR, np.zeros_like(openings), openings)
    traction = BILINEAR.stiffness * (1.0 - damage) * openings
    assert traction.max() == pytest.approx(BILINEAR.strength, rel=1e-4)
    assert np.trapz(traction, openings) == pytest.approx(BILINEAR.toughness, rel=1e-6)
    assert np.all(damage[openings >= 0.02] == 1.0) and np.all(damage[openings <= 1e-4] == 0.0)
    assert np.all(cohesive.damage_of(BILINEAR, np.zeros(3), -np.array([1.0, 0.1, 0.01])) == 0.0)  # pressed: none


@pytest.mark.unit
def test_benzeggagh_kenane_mixes_the_strengths_and_toughnesses():
    start, end = cohesive.law_openings(MIXED, np.array([0.0, 1.0]), np.array([1.0, 0.0]))
    assert start == pytest.approx([1e-4, 2e-4]) and end == pytest.approx([2 * 0.01 / 1.0, 2 * 0.03 / 2.0])
    # the area under the law in pure shear is G_IIc
    slides = np.linspace(0.0, 0.035, 200001)
    damage = cohesive.damage_of(MIXED, slides, np.zeros_like(slides))
    assert np.trapz(MIXED.stiffness * (1.0 - damage) * slides, slides) == pytest.approx(0.03, rel=1e-6)


@pytest.mark.unit
def test_the_tangent_is_the_derivative_of_the_traction_under_the_mode_independent_law():
    rng = np.random.default_rng(3)
    history = np.array([0.0, 0.5, 0.9, 0.0, 0.999])
    gap = np.column_stack([rng.uniform(-4e-3, 4e-3, 5), -rng.uniform(5e-4, 1e-2, 5)])
    law = cohesive.response(BILINEAR, history, gap)
    assert (law.damage > history).any() and (law.damage == history).any()  # growing and unloading vertices
    for j in range(2):
        step = np.zeros_like(gap)
        step[:, j] = 1e-9
        numeric = (cohesive.response(BILINEAR, history, gap + step).traction
                   - cohesive.response(BILINEAR, history, gap - step).traction) / 2e-9
        assert np.allclose(law.tangent[:, :, j], numeric, rtol=1e-4, atol=1e-6 * BILINEAR.stiffness)


@pytest.mark.unit
def test_damage_is_irreversible_and_unloading_follows_the_secant():
    gap = np.array([[0.0, -0.01]])  # opened half way along the softening branch
    loaded = cohesive.response(BILINEAR, np.zeros(1), gap)
    unloaded = cohesive.response(BILINEAR, loaded.damage, 0.5 * gap)
    assert unloaded.damage == loaded.damage  # kept
    assert unloaded.traction == pytest.approx(0.5 * loaded.traction)  # on the secant to the origin
    assert unloaded.tangent[0, 1, 1] == pytest.approx(BILINEAR.stiffness * (1.0 - loaded.damage[0]))
    pressed = cohesive.response(BILINEAR, loaded.damage, -gap)  # closed again: the undamaged penalty
    assert pressed.pressed[0] and pressed.traction[0, 1] == pytest.approx(BILINEAR.stiffness * 0.01)
    assert cohesive.softening(BILINEAR, np.array([0.0, loaded.damage[0], 1.0])) == pytest.approx(
        [0.0, (0.01 - 1e-4) / (0.02 - 1e-4), 1.0])


@pytest.mark.unit
def test_the_bond_makes_the_glue_rows_compliant_and_the_check_measures_gap_minus_c_lambda():
    interface = bonded()
    tangential, normal = interface.bond_rows(0), interface.bond_rows(1)
    assert len(tangential) == len(normal) == 4  # the glued vertices 0, 1, 5, 6
    assert np.allclose(interface.compliance[np.concatenate([tangential, normal])], 1e-4)
    assert np.all(interface.compliance[~np.isin(np.arange(interface.size), np.concatenate([tangential, normal]))] == 0)
    damage = np.where(np.arange(7) == 0, 0.75, np.where(np.arange(7) == 1, 1.0, 0.0))
    state = interface.with_damage(damage, np.arange(7) == 5)
    c = state.compliance
    assert c[tangential[0]] == pytest.approx(4e-4) and c[normal[0]] == pytest.approx(4e-4)
    assert c[tangential[1]] == 0.0 and c[normal[1]] == pytest.approx(1e-4)  # broken: freed, penalized contact
    lower, upper = state.bounds(None)
    assert lower[tangential[1]] == upper[tangential[1]] == 0.0 and lower[normal[1]] == 0.0
    assert c[normal[2]] == pytest.approx(1e-4)  # pressed: the undamaged stiffness
    rng = np.random.default_rng(2)  # faces u± = v±, a jump on the bonded vertices only (the broken one opening)
    lower_face = 1e-3 * rng.standard_normal(state.trace_size)
    jump = np.zeros(state.trace_size)
    for vertex in (0, 1, 5, 6):
        jump[2 * vertex:2 * vertex + 2] = 1e-4 * rng.standard_normal(2)
    jump[3] = -abs(jump[3])  # vertex 1's normal gap u⁻ − u⁺ < 0: open
    jump[11] = abs(jump[11])  # vertex 5's: pressed
    traces = np.array([lower_face, lower_face - jump, lower_face, lower_face - jump])
    gap = state.gap(traces)
    lam = np.where(c > 0, gap / np.where(c > 0, c, 1.0), 0.0)
    lam[normal[1]] = 0.0  # the broken vertex's open faces carry nothing
    held = kkt(state, traces, lam, None, np.zeros(4), 1e-3)
    assert held.gluing_gap < 1e-12 and held.multiplier_bounds == 0.0
    rigid = kkt(state, traces, np.zeros(state.size), None, np.zeros(4), 1e-3)
    assert rigid.gluing_gap > 1e-3  # without the springs' forces the jumps violate the law


@pytest.mark.unit
def test_keys_of_the_interface_table():
    base = 'title = "t"\n[geometry]\ncrack = [-0.5, 0.5]\n[mesh]\nsize = 0.5\n' + MATERIALS
    scene = scenes.loads(base + '[interface]\nlaw = "bilinear"\nstrength = 2.0\ntoughness = 0.5\n')
    assert scene.bond.stiffness == pytest.approx(2.0 ** 2 / (2e-3 * 0.5))  # δ₀ = 10⁻³ δ_f
    assert scenes.loads(base).bond is None
    bad = {'law = "elastic"\nstiffness = 1.0\n[contact]\nfriction = 0.5': "contact.friction",
           'law = "bilinear"\nstrength = 0.0\ntoughness = 1.0': "interface.strength",
           'law = "bilinear"\nstrength = -1.0\ntoughness = 1.0': "interface.strength",
           'law = "bilinear"\nstrength = 1.0\ntoughness = 0.0': "interface.toughness",
           'law = "bilinear"\nstrength = 1.0': "interface.toughness",
           'law = "plastic"\nstiffness = 1.0': "interface.law",
           'law = "elastic"': "interface.stiffness",
           'law = "elastic"\nstiffness = 1.0\nstrength = 1.0': "interface.strength",
           'stiffness = 1.0': "interface.stiffness",
           'law = "bilinear"\nstrength = 1.0\ntoughness = 1.0\nmode_mix = "benzeggagh-kenane"': "interface.G_IIc",
           'law = "bilinear"\nstrength = 1.0\ntoughness = 0.1\nstiffness = 1.0': "interface.stiffness"}
    for body, key in bad.items():
        with pytest.raises(SceneError) as error:
            scenes.loads(base + "[interface]\n" + body + "\n")
        message = str(error.value)
        assert key in message and "\n" not in message, message


@pytest.mark.solve
def test_a_law_on_a_crack_alone_is_refused_naming_the_key():
    import ddsolve

    held = "".join(f"[displacements.{layer}.{side}]\nx = 0.0\ny = 0.0\n" for layer in ("layer1", "layer2")
                   for side in ("bottom", "top"))
    scene = scenes.loads('title = "t"\n[geometry]\nbox = [0, 2, 0, 1]\ncrack = [0, 2]\nclamped = []\n[mesh]\n'
                         'size = 0.5\n' + MATERIALS + held + '[interface]\nlaw = "elastic"\nstiffness = 1.0\n')
    with pytest.raises(DDSolveError, match="interface.law"):
        ddsolve.solve(scene, progress=lambda line: None)


@pytest.mark.solve
def test_elastic_bond_tends_to_the_rigid_one_and_schur_equals_mprgp():
    from experiments import cohesive as experiment

    rows = experiment.stiff_limit((1e3, 1e5, 1e7))
    by = {(row["method"], row["stiffness"]): row for row in rows}
    for method in ("schur", "mprgp"):
        differences = [by[method, k]["difference"] for k in (1e3, 1e5, 1e7)]
        assert differences[0] > 0.1  # a soft layer changes the answer
        assert differences[1] / differences[2] == pytest.approx(100.0, rel=0.05)  # as 1/k
    assert max(row["methods_differ"] for row in rows) < 1e-8


def uniform_pull(method: str, mode: str, moduli: tuple[float, ...], stiffness: float = 50.0,
                 opening: float = 0.01):
    """A box of height 3 with Σ at y = 1 bonded by the elastic law, its top moved by ``opening`` normal to Σ
    (``mode`` "normal": rollers on the bottom and the left side) or along it ("shear": the bottom clamped, the
    sides held in y; ``method`` "reference": the monolithic reference): every layer's strain ε is uniform and the
    bond carries the layers' stresses together, so opening = 3ε + Σ M_i ε / k (M_i = E′_i, or G_i in shear).  The solved result, each layer's closed-form
    stress and the bond's jump Σ M_i ε / k."""
    import ddsolve

    names = [f"layer{i + 1}" for i in range(len(moduli))]
    held = ({"bottom": "y = 0.0", "left": "x = 0.0", "top": f"y = {opening!r}"} if mode == "normal" else
            {"bottom": "x = 0.0\ny = 0.0", "left": "y = 0.0", "right": "y = 0.0", "top": f"x = {opening!r}\ny = 0.0"})
    text = (f'title = "uniform {mode}"\n[geometry]\nbox = [0.0, 2.0, 0.0, 3.0]\nsigma = 1.0\ncracks = []\n'
            f'clamped = []\nlayers = {len(names)}\n[mesh]\nsize = 1.0\n'
            + "".join(f"[materials.{name}]\nE = {E!r}\nnu = 0.3\n" for name, E in zip(names, moduli))
            + "".join(f"[displacements.{name}.{side}]\n{values}\n" for name in names for side, values in held.items())
            + f'[interface]\nlaw = "elastic"\nstiffness = {stiffness!r}\n'
            + ("" if method == "reference" else f'[solver]\nmethod = "{method}"\n'))
    scene = scenes.loads(text, origin=f"uniform-{mode}")
    result = (ddsolve.reference(scene) if method == "reference" else
              ddsolve.solve(scene, progress=lambda line: None))
    M = np.array([E / (1.0 - 0.3 ** 2) if mode == "normal" else E / 2.6 for E in moduli])
    strain = opening / (3.0 + M.sum() / stiffness)
    return result, M * strain, M.sum() * strain / stiffness


def sigma_jump(result) -> np.ndarray:
    """``(k, 2)``: u⁺ − u⁻ at the Σ nodes of layer 1, in x order."""
    faces = []
    for name in ("u_minus", "u_plus"):
        points, field = result.half(name).points, result.solution[name]
        on = np.flatnonzero(np.isclose(points[:, 1], 1.0))
        faces.append(field[on[np.argsort(points[on, 0])]])
    return faces[1] - faces[0]


@pytest.mark.solve
def test_the_elastic_law_gives_the_closed_form_jump_of_a_uniform_pull_and_shear():
    cases = [(method, mode, (100.0,)) for method in ("schur", "mprgp", "fista", "reference")
             for mode in ("normal", "shear")]
    cases += [("schur", "normal", (100.0, 250.0)), ("mprgp", "shear", (100.0, 250.0)),
              ("reference", "shear", (100.0, 250.0))]
    for method, mode, moduli in cases:
        result, stresses, expected = uniform_pull(method, mode, moduli)
        assert result.converged, (method, mode)
        component = 1 if mode == "normal" else 0
        jump = sigma_jump(result)
        tolerance = 1e-12 if method in ("schur", "reference") else 1e-8  # exact, or an iteration's tol
        assert np.abs(jump[:, component] / expected - 1.0).max() < tolerance, (method, mode, moduli)
        assert np.abs(jump[:, 1 - component]).max() < tolerance * expected
        for name, stress in zip(result.reactions, stresses):  # the top's reaction: the layer's stress × width 2
            assert result.reactions[name]["top"][component] == pytest.approx(2.0 * stress, rel=tolerance)


@pytest.mark.solve
def test_newton_on_schur_and_the_secant_fixed_point_of_mprgp_agree_on_a_damaged_bond():
    from experiments import cohesive as experiment

    both = experiment.bilinear_methods()
    assert 0.5 < both["largest_damage"] < 1.0  # softening, not broken
    assert both["energy_difference"] < 1e-8 and both["damage_difference"] < 1e-6
    assert both["schur"]["rounds"] == 3 and both["schur"]["bond_solves"] < 10


@pytest.mark.solve
def test_old_results_are_unchanged_without_an_interface_table():
    import ddsolve

    scene = ddsolve.Scene.load("full-opening", ['solver.method="schur"'])
    assert scene.bond is None and "interface" not in scene.text
    result = ddsolve.solve(scene, progress=lambda line: None)
    assert "bond_solves" not in result.attrs and "damage" not in result.multipliers and "pressed" not in result.multipliers


@pytest.mark.solve
def test_uzawa_feti_and_the_reference_refuse_what_they_do_not_solve_in_one_line():
    import ddsolve

    for method in ("uzawa", "feti"):
        scene = ddsolve.Scene.load("full-opening", [f'solver.method="{method}"', 'interface.law="elastic"',
                                                    "interface.stiffness=1e3"])
        with pytest.raises(DDSolveError) as error:
            ddsolve.solve(scene, progress=lambda line: None)
        assert "interface.law" in str(error.value) and "\n" not in str(error.value)
    bilinear = ddsolve.Scene.load("full-opening", ['interface.law="bilinear"', "interface.strength=0.002",
                                                   "interface.toughness=1e-6"])
    with pytest.raises(DDSolveError) as error:
        ddsolve.reference(bilinear)
    assert 'interface.law = "bilinear"' in str(error.value) and "\n" not in str(error.value)


@pytest.mark.solve
def test_the_reference_solves_the_elastic_bond_as_springs_and_equals_schur():
    import ddsolve
    from ddsolve.post import analysis

    scene = ddsolve.Scene.load("partial-closure", ['interface.law="elastic"', "interface.stiffness=1e5",
                                                   "mesh.size=0.25", 'solver.method="schur"'])
    reference = ddsolve.reference(scene)
    decomposed = ddsolve.solve(scene, progress=lambda line: None)
    assert reference.converged and reference.attrs["closed_vertices"] > 0  # contact and the bond together
    assert analysis.compare(decomposed, reference).energy_error < 1e-12
    assert decomposed.attrs["energy"] == pytest.approx(reference.attrs["energy"], rel=1e-12)
    rigid = ddsolve.reference(ddsolve.Scene.load("partial-closure", ["mesh.size=0.25"]))
    assert analysis.compare(rigid, reference).energy_error > 1e-4  # the springs count


@pytest.mark.solve
@pytest.mark.slow
def test_a_dcb_grown_with_the_bilinear_law_follows_griffith():
    """The acceptance DCB at mesh size 0.125 (5 Σ nodes per process zone), to just past initiation: within 1 % of
    the linear curve before damage, within 3 % of Griffith's growth curve once the crack grows."""
    from experiments import cohesive as experiment

    record = experiment.dcb_growth(limit=0.14, steps=7, size=0.125)
    assert record["before_damage"] < 0.01
    assert np.isfinite(record["grown"]) and record["grown"] < 0.03
    assert max(record["tip"]) > experiment.CRACK + 0.25  # the crack has grown
    assert record["elements_per_zone"] >= 4
    assert record["irreversible"]  # no vertex's damage ever falls from one step to the next


@pytest.mark.mpi
def test_grow_unloads_along_the_secant_and_reloads_to_the_old_peak(tmp_path):
    """A coarse DCB (P2, size 0.5) driven by ``grow --to 0.1,0,0.12``: damaged at 0.1, unloaded to 0 and reloaded:
    the damage stays fixed and the force follows the secant through the origin until the old peak, then the
    damage grows again and the force falls below that line.  Bad paths are refused in one line."""
    from conftest import ddsolve, refused
    from experiments import cohesive as experiment

    from ddsolve.solvers import growth_files

    scene = experiment.dcb_scene(True, size=0.5)
    toml, output = scene.base / "dcb-bond.toml", tmp_path / "path.h5"
    ddsolve("grow", str(toml), "--to", "0.1,0,0.12", "--steps", "4", "--pictures", "1", "-o", str(output))
    run = growth_files.read(output)
    assert list(run["attrs"]["path"]) == [0.1, 0.0, 0.12]
    control, load, damage = run["control"], run["load"], run["damage"]
    peak = int(np.flatnonzero(control == 0.1)[0])
    assert damage[peak].max() > 0.0  # softening before the unloading
    secant = load[peak] / run["displacement"][peak]
    after = np.arange(peak, len(control))
    below = after[control[after] <= 0.1]  # unloaded to 0 and reloaded to the old peak
    assert control[below].min() == 0.0 and abs(load[below][control[below] == 0.0]).max() < 1e-12 * load[peak]
    assert np.allclose(load[below], secant * run["displacement"][below], rtol=1e-9, atol=1e-12 * load[peak])
    assert np.all(damage[below] == damage[peak])
    assert damage[-1].max() > damage[peak].max() and load[-1] < secant * run["displacement"][-1] * (1 - 1e-3)
    assert any("turns down" in event for event in run["events"]) and any("turns up" in e for e in run["events"])
    assert (tmp_path / f"path-step{len(control) - 1}.png").exists()  # the picture solved again from its start
    for path in ("0.1,0.1", "0,0.1", "0.1,-0.05"):
        refused(ddsolve("grow", str(toml), "--to", path, "-o", str(tmp_path / "bad.h5"), check=False), 2, "--to")
    refused(ddsolve("grow", "partial-closure", "--set", "fracture.toughness=1e-6", "--to", "0.2,0.1", "-o",
                    str(tmp_path / "bad.h5"), check=False), 2, "--to 0.2,0.1", "damaging bond")
