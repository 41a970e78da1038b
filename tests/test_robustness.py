"""Hard numerical cases and bad input (docs/robustness.md lists each with its measured outcome)."""
from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import meshio
import numpy as np
import pytest
from conftest import SMALL, ddsolve, solved_reference, structured_square
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from launch_many import launch

from ddsolve.errors import SceneError
from ddsolve.io import hdf5
from ddsolve.mesh import geometry
from ddsolve.post import analysis
from ddsolve.problem import scene


def solve_and_reference(tmp_path, name, *overrides, method_args=(), ranks=4):
    """The default (or given) method and the reference on the same scene; (result, reference)."""
    dd, ref = tmp_path / "dd.h5", tmp_path / "ref.h5"
    ddsolve("solve", name, *overrides, *method_args, "-o", str(dd), ranks=ranks)
    solved_reference(name, *overrides, "-o", str(ref))
    return hdf5.read(dd), hdf5.read(ref)


# --- hard numerical cases ---------------------------------------------------------------------
#: Paper scenes (small) that the default method on 4 ranks must solve as the reference does: (scene, overrides).
HARD_CASES = {
    "E-ratio-1e-4": ("partial-closure", ["--set", "materials.layer2.E=0.02"]),
    "E-ratio-1e4": ("partial-closure", ["--set", "materials.layer2.E=2e6"]),
    "nu-0.49": ("partial-closure", ["--set", "materials.layer1.nu=0.49", "--set", "materials.layer2.nu=0.49"]),
    "nu-0.4999": ("partial-closure", ["--set", "materials.layer1.nu=0.4999", "--set", "materials.layer2.nu=0.4999"]),
    "crack-almost-all": ("partial-closure", ["--set", "geometry.crack=[-0.98, 0.98]"]),
    "crack-one-element": ("partial-closure", ["--set", "geometry.crack=[0.0, 0.05]"]),  # no crack vertex inside
    "no-crack": ("partial-closure", ["--set", "geometry.crack=[]"]),
    "full-closure": ("full-closure", []),
    "full-opening": ("full-opening", []),
    "layer-2-only": ("partial-closure", ["--set", "loads.layer1.bottom.y=[]", "--set", "loads.layer1.top.y=[]",
                                         "--set", "loads.layer2.bottom.y=[0.0, 0.05]",
                                         "--set", "loads.layer2.top.x=[0.02]"]),
}


@pytest.fixture(scope="module")
def hard_cases(tmp_path_factory) -> Path:
    """HARD_CASES by the default method on 4 ranks (one launch) and by the reference (in this process):
    CASE-solve.h5 and CASE-reference.h5."""
    folder = tmp_path_factory.mktemp("hard")
    launch([["solve", name, *SMALL, *overrides, "-o", str(folder / f"{case}-solve.h5")]
            for case, (name, overrides) in HARD_CASES.items()], 4, folder)
    for case, (name, overrides) in HARD_CASES.items():
        solved_reference(name, *SMALL, *overrides, "-o", str(folder / f"{case}-reference.h5"))
    return folder


def solved_case(folder: Path, case: str):
    """(result, reference) of the HARD_CASES ``case``."""
    return hdf5.read(folder / f"{case}-solve.h5"), hdf5.read(folder / f"{case}-reference.h5")


@pytest.mark.mpi
@pytest.mark.parametrize("case", ["E-ratio-1e-4", "E-ratio-1e4", "nu-0.49", "nu-0.4999", "crack-almost-all",
                                  "crack-one-element", "no-crack"])
def test_default_method_matches_the_reference_on_hard_cases(hard_cases, case):
    result, reference = solved_case(hard_cases, case)
    assert result.converged and result.solves == 3
    assert analysis.compare(result, reference).energy_error < 1e-6
    assert analysis.constraints(result).penetration < 1e-9


