"""P2, graded and adaptive meshes and the error estimate, end to end under mpiexec."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import ddsolve, paper_references

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


@pytest.fixture(scope="module")
def p2_references(tmp_path_factory):
    return paper_references(tmp_path_factory.mktemp("p2"), *P2)


@pytest.mark.parametrize("name, method", [("partial-closure", m) for m in METHODS]
                         + [("full-opening", "schur"), ("linear", "schur")])
def test_p2_dd_equals_the_reference(tmp_path, p2_references, name, method):
    output = tmp_path / "dd.h5"
    completed = ddsolve("solve", name, *P2, *METHODS[method], "-o", str(output), ranks=4)
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
    assert f"estimated discretization error {100 * result.attrs['error_estimate']:.3g} %" in completed.stdout


def test_compare_and_check_work_on_p2_results(tmp_path, p2_references):
    output = tmp_path / "dd.h5"
    ddsolve("solve", "partial-closure", *P2, "-o", str(output), ranks=2)
    compared = ddsolve("compare", str(output), str(p2_references["partial-closure"])).stdout
    assert float(compared.split()[3]) < 1e-10
    checked = ddsolve("check", str(output)).stdout
    assert float(checked.split()[2]) < 1e-9  # max penetration


def test_graded_p2_gives_the_same_solution_on_1_2_4_and_8_ranks(tmp_path):
    """With 2 ranks or more the halves are meshed in two processes: the Σ nodes must still match."""
    path = graded_scene(tmp_path)
    results = {}
    for ranks in (1, 2, 4, 8):
        output = tmp_path / f"n{ranks}.h5"
        ddsolve("solve", path, "-o", str(output), ranks=ranks)
        results[ranks] = hdf5.read(output)
    for ranks in (1, 2, 8):
        assert results[ranks].ranks == ranks
        assert np.array_equal(results[ranks].lower.points, results[4].lower.points)
        assert analysis.compare(results[ranks], results[4]).energy_error < 1e-10
        assert results[ranks].attrs["error_estimate"] == pytest.approx(results[4].attrs["error_estimate"], rel=1e-8)


def test_the_result_file_has_the_indicators_per_cell(tmp_path):
    output = tmp_path / "dd.h5"
    ddsolve("solve", graded_scene(tmp_path), "-o", str(output), ranks=4)
    import h5py

    with h5py.File(output) as f:
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


@pytest.mark.parametrize("name", ["strip-disbonds", "arc-bond", "kinked-bond", "orthotropic-plate"])
def test_target_error_works_on_the_gallery_scenes(tmp_path, name):
    output = tmp_path / f"{name}.h5"
    ddsolve("solve", name, "--set", "mesh.size=0.25", "--set", "mesh.degree=2", "--set", "mesh.target_error=0.02",
            "-o", str(output), ranks=2)
    result = hdf5.read(output)
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
