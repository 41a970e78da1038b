"""Stacked structures against their closed forms: ``./run stacks`` writes docs/stacks.md, docs/stacks-*.png and
results/stacks.h5.

Every case is solved by the monolithic reference in this process (the DD methods converge to it) and set beside
its closed form with its wall time (mesh, solve and G):

- the Griffith interface crack between two materials, half model (:mod:`experiments.interface_crack`), over a
  range of stiffness ratios, mesh-converged for the ratios 10 and 100;
- a bi-material DCB (:mod:`experiments.regions`) bent by end couples (beam theory with each arm's own stiffness,
  exact once the tip's field is steady) and pulled by end forces at growing a/h (Kanninen's two-beam
  foundation for the root rotation), and a bi-material ENF on point supports (the arms in frictionless contact
  share the curvature over the crack, the bonded part bends about the composite neutral axis);
- the thermal bilayer's curvature (Timoshenko) and its edge delamination's G against crack length, approaching
  the steady state of Suo and Hutchinson: the strain energy per unit length stored in the bonded bilayer;
- a laminate with two delaminations at two interfaces (:mod:`experiments.laminate`).
"""
from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from experiments import interface_crack, regions, report
from experiments.delamination import ARM, CHI_II, LENGTH, SPAN, plane_strain_modulus, strip_geo

RESULTS = Path("results")
DOCS = Path("docs")
#: The Griffith crack's stiffness ratios E₁/E₂ at the middle mesh, and those refined twice (mesh.size in a).
RATIOS, REFINED = (1.0, 3.0, 10.0, 30.0, 100.0), (10.0, 100.0)
GRIFFITH_SIZES = (4.0, 2.0, 1.0)
#: Crack lengths a (h = 1) of the couple-loaded and the force-loaded DCB and of the ENF; the beams' mesh sizes.
MOMENT_CRACKS, FORCE_CRACKS, ENF_CRACKS = (5.0, 10.0), (5.0, 10.0, 20.0, 40.0), (5.0, 10.0, 15.0)
#: The ENF's arms: the DCB's (stiff above, soft below), and both the stiff one (the setup against the standard ENF).
ARMS = {"dissimilar": regions.DCB_REGIONS, "identical": {"upper": regions.DCB_REGIONS["upper"],
                                                         "lower": regions.DCB_REGIONS["upper"]}}
BEAM_SIZES = (0.2, 0.1)
#: Kanninen's root rotation: each arm a beam on the Winkler foundation of the arms' halves (stiffness
#: 2/(h(1/E₁′ + 1/E₂′)) between them): λ⁴ = 6/h⁴ for arms of equal thickness whatever their moduli, χ = 1/(λh).
CHI_KANNINEN = 6.0 ** -0.25
#: The ENF's midspan load: a Gaussian of width LOAD_WIDTH on the top, P/2 = ENF_LOAD/2 on each layer.
ENF_LOAD, LOAD_WIDTH = 1e-3, 0.25
#: The edge delamination's crack lengths from the free end (the bilayer 2h thick, h = 1).
EDGE_CRACKS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
EDGE_SIZE = 0.1


def timed(function, *args, **kwargs) -> dict:
    """``function(*args, **kwargs)`` (a row) with its wall time as ``seconds``."""
    started = time.perf_counter()
    row = function(*args, **kwargs)
    return {**row, "seconds": time.perf_counter() - started}


# --- closed forms ----------------------------------------------------------------------------------------
def composite_rigidity(moduli: dict[str, float], h: float) -> float:
    """(EI) of the bonded strip, region ``lower`` (−h, 0) below ``upper`` (0, h), about its neutral axis."""
    centres = {"lower": -0.5 * h, "upper": 0.5 * h}
    axis = sum(moduli[r] * centres[r] for r in moduli) / sum(moduli.values())
    return sum(E * (h ** 3 / 12.0 + h * (centres[r] - axis) ** 2) for r, E in moduli.items())


def enf_release(moment: float, h: float, moduli: dict[str, float]) -> float:
    """G of a bi-material ENF with the moment M at the tip: the arms in frictionless contact share the curvature
    (M splits by bending stiffness), the bonded part bends as one: G = M²/2 [1/(E₁I₁ + E₂I₂) − 1/(EI)_c]."""
    split = sum(E * h ** 3 / 12.0 for E in moduli.values())
    return 0.5 * moment * moment * (1.0 / split - 1.0 / composite_rigidity(moduli, h))