@pytest.mark.mpi
@pytest.mark.parametrize("name", ["full-closure", "full-opening"])
def test_full_closure_and_full_opening(hard_cases, name):
    result, reference = solved_case(hard_cases, name)
    assert analysis.compare(result, reference).energy_error < 1e-6
    crack = result.crack
    if name == "full-closure":
        assert np.all(result.multipliers["mu_c"][crack] > 0)
        assert reference.attrs["closed_vertices"] == crack.sum()
    else:
        assert np.all(result.multipliers["mu_c"][crack] == 0)


@pytest.mark.mpi
def test_load_on_layer_2_only(hard_cases):
    result, reference = solved_case(hard_cases, "layer-2-only")
    assert analysis.compare(result, reference).energy_error < 1e-6
    assert np.abs(result.solution["u_minus"]).max() > 0  # layer 1 moves through the gluing


ZERO_METHODS = ["schur", "mprgp", "fista", "uzawa"]


@pytest.fixture(scope="module")
def zero_loads(tmp_path_factory) -> Path:
    """Partial closure (small) without loads by each of ZERO_METHODS on 2 ranks, one launch: METHOD.h5."""
    folder = tmp_path_factory.mktemp("zero")
    launch([["solve", "partial-closure", *SMALL, "--set", "loads.layer1.bottom.y=[0.0]", "--set",
             "loads.layer1.top.y=[0.0]", "--set", f"solver.method={method}", "-o", str(folder / f"{method}.h5")]
            for method in ZERO_METHODS], 2, folder)
    return folder


@pytest.mark.mpi
@pytest.mark.parametrize("method", ZERO_METHODS)
def test_zero_load_gives_exactly_zero_without_division_by_zero(zero_loads, method):
    result = hdf5.read(zero_loads / f"{method}.h5")
    assert result.converged and result.iterations <= 1
    assert all(np.all(values == 0.0) for values in result.solution.values())
    assert np.all(np.isfinite(result.history))


SCALED_METHODS = ["schur", "mprgp", "fista"]
#: The load factors: exact in floating point (2^±40), and decimal (1e±12).
SCALINGS = {"powers-of-two": (2.0 ** -40, 2.0 ** 40), "decimal": (1e-12, 1e12)}


@pytest.fixture(scope="module")
def scaled_loads(tmp_path_factory) -> dict[tuple[str, float], Path]:
    """Partial closure (small) with its loads scaled by 1 and by each factor of SCALINGS, by each of
    SCALED_METHODS on 4 ranks, one launch: the result paths by (method, factor)."""
    folder = tmp_path_factory.mktemp("scaled")
    factors = [1.0, *(factor for pair in SCALINGS.values() for factor in pair)]
    paths = {(method, factor): folder / f"{method}-{factor:g}.h5" for method in SCALED_METHODS for factor in factors}
    # p = 1e7 (the scene's) would be an active bound at 1e12 × the loads: lift it
    launch([["solve", "partial-closure", *SMALL, "--set", f"solver.method={method}", "--set", "solver.p=1e300",
             "--set", f"loads.layer1.bottom.y=[0.0, {0.078125 * factor!r}]",
             "--set", f"loads.layer1.top.y=[0.0, {-0.078125 * factor!r}]", "-o", str(path)]
            for (method, factor), path in paths.items()], 4, folder)
    return paths


@pytest.mark.mpi
@pytest.mark.parametrize("method", SCALED_METHODS)
@pytest.mark.parametrize("scaling", SCALINGS)
def test_scaled_loads_give_scaled_solutions_in_the_same_iterations(scaled_loads, method, scaling):
    """Scaling by 2^±40 (about 1e±12) is exact in floating point, so every iterate scales exactly and
    the iterations are identical; 1e±12 is not, and a criterion that lands within round-off of the
    tolerance may stop one iteration apart."""
    factors = SCALINGS[scaling]
    results = {factor: hdf5.read(scaled_loads[method, factor]) for factor in (factors[0], 1.0, factors[1])}
    iterations = [r.iterations for r in results.values()]
    exact = factors[1] == 2.0 ** 40
    assert max(iterations) - min(iterations) <= (0 if exact else 1)
    agreement = 1e-12 if method == "schur" or exact else 1e-6  # round-off grown over the iterations
    for factor in factors:
        for name, values in results[1.0].solution.items():
            difference = np.abs(results[factor].solution[name] / factor - values).max()
            assert difference <= agreement * np.abs(values).max()


