"""``ddsolve sweep``: ranges, combinations, list indices in keys, reuse of meshes and factorizations, the
file of every run, failures recorded, bad input in one line."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import ddsolve

from ddsolve.errors import SceneError
from ddsolve.io import hdf5
from ddsolve.problem import scene
from ddsolve.solvers import sweep

SMALL = ["--set", "mesh.sigma_vertices=25", "--set", "mesh.boundary_vertices=48"]


def test_ranges_and_fixed_values():
    fixed, ranges = sweep.parse(["solver.tol=1e-10", "materials.layer2.E=1:100:3:log", "mesh.sigma_vertices=49:193:4",
                                 "geometry.crack.0=-0.2:-0.8:4", 'title="a:b:3"'])
    assert fixed == ["solver.tol=1e-10", 'title="a:b:3"']
    assert [r.key for r in ranges] == ["materials.layer2.E", "mesh.sigma_vertices", "geometry.crack.0"]
    assert ranges[0].values == pytest.approx((1.0, 10.0, 100.0))
    assert ranges[1].values == (49, 97, 145, 193) and all(isinstance(v, int) for v in ranges[1].values)
    assert ranges[2].values == pytest.approx((-0.2, -0.4, -0.6, -0.8))
    assert sweep.parse(["loads.layer1.top.y=0.5:0.5:1"])[1][0].values == (0.5,)
    assert sweep.parse(["mesh.sigma_vertices=16:64:3:log"])[1][0].values == (16, 32, 64)  # integers stay integers
    uneven = sweep.parse(["mesh.sigma_vertices=24:25:4"])[1][0].values
    assert uneven == pytest.approx((24, 24 + 1 / 3, 24 + 2 / 3, 25)) and [type(v) for v in uneven] == [int, float,
                                                                                                        float, int]


@pytest.mark.parametrize("item, message", [
    ("materials.layer2.E=0:100:3:log", "a log range needs START > 0"),
    ("materials.layer2.E=1:100:0", "COUNT must be at least 1"),
    ("materials.layer2.E=abc:200:3", r"=abc:200:3: not a range START:STOP:COUNT\[:log\]"),  # alone: not a value
    ("materials.layer2.E=100:200", "not a range START:STOP:COUNT"),
])
def test_bad_ranges(item, message):
    with pytest.raises(SceneError, match=message):
        sweep.parse([item])


def test_the_apis_values_are_a_non_empty_list():
    assert sweep.given_range("a", np.array([1.0, 2.0])).values == (1.0, 2.0)
    for values in ([], 100.0, "100"):
        with pytest.raises(SceneError, match="a: a sweep takes a non-empty list of values"):
            sweep.given_range("a", values)


def test_every_combination_or_side_by_side():
    ranges = [sweep.Range("a", (1, 2)), sweep.Range("b", (10, 20, 30))]
    assert sweep.plan(ranges, paired=False) == [{"a": 1, "b": 10}, {"a": 1, "b": 20}, {"a": 1, "b": 30},
                                                {"a": 2, "b": 10}, {"a": 2, "b": 20}, {"a": 2, "b": 30}]
    assert sweep.plan([sweep.Range("a", (1, 2)), sweep.Range("b", (10, 20))], paired=True) == \
        [{"a": 1, "b": 10}, {"a": 2, "b": 20}]
    with pytest.raises(SceneError, match=r"--zip: the ranges must have the same COUNT \(a: 2, b: 3\)"):
        sweep.plan(ranges, paired=True)
    with pytest.raises(SceneError, match="no range to sweep"):
        sweep.plan([], paired=False)
    with pytest.raises(SceneError, match="swept twice"):
        sweep.parse(["a.b=1:2:2", "a.b=3:4:2"])


def test_a_number_in_a_key_indexes_a_list():
    assert scene.load("partial-closure", ["geometry.crack.1=0.6"]).geometry.cracks == ((-0.5, 0.6),)
    two = scene.loads('[geometry]\nbox = [0.0, 4.0, -1.0, 1.0]\ncracks = [[1.0, 2.0], [2.5, 3.0]]\n[mesh]\nsize = 0.5\n'
                      '[materials.layer1]\nE = 1.0\nnu = 0.3\n[materials.layer2]\nE = 1.0\nnu = 0.3\n',
                      ["geometry.cracks.1.0=2.2"])
    assert two.geometry.cracks == ((1.0, 2.0), (2.2, 3.0))
    with pytest.raises(SceneError, match=r"geometry\.crack is a list of 2; 2 is not an index into it \(0 to 1\)"):
        scene.load("partial-closure", ["geometry.crack.2=0.6"])
    with pytest.raises(SceneError, match=r"the scene has no geometry\.cracks to index"):
        scene.load("partial-closure", ["geometry.cracks.0.1=0.6"])


@pytest.mark.mpi
def test_loads_sweep_reuses_the_factorization(tmp_path):
    """Only loads change: one mesh, one factorization; G scales with the load squared; the middle run equals a
    separate solve; one progress line per run."""
    out = tmp_path / "loads.h5"
    run = ddsolve("sweep", "full-opening", *SMALL, "--set", "loads.layer1.top.y=0.05:0.15:3",
                  "--set", "loads.layer1.bottom.y=-0.05:-0.15:3", "--zip", "-o", str(out), ranks=2)
    assert run.stdout.count("sweep 1/3") == 1 and "sweep 3/3" in run.stdout
    assert "(mesh and factorization reused)" in run.stdout
    data = sweep.read(out)
    assert data["attrs"]["complete"] and data["attrs"]["mode"] == "zip" and data["attrs"]["runs"] == 3
    assert data["converged"].all() and not any(data["message"])
    assert data["mesh_reused"].tolist() == [False, True, True] == data["factors_reused"].tolist()
    assert data["factorization_time"][1:].tolist() == [0.0, 0.0]
    np.testing.assert_allclose(data["parameters/loads.layer1.top.y"], [0.05, 0.1, 0.15])
    G = data["tips/G"]
    np.testing.assert_allclose(G / G[0], np.array([[1.0], [4.0], [9.0]]) * np.ones((1, 2)), rtol=1e-8)
    ddsolve("solve", "full-opening", *SMALL, "--set", "loads.layer1.top.y=0.1", "--set", "loads.layer1.bottom.y=-0.1",
            "-o", str(tmp_path / "one.h5"), ranks=2)
    single = hdf5.read(tmp_path / "one.h5")
    np.testing.assert_allclose(G[1], single.fracture.G, rtol=1e-10)
    assert data["energy"][1] == pytest.approx(single.attrs["energy"], rel=1e-10)


@pytest.mark.mpi
def test_geometry_sweep_remeshes(tmp_path):
    """A crack growing at both ends: a new mesh per run, tips where the crack ends are, G of each run equal to
    a separate solve, contact zones recorded per run."""
    out = tmp_path / "length.h5"
    ddsolve("sweep", "partial-closure", *SMALL, "--set", "geometry.crack.0=-0.3:-0.5:2",
            "--set", "geometry.crack.1=0.3:0.5:2", "--zip", "-o", str(out), ranks=4)
    data = sweep.read(out)
    assert data["mesh_reused"].tolist() == [False, False]
    np.testing.assert_allclose(data["tips/points"][:, :, 0], [[-0.3, 0.3], [-0.5, 0.5]])
    ddsolve("solve", "partial-closure", *SMALL, "--set", "geometry.crack=[-0.3, 0.3]", "-o", str(tmp_path / "a.h5"),
            ranks=4)
    np.testing.assert_allclose(data["tips/G"][0], hdf5.read(tmp_path / "a.h5").fracture.G, rtol=1e-10, atol=1e-18)
    assert sorted(set(data["contact_zones/run"].tolist())) == [0, 1]


@pytest.mark.mpi
def test_a_sweep_without_non_penetration_records_overlaps_not_contact(tmp_path):
    """The linear problem's faces overlap on the right part of the crack in every run: overlap zones, no
    contact zones."""
    out = tmp_path / "linear.h5"
    ddsolve("sweep", "linear", *SMALL, "--set", "materials.layer2.E=100:200:2", "-o", str(out), ranks=2)
    data = sweep.read(out)
    assert data["contact_zones/run"].size == 0 and data["overlap_zones/run"].tolist() == [0, 1]
    assert np.all(data["overlap_zones/start"] < data["overlap_zones/end"])


@pytest.mark.mpi
def test_a_failed_run_is_recorded_and_the_sweep_goes_on(tmp_path):
    out = tmp_path / "short.h5"
    run = ddsolve("sweep", "partial-closure", *SMALL, "--set", "solver.method=uzawa",
                  "--set", "solver.max_iterations=3", "--set", "materials.layer2.E=100:200:2", "-o", str(out), ranks=2)
    assert run.stdout.count("NOT converged") == 2 and "2 runs (0 converged)" in run.stdout
    data = sweep.read(out)
    assert not data["converged"].any() and all("no convergence in 3 iterations" in m for m in data["message"])
    assert np.isfinite(data["tips/G"]).all()


@pytest.mark.mpi
@pytest.mark.parametrize("arguments, message", [
    (["--set", "geometry.crack.1=0.5:1.5:3"], "sweep run 3 (geometry.crack.1=1.5): partial-closure: "
                                              "geometry.crack: the crack [-0.5, 1.5] leaves the box"),
    (["--set", "mesh.sigma_vertices=24:25:4"], "sweep run 2 (mesh.sigma_vertices=24.3333): partial-closure: "
                                                "mesh.sigma_vertices must be an integer (got 24.33"),
    (["--set", "solver.tol=1e-9"], "sweep: no range to sweep; give --set KEY=START:STOP:COUNT"),
    (["--set", "a.b=1:2:2", "--set", "c.d=1:2:3", "--zip"], "--zip: the ranges must have the same COUNT"),
    (["--set", "materials.layer2.E=1:2:2", "-o", "missing/x.h5"], "missing/x.h5: output directory missing does not"),
])
def test_bad_input_is_one_line(tmp_path, arguments, message):
    out = tmp_path / "bad.h5"
    run = ddsolve("sweep", "partial-closure", *SMALL, "-o", str(out), *arguments, ranks=2, check=False)
    assert run.returncode == 1 and not out.exists()
    (line,) = run.stderr.strip().splitlines()
    assert line.startswith("ddsolve: error: " + message)
