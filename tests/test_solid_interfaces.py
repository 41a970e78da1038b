"""A 3-D box of several interfaces (``geometry.sigma = [y1, y2, ...]``): its regions and their Σ conform, the
decomposition (a block per region, joined at every Σ) equals the reference with contact on both cracks, and bad
input is refused in one line naming the key."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ddsolve.errors import SceneError
from ddsolve.problem.scene import load, loads

SAMPLE = Path(__file__).resolve().parents[1] / "docs" / "three-d-interfaces.toml"
#: The sample at its coarsest mesh that still shuts part of each crack.
COARSE = ["mesh.size=0.45"]


def test_regions_conform_on_every_sigma_and_carry_their_tags():
    """Three regions bottom to top (region1 …) between y = 0, 1, 2, 3: each Σ's vertices are nodes of the regions
    below and above it at the same points, its triangles are the region below's faces there, the crack vertices
    lie in their rectangles; a region's faces on Σ are named sigma1, sigma2."""
    from ddsolve.mesh import solid

    scene = load(SAMPLE, COARSE)
    mesh = solid.build(scene)
    assert [region.name for region in mesh.regions] == ["region1", "region2", "region3"]
    for k, (low, high) in enumerate(((0.0, 1.0), (1.0, 2.0), (2.0, 3.0))):
        region = mesh.regions[k]
        centres = region.points[region.tetrahedra].mean(axis=1)[:, 1]
        assert low < centres.min() and centres.max() < high
    assert {key for key, faces in mesh.regions[1].faces.items() if len(faces)} == {
        "left", "right", "front", "back", "sigma1", "sigma2"}
    for k, (height, crack) in enumerate(((1.0, (1.0, 2.0, 0.25, 0.75)), (2.0, (2.0, 3.0, 0.0, 1.0)))):
        sigma, (below, above) = mesh.sigmas[k], mesh.border(k)
        assert np.array_equal(mesh.regions[k].points[below], sigma.points)
        assert np.array_equal(mesh.regions[k + 1].points[above], sigma.points)
        assert np.allclose(sigma.points[:, 1], height) and np.isclose(sigma.weights.sum(), 4.0)
        a, b, c, d = crack
        cracked = sigma.points[sigma.cracked]
        assert len(cracked) and np.all((cracked[:, 0] > a) & (cracked[:, 0] < b) & (cracked[:, 2] >= c)
                                       & (cracked[:, 2] <= d))
        view = mesh.interface(k)
        assert [half.name for half in view.halves] == ["lower", "upper"] and view.sigma is sigma
    with pytest.raises(Exception, match="has no single sigma"):
        mesh.sigma


@pytest.mark.solve
def test_the_regions_decomposition_equals_the_reference_with_both_cracks_shut_in_part(tmp_path):
    """On one rank (in this process) schur and feti give the reference's solution to 1e-8 in energy norm, some
    but not all crack vertices of each Σ shut, G along each interface's fronts; the file holds each Σ and is read
    back; no slabs of the regions; a floating middle region (held only through both interfaces) solved too."""
    import h5py
    from mpi4py import MPI

    from ddsolve.io import solid as solid_files
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver, solid_dd

    scene = load(SAMPLE, COARSE)
    mesh = solid.build(scene)
    reference = solid_solver.reference_on(scene, mesh)
    assert reference.converged and max(reference.checks.values()) < 1e-8
    for pressure, sigma in zip(reference.pressures, mesh.sigmas):
        assert 0 < np.count_nonzero(pressure > 0) < np.count_nonzero(sigma.cracked)
    assert set(reference.fracture_interface) == {1, 2}
    for method in ("schur", "feti"):
        result = solid_dd.solve(scene.with_({"solver.method": method, "solver.tol": 1e-12}), MPI.COMM_SELF,
                                tmp_path / f"{method}.h5", progress=lambda _line: None)
        assert result.converged and result.closed == reference.closed
        assert solid_solver.energy_error(result, reference) < 1e-8
        assert np.allclose(result.fracture.G, reference.fracture.G, rtol=1e-6,
                           atol=1e-8 * reference.fracture.G.max())
        read = solid_files.read(tmp_path / f"{method}.h5")
        assert solid_solver.energy_error(read, reference) < 1e-8 and read.closed == reference.closed
    with h5py.File(tmp_path / "schur.h5") as f:
        assert f.attrs["interfaces"] == 2 and "interfaces/2/sigma/contact_pressure" in f and "sigma" not in f
        assert np.array_equal(f["fracture/interface"][()], reference.fracture_interface)
    assert sorted(path.name for path in tmp_path.glob("schur-*.vtu")) == [
        "schur-region1.vtu", "schur-region2.vtu", "schur-region3.vtu", "schur-sigma1.vtu", "schur-sigma2.vtu"]
    assert solid_dd.decomposition(scene, mesh, 2) is None
    held = load(SAMPLE, [*COARSE, 'geometry.clamped=["bottom", "top"]'])  # the middle region floats
    kernels = solid_dd.kernels_of(solid_dd.decomposition(held, mesh, 1))
    assert kernels.names() == "region2"
    floating_reference = solid_solver.reference_on(held, mesh)
    for method in ("schur", "feti"):
        result = solid_dd.solve(held.with_({"solver.method": method, "solver.tol": 1e-12}), MPI.COMM_SELF, None,
                                progress=lambda _line: None, mesh=mesh)
        assert result.converged and result.closed == floating_reference.closed
        assert solid_solver.energy_error(result, floating_reference) < 1e-8


