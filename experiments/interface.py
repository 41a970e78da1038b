"""Interface laws against closed forms: ``./run interface`` writes docs/interface.md, docs/interface-*.png and
results/interface.h5.

The page is :data:`SECTIONS`, a list of :class:`Section`s: each measures its cases into a record, draws its pictures
from the record and writes its markdown and its rows of the summary table from it. Every friction case is
``./run solve`` on :data:`RANKS` ranks with the default method, as a user runs it, timed around the launch. Friction
on the crack faces:

- the closed crack under remote compression S and shear T (docs/closed-crack.toml), Coulomb and Tresca from no
  friction to stick, against the infinite plane's K_II = (T − g)√(πa), the finite square's excess measured at two
  sides and extrapolated;
- the ENF with friction between the arms against Euler beam theory with the friction fully developed at the mouth.

The cohesive bond (experiments/cohesive.py's DCB, ``ddsolve grow`` in one process): the bilinear law at three
strengths against Griffith's growth of the same structure, the process zone against Hillerborg's and the slender
arm's estimates, mesh convergence, a bond with no initial crack, and the runs' Newton steps and block solves; the
ENF (mode II) with the law under Benzeggagh–Kenane at three strengths against Griffith's growth with G_IIc.
"""
from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from experiments import cohesive, report, stacks
from experiments.delamination import ARM, CHI_II, plane_strain_modulus
from experiments.stacks import table

RESULTS = Path("results")
DOCS = Path("docs")
RANKS = 2
CLOSED_CRACK = DOCS / "closed-crack.toml"
#: docs/closed-crack.toml: remote compression S and shear T, the crack's half-length a, the layers' material.
S, T, HALF_LENGTH, E, NU = 1.0, 1.0, 1.0, 100.0, 0.3
#: The sweep's square (side) and mesh.size; the larger square and the finer mesh that measure their errors.
SIDE, LARGE_SIDE, SIZE, FINE_SIZE = 20.0, 40.0, 0.5, 0.25
#: Coulomb's μ (the faces stick from T/S = 1 on) and Tresca's slip_bound (both layers together: per layer half).
COULOMB = (0.2, 0.4, 0.5, 0.6, 0.8, 0.9, 1.0, 1.5)
TRESCA = (0.5, 1.0, 1.5, 2.0, 3.0)
#: The case whose traction and slip along the crack are drawn.
PROFILED = ("Coulomb", 0.5)
#: The ENF's crack lengths (h = 1), its μ, mesh sizes, the cases refined and those solved by feti too.
ENF_CRACKS, ENF_FRICTION = (5.0, 10.0), (0.0, 0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0)
ENF_SIZE, ENF_FINE = 0.2, 0.1
ENF_REFINED, ENF_CHECKED = (0.0, 0.5, 2.0, 8.0), (0.5, 8.0)
#: The ENF's profiled case: friction sticks at the mouth and slips beyond.
ENF_PROFILED = (5.0, 8.0)


# --- closed forms ----------------------------------------------------------------------------------------
def friction_stress(law: str, value: float, pressure: float = S) -> float:
    """The friction stress g per layer: Coulomb's μS, Tresca's ``slip_bound``/2 (the bound is the traction both
    layers carry together, docs/fracture.md), none without friction."""
    return {"none": 0.0, "Coulomb": value * pressure, "Tresca": 0.5 * value}[law]


def closed_crack_release(g: float, shear: float = T, a: float = HALF_LENGTH, modulus: float = E, nu: float = NU,
                         layers: int = 2) -> float:
    """G of the crack (−a, a) in an infinite plane under remote shear T, its faces held by the friction stress g:
    K_II = (T − g)√(πa), G = (1 − ν²)K_II²/E per layer (plane strain) while g < T; 0 once the faces stick."""
    return layers * (1.0 - nu * nu) * max(shear - g, 0.0) ** 2 * math.pi * a / modulus


def closed_crack_slip(x: np.ndarray, g: float, shear: float = T, a: float = HALF_LENGTH, modulus: float = E,
                      nu: float = NU) -> np.ndarray:
    """The faces' slip per layer along the crack, 4(1 − ν²)(T − g)√(a² − x²)/E (plane strain)."""
    return 4.0 * (1.0 - nu * nu) * max(shear - g, 0.0) * np.sqrt(np.maximum(a * a - x * x, 0.0)) / modulus


def infinite_plane(small: float, large: float, ratio: float = LARGE_SIDE / SIDE) -> float:
    """G of an infinite plane from squares of sides W and ``ratio``·W, the excess falling as (a/W)²."""
    return (ratio ** 2 * large - small) / (ratio ** 2 - 1.0)


def enf_stick_friction(a: float, h: float = ARM) -> float:
    """The μ from which the ENF's arms stick at the mouth: 3a/(4h)."""
    return 0.75 * a / h


def enf_friction_ratio(mu: float, a: float, h: float = ARM) -> float:
    """G/G₀ of the ENF (identical arms of thickness h, crack a) with friction μ between the arms, Euler beam
    theory: the roller's reaction R reaches the upper arm as R/2 at the mouth, where the friction μR/2 acts
    along the faces, h/2 from each arm's axis. At the tip each arm carries M = Ra/2 − Fh/2 and ∓F, so
    G/G₀ = (1 − 2μh/(3a))² while the arms slip; from μ = 3a/(4h) they stick, F = 3Ra/(8h), G/G₀ = 1/4."""
    return (1.0 - 2.0 * min(mu, enf_stick_friction(a, h)) * h / (3.0 * a)) ** 2


def enf_frictionless(a: float, reaction: float) -> float:
    """The standard ENF's G (both layers) with the tip correction χ_II, R the roller's reaction."""
    modulus = 2.0 * plane_strain_modulus(200.0, 0.28)
    return stacks.enf_release(reaction * (a + CHI_II * ARM), ARM, {"lower": modulus, "upper": modulus})


# --- solving as a user does --------------------------------------------------------------------------------
def solve(scene: Path, settings: dict[str, object], folder: Path, name: str) -> tuple[object, float]:
    """``./run solve -n RANKS SCENE --set KEY=VALUE ...``: the result read back, the launch's wall time."""
    from ddsolve.io import hdf5

    path = folder / f"{name}.h5"
    overrides = [item for key, value in settings.items() for item in ("--set", f"{key}={value}")]
    started = time.perf_counter()
    report.run(RANKS, ["solve", str(scene), *overrides, "-o", str(path)])
    return hdf5.read(path), time.perf_counter() - started


def friction_settings(law: str, value: float) -> dict[str, float]:
    return {"none": {}, "Coulomb": {"contact.friction": value}, "Tresca": {"contact.slip_bound": value}}[law]


def zones(result) -> dict[str, str]:
    """Where the faces slip and stick, as x ranges on Σ."""
    from ddsolve.post import analysis

    x = result.interface_points[:, 0]
    return {kind: ", ".join(f"[{x[a]:.3g}, {x[b]:.3g}]" for a, b in runs) or "none"
            for kind, runs in analysis.friction_zones(result).items()}


def solved_row(result, seconds: float) -> dict:
    """What every case keeps of its solve: size, method, work, time, the slip and stick zones."""
    return {"unknowns": result.unknowns, "method": result.method, "iterations": int(result.iterations),
            "coulomb_iterations": int(result.attrs.get("coulomb_iterations", 0)), "seconds": seconds,
            "solve_seconds": float(result.wall_time), **zones(result)}


def friction_profile(result) -> dict[str, list[float]]:
    """Along the crack: x, the tangential traction μ_t and the slip (u⁻ − u⁺)·τ of layer 1."""
    from ddsolve.io.viewer import friction_arrays

    on, nodes = result.on_sigma, result.mesh.sigma.multiplier_nodes
    arrays = friction_arrays(on, result.scene.friction)
    crack = result.crack
    return {"x": result.interface_points[crack, 0].tolist(),
            "traction": arrays["tangential_traction"][nodes][crack].tolist(),
            "slip": arrays["slip"][nodes][crack].tolist(), "pressure": on.multipliers["mu_c"][crack].tolist(),
            "state": arrays["friction_state"][nodes][crack].astype(float).tolist()}


def commit(result) -> str:
    return str(result.attrs.get("git_commit", "unknown"))