@pytest.mark.mpi
def test_strongly_graded_and_distorted_mesh(tmp_path):
    """Cells of aspect ratio about 60 at Σ, growing geometrically (×1.6) towards y = ±1."""
    points, cells = structured_square(16, 12)
    ratio, n = 1.6, 12
    heights = (ratio ** np.arange(n + 1) - 1.0) / (ratio ** n - 1.0)
    levels = np.concatenate([-heights[::-1], heights[1:]])
    points[:, 1] = levels[np.round((points[:, 1] + 1.0) * n).astype(int)]
    path = tmp_path / "graded.vtu"
    meshio.write(path, meshio.Mesh(points, [("triangle", cells)]))
    scene_file = tmp_path / "graded.toml"
    scene_file.write_text(scene.builtin_scenes()["partial-closure"].replace(
        "sigma_vertices = 96\nboundary_vertices = 144", f'file = "{path.name}"'))
    lower = geometry.build(scene.load(scene_file)).lower
    p = lower.points[lower.cells]
    edges = np.linalg.norm(p - p[:, [1, 2, 0]], axis=2)
    area = np.abs(lower.areas())
    assert (edges.max(axis=1) ** 2 / (2 * area)).max() > 50  # longest edge / height
    result, reference = solve_and_reference(tmp_path, str(scene_file))
    assert analysis.compare(result, reference).energy_error < 1e-6


@pytest.mark.mpi
def test_uzawa_above_the_stable_bound_with_a_closed_crack(tmp_path):
    completed = ddsolve("solve", "full-closure", "--set", "mesh.sigma_vertices=48", "--set",
                        "mesh.boundary_vertices=80", "--set", "solver.method=uzawa", "-o", str(tmp_path / "x.h5"),
                        ranks=4, check=False)
    assert completed.returncode == 4
    message = completed.stderr.strip()
    iteration = int(message.split("diverged at iteration ")[1].split(":")[0])
    bound = float(message.split("stable bound 2/lambda_max ~ ")[1].split()[0])
    assert iteration < 500 and 50 < bound < 65  # power iteration: 2/lambda_max = 58.1 on this mesh


# --- bad input --------------------------------------------------------------------------------
def one_line_failure(completed: subprocess.CompletedProcess, fragment: str, status: int = 1) -> None:
    assert completed.returncode == status, completed.stderr
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0], completed.stderr
    assert "Traceback" not in completed.stdout + completed.stderr


@pytest.mark.mpi
def test_five_ranks_are_refused_on_every_rank(tmp_path):
    completed = ddsolve("solve", "partial-closure", *SMALL, "-o", str(tmp_path / "x.h5"), ranks=5, check=False)
    one_line_failure(completed, "unsupported number of ranks 5: use 1, 2 or a multiple of 4")


@pytest.mark.mpi
def test_unwritable_output_is_reported_and_all_ranks_exit(tmp_path):
    completed = ddsolve("solve", "partial-closure", *SMALL, "-o", "/proc/ddsolve-result.h5", ranks=4,
                        check=False, timeout=120)
    one_line_failure(completed, "/proc/ddsolve-result.h5: cannot write")


