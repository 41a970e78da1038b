"""Delamination tests: DCB, ELS, ENF and MMB specimens and a thermal mismatch, against beam theory.

``ddsolve delamination`` (a few minutes on two cores) solves every case with the monolithic reference
(the exact discrete solution every DD method converges to) in this process, checks one floating-block
case (ENF: the upper arm held only by the glue) with a 2-rank ``ddsolve solve`` launch, keeps
results/delamination.json and the scenes of the standard specimens in results/delamination/, and rewrites
docs/delamination.md's generated section and docs/delamination-*.png.

The model (docs/delamination.md): both layers occupy the whole strip and are tied along Σ only, so every
arm is two plane beams of thickness h side by side, tied along their face on Σ.  They bend with one
deflection, and beam theory gives the energy release rates of a homogeneous specimen whose plane-strain
modulus is E₁′ + E₂′ (per unit width) with P the load summed over the layers.
"""
from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from experiments import report

RESULTS = Path("results")
DOCS = Path("docs")
RANKS = 2
#: The strip: length (DCB, ELS: the clamp at x = LENGTH), the span of ENF and MMB (L = SPAN/2 = 20h, as in
#: ASTM D7905), arm thickness h (Σ the mid-plane, the strip 2h high), mesh size (graded P2).
LENGTH, SPAN, ARM, SIZE, FINE_SIZE = 20.0, 40.0, 1.0, 0.1, 0.05
#: Loads: P summed over both layers (each layer carries P/2), the DCB opening δ, the midspan load's width.
LOAD, OPENING, LOAD_WIDTH = 1e-3, 0.01, 0.2
#: The supports of ENF and MMB: a pin (u = 0) on the right end face for |y| ≤ PIN/5 (centred on the neutral
#: axis; a segment −0.1 ≤ y ≤ 0 held the end's rotation with a couple that took 1.7 % off the left reaction,
#: 3.4 % off G) and a roller (u_y = 0) on the rest of that face of the lower arm; a roller on the lower arm's
#: left end face for y ≤ −PIN (off the crack's mouth, whose faces may only be held together).
PIN = 0.1
#: Layer pairs: two identical layers, and the paper's two different ones (E2 ≠ E1).
LAYERS = {"identical": ((200.0, 0.28), (200.0, 0.28)), "different": ((200.0, 0.28), (112.0, 0.32))}
#: Crack lengths a (a/h ≥ 5) per specimen; MMB at a = 6 for three lever lengths c/L.
CRACKS = {"DCB": (5.0, 6.0, 8.0, 10.0, 12.0), "ELS": (5.0, 6.0, 8.0, 10.0, 12.0), "ENF": (5.0, 6.0, 8.0, 10.0, 12.0)}
MMB_CRACK, LEVERS = 6.0, (0.6, 1.0, 2.0)
#: Corrected beam theory for isotropic arms: the crack-tip (root rotation) corrections a + Yh of the
#: elasticity solution of a semi-infinite crack between two isotropic strips, Y_I = 0.677 (mode I: DCB) and
#: Y_II = 0.206 (mode II: ELS, ENF), at ρ = 1 (isotropic layers, any ν): Bao, Ho, Suo and Fan, Int. J.
#: Solids Struct. 29 (1992) 1105; Suo, Bao, Fan and Wang, Int. J. Solids Struct. 28 (1991) 235.
CHI_I, CHI_II = 0.677, 0.206
#: The composite corrections, for E11/G13 ≫ 1, kept as a second comparison: Kanninen's χ = 6^(−1/4) = 0.639
#: (a beam on a Winkler foundation of stiffness 2E/h), with Wang and Williams' mode II factors 0.42χ (ENF)
#: and 0.49χ (ELS).
CHI_KANNINEN = 6.0 ** -0.25
CHI_WW_ENF, CHI_WW_ELS = 0.42 * CHI_KANNINEN, 0.49 * CHI_KANNINEN
#: The tip correction χ (in units of h) of each specimen in each formula: beam theory ("simple") has none,
#: "corrected" the isotropic elasticity corrections, "wang_williams" the composite ones (the MMB takes the
#: DCB's for its mode I part and the ENF's for its mode II part).
CORRECTIONS = {"simple": {"DCB": 0.0, "ELS": 0.0, "ENF": 0.0},
               "corrected": {"DCB": CHI_I, "ELS": CHI_II, "ENF": CHI_II},
               "wang_williams": {"DCB": CHI_KANNINEN, "ELS": CHI_WW_ELS, "ENF": CHI_WW_ENF}}
#: Thermal strip: expansion coefficients of the two layers, temperature change, an interior crack.
THERMAL = {"alpha": (2e-5, 1e-5), "dT": 100.0, "crack": (8.0, 12.0), "steps": (1e-4,)}


# --- beam theory (per unit width, P summed over the layers, E′ summed over the layers) ---------------
def plane_strain_modulus(E: float, nu: float) -> float:
    """E′ = E / (1 − ν²)."""
    return E / (1.0 - nu * nu)


def summed_modulus(layers) -> float:
    """E₁′ + E₂′: the two layers' arms bend together (one deflection along their tied face)."""
    return sum(plane_strain_modulus(E, nu) for E, nu in layers)


def dcb(P: float, a: float, h: float, modulus: float, chi: float = 0.0) -> float:
    """DCB: G = 12 P² (a + χh)² / (E′ h³), P the force on each arm (ASTM D5528; corrected: χ = CHI_I)."""
    return 12.0 * P * P * (a + chi * h) ** 2 / (modulus * h ** 3)


def dcb_opening(delta: float, a: float, h: float, modulus: float, chi: float = 0.0) -> float:
    """DCB under a prescribed opening δ of the arms' ends: with the compliance δ/P = 8 (a + χh)³/(E′h³),
    G = 3 δ² E′ h³ / (16 (a + χh)⁴)."""
    return 3.0 * delta * delta * modulus * h ** 3 / (16.0 * (a + chi * h) ** 4)


