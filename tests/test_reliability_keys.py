"""Issue 21, classes 4 and 7 (keys): work that cannot finish is refused up front with its estimate
(sweep counts and durations, adaptive targets), and every scene key a command is given is honoured or
refused in one line naming it (solve, reference, sweep and mesh over every key of the schema).

Run as a script (``python tests/test_reliability_keys.py COMMAND FOLDER``) it runs one command over
every key in one process and prints a JSON line per case: the exit status, standard error and a digest
of what the command did (its numbers, not the scene text it copies).
"""
from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io as text_io
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

ROOT = Path(__file__).resolve().parents[1]
SMALL = ["mesh.sigma_vertices=13", "mesh.boundary_vertices=32"]
SET_SMALL = [word for item in SMALL for word in ("--set", item)]
#: The commands that read a scene.
COMMANDS = ("solve", "reference", "sweep", "mesh")
ORTHOTROPIC = {"E1": "200.0", "E2": "100.0", "G12": "60.0", "nu12": "0.3"}
ANISOTROPIC = {"D": "[[280.0, 100.0, 0.0], [100.0, 280.0, 0.0], [0.0, 0.0, 90.0]]"}


def _table(layer: str, base: dict, key: str | None = None, value: str | None = None) -> str:
    """``materials.LAYER={...}`` with ``key`` (first, so that a refusal names it) set to ``value``."""
    entries = ({key: value} if key else {}) | {k: v for k, v in base.items() if k != key}
    return f"materials.{layer}={{{', '.join(f'{k}={v}' for k, v in entries.items())}}}"