def bilayer_state(regions_: dict[str, tuple[float, float, float]], dT: float, h: float) -> dict[str, float]:
    """The bonded bilayer far from its ends (plane strain, one sheet): the strain ε₀ + κy minimizing the energy
    Σ ∫ E′/2 (ε₀ + κy − m)² dy, m = (1 + ν)αΔT (the plane-strain eigenstrain; the out-of-plane stress's energy is
    the same bonded and free), its curvature w″ = −κ and the energy per unit length U — the steady-state G of an
    edge delamination, behind whose tip both layers are free and stress-free (Suo and Hutchinson 1990)."""
    spans = {"lower": (-h, 0.0), "upper": (0.0, h)}
    normal, load, constant = np.zeros((2, 2)), np.zeros(2), 0.0
    for region, (E, nu, alpha) in regions_.items():
        modulus, mismatch = plane_strain_modulus(E, nu), (1.0 + nu) * alpha * dT
        lo, hi = spans[region]
        moments = np.array([hi - lo, (hi ** 2 - lo ** 2) / 2.0, (hi ** 3 - lo ** 3) / 3.0])
        normal += modulus * np.array([[moments[0], moments[1]], [moments[1], moments[2]]])
        load += modulus * mismatch * moments[:2]
        constant += modulus * mismatch ** 2 * moments[0]
    strain, kappa = np.linalg.solve(normal, load)
    return {"strain": float(strain), "curvature": float(-kappa), "energy": float(0.5 * (constant - load @ (strain,
                                                                                                         kappa)))}


# --- the cases -----------------------------------------------------------------------------------------
def griffith_rows() -> list[dict]:
    """The half-model Griffith crack: every ratio at the middle size, the refined ratios at all three."""
    rows = []
    for ratio in RATIOS:
        sizes = GRIFFITH_SIZES if ratio in REFINED else GRIFFITH_SIZES[1:2]
        for size in sizes:
            row = timed(interface_crack.griffith, ratio, size)
            rows.append(row)
            print(f"stacks: Griffith, E1/E2 = {ratio:g}, size {size:g}a: G {row['error']:+.3%}, ψ(2a) "
                  f"{row['phase'] - row['phase_theory']:+.3f}° off atan 2ε, {row['seconds']:.1f} s", flush=True)
    return rows


def dcb_rows() -> list[dict]:
    """The bi-material DCB: couples at MOMENT_CRACKS, forces at FORCE_CRACKS (the strip a + 10h long), both
    sizes."""
    rows = []
    for size in BEAM_SIZES:
        for loading, cracks in (("moment", MOMENT_CRACKS), ("force", FORCE_CRACKS)):
            for a in cracks:
                row = timed(regions.dcb, a, size, loading=loading, length=max(regions.LENGTH, a + 10.0 * ARM),
                            chi=CHI_KANNINEN)
                simple = row["theory"] * (a / (a + CHI_KANNINEN * ARM)) ** 2 if loading == "force" else row["theory"]
                rows.append({**row, "loading": loading, "size": size, "simple": simple,
                             "implied_chi": implied_chi(row["G"], simple, a, 0.0)})
                print(f"stacks: DCB, {loading}, a = {a:g}, size {size:g}: G {row['error']:+.3%}, "
                      f"{row['seconds']:.1f} s", flush=True)
    return rows


def implied_chi(G: float, theory: float, a: float, chi: float) -> float:
    """The tip correction χ with which beam theory, G ∝ (a + χh)², gives the computed G."""
    return ((a + chi * ARM) * math.sqrt(G / theory) - a) / ARM


def faces(result) -> dict[str, float]:
    """The crack faces: their largest gap against the largest displacement, and the length of Σ in contact."""
    from ddsolve.post import analysis

    gap = float(analysis.normal_jump(result).max()) / analysis.largest_displacement(result.solution.values())
    return {"gap": gap, "contact": float(sum(high - low for low, high in result.fracture.zones))}


