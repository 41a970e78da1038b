"""Issue 40, class 4, measured for docs/robustness.md: structures whose exact displacement is zero.  The scenes
are made here (tests/test_round4_zero.py uses them too): the paper's square clamped on all four sides by
``[displacements]`` and heated (u ≡ 0, σxx = σyy = −EαΔT/(1 − 2ν) in plane strain), and the same square on
rollers with the pressure that cancels the expansion (u ≡ 0, the upper halves floating).  *Before* is what the
code before the fix did (measured once, quoted)."""
from __future__ import annotations

SIDES = ("left", "right", "top", "bottom")
LAYERS = ("layer1", "layer2")
#: (E, ν, α, ΔT) of each layer of the clamped plate: σ = −200 × 1e-5 × 100 / (1 − 0.6) = −0.5.
PAPER_LAYERS = ((200.0, 0.3, 1e-5, 100.0),) * 2
HEADER = """[geometry]
box = [-1.0, 1.0, -1.0, 1.0]
crack = {crack}
clamped = []
[mesh]
sigma_vertices = 13
boundary_vertices = 32
[materials]
model = "{model}"
"""


def _layers_and_heat(layers) -> str:
    text = "".join(f"[materials.{layer}]\nE = {modulus!r}\nnu = {poisson!r}\nalpha = {alpha!r}\n"
                   for layer, (modulus, poisson, alpha, _) in zip(LAYERS, layers))
    return text + "[temperature]\n" + "".join(f"{layer} = {change!r}\n" for layer, (*_, change) in zip(LAYERS, layers))


def clamped_plate(model: str = "plane_strain", layers=PAPER_LAYERS, crack: str = "[-0.5, 0.5]") -> str:
    """Scene text: ``layers`` as (E, ν, α, ΔT) of layer 1 and layer 2, each clamped on all four sides, on the
    P = 13, M = 32 mesh of the paper's square, with ``crack`` (TOML) on Σ."""
    return (HEADER.format(crack=crack, model=model) + _layers_and_heat(layers)
            + "".join(f"[displacements.{layer}.{side}]\nx = 0.0\ny = 0.0\n" for layer in LAYERS for side in SIDES))


#: (E, ν, α, ΔT) of the pressed plate's layers: the pressures −EαΔT/(1 − 2ν) are 0.5 and 1/3.
PRESSED_LAYERS = ((200.0, 0.3, 1e-5, 100.0), (100.0, 0.2, 2e-5, 100.0))


def pressed_plate() -> str:
    """Scene text: rollers on the left (x = 0) and the bottom (y = 0), on the right and top sides each layer's
    pressure EαΔT/(1 − 2ν) (plane strain), which holds its thermal expansion back: u ≡ 0 again."""
    rollers = "".join(f"[displacements.{layer}.{side}]\n{axis} = 0.0\n" for layer in LAYERS
                      for side, axis in (("left", "x"), ("bottom", "y")))
    pressures = "".join(f"[loads.{layer}.{side}]\npressure = {modulus * alpha * change / (1 - 2 * poisson)!r}\n"
                        for layer, (modulus, poisson, alpha, change) in zip(LAYERS, PRESSED_LAYERS)
                        for side in ("right", "top"))
    header = HEADER.format(crack="[-0.5, 0.5]", model="plane_strain")
    return header + _layers_and_heat(PRESSED_LAYERS) + rollers + pressures


CLASSES = {204: ("A structure whose exact displacement is zero is refused",
                 "the KKT check, every method's stopping rule (kkt's gap scale, uzawa's block energies, schur's "
                 "prediction check) and the reference's active set measure displacements against max |u| or 1e-2 × "
                 "the displacement the data would make (the prescribed values; Σ's length × the largest eigenstrain "
                 "or traction / modulus), whichever is larger, and every equilibrium residual against ‖K‖‖x‖ + ‖f‖ + "
                 "‖ℓ‖ instead of ‖K‖‖x‖ + ‖f + ℓ‖: where u ≡ 0, max |u|, the gaps and f + ℓ are all round-off")}