def els(P: float, a: float, h: float, modulus: float, chi: float = 0.0) -> float:
    """ELS: G = 9 P² (a + χh)² / (4 E′ h³) (corrected: χ = CHI_II)."""
    return 9.0 * P * P * (a + chi * h) ** 2 / (4.0 * modulus * h ** 3)


def enf(P: float, a: float, h: float, modulus: float, chi: float = 0.0) -> float:
    """ENF: G = 9 P² (a + χh)² / (16 E′ h³), P the midspan load (ASTM D7905; corrected: χ = CHI_II)."""
    return 9.0 * P * P * (a + chi * h) ** 2 / (16.0 * modulus * h ** 3)


def mmb_loads(P: float, c: float, L: float) -> tuple[float, float]:
    """Reeder and Crews: the lever load P at c splits into a DCB opening P_I = P (3c − L)/(4L) of the arms
    and an ENF midspan load P_II = P (c + L)/L (ASTM D6671)."""
    return P * (3.0 * c - L) / (4.0 * L), P * (c + L) / L


def mmb_lever_forces(P: float, c: float, L: float) -> tuple[float, float]:
    """What the lever puts on the specimen: the upward pull P c/L on the upper arm's end and the downward
    push P (c + L)/L at midspan (the supports carry the rest)."""
    return P * c / L, P * (c + L) / L


def mmb(P: float, c: float, L: float, a: float, h: float, modulus: float, chi_I: float = 0.0,
        chi_II: float = 0.0) -> tuple[float, float]:
    """(G_I, G_II) of the MMB: DCB with P_I and tip correction χ_I, ENF with P_II and χ_II.  Their ratio is
    (4/3)((3c − L)/(c + L))² ((a + χ_I h)/(a + χ_II h))²."""
    P_I, P_II = mmb_loads(P, c, L)
    return dcb(P_I, a, h, modulus, chi_I), enf(P_II, a, h, modulus, chi_II)


def mismatch_stress(layers, alphas, dT: float) -> float:
    """σxx of layer 1 far from the ends of a free strip (plane strain): the layers, tied along Σ, share one
    strain along x; equal and opposite forces: σ₁ = (m₂ − m₁) / (1/E₁′ + 1/E₂′), m = (1 + ν)αΔT; σ₂ = −σ₁."""
    (E1, nu1), (E2, nu2) = layers
    m1, m2 = (1.0 + nu1) * alphas[0] * dT, (1.0 + nu2) * alphas[1] * dT
    return (m2 - m1) / (1.0 / plane_strain_modulus(E1, nu1) + 1.0 / plane_strain_modulus(E2, nu2))


# --- geometry and scenes ---------------------------------------------------------------------------------
def strip_geo(length: float, h: float, cracks: list[tuple[float, float]], pieces: dict[str, list]) -> str:
    """gmsh .geo text of the strip (0, length) × (−h, h) cut by Σ at y = 0 with ``cracks`` on it.

    ``pieces``: name -> [(side, lo, hi), ...], side one of bottom, top (x intervals), left, right (y
    intervals); the boundary pieces not named are ``bottom``, ``top``, ``left_lower``, ``left_upper``,
    ``right_lower`` and ``right_upper``.  The element size comes from the scene's ``mesh.size``.
    """
    points: dict[tuple[float, float], int] = {}
    lines: dict[tuple[int, int], int] = {}
    text, names = ["lc = 1.0;"], {}

    def point(x: float, y: float) -> int:
        key = (round(x, 12), round(y, 12))
        if key not in points:
            points[key] = len(points) + 1
            text.append(f"Point({points[key]}) = {{{x!r}, {y!r}, 0, lc}};")
        return points[key]

    def path(coordinates: list[tuple[float, float]], name_of) -> list[int]:
        ids = []
        for a, b in zip(coordinates[:-1], coordinates[1:]):
            pa, pb = point(*a), point(*b)
            if (pb, pa) in lines:
                ids.append(-lines[(pb, pa)])
                continue
            lines[(pa, pb)] = len(lines) + 1
            text.append(f"Line({lines[(pa, pb)]}) = {{{pa}, {pb}}};")
            names[lines[(pa, pb)]] = name_of(0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]))
            ids.append(lines[(pa, pb)])
        return ids

    def named(side: str, along: float, default: str) -> str:
        return next((name for name, spans in pieces.items() for s, lo, hi in spans
                     if s == side and lo <= along <= hi), default)

    def cuts(side: str, lo: float, hi: float) -> list[float]:
        inside = [v for spans in pieces.values() for s, *ends in spans if s == side for v in ends if lo < v < hi]
        return sorted({lo, hi, *inside})

    def boundary(x: float, y: float) -> str:
        if y in (-h, h):
            return named("bottom" if y < 0 else "top", x, "bottom" if y < 0 else "top")
        side = "left" if x == 0.0 else "right"
        return named(side, y, f"{side}_{'lower' if y < 0 else 'upper'}")

    def on_sigma(x: float, _y: float) -> str:
        return "crack" if any(lo <= x <= hi for lo, hi in cracks) else "sigma"

    sigma_x = sorted({0.0, length, *(v for crack in cracks for v in crack)})
    sigma = path([(x, 0.0) for x in sigma_x], on_sigma)
    bottom = path([(x, -h) for x in cuts("bottom", 0.0, length)], boundary)
    right = [path([(length, y) for y in cuts("right", lo, hi)], boundary) for lo, hi in ((-h, 0.0), (0.0, h))]
    top = path([(x, h) for x in cuts("top", 0.0, length)[::-1]], boundary)
    left = [path([(0.0, y) for y in cuts("left", lo, hi)[::-1]], boundary) for lo, hi in ((-h, 0.0), (0.0, h))]
    loops = {"lower": bottom + right[0] + [-i for i in sigma[::-1]] + left[0],
             "upper": sigma + right[1] + top + left[1]}
    for number, (name, loop) in enumerate(loops.items(), start=1):
        text.append(f"Curve Loop({number}) = {{{', '.join(map(str, loop))}}}; Plane Surface({number}) = {{{number}}};")
        text.append(f'Physical Surface("{name}") = {{{number}}};')
    groups: dict[str, list[int]] = {}
    for line, name in names.items():
        groups.setdefault(name, []).append(line)
    groups["sigma"] = groups.get("sigma", []) + groups.get("crack", [])
    text += [f'Physical Curve("{name}") = {{{", ".join(map(str, sorted(ids)))}}};' for name, ids in groups.items()]
    return "\n".join(text) + "\n"


