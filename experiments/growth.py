"""Crack growth along Σ (``ddsolve grow``) against corrected beam theory, and two studies.

``ddsolve growth`` grows, with the product's :func:`ddsolve.solvers.grow.grow` in this process:

- the DCB of two identical layers under a prescribed opening (the stable branch, against corrected beam
  theory's P = √(G_c E′h³/12)/(a + χ_I h) and δ = 8(a + χ_I h)² √(G_c/(12E′h³))), under load control (unstable
  at initiation), on three meshes (convergence) and with two step counts;
- the ENF under a prescribed midspan deflection at a/L = 0.5 (unstable at initiation: beam theory's
  limit is a/L = 3^(−1/3) = 0.693) and 0.8 (stable), its initiation load against P = √(16G_IIc E′h³/9)/(a + χ_II h);
- Example 1 (``partial-closure``) with a toughness, and the ``strip-disbonds`` gallery scene, under a
  rising load;

and rewrites docs/growth.md's generated section, docs/growth-*.png and results/growth/.  E′ is the
summed plane-strain modulus of the layers, P the load summed over them (docs/delamination.md).
"""
from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from experiments import delamination as beams
from experiments import report

RESULTS = Path("results") / "growth"
DOCS = Path("docs")
#: The toughness of the DCB (mode I) and of the ENF (mode II), in the scene's units (E = 200).
G_IC, G_IIC = 1e-6, 2e-6
#: Uniform P2 meshes (the tips move: no grading at the initial tip); the convergence sizes.
SIZE, SIZES = 0.1, (0.2, 0.1, 0.05)
#: The DCB's initial crack and the crack length its opening is raised to; the ENF's two cracks (a/L).
DCB_CRACK, DCB_END = 6.0, 12.0
ENF_RATIOS = (0.5, 0.6, 0.8)
#: The runs whose curves docs/growth.md shows (the others' go to results/growth/).
DRAWN = ("dcb-load", "enf-0.6", "partial-closure", "strip-disbonds")
#: The width of the ENF's loading nose (a segment displaced rigidly).
NOSE = 0.02
#: |G/G_c − 1| at every growing tip.
TOLERANCE = 1e-4


# --- corrected beam theory -----------------------------------------------------------------------------
def dcb_load(a: float, modulus: float, toughness: float, h: float = beams.ARM) -> float:
    """The DCB's load on its stable branch at crack length a: P = √(G_c E′h³/12)/(a + χ_I h)."""
    return math.sqrt(toughness * modulus * h ** 3 / 12.0) / (a + beams.CHI_I * h)


def dcb_opening(a: float, modulus: float, toughness: float, h: float = beams.ARM) -> float:
    """The opening δ = C(a) P(a), C = 8(a + χ_I h)³/(E′h³)."""
    return 8.0 * (a + beams.CHI_I * h) ** 3 / (modulus * h ** 3) * dcb_load(a, modulus, toughness, h)


def dcb_length(delta: float, modulus: float, toughness: float, h: float = beams.ARM) -> float:
    """The crack length at opening δ on the stable branch (δ ∝ (a + χ_I h)²)."""
    return math.sqrt(delta / 8.0 * math.sqrt(12.0 * modulus * h ** 3 / toughness)) - beams.CHI_I * h


def enf_load(a: float, modulus: float, toughness: float, h: float = beams.ARM) -> float:
    """The ENF's initiation load: G = 9P²(a + χ_II h)²/(16E′h³) = G_IIc."""
    return math.sqrt(16.0 * toughness * modulus * h ** 3 / 9.0) / (a + beams.CHI_II * h)


# --- scenes ----------------------------------------------------------------------------------------------
def specimen(folder: Path, name: str, case, conditions: str, size: float, toughness: float,
             pieces: dict | None = None):
    """A strip specimen (``case``: a :class:`experiments.delamination.Case`, its boundary pieces
    or ``pieces``) with its supports and loads ``conditions`` (scene text), a uniform P2 mesh of ``size``
    and a constant toughness."""
    from ddsolve.problem import scene

    (folder / f"{name}.geo").write_text(beams.strip_geo(case.length, beams.ARM, [(0.0, case.a)], pieces or case.pieces()))
    materials = "".join(f"[materials.{layer}]\nE = {E!r}\nnu = {nu!r}\n"
                        for layer, (E, nu) in zip(("layer1", "layer2"), beams.LAYERS[case.layers]))
    text = (f'title = "{name}"\n[mesh]\nfile = "{name}.geo"\nsize = {size!r}\ndegree = 2\n{materials}'
            f"{conditions}[fracture]\ntoughness = {toughness!r}\n")
    (folder / f"{name}.toml").write_text(text)
    return scene.loads(text, origin=name, base=folder)


