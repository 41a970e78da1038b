"""Issue 21's load expressions, measured for docs/robustness.md: class 1 (expressions at the parser's
limits), the singular load and the fibre angle of class 7, the infinite load and the byte-order mark of
class 8.  *Before* is what the code before the fix did (measured once, quoted)."""
from __future__ import annotations

from experiments.robustness import SMALL
from ddsolve.problem import scene as scenes

KEY = "loads.layer1.top.y"
SOLVE = ["solve", "-n", "2"]


def measure(hostile) -> None:
    paper = scenes.builtin_scenes()["partial-closure"]

    def scene_file(name: str, value: str, prefix: bytes = b"") -> str:
        """The partial-closure scene with ``KEY = value`` (TOML text), written in the scratch folder."""
        (hostile.folder / f"{name}.toml").write_bytes(
            prefix + paper.replace("y = [0.0, -0.078125]", f"y = {value}", 1).encode())
        return f"{name}.toml"

    def load(value: str) -> list[str]:
        return [*SOLVE, "partial-closure", *SMALL, "--set", f"{KEY}={value}", "-o", "e.h5"]

    for label, before, arguments in (
            ("3000 nested parentheses", "exit 1, 0.7 s: 2986-line traceback (RecursionError)",
             load('"' + "(" * 3000 + "x" + ")" * 3000 + '"')),
            ("a sum of 3000 terms `x+x+…+x`", "exit 1, 4.6 s: 18-line traceback (RecursionError while pickling the "
             "scene for the ranks)", load('"' + "+".join(["x"] * 3000) + '"')),
            ("a chain of 3000 powers `x^x^…^x`", "exit 1, 0.8 s: 2986-line traceback (RecursionError)",
             load('"' + "^".join(["x"] * 3000) + '"')),
            ("a 1 MB expression (in the scene file)", "exit 1, 65.9 s: 18-line traceback (RecursionError while "
             "pickling)", [*SOLVE, scene_file("megabyte", '"' + "+".join(["1.0"] * 262144) + '"'), *SMALL,
                           "-o", "e.h5"]),
            ("`x^inf`", "exit 1, 0.9 s: «ddsolve: error: partial-closure: loads.layer1.top.y: bad expression "
             "'x^inf': unknown name 'inf' (known: x, y, pi, sin, cos, exp, sqrt) at position 3»", load('"x^inf"')),
            ("`x^1e400`", "exit 1, 5.8 s: 51 lines, a traceback (OverflowError: cannot convert float infinity to "
             "integer) and «ddsolve: terminated»", load('"x^1e400"')),
            ("`x^(1/0)`", "exit 1, 5.1 s: 53 lines, a numpy warning, a traceback (OverflowError) and «ddsolve: "
             "terminated»", load('"x^(1/0)"')),
            ("`x^1000000`", "exit 1, 5.3 s: 51 lines, a traceback (numpy: unable to allocate 1.82 TiB for the "
             "quadrature rule) and «ddsolve: terminated»", load('"x^1000000"')),
            ("a list of 1 000 000 polynomial coefficients (in the scene file)", "exit 1, 27.3 s: 18-line traceback "
             "(RecursionError while pickling)", [*SOLVE, scene_file("million", "[" + "0.0, " * 999999 + "0.0]"),
                                                 *SMALL, "-o", "e.h5"]),
            ("a list nested 3000 deep", "exit 1, 1.1 s: 2985-line traceback (RecursionError in the TOML parser)",
             load("[" * 3000 + "]" * 3000))):
        hostile.case(101, label, before, arguments, kept=("e",))
    hostile.case(107, "load `1e-4/(x-0.0123)^2` (a pole on the top boundary)", "exit 0, 4.9 s, nothing said; its "
                 "energy changes by two orders of magnitude with the mesh", load('"1e-4/(x-0.0123)^2"'), kept=("e",))
    hostile.case(107, "reference, the same load", "exit 0, nothing said",
                 ["reference", "partial-closure", *SMALL, "--set", f'{KEY}="1e-4/(x-0.0123)^2"', "-o", "e.h5"],
                 kept=("e",))
    hostile.case(107, "orthotropic `angle = 1e20` (degrees)", "exit 0, 4.8 s, nothing said",
                 [*SOLVE, "partial-closure", *SMALL, "--set",
                  "materials.layer2={E1=140.0, E2=10.0, G12=5.0, nu12=0.3, angle=1e20}", "-o", "e.h5"], kept=("e",))
    hostile.case(108, "infinite load `exp(1000*x)`", "exit 1, 6.0 s: «ddsolve: error: materials.layer1.E: the elastic "
                 "matrix (largest entry 256) with loads.layer1.top up to inf on a domain of size 2 gives displacements "
                 "of order inf, outside the range a double-precision solve represents (1e-100 to 1e+100): change the "
                 "units of the moduli and the loads»", load('"exp(1000*x)"'), kept=("e",))
    hostile.case(108, "infinite coefficient `[0.0, -1e400]`", "exit 1, 0.5 s: «ddsolve: error: partial-closure: "
                 "loads.layer1.top.y must be a finite number (got [0.0, -inf])» (named already)",
                 load("[0.0, -1e400]"), kept=("e",))
    hostile.case(108, "scene file starting with a UTF-8 byte-order mark", "exit 1, 0.6 s: «ddsolve: error: bom.toml: "
                 "malformed TOML: Invalid statement (at line 1, column 1)»",
                 [*SOLVE, scene_file("bom", "[0.0, -0.078125]", prefix=b"\xef\xbb\xbf"), *SMALL, "-o", "e.h5"])