def cases(folder: Path) -> list[tuple[str, list[str], list[str]]]:
    """(key, context overrides, overrides setting the key to a valid non-default value) for every leaf
    key of the scene schema; the context (kept when the command reads it) is the baseline's."""
    uzawa = ['solver.method="uzawa"']
    out = [("title", [], ['title="keys"']),
           ("geometry.box", [], ["geometry.box=[-1.0, 1.0, -1.0, 1.5]"]),
           ("geometry.sigma", [], ["geometry.sigma=0.25"]),
           ("geometry.crack", [], ["geometry.crack=[-0.5, 0.25]"]),
           ("geometry.cracks", [], ["geometry.cracks=[[-0.5, -0.25], [0.25, 0.5]]"]),
           ("geometry.clamped", [], ['geometry.clamped=["left"]']),
           ("geometry.layers", [], ["geometry.layers=1"]),  # refused: the scene's layer2 tables (test_one_layer.py)
           ("mesh.file", ["geometry={}"], [f'mesh.file="{folder / "other.msh"}"']),
           ("mesh.sigma_vertices", [], ["mesh.sigma_vertices=15"]),
           ("mesh.boundary_vertices", [], ["mesh.boundary_vertices=36"]),
           ("mesh.size", [], ["mesh.size=0.5"]),
           ("mesh.degree", [], ["mesh.degree=2"]),
           ("mesh.grading", ["mesh.size=0.5"], ["mesh.grading=true"]),
           ("mesh.target_error", [], ["mesh.target_error=0.25"]),
           ("mesh.refine", ["mesh.sigma_vertices=25"], ["mesh.refine=1"]),
           ("mesh.extrude", [], ["mesh.extrude=2"]),  # refused in the plane
           ("materials.model", [], ['materials.model="plane_stress"']),
           ("materials.layer1.E", [], ["materials.layer1.E=150.0"]),
           ("materials.layer2.nu", [], ["materials.layer2.nu=0.2"])]
    heated = ["temperature.layer1=100.0"]
    laws = [(ORTHOTROPIC, [], {"E1": "300.0", "E2": "120.0", "G12": "50.0", "nu12": "0.25", "angle": "30.0",
                               "E3": "150.0", "nu13": "0.2", "nu23": "0.2",
                               "fibre": "[1.0, 0.0, 0.0]"}),  # refused in the plane
            (ANISOTROPIC, [], {"D": "[[300.0, 80.0, 0.0], [80.0, 250.0, 0.0], [0.0, 0.0, 90.0]]",
                               "Dzz": "[100.0, 100.0, 0.0]"}),
            *((ORTHOTROPIC | {other: "2e-5"}, heated, {key: "1e-5"})  # a heated layer gives an expansion
              for key, other in (("alpha1", "alpha2"), ("alpha2", "alpha1")))]
    for base, extra, values in laws:  # each key of each kind, on the layer and on a region of it
        for key, value in values.items():
            context = [_table("layer1", base), *extra]
            out.append((f"materials.layer1.{key}", context, [_table("layer1", base, key, value)]))
            out.append((f"materials.layer1.upper.{key}", context, [_table("layer1.upper", base, key, value)]))
    out += [("materials.layer1.upper.E", [], ["materials.layer1.upper.E=150.0"]),
            ("materials.layer2.lower.nu", [], ["materials.layer2.lower.nu=0.2"]),
            ("materials.layer1.upper.alpha", ["materials.layer1.alpha=2e-5", *heated],
             ["materials.layer1.upper.alpha=1e-5"])]
    out += [("materials.layer1.alpha", ["materials.layer1.alpha=2e-5", *heated], ["materials.layer1.alpha=1e-5"]),
            ("temperature.layer1", ["materials.layer1.alpha=1e-5"], ["temperature.layer1=50.0"]),
            ("displacements.layer1.top.x", [], ["displacements.layer1.top.x=0.001"]),
            ("displacements.layer1.top.y", [], ["displacements.layer1.top.y=0.001"]),
            ("displacements.layer1.top.z", [], ["displacements.layer1.top.z=0.001"]),  # refused in the plane
            ("displacements.layer1.top.normal", [], ["displacements.layer1.top.normal=0.001"]),
            ("displacements.layer1.pin.point", [], ["displacements.layer1.pin={point=[0.5, 1.0], x=0.001}"])]
    out += [("loads.layer1.top.x", [], ["loads.layer1.top.x=0.01"]),
            ("loads.layer1.top.y", [], ["loads.layer1.top.y=[0.0, -0.05]"]),
            ("loads.layer1.top.z", [], ["loads.layer1.top.z=0.01"]),  # refused in the plane
            ("loads.layer2.top.pressure", [], ["loads.layer2.top.pressure=0.01"]),
            ("contact.nonpenetration", [], ["contact.nonpenetration=false"]),
            ("contact.friction", [], ["contact.friction=0.5"]),
            ("contact.slip_bound", [], ["contact.slip_bound=0.05"]),
            ("solver.method", [], uzawa),
            ("solver.theta", uzawa, ["solver.theta=30.0"]),
            ("solver.p", [], ["solver.p=0.01"]),
            ("solver.tol", [], ["solver.tol=1e-3"]),
            ("solver.stop", uzawa, ['solver.stop="relative"']),
            ("solver.max_iterations", uzawa, ["solver.max_iterations=5"]),
            ("solver.out_of_core", [], ["solver.out_of_core=true"]),
            ("solver.pieces", [], ["solver.pieces=2"]),  # refused in the plane
            ("solver.preconditioner", [], ['solver.preconditioner="lumped"']),  # refused in the plane
            ("solver.coarse_degree", ['solver.method="feti"'], ["solver.coarse_degree=2"]),
            ("fracture.inner", [], ["fracture.inner=0.1"]),
            ("fracture.outer", [], ["fracture.outer=0.3"]),
            ("fracture.toughness", [], ["fracture.toughness=1e-4"])]
    kenane = ['fracture.law="benzeggagh-kenane"', "fracture.G_Ic=1e-4", "fracture.G_IIc=3e-4", "fracture.eta=1.0"]
    suo = ['fracture.law="hutchinson-suo"', "fracture.G_Ic=1e-4", "fracture.lambda=0.3"]
    out += [("fracture.law", [], kenane), ("fracture.G_Ic", kenane, ["fracture.G_Ic=2e-4"]),
            ("fracture.G_IIc", kenane, ["fracture.G_IIc=5e-4"]), ("fracture.eta", kenane, ["fracture.eta=2.0"]),
            ("fracture.lambda", suo, ["fracture.lambda=0.6"])]
    elastic = ['interface.law="elastic"', "interface.stiffness=1e3"]
    bilinear = ['interface.law="bilinear"', "interface.strength=0.01", "interface.toughness=1e-4"]  # damage 0.4
    sheared = [*bilinear, "loads.layer1.top.x=0.05"]  # damage 0.7 in both modes: each mixed-mode key shows
    mixing = ['interface.mode_mix="benzeggagh-kenane"', "interface.G_IIc=3e-4", "interface.eta=1.0",
              "interface.shear_strength=0.005"]
    mixed = [*sheared, *mixing]
    out += [("interface.law", [], elastic), ("interface.stiffness", elastic, ["interface.stiffness=1e4"]),
            ("interface.strength", bilinear, ["interface.strength=0.02"]),
            ("interface.toughness", bilinear, ["interface.toughness=1e-5"]),
            ("interface.mode_mix", sheared, mixing), ("interface.G_IIc", mixed, ["interface.G_IIc=3e-2"]),
            ("interface.eta", mixed, ["interface.eta=2.0"]),
            ("interface.shear_strength", mixed, ["interface.shear_strength=0.02"])]
    interface = ["materials.layer2.nu=0.28", "materials.layer1.upper.E=2000.0", "materials.layer2.upper.E=1120.0"]
    out += [("fracture.reference_length", interface + suo, ["fracture.reference_length=0.01"])]  # ψ, so G_c
    return out


