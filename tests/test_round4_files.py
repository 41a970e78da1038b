"""Issue 40, classes 6 and 7 and first use: inputs reached through other files, the API's arguments and
its runs under MPI, a short repr of a result, and docs/api.md's mpiexec line as written."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import meshio
import pytest
from conftest import ROOT, SMALL, ddsolve, refused, structured_square, without_open_mpi_noise
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import ddsolve as api
from ddsolve.io import hdf5, inputs
from experiments.hostile4_files import XDMF_SCENE

#: The SMALL mesh as overrides of the API.
SMALL_KEYS = {"mesh.sigma_vertices": 13, "mesh.boundary_vertices": 32}
#: Derandomized, few examples: these generators would have found the bugs, and run in seconds.
FEW = settings(derandomize=True, max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def xdmf_scene(folder: Path) -> tuple[Path, Path]:
    """A scene whose mesh is an XDMF file keeping its arrays in ``box.h5``; (the scene file, box.h5)."""
    points, cells = structured_square(8, 4, shear=0.3)
    meshio.write(folder / "box.xdmf", meshio.Mesh(points, [("triangle", cells)]))
    assert b"box.h5:/" in (folder / "box.xdmf").read_bytes()
    scene = folder / "x.toml"
    scene.write_text(XDMF_SCENE)
    return scene, folder / "box.h5"


# --- class 6: inputs reached through other files ---------------------------------------------------
@pytest.mark.mpi
@pytest.mark.parametrize("command", [["solve"], ["reference"], ["sweep", "--set", "materials.layer2.E=100:120:2"],
                                     ["grow", "--to", "2", "--steps", "2", "--pictures", "0"]])
def test_an_xdmf_meshs_arrays_are_an_input_no_command_replaces(command, tmp_path):
    scene, heavy = xdmf_scene(tmp_path)
    before = heavy.read_bytes()
    line = refused(ddsolve(command[0], str(scene), *command[1:], "-o", str(heavy), check=False), 1,
                   "is an input of this run", "read through", "box.xdmf", "choose another -o")
    assert heavy.read_bytes() == before, line


@pytest.mark.mpi
def test_a_file_a_geo_merges_is_an_input_mesh_o_does_not_replace(tmp_path):
    scenes = ROOT / "ddsolve" / "problem" / "scenes"
    (tmp_path / "a.geo").write_text((scenes / "arc-bond.geo").read_text() + 'Merge "extra.msh";\n')
    (tmp_path / "a.toml").write_text((scenes / "arc-bond.toml").read_text().replace("arc-bond.geo", "a.geo"))
    (tmp_path / "extra.msh").write_text("a mesh merged into the geometry")
    refused(ddsolve("mesh", str(tmp_path / "a.toml"), "-o", str(tmp_path / "extra.msh"), check=False), 1,
            "extra.msh: is an input of this run", "read through", "a.geo")
    assert (tmp_path / "extra.msh").read_text() == "a mesh merged into the geometry"


def references(draw, folder: Path) -> tuple[Path, set[Path]]:
    """A mesh or geometry file naming others (XDMF heavy data and binary items, XIncludes; a .geo's
    Include, Merge and ShapeFromFile, in chains), some in subfolders, some absolute, some missing;
    (the file, the existing files it reaches)."""
    kind = draw(st.sampled_from(["xdmf", "geo"]))
    names = draw(st.lists(st.sampled_from(["a.h5", "sub/b.h5", "c.bin", "d.geo", "e.msh", "f.brep", "g.xmf"]),
                          min_size=0, max_size=4, unique=True))
    missing = draw(st.sets(st.sampled_from(names), max_size=1)) if names else set()
    absolute = draw(st.booleans())
    (folder / "sub").mkdir(exist_ok=True)
    reached = set()
    for name in names:
        if name not in missing:
            (folder / name).write_text('Merge "e.msh";\n' if name.endswith(".geo") else "data\n")
            reached.add(folder / name)
    if "d.geo" in names and "d.geo" not in missing:  # a chain: d.geo merges e.msh
        (folder / "e.msh").write_text("mesh\n")
        reached.add(folder / "e.msh")
    spelt = [str(folder / name) if absolute else name for name in names]
    if kind == "xdmf":
        items = "".join(f'<DataItem Format="HDF" Dimensions="3">{name}:/data{i}</DataItem>' if name.endswith(".h5") else
                        f'<xi:include href="{name}"/>' if name.endswith(".xmf") else
                        f'<DataItem Format="Binary" Dimensions="3">{name}</DataItem>'
                        for i, name in enumerate(spelt))
        text = (f'<?xml version="1.0" ?><Xdmf Version="3.0" xmlns:xi="http://www.w3.org/2001/XInclude"><Domain>'
                f'<Grid Name="g"><Geometry>{items}</Geometry></Grid></Domain></Xdmf>')
        path = folder / "m.xdmf"
    else:
        statements = draw(st.lists(st.sampled_from(['Include "{}";', 'Merge "{}";', 'ShapeFromFile("{}");']),
                                   min_size=len(spelt), max_size=len(spelt)))
        text = "Point(1) = {0, 0, 0};\n" + "\n".join(s.format(n) for s, n in zip(statements, spelt)) + "\n"
        path = folder / "m.geo"
    path.write_text(text)
    return path, {path, *reached}


@FEW
@given(data=st.data())
def test_every_file_a_mesh_file_reaches_is_an_input_an_output_cannot_be(data, tmp_path_factory):
    folder = tmp_path_factory.mktemp("reach")
    path, expected = references(data.draw, folder)
    found = inputs.reached(path)
    assert {p.resolve() for p in found} == {p.resolve() for p in expected}
    for target in expected - {path}:
        if target.suffix == ".h5":
            with pytest.raises(api.DDSolveError, match=r"^.*: is an input of this run \(.*read through"):
                hdf5.check_result(target, found, viewer=False)


@pytest.mark.solve
def test_the_api_writers_refuse_what_the_run_reads_and_names_that_are_not_hdf5(tmp_path):
    """``output=`` of every writer and ``save`` go through the -o check, with the run's inputs."""
    scene, heavy = xdmf_scene(tmp_path)
    before = heavy.read_bytes()
    writers = {"solve": lambda out: api.solve(scene, output=out),
               "reference": lambda out: api.reference(scene, output=out),
               "sweep": lambda out: api.sweep(scene, {"materials.layer2.E": [100.0, 120.0]}, output=out),
               "grow": lambda out: api.grow(scene, 2.0, steps=2, output=out)}
    for name, write in writers.items():
        with pytest.raises(api.DDSolveError, match=r"^.*box\.h5: is an input of this run .*choose another output$"):
            write(heavy)
        with pytest.raises(api.DDSolveError, match=r"^output .*x\.toml: a result is an HDF5 file.*an input of this run"):
            write(scene)
        with pytest.raises(api.DDSolveError, match=r"^output .*g\.txt: a result is an HDF5 file"):
            write(tmp_path / "g.txt")
    result = api.reference(api.Scene.load("full-opening", SMALL_KEYS))
    assert result.inputs == {}  # a built-in scene: no file of the user's
    result.inputs = {heavy: "read through box.xdmf"}
    with pytest.raises(api.DDSolveError, match=r"^.*box\.h5: is an input of this run .*choose another save path$"):
        api.save(result, heavy)
    arrays = tmp_path / "box-xdmf.h5"  # the arrays of box.h5's XDMF viewer files, say read as a mesh
    arrays.write_bytes(b"arrays")
    result.inputs = {arrays: "read through box-lower.xdmf"}
    with pytest.raises(api.DDSolveError, match=r"^.*box-xdmf\.h5: is an input of this run"):
        api.save(result, tmp_path / "box.h5", viewer="xdmf")
    assert heavy.read_bytes() == before and not (tmp_path / "g.txt").exists()
    assert api.reference(scene).inputs == {scene: "the scene file", tmp_path / "box.xdmf": "the mesh file",
                                           heavy: f"read through {tmp_path / 'box.xdmf'}"}