@dataclass
class Case:
    """One specimen: what the scene says, and how beam theory reads it."""

    specimen: str  # DCB, DCB-displacement, ELS, ENF, MMB
    layers: str  # identical, different
    a: float
    c: float | None = None
    size: float = SIZE
    results: dict = field(default_factory=dict)

    @property
    def length(self) -> float:
        return SPAN if self.specimen in ("ENF", "MMB") else LENGTH

    @property
    def half_span(self) -> float:
        return 0.5 * self.length

    def pieces(self) -> dict[str, list]:
        if self.specimen in ("ENF", "MMB"):
            middle = self.half_span
            return {"pin": [("right", -0.2 * PIN, 0.2 * PIN)], "roller": [("left", -ARM, -PIN)],
                    "load": [("top", middle - 0.5 * LOAD_WIDTH, middle + 0.5 * LOAD_WIDTH)]}
        return {"clamped": [("right", -ARM, ARM)]}

    def conditions(self) -> str:
        """The loads and displacements of both layers, as scene text (each layer carries half)."""
        face = LOAD / (2.0 * ARM)  # the traction of P/2 on an arm's end face
        if self.specimen == "DCB":
            tables = {("loads", "left_upper"): f"y = {face!r}", ("loads", "left_lower"): f"y = {-face!r}"}
        elif self.specimen == "DCB-displacement":
            tables = {("displacements", "left_upper"): f"y = {0.5 * OPENING!r}",
                      ("displacements", "left_lower"): f"y = {-0.5 * OPENING!r}"}
        elif self.specimen == "ELS":
            tables = {("loads", "left_upper"): f"y = {-face!r}"}
        else:
            pull, push = mmb_lever_forces(LOAD, self.c, self.half_span) if self.specimen == "MMB" else (0.0, LOAD)
            tables = {("displacements", "roller"): "y = 0.0", ("displacements", "right_lower"): "y = 0.0",
                      ("displacements", "pin"): "x = 0.0\ny = 0.0",
                      ("loads", "load"): f"y = {-push / (2.0 * LOAD_WIDTH)!r}"}
            if pull:
                tables[("loads", "left_upper")] = f"y = {pull / (2.0 * ARM)!r}"
        return "".join(f"[{kind}.{layer}.{name}]\n{body}\n" for (kind, name), body in tables.items()
                       for layer in ("layer1", "layer2"))

    def text(self, geo: str) -> str:
        materials = "".join(f"[materials.{layer}]\nE = {E!r}\nnu = {nu!r}\n"
                            for layer, (E, nu) in zip(("layer1", "layer2"), LAYERS[self.layers]))
        lever = f", c/L = {self.c:g}" if self.c is not None else ""
        return (f'title = "{self.specimen}, {self.layers} layers, a = {self.a:g}{lever}"\n'
                f'[mesh]\nfile = "{geo}"\nsize = {self.size!r}\ndegree = 2\ngrading = true\n'
                f"{materials}{self.conditions()}")

    def geo(self) -> str:
        return strip_geo(self.length, ARM, [(0.0, self.a)], self.pieces())

    def scene(self, folder: Path, name: str):
        from ddsolve.problem import scene

        (folder / f"{name}.geo").write_text(self.geo())
        (folder / f"{name}.toml").write_text(self.text(f"{name}.geo"))
        return scene.loads(self.text(f"{name}.geo"), origin=name, base=folder)

    def theory(self, reaction: float | None = None) -> dict:
        """Beam theory ("simple"), corrected beam theory with the isotropic elasticity corrections
        ("corrected") and with the composite ones ("wang_williams") for this case (the MMB's modes as
        NAME_I, NAME_II; the displacement-controlled DCB's G at the measured reaction, "from_reaction")."""
        modulus = summed_modulus(LAYERS[self.layers])
        out = {}
        for name, chi in CORRECTIONS.items():
            if self.specimen == "MMB":
                G_I, G_II = mmb(LOAD, self.c, self.half_span, self.a, ARM, modulus, chi["DCB"], chi["ENF"])
                out.update({name: G_I + G_II, f"{name}_I": G_I, f"{name}_II": G_II})
            elif self.specimen == "DCB-displacement":
                out[name] = dcb_opening(OPENING, self.a, ARM, modulus, chi["DCB"])
            else:
                formula = {"DCB": dcb, "ELS": els, "ENF": enf}[self.specimen]
                out[name] = formula(LOAD, self.a, ARM, modulus, chi[self.specimen])
        if self.specimen == "DCB-displacement":
            out["from_reaction"] = dcb(reaction, self.a, ARM, modulus, CHI_I)
        return out