def bending_enf(a: float, size: float, moment: float = regions.MOMENT) -> dict:
    """The bi-material strip cracked over (0, a), clamped at x = LENGTH, its end face x = 0 bent by the couple
    ``moment`` (summed over the layers) shared by the arms as one curvature κ (σxx = E′κ(y − c) on each arm's
    face, c its centre): the arms slide over each other without pressing, G = :func:`enf_release` exactly once
    the tip's field is steady (the mode II counterpart of the couple-loaded DCB)."""
    from ddsolve.problem import scene

    moduli = {region: plane_strain_modulus(E, nu) for region, (E, nu) in regions.DCB_REGIONS.items()}
    kappa = moment / (2.0 * sum(moduli.values()) * ARM ** 3 / 12.0)
    centres = {"lower": -0.5 * ARM, "upper": 0.5 * ARM}
    loads = "".join(f'[loads.{layer}.left_{region}]\nx = "{modulus * kappa!r} * (y - {centres[region]!r})"\n'
                    for layer in ("layer1", "layer2") for region, modulus in moduli.items())
    with tempfile.TemporaryDirectory() as folder:
        geo = strip_geo(LENGTH, ARM, [(0.0, a)], {"clamped": [("right", -ARM, ARM)]})
        (Path(folder) / "bending.geo").write_text(geo)
        text = (f'title = "bi-material strip bent by a couple, a = {a:g}"\n[mesh]\nfile = "bending.geo"\n'
                f"size = {size!r}\ndegree = 2\ngrading = true\n{regions.region_materials(regions.DCB_REGIONS)}{loads}")
        result = regions.solved(scene.loads(text, origin="bi-material bending", base=Path(folder)))
    theory = enf_release(moment, ARM, {region: 2.0 * modulus for region, modulus in moduli.items()})
    G = float(result.fracture.G[0])
    return {"a": a, "size": size, "G": G, "theory": theory, "error": G / theory - 1.0,
            "phase": float(result.fracture.phase[0]), **faces(result), "unknowns": result.unknowns}


def enf_text(a: float, size: float, arms: str = "dissimilar") -> str:
    """The bi-material ENF: the strip (0, SPAN) × (−h, h) cracked over (0, a), a roller at the lower left corner,
    a pin at the lower right one (points: a segment would hold the ends' rotation), the midspan load a Gaussian
    on the top; both layers the ``arms``' regions, each carrying half."""
    q = 0.5 * ENF_LOAD / (LOAD_WIDTH * math.sqrt(math.pi))
    middle = 0.5 * SPAN
    per_layer = (f'[loads.{{layer}}.top]\ny = "{-q!r} * exp(-((x - {middle!r}) / {LOAD_WIDTH!r})^2)"\n'
                 f"[displacements.{{layer}}.roller]\npoint = [0.0, {-ARM!r}]\ny = 0.0\n"
                 f"[displacements.{{layer}}.pin]\npoint = [{SPAN!r}, {-ARM!r}]\nx = 0.0\ny = 0.0\n")
    return (f'title = "bi-material ENF, a = {a:g}"\n[geometry]\nbox = [0.0, {SPAN!r}, {-ARM!r}, {ARM!r}]\n'
            f"sigma = 0.0\ncrack = [0.0, {a!r}]\nclamped = []\n[mesh]\nsize = {size!r}\ndegree = 2\ngrading = true\n"
            + regions.region_materials(ARMS[arms])
            + "".join(per_layer.format(layer=layer) for layer in ("layer1", "layer2")))


def enf(a: float, size: float, arms: str = "dissimilar") -> dict:
    """The bi-material ENF against :func:`enf_release` with M = R (a + χ_II h) at the tip, R the roller's
    reaction (summed over the layers) and χ_II the homogeneous ENF's tip correction."""
    from ddsolve.problem import scene

    result = regions.solved(scene.loads(enf_text(a, size, arms), origin="bi-material ENF"))
    reaction = float(sum(forces["roller"][1] for forces in result.reactions.values()))
    moduli = {region: 2.0 * plane_strain_modulus(E, nu) for region, (E, nu) in ARMS[arms].items()}
    theory = enf_release(reaction * (a + CHI_II * ARM), ARM, moduli)
    simple = enf_release(reaction * a, ARM, moduli)
    G = float(result.fracture.G[0])
    return {"a": a, "size": size, "arms": arms, "G": G, "theory": theory, "error": G / theory - 1.0, "simple": simple,
            "reaction": reaction, "implied_chi": implied_chi(G, simple, a, 0.0),
            "G_I": float(result.fracture.G_I[0]), "phase": float(result.fracture.phase[0]), **faces(result),
            "unknowns": result.unknowns}


def enf_rows() -> list[dict]:
    rows = []
    for arms in ARMS:
        for size in BEAM_SIZES:
            for a in ENF_CRACKS:
                row = timed(enf, a, size, arms)
                rows.append(row)
                print(f"stacks: ENF, {arms} arms, a = {a:g}, size {size:g}: G {row['error']:+.3%} (reaction "
                      f"{row['reaction']:.6e}), {row['seconds']:.1f} s", flush=True)
    return rows


def edge(crack: float, size: float = EDGE_SIZE) -> dict:
    """The thermal bilayer with Σ cracked over ``crack`` from its free end: G against the steady state."""
    with tempfile.TemporaryDirectory() as folder:
        result = regions.solved(regions.bimetal_scene(Path(folder), size, crack=crack))
    steady = 2.0 * bilayer_state(regions.BIMETAL_REGIONS, regions.HEATING, ARM)["energy"]  # both sheets
    G = float(result.fracture.G[0])
    return {"crack": crack, "size": size, "G": G, "theory": steady, "error": G / steady - 1.0,
            "phase": float(result.fracture.phase[0]), "zones": int(len(result.fracture.zones)),
            "unknowns": result.unknowns}


