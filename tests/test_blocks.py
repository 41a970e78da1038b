"""PETSc blocks (serial, in this process): solves, Schur complements, options prefixes."""
import numpy as np
import pytest

petsc4py = pytest.importorskip("petsc4py")
petsc4py.init()
from conftest import structured_mesh  # noqa: E402
from petsc4py import PETSc  # noqa: E402

from ddsolve.fem import assembly
from ddsolve.parallel.blocks import Block, default_factor_package
from ddsolve.problem import expressions, materials
from ddsolve.problem.scene import Load


@pytest.fixture(scope="module", params=[1, 2], ids=["P1", "P2"])
def system(request):
    mesh = structured_mesh(12, 6, shear=0.3, degree=request.param)
    D, _ = materials.elasticity(materials.Isotropic(200.0, 0.28))
    load = Load("loads.layer1.bottom", y=expressions.polynomial_in_x((0.1, 0.2)))
    return assembly.block_system("u_minus", mesh.lower, mesh.sigma, D, [load])


def dense(system):
    K = np.zeros((system.size, system.size))
    K[np.repeat(np.arange(system.size), np.diff(system.indptr)), system.indices] = system.data
    return K


@pytest.mark.parametrize("package", ["petsc", "mumps"])
def test_solve_matches_a_dense_solve(system, package):
    block = Block(system, factor_package=package)
    block.factor()
    load = np.linspace(-1.0, 1.0, len(system.trace_dofs))
    rhs = system.rhs.copy()
    rhs[system.trace_dofs] += load
    x = block.solve(load, body=True)
    assert np.allclose(x, np.linalg.solve(dense(system), rhs), rtol=1e-10, atol=1e-14)
    block.destroy()


@pytest.mark.skipif(default_factor_package("mumps") != "mumps", reason="PETSc without MUMPS")
def test_schur_complement_from_mumps_is_the_condensed_stiffness(system):
    K = dense(system)
    trace = system.trace_dofs
    inner = np.setdiff1d(np.arange(system.size), trace)
    expected = K[np.ix_(trace, trace)] - K[np.ix_(trace, inner)] @ np.linalg.solve(K[np.ix_(inner, inner)],
                                                                                   K[np.ix_(inner, trace)])
    block = Block(system, factor_package="mumps")
    block.factor(schur=True)
    S = block.schur_complement()
    assert np.abs(S - expected).max() < 1e-10 * np.abs(expected).max()
    # full solves still work with the Schur complement requested
    x = block.solve(np.ones(len(trace)), body=True)
    rhs = system.rhs.copy()
    rhs[trace] += 1.0
    assert np.allclose(K @ x, rhs, rtol=1e-9, atol=1e-12)
    # and without it the same matrix comes from multi-column solves
    plain = Block(system, factor_package="petsc")
    plain.factor(schur=True)  # no MUMPS: falls back to the flexibility
    assert np.abs(plain.schur_complement() - expected).max() < 1e-9 * np.abs(expected).max()
    block.destroy()
    plain.destroy()


@pytest.mark.skipif(default_factor_package("mumps") != "mumps", reason="PETSc without MUMPS")
@pytest.mark.parametrize("route", ["dirichlet", "inverse", "solves"])
def test_every_schur_route_gives_the_condensed_stiffness(system, route):
    """``-u_minus_schur_complement dirichlet`` (multi-column solves of the Dirichlet problem), ``inverse``
    (MUMPS's entries of K⁻¹) and ``solves`` (multi-column solves) after a plain factorization give the Schur
    complement of ``factorization``, and solves afterwards are still ordinary ones."""
    reference = Block(system, factor_package="mumps")
    reference.factor(schur=True)
    assert reference.route == "factorization"
    expected = reference.schur_complement()
    reference.destroy()
    options = PETSc.Options()
    options["u_minus_schur_complement"] = route
    try:
        block = Block(system, factor_package="mumps")
        block.factor(schur=True)
    finally:
        options.delValue("u_minus_schur_complement")
    assert block.route == route
    assert np.abs(block.schur_complement() - expected).max() < 1e-10 * np.abs(expected).max()
    if route == "inverse":
        assert np.allclose(block.inverse_entries(), block.flexibility(), rtol=1e-10, atol=1e-14)
    x = block.solve(np.ones(len(system.trace_dofs)), body=True)
    rhs = system.rhs.copy()
    rhs[system.trace_dofs] += 1.0
    assert np.allclose(dense(system) @ x, rhs, rtol=1e-9, atol=1e-12)
    block.destroy()


def test_a_route_the_package_cannot_take_falls_back_to_dirichlet_and_a_bad_route_is_refused(system):
    from ddsolve.errors import SolverError

    options = PETSc.Options()
    try:
        options["u_minus_schur_complement"] = "inverse"
        plain = Block(system, factor_package="petsc")
        plain.factor(schur=True)  # PETSc's Cholesky has no entries of the inverse
        assert plain.route == "dirichlet"
        options["u_minus_schur_complement"] = "lu"
        with pytest.raises(SolverError, match=r"^-u_minus_schur_complement lu: unknown, use one of factorization, "
                                              r"dirichlet, inverse, solves$"):
            plain.factor(schur=True)
        plain.destroy()
    finally:
        options.delValue("u_minus_schur_complement")