def cases() -> list[Case]:
    out = []
    for layers in LAYERS:
        for specimen, lengths in CRACKS.items():
            out += [Case(specimen, layers, a) for a in lengths]
        out.append(Case("DCB-displacement", layers, 6.0))
        out += [Case("MMB", layers, MMB_CRACK, c * 0.5 * SPAN) for c in LEVERS]
    # mesh convergence: the a = 6 cases of identical layers at half the size (the 40-long ENF and MMB strips,
    # graded at every support and load point, would need about 1.7e6 vertices there: refused for memory)
    out += [Case(specimen, "identical", 6.0, size=FINE_SIZE) for specimen in ("DCB", "ELS")]
    return out


# --- solving -------------------------------------------------------------------------------------------
def solve_case(source):
    """A case's scene solved by the monolithic reference on its mesh."""
    from ddsolve.mesh import geometry
    from ddsolve.solvers import reference

    mesh = geometry.build(source)
    return reference.solve_monolithic(source, mesh)


def measure(case: Case, result, seconds: float) -> dict:
    """G and its split at the (one) tip, the theory, penetration and the reactions."""
    from ddsolve.post import analysis

    f = result.fracture
    largest = analysis.largest_displacement(result.solution.values())
    opening = analysis.normal_jump(result)[result.crack]
    reaction = None
    if case.specimen == "DCB-displacement":
        reaction = float(sum(result.reactions[layer]["left_upper"][1] for layer in ("layer1", "layer2")))
    return {"specimen": case.specimen, "layers": case.layers, "a": case.a, "c": case.c, "size": case.size,
            "L": case.half_span, "G": float(f.G[0]), "G_I": float(f.G_I[0]), "G_II": float(f.G_II[0]),
            "phase": float(f.phase[0]), "largest": largest,
            "penetration": float(max(-opening.min(initial=0.0), 0.0) / largest),
            "contact_zones": int(len(f.zones)), "reaction": reaction, "seconds": seconds,
            "unknowns": 4 * (len(result.lower.points) + len(result.upper.points)),
            "reactions": {layer: {name: [float(v) for v in force] for name, force in forces.items()}
                          for layer, forces in result.reactions.items()},
            **case.theory(reaction)}


def moved_mesh(mesh, tip, step: float):
    """The mesh with its nodes moved by step·θ (the virtual crack extension of the domain integral)."""
    from ddsolve.mesh.mesh import HalfMesh, make_mesh
    from ddsolve.post import fracture

    halves = [HalfMesh(h.points + step * fracture.theta(tip, mesh.sigma, h.points), h.cells, h.side, h.sigma,
                       h.boundaries) for h in mesh.halves]
    return make_mesh(*halves, "moved")


def thermal(folder: Path) -> tuple[dict, object]:
    """A free strip of two different layers under ΔT with an interior crack: the mismatch stress against
    its closed form, G at the tips (zero far from the ends), and G against finite differences of Π."""
    from ddsolve.mesh import geometry
    from ddsolve.post import analysis, fracture
    from ddsolve.problem import scene
    from ddsolve.solvers import reference

    layers, (alpha1, alpha2), dT = LAYERS["different"], THERMAL["alpha"], THERMAL["dT"]
    pieces = {"pin": [("left", -PIN, PIN)]}
    (folder / "thermal.geo").write_text(strip_geo(LENGTH, ARM, [THERMAL["crack"]], pieces))
    materials = "".join(f"[materials.{layer}]\nE = {E!r}\nnu = {nu!r}\nalpha = {alpha!r}\n"
                        for layer, (E, nu), alpha in zip(("layer1", "layer2"), layers, (alpha1, alpha2)))
    supports = "".join(f"[displacements.{layer}.{name}]\nx = 0.0\n{extra}" for layer in ("layer1", "layer2")
                       for name, extra in (("left_lower", ""), ("left_upper", ""), ("pin", "y = 0.0\n")))
    text = (f'title = "thermal mismatch, free strip"\n[mesh]\nfile = "thermal.geo"\nsize = {SIZE!r}\ndegree = 2\n'
            f"grading = true\n{materials}[temperature]\nlayer1 = {dT!r}\nlayer2 = {dT!r}\n{supports}")
    (folder / "thermal.toml").write_text(text)
    source = scene.loads(text, origin="thermal", base=folder)
    mesh = geometry.build(source)
    started = time.perf_counter()
    result = reference.solve_monolithic(source, mesh)
    seconds = time.perf_counter() - started
    expected = mismatch_stress(layers, (alpha1, alpha2), dT)
    stresses = {}
    for name, fields in analysis.cell_fields(result).items():
        half = result.half(name)
        centres = half.points[half.cells[:, :3]].mean(axis=1)
        away = (centres[:, 0] > 3.0) & (centres[:, 0] < 6.0)  # away from the ends (symmetry plane at x = 0) and the crack
        stresses[name] = [float(fields.stress[away, 0].mean()), float(np.abs(fields.stress[away, 0]).max()),
                          float(np.abs(fields.stress[away, 1]).max()), float(np.abs(fields.stress[away, 2]).max())]
    modulus = plane_strain_modulus(*layers[0])
    scale = expected ** 2 * 2.0 * ARM / modulus  # strain energy per unit length of the strip, order of
    tips = fracture.find_tips(mesh)
    differences = []
    for tip, rate in zip(tips, result.fracture.G):
        step = THERMAL["steps"][0]
        energies = [reference.solve_monolithic(source, moved_mesh(mesh, tip, s)).attrs["energy"] for s in (step, -step)]
        differences.append({"tip": float(tip.point[0]), "G": float(rate),
                            "fd": float(-(energies[0] - energies[1]) / (2.0 * step))})
    record = {"expected": expected, "stresses": stresses, "G": [float(g) for g in result.fracture.G],
              "G_I": [float(g) for g in result.fracture.G_I], "G_II": [float(g) for g in result.fracture.G_II],
              "scale": scale, "seconds": seconds, "finite_differences": differences,
              "unknowns": 4 * (len(result.lower.points) + len(result.upper.points))}
    return record, result


