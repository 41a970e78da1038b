"""The experiments' commands (``python -m experiments COMMAND``, ``./run COMMAND``): each reruns
its measurements and rewrites its part of docs/ and results/.  The solver never imports them."""
from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from ddsolve.errors import DDSolveError
from ddsolve.parallel.runtime import Parser, guarded, init_petsc, split_arguments, unused_options_reported

#: Experiments: command -> (module, function, one-line summary, what it writes).
EXPERIMENTS = {
    "table1": ("paper", "table1", "the paper's Table 1: meshes, the paper's algorithm and the default method",
               "docs/results.md (table1)"),
    "theta-sweep": ("paper", "theta_sweep", "Uzawa's iterations against its step θ",
                    "docs/results.md (theta-sweep), docs/theta-sweep.png"),
    "figures": ("paper", "figures", "the paper's figures: deformed layers, normal jump along Σ",
                "docs/results.md (figures), docs/fig*.png"),
    "accuracy": ("accuracy", "accuracy", "error against the continuous solution: uniform, graded, adaptive, P1, P2",
                 "docs/results.md (accuracy), docs/accuracy.png, results/accuracy.h5"),
    "scaling": ("scaling", "scaling", "strong and weak scaling, P = 800 and 1600, a fitted cost model",
                "docs/scaling.md, docs/scaling-*.png, results/scaling.h5"),
    "scaling-3d": ("scaling_3d", "scaling_3d", "auto's cost model in a 3-D box: blocks, rank 0 and feti's rounds "
                   "measured and fitted, every candidate side by side on 2 ranks",
                   "docs/scaling.md (scaling-3d section), results/scaling-3d.json"),
    "robustness": ("robustness", "robustness", "every hard case and bad input, measured", "docs/robustness.md"),
    "gallery": ("gallery", "gallery", "structures beyond the paper's square, solved and drawn",
                "docs/gallery.md, docs/gallery-*.png, results/gallery/"),
    "fracture": ("fracture", "fracture", "G at the crack tips: finite differences, radii, a plate; G against "
                 "crack length and E2/E1", "docs/fracture.md, docs/fracture-*.png, results/fracture-*"),
    "delamination": ("delamination", "delamination", "DCB, ELS, ENF, MMB and a thermal mismatch against beam "
                     "theory", "docs/delamination.md, docs/delamination-*.png, results/delamination*"),
    "growth": ("growth", "growth", "crack growth along Σ: DCB and ENF against corrected beam theory, Example 1, "
               "the strip's disbonds", "docs/growth.md, docs/growth-*.png, results/growth/"),
    "stacks": ("stacks", "stacks", "stacked structures against closed forms: the Griffith interface crack between "
               "two materials, bi-material DCB and ENF, the thermal bilayer and its edge delamination",
               "docs/stacks.md, docs/stacks-*.png, results/stacks.h5"),
    "laminate": ("laminate", "laminate", "a laminate of four plies with two delaminations at two interfaces: G at "
                 "every tip on three meshes, the picture (also part of stacks)",
                 "docs/stacks.md (laminate section), docs/stacks-laminate.png, results/stacks-laminate.h5"),
    "interface": ("interface", "interface", "interface laws against closed forms: friction on the faces of a closed "
                  "crack under compression and shear and between the arms of the ENF, the cohesive bond's DCB and ENF "
                  "against Griffith growth",
                  "docs/interface.md, docs/interface-*.png, results/interface.h5"),
    "three-d": ("three_d", "three_d", "the 3-D reference on a plane scene extruded with rollers: energy per unit "
                "depth and the crack opening against the plane continuous values, open and partly shut",
                "docs/three-d.md"),
    "three-d-front": ("three_d_front", "three_d_front", "G along 3-D crack fronts: the extruded plane scene against "
                      "the plane G, the penny-shaped crack against Sneddon", "docs/three-d-front.md, "
                      "docs/three-d-front.png"),
    "three-d-shapes": ("three_d_shapes", "three_d_shapes", "G along 3-D fronts of other shapes: a DCB across its "
                       "width against plane-strain and plane-stress beam theory, an elliptical delamination against "
                       "Irwin", "docs/three-d-front.md (shapes section), docs/three-d-dcb.png, "
                       "docs/three-d-ellipse.png"),
    "three-d-interfaces": ("three_d_interfaces", "three_d_interfaces", "a 3-D box of two interfaces: the plane "
                           "structure extruded with rollers against the plane energy and G, the sample's "
                           "decomposition against its reference", "docs/three-d.md (three-d-interfaces section)"),
    "three-d-adapt": ("three_d_adapt", "three_d_adapt", "3-D mesh.target_error on the extruded plane scene: "
                      "levels, estimate against the true error, G against the plane G, the DD on the final mesh",
                      "docs/three-d-adapt.md"),
    "architecture": ("architecture", "architecture", "the package's stages and the imports between them, read "
                     "from the source", "docs/architecture.png"),
}
#: The experiment that hands options to PETSc.
PETSC_COMMANDS = ("bench",)


