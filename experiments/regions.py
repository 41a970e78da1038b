"""A material per region against beam theory: a bi-material DCB and a thermal bilayer (Timoshenko's bimetal).

``python -m experiments.regions`` solves both with the monolithic reference in this process and prints
each number beside its closed form.  Both layers carry the same materials in each region (the arm above Σ
stiff, the one below soft; the strip above Σ expanding more than the one below), so the two layers move as
one and each structure is a one-body bi-material strip (docs/usage.md, "A material per region").

- The DCB: the strip (0, 20) × (−h, h), h = 1, cracked along Σ over (0, a), clamped at x = 20.  Beam theory
  with each arm's own stiffness (plane strain, per unit width, summed over the layers): G = M²/2 ·
  (1/(E′I)₊ + 1/(E′I)₋) with M the moment at the tip.  Loaded by couples M on the arms' ends this is exact
  once the tip's field is steady (a/h ≳ 3: the energy ahead of and behind the tip of a long crack), and it is
  the acceptance check.  Loaded by forces P, M = P (a + χh) needs the crack-tip correction χ, which
  ddsolve's homogeneous DCB has as χ = 0.677 (:data:`experiments.delamination.CHI_I`); between arms of
  different stiffness that value does not carry over (Kanninen's elastic-foundation model keeps χ = 6^(−1/4)
  for equally thick arms of any moduli, but the soft arm bonded to a stiff one is held more firmly at its
  root than by a symmetry plane): the force-loaded rows print the χ the computed G implies.
- The thermal bilayer: the same strip uncracked, half of a free strip of length 40 (x = 0 a symmetry
  plane, one point held in y), heated uniformly by ΔT.  Timoshenko (1925) for equal thicknesses, plane
  strain (α → (1 + ν)α, E → E/(1 − ν²)): κ = 24 Δα ΔT / (H (12 + (1 + n)²/n)), H = 2h the whole
  thickness, n = E₋′/E₊′.  The curvature is measured by a least-squares fit w = w₀ + κx²/2 of Σ's
  deflection over 0 ≤ x ≤ 20 − 3H (away from the free end, where the stresses are not those of a beam).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from experiments.delamination import ARM, CHI_I, LENGTH, LOAD, PIN, plane_strain_modulus, strip_geo

#: The regions' materials (E, ν) of the DCB: the arm above Σ ten times stiffer than the one below.
DCB_REGIONS = {"upper": (200.0, 0.28), "lower": (20.0, 0.28)}
#: The regions' materials (E, ν, α) of the thermal bilayer, and its temperature change.
BIMETAL_REGIONS = {"upper": (70.0, 0.3, 2.3e-5), "lower": (200.0, 0.3, 1.2e-5)}
HEATING = 100.0
#: The couple on each arm's end (summed over the layers) of the moment-loaded DCB.
MOMENT = 1e-2


def bilayer_dcb(load: float, a: float | None, h: float, moduli: dict[str, float], chi: float = CHI_I) -> float:
    """G of a DCB whose arms (thickness h, plane-strain moduli ``moduli`` by region, summed over the layers)
    are bent apart by the moment M at the tip: M² / 2 · Σ 12/(E′h³).  ``a`` None: ``load`` is the couple M on
    each arm's end (exact beam theory, the tip's field steady); else the force P on each arm's end at the
    crack length ``a``, M = P (a + χh) (corrected beam theory)."""
    moment = load if a is None else load * (a + chi * h)
    return 0.5 * moment * moment * sum(12.0 / (modulus * h ** 3) for modulus in moduli.values())


def bimetal_curvature(regions: dict[str, tuple[float, float, float]], dT: float, h: float) -> float:
    """Timoshenko's curvature w″ of two strips of thickness h each (plane strain), the upper one expanding by
    (1 + ν₊)α₊ΔT, the lower by (1 + ν₋)α₋ΔT: negative when the upper one expands more (the strip arches up)."""
    (E_up, nu_up, alpha_up), (E_low, nu_low, alpha_low) = regions["upper"], regions["lower"]
    n = plane_strain_modulus(E_low, nu_low) / plane_strain_modulus(E_up, nu_up)
    mismatch = ((1.0 + nu_up) * alpha_up - (1.0 + nu_low) * alpha_low) * dT
    return -24.0 * mismatch / (2.0 * h * (12.0 + (1.0 + n) ** 2 / n))


def region_materials(regions: dict[str, tuple]) -> str:
    """Both layers' materials: the upper region's as the layer's, the lower region's overriding it."""
    keys = ("E", "nu", "alpha")
    return "".join(f"[materials.{layer}{'' if region == 'upper' else '.lower'}]\n"
                   + "".join(f"{key} = {value!r}\n" for key, value in zip(keys, values))
                   for layer in ("layer1", "layer2") for region, values in regions.items())


def dcb_scene(folder: Path, a: float, size: float, degree: int = 2, loading: str = "moment",
              length: float = LENGTH):
    """The bi-material DCB's scene (its .toml and .geo written into ``folder``), the strip ``length`` long: the
    arms' end faces bent apart by couples MOMENT (``moment``: σxx linear across each face) or pulled apart by
    forces LOAD (``force``), half on each layer."""
    from ddsolve.problem import scene

    (folder / "dcb.geo").write_text(strip_geo(length, ARM, [(0.0, a)], {"clamped": [("right", -ARM, ARM)]}))
    if loading == "moment":
        slope = 12.0 * 0.5 * MOMENT / ARM ** 3  # σxx = slope (y − centre) on a layer's end face: M/2 about it
        parts = {"upper": f'x = "{slope!r} * (y - {0.5 * ARM!r})"', "lower": f'x = "{-slope!r} * (y + {0.5 * ARM!r})"'}
    else:
        parts = {"upper": f"y = {LOAD / (2.0 * ARM)!r}", "lower": f"y = {-LOAD / (2.0 * ARM)!r}"}
    loads = "".join(f"[loads.{layer}.left_{side}]\n{part}\n" for layer in ("layer1", "layer2")
                    for side, part in parts.items())
    text = (f'title = "bi-material DCB, a = {a:g}, {loading} loading"\n[mesh]\nfile = "dcb.geo"\nsize = {size!r}\n'
            f"degree = {degree}\ngrading = true\n{region_materials(DCB_REGIONS)}{loads}")
    (folder / "dcb.toml").write_text(text)
    return scene.loads(text, origin="bi-material DCB", base=folder)


def bimetal_scene(folder: Path, size: float, degree: int = 2, crack: float = 0.0):
    """The thermal bilayer's scene (its .toml and .geo written into ``folder``): x = 0 a symmetry plane, the
    point (0, 0) held in y; ``crack`` > 0: Σ cracked over that length from the free end x = LENGTH."""
    from ddsolve.problem import scene

    cracks = [(LENGTH - crack, LENGTH)] if crack > 0.0 else []
    (folder / "bimetal.geo").write_text(strip_geo(LENGTH, ARM, cracks, {"pin": [("left", -0.2 * PIN, 0.2 * PIN)]}))
    supports = "".join(f"[displacements.{layer}.{name}]\nx = 0.0\n{extra}" for layer in ("layer1", "layer2")
                       for name, extra in (("left_lower", ""), ("left_upper", ""), ("pin", "y = 0.0\n")))
    text = (f'title = "thermal bilayer"\n[mesh]\nfile = "bimetal.geo"\nsize = {size!r}\ndegree = {degree}\n'
            f"{region_materials(BIMETAL_REGIONS)}[temperature]\nlayer1 = {HEATING!r}\nlayer2 = {HEATING!r}\n{supports}")
    (folder / "bimetal.toml").write_text(text)
    return scene.loads(text, origin="thermal bilayer", base=folder)


def solved(source):
    """The scene solved by the monolithic reference on its mesh."""
    from ddsolve.mesh import geometry
    from ddsolve.solvers import reference

    return reference.solve_monolithic(source, geometry.build(source))


def dcb(a: float, size: float, degree: int = 2, loading: str = "moment", length: float = LENGTH,
        chi: float = CHI_I) -> dict:
    """G of the bi-material DCB at crack length ``a`` against beam theory (``moment`` loading: exact; ``force``:
    corrected with the tip correction ``chi``), the crack's opening at its mouth (positive: the arms open), the
    G_I reported and the interface crack's ε and ψ (at the scene's reference length, docs/fracture.md)."""
    with tempfile.TemporaryDirectory() as folder:
        result = solved(dcb_scene(Path(folder), a, size, degree, loading, length))
    moduli = {region: 2.0 * plane_strain_modulus(E, nu) for region, (E, nu) in DCB_REGIONS.items()}
    theory = bilayer_dcb(MOMENT, None, ARM, moduli) if loading == "moment" else bilayer_dcb(LOAD, a, ARM, moduli, chi)
    G = float(result.fracture.G[0])
    mouth = np.argmin(result.lower.points[result.lower.sigma, 0])
    opening = float(result.solution["u_plus"][result.upper.sigma[mouth], 1]
                    - result.solution["u_minus"][result.lower.sigma[mouth], 1])
    return {"a": a, "G": G, "theory": theory, "error": G / theory - 1.0, "opening": opening,
            "G_I": float(result.fracture.G_I[0]), "epsilon": float(result.fracture.epsilon[0]),
            "phase": float(result.fracture.phase[0]), "unknowns": result.unknowns}


def measured_curvature(result) -> float:
    """κ of a least-squares fit w = w₀ + κx²/2 of the deflection of Σ (layer 1's lower side) away from the
    free end x = LENGTH."""
    sigma = result.lower.sigma
    x, w = result.lower.points[sigma, 0], result.solution["u_minus"][sigma, 1]
    kept = x <= LENGTH - 6.0 * ARM
    fit = np.linalg.lstsq(np.column_stack([np.ones(kept.sum()), 0.5 * x[kept] ** 2]), w[kept], rcond=None)[0]
    return float(fit[1])


def bimetal(size: float, degree: int = 2) -> dict:
    """The thermal bilayer's curvature against Timoshenko's."""
    with tempfile.TemporaryDirectory() as folder:
        result = solved(bimetal_scene(Path(folder), size, degree))
    kappa, theory = measured_curvature(result), bimetal_curvature(BIMETAL_REGIONS, HEATING, ARM)
    return {"curvature": kappa, "theory": theory, "error": kappa / theory - 1.0, "unknowns": result.unknowns}


def implied_correction(row: dict) -> float:
    """The χ with which corrected beam theory would give the force-loaded DCB's G: G ∝ (a + χh)²."""
    return (row["a"] + CHI_I * ARM) * (1.0 + row["error"]) ** 0.5 / ARM - row["a"] / ARM


def main() -> None:
    for size in (0.2, 0.1):
        for loading in ("moment", "force"):
            for a in (6.0, 10.0):
                row = dcb(a, size, loading=loading)
                implied = f"; the χ it implies {implied_correction(row):.3f}" if loading == "force" else ""
                print(f"bi-material DCB, {loading} loading, size {size:g}, a = {a:g}: G {row['G']:.6e}, beam theory "
                      f"{row['theory']:.6e} ({row['error']:+.2%}){implied}; ε {row['epsilon']:.4f}, "
                      f"ψ {row['phase']:.2f}° at l = 1", flush=True)
        row = bimetal(size)
        print(f"thermal bilayer, size {size:g}: curvature {row['curvature']:.6e}, Timoshenko {row['theory']:.6e} "
              f"({row['error']:+.3%})", flush=True)


if __name__ == "__main__":
    main()