def clamped_thermal() -> dict:
    """The paper's square, both sides clamped, layers with different α under ΔT: G against −ΔΠ/Δa."""
    from ddsolve.mesh import geometry
    from ddsolve.post import fracture
    from ddsolve.problem import scene
    from ddsolve.solvers import reference

    (E1, nu1), (E2, nu2) = LAYERS["different"]
    text = (f"[geometry]\nbox = [-1.0, 1.0, -1.0, 1.0]\ncrack = [-0.5, 0.5]\n[mesh]\nsize = 0.1\ndegree = 2\n"
            f"grading = true\n[materials.layer1]\nE = {E1!r}\nnu = {nu1!r}\nalpha = {THERMAL['alpha'][0]!r}\n"
            f"[materials.layer2]\nE = {E2!r}\nnu = {nu2!r}\nalpha = {THERMAL['alpha'][1]!r}\n"
            f"[temperature]\nlayer1 = {THERMAL['dT']!r}\nlayer2 = {THERMAL['dT']!r}\n")
    source = scene.loads(text)
    mesh = geometry.build(source)
    result = reference.solve_monolithic(source, mesh)
    rows, step = [], THERMAL["steps"][0]
    for tip, rate, G_I, G_II in zip(fracture.find_tips(mesh), result.fracture.G, result.fracture.G_I,
                                    result.fracture.G_II):
        energies = [reference.solve_monolithic(source, moved_mesh(mesh, tip, s)).attrs["energy"] for s in (step, -step)]
        rows.append({"G": float(rate), "G_I": float(G_I), "G_II": float(G_II),
                     "fd": float(-(energies[0] - energies[1]) / (2.0 * step))})
    return {"tips": rows, "points": result.fracture.points[:, 0].tolist()}


def cross_check(folder: Path, record: dict) -> dict:
    """ENF (upper arm floating) solved by ``ddsolve solve -n 2`` (schur): its G against the reference's."""
    from ddsolve.io import hdf5

    case = Case("ENF", "identical", 6.0)
    case.scene(folder, "enf-mpi")
    output = folder / "enf-mpi.h5"
    started = time.perf_counter()
    report.run(RANKS, ["solve", str(folder / "enf-mpi.toml"), "-o", str(output)])
    seconds = time.perf_counter() - started
    result = hdf5.read(output)
    f = result.fracture
    reference_row = next(row for row in record["cases"] if row["specimen"] == "ENF" and row["layers"] == "identical"
                         and row["a"] == 6.0 and row["size"] == SIZE)
    return {"method": result.method, "ranks": RANKS, "G": float(f.G[0]), "G_I": float(f.G_I[0]),
            "G_II": float(f.G_II[0]), "reference_G": reference_row["G"], "seconds": seconds,
            "floating": "u_plus, v_plus"}


def write_scenes() -> None:
    """The standard specimens at a = 6 (identical layers) as scenes users can start from."""
    folder = RESULTS / "delamination"
    folder.mkdir(parents=True, exist_ok=True)
    for name, case in (("dcb", Case("DCB", "identical", 6.0)),
                       ("dcb-displacement", Case("DCB-displacement", "identical", 6.0)),
                       ("els", Case("ELS", "identical", 6.0)), ("enf", Case("ENF", "identical", 6.0)),
                       ("mmb", Case("MMB", "identical", MMB_CRACK, 0.5 * SPAN))):
        case.scene(folder, name)


# --- the command ---------------------------------------------------------------------------------------
#: The results drawn as deformed shapes (a = 6, identical layers, c = L for the MMB) and the thermal strip.
SHAPES = RESULTS / "delamination"


def is_drawn(case: Case) -> bool:
    return case.layers == "identical" and case.a == 6.0 and case.size == SIZE and \
        (case.specimen in ("DCB", "ELS", "ENF") or case.c == 0.5 * SPAN)


def measurements() -> dict:
    """Solve every case; keep the drawn results in results/delamination/; return the record."""
    from ddsolve.io import save

    SHAPES.mkdir(parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(prefix="ddsolve-delamination-"))
    record = {"cases": [], "setup": {"length": LENGTH, "arm": ARM, "load": LOAD, "opening": OPENING,
                                     "pin": PIN, "load_width": LOAD_WIDTH, "layers": LAYERS,
                                     "chi": CORRECTIONS}}
    try:
        for index, case in enumerate(cases()):
            started = time.perf_counter()
            result = solve_case(case.scene(folder, f"case{index}"))
            row = measure(case, result, time.perf_counter() - started)
            record["cases"].append(row)
            print(f"delamination: {case.specimen}, {case.layers}, a = {case.a:g}"
                  + (f", c/L = {case.c / case.half_span:g}" if case.c is not None else "")
                  + f", size {case.size:g}: G = {row['G']:.6e} (G_I {row['G_I']:.4e}, G_II {row['G_II']:.4e}), "
                  f"corrected beam theory {row['corrected']:.6e} ({row['G'] / row['corrected'] - 1:+.2%}), "
                  f"{row['seconds']:.1f} s", flush=True)
            if is_drawn(case):
                save(result, SHAPES / f"shape-{case.specimen.lower()}.h5")
        record["thermal"], thermal_result = thermal(folder)
        save(thermal_result, SHAPES / "shape-thermal.h5")
        print(f"delamination: thermal strip: σxx {record['thermal']['stresses']} against "
              f"{record['thermal']['expected']:.6e}; G {record['thermal']['G']}", flush=True)
        record["thermal_clamped"] = clamped_thermal()
        print(f"delamination: clamped thermal square: {record['thermal_clamped']}", flush=True)
        (RESULTS / "delamination.json").write_text(json.dumps(record, indent=1))  # kept if the launch fails
        record["cross_check"] = cross_check(folder, record)
        print(f"delamination: ENF on {RANKS} ranks: {record['cross_check']}", flush=True)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    from ddsolve.parallel import launch

    record["provenance"] = launch.provenance()
    return record