# --- class 7: the API's arguments ------------------------------------------------------------------
GOOD = {"limit": 2.0, "steps": 2, "tolerance": 1e-4, "output": None, "progress": None}
#: Wrong values of every argument of grow, sweep, solve and save, with the argument they must be named by.
WRONG = st.one_of(
    st.tuples(st.just("grow"), st.sampled_from(["limit", "tolerance"]),
              st.one_of(st.text(max_size=5), st.booleans(), st.none(), st.lists(st.floats(), max_size=2))),
    st.tuples(st.just("grow"), st.just("steps"),
              st.one_of(st.booleans(), st.floats(allow_nan=True), st.text(max_size=3), st.none())),
    st.tuples(st.sampled_from(["grow", "sweep", "solve"]), st.just("output"),
              st.one_of(st.integers(), st.floats(), st.lists(st.text(max_size=2), max_size=2))),
    st.tuples(st.sampled_from(["grow", "sweep", "solve"]), st.just("progress"),
              st.one_of(st.integers(), st.text(min_size=1, max_size=3), st.booleans())),
    st.tuples(st.just("sweep"), st.just("parameters"),
              st.one_of(st.none(), st.text(max_size=3), st.lists(st.text(), max_size=2),
                        st.dictionaries(st.sampled_from(["materials.layer2.E"]),
                                        st.one_of(st.text(max_size=4), st.integers(), st.floats()), min_size=1),
                        st.dictionaries(st.integers(), st.just([1.0, 2.0]), min_size=1))),
    st.tuples(st.just("sweep"), st.just("paired"), st.one_of(st.integers(), st.text(max_size=3), st.none())),
    st.tuples(st.just("save"), st.sampled_from(["result", "path", "viewer"]),
              st.one_of(st.integers(), st.none(), st.lists(st.integers()))),
    st.tuples(st.just("save"), st.just("viewer"), st.sampled_from(["png", "VTU", ""])))