# --- the closed crack ----------------------------------------------------------------------------------
def closed_crack_settings(law: str, value: float, side: float = SIDE, size: float = SIZE) -> dict[str, object]:
    """The ``--set`` overrides of docs/closed-crack.toml: the friction, the mesh size, and a square of another
    side with its pin and roller moved to Σ's ends."""
    settings: dict[str, object] = {"mesh.size": size, **friction_settings(law, value)}
    if side != SIDE:
        half = 0.5 * side
        settings["geometry.box"] = f"[{-half!r},{half!r},{-half!r},{half!r}]"
        settings.update({f"displacements.{layer}.{support}.point": f"[{x!r},0.0]" for layer in ("layer1", "layer2")
                         for support, x in (("pin", -half), ("roller", half))})
    return settings


def closed_crack_case(law: str, value: float, folder: Path, side: float = SIDE, size: float = SIZE):
    """One solve of the closed crack: its row (G the mean of the two tips) and the result."""
    result, seconds = solve(CLOSED_CRACK, closed_crack_settings(law, value, side, size), folder,
                            f"closed-{law}-{value:g}-{side:g}-{size:g}")
    g = friction_stress(law, value)
    row = {"law": law, "value": value, "g": g, "side": side, "size": size, "G": float(np.mean(result.G)),
           "tips": float(np.ptp(result.G)), "G_II": float(np.mean(result.fracture.G_II)),
           "theory": closed_crack_release(g), **solved_row(result, seconds)}
    print(f"interface: closed crack, {law} {value:g}, side {side:g}, size {size:g}: G {row['G']:.6e} (closed form "
          f"{row['theory']:.6e}), {seconds:.1f} s", flush=True)
    return row, result


def measure_closed_crack() -> dict:
    """The sweep (no friction, Coulomb, Tresca) in the square of side SIDE; no friction and μ = 0.5 in the larger
    square and on the finer mesh; the traction and slip of the PROFILED case."""
    cases = [("none", 0.0)] + [("Coulomb", mu) for mu in COULOMB] + [("Tresca", g) for g in TRESCA]
    with tempfile.TemporaryDirectory() as folder:
        sweep, profile, revision = [], {}, "unknown"
        for law, value in cases:
            row, result = closed_crack_case(law, value, Path(folder))
            sweep.append(row)
            revision = commit(result)
            if (law, value) == PROFILED:
                profile = friction_profile(result)
        box = [closed_crack_case(law, value, Path(folder), side, size)[0]
               for side, size in ((LARGE_SIDE, SIZE), (SIDE, FINE_SIZE)) for law, value in (("none", 0.0), PROFILED)]
    return {"sweep": sweep, "box": box, "profile": profile, "commit": revision}


def frictionless(rows: list[dict]) -> float:
    return next(row["G"] for row in rows if row["law"] == "none")


def box_excess(record: dict) -> float:
    """How much the square of side SIDE raises G above the infinite plane (no friction, mesh SIZE)."""
    large = frictionless([row for row in record["box"] if row["side"] == LARGE_SIDE])
    return frictionless(record["sweep"]) / infinite_plane(frictionless(record["sweep"]), large) - 1.0


def closed_crack_error(row: dict, excess: float) -> float:
    """G against the infinite plane's closed form, the square's excess taken out; once the faces stick (closed
    form 0) |G| against the frictionless closed form."""
    if row["theory"] == 0.0:
        return abs(row["G"]) / closed_crack_release(0.0)
    return row["G"] / (1.0 + excess) / row["theory"] - 1.0


def law_label(row: dict) -> str:
    return {"none": "no friction", "Coulomb": f"Coulomb μ = {row['value']:g}",
            "Tresca": f"Tresca slip_bound = {row['value']:g}"}[row["law"]]


def percent(value: float, digits: int = 2) -> str:
    return f"{100.0 * value:+.{digits}f} %"


def summary_row(case: str, closed: float, G: float, error: str, row: dict) -> dict:
    """A row of the page's summary: the case, its closed form, ddsolve's value, the error, the solve."""
    return {"case": case, "closed": closed, "G": G, "error": error, "unknowns": row["unknowns"],
            "method": row["method"], "seconds": row["seconds"]}


def closed_crack_summary(record: dict) -> list[dict]:
    excess = box_excess(record)
    return [summary_row(f"closed crack, {law_label(row)}", row["theory"], row["G"],
                        f"\\|G\\|/G₀ = {error:.1e}" if row["theory"] == 0.0 else percent(error, 3), row)
            for row in record["sweep"] for error in [closed_crack_error(row, excess)]]


# --- the ENF -------------------------------------------------------------------------------------------
def enf_series(a: float, frictions: tuple[float, ...], size: float, folder: Path, method: str | None = None,
               tol: float | None = None) -> tuple[list[dict], dict]:
    """The ENF with identical arms (experiments.stacks.enf_text), crack a, at each μ of ``frictions`` (the first
    0): the rows, G/G₀ against the frictionless first, and the results by μ."""
    scene = folder / f"enf-{a:g}-{size:g}.toml"
    scene.write_text(stacks.enf_text(a, size, "identical"))
    rows, results = [], {}
    for mu in frictions:
        settings = {"contact.friction": mu, **({"solver.method": method} if method else {}),
                    **({"solver.tol": tol} if tol else {})}
        result, seconds = solve(scene, settings, folder, f"enf-{a:g}-{size:g}-{mu:g}-{method}")
        reaction = float(sum(forces["roller"][1] for forces in result.reactions.values()))
        G = float(result.fracture.G[0])
        base = rows[0]["G"] if rows else G
        contact = ", ".join(f"[{low:.3g}, {high:.3g}]" for low, high in result.contact_zones) or "none"
        rows.append({"a": a, "mu": mu, "size": size, "G": G, "G_II": float(result.fracture.G_II[0]),
                     "G_I": float(result.fracture.G_I[0]), "reaction": reaction, "ratio": G / base,
                     "estimate": enf_friction_ratio(mu, a), "theory": enf_frictionless(a, reaction)
                     * enf_friction_ratio(mu, a), "contact": contact, **solved_row(result, seconds)})
        results[mu] = result
        print(f"interface: ENF, a = {a:g}, μ = {mu:g}, size {size:g} ({result.method}): G/G₀ {G / base:.5f} "
              f"(beam theory {enf_friction_ratio(mu, a):.5f}), {seconds:.1f} s", flush=True)
    return rows, results


def measure_enf() -> dict:
    """Every crack length at every μ; the refined mesh; feti against schur at the checked μ (tol 1e-11)."""
    from ddsolve.post import analysis

    with tempfile.TemporaryDirectory() as folder:
        rows, profile, revision = [], {}, "unknown"
        for a in ENF_CRACKS:
            series, results = enf_series(a, ENF_FRICTION, ENF_SIZE, Path(folder))
            rows += series
            revision = commit(results[0.0])
            if a == ENF_PROFILED[0]:
                profile = friction_profile(results[ENF_PROFILED[1]])
        refined = enf_series(ENF_CRACKS[0], ENF_REFINED, ENF_FINE, Path(folder))[0]
        checks = (0.0, *ENF_CHECKED)
        schur, exact = enf_series(ENF_CRACKS[0], checks, ENF_SIZE, Path(folder), "schur", 1e-11)
        feti, other = enf_series(ENF_CRACKS[0], checks, ENF_SIZE, Path(folder), "feti", 1e-11)
        methods = [{**row, "schur_G": reference["G"], "schur_seconds": reference["seconds"],
                    "energy_error": float(analysis.compare(other[row["mu"]], exact[row["mu"]]).energy_error)}
                   for row, reference in zip(feti, schur)]
    return {"rows": rows, "refined": refined, "methods": methods, "profile": profile, "commit": revision}


def enf_summary(record: dict) -> list[dict]:
    return [summary_row(f"ENF, a/h = {row['a'] / ARM:g}, Coulomb μ = {row['mu']:g}"
                        + (" (beyond stick: beam theory's 1/4)" if row["mu"] >= enf_stick_friction(row["a"]) else ""),
                        row["theory"], row["G"], percent(row["G"] / row["theory"] - 1.0), row)
            for row in record["rows"]]


# --- pictures ------------------------------------------------------------------------------------------
def _pyplot():
    from ddsolve.post.plots import _pyplot as pyplot

    return pyplot()