def delamination() -> None:
    """Solve every case, cross-check a floating one on 2 ranks, draw, rewrite docs/delamination.md."""
    RESULTS.mkdir(exist_ok=True)
    record = measurements()
    (RESULTS / "delamination.json").write_text(json.dumps(record, indent=1))
    write_scenes()
    draw(record)


def draw(record: dict) -> None:
    """The pictures and the generated section of docs/delamination.md, from the record and the kept results."""
    from ddsolve.io import hdf5

    shapes_plot({name: hdf5.read(SHAPES / f"shape-{name.lower()}.h5") for name in ("DCB", "ELS", "ENF", "MMB")})
    length_plot(record)
    mmb_plot(record)
    thermal_plot(hdf5.read(SHAPES / "shape-thermal.h5"), record["thermal"])
    report.section(DOCS / "delamination.md", "delamination", text(record))


# --- pictures and text -----------------------------------------------------------------------------------
def _pyplot():
    from ddsolve.post.plots import _pyplot as pyplot

    return pyplot()


def rows(record: dict, specimen: str, layers: str, size: float = SIZE) -> list[dict]:
    return [row for row in record["cases"] if row["specimen"] == specimen and row["layers"] == layers
            and row["size"] == size]


#: The beam theories drawn: CORRECTIONS key, line style, legend.
CURVES = (("simple", "k:", "beam theory"), ("corrected", "k-", "corrected, isotropic (Bao et al.)"),
          ("wang_williams", "k--", "corrected, Wang–Williams"))


def shapes_plot(results: dict) -> None:
    """Layer 1 of DCB, ELS, ENF and MMB deformed (magnified), coloured by von Mises stress."""
    from ddsolve.post import analysis, plots

    plt = _pyplot()
    fig, axes = plt.subplots(len(results), 1, figsize=(10, 2.2 * len(results)), constrained_layout=True)
    for ax, (name, result) in zip(axes, results.items()):
        scale = plots.magnification(result, 0.1)
        stresses = analysis.layer_stresses(result)
        top = plots.stress_ceiling(np.concatenate([stresses["u_minus"], stresses["u_plus"]]))
        for block in ("u_minus", "u_plus"):
            half = result.half(block)
            moved = half.points + scale * result.solution[block]
            triangles, parent = plots.linear_triangles(half.cells)
            image = ax.tripcolor(moved[:, 0], moved[:, 1], triangles, facecolors=stresses[block][parent],
                                 cmap="viridis", vmin=0.0, vmax=top, edgecolors="none")
        fig.colorbar(image, ax=ax, label="von Mises", pad=0.01)
        ax.set_title(f"{name}, a = 6, identical layers: layer 1, displacements ×{scale:g}", fontsize=10)
        ax.set_aspect("equal")
    fig.savefig(DOCS / "delamination-shapes.png", dpi=110)
    plt.close(fig)


def length_plot(record: dict) -> None:
    """G, G_I and G_II against a for DCB, ELS and ENF, with beam theory and both corrected beam theories."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, 3, figsize=(13, 7.5), constrained_layout=True)
    for row_axes, layers in zip(axes, LAYERS):
        for ax, specimen in zip(row_axes, ("DCB", "ELS", "ENF")):
            data = rows(record, specimen, layers)
            a = np.array([row["a"] for row in data])
            for key, marker, label in (("G", "o", "G (domain integral)"), ("G_I", "^", "G_I"), ("G_II", "v", "G_II")):
                ax.plot(a, [row[key] for row in data], marker, label=label, markersize=6, fillstyle="none")
            fine = np.linspace(a.min(), a.max(), 50)
            modulus = summed_modulus(LAYERS[layers])
            formula = {"DCB": dcb, "ELS": els, "ENF": enf}[specimen]
            for name, style, label in CURVES:
                chi = CORRECTIONS[name][specimen]
                ax.plot(fine, formula(LOAD, fine, ARM, modulus, chi), style,
                        label=f"{label} (χ = {chi:.3f})" if chi else label)
            ax.set_yscale("log")
            ax.set_xlabel("crack length a (h = 1)")
            ax.set_ylabel("G")
            ax.set_title(f"{specimen}, {layers} layers", fontsize=10)
            ax.grid(alpha=0.3, which="both")
            ax.legend(fontsize=7)
    fig.savefig(DOCS / "delamination-length.png", dpi=110)
    plt.close(fig)


def mmb_plot(record: dict) -> None:
    """G_I/G_II against the lever length c/L: the computed ratio, beam theory and both corrected beam theories."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4.5), constrained_layout=True)
    L = 0.5 * SPAN
    fine = np.linspace(0.45, 2.2, 100) * L
    for layers, marker in zip(LAYERS, ("o", "s")):
        data = rows(record, "MMB", layers)
        ax.plot([row["c"] / L for row in data], [row["G_I"] / row["G_II"] for row in data], marker,
                fillstyle="none", markersize=8, label=f"computed, {layers} layers")
    for name, style, label in CURVES:
        chi = CORRECTIONS[name]
        ratio = [np.divide(*mmb(LOAD, c, L, MMB_CRACK, ARM, 1.0, chi["DCB"], chi["ENF"])) for c in fine]
        ax.plot(fine / L, ratio, style, label=label)
    ax.set_yscale("log")
    ax.set_xlabel("lever length c / L")
    ax.set_ylabel("G_I / G_II")
    ax.set_title(f"MMB, a = {MMB_CRACK:g}, L = {L:g} (h = 1)", fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.savefig(DOCS / "delamination-mmb.png", dpi=110)
    plt.close(fig)


def thermal_plot(result, record: dict) -> None:
    """σxx of both layers along y = −h/2 in the thermal strip against the closed form, and the opening."""
    from ddsolve.post import analysis

    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6), constrained_layout=True)
    fields = analysis.cell_fields(result)
    for block, label in (("u_minus", "layer 1"), ("v_minus", "layer 2")):
        half = result.half(block)
        centres = half.points[half.cells[:, :3]].mean(axis=1)
        band = np.abs(centres[:, 1] + 0.5 * ARM) < 0.1
        order = np.argsort(centres[band, 0])
        top.plot(centres[band, 0][order], fields[block].stress[band, 0][order], ".", markersize=2, label=label)
    expected = record["expected"]
    top.axhline(expected, color="k", linestyle="--", label="closed form σ₁ (and σ₂ = −σ₁)")
    top.axhline(-expected, color="k", linestyle="--")
    top.set_xlabel("x")
    top.set_ylabel("σxx near y = −h/2")
    top.legend(fontsize=8)
    top.grid(alpha=0.3)
    opening = analysis.normal_jump(result)
    position, _ = analysis.along_sigma(result)
    bottom.plot(position, opening, ".-", markersize=2)
    bottom.axvspan(*THERMAL["crack"], color="0.9")
    bottom.set_xlabel("x along Σ")
    bottom.set_ylabel("opening [u]·ν")
    bottom.grid(alpha=0.3)
    fig.savefig(DOCS / "delamination-thermal.png", dpi=110)
    plt.close(fig)


