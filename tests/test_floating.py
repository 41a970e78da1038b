"""Floating blocks (issue 18): halves held only through Σ, solved by schur and feti on 1 to 8 ranks
against the reference; a structure that can move rigidly, and methods that cannot solve floating
blocks, are refused in one line."""
from __future__ import annotations

import pytest
from conftest import ddsolve, refused

from ddsolve.io import hdf5 as io
from ddsolve.post import analysis

#: A strip clamped on its bottom side only: the upper half (u_plus, v_plus) touches no support and is
#: held by the glue; pulled and sheared on top, with a crack whose faces close partly.
STRIP = """
[geometry]
box = [0.0, 4.0, -0.5, 0.5]
cracks = [[1.0, 2.0]]
clamped = [{clamped}]
[mesh]
sigma_vertices = 9
boundary_vertices = 24
[materials.layer1]
E = 200.0
nu = 0.28
[materials.layer2]
E = 112.0
nu = 0.32
[loads.layer1.top]
y = "-1e-3*x"
x = 2e-3
"""


def strip(folder, clamped: str = '"bottom"'):
    path = folder / "strip.toml"
    path.write_text(STRIP.format(clamped=clamped))
    return path


@pytest.fixture(scope="module")
def floating_reference(tmp_path_factory):
    folder = tmp_path_factory.mktemp("floating")
    scene = strip(folder)
    ddsolve("reference", str(scene), "-o", str(folder / "reference.h5"))
    return scene, io.read(folder / "reference.h5")


@pytest.mark.mpi
@pytest.mark.parametrize("method", ["schur", "feti"])
def test_floating_halves_equal_the_reference_on_every_rank_count(tmp_path, floating_reference, method):
    scene, reference = floating_reference
    assert reference.attrs["closed_vertices"] > 0  # contact on part of the crack
    for ranks in (1, 2, 4, 8):
        output = tmp_path / f"n{ranks}.h5"
        ddsolve("solve", str(scene), "--set", f"solver.method={method}", "--set", "solver.tol=1e-12", "-o",
                str(output), ranks=ranks)
        result = io.read(output)
        assert result.converged and result.ranks == ranks
        assert analysis.compare(result, reference).energy_error < 1e-10, ranks
        assert abs(result.attrs["energy"] - reference.attrs["energy"]) <= 1e-10 * abs(reference.attrs["energy"])
        if method == "schur":
            assert result.solves == 3


@pytest.mark.mpi
def test_a_structure_without_supports_is_refused_naming_the_motion(tmp_path):
    scene = strip(tmp_path, clamped="")
    for command, ranks in (("solve", 2), ("reference", None)):
        completed = ddsolve(command, str(scene), "-o", str(tmp_path / "x.h5"), ranks=ranks, check=False)
        refused(completed, 1, "the structure can translate in x: add a support")
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.mpi
@pytest.mark.parametrize("method", ["uzawa", "mprgp", "fista"])
def test_methods_that_need_every_block_invertible_refuse_floating_blocks(tmp_path, method):
    theta = ["--set", "solver.theta=auto"] if method == "uzawa" else []
    completed = ddsolve("solve", str(strip(tmp_path)), "--set", f"solver.method={method}", *theta, "-o",
                        str(tmp_path / "x.h5"), ranks=2, check=False)
    refused(completed, 1, f"solver.method = {method}: blocks u_plus, v_plus are floating", "use schur or feti")