def test_options_prefix_selects_the_block_solver(system):
    options = PETSc.Options()
    options["u_minus_ksp_type"] = "cg"
    options["u_minus_pc_type"] = "jacobi"
    options["u_minus_ksp_rtol"] = 1e-12
    try:
        block = Block(system)
        assert block.ksp.getOptionsPrefix() == "u_minus_"
        assert block.ksp.getType() == "cg" and block.ksp.getPC().getType() == "jacobi"
        assert not block.is_direct()
        block.factor()
        x = block.solve(np.zeros(len(system.trace_dofs)), body=True)
        assert np.allclose(x, np.linalg.solve(dense(system), system.rhs), rtol=1e-8, atol=1e-12)
        block.destroy()
    finally:
        for key in ("u_minus_ksp_type", "u_minus_pc_type", "u_minus_ksp_rtol"):
            options.delValue(key)


def test_power_iteration_bound_is_the_largest_eigenvalue_of_the_dual_operator():
    """driver.bound (rounds of block solves, here on one rank) against the assembled dense operator."""
    from mpi4py import MPI

    from ddsolve.dd.interface import for_mesh
    from ddsolve.mesh import geometry
    from ddsolve.problem import scene
    from ddsolve.solvers import driver

    s = scene.load("partial-closure", ["mesh.sigma_vertices=13", "mesh.boundary_vertices=32", "solver.method=uzawa"])
    mesh = geometry.build(s)
    interface = for_mesh(mesh.sigma, s.nonpenetration)
    flexibilities = []
    for system in assembly.block_systems(s, mesh):
        block = Block(system)
        block.factor()
        flexibilities.append(block.flexibility())
        block.destroy()
    sqrt_w = np.sqrt(interface.row_weights)
    dense = interface.dual_matrix(np.array(flexibilities)) / np.outer(sqrt_w, sqrt_w)
    expected = np.linalg.eigvalsh(dense).max()
    assert driver.bound(s, MPI.COMM_WORLD, mesh) == pytest.approx(expected, rel=1e-6)


@pytest.mark.skipif(default_factor_package("mumps") != "mumps", reason="PETSc without MUMPS")
@pytest.mark.parametrize("schur", [False, True], ids=["plain", "schur"])
def test_out_of_core_factors_give_the_in_core_answers_and_leave_no_files(system, schur, tmp_path, monkeypatch):
    """``out_of_core``: MUMPS writes the factors into MUMPS_OOC_TMPDIR, solves the same, and removes its
    files when the block is destroyed; the code default leaves PETSc's option database as it was."""
    monkeypatch.setenv("MUMPS_OOC_TMPDIR", str(tmp_path))
    answers = []
    for out_of_core in (False, True):
        block = Block(system, factor_package="mumps")
        block.factor(schur=schur, out_of_core=out_of_core)
        assert block.out_of_core() == out_of_core
        if out_of_core:
            assert any(tmp_path.iterdir())  # the factors are on disk while the block lives
        x = block.solve(np.linspace(-1.0, 1.0, len(system.trace_dofs)), body=True).copy()
        answers.append((x, block.schur_complement() if schur else None))
        block.destroy()
    assert not any(tmp_path.iterdir())
    assert not PETSc.Options().hasName("u_minus_mat_mumps_icntl_22")
    assert np.allclose(answers[1][0], answers[0][0], rtol=1e-12, atol=1e-15 * np.abs(answers[0][0]).max())
    if schur:
        assert np.allclose(answers[1][1], answers[0][1], rtol=1e-12, atol=1e-12 * np.abs(answers[0][1]).max())


@pytest.mark.skipif(default_factor_package("mumps") != "mumps", reason="PETSc without MUMPS")
@pytest.mark.parametrize("route", ["factorization", "inverse", "solves", "one by one"])
def test_a_floating_blocks_schur_complement_is_its_condensed_stiffness_by_every_route(system, route):
    """A block with no support (K singular, K_II not): MUMPS's partial factorization (``factorization``),
    multi-column Dirichlet solves (the other routes) and single Dirichlet solves (an iterative Dirichlet
    solver) all give K_ΣΣ − K_ΣI K_II⁻¹ K_IΣ, singular on the rigid motions."""
    K = dense(system)
    trace = system.trace_dofs
    inner = np.setdiff1d(np.arange(system.size), trace)
    expected = K[np.ix_(trace, trace)] - K[np.ix_(trace, inner)] @ np.linalg.solve(K[np.ix_(inner, inner)],
                                                                                   K[np.ix_(inner, trace)])
    options = PETSc.Options()
    settings = ({"u_minus_dirichlet_ksp_type": "cg", "u_minus_dirichlet_pc_type": "jacobi",
                 "u_minus_dirichlet_ksp_rtol": 1e-14, "u_minus_schur_complement": "solves"} if route == "one by one"
                else {"u_minus_schur_complement": route})
    try:
        for key, value in settings.items():
            options[key] = value
        block = Block(system, factor_package="mumps")
        block.make_floating(np.zeros((3, system.size)))
        block.factor(schur=True)
        block.factor_dirichlet()
        S = block.schur_complement()
    finally:
        for key in settings:
            options.delValue(key)
    assert np.abs(S - expected).max() < 1e-8 * np.abs(expected).max()
    block.destroy()