def measure(hostile) -> None:
    (hostile.folder / "clamped.toml").write_text(clamped_plate())
    (hostile.folder / "pressed.toml").write_text(pressed_plate())

    def observe(completed) -> str:
        """Converged or not, the largest stress error against −0.5 and max |u| of the result in z.h5."""
        from ddsolve.io import hdf5
        from ddsolve.post import analysis

        if completed.returncode not in (0, 3):
            return ""
        result = hdf5.read(hostile.folder / "z.h5")
        stress = max(float(abs(fields.stress[:, :2] + 0.5).max())
                     for fields in analysis.cell_fields(result).values())
        return (f"; converged = {str(result.converged).lower()}, |σ − (−EαΔT/(1 − 2ν))| ≤ {stress:.1e}, "
                f"max |u| {analysis.largest_displacement(result.solution.values()):.1e}")

    wrong = "the final solution violates"
    for method, extra, before in (
            ("auto", [], f"exit 3, 2.2 s: «schur: not converged: {wrong} penetration 1.64e+00, complementarity "
             "1.64e+00, gluing gap 7.77e-01 (scale-free tolerance 1e-06); the interface problem is too ill-conditioned "
             "for an exact solve: try solver.method = \"mprgp\"»"),
            ("mprgp", [], f"exit 3, 3.1 s: «mprgp: not converged: {wrong} complementarity 1.83e+00, gluing gap "
             "9.42e-01 (scale-free tolerance 1e-06); lower solver.tol»"),
            ("fista", [], "exit 3, 7.6 s: «fista: no convergence in 20000 iterations (criterion 9.581e-17, tol "
             "1.63402e-22)» (the final check had lowered its tol)"),
            ("feti", [], f"exit 3, 3.3 s: «feti: not converged: {wrong} penetration 1.85e+00, complementarity 1.85e+00, "
             "gluing gap 9.76e-01 (scale-free tolerance 1e-06); lower solver.tol»"),
            ("uzawa", ["solver.theta=auto"], "exit 4, 2.1 s: «uzawa diverged at iteration 273» (‖Δx‖/‖x‖² grew as "
             "x went to 0)"),
            ("uzawa", ["solver.theta=auto", "solver.stop=kkt"], f"exit 3, 3.1 s: «uzawa: not converged: {wrong} "
             "gluing gap 7.73e-01, complementarity 7.41e-03, penetration 7.29e-03 (scale-free tolerance 1e-06); lower "
             "solver.tol or solver.theta»")):
        settings = [item for value in (f"solver.method={method}", *extra) for item in ("--set", value)]
        label = f"plate clamped all round and heated, `{method}`" + "".join(f" `{value}`" for value in extra)
        hostile.case(204, label, before, ["solve", "-n", "2", "clamped.toml", *settings, "-o", "z.h5"],
                     kept=("z",), observe=observe)
    hostile.case(204, "the same plate, `reference`", "exit 3, 0.8 s: «reference: the solution violates equilibrium "
                 "1.49e-02 (scale-free tolerance 1e-09): the problem is too ill-conditioned for double precision»",
                 ["reference", "clamped.toml", "-o", "z.h5"], kept=("z",), observe=observe)
    hostile.case(204, "`check` of the reference's result", "exit 3: «KKT check failed: equilibrium 1.49e-02 above the "
                 "tolerance 1e-09 (the file says converged = true)» (the same file, checked by that code)",
                 ["check", "z.h5"], observe=lambda completed: f"; «{completed.stdout.strip().splitlines()[-1]}»")
    for method, before in (("schur", "exit 3, 1.8 s: «schur: not converged: the final solution violates gluing gap "
                            "1.12e-01, complementarity 9.79e-02, penetration 9.12e-02, equilibrium 1.01e-02 (scale-free "
                            "tolerance 1e-06); the block solves are inaccurate: check the blocks' PETSc options ...»"),
                           ("feti", "exit 3, 2.3 s: «feti: not converged: the final solution violates gluing gap "
                            "1.90e+00, complementarity 1.61e-01, penetration 1.44e-01, equilibrium 2.11e-03 (scale-free "
                            "tolerance 1e-06); the block solves are inaccurate: ...»")):
        hostile.case(204, f"rollers and the pressure that cancels the expansion (upper halves floating), `{method}`",
                     before, ["solve", "-n", "2", "pressed.toml", "--set", f"solver.method={method}", "-o", "p.h5"],
                     kept=("p",))
    hostile.case(204, "the same, `reference`", "exit 3, 0.9 s: «reference: the solution violates equilibrium 3.23e-03 "
                 "(scale-free tolerance 1e-09): the problem is too ill-conditioned for double precision»",
                 ["reference", "pressed.toml", "-o", "p.h5"], kept=("p",))
