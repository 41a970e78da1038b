"""G along fronts of other shapes: ``./run three-d-shapes`` rewrites the shapes section of docs/three-d-front.md and
docs/three-d-dcb.png, docs/three-d-ellipse.png.

* A double cantilever beam across its width: the box [0, 10] × [−1, 1] × [0, W/2] (arms h = 1, Σ at mid-height),
  the crack a = 5 from the left end over the whole width, the right end clamped, a half model (rollers on z = 0,
  the specimen's mid-plane), the arms' left ends pulled apart by a shear traction 2y (a force 1 per unit width on
  each arm).  G(z) from the centre to the free edge, its width average against the plane-strain and plane-stress
  G of the same section (the plane reference) and corrected beam theory, and the width average from the energy
  of two crack lengths.
* An elliptical delamination, semi-axes a = ½ along x and b = ¼ along z, in the penny's quarter-model box
  (docs/three-d-front.md): G against Irwin's K_I(φ) = σ√(πb/a) (a² sin²φ + b² cos²φ)^¼ / E(k), k² = 1 − b²/a²,
  G = (1 − ν²) K_I² / E, φ the ellipse's parametric angle from the major axis.
* G under a temperature change: docs/three-d.md's scene extruded with rollers, the two materials' expansions and a
  ΔT varying in x, against the plane G of the same heated scene.
"""
from __future__ import annotations

import numpy as np
from scipy.special import ellipe

from experiments import report, three_d, three_d_front
from experiments.delamination import CHI_I, dcb, plane_strain_modulus
from ddsolve.mesh import geometry
from ddsolve.post import fracture, front
from ddsolve.problem.scene import loads
from ddsolve.solvers import reference as plane_reference

PAGE = three_d.DOCS / "three-d-front.md"
#: The DCB: length, arm thickness h, crack length a, E and ν; its 3-D runs (half width W/2, P2 mesh.size) and the
#: plane runs' mesh.size (graded P2); the crack lengths a ± DELTA whose energies give the width average.
LENGTH, ARM, CRACK, MODULUS, POISSON = 10.0, 1.0, 5.0, 1.0, 0.3
DCB_RUNS = ((1.0, 0.2), (1.0, 0.15), (2.0, 0.2))
PLANE_SIZE, DELTA = 0.05, 0.1
DCB = """
[geometry]
box = [0, {length}, -{arm}, {arm}{depth}]
{layers}
crack = [0, {crack}]
clamped = ["right"]
[mesh]
size = {size}
grading = {grading}
degree = 2
[materials]
model = "{model}"
[materials.layer1]
E = {E}
nu = {nu}
[loads.layer1.left]
y = "2*y"
{rollers}
"""
#: The heated extruded scene: its load case, the expansions (below, above Σ), the temperature change, the 3-D run
#: (mesh.size, degree).
HEAT = {"case": "opening", "alpha": (2e-5, 1e-5), "change": "100 + 50 * x", "run": (0.14, 2)}
#: The ellipse's semi-axes (x, z), its box's half-side and P2 mesh.size; θ's radii (inner, outer) set beside the
#: default ones: just under the front's smallest radius of curvature b²/a, where the default takes half of it.
ELLIPSE, ELLIPSE_BOX, ELLIPSE_SIZE = (0.5, 0.25), 2.0, 0.15
ELLIPSE_RADII = (0.06, 0.12)


def dcb_scene(size: float, half_width: float | None = None, model: str = "plane_strain", crack: float = CRACK):
    """The DCB in 3-D over z in [0, ``half_width``] (rollers on z = 0), or its plane section (``half_width`` None)
    in the plane ``model``."""
    solid_box = half_width is not None
    return loads(DCB.format(length=LENGTH, arm=ARM, crack=crack, depth=f", 0, {half_width}" if solid_box else "",
                            layers="" if solid_box else "layers = 1", size=size,
                            grading=three_d_front.GRADING if solid_box else "true", model=model, E=MODULUS,
                            nu=POISSON, rollers="[displacements.layer1.front]\nz = 0.0" if solid_box else ""))


def dcb_plane(model: str) -> float:
    """The plane G of the DCB's section in ``model`` (plane_strain or plane_stress) at graded P2."""
    scene = dcb_scene(PLANE_SIZE, model=model)
    return float(fracture.evaluate(plane_reference.solve_monolithic(scene, geometry.build(scene))).G[0])


