"""The MPI launches of the experiments: part name -> function, with typed arguments before OUTPUT."""
from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

from ddsolve.parallel.runtime import guarded, init_petsc, split_arguments

#: part -> (module in this package, function, typed arguments before OUTPUT).  The function is called
#: with those arguments, the output path and MPI.COMM_WORLD.
PARTS = {
    "bench-mesh": ("bench", "bench_mesh", (("plan", str), ("P", int), ("M", int))),
    "bench-baseline": ("bench", "bench_baseline", (("name", str), ("P", int), ("M", int), ("repeats", int))),
    "bench-baseline-3d": ("bench_solid", "bench_solid", (("size", float), ("repeats", int))),
    "bench-memory-3d": ("bench_solid", "memory", (("side", str), ("size", float))),
    "scaling-3d-measure": ("scaling_3d", "measure_launch", ()),
    "scaling-3d-candidates": ("scaling_3d", "candidates_launch", (("degree", int), ("size", float), ("contact", int),
                                                                  ("repeats", int))),
    "theta-mesh": ("paper", "theta_mesh", (("P", int), ("M", int), ("scene", str))),
    "accuracy-family": ("accuracy", "family_run", (("scene", str), ("family", str), ("degree", int))),
    "scaling-network": ("scaling", "network", ()),
    "scaling-calibrate": ("scaling", "calibrate", ()),
    "scaling-meshing": ("scaling", "meshing", (("P", int), ("M", int), ("refine", str))),
    "fracture-checks": ("fracture", "checks", ()),
}


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(prog="python -m experiments")
    sub = top.add_subparsers(dest="part", required=True)
    for name, (_, _, arguments) in PARTS.items():
        p = sub.add_parser(name)
        for argument, kind in arguments:
            p.add_argument(argument, type=kind)
        p.add_argument("output", type=Path)
    return top


def run(args, petsc_options: list[str]) -> int:
    init_petsc(petsc_options)
    from mpi4py import MPI

    module, function, arguments = PARTS[args.part]
    values = [getattr(args, name) for name, _ in arguments]
    getattr(importlib.import_module(f".{module}", __package__), function)(*values, args.output, MPI.COMM_WORLD)
    return 0


def main(argv: list[str] | None = None) -> int:
    top = parser()
    own, petsc_options = split_arguments(top, sys.argv[1:] if argv is None else argv, tuple(PARTS))
    args = top.parse_args(own)
    return guarded(lambda: run(args, petsc_options))
