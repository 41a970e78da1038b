"""Interface laws against closed forms: ``./run interface`` writes docs/interface.md, docs/interface-*.png and
results/interface.h5.

The page is :data:`SECTIONS`, a list of :class:`Section`s: each measures its cases into a record, draws its pictures
from the record and writes its markdown and its rows of the summary table from it. Every case is ``./run solve`` on
:data:`RANKS` ranks with the default method, as a user runs it, timed around the launch. Friction on the crack faces:

- the closed crack under remote compression S and shear T (docs/closed-crack.toml), Coulomb and Tresca from no
  friction to stick, against the infinite plane's K_II = (T − g)√(πa), the finite square's excess measured at two
  sides and extrapolated;
- the ENF with friction between the arms against Euler beam theory with the friction fully developed at the mouth.
"""
from __future__ import annotations

import math
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from experiments import report, stacks
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
            Section("enf", measure_enf, enf_plot, enf_page, enf_summary)]


def page(records: dict[str, dict], sections: list[Section] = SECTIONS) -> str:
    """docs/interface.md from the sections' records."""
    revision = next(iter(records.values()))["commit"][:10]
    summary = [row for section in sections for row in section.summary(records[section.name])]
    out = ["# Interface laws", "",
           "Laws on Σ beyond bonded-or-free, each against a closed form: friction on crack faces in contact "
           "([fracture.md](fracture.md#friction-on-the-crack-faces) says how it is solved and how G takes it). "
           f"Generated by `./run interface` ({revision}): every case is `./run solve -n {RANKS}` as a user runs it, "
           "the wall time the whole launch (start, mesh, solve, G, output); graded P2 meshes, plane strain. The "
           "code is experiments/interface.py; results/interface.h5 keeps every number of the tables.", "",
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