def implied_correction(row: dict) -> float:
    """The tip correction Δ/h that makes beam theory give the computed G: √(G/G_beam) a − a."""
    return (math.sqrt(row["G"] / row["simple"]) * row["a"] - row["a"]) / ARM


def _percent(value: float) -> str:
    return f"{100.0 * value:+.2f} %"


def text(record: dict) -> str:
    """The section of docs/delamination.md from a record of ``./run delamination``, a part per function."""
    out = _introduction(record)
    for layers in LAYERS:
        out += _specimens(record, layers)
    out += _mode_ratio(record) + _mesh_convergence(record) + _thermal(record) + _floating_block(record)
    return "\n".join(out)


def _introduction(record: dict) -> list[str]:
    """What was solved, how, and the beam theories compared."""
    out = [f"Generated by `./run delamination` ({record['provenance'].get('git_commit', '')[:10]}). Strips of "
           f"arm thickness h = {ARM:g} (the strip 2h high, Σ its mid-plane, an edge crack (0, a) on Σ), graded P2 "
           f"meshes (`mesh.size = {SIZE:g}`, `mesh.degree = 2`, `mesh.grading = true`), plane strain; P = {LOAD:g} "
           "summed over both layers (each layer carries half). Solved with the monolithic reference in one "
           "process (the DD methods converge to it; one floating case is checked on 2 ranks below).", "",
           f"'corrected': corrected beam theory with the isotropic elasticity corrections a + χh, χ = {CHI_I:g} "
           f"(mode I: DCB, the MMB's G_I) and {CHI_II:g} (mode II: ELS, ENF, the MMB's G_II) (Bao et al. 1992); "
           f"'Wang–Williams': with the composite corrections χ = 6^(−1/4) = {CHI_KANNINEN:.3f} (DCB), "
           f"0.49·{CHI_KANNINEN:.3f} = {CHI_WW_ELS:.3f} (ELS), 0.42·{CHI_KANNINEN:.3f} = {CHI_WW_ENF:.3f} (ENF); "
           "'implied χh': the correction that makes beam theory give the computed G.", ""]
    return out


