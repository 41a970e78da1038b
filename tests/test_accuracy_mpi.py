"""P2, graded and adaptive meshes and the error estimate, end to end under mpiexec."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import ddsolve, solved_reference
from launch_many import launch

from ddsolve.io import hdf5
from ddsolve.post import analysis
from ddsolve.problem import scene

pytestmark = pytest.mark.mpi

#: A small P2 mesh of the paper's family.
P2 = ["--set", "mesh.sigma_vertices=13", "--set", "mesh.boundary_vertices=32", "--set", "mesh.degree=2"]
METHODS = {
    "schur": [],
    "mprgp": ["--set", "solver.method=mprgp", "--set", "solver.tol=1e-11"],
    "fista": ["--set", "solver.method=fista", "--set", "solver.tol=1e-11"],
    "uzawa": ["--set", "solver.method=uzawa", "--set", "solver.stop=relative", "--set", "solver.tol=1e-12"],
}


def graded_scene(folder, name: str = "partial-closure", size: float = 0.25) -> str:
    """A paper scene meshed with mesh.size (and P2, grading) instead of (P, M), as a file."""
    text = scene.builtin_scenes()[name]
    text = text.replace("sigma_vertices = 96", f"size = {size}\ndegree = 2\ngrading = true")
    text = text.replace("boundary_vertices = 144\n", "")
    path = folder / f"{name}-graded.toml"
    path.write_text(text)
    return str(path)


P2_CASES = [("partial-closure", method) for method in METHODS] + [("full-opening", "schur"), ("linear", "schur")]


@pytest.fixture(scope="module")
def p2_references(tmp_path_factory) -> dict[str, Path]:
    """The paper scenes' P2 references, solved in this process."""
    folder = tmp_path_factory.mktemp("p2")
    return {name: solved_reference(name, *P2, "-o", str(folder / f"{name}.h5"))
            for name in ("partial-closure", "full-opening", "linear")}


@pytest.fixture(scope="module")
def p2_solved(tmp_path_factory) -> dict[tuple[str, str], tuple[Path, str]]:
    """Each of P2_CASES solved on 4 ranks, one launch: its result path and standard output."""
    folder = tmp_path_factory.mktemp("p2dd")
    paths = [folder / f"{name}-{method}.h5" for name, method in P2_CASES]
    stdout = launch([["solve", name, *P2, *METHODS[method], "-o", str(path)]
                     for (name, method), path in zip(P2_CASES, paths)], 4, folder)
    return dict(zip(P2_CASES, zip(paths, stdout)))


@pytest.mark.parametrize("name, method", P2_CASES)
def test_p2_dd_equals_the_reference(p2_solved, p2_references, name, method):
    output, stdout = p2_solved[name, method]
    result, reference = hdf5.read(output), hdf5.read(p2_references[name])
    assert result.mesh.degree == 2 and result.lower.cells.shape[1] == 6 and result.converged
    error = analysis.compare(result, reference).energy_error
    assert error < (1e-10 if method == "schur" else 1e-8)
    checks = analysis.constraints(result)
    assert checks.gluing_gap < 1e-10
    if name == "partial-closure":  # non-penetration at every crack node, midpoints included
        assert checks.penetration < 1e-9 and checks.min_mu_c >= 0.0 and reference.attrs["closed_vertices"] > 0
        assert not result.mesh.sigma.corner[result.multiplier_nodes][result.crack].all()
    # The same estimate from the blocks' ranks as from the reference, printed at the end.
    assert result.attrs["error_estimate"] == pytest.approx(reference.attrs["error_estimate"], rel=1e-6)
    assert f"estimated discretization error {100 * result.attrs['error_estimate']:.3g} %" in stdout


def test_compare_and_check_work_on_p2_results(p2_solved, p2_references):
    output = p2_solved["partial-closure", "schur"][0]
    compared = ddsolve("compare", str(output), str(p2_references["partial-closure"])).stdout
    assert float(compared.split()[3]) < 1e-10
    checked = ddsolve("check", str(output)).stdout
    assert float(checked.split()[2]) < 1e-9  # max penetration