def both_layers(kind: str, name: str, body: str) -> str:
    return "".join(f"[{kind}.{layer}.{name}]\n{body}\n" for layer in ("layer1", "layer2"))


def dcb(folder: Path, size: float, control: str):
    """The DCB at a = DCB_CRACK: unit opening δ = 1 (±1/2 on the arms' end faces) or unit load P = 1
    (±1/2 per layer, each on its arm's end face of height h)."""
    case = beams.Case("DCB", "identical", DCB_CRACK, size=size)
    if control == "displacement":
        conditions = both_layers("displacements", "left_upper", "y = 0.5") + \
            both_layers("displacements", "left_lower", "y = -0.5")
    else:
        face = 0.5 / beams.ARM  # P/2 per layer on a face of height h
        conditions = both_layers("loads", "left_upper", f"y = {face!r}") + \
            both_layers("loads", "left_lower", f"y = {-face!r}")
    return specimen(folder, f"dcb-{control}-{size:g}", case, conditions, size, G_IC)


def enf(folder: Path, ratio: float, size: float = SIZE):
    """The ENF at a = ratio·L under a unit midspan deflection: −1 on the top segment ``load``, NOSE wide (a
    loading nose: a wider rigid segment holds the beam's slope there with a couple, which the ENF's
    asymmetry turns into a few per cent less G)."""
    case = beams.Case("ENF", "identical", ratio * 0.5 * beams.SPAN, size=size)
    middle = case.half_span
    pieces = {**case.pieces(), "load": [("top", middle - 0.5 * NOSE, middle + 0.5 * NOSE)]}
    conditions = (both_layers("displacements", "roller", "y = 0.0") +
                  both_layers("displacements", "right_lower", "y = 0.0") +
                  both_layers("displacements", "pin", "x = 0.0\ny = 0.0") +
                  both_layers("displacements", "load", "y = -1.0"))
    return specimen(folder, f"enf-{ratio:g}", case, conditions, size, G_IIC, pieces)


# --- runs ------------------------------------------------------------------------------------------------
def run(scene, limit: float, steps: int, name: str) -> dict:
    """``grow`` in this process (one rank); the growth file kept as results/growth/NAME.h5."""
    from mpi4py import MPI

    from ddsolve.post import plots
    from ddsolve.solvers import grow, growth_files

    started = time.perf_counter()
    path = RESULTS / f"{name}.h5"
    grow.grow(scene, MPI.COMM_SELF, limit, steps, TOLERANCE, progress=lambda line: print(line, flush=True),
              output=path)
    data = growth_files.read(path)
    plots.growth_curves(data, (DOCS / f"growth-{name}.png") if name in DRAWN else path.with_suffix(".png"))
    data["seconds"] = time.perf_counter() - started
    print(f"growth: {name}: {len(data['control']) - 1} steps, {int(data['solves'].sum())} solves, "
          f"{data['seconds']:.0f} s", flush=True)
    return data


def crack_tip(data: dict) -> np.ndarray:
    """The DCB's (and ENF's) crack length at every step: the right end of its one crack."""
    return data["cracks"][:, 0, 1]


def dcb_rows(data: dict, modulus: float) -> list[dict]:
    """The DCB's grown steps against corrected beam theory: P at the step's crack length, a at its opening."""
    rows = []
    for step in np.flatnonzero(crack_tip(data) > DCB_CRACK + 1e-9):
        a, delta, load = float(crack_tip(data)[step]), float(data["displacement"][step]), float(data["load"][step])
        rows.append({"step": int(step), "delta": delta, "a": a, "P": load,
                     "P_cbt": dcb_load(a, modulus, G_IC), "a_cbt": dcb_length(delta, modulus, G_IC)})
    return rows


