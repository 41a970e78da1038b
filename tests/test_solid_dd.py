"""The domain decomposition of a 3-D box: the interface with three trace entries per vertex, schur and feti
equal to the monolithic 3-D reference with contact active on 1, 2 and 4 ranks, and the refusals."""
from __future__ import annotations

import numpy as np
import pytest

from ddsolve.dd.interface import Interface
from ddsolve.errors import SceneError
from ddsolve.mesh.mesh import blocks
from ddsolve.problem.scene import loads
from experiments import three_d, three_d_front

#: Example 1's loads on one body extruded over [0, ½] with rollers on the front and back (the 3-D page's scene):
#: part of the crack shut.
CLOSURE = three_d.scene_of("partial closure", 0.3, 3)


@pytest.mark.unit
def test_an_interface_of_three_components_glues_every_component_and_presses_the_normal():
    """Three vertices, the middle one cracked: μᶜ on its normal (component 1), μᵍ on the three components of the
    others; the loads −Cᵀ W λ are the adjoint of the gap; a vertex whose x both blocks prescribe has no x row."""
    fixed = np.zeros((2, 9), dtype=bool)
    fixed[:, 6] = True  # the last vertex's x
    interface = Interface(np.array([0.5, 1.0, 0.5]), np.array([False, True, False]), True, fixed,
                          specs=blocks(1), components=3)
    assert interface.trace_size == 9 and interface.slices == {"mu_c": slice(0, 1), "mu_g": slice(1, 6)}
    assert list(interface.trace_index) == [4, 0, 1, 2, 7, 8]
    rng = np.random.default_rng(3)
    traces, lam = rng.standard_normal((2, 9)), rng.standard_normal(interface.size)
    assert np.isclose(interface.gap(traces) @ (interface.row_weights * lam), -np.sum(interface.loads(lam) * traces))
    assert np.allclose(interface.multipliers(interface.loads(lam)), lam)
    lower, upper = interface.trace_unknowns()
    assert np.array_equal(lower[:3], upper[:3]) and not np.any(lower[3:6] == upper[3:6])  # tied off the crack


@pytest.mark.solve
def test_schur_and_feti_equal_the_3d_reference_with_contact_active(tmp_path, monkeypatch):
    """On one rank (in this process) both methods give the reference's solution to 1e-8 in energy norm with crack
    vertices shut, and G along the front; the file is the reference's, read back; schur above its memory limit is
    refused (auto then takes feti)."""
    from mpi4py import MPI

    from ddsolve.environment import physical_memory
    from ddsolve.io import solid as solid_files
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver, solid_dd
    from ddsolve.solvers.solid import energy_error

    scene = CLOSURE
    mesh = solid.build(scene)
    reference = solid_solver.solve_solid(scene, mesh)
    solid_solver.with_fracture(reference)
    assert reference.converged and reference.closed > 0 and len(reference.fracture.G)
    for method in ("schur", "feti"):
        result = solid_dd.solve(scene.with_({"solver.method": method}), MPI.COMM_SELF, tmp_path / f"{method}.h5",
                                progress=lambda _line: None)
        assert result.converged and result.closed == reference.closed and max(result.checks.values()) < 1e-6
        assert energy_error(result, reference) < 1e-8
        assert abs(result.energy - reference.energy) < 1e-8 * abs(reference.energy)
        assert np.allclose(result.fracture.G, reference.fracture.G, rtol=1e-6, atol=1e-8 * reference.fracture.G.max())
        read = solid_files.read(tmp_path / f"{method}.h5")
        assert energy_error(read, reference) < 1e-8 and read.scene.solver.method == method
    parts = solid_dd.decomposition(scene, mesh, 1)
    held = solid_dd.kernels_of(parts)
    monkeypatch.setattr(solid_dd, "SCHUR_MEMORY_SHARE",
                        0.5 * solid_dd.schur_bytes(parts.interface) / physical_memory())
    refused = "^solver.method = schur: the dense Schur complements .* use solver.method = feti$"
    with pytest.raises(SceneError, match=refused):
        solid_dd.method_of(scene.with_({"solver.method": "schur"}), parts, held)
    assert solid_dd.method_of(scene, parts, held).solver.method == "feti"  # auto


#: The quarter penny-shaped crack of radius ½ (experiments/three_d_front.py, coarse): rollers on x = 0 and z = 0,
#: the bottom held in y, a traction on top; the upper half is held only through Σ (its rollers leave it y).
PENNY = three_d_front.PENNY.format(L=2, size=0.3, grading=0.2)


@pytest.mark.solve
def test_a_floating_half_is_solved_and_a_box_free_as_a_whole_refused(tmp_path):
    """The penny's upper half floats (its kernel: the translation in y): schur and feti (at solver.tol 1e-10: its
    default KKT tolerance leaves ~1e-7 in energy norm, as in the plane) give the reference's solution to 1e-8 in
    energy norm and its G along the front; mprgp is refused naming the half; without the bottom's support the box
    can translate in y, refused in one line."""
    from mpi4py import MPI

    from ddsolve.dd import kernels
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver, solid_dd
    from ddsolve.solvers.solid import energy_error

    scene = loads(PENNY)
    mesh = solid.build(scene)
    held = solid_dd.kernels_of(solid_dd.decomposition(scene, mesh, 1))
    relative = kernels.describe(np.concatenate([np.zeros((6, 1)), held.kernels[1]]), held.frame, held.specs)
    assert held.floating == [1] and relative == "blocks u_plus can translate along (0, 1, 0) relative to the rest"
    reference = solid_solver.reference(scene)
    for method, tol in (("schur", 1e-8), ("feti", 1e-10)):
        result = solid_dd.solve(scene.with_({"solver.method": method, "solver.tol": tol}), MPI.COMM_SELF, None,
                                progress=lambda _line: None)
        assert result.converged and energy_error(result, reference) < 1e-8
        assert np.allclose(result.fracture.G, reference.fracture.G, rtol=1e-6)
    with pytest.raises(SceneError, match="^solver.method = mprgp: block u_plus of the 3-D box is floating"):
        solid_dd.method_of(scene.with_({"solver.method": "mprgp"}), solid_dd.decomposition(scene, mesh, 1), held)
    free = loads(PENNY.replace("[displacements.layer1.bottom]\ny = 0.0\n", ""))
    free_mesh = solid.build(free)
    with pytest.raises(SceneError, match="^the structure can translate in y: add a support"):
        solid_dd.kernels_of(solid_dd.decomposition(free, free_mesh, 1))


@pytest.mark.mpi
def test_the_3d_decomposition_on_2_and_4_ranks_equals_the_reference(tmp_path):
    """ddsolve solve -n 4 (each half on two ranks, schur) and -n 2 (feti): their files hold the reference's
    solution to 1e-8 in energy norm."""
    from conftest import ddsolve

    from ddsolve.io import solid as solid_files
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid as solid_solver

    scene = tmp_path / "closure.toml"
    scene.write_text(CLOSURE.text)
    reference = solid_solver.solve_solid(CLOSURE, solid.build(CLOSURE))
    for ranks, method in ((4, "schur"), (2, "feti")):
        solved = ddsolve("solve", str(scene), "-o", str(tmp_path / f"{ranks}.h5"), "--set", f"solver.method={method}",
                         ranks=ranks)
        assert f"{method} (3-D):" in solved.stdout and f"on {ranks} ranks" in solved.stdout
        assert solid_solver.energy_error(solid_files.read(tmp_path / f"{ranks}.h5"), reference) < 1e-8