def closed_crack_plot(record: dict) -> None:
    """G/G₀ against the friction stress with (1 − g/T)²; the traction and slip along the profiled case's crack."""
    plt = _pyplot()
    fig, (left, traction, slip) = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    stress = np.linspace(0.0, 1.6, 200)
    left.plot(stress, [closed_crack_release(g) / closed_crack_release(0.0) for g in stress], "k-",
              label="closed form (1 − g/T)², 0 once g ≥ T")
    base = frictionless(record["sweep"])
    for law, marker in (("none", "D"), ("Coulomb", "o"), ("Tresca", "s")):
        rows = [row for row in record["sweep"] if row["law"] == law]
        left.plot([row["g"] / T for row in rows], [row["G"] / base for row in rows], marker, fillstyle="none",
                  markersize=8, label={"none": "no friction", "Coulomb": "Coulomb, g = μS",
                                       "Tresca": "Tresca, g = slip_bound/2"}[law])
    left.set_xlabel("friction stress per layer g / T")
    left.set_ylabel("G / G(no friction)")
    left.set_title(f"closed crack, S = T: G/G₀ within {worst_ratio(record):.1e} of (1 − g/T)²", fontsize=10)
    left.grid(alpha=0.3)
    left.legend(fontsize=8)
    profile, g = record["profile"], friction_stress(*PROFILED)
    x, name = np.array(profile["x"]), law_label({"law": PROFILED[0], "value": PROFILED[1]})
    traction.plot(x, 0.5 * np.abs(profile["traction"]), "o", markersize=3, label="|μ_t|/2: per layer")
    traction.axhline(g, color="k", linestyle="--", linewidth=0.8, label=f"g = μS = {g:g}")
    traction.set_ylim(0.0, 1.5 * g)
    traction.set_ylabel("tangential traction per layer")
    traction.set_title(f"{name}: the traction, g along the whole crack", fontsize=10)
    dense = np.linspace(-HALF_LENGTH, HALF_LENGTH, 201)
    slip.plot(dense, closed_crack_slip(dense, g), "k-", label="closed form 4(1 − ν²)(T − g)√(a² − x²)/E")
    slip.plot(x, np.abs(profile["slip"]), "s", markersize=3, fillstyle="none", label="ddsolve |(u⁻ − u⁺)·τ|")
    slip.set_ylabel("slip per layer")
    slip.set_title(f"{name}: the slip, the ellipse of T − g", fontsize=10)
    for ax in (traction, slip):
        ax.set_xlabel("x on Σ (the crack (−1, 1))")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="lower center")
    fig.savefig(DOCS / "interface-closed-crack.png", dpi=110)
    plt.close(fig)


def worst_ratio(record: dict) -> float:
    """The largest |G/G₀ − (1 − g/T)²| of the sweep: the ratio, which the square's excess does not change."""
    base = frictionless(record["sweep"])
    return max(abs(row["G"] / base - row["theory"] / closed_crack_release(0.0)) for row in record["sweep"])


def enf_plot(record: dict) -> None:
    """G/G₀ against μ with beam theory; the traction, its bound and the slip near the profiled case's mouth."""
    plt = _pyplot()
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    mus = np.linspace(0.0, max(ENF_FRICTION), 300)
    for index, a in enumerate(ENF_CRACKS):
        rows = [row for row in record["rows"] if row["a"] == a]
        left.plot(mus, [enf_friction_ratio(mu, a) for mu in mus], f"C{index}-",
                  label=f"a/h = {a / ARM:g}: beam theory, stick from μ = {enf_stick_friction(a):g}")
        for stuck, fill in ((False, "full"), (True, "none")):
            chosen = [row for row in rows if (row["stick"] != "none") == stuck]
            left.plot([row["mu"] for row in chosen], [row["ratio"] for row in chosen], f"C{index}o", fillstyle=fill,
                      label=f"a/h = {a / ARM:g}, ddsolve, " + ("part sticks" if stuck else "all slips"))
    left.set_xlabel("Coulomb μ between the arms")
    left.set_ylabel("G_II / G_II(μ = 0)")
    left.set_title("ENF with friction: G_II against μ", fontsize=10)
    left.grid(alpha=0.3)
    left.legend(fontsize=7)
    profile, mu = record["profile"], ENF_PROFILED[1]
    x, state = np.array(profile["x"]), np.array(profile["state"])
    zone = x <= 1.0
    right.plot(x[zone], np.abs(profile["traction"])[zone], "o-", markersize=3, label="|μ_t|")
    right.plot(x[zone], mu * np.array(profile["pressure"])[zone], "k--", label=f"μ μᶜ (μ = {mu:g})")
    right.plot(x[zone & (state == 1)], np.abs(profile["traction"])[zone & (state == 1)], "s", fillstyle="none",
               markersize=8, label="stick")
    right.set_xlabel("x on Σ (the mouth at 0)")
    right.set_ylabel("traction (both layers)")
    twin = right.twinx()
    twin.plot(x[zone], np.array(profile["slip"])[zone], "C1-", label="slip (u⁻ − u⁺)·τ")
    twin.set_ylabel("slip")
    lines = right.get_legend_handles_labels(), twin.get_legend_handles_labels()
    right.legend(lines[0][0] + lines[1][0], lines[0][1] + lines[1][1], fontsize=7)
    right.set_title(f"a/h = {ENF_PROFILED[0]:g}, μ = {mu:g}: the faces stick at the mouth, slip beyond", fontsize=10)
    fig.savefig(DOCS / "interface-enf.png", dpi=110)
    plt.close(fig)


# --- the page ------------------------------------------------------------------------------------------
def closed_crack_page(record: dict) -> list[str]:
    excess, base = box_excess(record), frictionless(record["sweep"])
    out = ["## The closed crack", "",
           f"`docs/closed-crack.toml`: a crack (−a, a), a = {HALF_LENGTH:g}, on Σ in a square of side {SIDE:g}, both "
           f"layers (E = {E:g}, ν = {NU:g}, plane strain) loaded on all four sides by the self-equilibrated remote "
           f"stress σ_yy = −S, σ_xy = T (S = {S:g}, T = {T:g}); a pin and a roller at Σ's ends take the rigid motions "
           "only. The faces stay pressed by S and slide under T against the friction stress g per layer: Coulomb's "
           "g = μS, Tresca's g = `slip_bound`/2 (`slip_bound` bounds the traction μ_t both layers carry together, "
           "[fracture.md](fracture.md#friction-on-the-crack-faces)). Where the whole crack slips the faces carry "
           "g uniformly, so the crack sees the shear T − g: K_II = (T − g)√(πa) and, summed over the two identical "
           "layers, G = 2(1 − ν²)(T − g)²πa/E; once g ≥ T (μ ≥ T/S) the faces stick and G = 0. "
           f"`./run solve -n {RANKS} docs/closed-crack.toml --set contact.friction=μ` (or `contact.slip_bound=`, "
           f"`mesh.size={SIZE:g}`), the scene's method (schur); G is the mean of the two tips.", ""]
    out += closed_crack_box(record)
    out += ["", "![closed crack](interface-closed-crack.png)", ""]
    out += table(["friction", "g per layer", "closed form (infinite plane)", "G (side 20)", "tips differ by",
                  "G / closed form − 1", "error", "slip", "stick", "Tresca problems", "unknowns", "wall time"],
                 [[law_label(row), f"{row['g']:g}", f"{row['theory']:.6e}", f"{row['G']:.6e}", f"{row['tips']:.1e}",
                   percent(row["G"] / row["theory"] - 1.0, 3) if row["theory"] else f"G/G₀ = {row['G'] / base:.1e}",
                   percent(error, 3) if row["theory"] else f"\\|G\\|/G₀ = {error:.1e}", row["slip"], row["stick"],
                   str(row["coulomb_iterations"] or ""), f"{row['unknowns']:,}", f"{row['seconds']:.1f} s"]
                  for row in record["sweep"] for error in [closed_crack_error(row, excess)]])
    out += ["", f"G/G₀ against (1 − g/T)², where the square's excess cancels: within {worst_ratio(record):.1e} at "
            "every friction. *Tresca problems*: Coulomb's fixed point solves Tresca problems with g = μμᶜ from the "
            "last multipliers until the bounds stop moving. The pictures' middle and right: the traction per layer "
            f"is g along the crack but for the few nodes within {scattered(record['profile']):.2g}a of the tips, the "
            "graded mesh's smallest "
            "elements, where the contact pressure μᶜ (so μμᶜ) scatters about its mean, the node at the tip itself "
            "apart; the slip is the infinite plane's ellipse of the reduced shear T − g (above it by half the "
            "square's excess)."]
    return out