def critical_load(scene, lengths) -> list[float]:
    """The load at which the DCB's crack of each length grows, on ``scene``'s mesh: F₁√(G_c/G₁) from one
    solve at unit opening (what the growth curve passes through at that length, by construction)."""
    from mpi4py import MPI

    from ddsolve.solvers import grow

    growth = grow.Growth(scene, MPI.COMM_SELF)
    loads = []
    for a in lengths:
        state = growth.state(((0.0, float(a)),), 1.0)
        loads.append(float(state.load * math.sqrt(state.G_c[0] / state.G[0])))
    return loads


def measurements() -> dict:
    import tempfile

    RESULTS.mkdir(parents=True, exist_ok=True)
    modulus = beams.summed_modulus(beams.LAYERS["identical"])
    folder = Path(tempfile.mkdtemp(prefix="ddsolve-growth-"))
    record: dict = {"toughness": {"G_Ic": G_IC, "G_IIc": G_IIC}, "modulus": modulus, "chi": {"I": beams.CHI_I,
                    "II": beams.CHI_II}, "tolerance": TOLERANCE}
    end = dcb_opening(DCB_END, modulus, G_IC)
    runs = {}
    for size in SIZES:
        steps = 12 if size == SIZE else 4
        runs[f"dcb-{size:g}"] = run(dcb(folder, size, "displacement"), end, steps, f"dcb-displacement-{size:g}")
    runs["dcb-coarse-steps"] = run(dcb(folder, SIZE, "displacement"), end, 6, "dcb-displacement-6-steps")
    runs["dcb-load"] = run(dcb(folder, SIZE, "load"), 1.5 * dcb_load(DCB_CRACK, modulus, G_IC), 3, "dcb-load")
    for ratio in ENF_RATIOS:
        a = ratio * 0.5 * beams.SPAN
        runs[f"enf-{ratio:g}"] = run(enf(folder, ratio), 3.0 * enf_deflection_guess(a, modulus), 6, f"enf-{ratio:g}")
    for name in STUDIES:
        runs[name] = study(name)
    record["dcb"] = dcb_rows(runs[f"dcb-{SIZE:g}"], modulus)
    # the load at the crack lengths the finest mesh grew to, on every mesh (no interpolation)
    lengths = crack_tip(runs[f"dcb-{SIZES[-1]:g}"])
    lengths = lengths[lengths > DCB_CRACK + 1e-9]
    record["convergence"] = {f"{size:g}": critical_load(dcb(folder, size, "displacement"), lengths) for size in SIZES}
    record["convergence"]["lengths"] = lengths.tolist()
    # the step size: the crack length at the controls both step counts reach (6 steps: every other of 12)
    fine, coarse = runs[f"dcb-{SIZE:g}"], runs["dcb-coarse-steps"]
    common = [c for c in coarse["control"] if c > 0 and np.any(np.isclose(fine["control"], c, rtol=1e-12, atol=0))]
    record["steps"] = [{"control": float(c),
                        "a_12": float(crack_tip(fine)[np.flatnonzero(np.isclose(fine["control"], c, rtol=1e-12, atol=0))[-1]]),
                        "a_6": float(crack_tip(coarse)[np.flatnonzero(np.isclose(coarse["control"], c, rtol=1e-12, atol=0))[-1]])}
                       for c in common]
    record["runs"] = {name: summary(data) for name, data in runs.items()}
    record["enf"] = {f"{ratio:g}": enf_summary(runs[f"enf-{ratio:g}"], ratio, modulus) for ratio in ENF_RATIOS}
    return record


#: The studies: built-in scenes grown with a toughness at which they start to grow at factor 1.
STUDIES = ("partial-closure", "strip-disbonds")


def study(name: str) -> dict:
    """A built-in scene with the toughness that makes its largest G at the scene's loads critical (factor 1),
    grown to factor 3."""
    from mpi4py import MPI

    from ddsolve.problem.scene import Scene
    from ddsolve.solvers import driver

    scene = Scene.load(name)
    result = driver.solve_decomposed(scene, MPI.COMM_SELF, None, progress=lambda line: None)
    toughness = float(f"{float(np.max(result.fracture.G)):.3g}")
    return run(scene.with_({"fracture.toughness": toughness}), 3.0, 6, name)