@pytest.fixture(scope="module")
def small_result():
    return api.reference(api.Scene.load("full-opening", SMALL_KEYS))


@pytest.mark.solve
@FEW
@given(wrong=WRONG)
def test_arguments_of_the_wrong_type_are_one_line_errors_naming_them(wrong, small_result):
    function, name, value = wrong
    scene = api.Scene.load("full-opening", {**SMALL_KEYS, "fracture.toughness": 1e-6})
    calls = {"grow": lambda: api.grow(scene, **{**GOOD, name: value}),
             "sweep": lambda: api.sweep(scene, **{"parameters": {"materials.layer2.E": [100.0]}, name: value}),
             "solve": lambda: api.solve(scene, **{name: value}),
             "save": lambda: api.save(**{"result": small_result, "path": "unwritten.h5", "viewer": "vtu", name: value})}
    with pytest.raises(api.DDSolveError) as raised:
        calls[function]()
    message = str(raised.value)
    assert "\n" not in message and message.startswith(f"{function}: {name}"), message
    assert isinstance(raised.value, api.ArgumentError) and isinstance(raised.value, TypeError), message
    assert not Path("unwritten.h5").exists()


OVERRIDES = st.one_of(st.none(), st.integers(), st.floats(), st.booleans(), st.sets(st.text(max_size=3), max_size=2),
                      st.lists(st.one_of(st.integers(), st.none(), st.floats()), min_size=1, max_size=3),
                      st.dictionaries(st.one_of(st.integers(), st.none()), st.integers(), min_size=1, max_size=2))


@FEW
@given(overrides=OVERRIDES)
def test_with_refuses_what_is_not_overrides_in_one_line(overrides):
    scene = api.Scene.load("partial-closure")
    with pytest.raises(api.SceneError, match=r"^overrides: [^\n]*$"):
        scene.with_(overrides)


def test_with_takes_one_key_value_item_as_a_list_of_one():
    scene = api.Scene.load("partial-closure")
    assert scene.with_("solver.tol=1e-10") == scene.with_(["solver.tol=1e-10"]) == scene.with_({"solver.tol": 1e-10})
    assert api.Scene.load("partial-closure", "solver.tol=1e-10").solver.tol == 1e-10


# --- class 7: the API under MPI, and docs/api.md's mpiexec line -------------------------------------
def documented_line() -> str:
    """The mpiexec line of docs/api.md's first shell block."""
    block = re.search(r"```sh\n(.*?)```", (ROOT / "docs" / "api.md").read_text(encoding="utf-8"), re.S).group(1)
    return next(line.split("#")[0].strip() for line in block.splitlines() if line.startswith("mpiexec"))


