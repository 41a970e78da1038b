"""The Griffith interface crack between two materials against its closed form (Rice and Sih 1965; Hutchinson
and Suo 1992).

``python -m experiments.interface_crack`` solves each case with the monolithic reference in this process and
prints G, ε and ψ beside the closed form.  A crack of length 2a on the interface of an infinite body, material 1
above (E₁ = ratio × E₂, equal ν), under remote tension σ:

    K = σ (1 + 2iε) √(πa) (2a)^{−iε},   G = (1/Ē₁ + 1/Ē₂)(1 + 4ε²) πaσ² / (2 cosh²πε),   ψ(l = 2a) = atan 2ε.

The model is the half x ≥ 0 (a roller on the symmetry plane x = 0 through the crack's centre), the box
(0, W) × (−W, W) with W = 80a, the crack [0, a] on Σ: y = 0.  Every layer carries the same materials (the
pair in every layer) and the same loads, so they move as one and the structure is LAYERS identical sheets: G
is LAYERS times the one-sheet value, K that of the summed sheet, ε and ψ the sheet's; the body is posed with
one layer (``geometry.layers = 1``), LAYERS = 1.  The remote state of the closed
form is uniform in each material with equal strains along the interface: besides σ_yy = σ on the top and
bottom, the upper material carries σ_xx = ν′σ(1 − Ē₁/Ē₂) on the far side (ν′ = ν/(1 − ν), plane strain),
which leaves the crack's loading unchanged; without it the free far side bends the strip and the crack line
sees a smaller opening stress (G 11 % low for the ratio 10, independent of W: the mismatch's field scales with
the box).  The finite width then changes G by about (πa/2W)²/4 ≈ 10⁻⁴ (Feddersen's √sec(πa/2W)): no correction
is applied.
"""
from __future__ import annotations

import math

import numpy as np

#: The half box's width (and half height) in crack half-lengths, the remote tension, Poisson's ratio.
WIDTH = 80.0
TENSION = 1e-3
NU = 0.3
#: Smooth step of the upper material's side traction (its width, 1/STEEPNESS, far below the elements there).
STEEPNESS = 1000.0
#: The sheets the body is posed as: one layer (``geometry.layers = 1``), the closed form's single body.
LAYERS = 1


def closed_form(ratio: float, a: float = 1.0, layers: int = LAYERS) -> dict[str, float]:
    """ε, G (summed over ``layers`` sheets) and ψ at l = 2a of the Griffith interface crack, material 1 above
    ``ratio`` × stiffer."""
    moduli = [ratio / (1.0 - NU * NU), 1.0 / (1.0 - NU * NU)]
    shear, kappa = [ratio / (2.0 * (1.0 + NU)), 1.0 / (2.0 * (1.0 + NU))], 3.0 - 4.0 * NU
    epsilon = math.log((kappa / shear[0] + 1.0 / shear[1]) / (kappa / shear[1] + 1.0 / shear[0])) / (2.0 * math.pi)
    one_sheet = ((1.0 / moduli[0] + 1.0 / moduli[1]) * (1.0 + 4.0 * epsilon ** 2) * math.pi * a * TENSION ** 2
                 / (2.0 * math.cosh(math.pi * epsilon) ** 2))
    return {"epsilon": epsilon, "G": layers * one_sheet, "phase": math.degrees(math.atan(2.0 * epsilon))}


def scene_text(ratio: float, size: float, width: float = WIDTH, a: float = 1.0, degree: int = 2,
               layers: int = LAYERS) -> str:
    """The half model's scene: the graded mesh of largest element ``size``, each of the ``layers`` the pair
    (``geometry.layers`` written where it is not the default two)."""
    side = TENSION * NU / (1.0 - NU) * (1.0 - ratio)  # the upper material's σ_xx: equal strains along Σ
    tables = []
    for layer in (f"layer{k}" for k in range(1, layers + 1)):
        tables.append(f"""[materials.{layer}]
E = 1.0
nu = {NU}
[materials.{layer}.upper]
E = {ratio!r}
nu = {NU}
[loads.{layer}.top]
y = {TENSION!r}
[loads.{layer}.bottom]
y = {-TENSION!r}
[loads.{layer}.right]
x = "{side!r}/(1 + exp({-STEEPNESS!r}*y))"
[displacements.{layer}.left]
x = 0.0
[displacements.{layer}.pin]
point = [{width!r}, {-width!r}]
y = 0.0
""")
    count = "" if layers == 2 else f"layers = {layers}\n"
    return f"""title = "Griffith interface crack, half model, E1/E2 = {ratio:g}"
[geometry]
box = [0.0, {width!r}, {-width!r}, {width!r}]
sigma = 0.0
crack = [0.0, {a!r}]
clamped = []
{count}[mesh]
size = {size!r}
degree = {degree}
grading = true
""" + "".join(tables)


def griffith(ratio: float, size: float, width: float = WIDTH, layers: int = LAYERS) -> dict[str, float]:
    """The solved half model against :func:`closed_form`: G, ε, ψ at l = 2a, G from |K| (the interaction
    integral's, against the domain integral's G; NaN for one material, whose ψ is the classical split's), the
    tip's Σ spacing and the unknowns."""
    from ddsolve.mesh import geometry
    from ddsolve.post import interface_crack
    from ddsolve.problem import scene
    from ddsolve.solvers import reference

    source = scene.loads(scene_text(ratio, size, width, layers=layers))
    result = reference.solve_monolithic(source, geometry.build(source))
    fracture, exact = result.fracture, closed_form(ratio, layers=layers)
    K, epsilon, pair = complex(*fracture.K[0]), float(fracture.epsilon[0]), interface_crack.interface_pair(source)
    if pair is None:
        phase, G_of_K = float(fracture.phase[0]), math.nan
    else:
        phase = interface_crack.phase(K, epsilon, 2.0)
        G_of_K = float(interface_crack.release(np.array([K]), epsilon, pair)[0])
    return {"ratio": ratio, "size": size, "width": width, "G": float(fracture.G[0]), "theory": exact["G"],
            "error": float(fracture.G[0]) / exact["G"] - 1.0, "epsilon": epsilon, "epsilon_theory": exact["epsilon"],
            "phase": phase, "phase_theory": exact["phase"], "G_of_K": G_of_K, "spacing": float(fracture.spacing[0]),
            "unknowns": result.unknowns}


def main() -> None:
    for ratio in (10.0, 100.0):
        for size, width in ((4.0, WIDTH), (2.0, WIDTH), (1.0, WIDTH), (1.0, WIDTH / 2.0)):
            row = griffith(ratio, size, width)
            print(f"E1/E2 = {ratio:g}, W = {width:g}a, size {size:g} (tip spacing {row['spacing']:.4g}, "
                  f"{row['unknowns']} unknowns): G {row['G']:.6e}, closed form {row['theory']:.6e} "
                  f"({row['error']:+.3%}); G from |K| {row['G_of_K'] / row['G'] - 1.0:+.1e} off G; "
                  f"ε {row['epsilon']:.6f} ({row['epsilon_theory']:.6f}); ψ(2a) {row['phase']:.3f}°, atan 2ε "
                  f"{row['phase_theory']:.3f}° ({row['phase'] - row['phase_theory']:+.3f}°)", flush=True)


if __name__ == "__main__":
    main()
