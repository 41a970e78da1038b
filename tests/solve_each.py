"""Solve every built-in scene with every method in one MPI launch (small meshes): used by
test_convergence_claim.py, run as ``mpiexec -n N python tests/solve_each.py FOLDER``.

A run that does not converge writes its result with converged = false (NotConvergedError, raised on
every rank), one that diverges writes nothing (DivergedError), and the loop goes on; anything else
stops the launch.
"""
from __future__ import annotations

import sys
from pathlib import Path

#: Small meshes: the paper's scenes on (P, M) = (13, 32), the gallery at mesh.size = 0.25.
SMALL = {"box": ["mesh.sigma_vertices=13", "mesh.boundary_vertices=32"], "size": ["mesh.size=0.25"]}
#: Per method: what the gallery scenes (which set no θ) need, and a bound on the iterations.
METHOD_SETTINGS = {
    "schur": [],
    "mprgp": ["solver.max_iterations=3000"],
    "fista": ["solver.max_iterations=3000"],
    "uzawa": ["solver.theta=auto", "solver.max_iterations=3000"],
}


def cases() -> list[tuple[str, str, list[str]]]:
    """(scene, method, overrides) for every built-in scene and method."""
    from ddsolve.problem import scene as scenes

    out = []
    for name, text in sorted(scenes.builtin_scenes().items()):
        mesh = SMALL["box"] if "sigma_vertices" in text else SMALL["size"]
        for method, settings in METHOD_SETTINGS.items():
            settings = [s for s in settings if not (s.startswith("solver.theta") and "theta" in text)]
            out.append((name, method, [*mesh, f"solver.method={method}", *settings]))
    return out


def main(folder: Path) -> None:
    import petsc4py

    petsc4py.init(sys.argv[:1])
    from mpi4py import MPI

    from ddsolve.errors import DivergedError, NotConvergedError
    from ddsolve.problem import scene as scenes
    from ddsolve.solvers import driver

    comm = MPI.COMM_WORLD
    for name, method, overrides in cases():
        scene = scenes.load(name, overrides)
        try:
            driver.solve_decomposed(scene, comm, folder / f"{name}-{method}.h5", progress=lambda *_: None)
        except (NotConvergedError, DivergedError):
            pass


if __name__ == "__main__":
    main(Path(sys.argv[1]))
