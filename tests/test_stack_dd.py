"""The domain decomposition of several interfaces (issue 36 item 3): a three-region strip with a crack on each of its
two interfaces, its faces pressed together, solved by the DD equals the monolithic reference of several interfaces
(:mod:`ddsolve.solvers.stacked`) to round-off, on any number of ranks the six blocks can use."""
from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import ddsolve, refused
from mpi4py import MPI

from ddsolve.dd.interface import Interface, for_mesh
from ddsolve.errors import DDSolveError
from ddsolve.fem import assembly
from ddsolve.mesh import stack
from ddsolve.mesh.mesh import blocks
from ddsolve.problem import scene as scenes
from ddsolve.solvers import stacked, stacked_dd

#: Three regions, two interfaces, a crack on each (docs/two-interfaces.toml); layer 1 pressed onto Σ from above and
#: below and pulled at the right, its middle region stiffer: both cracks have faces in contact.
STRIP = (Path(__file__).resolve().parents[1] / "docs" / "two-interfaces.toml").read_text()


#: The same strip as one body: the blocks u1, u2, u3.
ONE_LAYER = STRIP.replace("[materials.layer2]\nE = 1.0\nnu = 0.3\n", "").replace("[geometry]\n", "[geometry]\nlayers = 1\n")


def strip(*overrides: str, text: str = STRIP) -> scenes.Scene:
    return scenes.loads(text, list(overrides), origin="strip.toml")


def solved_by_reference(source: scenes.Scene) -> tuple[stacked.StackResult, list]:
    """The reference's solution and its block systems (the energy norm)."""
    mesh = stack.build_any(source)
    return stacked.solve_stack(source, mesh), stacked.assemble(source, mesh)[0]


@pytest.fixture(scope="module")
def reference() -> tuple[stacked.StackResult, list]:
    return solved_by_reference(strip())


def energy_error(solution: dict[str, np.ndarray], reference: stacked.StackResult, systems: list) -> float:
    """‖u − u_ref‖_K / ‖u_ref‖_K over every block."""
    error = norm = 0.0
    for system, (name, expected) in zip(systems, reference.solution.items()):
        difference = (solution[name] - expected).ravel()
        error += difference @ assembly.csr_matvec(system, difference)
        norm += expected.ravel() @ assembly.csr_matvec(system, expected.ravel())
    return float(np.sqrt(error / norm))


def test_one_interface_joined_alone_is_itself():
    """The rows of one interface joined are its rows: the same couplings, multipliers and interface unknowns."""
    source = scenes.load("partial-closure", ["mesh.sigma_vertices=11", "mesh.boundary_vertices=24"])
    mesh = stack.build_any(source)
    one = for_mesh(mesh.sigma, True, specs=blocks(2))
    joined = Interface.joined([one], [(0, 1, 2, 3)], blocks(2))
    assert joined.size == one.size and joined.slices == one.slices and list(joined.part_rows[0]) == list(range(one.size))
    for mine, theirs in zip(joined.couplings, one.couplings):
        assert all(np.array_equal(getattr(mine, key), getattr(theirs, key)) for key in ("rows", "trace", "sign"))
    loads = one.loads(np.random.default_rng(3).normal(size=one.size))
    np.testing.assert_array_equal(joined.multipliers(loads), one.multipliers(loads))
    np.testing.assert_array_equal(joined.trace_unknowns(), one.trace_unknowns())


@pytest.mark.solve
@pytest.mark.parametrize("method, text", [("schur", STRIP), ("feti", STRIP), ("schur", ONE_LAYER)],
                         ids=["schur", "feti", "schur one layer"])
def test_the_decomposition_equals_the_reference_with_g_at_every_tip(reference, method, text):
    solved, systems = reference if text == STRIP else solved_by_reference(strip(text=text))
    dd = stacked_dd.solve(strip(f"solver.method={method}", "solver.tol=1e-10", text=text), MPI.COMM_SELF, None,
                          progress=lambda _: None)
    assert solved.converged and dd.converged, dd.message
    assert all(part.multipliers["mu_c"].max() > 0 for part in solved.interfaces)  # contact on both cracks
    assert energy_error(dd.solution, solved, systems) < 1e-8
    assert dd.energy == pytest.approx(solved.energy, rel=1e-9)
    assert list(dd.fracture.interface) == [1, 1, 2, 2]
    np.testing.assert_allclose(dd.fracture.G, solved.fracture.G, rtol=0, atol=1e-6 * np.abs(solved.fracture.G).max())


@pytest.mark.solve
def test_what_the_decomposition_of_several_interfaces_does_not_take_is_refused_in_one_line():
    held_at_the_bottom = scenes.loads(STRIP.replace("[loads.layer1.bottom]\ny = 0.05\n", ""),
                                      ["geometry.clamped=[\"bottom\"]"])
    for source, key in ((strip("contact.friction=0.3"), "contact.friction"),
                        (held_at_the_bottom, "geometry.clamped: blocks u2, u3, v2, v3")):
        with pytest.raises(DDSolveError) as caught:
            stacked_dd.solve(source, MPI.COMM_SELF, None, progress=lambda _: None)
        assert str(caught.value).startswith(key) and "\n" not in str(caught.value), str(caught.value)


@pytest.mark.mpi
def test_the_decomposition_on_2_3_6_and_12_ranks_equals_the_reference(reference, tmp_path, monkeypatch):
    """One scene, every rank count six blocks can use (12: two ranks per block), compared with the reference
    solved here; 4 ranks refused in one line."""
    solved, systems = reference
    scene_file = tmp_path / "strip.toml"
    scene_file.write_text(STRIP)
    monkeypatch.setenv("OMPI_MCA_rmaps_base_oversubscribe", "1")  # 12 ranks on the cores there are
    for ranks in (2, 3, 6, 12):
        output = tmp_path / f"strip-{ranks}.h5"
        ddsolve("solve", str(scene_file), "-o", str(output), ranks=ranks)
        with h5py.File(output, "r") as written:
            solution = {name: written[f"solution/{name}"][()] for name in solved.solution}
            assert bool(written.attrs["converged"])
            np.testing.assert_allclose(written["fracture/G"][()], solved.fracture.G, rtol=1e-6)
        assert energy_error(solution, solved, systems) < 1e-8, ranks
    refused(ddsolve("solve", str(scene_file), "-n", "4", "-o", str(tmp_path / "four.h5"), check=False), 2,
            "-n 4: unsupported number of ranks: use 1, 2, 3 or a multiple of 6")