def width_average(released) -> float:
    """The mean of G(z) over the front (trapezoids in z)."""
    order = np.argsort(released.points[:, 2])
    z, G = released.points[order, 2], released.G[order]
    return float(np.sum(0.5 * (G[1:] + G[:-1]) * np.diff(z)) / (z[-1] - z[0]))


def energy_average(half_width: float, size: float) -> float:
    """The width average of G from the energies Π of the crack lengths a ± DELTA: −ΔΠ / (2 DELTA × width)."""
    energies = [three_d_front.solved(dcb_scene(size, half_width, crack=CRACK + step))[0].energy
                for step in (-DELTA, DELTA)]
    return -(energies[1] - energies[0]) / (2.0 * DELTA * half_width)


def measure_dcb() -> dict:
    """The DCB's 3-D runs, its plane G in both models and corrected beam theory's."""
    runs = []
    for half_width, size in DCB_RUNS:
        result, released, unknowns, seconds = three_d_front.solved(dcb_scene(size, half_width))
        runs.append({"half": half_width, "size": size, "unknowns": unknowns, "seconds": seconds,
                     "released": released, "average": width_average(released)})
    beam = {"plane_strain": dcb(1.0, CRACK, ARM, plane_strain_modulus(MODULUS, POISSON), CHI_I),
            "plane_stress": dcb(1.0, CRACK, ARM, MODULUS, CHI_I)}
    return {"runs": runs, "plane": {model: dcb_plane(model) for model in beam}, "beam": beam,
            "energy": energy_average(*DCB_RUNS[0])}