def schema_leaves() -> set[str]:
    """Every leaf key of the schema (load tables under one boundary name, each material kind)."""
    from ddsolve.problem import scene

    def walk(schema: dict, path: tuple[str, ...], kinds=({"E": 1, "nu": 0}, {"E1": 1}, {"D": 1})):
        for key, spec in schema.items():
            if isinstance(spec, tuple):
                yield ".".join((*path, key))
            elif isinstance(spec, scene.Tables):
                yield from walk(spec.schema, (*path, key, "NAME"))
            elif isinstance(spec, dict):
                yield from walk(spec, (*path, key))
            else:  # a material: every kind; its regions' tables: the layer's kind
                for kind in kinds:
                    yield from walk(spec(kind), (*path, key), (kind,))

    return set(walk(scene.SCHEMA, ()))


# --- the script: one command over every case, in one process ----------------------------------------
def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for array in arrays:
        h.update(np.ascontiguousarray(np.round(np.asarray(array, dtype=float), 10)).tobytes())
    return h.hexdigest()[:16]


def observe(command: str, output: Path, stdout: str) -> dict:
    """What the command did: the numbers of its result (not the scene text it copies)."""
    if command == "mesh":
        return {"table": stdout, "msh": hashlib.sha256(output.read_bytes()).hexdigest()[:16]}
    if command == "sweep":
        from ddsolve.solvers import sweep

        data = sweep.read(output)
        timing = {"time", "setup_time", "factorization_time", "solve_time", "attrs", "message"}
        return {name: _digest(value) for name, value in sorted(data.items()) if name not in timing} | \
            {"message": [str(m) for m in data["message"]]}
    from ddsolve.io import hdf5
    from ddsolve.post import analysis
    result = hdf5.read(output)
    fields = analysis.cell_fields(result)
    return {"title": result.scene.title, "method": result.method, "converged": bool(result.converged),
            "iterations": int(result.iterations), "points": len(result.lower.points) + len(result.upper.points),
            "energy": _digest(result.attrs.get("energy", np.nan)), "kkt_tolerance": float(result.attrs.get("kkt_tolerance", 0)),
            "out_of_core": bool(result.attrs.get("factors_out_of_core", False)),  # memory, not numbers
            "solution": _digest(*result.solution.values(), *result.multipliers.values()),
            "fields": _digest(*(np.r_[f.strain_zz, f.stress_zz] for f in fields.values())),
            "G": _digest(*(result.fracture.G, result.fracture.inner, result.fracture.outer, result.fracture.toughness,
                           result.fracture.critical_factor) if result.fracture is not None else [])}