@pytest.mark.mpi
def test_halves_with_different_sigma_vertices_are_rejected(tmp_path):
    points, cells = structured_square(8, 2)
    upper = points[:, 1] > 0
    shifted = points.copy()
    on_sigma = (points[:, 1] == 0) & (np.abs(points[:, 0]) < 1) & (np.abs(points[:, 0]) != 0.5)
    duplicate = np.flatnonzero(on_sigma)
    shifted = np.vstack([points, points[duplicate] + [0.05, 0.0]])  # the upper half's own Σ vertices, moved
    renumber = np.arange(len(points))
    renumber[duplicate] = len(points) + np.arange(len(duplicate))
    upper_cells = np.any(upper[cells], axis=1)
    cells = np.where(upper_cells[:, None], renumber[cells], cells)
    path = tmp_path / "mismatch.vtu"
    meshio.write(path, meshio.Mesh(shifted, [("triangle", cells)]))
    scene_file = tmp_path / "s.toml"
    scene_file.write_text(scene.builtin_scenes()["partial-closure"].replace(
        "sigma_vertices = 96\nboundary_vertices = 144", f'file = "{path.name}"'))
    completed = ddsolve("solve", str(scene_file), ranks=2, check=False)
    one_line_failure(completed, "the Σ nodes of the two halves do not match")


@pytest.mark.mpi
def test_a_block_solver_failing_on_one_rank_stops_every_rank(tmp_path):
    output = tmp_path / "kept.h5"
    output.write_bytes(b"previous")
    completed = ddsolve("solve", "partial-closure", *SMALL, "--set", "solver.method=mprgp", "-o", str(output),
                        "-v_plus_ksp_type", "cg", "-v_plus_pc_type", "none", "-v_plus_ksp_max_it", "2",
                        ranks=4, check=False, timeout=120)
    one_line_failure(completed, "block v_plus: cg solve did not converge (DIVERGED_MAX_IT -3)")
    assert output.read_bytes() == b"previous"


@pytest.mark.mpi
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_stops_every_rank_promptly_and_keeps_the_previous_file(tmp_path, signum):
    from experiments.robustness import interrupt

    outcome = interrupt(tmp_path, signum)
    assert outcome["running"] and outcome["status"] != 0 and not outcome["traceback"]
    assert outcome["seconds"] < 10.0
    assert outcome["kept"] and outcome["leftovers"] == []


# --- fuzzing the scene parser -----------------------------------------------------------------
KEYS = ["title", "geometry.crack", "mesh.sigma_vertices", "mesh.boundary_vertices", "mesh.file",
        "materials.layer1.E", "materials.layer2.nu", "loads.layer1.bottom.y", "loads.layer2.top.x",
        "contact.nonpenetration", "solver.method", "solver.theta", "solver.p", "solver.tol", "solver.stop",
        "solver.max_iterations", "solver", "materials", "loads.layer1", "nope", "solver.nope", ""]
VALUES = st.one_of(st.integers(-10**6, 10**6).map(str), st.floats(allow_nan=True).map(repr),
                   st.sampled_from(["true", "false", "[]", "[1, 2]", "[-0.5, 0.5]", "[0.5, -0.5]", "{}",
                                    "\"uzawa\"", "uzawa", "mprgp", "kkt", "paper", "inf", "nan", "[1, \"a\"]",
                                    "1e400", "-0", "=", "[[1]]"]),
                   st.text(max_size=12))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(KEYS), VALUES), max_size=5))
def test_overrides_never_raise_anything_but_scene_errors(pairs):
    overrides = [f"{key}={value}" for key, value in pairs]
    try:
        scene.load("partial-closure", overrides)
    except SceneError as error:
        assert "\n" not in str(error)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=200))
def test_arbitrary_text_never_raises_anything_but_scene_errors(text):
    try:
        scene.loads(text)
    except SceneError as error:
        assert "\n" not in str(error)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(scene.builtin_scenes()["partial-closure"].splitlines()), max_size=40))
def test_shuffled_scene_lines_never_raise_anything_but_scene_errors(lines):
    try:
        scene.loads("\n".join(lines))
    except SceneError as error:
        assert "\n" not in str(error)