def scattered(profile: dict, g: float = friction_stress(*PROFILED)) -> float:
    """How far from the tips (in a) the traction per layer strays by over 1 % from g."""
    x, traction = np.array(profile["x"]), 0.5 * np.abs(profile["traction"])
    off = np.abs(traction - g) > 0.01 * g
    return float(np.max(HALF_LENGTH - np.abs(x[off]), initial=0.0)) / HALF_LENGTH


def closed_crack_box(record: dict) -> list[str]:
    """The square's excess: the sides W and 2W, the finer mesh, the infinite plane extrapolated."""
    rows = [row for row in record["sweep"] if (row["law"], row["value"]) in (("none", 0.0), PROFILED)] + record["box"]

    def G(case: tuple[str, float], side: float, size: float) -> float:
        return next(row["G"] for row in rows if (row["law"], row["value"]) == case and row["side"] == side
                    and row["size"] == size)

    mesh = max(abs(G(case, SIDE, FINE_SIZE) / G(case, SIDE, SIZE) - 1.0) for case in (("none", 0.0), PROFILED))
    out = ["**The square's excess.** The square is finite: its frictionless G lies above the infinite plane's by "
           "an amount that falls as (a/W)². Solved in squares of side W and 2W at the same mesh.size, the infinite "
           "plane is G∞ = (4G(2W) − G(W))/3; with friction the ratio to the frictionless G is exactly (1 − g/T)² "
           "in any square (a slipping crack is the frictionless one under T − g), so one factor serves every case. "
           f"Halving mesh.size changes G by {mesh:.2%} at most: the discretization's share is small.", ""]
    out += table(["square side", "mesh.size", "friction", "unknowns", "G", "closed form", "G / closed form − 1",
                  "wall time"],
                 [[f"{row['side']:g}", f"{row['size']:g}", law_label(row), f"{row['unknowns']:,}", f"{row['G']:.6e}",
                   f"{row['theory']:.6e}", percent(row["G"] / row["theory"] - 1.0, 3), f"{row['seconds']:.1f} s"]
                  for row in rows])
    limits = {case: infinite_plane(G(case, SIDE, SIZE), G(case, LARGE_SIDE, SIZE)) for case in (("none", 0.0), PROFILED)}
    return out + ["", "Extrapolated to the infinite plane: " + "; ".join(
        f"{law_label({'law': law, 'value': value})} {limit:.6e}, the closed form "
        f"{percent(limit / closed_crack_release(friction_stress(law, value)) - 1.0, 3)}"
        for (law, value), limit in limits.items())
        + f". The square of side {SIDE:g} raises G by {percent(box_excess(record), 3)}: the column *error* below "
          "divides it out."]


def enf_page(record: dict) -> list[str]:
    rows = record["rows"]
    slipping = [row for row in rows if row["mu"] < enf_stick_friction(row["a"])]
    example = next(row for row in rows if row["a"] == ENF_CRACKS[0] and row["mu"] == ENF_CHECKED[0])
    out = ["## The ENF with friction between the arms", "",
           f"The standard ENF of [stacks.md](stacks.md) (identical arms E = 200, ν = 0.28, h = {ARM:g}, span "
           "40, a roller at the lower left corner and a pin at the lower right one: points, since a segment would "
           "hold the ends' rotation; the midspan load P a Gaussian on the top), `contact.friction = μ` between the "
           "arms. The arms touch at the mouth only, where half the roller's reaction R = P/2 passes to the upper arm; "
           "the faces there slide, the upper arm's lower face outwards against the lower arm's upper face, and "
           "friction holds them back. **Beam theory** (Euler beams, friction fully developed where it acts, the "
           "model of Gradin, Gustafson and Hojo 1991; Carlsson, Gillespie and Pipes 1986 examine the same effect; "
           "the closed form below is derived here): the arms' end deflections agree, so the upper arm receives "
           "R/2 at the mouth and with it the friction F = μR/2 along its lower face, h/2 from its axis. At the tip "
           "each arm carries M = Ra/2 − Fh/2 and the axial forces ∓F, and the tip's energy balance "
           "G = Σ_arms (M²/2EI + N²/2EA) − (Ra)²/2(EI)_bonded gives", "",
           "    G/G₀ = (1 − 2μh/(3a))²   while the faces slip, μ < 3a/(4h);",
           "    G/G₀ = 1/4               from μ = 3a/(4h) on: the faces stick at the mouth, F = 3Ra/(8h),", "",
           "with the slip at the mouth 3Ra²/(Eh²)·(1 − 4μh/(3a)) per unit width. G₀ is the frictionless ENF's, "
           f"here the computed one at the same mesh (the closed form's column multiplies the ratio by the standard "
           f"ENF's G with Bao's tip correction χ_II = {CHI_II:g}, as in stacks.md). Friction matters for short "
           f"cracks and large μ: at a/h = {example['a'] / ARM:g}, μ = {example['mu']:g} takes "
           f"{1.0 - example['ratio']:.1%} off G_II; the faces stick from μ = {enf_stick_friction(example['a']):g}. "
           f"While all slips the computed ratio is within {max(abs(row['ratio'] - row['estimate']) for row in slipping):.1e} "
           "of beam theory. Past μ = 3a/(4h) the contact zone, a point in beam theory, has a finite length here, "
           "and its stuck part grows with μ: the ratio comes down to 1/4 smoothly rather than at a kink, and goes "
           "on falling below it (" + "; ".join(
               f"a/h = {a / ARM:g}: {stuck[0]['ratio']:.3f} at μ = {stuck[0]['mu']:g}, {stuck[-1]['ratio']:.3f} at "
               f"μ = {stuck[-1]['mu']:g}" for a in ENF_CRACKS
               for stuck in [[row for row in rows if row["a"] == a and row["mu"] >= enf_stick_friction(a)]] if stuck)
           + "): beyond stick, beam theory's 1/4 is an estimate, and the table's error there says by how much. "
           f"`./run solve -n {RANKS}` with the default method (auto: schur), `mesh.size = {ENF_SIZE:g}`.", "",
           "![ENF with friction](interface-enf.png)", ""]
    out += enf_table(rows)
    out += ["", f"**Mesh convergence** (a/h = {ENF_CRACKS[0]:g}, `mesh.size = {ENF_FINE:g}`, against "
            f"{ENF_SIZE:g} above):", ""]
    coarse = {row["mu"]: row for row in rows if row["a"] == ENF_CRACKS[0]}
    out += table(["μ", "unknowns", "G_II", f"G_II at {ENF_SIZE:g}", "G/G₀", f"G/G₀ at {ENF_SIZE:g}", "slip", "stick",
                  "wall time"],
                 [[f"{row['mu']:g}", f"{row['unknowns']:,}", f"{row['G_II']:.6e}", f"{coarse[row['mu']]['G_II']:.6e}",
                   f"{row['ratio']:.5f}", f"{coarse[row['mu']]['ratio']:.5f}", row["slip"], row["stick"],
                   f"{row['seconds']:.1f} s"] for row in record["refined"]])
    out += ["", "**Two methods** (a/h = 5, `mesh.size = 0.2`, `solver.tol = 1e-11`): feti against schur, the "
            "energy norm of the difference relative to the solution's (`ddsolve compare`):", ""]
    out += table(["μ", "schur G", "feti G", "energy-norm difference", "feti iterations", "Tresca problems",
                  "schur wall time", "feti wall time"],
                 [[f"{row['mu']:g}", f"{row['schur_G']:.9e}", f"{row['G']:.9e}", f"{row['energy_error']:.1e}",
                   str(row["iterations"]), str(row["coulomb_iterations"]), f"{row['schur_seconds']:.1f} s",
                   f"{row['seconds']:.1f} s"] for row in record["methods"]])
    return out


def enf_table(rows: list[dict]) -> list[str]:
    return table(["a/h", "μ", "unknowns", "G_II", "G/G₀", "beam theory", "difference", "G closed form", "error",
                  "contact", "slip", "stick", "Tresca problems", "wall time"],
                 [[f"{row['a'] / ARM:g}", f"{row['mu']:g}", f"{row['unknowns']:,}", f"{row['G_II']:.6e}",
                   f"{row['ratio']:.5f}", f"{row['estimate']:.5f}", f"{row['ratio'] - row['estimate']:+.5f}",
                   f"{row['theory']:.6e}", percent(row["G"] / row["theory"] - 1.0), row["contact"], row["slip"],
                   row["stick"], str(row["coulomb_iterations"] or ""), f"{row['seconds']:.1f} s"] for row in rows])