@pytest.mark.solve
def test_auto_takes_feti_where_a_region_is_one_element_thick():
    """The middle region as thick as mesh.size (0.45): MUMPS cannot factor it with its Schur complement on the
    trace, so an explicit schur stops with its one line and auto takes feti, which equals the reference; the sample
    itself and a region a little thicker keep schur."""
    from mpi4py import MPI

    from ddsolve.errors import DDSolveError
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver, solid_dd

    for sigma, thin in (("[1.0, 2.0]", []), ("[1.0, 1.5]", []), ("[1.0, 1.45]", [1])):
        scene = load(SAMPLE, [*COARSE, f"geometry.sigma={sigma}"])
        mesh = solid.build(scene)
        parts = solid_dd.decomposition(scene, mesh, 1)
        assert solid_dd.thin_blocks(parts) == thin, sigma
        method = solid_dd.method_of(scene, parts, solid_dd.kernels_of(parts)).solver.method
        assert method == ("feti" if thin else "schur"), sigma
    with pytest.raises(DDSolveError, match=r"^block region2: .*\(a region thinner than mesh.size\): use solver.method "
                                           r"= feti or mprgp$"):
        solid_dd.solve(scene.with_({"solver.method": "schur"}), MPI.COMM_SELF, None, progress=lambda _line: None,
                       mesh=mesh)
    result = solid_dd.solve(scene.with_({"solver.tol": 1e-12}), MPI.COMM_SELF, None, progress=lambda _line: None,
                            mesh=mesh)
    assert result.scene.solver.method == "feti" and result.converged
    assert solid_solver.energy_error(result, solid_solver.reference_on(scene, mesh)) < 1e-8


@pytest.mark.mpi
def test_the_regions_on_2_and_3_ranks_equal_the_reference(tmp_path):
    """ddsolve solve -n 3 (a region per rank) and, in one launch, -n 2 with schur and feti (regions 1 and 3 on rank
    0, region 2 on rank 1): their files hold the reference's solution to 1e-8 in energy norm; 4 ranks are refused
    naming the regions' rule."""
    import launch_many
    from conftest import ddsolve

    from ddsolve.io import solid as solid_files
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver

    scene = load(SAMPLE, COARSE)
    reference = solid_solver.solve_solid(scene, solid.build(scene))
    solved = ddsolve("solve", str(SAMPLE), "-o", str(tmp_path / "3.h5"), "--set", COARSE[0], ranks=3)
    assert "on 3 ranks" in solved.stdout
    assert solid_solver.energy_error(solid_files.read(tmp_path / "3.h5"), reference) < 1e-8
    methods = ("schur", "feti")
    outputs = launch_many.launch([["solve", str(SAMPLE), "-o", str(tmp_path / f"{method}-2.h5"), "--set", COARSE[0],
                                   "--set", f"solver.method={method}", "--set", "solver.tol=1e-12"]
                                  for method in methods], 2, tmp_path)
    for method, output in zip(methods, outputs):
        assert f"{method} (3-D):" in output and "on 2 ranks" in output
        assert solid_solver.energy_error(solid_files.read(tmp_path / f"{method}-2.h5"), reference) < 1e-8, method
    refused = ddsolve("solve", str(SAMPLE), "-n", "4", "-o", str(tmp_path / "4.h5"), check=False)
    assert refused.returncode == 2 and refused.stderr.strip() == (
        "ddsolve: error: -n 4: unsupported number of ranks: use 1, 2 or a multiple of 3 (the 3 regions of the 3-D "
        "box, a block each)")


REFUSED = {
    "sigma = [2.0, 1.0]": "geometry.sigma: interfaces 1 and 2 cross or touch .* strictly increasing",
    "sigma = [1.0, 3.5]": "geometry.sigma = 3.5 must lie strictly between the box's y0 = 0 and y1 = 3",
    "cracks = [[[1.0, 2.0]]]": "geometry.cracks lists 1 crack list for the 2 interfaces",
    "cracks = [[1.0, 1.5], [2.0, 3.0]]": "geometry.cracks: with 2 interfaces give one list of intervals per interface",
    "cracks = [[[1.0, 2.0, 0.5, 1.5]], []]": r"geometry.cracks: the crack \[1.0, 2.0, 0.5, 1.5\] leaves Σ: its z",
    "cracks = [[], [{center = [5.0, 0.5], radii = [0.2, 0.2]}]]": "geometry.cracks: the ellipse's centre .* leaves Σ",
    "[materials.layer1.region4]\nE = 2.0": "materials.layer1.region4: no region of that name",
    "[materials.layer1.upper]\nE = 2.0": "materials.layer1.upper: no region of that name",
    "[mesh]\nsize = 0.5\nextrude = 2": "mesh.extrude: a 3-D box of several interfaces",
    "[mesh]\nsize = 0.5\ntarget_error = 0.1": "mesh.target_error: a 3-D box of several interfaces",
    "[solver]\npieces = 2": "solver.pieces = 2: a 3-D box of several interfaces is decomposed into its regions",
}
BASE = """
[geometry]
box = [0.0, 4.0, 0.0, 3.0, 0.0, 1.0]
{geometry}
[materials.layer1]
E = 1.0
nu = 0.3
"""


@pytest.mark.unit
@pytest.mark.parametrize("given", list(REFUSED))
def test_bad_input_of_several_interfaces_is_refused_naming_the_key(given):
    geometry = {"sigma": "sigma = [1.0, 2.0]", "cracks": "cracks = [[[1.0, 2.0]], [[2.0, 3.0]]]"}
    key = given.split(" ")[0]
    table = given.startswith("[")
    lines = list(geometry.values()) if table else [given if key == name else line
                                                     for name, line in geometry.items()]
    text = BASE.format(geometry="\n".join(lines)) + (given + "\n" if table else "")
    with pytest.raises(SceneError, match=f"^scene: {REFUSED[given]}"):
        loads(text)