def run_command(command: str, overrides: list[str], folder: Path, name: str) -> dict:
    from ddsolve.cli import main

    output = folder / f"{name}.{'msh' if command == 'mesh' else 'h5'}"
    output.unlink(missing_ok=True)
    arguments = [command, "partial-closure", *SET_SMALL, *(w for item in overrides for w in ("--set", item))]
    if command == "sweep":  # a range of one run at the scene's own value
        arguments += ["--set", "materials.layer2.E=112.0:112.0:1"]
    out, err = text_io.StringIO(), text_io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main([*arguments, "-o", str(output)])
    record = {"status": status, "stderr": err.getvalue()}
    if status in (0, 3) and output.exists():
        record["observed"] = observe(command, output, out.getvalue())
    return record


def script(command: str, folder: Path) -> None:
    import threading

    threading.excepthook = lambda _: None  # the interrupt watchers of earlier commands in this process
    run_command("mesh", ["mesh.sigma_vertices=9", "mesh.boundary_vertices=24"], folder, "other")
    baselines: dict[tuple, dict] = {}

    def baseline(context: list[str]) -> dict:
        if tuple(context) not in baselines:
            baselines[tuple(context)] = run_command(command, context, folder, f"base{len(baselines)}")
        return baselines[tuple(context)]

    for number, (key, context, overrides) in enumerate(cases(folder)):
        if baseline(context)["status"] != 0:  # the command refuses the context: the key alone
            context = []
        case = run_command(command, context + overrides, folder, f"case{number}")
        print(json.dumps({"key": key, "baseline": baseline(context), "case": case}), flush=True)


