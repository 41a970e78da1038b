"""The result file of several interfaces read back (a StackResult), and check, compare, plot and export of it."""
from __future__ import annotations

import contextlib
import dataclasses
import io as text_io
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from test_interfaces import STRIP

from ddsolve.cli import parser
from ddsolve.errors import DDSolveError
from ddsolve.io import hdf5
from ddsolve.mesh import stack
from ddsolve.post import stack as stacks
from ddsolve.problem import scene
from ddsolve.solvers import stacked

pytestmark = pytest.mark.solve

#: The strip of three regions on a coarse mesh, pressed on top so that one crack closes.
COARSE = ["mesh.size=0.5", "loads.layer1.top.y=-0.05"]


def solved(*overrides: str, text: str = STRIP) -> stacks.StackResult:
    source = scene.loads(text, [*COARSE, *overrides], origin="strip.toml")
    return stacked.solve_stack(source, stack.build_any(source))


def command(*arguments: str) -> tuple[int, str]:
    """The command ``ddsolve ARGUMENTS`` run in this process (its errors raised): its status and output."""
    args = parser().parse_args(list(arguments))
    out = text_io.StringIO()
    with contextlib.redirect_stdout(out):
        status = args.run(args, [])
    return status, out.getvalue()


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> tuple[stacks.StackResult, Path]:
    result = solved()
    path = tmp_path_factory.mktemp("stack") / "strip.h5"
    hdf5.write_stack(path, result)
    return result, path


def test_the_file_reads_back_as_the_result_it_was_written_from(written):
    result, path = written
    back = hdf5.read(path)
    assert isinstance(back, stacks.StackResult) and back.converged and back.energy == result.energy
    assert list(back.solution) == ["u1", "u2", "u3", "v1", "v2", "v3"]
    for name, u in result.solution.items():
        np.testing.assert_array_equal(back.solution[name], u)
    for mine, theirs in zip(back.mesh.regions, result.mesh.regions):
        assert (mine.name, mine.side, sorted(mine.boundaries)) == (theirs.name, theirs.side, sorted(theirs.boundaries))
        for key in ("points", "cells", "sigma", "sigma_above"):
            np.testing.assert_array_equal(getattr(mine, key), getattr(theirs, key))
    for mine, theirs in zip(back.interfaces, result.interfaces):
        assert mine.scene.regions == theirs.scene.regions  # each view's regions' materials
        for name, values in theirs.multipliers.items():
            np.testing.assert_array_equal(mine.multipliers[name], values)
        np.testing.assert_array_equal(mine.fracture.G, theirs.fracture.G)
    for key in ("G", "points", "interface", "crack_interface", "zones"):
        np.testing.assert_array_equal(getattr(back.fracture, key), getattr(result.fracture, key))
    assert all(not checked.violations(1e-9) for checked in stacked.check(back))


def test_a_file_of_several_interfaces_without_its_views_is_refused_in_one_line(written, tmp_path):
    old = tmp_path / "old.h5"
    old.write_bytes(written[1].read_bytes())
    with h5py.File(old, "a") as f:
        del f["interfaces"]  # as files were written before they were read back
    with pytest.raises(DDSolveError) as caught:
        hdf5.read(old)
    assert str(caught.value) == (f"{old}: not a ddsolve result file (a result of 2 interfaces written before such "
                                 "files were read back (no /interfaces): solve it again (ddsolve reference or solve))")


def test_check_compare_plot_and_export_take_the_file(written, tmp_path):
    _, path = written
    status, out = command("check", str(path))
    assert status == 0 and out.startswith("interface 1: max penetration") and "KKT check passed" in out
    finer = tmp_path / "finer.h5"
    hdf5.write_stack(finer, solved("mesh.size=0.25"))
    status, out = command("compare", str(path), str(finer))
    lines = out.splitlines()
    assert status == 0 and lines[0].endswith("(on the reference's mesh)") and len(lines) == 5
    assert 1e-3 < float(lines[0].split()[3]) < 0.5  # the coarse mesh's error against the finer one
    assert lines[4].startswith("G at tip (3, 2) of crack 1 on interface 2: ")
    status, out = command("compare", str(path), str(path))
    assert out.startswith("relative energy-norm error 0.000e+00   max nodal difference 0.000e+00")
    status, out = command("plot", str(path), "--scale", "0.5")
    assert status == 0 and "strip-crack-faces-2.png" in out
    assert Path(path.parent / "strip-deformed.png").read_bytes()[:4] == b"\x89PNG"
    status, out = command("export", str(path), "-o", str(tmp_path))
    block = meshio.read(tmp_path / "strip-u2.vtu")
    np.testing.assert_allclose(block.point_data["displacement"][:, :2], written[0].solution["u2"])
    assert set(block.cell_data) >= {"stress", "von_mises"}
    assert meshio.read(tmp_path / "strip-sigma2.vtu").point_data["contact_pressure"].max() > 0


def test_files_of_different_structures_are_compared_in_one_line(written, tmp_path):
    result, path = written
    one = tmp_path / "one.h5"
    hdf5.write(one, result.interfaces[0])  # interface 1 alone: a one-interface file
    layer = tmp_path / "layer.h5"
    hdf5.write_stack(layer, solved("geometry.layers=1", text=STRIP.replace("[materials.layer2]\nE = 1.0\nnu = 0.3\n", "")))
    for other, words in ((one, "one interface, blocks u_minus, u_plus, v_minus, v_plus"),
                         (layer, "2 interfaces, blocks u1, u2, u3")):
        with pytest.raises(DDSolveError) as caught:
            command("compare", str(path), str(other))
        assert str(caught.value) == (f"{path} and {other} are results of different structures (2 interfaces, blocks "
                                     f"u1, u2, u3, v1, v2, v3; {words}): compare results of one structure")