@pytest.fixture(scope="module")
def graded_by_ranks(tmp_path_factory) -> dict[int, Path]:
    """The graded P2 partial closure (graded_scene) solved on 1, 2, 4 and 8 ranks: the result paths."""
    folder = tmp_path_factory.mktemp("graded")
    path = graded_scene(folder)
    outputs = {ranks: folder / f"n{ranks}.h5" for ranks in (1, 2, 4, 8)}
    for ranks, output in outputs.items():
        ddsolve("solve", path, "-o", str(output), ranks=ranks)
    return outputs


def test_graded_p2_gives_the_same_solution_on_1_2_4_and_8_ranks(graded_by_ranks):
    """With 2 ranks or more the halves are meshed in two processes: the Σ nodes must still match."""
    results = {ranks: hdf5.read(output) for ranks, output in graded_by_ranks.items()}
    for ranks in (1, 2, 8):
        assert results[ranks].ranks == ranks
        assert np.array_equal(results[ranks].lower.points, results[4].lower.points)
        assert analysis.compare(results[ranks], results[4]).energy_error < 1e-10
        assert results[ranks].attrs["error_estimate"] == pytest.approx(results[4].attrs["error_estimate"], rel=1e-8)


def test_the_result_file_has_the_indicators_per_cell(graded_by_ranks):
    import h5py

    with h5py.File(graded_by_ranks[4]) as f:
        assert 0 < f.attrs["error_estimate"] < 0.2
        for block in ("u_minus", "u_plus", "v_minus", "v_plus"):
            half = "lower" if block.endswith("minus") else "upper"
            assert f[f"error/indicator/{block}"].shape == (len(f[f"mesh/{half}/cells"]),)
            assert f[f"mesh/{half}/cells"].shape[1] == 6


def test_adaptive_refinement_reaches_the_target(tmp_path):
    output = tmp_path / "adaptive.h5"
    completed = ddsolve("solve", graded_scene(tmp_path, "partial-closure", 0.5), "--set", "mesh.grading=false",
                        "--set", "mesh.target_error=0.03", "-o", str(output), ranks=4)
    result = hdf5.read(output)
    levels = result.levels
    assert 2 <= len(levels["unknowns"]) <= 3 and np.all(np.diff(levels["unknowns"]) > 0)  # at most three solves
    assert levels["error_estimate"][-1] <= 0.03 < levels["error_estimate"][-2]
    assert result.attrs["error_estimate"] == levels["error_estimate"][-1]
    assert np.all(np.diff(levels["energy"]) < 0)  # finer conforming meshes: lower energy
    lines = [line for line in completed.stdout.splitlines() if line.startswith("level ")]
    assert len(lines) == len(levels["unknowns"]) and "unknowns, estimated error" in lines[0]


TARGET_GALLERY = ["strip-disbonds", "arc-bond", "kinked-bond", "orthotropic-plate"]


@pytest.fixture(scope="module")
def gallery_to_target(tmp_path_factory) -> Path:
    """TARGET_GALLERY solved to mesh.target_error = 0.02 (P2 from mesh.size 0.25) on 2 ranks, one launch."""
    folder = tmp_path_factory.mktemp("target")
    launch([["solve", name, "--set", "mesh.size=0.25", "--set", "mesh.degree=2", "--set", "mesh.target_error=0.02",
             "-o", str(folder / f"{name}.h5")] for name in TARGET_GALLERY], 2, folder)
    return folder


@pytest.mark.parametrize("name", TARGET_GALLERY)
def test_target_error_works_on_the_gallery_scenes(gallery_to_target, name):
    result = hdf5.read(gallery_to_target / f"{name}.h5")
    assert result.attrs["error_estimate"] <= 0.02 and len(result.levels["unknowns"]) <= 3


def test_target_error_on_a_fixed_mesh_file_is_refused_in_one_line(tmp_path, mesh_file):
    path = tmp_path / "fixed.toml"
    path.write_text(scene.builtin_scenes()["partial-closure"].replace(
        "sigma_vertices = 96\nboundary_vertices = 144", f'file = "{mesh_file}"\ntarget_error = 0.01'))
    completed = ddsolve("solve", str(path), "-o", str(tmp_path / "x.h5"), ranks=2, check=False)
    assert completed.returncode == 1
    assert completed.stderr.strip().splitlines() == [
        f"ddsolve: error: {path}: mesh.target_error needs a geometry to mesh (the built-in box or a .geo file); "
        f"mesh.file = {mesh_file} is a fixed mesh"]