# --- the cohesive bond -------------------------------------------------------------------------------------
#: The bilinear DCB of experiments/cohesive.py: (strength / E, mesh.size) of every run, the acceptance case
#: first (its mesh cohesive.SIZE), the strength sweep on its mesh, the mesh study on a coarser one (σ_c = 0.01 E
#: on size 0.25 fails: its zone is one Σ spacing, a vertex snaps and Newton finds no state); the sweep's mesh.
BOND_RUNS = ((0.005, 0.1), (0.0025, 0.1), (0.01, 0.1), (0.005, 0.25))
BOND_SWEEP_SIZE = 0.1
#: The bond with no initial crack's mesh (its growth takes many short steps).
OPENED_SIZE = 0.25
#: The openings the runs reach: the acceptance run's (Griffith's too) in steps of at most 0.01, the others' (the
#: crack grows from ≈ 0.12) in steps of at most 0.02; the growth halves them where damage moves fast.
BOND_LIMIT, SWEEP_LIMIT, SWEEP_STEPS = 0.2, 0.16, 8
#: The acceptance: the load within 1 % of the linear curve before damage, 3 % of Griffith's once grown.
BEFORE_DAMAGE, ONCE_GROWN = 0.01, 0.03


def run_name(strength: float, size: float) -> str:
    return f"strength {strength:g} E, size {size:g}"


def tips(cracks: np.ndarray, start: float) -> np.ndarray:
    """The crack tip (the last broken vertex) per step of a growth file's ``cracks``, ``start`` while none."""
    ends = np.where(np.isfinite(cracks[:, :, 1]), cracks[:, :, 1], start)
    return np.maximum(ends.max(axis=1), start)


def bond_speed(run: dict) -> dict:
    """A growth run's steps, Newton steps (linear problems on Σ) and block solves per step, and its wall time."""
    newton, solves = np.asarray(run["newton"]), np.asarray(run["solves"])
    return {"steps": len(solves) - 1, "newton_mean": float(newton[1:].mean()), "newton_max": int(newton.max()),
            "solves_mean": float(solves[1:].mean()), "seconds": float(run["seconds"]), "unknowns": int(run["unknowns"])}


def measure_opened(griffith: dict) -> dict:
    """The bond with no initial crack (the end faces' outer halves opened) on the sweep's mesh: its curve, tip,
    process zone, where damage starts and the first vertex breaks, and its load once the tip passes the other
    runs' initial crack against Griffith's branch there (the stable branch does not depend on the initial crack)."""
    run = cohesive.bond_run(OPENED_SIZE, cohesive.STRENGTH, 0.0, SWEEP_LIMIT, SWEEP_STEPS)
    tip, load, opening = tips(run["cracks"], 0.0), run["load"], run["displacement"]
    damaged, broken = run["damage"].max(axis=1) > 0.0, tip > 0.0
    beyond = tip > cohesive.CRACK + 1e-9
    expected = np.array([cohesive.griffith_load(d, griffith) for d in opening])
    return {"opening": opening.tolist(), "load": load.tolist(), "tip": tip.tolist(), "griffith": expected.tolist(),
            "process_zone": run["process_zone"].tolist(), "newton": run["bond_solves"].tolist(),
            "solves": run["solves"].tolist(), "seconds": run["seconds"], "unknowns": run["unknowns"],
            "damage_starts": float(opening[np.argmax(damaged)]), "breaks": float(opening[np.argmax(broken)]),
            "peak": float(load.max()), "peak_opening": float(opening[np.argmax(load)]),
            "beyond": float(np.nanmax(np.abs(load[beyond] / expected[beyond] - 1.0), initial=np.nan)),
            "zone": float(np.median(run["process_zone"][beyond])) if beyond.any() else np.nan}


def measure_cohesive() -> dict:
    """Griffith's growth on every mesh, the bilinear DCB at every (strength, size) of BOND_RUNS against it, and
    the bond with no initial crack."""
    sizes = sorted({OPENED_SIZE, *(size for _, size in BOND_RUNS)})
    griffith = {size: cohesive.griffith_run(size, BOND_LIMIT) for size in sizes}
    runs = {}
    for strength, size in BOND_RUNS:
        limit, steps = (BOND_LIMIT, 20) if (strength, size) == BOND_RUNS[0] else (SWEEP_LIMIT, SWEEP_STEPS)
        run = cohesive.dcb_growth(limit, steps, size, strength * cohesive.MODULUS, griffith[size])
        runs[run_name(strength, size)] = {"strength": strength, "size": size, **run}
        print(f"interface: cohesive DCB, {run_name(strength, size)}: before damage {run['before_damage']:.3%}, "
              f"once grown {run['grown']:.3%}, {run['seconds']:.0f} s", flush=True)
    opened = measure_opened(griffith[OPENED_SIZE])
    curves = {f"size {size:g}": {"opening": g["displacement"].tolist(), "load": g["load"].tolist(),
                                 "solves": g["solves"].tolist(), "seconds": g["seconds"], "unknowns": g["unknowns"],
                                 "tip": tips(g["cracks"], cohesive.CRACK).tolist(),
                                 "size": size} for size, g in griffith.items()}
    return {"runs": runs, "griffith": curves, "opened": opened,
            "commit": str(griffith[sizes[0]]["attrs"].get("git_commit", "unknown"))}


# --- the cohesive bond: closed-form estimates and what the page reads of a run -----------------------------
def arm_modulus() -> float:
    return plane_strain_modulus(cohesive.MODULUS, cohesive.POISSON)


def hillerborg_length(strength: float) -> float:
    """Hillerborg's characteristic length E′G_c/σ_c² (E′ the arms' plane-strain modulus)."""
    return arm_modulus() * cohesive.TOUGHNESS / strength ** 2


def slender_length(strength: float, h: float = ARM) -> float:
    """The slender arm's (beam on the bond's foundation) zone length (E′G_c/σ_c²)^¼ h^¾."""
    return hillerborg_length(strength) ** 0.25 * h ** 0.75


def whole_curve(run: dict) -> float:
    """The largest |P/P_Griffith − 1| over the whole run (the peak's rounding included)."""
    load, griffith = np.asarray(run["load"]), np.asarray(run["griffith"])
    return float(np.max(np.abs(load[griffith > 0] / griffith[griffith > 0] - 1.0)))


def zone(run: dict) -> float:
    """The process zone's median length once the crack grows."""
    grown = np.asarray(run["tip"]) > cohesive.CRACK + 1e-9
    return float(np.median(np.asarray(run["process_zone"])[grown]))


def acceptance(record: dict) -> dict:
    return record["runs"][run_name(*BOND_RUNS[0])]


def sweep(record: dict) -> list[dict]:
    return [run for run in record["runs"].values() if run["size"] == BOND_SWEEP_SIZE]


def mesh_study(record: dict) -> list[dict]:
    """The acceptance strength's runs, coarsest mesh first."""
    strength = BOND_RUNS[0][0]
    return sorted((run for run in record["runs"].values() if run["strength"] == strength), key=lambda r: -r["size"])


def zone_exponent(record: dict) -> float:
    """The slope of log(process zone) against log(strength) over the sweep (Hillerborg −2, slender arm −½)."""
    rows = sweep(record)
    return float(np.polyfit(np.log([row["strength"] for row in rows]), np.log([zone(row) for row in rows]), 1)[0])


def cohesive_summary(record: dict) -> list[dict]:
    run, opened = acceptance(record), record["opened"]
    out = [summary_row(f"cohesive DCB, strength {run['strength']:g} E, size {run['size']:g}: the load at δ = "
                       f"{run['opening'][-1]:g} (against Griffith growth; the error: the largest once grown)",
                       run["griffith"][-1], run["load"][-1], percent(run["grown"]),
                       {"unknowns": run["unknowns"], "method": "schur", "seconds": run["seconds"]})]
    out.append(summary_row(f"bond with no initial crack, size {OPENED_SIZE:g}: the load at δ = "
                           f"{opened['opening'][-1]:g} (against Griffith growth from the crack 4)",
                           opened["griffith"][-1], opened["load"][-1], percent(opened["beyond"]),
                           {"unknowns": opened["unknowns"], "method": "schur", "seconds": opened["seconds"]}))
    return out


