"""End-to-end runs under mpiexec with 1, 2 and 4 ranks, against the monolithic reference."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import SMALL, ddsolve, paper_references, refused
from launch_many import launch

from ddsolve.io import hdf5
from ddsolve.parallel.phases import PHASES
from ddsolve.post import analysis

UZAWA = ["--set", "solver.method=uzawa"]
#: Each method with a tolerance tight enough for a 1e-8 energy error.
TIGHT = {
    "uzawa": UZAWA + ["--set", "solver.stop=relative", "--set", "solver.tol=1e-12"],
    "schur": [],
    "mprgp": ["--set", "solver.method=mprgp", "--set", "solver.tol=1e-11"],
    "fista": ["--set", "solver.method=fista", "--set", "solver.tol=1e-11"],
    "feti": ["--set", "solver.method=feti", "--set", "solver.tol=1e-11"],
}


@pytest.fixture(scope="module")
def references(tmp_path_factory):
    """Reference results of the three paper scenes on a small mesh, computed once."""
    return paper_references(tmp_path_factory.mktemp("references"), *SMALL)


PAPER_SCENES = ["partial-closure", "full-opening", "linear"]


@pytest.fixture(scope="module")
def solved_on_four(tmp_path_factory) -> Path:
    """Each paper scene (small) by each method of TIGHT on 4 ranks, one launch: NAME-METHOD.h5."""
    folder = tmp_path_factory.mktemp("four")
    launch([["solve", name, *SMALL, *TIGHT[method], "-o", str(folder / f"{name}-{method}.h5")]
            for name in PAPER_SCENES for method in TIGHT], 4, folder)
    return folder


@pytest.mark.mpi
@pytest.mark.parametrize("method", TIGHT)
@pytest.mark.parametrize("name", PAPER_SCENES)
def test_dd_equals_the_reference(solved_on_four, references, name, method):
    result, reference = hdf5.read(solved_on_four / f"{name}-{method}.h5"), hdf5.read(references[name])
    assert result.converged and result.ranks == 4 and result.method == method
    if method == "uzawa":
        assert result.solves == result.iterations + 2
    if method == "schur":
        assert result.solves == 3
    comparison = analysis.compare(result, reference)
    assert comparison.energy_error < 1e-8
    checks = analysis.constraints(result)
    assert checks.gluing_gap < 1e-9
    if name == "partial-closure":
        assert checks.penetration < 1e-9 and checks.min_mu_c >= 0.0
        assert reference.attrs["closed_vertices"] > 0  # contact on part of the crack
    if name == "full-opening":
        assert reference.attrs["closed_vertices"] == 0 and np.all(result.multipliers["mu_c"] == 0.0)


@pytest.mark.mpi
def test_contact_where_the_linear_problem_overlaps(references):
    from ddsolve.post.analysis import normal_jump

    contact, linear = hdf5.read(references["partial-closure"]), hdf5.read(references["linear"])
    crack = contact.crack
    assert normal_jump(linear)[crack].min() < 0.0  # the free faces overlap ...
    assert normal_jump(contact)[crack].min() > -1e-12 * np.abs(normal_jump(linear)).max()  # ... contact does not
    overlap = normal_jump(linear) < 0
    assert np.all(contact.multipliers["mu_c"][crack & ~overlap] < 1e-9)


AGREEING_METHODS = ["uzawa", "schur", "mprgp", "fista"]


@pytest.fixture(scope="module")
def agreeing(tmp_path_factory) -> dict[tuple[str, int], Path]:
    """Partial closure (small) by each of AGREEING_METHODS on 1, 2 and 4 ranks, one launch per rank count:
    the result paths by (method, ranks)."""
    folder = tmp_path_factory.mktemp("agreeing")
    paths = {(method, ranks): folder / f"{method}-{ranks}.h5" for method in AGREEING_METHODS for ranks in (1, 2, 4)}
    for ranks in (1, 2, 4):
        launch([["solve", "partial-closure", *SMALL, "--set", f"solver.method={method}", "-o",
                 str(paths[method, ranks])] for method in AGREEING_METHODS], ranks, folder)
    return paths


@pytest.mark.mpi
@pytest.mark.parametrize("method", AGREEING_METHODS)
def test_rank_counts_agree(agreeing, method):
    results = {ranks: hdf5.read(agreeing[method, ranks]) for ranks in (1, 2, 4)}
    assert len({(r.iterations, r.solves) for r in results.values()}) == 1
    for ranks in (1, 2):
        assert results[ranks].ranks == ranks
        assert analysis.compare(results[ranks], results[4]).energy_error < 1e-10
        assert np.allclose(results[ranks].history, results[4].history, rtol=1e-6, atol=1e-14)


@pytest.mark.mpi
def test_unsupported_rank_count_fails_on_every_rank(tmp_path):
    completed = ddsolve("solve", "partial-closure", *SMALL, "-o", str(tmp_path / "x.h5"), ranks=3, check=False,
                        timeout=120)
    assert completed.returncode != 0
    assert completed.stderr.strip() == "ddsolve: error: unsupported number of ranks 3: use 1, 2 or a multiple of 4"
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.mpi
def test_max_iterations_writes_an_unconverged_result(tmp_path):
    output = tmp_path / "short.h5"
    completed = ddsolve("solve", "partial-closure", *SMALL, *UZAWA, "--set", "solver.max_iterations=25",
                        "-o", str(output), ranks=2, check=False)
    assert completed.returncode == 3
    assert "no convergence in 25 iterations" in completed.stderr
    result = hdf5.read(output)
    assert not result.converged and result.iterations == 25 and len(result.history) == 25


@pytest.mark.mpi
def test_divergence_stops_early_and_keeps_the_previous_file(tmp_path):
    output = tmp_path / "kept.h5"
    output.write_bytes(b"previous result")
    completed = ddsolve("solve", "partial-closure", *SMALL, *UZAWA, "--set", "solver.theta=200",
                        "-o", str(output), ranks=4, check=False)
    assert completed.returncode == 4
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and "uzawa diverged at iteration" in lines[0] and "stable bound" in lines[0]
    assert output.read_bytes() == b"previous result"


#: Per method, the PETSc options of its run on 8 ranks.
SPLIT_OPTIONS = {
    "schur": [],  # block interface matrices by parallel multi-column MUMPS solves
    "feti": [],  # Neumann and Dirichlet solves by parallel MUMPS
    "mprgp": ["-u_minus_ksp_type", "cg", "-u_minus_pc_type", "gamg", "-u_minus_ksp_rtol", "1e-13"],
}


@pytest.fixture(scope="module")
def split(tmp_path_factory) -> dict[tuple[str, int], Path]:
    """Partial closure (small) by each method of SPLIT_OPTIONS on 4 and 8 ranks: one launch on 4 ranks, one
    on 8 for the methods without PETSc options, one per method with them (PETSc reads its options once per
    process).  The result paths by (method, ranks)."""
    folder = tmp_path_factory.mktemp("split")
    paths = {(method, ranks): folder / f"{method}-{ranks}.h5" for method in SPLIT_OPTIONS for ranks in (4, 8)}

    def command(method: str, ranks: int) -> list[str]:
        return ["solve", "partial-closure", *SMALL, "--set", f"solver.method={method}", "-o", str(paths[method, ranks]),
                *(SPLIT_OPTIONS[method] if ranks == 8 else [])]
    launch([command(method, 4) for method in SPLIT_OPTIONS], 4, folder)
    launch([command(method, 8) for method, options in SPLIT_OPTIONS.items() if not options], 8, folder)
    for method in (method for method, options in SPLIT_OPTIONS.items() if options):
        launch([command(method, 8)], 8, folder)
    return paths


@pytest.mark.mpi
@pytest.mark.parametrize("method", SPLIT_OPTIONS)
def test_eight_ranks_split_every_block_over_two(split, method):
    results = {ranks: hdf5.read(split[method, ranks]) for ranks in (4, 8)}
    assert results[8].ranks == 8 and results[8].converged
    assert analysis.compare(results[8], results[4]).energy_error < 1e-8
    # the error estimate and G's volume terms, made by both ranks of each block on their pieces: those of 4 ranks
    assert results[8].attrs["error_estimate"] == pytest.approx(results[4].attrs["error_estimate"], rel=1e-6)
    np.testing.assert_allclose(results[8].fracture.G, results[4].fracture.G, rtol=1e-6)
    for name, indicators in results[4].indicators.items():
        np.testing.assert_allclose(results[8].indicators[name], indicators, rtol=0, atol=1e-6 * indicators.max())
    # G's split (mirror images found on the partner block's pieces), the reactions (each rank's own nodes), the
    # contact zones
    scale = np.abs(results[4].fracture.G).max()
    for key in ("G_I", "G_II"):
        np.testing.assert_allclose(getattr(results[8].fracture, key), getattr(results[4].fracture, key),
                                   rtol=1e-6, atol=1e-9 * scale)
    for layer, named in results[4].reactions.items():
        for name, force in named.items():
            np.testing.assert_allclose(results[8].reactions[layer][name], force, rtol=1e-6,  # the solver's accuracy
                                       atol=1e-7 * np.abs(force).max())
    assert analysis.contact_zones(results[8]) == analysis.contact_zones(results[4])
    assert len(results[8].attrs["peak_memory_mb"]) == 8
    memory = results[8].memory  # each rank holds a piece of one half (and Σ): less than the half
    assert len(memory["rank_mesh_bytes"]) == 8
    assert np.all(memory["rank_mesh_bytes"] < 0.5 * memory["whole_mesh_bytes"])


@pytest.mark.mpi
@pytest.mark.parametrize("sigma_vertices, makers", [(600, []), (300, [0, 2])])
def test_at_eight_ranks_a_rank_holds_its_piece_of_the_mesh_and_of_the_solution(tmp_path, sigma_vertices, makers):
    """On a refined mesh (P = 600) each rank of a block makes its piece of the half from the coarse one (its
    nodes, two rings of cells, Σ and the boundaries; :mod:`ddsolve.mesh.pieces`), holds it and the last solve
    there, and writes its rows: no rank holds more than 60 % of its half's mesh or of its block's solution
    (8 bytes per unknown) in any phase (the coarse half counted while the piece is made).  A half gmsh makes
    whole (P = 300) is held whole by the rank that makes it (rank 0, and u⁺'s leader, rank 2) until it has
    cut and sent the pieces; the others receive only theirs."""
    output = tmp_path / "eight.h5"
    ddsolve("solve", "partial-closure", "--set", f"mesh.sigma_vertices={sigma_vertices}", "--set",
            f"mesh.boundary_vertices={sigma_vertices * 128 // 100}", "-o", str(output), ranks=8)
    memory = hdf5.read(output).memory
    held = list(memory["held"])
    block_unknowns = memory["rank_unknowns"].reshape(4, 2).sum(axis=1).repeat(2)
    half = memory["whole_mesh_bytes"] / 2  # the halves are of one size here
    others = np.setdiff1d(np.arange(8), makers)
    for phase in ("meshing", "distribution", "assembly", "factorization", "iterations", "estimate", "output"):
        mesh, solutions = (memory[f"held_mb_{phase}"][:, held.index(what)] * 2 ** 20 for what in ("mesh", "solutions"))
        if phase in ("meshing", "distribution"):
            assert np.all(mesh[makers] >= 0.99 * half), (phase, mesh / half)  # the whole half, accounted
            mesh = mesh[others]
        assert np.all(mesh <= 0.6 * half), (phase, mesh / half)
        assert np.all(solutions <= 0.6 * 8 * block_unknowns), (phase, solutions / (8 * block_unknowns))
    assert np.all(solutions >= 0.5 * 8 * block_unknowns)  # at output: half the nodes each, and the rings


@pytest.mark.mpi
def test_an_active_multiplier_bound_p_is_honoured_by_schur_and_mprgp(tmp_path):
    """With p smaller than the gluing forces, schur's fallback (all bounds) and MPRGP solve the same QP."""
    methods = ("schur", "mprgp")
    launch([["solve", "partial-closure", *SMALL, "--set", f"solver.method={method}", "--set", "solver.p=0.005",
             "--set", "solver.tol=1e-11", "-o", str(tmp_path / f"{method}.h5")] for method in methods], 4, tmp_path)
    results = {method: hdf5.read(tmp_path / f"{method}.h5") for method in methods}
    multipliers = np.concatenate([np.ravel(v) for v in results["schur"].multipliers.values()])
    assert np.abs(multipliers).max() == pytest.approx(0.005)  # the bound is active
    assert analysis.compare(results["mprgp"], results["schur"]).energy_error < 1e-6


@pytest.mark.mpi
def test_the_launch_is_printed_phase_by_phase_and_every_rank_times_its_phases(tmp_path):
    output = tmp_path / "run.h5"
    completed = ddsolve("solve", "partial-closure", "--set", "mesh.sigma_vertices=100", "--set",
                        "mesh.boundary_vertices=128", "-o", str(output), ranks=2)  # MUMPS counts its factors in MB
    line = next(line for line in completed.stdout.splitlines() if line.startswith("launch "))
    result = hdf5.read(output)
    phases = [name for name in PHASES if name in result.timings and name != "write"]  # write: timed by the caller
    assert all(f"{name} {result.timings[name]:.2f}" in line for name in phases)
    printed = dict(re.findall(r"(\w+) (\d+\.\d\d)(?=,|;|$)", line.split(": ", 1)[1]))
    assert list(printed) == [*phases, "write"]
    total = float(line.split()[1])
    assert abs(total - sum(float(v) for v in printed.values())) <= 0.01 * len(printed)
    assert f"x the solve phase ({result.wall_time:.2f} s)" in line
    for name in phases[1:]:  # start-up is timed before MPI: every other phase on every rank
        cpu = result.memory[f"cpu_s_{name}"]
        assert len(cpu) == 2 and np.all(cpu >= 0.0)
    assert np.isclose(result.memory["cpu_s_assembly"].sum(), result.timings["assembly_cpu"])
    held = {phase: dict(zip(result.memory["held"], result.memory[f"held_mb_{phase}"].T))
            for phase in ("assembly", "factorization", "iterations", "estimate", "output")}
    assert np.all(held["assembly"]["mesh"] > 0) and np.all(held["assembly"]["matrices"] > 0)
    assert np.all(held["factorization"]["factors"] > 0) and np.all(held["iterations"]["factors"] > 0)
    assert np.all(held["estimate"]["factors"] == 0) and np.all(held["estimate"]["matrices"] == 0)  # dropped
    assert held["iterations"]["schur complements"][0] > held["iterations"]["schur complements"][1]  # rank 0's


@pytest.mark.mpi
def test_every_schur_complement_route_gives_the_same_answer(tmp_path):
    """``-<block>_schur_complement``: the Schur complements from the factorization, from the Dirichlet problem's
    multi-column solves, from MUMPS's entries of K⁻¹ or from multi-column solves give the same solution; a bad
    value is refused in one line naming it."""
    results = {}
    for route in ("factorization", "dirichlet", "inverse", "solves"):
        output = tmp_path / f"{route}.h5"
        options = [f"-{block}_schur_complement" for block in ("u_minus", "v_minus", "u_plus", "v_plus")]
        ddsolve("solve", "partial-closure", *SMALL, *(w for o in options for w in (o, route)), "-o", str(output),
                ranks=2)
        results[route] = hdf5.read(output)
        assert results[route].converged and results[route].method == "schur" and results[route].solves == 3
    for route in ("dirichlet", "inverse", "solves"):
        assert analysis.compare(results[route], results["factorization"]).energy_error < 1e-10
        assert results[route].attrs["energy"] == pytest.approx(results["factorization"].attrs["energy"], rel=1e-10)
    refused(ddsolve("solve", "partial-closure", *SMALL, "-v_plus_schur_complement", "lu", "-o", str(tmp_path / "x.h5"),
                    ranks=2, check=False), 1, "-v_plus_schur_complement lu: unknown, use one of factorization")


@pytest.mark.mpi
@pytest.mark.parametrize("method", ["schur", "feti"])
def test_out_of_core_factors_solve_the_reference_problem(tmp_path, references, method):
    """``solver.out_of_core = true`` on 4 ranks (and 8 for feti, whose blocks are then distributed): the
    reference's answer, as in core."""
    output = tmp_path / "ooc.h5"
    ddsolve("solve", "partial-closure", *SMALL, *TIGHT[method], "--set", "solver.out_of_core=true", "-o", str(output),
            ranks=8 if method == "feti" else 4)
    result = hdf5.read(output)
    assert result.converged and result.scene.solver.out_of_core and result.attrs["factors_out_of_core"]
    assert analysis.compare(result, hdf5.read(references["partial-closure"])).energy_error < 1e-8


@pytest.mark.mpi
def test_the_contact_zone_does_not_depend_on_the_method(tmp_path):
    """MPRGP's openings where the faces press are its tolerance (1-4e-9 max|u|), not 0: the zone is where
    μᶜ > 0 or the faces touch, one zone as schur finds it, not two."""
    methods = ("schur", "mprgp")
    launch([["solve", "partial-closure", "--set", "mesh.sigma_vertices=48", "--set", "mesh.boundary_vertices=80",
             "--set", f"solver.method={method}", "-o", str(tmp_path / f"{method}.h5")] for method in methods],
           2, tmp_path)
    zones = {method: hdf5.read(tmp_path / f"{method}.h5").fracture.zones for method in methods}
    assert len(zones["schur"]) == 1
    np.testing.assert_allclose(zones["mprgp"], zones["schur"])