def thermal_rows() -> dict:
    """The bilayer's curvature at two sizes and the edge delamination at every crack length."""
    curvature = []
    for size in BEAM_SIZES:
        row = timed(regions.bimetal, size)
        curvature.append({**row, "size": size})
        print(f"stacks: bilayer curvature, size {size:g}: {row['error']:+.4%}, {row['seconds']:.1f} s", flush=True)
    edges = []
    for crack in EDGE_CRACKS:
        row = timed(edge, crack)
        edges.append(row)
        print(f"stacks: edge delamination, c = {crack:g}: G {row['error']:+.3%} of G_ss, {row['seconds']:.1f} s",
              flush=True)
    return {"curvature": curvature, "edge": edges}


def bending_rows() -> list[dict]:
    rows = []
    for size in BEAM_SIZES:
        for a in MOMENT_CRACKS:
            row = timed(bending_enf, a, size)
            rows.append(row)
            print(f"stacks: strip bent by a couple, a = {a:g}, size {size:g}: G {row['error']:+.4%}, "
                  f"{row['seconds']:.1f} s", flush=True)
    return rows


# --- the command ---------------------------------------------------------------------------------------
#: The record's sections, in the page's order: name -> the function measuring its rows.
SECTIONS = {"griffith": griffith_rows, "dcb": dcb_rows, "bending": bending_rows, "enf": enf_rows}


def measurements() -> dict:
    """Every case, its closed form and wall time; the provenance."""
    from ddsolve.parallel import launch

    record = {name: measure() for name, measure in SECTIONS.items()}
    record.update(thermal_rows())
    record["provenance"] = launch.provenance()
    return record


def stacks() -> None:
    """Solve every case, keep results/stacks.h5, draw, write docs/stacks.md's generated sections (the laminate's:
    :func:`experiments.laminate.laminate`)."""
    from experiments.laminate import laminate

    RESULTS.mkdir(exist_ok=True)
    record = measurements()
    sections = [name for name in record if name != "provenance"]
    report.write_records(RESULTS / "stacks.h5", [{"case": name, "rows": record[name]} for name in sections],
                         {key: str(value) for key, value in record["provenance"].items()})
    draw(record)
    laminate()


def draw(record: dict) -> None:
    griffith_plot(record)
    beams_plot(record)
    thermal_plot(record)
    report.section(DOCS / "stacks.md", "stacks", text(record))


# --- pictures ------------------------------------------------------------------------------------------
def _pyplot():
    from ddsolve.post.plots import _pyplot as pyplot

    return pyplot()


def finest(rows: list[dict], **match) -> list[dict]:
    """The rows matching ``match`` on their finest mesh (the most unknowns) for each crack length or ratio."""
    chosen: dict = {}
    for row in rows:
        if all(row[key] == value for key, value in match.items()):
            key = row.get("ratio", row.get("a", row.get("crack")))
            if key not in chosen or row["unknowns"] > chosen[key]["unknowns"]:
                chosen[key] = row
    return [chosen[key] for key in sorted(chosen)]


def worst(rows: list[dict], key: str = "error") -> float:
    return max(abs(row[key]) for row in rows)