def cohesive_plot(record: dict) -> None:
    """The load against the opening (the sweep and the acceptance run against Griffith's; the bond with no crack);
    the process zone against the strength with the two estimates; the peak load's change against the elements
    per process zone."""
    plt = _pyplot()
    fig, ((sweeps, opened), (zones, meshes)) = plt.subplots(2, 2, figsize=(12, 8.4), constrained_layout=True)
    coarse, fine = record["griffith"][f"size {OPENED_SIZE:g}"], record["griffith"][f"size {BOND_SWEEP_SIZE:g}"]
    sweeps.plot(fine["opening"], fine["load"], "k-", linewidth=2, label=f"Griffith growth, size {BOND_SWEEP_SIZE:g}")
    for index, run in enumerate(sweep(record)):
        sweeps.plot(run["opening"], run["load"], f"C{index}o-", markersize=3, linewidth=1,
                    label=f"bilinear, σ_c = {run['strength']:g} E, size {run['size']:g}")
    others = [run for run in record["runs"].values() if run["size"] != BOND_SWEEP_SIZE]
    for run in others:
        sweeps.plot(run["opening"], run["load"], "C3s", fillstyle="none", markersize=5,
                    label=f"bilinear, σ_c = {run['strength']:g} E, size {run['size']:g}")
    sweeps.set_title("DCB: the bilinear law meets Griffith's curve as the strength grows", fontsize=10)
    free = record["opened"]
    opened.plot(coarse["opening"], coarse["load"], "k-", label=f"Griffith growth from the crack 4, size {OPENED_SIZE:g}")
    opened.plot(free["opening"], free["load"], "C0o-", markersize=3, linewidth=1, label="bilinear, no initial crack")
    opened.set_ylim(0.0, 1.1 * max(free["load"]))
    twin = opened.twinx()
    twin.plot(free["opening"], free["tip"], "C1-", label="its crack tip (d = 1)")
    twin.set_ylabel("crack tip x")
    lines = opened.get_legend_handles_labels(), twin.get_legend_handles_labels()
    opened.legend(lines[0][0] + lines[1][0], lines[0][1] + lines[1][1], fontsize=8)
    opened.set_title("a bond with no initial crack opens from its end", fontsize=10)
    for ax in (sweeps, opened):
        ax.set_xlabel("opening δ")
        ax.set_ylabel("load P (per layer)")
        ax.grid(alpha=0.3)
    sweeps.legend(fontsize=7)
    swept = [strength for strength, _ in BOND_RUNS]
    strengths = np.geomspace(0.5 * min(swept), 2.0 * max(swept), 50)
    zones.loglog(strengths, [hillerborg_length(s * cohesive.MODULUS) for s in strengths], "k--",
                 label="E′G_c/σ_c² (Hillerborg)")
    zones.loglog(strengths, [slender_length(s * cohesive.MODULUS) for s in strengths], "k-",
                 label="(E′G_c/σ_c²)^¼ h^¾ (slender arm)")
    zones.loglog([r["strength"] for r in sweep(record)], [zone(r) for r in sweep(record)], "C0o", markersize=8,
                 label=f"ddsolve, size {BOND_SWEEP_SIZE:g}")
    zones.loglog([r["strength"] for r in others], [zone(r) for r in others], "C3s", markersize=8,
                 label="ddsolve, size " + ", ".join(sorted({f"{r['size']:g}" for r in others})))
    zones.set_xlabel("strength σ_c / E")
    zones.set_ylabel("process zone (0 < d < 1) once grown")
    zones.set_title(f"process zone against the strength: slope {zone_exponent(record):.2f}", fontsize=10)
    study = mesh_study(record)
    finest = max(study[-1]["load"])
    meshes.semilogy([zone(r) / r["size"] for r in study[:-1]], [abs(max(r["load"]) / finest - 1.0) for r in study[:-1]],
                    "C0o-", label=f"|peak / peak at size {study[-1]['size']:g} − 1|")
    meshes.semilogy([zone(r) / r["size"] for r in study], [r["grown"] for r in study], "C1s-",
                    label="largest |P/P_Griffith − 1| once grown")
    for r in study:
        meshes.annotate(f"size {r['size']:g}", (zone(r) / r["size"], r["grown"]), fontsize=8)
    meshes.set_xlabel("P2 elements per process zone")
    meshes.set_title(f"mesh convergence, σ_c = {study[-1]['strength']:g} E", fontsize=10)
    for ax in (zones, meshes):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.savefig(DOCS / "interface-cohesive.png", dpi=110)
    plt.close(fig)


def cohesive_page(record: dict) -> list[str]:
    run, rows = acceptance(record), list(record["runs"].values())
    verdict = "within" if run["before_damage"] <= BEFORE_DAMAGE and run["grown"] <= ONCE_GROWN else "NOT within"
    out = ["## The DCB with the bilinear law against Griffith growth", "",
           f"`experiments/cohesive.py`'s DCB ([growth.md](growth.md), *A damaging bond*): {cohesive.LENGTH:g} long, arms "
           f"h = {ARM:g}, initial crack {cohesive.CRACK:g}, clamped at the right end, two identical layers (E = "
           f"{cohesive.MODULUS:g}, ν = {cohesive.POISSON:g}, plane strain) opened by ±δ/2 on both arms' end faces to "
           f"δ = {BOND_LIMIT:g} in steps of at most 0.01 (the acceptance run; the others to {SWEEP_LIMIT:g} in steps "
           f"of at most {SWEEP_LIMIT / SWEEP_STEPS:g}, halved where damage moves fast), uniform P2 meshes; "
           "`[interface] law = \"bilinear\"` with toughness G_c = "
           f"{cohesive.TOUGHNESS:g} and the strength σ_c below, grown by `ddsolve grow` (one process, schur), against "
           "`ddsolve grow` of the same scene with the rigid bond and `[fracture] toughness = G_c` on the same mesh "
           "(Griffith's load at the bond's opening, interpolated along its run). *Before damage*: the largest "
           "deviation while no vertex is damaged; *once grown*: while the crack (d = 1) is beyond its start; *whole "
           "curve*: every step, the rounded peak included. As σ_c grows the process zone shrinks and the cohesive "
           "peak rises to Griffith's corner: the curves meet.", "",
           f"**The acceptance** (σ_c = {run['strength']:g} E, size {run['size']:g}): before damage "
           f"{run['before_damage']:.3%} (≤ {BEFORE_DAMAGE:.0%}), once grown {run['grown']:.2%} (≤ {ONCE_GROWN:.0%}): "
           f"{verdict} the acceptance; damage never falls between steps: {run['irreversible']}.", "",
           "![cohesive DCB](interface-cohesive.png)", ""]
    out += table(["σ_c / E", "mesh.size", "peak load", "Griffith's initiation load", "peak / initiation",
                  "before damage", "once grown", "whole curve", "tip at the end (Griffith's)", "steps"],
                 [[f"{r['strength']:g}", f"{r['size']:g}", f"{max(r['load']):.5e}", f"{initiation(record, r):.5e}",
                   f"{max(r['load']) / initiation(record, r):.4f}", before_damage(r), f"{r['grown']:.3%}",
                   f"{whole_curve(r):.2%}", f"{r['tip'][-1]:.3f} ({griffith_tip(record, r):.3f})", str(r["steps"])]
                  for r in rows])
    return out


def before_damage(run: dict) -> str:
    """The largest deviation before damage, or that the first step damages already."""
    value = run["before_damage"]
    return f"{value:.3%}" if np.isfinite(value) else "none: the first step damages"


def initiation(record: dict, run: dict) -> float:
    """Griffith's largest load (its initiation, at the corner of its curve) on the run's mesh."""
    return max(record["griffith"][f"size {run['size']:g}"]["load"])


def griffith_tip(record: dict, run: dict) -> float:
    """Griffith's crack tip on the run's mesh at the run's last opening."""
    griffith = record["griffith"][f"size {run['size']:g}"]
    return float(np.interp(run["opening"][-1], griffith["opening"], griffith["tip"]))


