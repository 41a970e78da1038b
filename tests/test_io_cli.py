"""Result files and the command line (serial)."""
import h5py
import numpy as np
import pytest
from conftest import SMALL, ddsolve, solved_reference

from ddsolve import cli
from ddsolve.errors import UsageError
from ddsolve.io import hdf5


@pytest.fixture(scope="module")
def reference_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("io") / "ref.h5"
    solved_reference("partial-closure", *SMALL, "-o", str(path))
    return path


@pytest.mark.mpi
def test_result_layout_and_round_trip(reference_file):
    with h5py.File(reference_file) as f:
        for name in ("mesh/lower/points", "mesh/lower/cells", "mesh/upper/points", "mesh/upper/cells",
                     "solution/u_minus", "solution/v_minus", "solution/u_plus", "solution/v_plus",
                     "interface/x", "interface/crack", "interface/mu_c", "interface/mu_g",
                     "interface/mu_minus", "interface/mu_plus", "history/criterion",
                     "history/active_set_changes", "paraview/u_minus/displacement", "paraview/v_plus/von_mises"):
            assert name in f, name
        for key in ("converged", "iterations", "solves", "method", "wall_time", "ranks", "scene", "version"):
            assert key in f.attrs, key
        k = len(f["interface/x"])
        assert f["interface/mu_g"].shape == (k, 2) and f["interface/mu_c"].shape == (k,)
        assert f["solution/u_minus"].shape == f["mesh/lower/points"].shape
        assert f.attrs["method"] == "reference"
    result = hdf5.read(reference_file)
    copy = reference_file.with_name("copy.h5")
    hdf5.write(copy, result)
    again = hdf5.read(copy)
    assert again.scene == result.scene and np.array_equal(again.solution["v_plus"], result.solution["v_plus"])


@pytest.mark.mpi
def test_output_directory_must_exist_and_nothing_partial_is_left(tmp_path, reference_file):
    result = hdf5.read(reference_file)
    from ddsolve.errors import DDSolveError

    with pytest.raises(DDSolveError, match="does not exist"):
        hdf5.write(tmp_path / "missing" / "out.h5", result)
    hdf5.write(tmp_path / "out.h5", result)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out-layer1.vtu", "out-layer2.vtu", "out-paraview.py",
                                                          "out-sigma.vtu", "out.h5"]


def test_ddsolve_options_are_taken_wherever_they_are_typed():
    top = cli.parser()
    assert cli.split_arguments(top, ["solve", "s.toml", "-o", "x.h5", "--set", "a.b=-1", "-log_view"]) == (
        ["solve", "s.toml", "-o", "x.h5", "--set", "a.b=-1"], ["-log_view"])
    assert cli.split_arguments(top, ["solve", "s", "-u_minus_ksp_type", "cg", "--set", "solver.tol=1e-9",
                                     "-v_plus_pc_type", "gamg", "-o", "x.h5", "-n", "4"]) == (
        ["solve", "s", "--set", "solver.tol=1e-9", "-o", "x.h5", "-n", "4"],
        ["-u_minus_ksp_type", "cg", "-v_plus_pc_type", "gamg"])
    assert cli.split_arguments(top, ["solve", "s", "--", "-x", "-o", "y"]) == (["solve", "s"], ["-x", "-o", "y"])
    assert cli.split_arguments(top, ["solve", "s", "-mat_mumps_icntl_14", "-5", "-n4"]) == (
        ["solve", "s", "-n4"], ["-mat_mumps_icntl_14", "-5"])
    with pytest.raises(UsageError, match="unknown option -scale .did you mean --scale"):
        cli.split_arguments(top, ["plot", "r.h5", "-scale", "5"])


@pytest.mark.mpi
@pytest.mark.parametrize("arguments, message", [
    (["solve", "nope.toml"], "nope.toml: no such scene file or built-in scene"),
    (["solve", "partial-closure", "--set", "solver.thta=3"], "did you mean solver.theta?"),
    (["reference", "partial-closure", "--set", "mesh.file=missing.msh", "--set", "mesh.sigma_vertices=[]"],
     "mesh.sigma_vertices must be an integer"),
    (["compare", "missing-a.h5", "missing-b.h5"], "missing-a.h5: result file not found"),
])
def test_bad_input_is_one_line_and_nonzero(tmp_path, arguments, message):
    completed = ddsolve(*arguments, check=False)
    assert completed.returncode == 1
    assert completed.stderr.strip().count("\n") == 0 and message in completed.stderr
    assert "Traceback" not in completed.stderr


@pytest.mark.mpi
def test_missing_mesh_file_is_reported(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text('[mesh]\nfile = "absent.msh"\n[materials.layer1]\nE = 1.0\nnu = 0.3\n'
                     '[materials.layer2]\nE = 1.0\nnu = 0.3\n[solver]\ntheta = 1.0\n')
    completed = ddsolve("solve", str(scene), ranks=4, check=False)
    assert completed.returncode == 1
    assert completed.stderr.strip() == f"ddsolve: error: {tmp_path / 'absent.msh'}: mesh file not found"


@pytest.mark.mpi
def test_compare_check_and_plot(tmp_path, reference_file):
    out = ddsolve("compare", str(reference_file), str(reference_file)).stdout
    assert "relative energy-norm error 0.000e+00" in out
    out = ddsolve("check", str(reference_file)).stdout
    assert "max penetration 0.000e+00" in out
    local = tmp_path / "r.h5"
    local.write_bytes(reference_file.read_bytes())
    out = ddsolve("plot", str(local), "--scale", "100").stdout
    assert "(displacements ×100)" in out
    assert (tmp_path / "r-deformed.png").stat().st_size > 10_000
    assert (tmp_path / "r-crack-faces.png").stat().st_size > 10_000
    assert (tmp_path / "r-convergence.png").stat().st_size > 10_000


@pytest.mark.mpi
def test_plot_of_a_solution_that_is_not_finite_is_one_line(tmp_path, reference_file):
    import h5py

    broken = tmp_path / "nan.h5"
    broken.write_bytes(reference_file.read_bytes())
    with h5py.File(broken, "r+") as f:
        f["solution/u_minus"][0, 0] = float("nan")
    completed = ddsolve("plot", str(broken), check=False)
    assert completed.returncode == 1 and not list(tmp_path.glob("*.png"))
    assert completed.stderr.strip() == (f"ddsolve: error: {broken}: /solution/u_minus holds values that are not "
                                        "finite numbers: nothing to draw")