def enf_deflection_guess(a: float, modulus: float) -> float:
    """Beam theory's midspan deflection at initiation: δ = P(2L³ + 3a³)/(8E′h³) per unit width (E′ summed)."""
    L, h = 0.5 * beams.SPAN, beams.ARM
    return enf_load(a, modulus, G_IIC) * (2.0 * L ** 3 + 3.0 * a ** 3) / (8.0 * modulus * h ** 3)


def summary(data: dict) -> dict:
    return {"control": data["control"].tolist(), "load": data["load"].tolist(),
            "displacement": data["displacement"].tolist(), "cracks": data["cracks"].tolist(),
            "unstable": data["unstable"].tolist(), "events": data["events"].tolist(),
            "solves": data["solves"].tolist(), "seconds": data["seconds"]}


def enf_summary(data: dict, ratio: float, modulus: float) -> dict:
    first = int(np.flatnonzero(np.char.startswith(data["events"].astype(str), "initiation"))[0])
    a = ratio * 0.5 * beams.SPAN
    return {"a": a, "initiation_load": float(data["load"][first]), "cbt": enf_load(a, modulus, G_IIC),
            "unstable": bool(data["unstable"][first]), "events": str(data["events"][first]),
            "after": float(crack_tip(data)[first + 1])}


def growth() -> None:
    """Run the measurements, keep results/growth.json, rewrite docs/growth.md's generated section and draw
    the validation."""
    record = measurements()
    from ddsolve.parallel import launch

    record["provenance"] = launch.provenance()
    (Path("results") / "growth.json").write_text(json.dumps(record, indent=1))
    report.section(DOCS / "growth.md", "growth", text(record))
    validation_plot(record)


def validation_plot(record: dict) -> None:
    """The DCB's load against opening and crack length against opening beside corrected beam theory, and
    the ENF's load against deflection with beam theory's initiation loads; deviations in the titles."""
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    modulus = record["modulus"]
    rows = record["dcb"]
    run = record["runs"][f"dcb-{SIZE:g}"]
    lengths = np.linspace(DCB_CRACK, DCB_END, 100)
    fig, axes = plt.subplots(1, 3, figsize=(16, 5.2), constrained_layout=True)
    ax = axes[0]
    ax.plot(run["displacement"], run["load"], "o-", markersize=3, label="ddsolve grow (size 0.1, P2)")
    ax.plot([dcb_opening(a, modulus, G_IC) for a in lengths], [dcb_load(a, modulus, G_IC) for a in lengths], "k--",
            label="corrected beam theory (stable branch)")
    worst = max(abs(r["P"] / r["P_cbt"] - 1) for r in rows)
    ax.set_title(f"DCB: load against opening\n(largest deviation from CBT {worst:.2%})")
    ax.set_xlabel("opening δ")
    ax.set_ylabel("load P (summed over the layers)")
    ax = axes[1]
    ax.plot([r["delta"] for r in rows], [r["a"] for r in rows], "o", markersize=4, label="ddsolve grow")
    ax.plot([dcb_opening(a, modulus, G_IC) for a in lengths], lengths, "k--", label="corrected beam theory")
    worst = max(abs(r["a"] / r["a_cbt"] - 1) for r in rows)
    ax.set_title(f"DCB: crack length against opening\n(largest deviation from CBT {worst:.2%})")
    ax.set_xlabel("opening δ")
    ax.set_ylabel("crack length a")
    ax = axes[2]
    for ratio, row in record["enf"].items():
        data = record["runs"][f"enf-{ratio}"]
        line, = ax.plot(data["displacement"], data["load"], "o-", markersize=3,
                        label=f"a/L = {ratio}: {'unstable' if row['unstable'] else 'stable'} at initiation")
        ax.axhline(row["cbt"], color=line.get_color(), linestyle=":", linewidth=1.0)
    deviations = ", ".join(f"{row['initiation_load'] / row['cbt'] - 1:+.1%}" for row in record["enf"].values())
    ax.set_title(f"ENF: load against midspan deflection\n(dotted: CBT initiation loads)\ninitiation against CBT: {deviations}")
    ax.set_xlabel("midspan deflection")
    ax.set_ylabel("load P")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend()
    fig.savefig(DOCS / "growth-validation.png", dpi=130)
    plt.close(fig)