# --- the tests --------------------------------------------------------------------------------------
def ddsolve_run(arguments: list[str], folder: Path, timeout: float = 120, memory: int | None = None
                ) -> tuple[subprocess.CompletedProcess, float]:
    """``python -m ddsolve ARGUMENTS`` in ``folder`` (serial), optionally within ``memory`` bytes of address space."""
    def limit() -> None:
        if memory is not None:
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    started = time.perf_counter()
    completed = subprocess.run([sys.executable, "-m", "ddsolve", *arguments], capture_output=True, text=True,
                               timeout=timeout, cwd=folder, stdin=subprocess.DEVNULL, preexec_fn=limit,
                               env={**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"})
    return completed, time.perf_counter() - started


def refused(completed: subprocess.CompletedProcess, *names: str) -> str:
    """The one line of a refusal (exit 1, no traceback) that names every one of ``names``."""
    lines = completed.stderr.strip().splitlines()
    assert completed.returncode == 1, completed.stderr
    assert len(lines) == 1 and lines[0].startswith("ddsolve: error: "), completed.stderr
    assert "Traceback" not in completed.stdout + completed.stderr
    for name in names:
        assert name in lines[0], lines[0]
    return lines[0]


@pytest.mark.mpi
@pytest.mark.parametrize("ranges, names", [
    (["materials.layer2.E=1:100:1000000"], ["--set materials.layer2.E=1:100:1000000", "1,000,000 runs"]),
    (["materials.layer2.E=1:100:1000000000"], ["--set materials.layer2.E=1:100:1000000000", "1,000,000,000 runs"]),
    (["materials.layer2.E=1:100:200", "loads.layer1.top.x=0:1:100"],
     ["--set materials.layer2.E=1:100:200 x --set loads.layer1.top.x=0:1:100", "20,000 runs"]),
    (["materials.layer2.E=1:100:" + "9" * 40], ["about 1e+40 runs"]),
])
def test_a_sweep_of_too_many_runs_is_refused_at_once_with_its_estimate(tmp_path, ranges, names):
    arguments = ["sweep", "partial-closure", *SET_SMALL, *(w for r in ranges for w in ("--set", r)), "-o", "s.h5"]
    completed, elapsed = ddsolve_run(arguments, tmp_path, timeout=60, memory=3 * 2 ** 30)  # no 8 GB of values
    line = refused(completed, *names)
    assert "more than the 10,000 a sweep makes" in line and "would take at least about" in line
    assert elapsed < 30 and not (tmp_path / "s.h5").exists()


def test_a_sweep_estimated_beyond_a_day_is_refused_naming_its_ranges():
    from ddsolve.errors import SceneError
    from ddsolve.problem import materials, scene
    from ddsolve.solvers import sweep

    base = scene.load("partial-closure", ["mesh.sigma_vertices=800", "mesh.boundary_vertices=1024"])
    values = tuple(float(v) for v in np.linspace(1.0, 2.0, 9500))
    scenes = [dataclasses.replace(base, materials={**base.materials, "layer2": materials.Isotropic(E=v, nu=0.3)})
              for v in values]
    ranges = [sweep.Range("materials.layer2.E", values, "materials.layer2.E=1:2:9500")]
    runs = sweep.plan(ranges, paired=False)
    with pytest.raises(SceneError, match=r"^--set materials.layer2.E=1:2:9500: 9,500 runs would take at least about "
                                         r"\d+ h .*more than the 24 h a sweep may take"):
        sweep.check_cost(["materials.layer2.E=1:2:9500"], scenes, runs, ranges, 1)
    sweep.check_cost(["materials.layer2.E=1:2:9500"], scenes[:100], runs[:100], ranges, 1)  # 100 runs: fine


@pytest.mark.mpi
def test_a_sweep_whose_mesh_does_not_fit_is_refused_naming_the_run(tmp_path):
    completed, elapsed = ddsolve_run(["sweep", "partial-closure", "--set", "mesh.sigma_vertices=1000000000", "--set",
                                      "mesh.boundary_vertices=400000000", "--set", "materials.layer2.E=1:2:2"], tmp_path)
    refused(completed, "sweep run 1 (materials.layer2.E=1)", "mesh.sigma_vertices = 1000000000", "GB")
    assert elapsed < 60


@pytest.mark.mpi
@pytest.mark.parametrize("command", ["solve", "reference"])
@pytest.mark.parametrize("degree, target", [(1, "1e-12"), (2, "1e-09")])
def test_an_adaptive_target_out_of_reach_is_refused_after_the_first_level(tmp_path, command, degree, target):
    previous = tmp_path / "t.h5"
    previous.write_bytes(b"previous result")
    completed, elapsed = ddsolve_run([command, "partial-closure", *SET_SMALL, "--set", f"mesh.degree={degree}",
                                      "--set", f"mesh.target_error={target}", "-o", "t.h5"], tmp_path)
    line = refused(completed, f"mesh.target_error = {target} refused: it needs about", f"with P{degree}")
    assert "the smallest target in reach is about" in line
    assert elapsed < 60 and previous.read_bytes() == b"previous result"
    assert completed.stdout.count("level ") == 1


def test_the_prediction_uses_the_best_rate_of_the_element_degree():
    from ddsolve.solvers import adapt

    assert adapt.needed_unknowns(560, 0.325, 0.00325, 1) == pytest.approx(560 * 1e4)  # N^-1/2
    assert adapt.needed_unknowns(560, 0.325, 0.00325, 2) == pytest.approx(560 * 1e2)  # N^-1
    assert 0 < adapt.largest_level(4) <= adapt.MAX_UNKNOWNS


@pytest.mark.mpi
def test_reference_honours_target_error_with_its_own_levels(tmp_path):
    from ddsolve.io import hdf5

    completed, _ = ddsolve_run(["reference", "partial-closure", *SET_SMALL, "--set", "mesh.degree=1", "--set",
                                "mesh.target_error=0.2", "-o", "r.h5"], tmp_path)
    assert completed.returncode == 0, completed.stderr
    result = hdf5.read(tmp_path / "r.h5")
    assert result.method == "reference" and result.attrs["levels"] >= 2
    assert result.attrs["error_estimate"] <= 0.2 and len(result.levels["unknowns"]) == result.attrs["levels"]


@pytest.mark.mpi
def test_reference_refuses_a_multiplier_bound_and_solves_without_one(tmp_path):
    """The reference imposes no bound on the multipliers: a --set solver.p is refused naming it; the scene
    file's own p (the paper's 1e7) does not stop it, even where the multipliers exceed it."""
    completed, _ = ddsolve_run(["reference", "partial-closure", *SET_SMALL, "--set", "solver.p=0.001", "-o", "c.h5"],
                               tmp_path)
    refused(completed, "solver.p is not read by reference", "without a bound")
    assert not (tmp_path / "c.h5").exists()
    loud, _ = ddsolve_run(["reference", "partial-closure", *SET_SMALL, "--set", "loads.layer1.top.y=[0.0, -1e10]",
                           "-o", "d.h5"], tmp_path)
    assert loud.returncode == 0, loud.stderr


@pytest.mark.mpi
@pytest.mark.parametrize("command, item, names", [
    ("reference", "solver.tol=1e-3", ["--set solver.tol=1e-3", "solver.tol is not read by reference", "solve and sweep"]),
    ("reference", 'solver.method="uzawa"', ["solver.method is not read by reference"]),
    ("solve", "solver.theta=10", ["solver.theta is not read by solve", "method uzawa"]),
    ("solve", 'solver={method="schur", max_iterations=10}', ["solver.max_iterations is not read by solve", "schur"]),
    ("mesh", "materials.layer1.E=10", ["materials.layer1.E is not read by mesh"]),
    ("mesh", "mesh.target_error=0.1", ["mesh.target_error is not read by mesh"]),
    ("mesh", "solver={theta=3.0}", ["solver.theta is not read by mesh"]),
])
def test_a_key_the_command_does_not_read_is_refused_naming_it(tmp_path, command, item, names):
    completed, _ = ddsolve_run([command, "partial-closure", *SET_SMALL, "--set", item,
                                "-o", "k.msh" if command == "mesh" else "k.h5"], tmp_path)
    refused(completed, *names)
    assert not any(tmp_path.iterdir())


@pytest.mark.mpi
def test_dzz_is_refused_in_plane_stress_which_has_no_out_of_plane_stress(tmp_path):
    completed, _ = ddsolve_run(["solve", "partial-closure", *SET_SMALL, "--set", 'materials.model="plane_stress"',
                                "--set", "materials.layer2={D=[[200.0, 50.0, 0.0], [50.0, 200.0, 0.0], [0.0, 0.0, 80.0]], "
                                "Dzz=[1.0, 1.0, 0.0]}", "-o", "k.h5"], tmp_path)
    refused(completed, "materials.layer2.Dzz is not read by solve", "plane_stress")


@pytest.mark.mpi
def test_sweep_honours_target_error(tmp_path):
    from ddsolve.solvers import sweep

    for name, extra in (("plain.h5", []), ("adaptive.h5", ["--set", "mesh.target_error=0.2"])):
        completed, _ = ddsolve_run(["sweep", "partial-closure", *SET_SMALL, *extra, "--set",
                                    "materials.layer2.E=100:200:2", "-o", name], tmp_path)
        assert completed.returncode == 0, completed.stderr
    plain, adaptive = sweep.read(tmp_path / "plain.h5"), sweep.read(tmp_path / "adaptive.h5")
    assert (adaptive["unknowns"] > plain["unknowns"]).all() and not adaptive["mesh_reused"].any()


def test_the_cases_cover_every_key_of_the_schema(tmp_path):
    covered = {key.replace("layer2", "layer1").replace(".lower.", ".upper.") for key, _, _ in cases(tmp_path)}
    expected = {key.replace("layer2", "layer1").replace(".lower.", ".upper.").replace(".NAME.point", ".pin.point")
                .replace(".NAME", ".top") for key in schema_leaves()}
    assert expected == covered


@pytest.mark.mpi
@pytest.mark.parametrize("command", COMMANDS)
def test_every_key_is_honoured_or_refused_naming_it(tmp_path, command):
    """Each command over every key of the schema (P = 13, serial, one process): the key changes what the
    command does (its numbers, its mesh, its title), or the command refuses it in one line naming it."""
    completed = subprocess.run([sys.executable, __file__, command, str(tmp_path)], capture_output=True, text=True,
                               timeout=600, cwd=tmp_path, stdin=subprocess.DEVNULL,
                               env={**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"})
    assert completed.returncode == 0, completed.stderr[-3000:]
    records = [json.loads(line) for line in completed.stdout.splitlines()]
    assert len(records) == len(cases(tmp_path))
    ignored = []
    for record in records:
        key, baseline, case = record["key"], record["baseline"], record["case"]
        assert baseline["status"] == 0, (key, baseline["stderr"])
        errors = [line for line in case["stderr"].splitlines() if line.startswith("ddsolve: error: ")]
        if case["status"] in (0, 3):
            if case.get("observed") == baseline.get("observed"):
                ignored.append(key)
        else:
            assert case["status"] == 1 and len(errors) == 1 and key in errors[0], (key, case["stderr"])
            assert "Traceback" not in case["stderr"], (key, case["stderr"])
    assert ignored == [], f"{command} ignores {ignored}"


# --- the generator that would have found these bugs ------------------------------------------------
@settings(max_examples=60, deadline=None)
@given(counts=st.lists(st.integers(1, 10 ** 12), min_size=1, max_size=4), paired=st.booleans())
def test_sweeps_of_any_count_are_planned_or_refused_without_being_made(counts, paired):
    """Any COUNTs: either at most MAX_RUNS runs are planned, or SceneError names every range, with
    nothing the size of the count ever made (the address space is not touched)."""
    from ddsolve.errors import SceneError
    from ddsolve.solvers import sweep

    items = [f"k{i}.v=1:2:{count}" for i, count in enumerate(counts)]
    total = counts[0] if paired else int(np.prod([float(c) for c in counts]))
    try:
        fixed, ranges = sweep.parse(items, 0.1)
        runs = sweep.plan(ranges, paired, 0.1)
    except SceneError as error:
        text = str(error)
        assert "\n" not in text
        assert "--zip" in text or ("more than the 10,000" in text and "at least about" in text)
        assert "--zip" in text or max(counts) > sweep.MAX_RUNS or total > sweep.MAX_RUNS
        return
    assert fixed == [] and len(runs) <= sweep.MAX_RUNS


@settings(max_examples=40, deadline=None)
@given(key=st.sampled_from(sorted({"title", "mesh.target_error", "solver.theta", "solver.max_iterations",
                                   "solver.tol", "solver.p", "solver.method", "materials.layer1.E",
                                   "loads.layer1.top.y", "fracture.inner", "geometry.sigma", "mesh.size"})),
       command=st.sampled_from(COMMANDS))
def test_every_key_is_read_or_has_a_reason(key, command):
    """The decision of ``unread`` for any key and command: a reason in words, or None."""
    from ddsolve.problem import scene
    from ddsolve.solvers import checks

    reason = checks.unread(command, key.split("."), scene.load("partial-closure", SMALL))
    assert reason is None or (reason and "\n" not in reason)
    if command == "mesh":
        assert (reason is None) == (key.split(".")[0] in ("geometry", "mesh") and key != "mesh.target_error")
    if key in ("loads.layer1.top.y", "materials.layer1.E", "fracture.inner") and command != "mesh":
        assert reason is None
    if key.startswith("solver.") and command == "reference":
        assert reason is not None


if __name__ == "__main__":
    script(sys.argv[1], Path(sys.argv[2]))