def griffith_plot(record: dict) -> None:
    """G's error against the tip's Σ spacing for the refined ratios; ψ(2a) against the ratio with atan 2ε."""
    plt = _pyplot()
    rows = record["griffith"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for ratio in REFINED:
        data = [row for row in rows if row["ratio"] == ratio]
        left.semilogx([row["spacing"] for row in data], [100.0 * row["error"] for row in data], "o-",
                      label=f"E₁/E₂ = {ratio:g} (mesh.size 4a, 2a, a)")
    left.axhspan(-2.0, 2.0, color="0.92", label="±2 %")
    left.set_xlabel("Σ edge at the tip / a")
    left.set_ylabel("G / closed form − 1 [%]")
    best = finest(rows)
    left.set_title(f"G, half model: finest meshes within {worst(best):.2%}", fontsize=10)
    left.grid(alpha=0.3, which="both")
    left.legend(fontsize=8)
    ratios = np.geomspace(1.0, 100.0, 100)
    right.semilogx(ratios, [interface_crack.closed_form(r)["phase"] for r in ratios], "k-", label="atan 2ε")
    right.semilogx([row["ratio"] for row in best], [row["phase"] for row in best], "o", fillstyle="none",
                   markersize=8, label="ψ(l = 2a), ddsolve")
    off = max(abs(row["phase"] - row["phase_theory"]) for row in best)
    right.set_title(f"phase at l = 2a: within {off:.3f}° of atan 2ε", fontsize=10)
    right.set_xlabel("E₁ / E₂ (material 1 above)")
    right.set_ylabel("ψ [°]")
    right.grid(alpha=0.3, which="both")
    right.legend(fontsize=8)
    fig.savefig(DOCS / "stacks-griffith.png", dpi=110)
    plt.close(fig)


def beams_plot(record: dict) -> None:
    """G / beam theory − 1 against a/h: the DCB by couples and by forces, the ENF by a couple and at three points."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    panels = (("bi-material DCB", (by_loading(record, "moment"), "o", "by end couples (exact)"),
               (by_loading(record, "force"), "s", f"by end forces, χ = 6^(−1/4) = {CHI_KANNINEN:.3f} (Kanninen)")),
              ("bi-material ENF", (record["bending"], "o", "bent by a couple (exact)"),
               (by_arms(record, "dissimilar"), "s", f"three points, χ_II = {CHI_II:g} (homogeneous)")))
    for ax, (name, exact, corrected) in zip(axes, panels):
        for rows, marker, label in (exact, corrected):
            for size, fill in zip(BEAM_SIZES, ("none", "full")):
                data = [row for row in rows if row["size"] == size]
                ax.plot([row["a"] / ARM for row in data], [100.0 * row["error"] for row in data], marker + "-",
                        fillstyle=fill, label=f"{label}, size {size:g}")
        ax.axhspan(-2.0, 2.0, color="0.92")
        ax.set_xlabel("a / h")
        ax.set_ylabel("G / beam theory − 1 [%]")
        ax.set_title(f"{name}: the exact theory within {worst(finest(exact[0])):.3%};\n"
                     f"the tip-corrected one {worst(finest(corrected[0])):.1%} off at worst", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for size, fill in zip(BEAM_SIZES, ("none", "full")):
        data = [row for row in by_arms(record, "identical") if row["size"] == size]
        axes[1].plot([row["a"] / ARM for row in data], [100.0 * row["error"] for row in data], "^-", fillstyle=fill,
                     label=f"three points, identical arms (the standard ENF), size {size:g}")
    axes[1].legend(fontsize=7)
    fig.savefig(DOCS / "stacks-beams.png", dpi=110)
    plt.close(fig)


def by_loading(record: dict, loading: str) -> list[dict]:
    return [row for row in record["dcb"] if row["loading"] == loading]


def by_arms(record: dict, arms: str) -> list[dict]:
    return [row for row in record["enf"] if row["arms"] == arms]


def thermal_plot(record: dict) -> None:
    """The edge delamination's G against its length, approaching G_ss."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.2), constrained_layout=True)
    rows = record["edge"]
    ax.plot([row["crack"] / (2.0 * ARM) for row in rows], [row["G"] / row["theory"] for row in rows], "o-",
            label="ddsolve")
    ax.axhline(1.0, color="k", linestyle="--", label="G_ss: the bonded bilayer's energy per length")
    ax.set_xlabel("crack length c / H (H = 2h, the bilayer's thickness)")
    ax.set_ylabel("G / G_ss")
    long = [row for row in rows if row["crack"] >= 2.0 * ARM]
    curvature = worst(record["curvature"])
    ax.set_title(f"edge delamination: G within {worst(long):.3%} of G_ss for c ≥ H;\n"
                 f"the bilayer's curvature within {curvature:.3%} of Timoshenko's", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(DOCS / "stacks-thermal.png", dpi=110)
    plt.close(fig)


# --- the page ------------------------------------------------------------------------------------------
def table(header: list[str], rows: list[list[str]]) -> list[str]:
    """A markdown table."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + ["| " + " | ".join(row) + " |"
                                                                           for row in rows]


def _percent(value: float, digits: int = 2) -> str:
    return f"{100.0 * value:+.{digits}f} %"


def slope_error(rows: list[dict]) -> float:
    """The largest relative error of dG/d(a²)-like stiffness: ((√G₂ − √G₁)/(√B₂ − √B₁))² − 1 between successive
    crack lengths, B the uncorrected beam theory (∝ a²): the tip correction cancels, the arms' stiffness stays."""
    rows = sorted(rows, key=lambda row: row["a"])
    return max((abs(((math.sqrt(b["G"]) - math.sqrt(a["G"])) / (math.sqrt(b["simple"]) - math.sqrt(a["simple"])))
                    ** 2 - 1.0) for a, b in zip(rows, rows[1:])), default=math.nan)


def summary(record: dict) -> list[list[str]]:
    """One row per case at its finest mesh: closed form, ddsolve, error, unknowns, wall time."""
    cases = [(f"Griffith interface crack, E₁/E₂ = {row['ratio']:g}, G", row) for row in finest(record["griffith"])]
    cases += [(f"Griffith interface crack, E₁/E₂ = {row['ratio']:g}, ψ(2a) against atan 2ε", row)
              for row in finest(record["griffith"]) if row["ratio"] in REFINED]
    cases += [(f"DCB by end couples, a/h = {row['a']:g}", row) for row in finest(by_loading(record, "moment"))]
    cases += [(f"DCB by end forces, a/h = {row['a']:g} (Kanninen's χ)", row)
              for row in finest(by_loading(record, "force"))]
    cases += [(f"ENF bent by a couple, a/h = {row['a']:g}", row) for row in finest(record["bending"])]
    cases += [(f"ENF, three points, {arms} arms, a/h = {row['a']:g} (χ_II = {CHI_II:g})", row)
              for arms in ARMS for row in finest(by_arms(record, arms))]
    cases += [("thermal bilayer, curvature (Timoshenko)", finest(record["curvature"])[-1])]
    cases += [(f"edge delamination, c = {row['crack']:g}h, G_ss", row) for row in record["edge"]
              if row["crack"] == max(EDGE_CRACKS)]
    out = []
    for label, row in cases:
        if "ψ(2a)" in label:
            values = [f"{row['phase_theory']:.3f}°", f"{row['phase']:.3f}°",
                      f"{row['phase'] - row['phase_theory']:+.3f}°"]
        else:
            closed, computed = (row["theory"], row["curvature"]) if "curvature" in row else (row["theory"], row["G"])
            values = [f"{closed:.6e}", f"{computed:.6e}", _percent(row["error"], 3)]
        out.append([label, *values, f"{row['unknowns']:,}", f"{row['seconds']:.1f} s"])
    return out


def text(record: dict) -> str:
    """docs/stacks.md's generated section from a record of ``./run stacks``."""
    commit = record["provenance"].get("git_commit", "")[:10]
    out = [f"Generated by `./run stacks` ({commit}). Every case solved by the monolithic reference in one process "
           "(the DD methods converge to it), graded P2 meshes, plane strain; the wall time is the mesh, the solve "
           "and G. The summary gives each case at its finest mesh; the sections below give every mesh.", "",
           "### Summary", "",
           *table(["case", "closed form", "ddsolve", "error", "unknowns", "wall time"], summary(record))]
    out += _griffith(record) + _dcb(record) + _enf(record) + _thermal(record)
    return "\n".join(out)


def _griffith(record: dict) -> list[str]:
    rows = record["griffith"]
    out = ["", "### The Griffith interface crack", "",
           "A crack of length 2a on the interface of an infinite body, material 1 above (E₁ = ratio × E₂, ν = "
           f"{interface_crack.NU:g} both), under remote tension σ = {interface_crack.TENSION:g}: G = (1/Ē₁ + 1/Ē₂)"
           "(1 + 4ε²)πaσ²/(2 cosh²πε) per sheet, ψ = arg(K l^{iε}) = atan 2ε at l = 2a (Rice and Sih 1965; "
           "Hutchinson and Suo 1992). **Half model**: x ≥ 0 with a roller on the symmetry plane x = 0, which the "
           f"crack [0, a] on Σ reaches; the box (0, W) × (−W, W), W = {interface_crack.WIDTH:g}a, is large enough "
           "that the finite width changes G by about (πa/2W)²/4 ≈ 10⁻⁴ (Feddersen's √sec(πa/2W)), so no correction "
           "is applied. The closed form's remote state has equal strains along the interface: the upper material "
           "carries σxx = ν′σ(1 − Ē₁/Ē₂) on the far side (ν′ = ν/(1 − ν)). The body is one layer "
           "(`geometry.layers = 1`); the scene is `experiments.interface_crack.scene_text`. "
           "`mesh.size` is the largest element, in units of a; the grading refines towards the tip.", "",
           "![Griffith interface crack](stacks-griffith.png)", ""]
    out += table(["E₁/E₂", "mesh.size", "Σ edge at the tip", "unknowns", "G", "closed form", "error", "ε",
                  "ψ(2a)", "atan 2ε", "ψ − atan 2ε", "G(\\|K\\|)/G − 1", "wall time"],
                 [[f"{row['ratio']:g}", f"{row['size']:g}a", f"{row['spacing']:.2g}a", f"{row['unknowns']:,}",
                   f"{row['G']:.6e}", f"{row['theory']:.6e}", _percent(row["error"], 3), f"{row['epsilon']:.6f}",
                   f"{row['phase']:.3f}°", f"{row['phase_theory']:.3f}°", f"{row['phase'] - row['phase_theory']:+.3f}°",
                   f"{row['G_of_K'] / row['G'] - 1.0:+.1e}" if math.isfinite(row["G_of_K"]) else "(ε = 0)",
                   f"{row['seconds']:.1f} s"] for row in rows])
    return out


def _dcb(record: dict) -> list[str]:
    force = finest(by_loading(record, "force"))
    out = ["", "### Bi-material DCB", "",
           f"The strip (0, L) × (−h, h), h = {ARM:g}, cracked along Σ over (0, a), clamped at x = L (L = 20, or "
           f"a + 10h where that is longer); the arm above Σ E = {regions.DCB_REGIONS['upper'][0]:g}, below "
           f"E = {regions.DCB_REGIONS['lower'][0]:g} (ν = {regions.DCB_REGIONS['upper'][1]:g}), so ε = "
           f"{force[0]['epsilon']:.4f}. Beam theory with each arm's own stiffness (plane strain, per unit width, "
           "summed over the layers): G = M²/2 · (1/(E′I)₊ + 1/(E′I)₋), M the moment at the tip. **By end couples** M this "
           "is exact once the tip's field is steady (the energy per length far behind the tip minus far ahead). "
           "**By end forces** P, M = P(a + χh) with the root rotation χ of the arms at the tip: Kanninen's beams on "
           "an elastic foundation (Kanninen 1973), here two beams tied by the springs of their halves, stiffness "
           "2/(h(1/E₊′ + 1/E₋′)), give λ⁴ = 6/h⁴ whatever the moduli, χ = 6^(−1/4) = "
           f"{CHI_KANNINEN:.3f}. The shear part of the correction depends on the tip's field and has no closed form "
           "(Li, Wang and Thouless 2004): the force-loaded rows show the χ the computed G implies, and how the "
           f"error falls with a/h. The arms' stiffness alone is checked by the slope of √G against a between "
           f"successive lengths, where χ cancels: within {slope_error(force):.2%} of beam theory.", "",
           "![Bi-material DCB and ENF](stacks-beams.png)", ""]
    out += table(["loading", "a/h", "mesh.size", "unknowns", "G", "beam theory", "error", "implied χ", "ψ at l = 1",
                  "wall time"],
                 [[row["loading"], f"{row['a']:g}", f"{row['size']:g}", f"{row['unknowns']:,}", f"{row['G']:.6e}",
                   f"{row['theory']:.6e}", _percent(row["error"], 3),
                   f"{row['implied_chi']:.3f}" if row["loading"] == "force" else "", f"{row['phase']:.2f}°",
                   f"{row['seconds']:.1f} s"] for row in record["dcb"]])
    return out


def _enf(record: dict) -> list[str]:
    three = finest(by_arms(record, "dissimilar"))
    out = ["", "### Bi-material ENF", "",
           "The DCB's arms sliding over each other. The arms in frictionless contact share the curvature over the "
           "crack, so the moment splits by bending stiffness, and the bonded part bends about the composite neutral "
           "axis: G = M²/2 [1/(E₊′I + E₋′I) − 1/(E′I)_c] per unit width (summed over the layers), M the moment at "
           "the tip. **Bent by a couple**: the strip of the DCB, its end face x = 0 loaded by σxx = E′κ(y − c) on "
           "each arm (c the arm's centre, κ = M/(E₊′I + E₋′I): the arms' share of one curvature), clamped at "
           "x = 20: no shear anywhere, the formula exact once the tip's field is steady (the mode II counterpart of "
           "the DCB by couples). **Three points** (ASTM D7905 proportions, span 2L = "
           f"{SPAN:g}): a roller at the lower left corner and a pin at the lower right one (points: a segment would "
           "hold the end's rotation with a couple), the midspan load P a Gaussian of width "
           f"{LOAD_WIDTH:g} on the top, M = R(a + χ_II h) with R the roller's reaction (read from the solution) and "
           f"the homogeneous ENF's χ_II = {CHI_II:g} (Bao et al. 1992). With identical arms (both E = "
           f"{ARMS['identical']['upper'][0]:g}) this is the standard ENF, and the setup gives it within "
           f"{worst(finest(by_arms(record, 'identical'))):.2%}. Dissimilar arms open over the crack, bent by a couple "
           f"(the largest gap {max(row['gap'] for row in finest(record['bending'])):.1e} of the largest displacement) "
           f"as at three points ({max(row['gap'] for row in three):.1e}, against "
           f"{max(row['gap'] for row in finest(by_arms(record, 'identical'))):.1e} with identical arms): each arm's "
           "root rotates by its own amount. Bent by a couple that changes nothing, each arm's couple being its share "
           "by construction; at three points the roller's force reaches the upper arm only through the contact at "
           f"the mouth (the first {min(row['contact'] for row in three):.2g}–"
           f"{max(row['contact'] for row in three):.2g}h), so the arms' shares are set there by their compliances as "
           "cantilevers, root rotations included, not by one shared curvature. The homogeneous correction does "
           "not carry over, and the shear part of a tip correction depends on the tip's field, without a closed form (Li, Wang and "
           "Thouless 2004): the computed G implies χ ≈ "
           f"{np.mean([row['implied_chi'] for row in three]):.2f} at every a/h and mesh, so the tip-corrected rows "
           "miss by the amount shown, falling as 1/a; the slope of √G against a, where χ cancels, is within "
           f"{slope_error(three):.2%} of the beam theory's stiffness.", ""]
    out += table(["case", "a/h", "mesh.size", "unknowns", "G", "beam theory", "error", "implied χ",
                  "ψ at l = 1", "largest gap / largest \\|u\\|", "Σ in contact", "wall time"],
                 [[case, f"{row['a']:g}", f"{row['size']:g}", f"{row['unknowns']:,}", f"{row['G']:.6e}",
                   f"{row['theory']:.6e}", _percent(row["error"], 3), chi, f"{row['phase']:.2f}°", f"{row['gap']:.1e}",
                   f"{row['contact']:.3g}", f"{row['seconds']:.1f} s"]
                  for case, rows in (("bent by a couple", record["bending"]),
                                     *((f"three points, {arms} arms", by_arms(record, arms)) for arms in ARMS))
                  for row in rows for chi in [f"{row['implied_chi']:.3f}" if "implied_chi" in row else ""]])
    return out


def _thermal(record: dict) -> list[str]:
    (E_up, nu_up, alpha_up), (E_low, nu_low, alpha_low) = (regions.BIMETAL_REGIONS[r] for r in ("upper", "lower"))
    state = bilayer_state(regions.BIMETAL_REGIONS, regions.HEATING, ARM)
    out = ["", "### Thermal bilayer", "",
           f"The strip (0, 20) × (−h, h) above Σ E = {E_up:g}, ν = {nu_up:g}, α = {alpha_up:g}, below E = {E_low:g}, "
           f"ν = {nu_low:g}, α = {alpha_low:g}, heated by ΔT = {regions.HEATING:g}: half of a free strip 40 long "
           "(x = 0 a symmetry plane). Its curvature (a least-squares fit of Σ's deflection w₀ + κx²/2 away from the "
           "free end) against Timoshenko's bimetal formula (1925, plane strain: α → (1 + ν)α, E → E′):", ""]
    out += table(["mesh.size", "unknowns", "curvature", "Timoshenko", "error", "wall time"],
                 [[f"{row['size']:g}", f"{row['unknowns']:,}", f"{row['curvature']:.6e}", f"{row['theory']:.6e}",
                   _percent(row["error"], 4), f"{row['seconds']:.1f} s"] for row in record["curvature"]])
    out += ["", "**Edge delamination**: Σ cracked over a length c from the free end x = 20. Far behind a long "
            "crack both layers are free and stress-free (each expands on its own), far ahead the bilayer is "
            "bonded: the steady-state G is the strain energy per unit length stored in the bonded bilayer "
            "(Suo and Hutchinson 1990; Hutchinson and Suo 1992), G_ss = Σ ∫ E′/2 (ε₀ + κy − (1 + ν)αΔT)² dy with "
            f"ε₀ = {state['strain']:.6e}, −κ = w″ = {state['curvature']:.6e} (Timoshenko's) minimizing it, "
            "summed over the layers: "
            f"G_ss = {record['edge'][0]['theory']:.6e}. The faces touch behind the tip (a contact zone: the tip "
            "slides only, ψ = ±90°), which leaves G_ss unchanged: far behind, the free layers press on nothing. "
            "mesh.size "
            f"{EDGE_SIZE:g}:", "", "![Edge delamination](stacks-thermal.png)", ""]
    out += table(["c/h", "unknowns", "G", "G_ss", "G/G_ss − 1", "ψ at l = 1", "contact zones", "wall time"],
                 [[f"{row['crack']:g}", f"{row['unknowns']:,}", f"{row['G']:.6e}", f"{row['theory']:.6e}",
                   _percent(row["error"], 3), f"{row['phase']:.1f}°", str(row["zones"]), f"{row['seconds']:.1f} s"]
                  for row in record["edge"]])
    return out