def process_zone_page(record: dict) -> list[str]:
    study = mesh_study(record)
    finest = study[-1]
    out = ["## The process-zone length", "",
           "The process zone is the length of Σ where 0 < d < 1 (the growth file's `process_zone`), its median over "
           "the steps once the crack grows. Two estimates, with E′ = E/(1 − ν²) of an arm "
           f"({arm_modulus():.1f}): **Hillerborg's** characteristic length l_ch = E′G_c/σ_c², the zone of a crack in "
           "a large body being M·l_ch with M of order one (M = 1 Hillerborg, 9π/32 ≈ 0.88 Rice; Harper and Hallett "
           "2008 collect them); and the **slender arm's**, a beam of thickness h on the bond as its foundation "
           "(Yang and Cox 2005, taken up by Harper and Hallett 2008 for the DCB): l = M (E′G_c/σ_c²)^¼ h^¾, again M "
           "of order one. The table gives the measured M against each; the slope of log(zone) against log(σ_c) "
           f"over the sweep is **{zone_exponent(record):.2f}**: Hillerborg's form falls as σ_c⁻², the slender "
           "arm's as σ_c^−½. The zone is measured on the Σ nodes (spacing size/2), so on the sweep's mesh it "
           "is known to ±1 spacing.", ""]
    out += table(["σ_c / E", "mesh.size", "process zone", "Σ node spacings", "l_ch = E′G_c/σ_c²", "zone / l_ch",
                  "(E′G_c/σ_c²)^¼ h^¾", "zone / slender estimate"],
                 [[f"{r['strength']:g}", f"{r['size']:g}", f"{zone(r):.4f}", f"{zone(r) / (r['size'] / 2):.1f}",
                   f"{hillerborg_length(strength):.4f}", f"{zone(r) / hillerborg_length(strength):.3f}",
                   f"{slender_length(strength):.4f}", f"{zone(r) / slender_length(strength):.3f}"]
                  for r in record["runs"].values() for strength in [r["strength"] * cohesive.MODULUS]])
    out += ["", f"**Mesh convergence** (σ_c = {finest['strength']:g} E): the peak load against the finest mesh's "
            f"(size {finest['size']:g}) and the load once grown against Griffith's on the same mesh, by the P2 "
            "elements per process zone:", ""]
    out += table(["mesh.size", "unknowns", "process zone", "P2 elements per zone", "peak load",
                  f"peak / peak at size {finest['size']:g} − 1", "before damage", "once grown", "steps"],
                 [[f"{r['size']:g}", f"{r['unknowns']:,}", f"{zone(r):.4f}", f"{zone(r) / r['size']:.1f}",
                   f"{max(r['load']):.6e}", percent(max(r["load"]) / max(finest["load"]) - 1.0),
                   before_damage(r), f"{r['grown']:.3%}", str(r["steps"])] for r in study])
    return out


def opened_page(record: dict) -> list[str]:
    free = record["opened"]
    return ["## A bond with no initial crack", "",
            f"The same DCB with no crack on Σ: the bond holds all of Σ and the law is the same (σ_c = "
            f"{cohesive.STRENGTH / cohesive.MODULUS:g} E); the arms' end faces would meet at Σ's glued end, so the "
            "outer halves of the end faces are opened by ±δ/2 (`experiments/cohesive.py`, `dcb_scene` with no "
            f"crack; mesh.size {OPENED_SIZE:g}). Damage starts at δ = {free['damage_starts']:.4g}, the first "
            f"vertex breaks (d = 1: the crack starts) at δ = {free['breaks']:.4g}; the peak load "
            f"{free['peak']:.4e} is at δ = {free['peak_opening']:.4g}, and the crack then runs stably under the "
            f"opening to x = {free['tip'][-1]:.3f} at δ = {free['opening'][-1]:g}. Once its tip passes x = "
            f"{cohesive.CRACK:g} its load is Griffith's of the DCB with the crack {cohesive.CRACK:g} (the stable "
            f"branch does not depend on the initial crack) within **{free['beyond']:.2%}**, the process zone "
            f"{free['zone']:.3f} long there. Its curve is the upper right picture above."]


def cohesive_speed_page(record: dict) -> list[str]:
    out = ["## Speed of the cohesive runs", "",
           "Every run is `ddsolve grow` in one process with schur (its blocks factored once per crack; a step is "
           "Newton's method on Σ, each Newton step a dense solve on rank 0, and the block solves that recover the "
           "displacements); wall time of the growth alone (the mesh apart), on two cores shared with other work, so "
           "the counts are what to compare. *Newton steps*: linear problems on Σ per step (the growth file's "
           "`bond_solves`); the steps include those the growth halved where damage moved fast.", ""]
    cases = [(f"bilinear, {name}", run) for name, run in record["runs"].items()]
    cases += [(f"bilinear, no initial crack, size {OPENED_SIZE:g}", record["opened"])]
    rows = [[case, f"{s['unknowns']:,}", str(s["steps"]), f"{s['newton_mean']:.1f}", str(s["newton_max"]),
             f"{s['solves_mean']:.1f}", f"{s['seconds']:.1f} s", f"{s['seconds'] / max(s['steps'], 1):.2f} s"]
            for case, run in cases for s in [bond_speed(run)]]
    rows += [[f"Griffith (rigid bond), {name}", f"{g['unknowns']:,}", str(len(g["solves"]) - 1), "", "",
              f"{np.mean(g['solves'][1:]):.1f}", f"{g['seconds']:.1f} s",
              f"{g['seconds'] / max(len(g['solves']) - 1, 1):.2f} s"] for name, g in record["griffith"].items()]
    out += table(["run", "unknowns", "steps", "Newton steps per step", "most in a step", "block solves per step",
                  "wall time", "per step"], rows)
    return out


def cohesive_text(record: dict) -> list[str]:
    return [*cohesive_page(record), "", *process_zone_page(record), "", *opened_page(record), "",
            *cohesive_speed_page(record)]


# --- the ENF with the cohesive law -------------------------------------------------------------------------
#: The ENF's bonds (experiments/cohesive.py, ``enf_scene``): σ_c / E, τ_c = cohesive.SHEAR_RATIO σ_c; the summary
#: row is the strongest's (0.01 E on this mesh: a zone of one Σ spacing, the steps halve without end).
ENF_STRENGTHS = (0.00125, 0.0025, 0.005)


def measure_enf_cohesive() -> dict:
    """Griffith's growth of the ENF (G_IIc) and the bilinear ENF at every strength of ENF_STRENGTHS against it."""
    griffith = cohesive.enf_griffith_run()
    runs = {}
    for strength in ENF_STRENGTHS:
        run = cohesive.enf_growth(strength=strength * cohesive.MODULUS, griffith=griffith)
        runs[f"{strength:g}"] = {"strength": strength, **run}
        print(f"interface: cohesive ENF, strength {strength:g} E: before damage {run['before_damage']:.3%}, once "
              f"grown {run['grown']:.3%}, {run['seconds']:.0f} s", flush=True)
    curve = {"opening": griffith["displacement"].tolist(), "load": griffith["load"].tolist(),
             "tip": tips(griffith["cracks"], cohesive.ENF_CRACK).tolist(), "solves": griffith["solves"].tolist(),
             "seconds": griffith["seconds"], "unknowns": griffith["unknowns"]}
    return {"runs": runs, "griffith": curve, "commit": str(griffith["attrs"].get("git_commit", "unknown"))}


def enf_cohesive_summary(record: dict) -> list[dict]:
    run = record["runs"][f"{ENF_STRENGTHS[-1]:g}"]
    return [summary_row(f"cohesive ENF, strength {run['strength']:g} E, size {cohesive.ENF_SIZE:g}: the load at "
                        f"δ = {run['opening'][-1]:g} (against Griffith growth; the error: the largest once grown)",
                        run["griffith"][-1], run["load"][-1], percent(run["grown"]),
                        {"unknowns": run["unknowns"], "method": "schur", "seconds": run["seconds"]})]