def _specimens(record: dict, layers: str) -> list[str]:
    """Every specimen of one pair of layers, and DCB under a prescribed opening."""
    (E1, nu1), (E2, nu2) = LAYERS[layers]
    out = [f"### {layers.capitalize()} layers (E1 = {E1:g}, ν1 = {nu1:g}; E2 = {E2:g}, ν2 = {nu2:g}; "
           f"E₁′ + E₂′ = {summed_modulus(LAYERS[layers]):.4g})", "",
           "| specimen | a/h | G | G_I / G | G_II / G | (G_I + G_II)/G − 1 | beam theory | corrected | "
           "G / corrected − 1 | G / Wang–Williams − 1 | implied χh | penetration / max\\|u\\| |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for specimen in ("DCB", "DCB-displacement", "ELS", "ENF", "MMB"):
        for row in rows(record, specimen, layers):
            label = specimen if specimen != "MMB" else f"MMB, c/L = {row['c'] / row['L']:g}"
            implied = f"{implied_correction(row):.3f}" if specimen in ("DCB", "ELS", "ENF") else ""
            out.append(f"| {label} | {row['a'] / ARM:g} | {row['G']:.6e} | {row['G_I'] / row['G']:.2e} | "
                       f"{row['G_II'] / row['G']:.2e} | {(row['G_I'] + row['G_II']) / row['G'] - 1:+.1e} | "
                       f"{row['simple']:.4e} | {row['corrected']:.4e} | "
                       f"{_percent(row['G'] / row['corrected'] - 1)} | "
                       f"{_percent(row['G'] / row['wang_williams'] - 1)} | {implied} | {row['penetration']:.1e} |")
    displaced = rows(record, "DCB-displacement", layers)[0]
    out += ["", f"DCB under a prescribed opening δ = {OPENING:g} of the arms' end faces: the reaction "
            f"P = {displaced['reaction']:.6e} in corrected beam theory (χ = {CHI_I:g}) gives "
            f"{displaced['from_reaction']:.6e} "
            f"(G {_percent(displaced['G'] / displaced['from_reaction'] - 1)} of it); the table's 'corrected' "
            "is the opening form 3δ²E′h³/(16(a + χh)⁴), which also carries the compliance beam theory "
            "leaves out (shear, the clamp).", ""]
    return out


def _mode_ratio(record: dict) -> list[str]:
    """MMB's mode ratio at three lever lengths against beam theory."""
    out = ["### MMB: the mode ratio at three lever lengths", "",
           f"a = {MMB_CRACK:g}, L = {0.5 * SPAN:g}: G_I/G_II computed, and from P_I = P(3c − L)/(4L), "
           "P_II = P(c + L)/L in beam theory, (4/3)((3c − L)/(c + L))², and in corrected beam theory, times "
           f"((a + {CHI_I:g}h)/(a + {CHI_II:g}h))² (isotropic) or ((a + {CHI_KANNINEN:.3f}h)/(a + "
           f"{CHI_WW_ENF:.3f}h))² (Wang–Williams).", "",
           "| layers | c/L | G_I | G_II | G_I/G_II | beam theory | corrected | computed / corrected − 1 | "
           "Wang–Williams | computed / Wang–Williams − 1 | ψ |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    for layers in LAYERS:
        for row in rows(record, "MMB", layers):
            ratio = row["G_I"] / row["G_II"]
            corrected = row["corrected_I"] / row["corrected_II"]
            composite = row["wang_williams_I"] / row["wang_williams_II"]
            phase = f"{row['phase']:.1f}°" if np.isfinite(row["phase"]) else "undefined"  # NaN: G ≈ 0
            out.append(f"| {layers} | {row['c'] / row['L']:g} | {row['G_I']:.4e} | {row['G_II']:.4e} | {ratio:.4f} | "
                       f"{row['simple_I'] / row['simple_II']:.4f} | {corrected:.4f} | "
                       f"{_percent(ratio / corrected - 1)} | {composite:.4f} | {_percent(ratio / composite - 1)} | "
                       f"{phase} |")
    return out


def _mesh_convergence(record: dict) -> list[str]:
    """G of DCB and ELS on the default mesh and a finer one."""
    out = ["", "### Mesh convergence", "",
           f"The a = 6 cases of identical layers at `mesh.size = {SIZE:g}` and {FINE_SIZE:g}:", "",
           f"| specimen | G, size {SIZE:g} | G, size {FINE_SIZE:g} | change | unknowns | (G_I + G_II)/G − 1, "
           f"size {FINE_SIZE:g} |", "|---|---|---|---|---|---|"]
    for specimen in ("DCB", "ELS"):
        fine = rows(record, specimen, "identical", FINE_SIZE)[0]
        coarse = next(row for row in rows(record, specimen, "identical") if row["a"] == fine["a"]
                      and row["c"] == fine["c"])
        out.append(f"| {specimen} | {coarse['G']:.6e} | {fine['G']:.6e} | {_percent(fine['G'] / coarse['G'] - 1)} | "
                   f"{coarse['unknowns']:,} → {fine['unknowns']:,} | {(fine['G_I'] + fine['G_II']) / fine['G'] - 1:+.1e} |")
    return out


def _thermal(record: dict) -> list[str]:
    """The thermal mismatch: stresses against the closed form, G against the energy's derivative."""
    thermal_record = record["thermal"]
    out = ["", "### Thermal mismatch", "",
           f"The DCB strip's geometry with an interior crack {THERMAL['crack']}, the different layers with "
           f"α = {THERMAL['alpha'][0]:g}, {THERMAL['alpha'][1]:g} and ΔT = {THERMAL['dT']:g}, free to expand "
           f"(x = 0 on the left end, a pin |y| ≤ {PIN:g} there): σxx in 3 < x < 6 against the closed form "
           f"σ₁ = (m₂ − m₁)/(1/E₁′ + 1/E₂′) = {thermal_record['expected']:.6e}, m = (1 + ν)αΔT, σ₂ = −σ₁:", "",
           "| block | mean σxx | closed form | mean / closed form − 1 | max \\|σyy\\| | max \\|σxy\\| |", "|---|---|---|---|---|---|"]
    for block, (mean, _, syy, sxy) in thermal_record["stresses"].items():
        expected = thermal_record["expected"] * (1.0 if block.startswith("u") else -1.0)
        out.append(f"| {block} | {mean:.6e} | {expected:.6e} | {_percent(mean / expected - 1)} | {syy:.1e} | {sxy:.1e} |")
    out += ["", "G at the tips, against −dΠ/da by central differences of the energy with the mesh nodes moved by "
            f"±{THERMAL['steps'][0]:g}θ, and against the energy scale σ₁²·2h/E₁′ = {thermal_record['scale']:.3e}:", "",
            "| case | tip x | G | −dΠ/da | G / scale |", "|---|---|---|---|---|"]
    for row in thermal_record["finite_differences"]:
        out.append(f"| free strip | {row['tip']:g} | {row['G']:.4e} | {row['fd']:.4e} | {row['G'] / thermal_record['scale']:.1e} |")
    clamped = record["thermal_clamped"]
    for x, row in zip(clamped["points"], clamped["tips"]):
        out.append(f"| clamped square | {x:g} | {row['G']:.6e} | {row['fd']:.6e} ({_percent(row['G'] / row['fd'] - 1)}) | |")
    return out


def _floating_block(record: dict) -> list[str]:
    """ENF with floating blocks on 2 ranks against the reference."""
    cross = record["cross_check"]
    out = ["", "### A floating block on 2 ranks", "",
           f"ENF, identical layers, a = 6 (blocks {cross['floating']} held only through Σ): "
           f"`./run solve -n {cross['ranks']} results/delamination/enf.toml` (the scene `./run delamination` "
           f"writes) ({cross['method']}) gives G = {cross['G']:.9e} "
           f"(G_I {cross['G_I']:.3e}, G_II {cross['G_II']:.6e}), the reference {cross['reference_G']:.9e} "
           f"(relative difference {abs(cross['G'] / cross['reference_G'] - 1):.1e}; {cross['seconds']:.1f} s "
           "with the launch).", ""]
    return out