def run_documented(script: str, folder: Path, ranks: int = 4) -> subprocess.CompletedProcess:
    """``script`` run with docs/api.md's line as written (``-n`` changed to ``ranks``), in an environment
    without Open MPI's variables; as root with the option the page names for root."""
    line = documented_line().replace("-n 4", f"-n {ranks}")
    text = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")
    if os.geteuid() == 0:
        assert "--allow-run-as-root" in text
        line = line.replace("mpiexec ", "mpiexec --allow-run-as-root ", 1)
    (folder / "script.py").write_text(textwrap.dedent(script), encoding="utf-8")
    environment = {key: value for key, value in os.environ.items() if not key.startswith("OMPI_")}
    environment.update(PATH=f"{Path(sys.executable).parent}{os.pathsep}{environment.get('PATH', '')}",
                       PYTHONPATH=str(ROOT))
    return without_open_mpi_noise(subprocess.run(["bash", "-c", line], capture_output=True, text=True, timeout=600,
                                                 cwd=folder, env=environment, stdin=subprocess.DEVNULL))


@pytest.mark.mpi
def test_the_documented_mpiexec_line_runs_four_ranks_on_two_cores_without_open_mpis_variables(tmp_path):
    completed = run_documented(f"""
        import ddsolve
        from mpi4py import MPI
        result = ddsolve.solve(ddsolve.Scene.load("partial-closure", {SMALL_KEYS!r}))
        every = MPI.COMM_WORLD.allgather((result.ranks, result.converged, result.energy))
        if MPI.COMM_WORLD.rank == 0:
            print(len(every), "ranks,", len(set(every)), "answer:", result.ranks, result.converged)
        """, tmp_path)
    assert completed.returncode == 0, completed.stderr
    assert completed.stdout == "4 ranks, 1 answer: 4 True\n" and completed.stderr == ""


SCRIPTS = {
    "an error on one rank": ("""
        import ddsolve
        from mpi4py import MPI
        keys = {"solver.tl": 1} if MPI.COMM_WORLD.rank == 1 else {}
        ddsolve.solve(ddsolve.Scene.load("partial-closure", {**%r, **keys}))
        """, 2, "unknown key solver.tl"),
    "three ranks": ("""
        import ddsolve
        ddsolve.solve(ddsolve.Scene.load("partial-closure", %r))
        """, 3, "solve: unsupported number of ranks 3 in comm"),
    "a scene per rank": ("""
        import ddsolve
        from mpi4py import MPI
        ddsolve.solve(ddsolve.Scene.load("partial-closure", {**%r, "materials.layer2.E": 100.0 + MPI.COMM_WORLD.rank}))
        """, 2, "solve: rank 1 passed a different scene than rank 0"),
    "an argument per rank": ("""
        import ddsolve
        from mpi4py import MPI
        scene = ddsolve.Scene.load("full-opening", {**%r, "fracture.toughness": 1e-6})
        ddsolve.grow(scene, 2.0, steps=2 + MPI.COMM_WORLD.rank)
        """, 2, "grow: rank 1 passed a different steps than rank 0"),
}


@pytest.mark.mpi
@pytest.mark.parametrize("case", SCRIPTS)
def test_a_script_whose_ranks_cannot_go_on_ends_every_rank_with_one_line(case, tmp_path):
    script, ranks, fragment = SCRIPTS[case]
    completed = run_documented(script % (SMALL_KEYS,), tmp_path, ranks)
    refused(completed, 1, fragment)


@pytest.mark.solve
def test_a_results_repr_is_one_short_line(small_result, tmp_path):
    text = repr(small_result)
    assert "\n" not in text and len(text) < 300, text
    for part in ("Example 2: full opening", small_result.method, "converged", f"{small_result.energy:.10e}", "G at"):
        assert part in text, (part, text)
    api.save(small_result, tmp_path / "r.h5")
    again = api.load(tmp_path / "r.h5")
    assert repr(again).endswith(f"file {tmp_path / 'r.h5'}>") and len(repr(again.fracture)) < 200