def enf_cohesive_plot(record: dict) -> None:
    """The load and the crack tip against the midspan deflection: Griffith's growth and the bond at each strength."""
    plt = _pyplot()
    fig, (loads, cracks) = plt.subplots(1, 2, figsize=(12, 4.6), constrained_layout=True)
    griffith = record["griffith"]
    for ax, key in ((loads, "load"), (cracks, "tip")):
        ax.plot(griffith["opening"], griffith[key], "k-", linewidth=2, label="Griffith growth, G_IIc")
        for index, run in enumerate(record["runs"].values()):
            shear = cohesive.SHEAR_RATIO * run["strength"]
            ax.plot(run["opening"], run[key], f"C{index}o-", markersize=3, linewidth=1,
                    label=f"bilinear, σ_c = {run['strength']:g} E, τ_c = {shear:.4g} E")
        ax.set_xlabel("midspan deflection δ")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    loads.set_ylabel("load P (both layers)")
    cracks.set_ylabel("crack tip x (d = 1)")
    cracks.axhline(cohesive.ENF_HALF_SPAN, color="0.5", linestyle=":")
    loads.set_title("ENF: the bilinear law under Benzeggagh–Kenane meets Griffith's curve as the strength grows",
                    fontsize=10)
    cracks.set_title(f"the crack tip (dotted: the loading nose at x = {cohesive.ENF_HALF_SPAN:g})", fontsize=10)
    fig.savefig(DOCS / "interface-enf-cohesive.png", dpi=110)
    plt.close(fig)


def griffith_corner(griffith: dict) -> tuple[float, float]:
    """The deflection and load of Griffith's initiation: its last step before the crack grows."""
    last = int(np.argmax(np.asarray(griffith["tip"]) > cohesive.ENF_CRACK + 1e-9)) - 1
    return griffith["opening"][last], griffith["load"][last]


def griffith_tip_at(griffith: dict, opening: float) -> float:
    return float(np.interp(opening, griffith["opening"], griffith["tip"]))


def grown_text(run: dict) -> str:
    """The largest deviation once the crack grows, or that it has not grown."""
    return f"{run['grown']:.2%}" if np.isfinite(run["grown"]) else f"no growth by δ = {run['opening'][-1]:g}"


def enf_cohesive_page(record: dict) -> list[str]:
    griffith = record["griffith"]
    corner, initiation = griffith_corner(griffith)
    out = ["## The ENF with the bilinear law against Griffith growth", "",
           f"Mode II: `experiments/cohesive.py`'s ENF, span 2L = {2 * cohesive.ENF_HALF_SPAN:g}, arms h = {ARM:g}, "
           f"initial crack (0, {cohesive.ENF_CRACK:g}) from the roller's end (a/L = "
           f"{cohesive.ENF_CRACK / cohesive.ENF_HALF_SPAN:g} > 0.69: beam theory's growth is stable under the "
           "deflection), a pin at the other end's Σ, two identical layers (E = "
           f"{cohesive.MODULUS:g}, ν = {cohesive.POISSON:g}, plane strain) bent at three points by a loading nose "
           f"{cohesive.NOSE:g} wide moved down by δ, to δ = {cohesive.ENF_LIMIT:g} in steps of at most "
           f"{cohesive.ENF_LIMIT / cohesive.ENF_STEPS:g} (halved where damage moves fast), uniform P2 mesh of size "
           f"{cohesive.ENF_SIZE:g}. `[interface] law = \"bilinear\"` with `mode_mix = \"benzeggagh-kenane\"`: "
           f"G_Ic = {cohesive.TOUGHNESS:g}, G_IIc = {cohesive.G_IIC:g}, η = {cohesive.ETA:g}, the strength σ_c below "
           f"and the shear strength τ_c = √(G_IIc/G_Ic) σ_c = {cohesive.SHEAR_RATIO:.4g} σ_c (both modes start to "
           "soften at one opening, Turon et al. 2007); against `ddsolve grow` of the same scene with the rigid bond "
           f"and `[fracture] toughness = G_IIc` on the same mesh ({len(griffith['opening']) - 1} steps; the crack "
           "grows in mode II, G_I ≈ 0). Griffith's load falls from its initiation as the crack runs to the nose, "
           "then rises as it passes it. *Before damage*: the largest deviation while no vertex is damaged; *once "
           "grown*: while the crack (d = 1) is beyond its start; *whole curve*: every step. The cohesive curve rounds "
           "Griffith's corner from below (its process zone softens the bond ahead of the tip before the crack "
           f"grows): *at the corner* is its load at Griffith's initiation deflection δ = {corner:.4g} over "
           "Griffith's initiation load, which rises to 1 as the strength grows.", "",
           "![cohesive ENF](interface-enf-cohesive.png)", ""]
    rows = []
    for run in record["runs"].values():
        speed = bond_speed(run)
        rows.append([f"{run['strength']:g}", f"{cohesive.SHEAR_RATIO * run['strength']:.4g}",
                     f"{np.interp(corner, run['opening'], run['load']) / initiation:.4f}", before_damage(run),
                     grown_text(run),
                     f"{whole_curve(run):.2%}",
                     f"{run['tip'][-1]:.2f} ({griffith_tip_at(griffith, run['opening'][-1]):.2f})",
                     str(run["steps"]), f"{speed['newton_mean']:.1f} ({speed['newton_max']})",
                     f"{speed['solves_mean']:.1f}", f"{speed['seconds']:.0f} s"])
    out += table(["σ_c / E", "τ_c / E", f"at the corner (Griffith's {initiation:.5e})",
                  "before damage", "once grown", "whole curve", "tip at the end (Griffith's)", "steps",
                  "Newton steps per step (most)", "block solves per step", "wall time"], rows)
    out += ["", f"Griffith's run: {len(griffith['opening']) - 1} steps, {griffith['unknowns']:,} unknowns, "
            f"{griffith['seconds']:.0f} s (one process, two cores shared with other work)."]
    return out


@dataclass(frozen=True)
class Section:
    """A part of the page: ``measure()`` solves its cases into a record; ``draw``, ``text`` (markdown lines) and
    ``summary`` (rows of the page's summary, :func:`summary_row`) read the record only."""
    name: str
    measure: Callable[[], dict]
    draw: Callable[[dict], None]
    text: Callable[[dict], list[str]]
    summary: Callable[[dict], list[dict]]


#: The page, in order.
SECTIONS = [Section("closed_crack", measure_closed_crack, closed_crack_plot, closed_crack_page, closed_crack_summary),
            Section("enf", measure_enf, enf_plot, enf_page, enf_summary),
            Section("cohesive", measure_cohesive, cohesive_plot, cohesive_text, cohesive_summary),
            Section("enf_cohesive", measure_enf_cohesive, enf_cohesive_plot, enf_cohesive_page, enf_cohesive_summary)]


def page(records: dict[str, dict], sections: list[Section] = SECTIONS) -> str:
    """docs/interface.md from the sections' records."""
    revision = next(iter(records.values()))["commit"][:10]
    summary = [row for section in sections for row in section.summary(records[section.name])]
    out = ["# Interface laws", "",
           "Laws on Σ beyond bonded-or-free, each against a closed form or Griffith's growth: friction on crack "
           "faces in contact ([fracture.md](fracture.md#friction-on-the-crack-faces) says how it is solved and how G "
           "takes it) and a cohesive bond on Σ ([growth.md](growth.md), *A damaging bond*). "
           f"Generated by `./run interface` ({revision}): every friction case is `./run solve -n {RANKS}` as a user "
           "runs it, the wall time the whole launch (start, mesh, solve, G, output), on graded P2 meshes; the "
           "cohesive runs are `ddsolve grow` in one process on uniform P2 meshes; plane strain. The code is "
           "experiments/interface.py; results/interface.h5 keeps every number of the tables.", "",
           "## Summary", ""]
    out += table(["case", "closed form", "ddsolve", "error", "unknowns", "method", "wall time"],
                 [[row["case"], f"{row['closed']:.6e}", f"{row['G']:.6e}", row["error"], f"{row['unknowns']:,}",
                   row["method"], f"{row['seconds']:.1f} s"] for row in summary])
    for section in sections:
        out += ["", *section.text(records[section.name])]
    return "\n".join(out) + "\n"


def interface() -> None:
    """Solve every section's cases, keep results/interface.h5, draw, write docs/interface.md."""
    RESULTS.mkdir(exist_ok=True)
    records = {section.name: section.measure() for section in SECTIONS}
    report.write_records(RESULTS / "interface.h5", [{"case": name, **record} for name, record in records.items()],
                         {"git_commit": next(iter(records.values()))["commit"]})
    for section in SECTIONS:
        section.draw(records[section.name])
    (DOCS / "interface.md").write_text(page(records))