def text(record: dict) -> str:
    lines = [f"Generated by `./run growth` ({record['provenance'].get('git_commit', '')[:10]}). "
             f"G_Ic = {G_IC:g}, G_IIc = {G_IIC:g}, E′ = {record['modulus']:.4g} (two identical layers), "
             f"χ_I = {beams.CHI_I:.3f}, χ_II = {beams.CHI_II:.3f}; uniform P2 meshes of size {SIZE:g}; "
             f"|G/G_c − 1| ≤ {TOLERANCE:g} at every growing tip.", "",
             "### DCB, prescribed opening: the stable branch", "",
             "| step | opening δ | crack length a | a (CBT at δ) | a / CBT − 1 | load P | P (CBT at a) | P / CBT − 1 |",
             "|---|---|---|---|---|---|---|---|"]
    for row in record["dcb"]:
        lines.append(f"| {row['step']} | {row['delta']:.5e} | {row['a']:.4f} | {row['a_cbt']:.4f} | "
                     f"{row['a'] / row['a_cbt'] - 1:+.2%} | {row['P']:.5e} | {row['P_cbt']:.5e} | "
                     f"{row['P'] / row['P_cbt'] - 1:+.2%} |")
    conv = record["convergence"]
    sizes = [s for s in conv if s != "lengths"]
    lines += ["", "### Mesh convergence (DCB, prescribed opening)", "",
              f"The load at the crack lengths the size-{sizes[-1]} run grew to, on every mesh (each from one solve "
              "at that crack length: the point of that mesh's growth curve):", "",
              "| a | " + " | ".join(f"size {s}" for s in sizes) + " | change, two finest | change, two coarsest |",
              "|---|" + "---|" * len(sizes) + "---|---|"]
    for i, a in enumerate(conv["lengths"]):
        values = [conv[s][i] for s in sizes]
        lines.append(f"| {a:.4f} | " + " | ".join(f"{v:.6e}" for v in values) +
                     f" | {values[-1] / values[-2] - 1:+.3%} | {values[1] / values[0] - 1:+.3%} |")
    lines += ["", "### Step size (DCB, prescribed opening, size 0.1)", "",
              "The crack length at the openings both runs reach (6 steps: every other opening of 12):", "",
              "| opening δ | a, 12 steps | a, 6 steps | change |", "|---|---|---|---|"]
    for row in record["steps"]:
        lines.append(f"| {row['control']:.6e} | {row['a_12']:.6f} | {row['a_6']:.6f} | "
                     f"{row['a_6'] / row['a_12'] - 1:+.2e} |")
    lines += ["", "### Load control and the ENF", "", "| run | initiation | what happened | solves |", "|---|---|---|---|"]
    for name, data in record["runs"].items():
        if name.startswith("dcb-0") or name.startswith("dcb-coarse") or name in STUDIES:
            continue
        events = "; ".join(e for e in data["events"] if e)
        lines.append(f"| {name} | {next((c for c, e in zip(data['control'], data['events']) if e.startswith('initiation')), math.nan):.5g} "
                     f"| {events} | {sum(data['solves'])} |")
    lines += ["", "| ENF a/L | a | initiation load | CBT | / CBT − 1 | reported | crack after |", "|---|---|---|---|---|---|---|"]
    for ratio, row in record["enf"].items():
        lines.append(f"| {ratio} | {row['a']:g} | {row['initiation_load']:.5e} | {row['cbt']:.5e} | "
                     f"{row['initiation_load'] / row['cbt'] - 1:+.2%} | {'unstable' if row['unstable'] else 'stable'} | "
                     f"{row['after']:.4f} |")
    for name in STUDIES:
        data = record["runs"][name]
        lines += ["", f"### `{name}`, load control", "", "| factor | cracks (arc length along Σ) | events |", "|---|---|---|"]
        for control, cracks, events in zip(data["control"], data["cracks"], data["events"]):
            shown = ", ".join(f"({a:.4f}, {b:.4f})" for a, b in cracks if not math.isnan(a))
            lines.append(f"| {control:.4g} | {shown} | {events} |")
    return "\n".join(lines) + "\n"