def meshes(text: str | None):
    """``--meshes P:M,P:M`` as pairs (default: the benchmark meshes)."""
    from experiments.bench import BENCH_MESHES

    if not text:
        return BENCH_MESHES
    try:
        return tuple(tuple(int(v) for v in pair.split(":")) for pair in text.split(","))
    except ValueError:
        raise DDSolveError(f"--meshes {text}: expected P:M pairs separated by commas, e.g. 48:80,96:144") from None


def cmd_bench(args, petsc_options) -> int:
    if args.what == "contact":  # its launches start MPI: this process must not (bench's imports do)
        from experiments import contact

        output = Path(args.output or "results/bench-contact.h5")
        contact.contact(output)
        print(f"wrote {output}, docs/methods.md (bench-contact section), docs/bench-contact.png")
        return 0
    from experiments import bench, bench_solid

    if args.what == "factor":
        init_petsc(petsc_options)
        for P, M in meshes(args.meshes or "200:256"):
            bench.factor(P, M)
    elif args.what in ("baseline", "baseline-3d"):
        if args.what == "baseline":
            output = Path(args.output or "results/bench-baseline.h5")
            bench.baseline(meshes(args.meshes or "400:512,800:1024"), ranks=args.ranks, repeats=args.repeats,
                           busy=args.busy, output=output)
            print(f"wrote {output}, docs/methods.md (bench-baseline section)")
        bench_solid.baseline(args.size or bench_solid.SIZE, repeats=args.repeats)
        print("wrote results/bench-baseline-3d.json, docs/methods.md (bench-baseline-3d section)")
    else:
        args.output = args.output or "results/bench-methods.h5"
        bench.methods(meshes(args.meshes), Path(args.output), Path("docs"))
        print(f"wrote {args.output}, docs/results.md (bench-methods section), docs/bench-methods.png")
    return 0


def cmd_experiment(args, _petsc_options) -> int:
    module, function, _, written = EXPERIMENTS[args.command]
    getattr(importlib.import_module(f"experiments.{module}"), function)()
    print(f"wrote {written}")
    return 0


def parser() -> argparse.ArgumentParser:
    """The experiments' command line; its epilog lists them, one line each."""
    top = Parser(prog="python -m experiments", description="ddsolve's experiments: each reruns its "
                 "measurements and rewrites its part of docs/ and results/.",
                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = top.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (_, _, summary, written) in EXPERIMENTS.items():
        sub.add_parser(name, description=f"{summary}; writes {written}").set_defaults(run=cmd_experiment)
    summary = ("`bench methods`: every method and tolerance; `bench baseline`: the default method against one MUMPS "
               "factorization of the whole problem, plane and 3-D (`bench baseline-3d`: the 3-D case alone); `bench contact`: every method against the length of Σ in contact "
               "(ENF, ELS, a closed strip); `bench factor`: block factorizations")
    p = sub.add_parser("bench", description=summary)
    p.set_defaults(run=cmd_bench)
    p.add_argument("what", choices=("methods", "baseline", "baseline-3d", "contact", "factor"))
    p.add_argument("--size", type=float, help="mesh.size of the 3-D case of `bench baseline` and `bench baseline-3d` "
                   "(default 0.026: about 0.3 M unknowns)")
    p.add_argument("--meshes", help="comma-separated P:M pairs (default: Table 1 and 400:512; baseline: "
                   "400:512,800:1024)")
    p.add_argument("-n", dest="ranks", type=int, metavar="N",
                   help="ranks of the DD in `bench baseline` (default: 4, or fewer if there are fewer cores)")
    p.add_argument("--repeats", type=int, default=3, help="side-by-side pairs per case in `bench baseline`")
    p.add_argument("--busy", action="store_true", help="`bench baseline` with a second process keeping a core busy")
    p.add_argument("-o", dest="output", help="HDF5 file of `methods` (default results/bench-methods.h5), "
                   "`baseline` (default results/bench-baseline.h5) or `contact` (default results/bench-contact.h5)")
    listing = [(name, summary) for name, (_, _, summary, _) in EXPERIMENTS.items()] + [("bench", summary)]
    width = max(len(name) for name, _ in listing) + 2
    top.epilog = ("experiments (each reruns its measurements and rewrites its part of docs/ and results/):\n"
                  + "\n".join(f"  {name:{width}s}{text}" for name, text in listing))
    return top


def main(argv: list[str] | None = None) -> int:
    top = parser()

    def run() -> int:
        own, petsc_options = split_arguments(top, sys.argv[1:] if argv is None else argv, PETSC_COMMANDS)
        args = top.parse_args(own)
        if args.command in PETSC_COMMANDS:
            return unused_options_reported(lambda: args.run(args, petsc_options))
        return args.run(args, petsc_options)
    return guarded(run)