def irwin(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The parametric angle φ (radians) of front ``points`` on the ellipse and Irwin's G there (σ = E = 1)."""
    a, b = ELLIPSE
    phi = np.arctan2(points[:, 2] / b, points[:, 0] / a)
    K = np.sqrt(np.pi * b / a) / ellipe(1.0 - (b / a) ** 2) * (a * a * np.sin(phi) ** 2
                                                              + b * b * np.cos(phi) ** 2) ** 0.25
    return phi, (1.0 - POISSON ** 2) * K ** 2


def measure_ellipse() -> dict:
    """The quarter ellipse in the penny's box: G along its front with θ's default radii and ELLIPSE_RADII, and
    Irwin's."""
    scene = loads(three_d_front.PENNY.replace("radii = [0.5, 0.5]", f"radii = [{ELLIPSE[0]}, {ELLIPSE[1]}]").format(
        L=ELLIPSE_BOX, size=ELLIPSE_SIZE, grading=three_d_front.GRADING)).with_({"mesh.degree": 2})
    result, released, unknowns, seconds = three_d_front.solved(scene)
    wider = front.release(result, *ELLIPSE_RADII)
    phi, closed_form = irwin(released.points)
    return {"released": {"default": released, "chosen": wider}, "phi": phi, "irwin": closed_form,
            "unknowns": unknowns, "seconds": seconds}


def dcb_text(measured: dict) -> list[str]:
    """The DCB's table and what it shows."""
    plane, beam, runs = measured["plane"], measured["beam"], measured["runs"]
    lines = ["## A double cantilever beam across its width", "",
             f"The box [0, {LENGTH:g}] × [−{ARM:g}, {ARM:g}] × [0, W/2] (arms h = {ARM:g}, Σ at mid-height), the crack "
             f"a = {CRACK:g} from the left end over the whole width, the right end clamped, a half model (rollers on "
             f"z = 0, the specimen's mid-plane), E = {MODULUS:g}, ν = {POISSON:g}, the arms' left ends pulled apart "
             "by the shear traction 2y (a force P = 1 per unit width on each arm), graded P2.  The plane G of the "
             f"same section (graded P2, mesh.size {PLANE_SIZE:g}): {plane['plane_strain']:.2f} in plane strain, "
             f"{plane['plane_stress']:.2f} in plane stress; corrected beam theory G = 12P²(a + χh)²/(E′h³) with "
             f"χ = {CHI_I} (docs/delamination.md): {beam['plane_strain']:.2f} (E′ = E/(1 − ν²)) and "
             f"{beam['plane_stress']:.2f} (E′ = E).  Centre: z = 0; edge: z = W/2.", "",
             "| W / h | mesh.size | unknowns | front nodes | G centre | G edge | width average | average / plane "
             "strain | average / plane stress | seconds |", "|---|---|---|---|---|---|---|---|---|---|"]
    for run in runs:
        f = run["released"]
        order = np.argsort(f.points[:, 2])
        lines.append(f"| {2 * run['half'] / ARM:g} | {run['size']:g} | {run['unknowns']} | {len(f.G)} | "
                     f"{f.G[order[0]]:.2f} | {f.G[order[-1]]:.2f} | {run['average']:.2f} | "
                     f"{run['average'] / plane['plane_strain']:.4f} | {run['average'] / plane['plane_stress']:.4f} | "
                     f"{run['seconds']:.1f} |")
    narrow, wide = runs[0], runs[-1]
    centre = [run["released"].G[np.argmin(run["released"].points[:, 2])] for run in (narrow, wide)]
    lines += ["", f"The width average from the energies of a = {CRACK:g} ± {DELTA:g} (W/h = {2 * narrow['half']:g}, "
              f"mesh.size {narrow['size']:g}): {measured['energy']:.2f}, "
              f"{100 * (narrow['average'] / measured['energy'] - 1):+.2f} % from the G-θ average.  The finite "
              "sizes: corrected beam theory is "
              f"{100 * (beam['plane_strain'] / plane['plane_strain'] - 1):+.2f} % (plane strain) and "
              f"{100 * (beam['plane_stress'] / plane['plane_stress'] - 1):+.2f} % (plane stress) from the plane "
              "elasticity of this section: its χh takes the root rotation of the arms at the tip into account "
              f"(without it beam theory is {100 * ((CRACK / (CRACK + CHI_I * ARM)) ** 2 - 1):.1f} % low), and what "
              "is left is the clamp at the uncracked length 5h and the load's distribution over the end faces.  "
              "Across the width G is highest at the centre and falls towards the free edges, where the front meets "
              "a traction-free surface (there the singularity is weaker than the square root and the arm is in "
              f"plane stress).  From W/h = {2 * narrow['half']:g} to {2 * wide['half']:g} the width average "
              f"goes from {narrow['average'] / plane['plane_stress']:.3f} to "
              f"{wide['average'] / plane['plane_stress']:.3f} of the plane-stress G, towards plane strain; the "
              f"centre's G is {centre[0] / narrow['average']:.2f} and {centre[1] / wide['average']:.2f} "
              "times the average and the edge's falls from "
              f"{narrow['released'].G[np.argmax(narrow['released'].points[:, 2])]:.1f} to "
              f"{wide['released'].G[np.argmax(wide['released'].points[:, 2])]:.1f}: the arms' anticlastic bending (ν) "
              "concentrates the release in the front's middle.", "",
              "![G(z) across the DCB's width](three-d-dcb.png)", ""]
    return lines


def ellipse_text(measured: dict) -> list[str]:
    """The ellipse's numbers against Irwin's."""
    a, b = ELLIPSE
    released = measured["released"]
    rows = [(f"default: {released['default'].inner[0]:.3g}, {released['default'].outer[0]:.3g}", released["default"]),
            (f"{ELLIPSE_RADII[0]:g}, {ELLIPSE_RADII[1]:g}", released["chosen"])]
    return ["## An elliptical delamination", "",
            f"The crack `{{center = [0, 0], radii = [{a:g}, {b:g}]}}` (a quarter by symmetry, rollers on x = 0 and "
            f"z = 0) in the penny's box [0, {ELLIPSE_BOX:g}] × [−{ELLIPSE_BOX:g}, {ELLIPSE_BOX:g}] × "
            f"[0, {ELLIPSE_BOX:g}] under the unit traction on the top, one material (E = 1, ν = {POISSON:g}), P2 at "
            f"mesh.size {ELLIPSE_SIZE:g} graded ({measured['unknowns']} unknowns, {len(measured['phi'])} front "
            f"nodes, {measured['seconds']:.1f} s).  Irwin's closed form of the infinite body: G(φ) = (1 − ν²) K_I² / "
            "E, K_I = σ√(πb/a) (a² sin²φ + b² cos²φ)^¼ / E(k), k² = 1 − b²/a², φ the parametric angle from the "
            f"major axis: largest at the ends of the minor axis (φ = 90°: {measured['irwin'].max():.4f}), "
            f"smallest at the ends of the major one ({measured['irwin'].min():.4f}).  θ's radii: by default half "
            f"and a quarter of the front's smallest radius of curvature b²/a = {b * b / a:g} (at the major axis's "
            "end: θ's normals must not cross), a few elements at this mesh.size; set by `fracture.inner` and "
            "`fracture.outer` just under b²/a they take in more elements and the scatter from node to node "
            "falls:", "",
            "| θ radii (inner, outer) | mean G / Irwin | lowest | highest |", "|---|---|---|---|",
            *(f"| {label} | {(f.G / measured['irwin']).mean():.4f} | {(f.G / measured['irwin']).min():.4f} | "
              f"{(f.G / measured['irwin']).max():.4f} |" for label, f in rows), "",
            "The finite box: the penny of radius ½ in this box and mesh (the penny's table, P2 at mesh.size 0.15, "
            "L/a = 4) releases more than Sneddon's infinite body, mostly by the box (its share is measured above, "
            "from L/a = 4 to 6); the ellipse's major semi-axis is the penny's radius and its minor one half of "
            "it, so its box correction is at most the penny's, and G / Irwin above less that correction is the "
            "mesh's error.", "",
            "![G along the ellipse's front](three-d-ellipse.png)", ""]


def plot_dcb(measured: dict) -> None:
    """docs/three-d-dcb.png: G(z) of every run over z / (W/2), with the plane values."""
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    for run in measured["runs"]:
        f = run["released"]
        order = np.argsort(f.points[:, 2])
        ax.plot(f.points[order, 2] / run["half"], f.G[order], ".-",
                label=f"W/h = {2 * run['half'] / ARM:g}, P2 mesh.size {run['size']:g}")
    for model, style in (("plane_strain", "--"), ("plane_stress", ":")):
        ax.axhline(measured["plane"][model], color="k", ls=style, lw=0.9, label=model.replace("_", " ") + " (plane G)")
    ax.set_xlabel("z / (W/2): centre 0, free edge 1")
    ax.set_ylabel("G per unit length of front")
    ax.set_title("DCB across its width (half model)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(three_d.DOCS / "three-d-dcb.png", dpi=130)
    plt.close(fig)


def plot_ellipse(measured: dict) -> None:
    """docs/three-d-ellipse.png: G and Irwin's G against the parametric angle."""
    from ddsolve.post.plots import _pyplot

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    order = np.argsort(measured["phi"])
    angle = np.degrees(measured["phi"][order])
    for name, f in measured["released"].items():
        ax.plot(angle, f.G[order], ".-", label=f"P2, mesh.size {ELLIPSE_SIZE:g}, θ radii {f.inner[0]:.3g}, "
                f"{f.outer[0]:.3g}" + (" (default)" if name == "default" else ""))
    ax.plot(angle, measured["irwin"][order], "k-", lw=1, label="Irwin (infinite body)")
    ax.set_xlabel("parametric angle φ from the major axis (degrees)")
    ax.set_ylabel("G")
    ax.set_title(f"quarter elliptical crack, semi-axes {ELLIPSE[0]:g} (x) and {ELLIPSE[1]:g} (z)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.savefig(three_d.DOCS / "three-d-ellipse.png", dpi=130)
    plt.close(fig)


def heated(scene):
    """``scene`` (docs/three-d.md's, plane or extruded) with the two materials' expansions and HEAT."""
    lower, upper = HEAT["alpha"]
    text = scene.text.replace("nu = 0.28\n", f"nu = 0.28\nalpha = {lower!r}\n").replace(
        "nu = 0.32\n", f"nu = 0.32\nalpha = {upper!r}\n")
    return loads(text + f'\n[temperature]\nlayer1 = "{HEAT["change"]}"\n')


def measure_thermal() -> dict:
    """The heated extruded scene's G(z) against the heated plane G (plane strain, graded P2)."""
    plane_scene = heated(three_d.scene_of(HEAT["case"], PLANE_SIZE, 2, graded=True))
    plane = fracture.evaluate(plane_reference.solve_monolithic(plane_scene, geometry.build(plane_scene))).G
    size, degree = HEAT["run"]
    scene = heated(three_d.scene_of(HEAT["case"], size, 3)).with_({"mesh.grading": three_d_front.GRADING,
                                                                  "mesh.degree": degree})
    result, released, unknowns, seconds = three_d_front.solved(scene)
    return {"plane": plane, "closed": result.closed, "unknowns": unknowns, "seconds": seconds,
            "ratios": [three_d_front.interior_ratios(released, plane, tip) for tip in (0, 1)]}


def thermal_text(measured: dict) -> list[str]:
    """The heated extruded scene's table."""
    lower, upper = HEAT["alpha"]
    size, degree = HEAT["run"]
    return ["## G under a temperature change", "",
            "Under `temperature.layer1` the G-θ integral takes the eigenstrain ε₀ = α ΔT as the plane code does "
            "(ddsolve.post.fracture): σ = D (ε − ε₀), W = ½ σ:(ε − ε₀), and the term ∫ σ:(∂ε₀/∂x_k) θ_k dV of a "
            "temperature that varies in space (Shih, Moran and Nakamura 1986), ∇ΔT from ΔT at the nodes; it is "
            "the derivative of the discrete energy as the nodes move (tests/test_front.py, with a ΔT linear in x, "
            "y and z), and a free thermal expansion adds nothing to G.  Modes are split when the eigenstrain is "
            "its own mirror image about Σ (then it is all mode I).", "",
            f"docs/three-d.md's {HEAT['case']} scene extruded with rollers as above, heated by ΔT = "
            f"{HEAT['change']} with α = {lower:g} below Σ and {upper:g} above, against the plane-strain G of the same "
            f"heated scene at graded P2 (mesh.size {PLANE_SIZE:g}): "
            f"{measured['plane'][0]:.6e} at the left tip, {measured['plane'][1]:.6e} at the right.  P{degree} at "
            f"mesh.size {size:g}, grading {three_d_front.GRADING:g}: {measured['unknowns']} unknowns, "
            f"{measured['closed']} closed Σ vertices, {measured['seconds']:.1f} s.", "",
            "| front | mean G / G_plane | lowest | highest |", "|---|---|---|---|",
            *(f"| {side} | {ratios.mean():.4f} | {ratios.min():.4f} | {ratios.max():.4f} |"
              for side, ratios in zip(("left", "right"), measured["ratios"])), ""]


def summary(dcb_measured: dict, ellipse_measured: dict, thermal_measured: dict) -> list[str]:
    """The numbers the command prints: G at the DCB's centre and edge and its width average, the ellipse's and
    the heated scene's ratios."""
    plane = dcb_measured["plane"]
    lines = []
    for run in dcb_measured["runs"]:
        f = run["released"]
        order = np.argsort(f.points[:, 2])
        lines.append(f"DCB W/h = {2 * run['half'] / ARM:g}, P2 mesh.size {run['size']:g}: G centre "
                     f"{f.G[order[0]]:.2f}, edge {f.G[order[-1]]:.2f}, width average {run['average']:.2f} "
                     f"({run['average'] / plane['plane_strain']:.4f} of plane strain, "
                     f"{run['average'] / plane['plane_stress']:.4f} of plane stress)")
    ratios = [(f"ellipse, θ radii {name}", f.G / ellipse_measured["irwin"], "Irwin")
              for name, f in ellipse_measured["released"].items()]
    ratios += [(f"heated extruded scene, {side} front", values, "the plane G")
               for side, values in zip(("left", "right"), thermal_measured["ratios"])]
    return lines + [f"{what}: G / {against} mean {values.mean():.4f}, from {values.min():.4f} to {values.max():.4f}"
                    for what, values, against in ratios]


def three_d_shapes() -> None:
    """Measure, and rewrite docs/three-d-front.md's shapes section and its pictures."""
    dcb_measured, ellipse_measured, thermal_measured = measure_dcb(), measure_ellipse(), measure_thermal()
    plot_dcb(dcb_measured)
    plot_ellipse(ellipse_measured)
    report.section(PAGE, "shapes", "\n".join(dcb_text(dcb_measured) + ellipse_text(ellipse_measured)
                                             + thermal_text(thermal_measured)))
    print("\n".join(summary(dcb_measured, ellipse_measured, thermal_measured)))
