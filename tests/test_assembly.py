"""Serial checks of the P1 and P2 elasticity assembly and of Hooke's law."""
import math

import numpy as np
import pytest
from conftest import structured_mesh

from ddsolve.fem import assembly
from ddsolve.mesh.mesh import SigmaLine
from ddsolve.problem import expressions, materials
from ddsolve.problem.scene import Geometry, Load

STEEL = materials.Isotropic(E=200.0, nu=0.28)
D_STEEL, C_STEEL = materials.elasticity(STEEL)


def dense(points, cells, D=D_STEEL):
    rows, cols, values = assembly.stiffness(points, cells, D)
    n = 2 * len(points)
    indptr, indices, data = assembly.coo_to_csr(n, rows, cols, values)
    K = np.zeros((n, n))
    K[np.repeat(np.arange(n), np.diff(indptr)), indices] = data
    return K


@pytest.fixture(scope="module", params=[1, 2], ids=["P1", "P2"])
def half(request):
    return structured_mesh(6, 3, shear=0.4, degree=request.param).lower


def test_stiffness_is_symmetric_positive_semidefinite(half):
    K = dense(half.points, half.cells)
    assert np.abs(K - K.T).max() < 1e-12 * np.abs(K).max()
    assert np.linalg.eigvalsh(K).min() > -1e-10 * np.abs(K).max()


def test_rigid_body_modes_span_the_kernel(half):
    K = dense(half.points, half.cells)
    for mode in assembly.rigid_body_modes(half.points):
        assert np.abs(K @ mode).max() < 1e-11 * np.abs(K).max()
    eigenvalues = np.linalg.eigvalsh(K)
    assert np.sum(eigenvalues < 1e-9 * eigenvalues.max()) == 3


def exact_fields(points, degree):
    """Linear fields and, for P2, an equilibrated quadratic one: u = (x² − y², −2xy) has div u = 0, Δu = 0."""
    x, y = points.T
    linear = np.column_stack([0.01 + 0.002 * x - 0.003 * y, -0.02 + 0.004 * x + 0.001 * y])
    if degree == 1:
        return linear
    return linear + 0.005 * np.column_stack([x * x - y * y, -2.0 * x * y])


def test_patch_test_reproduces_the_polynomial_fields_of_the_element(half):
    """Prescribe the field on the boundary: the interior solution is that field exactly."""
    K = dense(half.points, half.cells)
    exact = exact_fields(half.points, half.degree).ravel()
    boundary = np.unique(half.boundary_edges)
    fixed = assembly.element_dofs(boundary[:, None]).ravel()
    free = np.setdiff1d(np.arange(len(exact)), fixed)
    u = exact.copy()
    u[free] = np.linalg.solve(K[np.ix_(free, free)], -K[np.ix_(free, fixed)] @ exact[fixed])
    assert np.abs(u - exact).max() < 1e-12


def test_energy_matches_the_assembled_matrix(half):
    K = dense(half.points, half.cells)
    u = np.random.default_rng(1).standard_normal((len(half.points), 2))
    assert assembly.energy(half.points, half.cells, D_STEEL, u) == pytest.approx(u.ravel() @ K @ u.ravel(), rel=1e-12)


def test_rotating_the_mesh_and_the_material_rotates_the_stiffness(half):
    """Invariance under rotation: K of the rotated mesh and fibre angle is Q K Qᵀ (Q rotates every node)."""
    angle = math.radians(37.0)
    R = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    fibre = materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3, angle=20.0)
    turned = materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3, angle=57.0)
    K = dense(half.points, half.cells, materials.elasticity(fibre, "plane_stress")[0])
    K_rotated = dense(half.points @ R.T, half.cells, materials.elasticity(turned, "plane_stress")[0])
    Q = np.kron(np.eye(len(half.points)), R)
    assert np.abs(K_rotated - Q @ K @ Q.T).max() < 1e-11 * np.abs(K).max()


@pytest.mark.parametrize("model", materials.MODELS)
def test_uniform_strain_gives_the_stress_of_the_plane_model(model):
    lower = structured_mesh(4, 2, shear=0.3, degree=2).lower
    x, y = lower.points.T
    u = np.column_stack([1e-3 * x, 0 * x])  # εxx = 1e-3 only
    D, c = materials.elasticity(STEEL, model)
    vm = assembly.von_mises(lower.points, lower.cells, D, c, u)
    E, nu = STEEL.E, STEEL.nu
    if model == "plane_strain":
        mu, lam = E / (2 * (1 + nu)), E * nu / ((1 + nu) * (1 - 2 * nu))
        sxx, syy, szz = (lam + 2 * mu) * 1e-3, lam * 1e-3, lam * 1e-3
    else:
        sxx, syy, szz = E / (1 - nu ** 2) * 1e-3, E * nu / (1 - nu ** 2) * 1e-3, 0.0
    expected = np.sqrt(0.5 * ((sxx - syy) ** 2 + (syy - szz) ** 2 + (szz - sxx) ** 2))
    assert np.allclose(vm, expected, rtol=1e-12)


def test_orthotropic_with_isotropic_constants_is_isotropic():
    E, nu = 200.0, 0.28
    same = materials.Orthotropic(E1=E, E2=E, G12=E / (2 * (1 + nu)), nu12=nu, angle=33.0)
    for model in materials.MODELS:
        for a, b in zip(materials.elasticity(same, model), materials.elasticity(STEEL, model)):
            assert np.allclose(a, b, rtol=1e-13, atol=1e-12 * E)


def test_plane_stress_is_plane_strain_with_modified_constants():
    E, nu = 200.0, 0.28
    stress = materials.elasticity(STEEL, "plane_stress")[0]
    strain = materials.elasticity(materials.Isotropic(E * (1 + 2 * nu) / (1 + nu) ** 2, nu / (1 + nu)))[0]
    assert np.allclose(stress, strain, rtol=1e-13)


def test_fibres_at_90_degrees_swap_the_directions():
    fibre = materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3)
    D0 = materials.elasticity(fibre, "plane_stress")[0]
    D90 = materials.elasticity(materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3, angle=90.0),
                               "plane_stress")[0]
    assert D90[0, 0] == pytest.approx(D0[1, 1]) and D90[1, 1] == pytest.approx(D0[0, 0])
    assert abs(D90[0, 2]) < 1e-12 * D0[0, 0]


@pytest.mark.parametrize("matrix, message", [
    ([[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "not symmetric"),
    ([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "not positive definite"),
])
def test_a_matrix_that_is_not_spd_is_rejected(matrix, message):
    with pytest.raises(materials.MaterialError, match=message):
        materials.elasticity(materials.Anisotropic(D=tuple(map(tuple, matrix))))


def polynomial_load(component, coefficients) -> Load:
    return Load("loads.layer1.bottom", **{component: expressions.polynomial_in_x(coefficients)})


@pytest.mark.parametrize("degree", [1, 2])
@pytest.mark.parametrize("coefficients", [(0.5,), (0.0, 0.078125), (1.0, -2.0, 3.0, 0.5)])
def test_traction_load_totals_equal_the_integrals(degree, coefficients):
    lower = structured_mesh(7, 2, shear=0.2, degree=degree).lower
    edges = lower.edges("bottom")
    load = assembly.boundary_load(lower.points, edges, polynomial_load("x", coefficients))
    load += assembly.boundary_load(lower.points, edges, polynomial_load("y", coefficients[::-1]))
    poly = np.polynomial.Polynomial
    integral = lambda c: (poly(c).integ()(1.0) - poly(c).integ()(-1.0))  # noqa: E731
    x = lower.points[:, 0]
    assert load[0::2].sum() == pytest.approx(integral(coefficients), abs=1e-13)
    assert load[1::2].sum() == pytest.approx(integral(coefficients[::-1]), abs=1e-13)
    # first moment: exact for the consistent load of a polynomial of any degree
    assert load[0::2] @ x == pytest.approx(integral(np.convolve(coefficients, [0.0, 1.0])), abs=1e-13)
    assert np.all(load.reshape(-1, 2)[lower.points[:, 1] != -1.0] == 0.0)


@pytest.mark.parametrize("degree", [1, 2])
def test_expressions_and_pressures(degree):
    mesh = structured_mesh(6, 3, degree=degree)
    lower, upper = mesh.lower, mesh.upper
    expression = Load("loads.layer1.bottom", y=expressions.parse("1e-3*(x^2 - y)"))
    load = assembly.boundary_load(lower.points, lower.edges("bottom"), expression)
    assert load[1::2].sum() == pytest.approx(1e-3 * (2.0 / 3.0 + 2.0), rel=1e-13)  # y = −1 on the bottom
    wave = Load("loads.layer1.bottom", x=expressions.parse("sin(pi*x/2)^2"))
    assert assembly.boundary_load(lower.points, lower.edges("bottom"), wave)[0::2].sum() == pytest.approx(1.0, rel=1e-6)
    # a pressure p pushes along −n: on the top (n = +y) the total force is (0, −2p); on the right side (n = +x), (−p·1, 0)
    pressure = Load("loads.layer1.top", pressure=expressions.constant(3.0))
    top = assembly.boundary_load(upper.points, upper.edges("top"), pressure).reshape(-1, 2).sum(axis=0)
    right = assembly.boundary_load(upper.points, upper.edges("right"), pressure).reshape(-1, 2).sum(axis=0)
    assert np.allclose(top, [0.0, -6.0], atol=1e-13) and np.allclose(right, [-3.0, 0.0], atol=1e-13)


def test_a_non_finite_load_names_its_key():
    from ddsolve.errors import SceneError

    lower = structured_mesh(4, 2).lower
    with pytest.raises(SceneError, match=r"loads.layer1.bottom: the load is not finite at \(x, y\)"):
        assembly.boundary_load(lower.points, lower.edges("bottom"), Load("loads.layer1.bottom",
                                                                         y=expressions.parse("sqrt(x)")))


@pytest.mark.parametrize("degree", [1, 2])
def test_block_system_decouples_clamped_dofs_and_lists_the_trace(degree):
    mesh = structured_mesh(8, 4, degree=degree)
    lower = mesh.lower
    load = Load("loads.layer1.bottom", y=expressions.constant(1.0))
    system = assembly.block_system("u_minus", lower, mesh.sigma, D_STEEL, [load])
    n = system.size
    K = np.zeros((n, n))
    K[np.repeat(np.arange(n), np.diff(system.indptr)), system.indices] = system.data
    clamped = assembly.element_dofs(lower.clamped()[:, None]).ravel()
    off_diagonal = K[clamped].copy()
    off_diagonal[np.arange(len(clamped)), clamped] = 0.0
    assert np.all(off_diagonal == 0.0) and np.all(K[clamped, clamped] > 0)
    assert np.all(system.rhs[clamped] == 0.0)
    assert np.linalg.eigvalsh(K).min() > 0
    inner = lower.sigma[1:-1]  # the Σ ends are clamped
    assert np.array_equal(system.trace_dofs, np.column_stack([2 * inner, 2 * inner + 1]).ravel())
    assert np.all(np.diff(lower.points[inner, 0]) > 0)


def test_local_frames_rotate_the_matrix_and_the_load():
    half = structured_mesh(4, 2, shear=0.3).lower
    nodes = half.sigma[1:-1]
    angles = np.linspace(0.1, 1.3, len(nodes))
    frames = np.array([[[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]] for a in angles])
    matrices = assembly.element_stiffness(half.points, half.cells, D_STEEL)
    assembly.rotate_elements(matrices, half.cells, nodes, frames, len(half.points))
    n = 2 * len(half.points)
    dofs = assembly.element_dofs(half.cells)
    R = np.eye(n)
    for node, frame in zip(nodes, frames):
        R[2 * node:2 * node + 2, 2 * node:2 * node + 2] = frame
    K, K_local = dense(half.points, half.cells), np.zeros((n, n))
    np.add.at(K_local, (dofs[:, :, None], dofs[:, None, :]), matrices)
    assert np.abs(K_local - R @ K @ R.T).max() < 1e-12 * np.abs(K).max()
    u = np.random.default_rng(3).standard_normal(n)
    assert np.allclose(assembly.rotate_vector(u, nodes, frames), R @ u)
    assert np.allclose(assembly.to_global(R @ u, nodes, frames).ravel(), u)


def csr_dense(system) -> np.ndarray:
    local = len(system.indptr) - 1
    K = np.zeros((local, system.size))
    K[np.repeat(np.arange(local), np.diff(system.indptr)), system.indices] = system.data
    return K


@pytest.mark.parametrize("degree", [1, 2])
def test_the_pattern_scatter_sums_rotated_element_matrices_and_splits_into_row_ranges(degree, monkeypatch):
    """block_system against a dense sum of R Kₑ Rᵀ with clamped dofs decoupled, whole and in row ranges."""
    import dataclasses

    mesh = structured_mesh(8, 3, shear=0.3, degree=degree, geometry=Geometry())
    half = mesh.lower
    angles = np.linspace(-0.4, 0.9, len(mesh.sigma.points))
    sigma = dataclasses.replace(mesh.sigma, normals=np.column_stack([-np.sin(angles), np.cos(angles)]))
    nodes, frames = assembly.trace_nodes(half, sigma), sigma.frames[sigma.multiplier_nodes]
    n = 2 * len(half.points)
    R = np.eye(n)
    for node, frame in zip(nodes, frames):
        R[2 * node:2 * node + 2, 2 * node:2 * node + 2] = frame
    expected = R @ dense(half.points, half.cells) @ R.T
    clamped = assembly.element_dofs(half.clamped()[:, None]).ravel()
    diagonal = expected[clamped, clamped].copy()
    expected[clamped, :] = 0.0
    expected[:, clamped] = 0.0
    expected[clamped, clamped] = diagonal
    whole = assembly.block_system("u_minus", half, sigma, D_STEEL, [])
    assert np.abs(csr_dense(whole) - expected).max() < 1e-12 * np.abs(expected).max()
    assert np.all(np.diff(whole.indptr) > 0) and whole.indices.dtype == np.int32
    row = np.repeat(np.arange(len(whole.indptr) - 1), np.diff(whole.indptr))
    assert np.all((np.diff(whole.indices) > 0) | (np.diff(row) > 0))  # columns increase in every row (PETSc's AIJ)
    parts = [assembly.block_system("u_minus", half, sigma, D_STEEL, [], rows)
             for rows in assembly.row_ranges(len(half.points), 3)]
    assert np.array_equal(np.vstack([csr_dense(part) for part in parts]), csr_dense(whole))
    assert np.allclose(np.hstack([part.modes for part in parts]), whole.modes)
    monkeypatch.setattr(assembly, "ELEMENT_ENTRIES", 500)  # element matrices a few cells at a time
    assert np.allclose(assembly.block_system("u_minus", half, sigma, D_STEEL, []).data, whole.data, rtol=1e-14,
                       atol=1e-14 * np.abs(whole.data).max())


def test_sigma_weights_and_normals():
    for degree in (1, 2):
        sigma: SigmaLine = structured_mesh(8, 4, shear=0.3, degree=degree, geometry=Geometry()).sigma
        assert sigma.weights.sum() == pytest.approx(2.0, rel=1e-13) and np.all(sigma.weights > 0)
        assert np.allclose(sigma.normals, [0.0, 1.0]) and np.allclose(sigma.frames, np.eye(2))
        assert sigma.clamped.sum() == 2 and np.array_equal(np.flatnonzero(sigma.tip), [2 * degree, 6 * degree])


def test_interpolation_is_exact_for_linear_fields_and_errors_vanish_on_the_same_mesh():
    from ddsolve.post.analysis import interpolate

    coarse = structured_mesh(4, 2, shear=0.3).lower
    fine = structured_mesh(12, 6, shear=0.1).lower
    linear = lambda p: np.column_stack([1 + 2 * p[:, 0] - p[:, 1], 3 * p[:, 1]])  # noqa: E731
    assert np.allclose(interpolate(coarse, linear(coarse.points), fine.points), linear(fine.points), atol=1e-13)


@pytest.mark.parametrize("degree", [1, 2])
def test_a_piece_assembles_the_rows_of_the_whole_half(degree):
    """The rows a rank owns, assembled on its piece of the half (:mod:`ddsolve.mesh.pieces`: the cells of its
    nodes and their neighbours, the half's Σ and boundaries) and renumbered, are the whole half's rows: matrix,
    loads, prescribed displacements, thermal load, trace dofs and energy offset."""
    from ddsolve.fem import supports
    from ddsolve.mesh import geometry, pieces
    from ddsolve.problem import scene as scenes

    source = scenes.load("partial-closure", [
        "mesh.sigma_vertices=25", "mesh.boundary_vertices=32", f"mesh.degree={degree}", "geometry.clamped=[]",
        "displacements.layer1.left.x=0.001", "displacements.layer1.left.y=0.0", "displacements.layer1.right.y=0.0",
        "materials.layer1.alpha=2e-5", "temperature.layer1=50+10*x"])
    mesh = geometry.build(source)
    table = supports.sigma_supports(source, mesh)
    spec = "layer1"

    def system(on, rows, block):
        D, _ = assembly.elasticity(source, spec, on.name)
        return assembly.block_system("u", on, mesh.sigma, D, assembly.layer_loads(source, spec, on), rows,
                                     None, supports.block_supports(source, on, mesh.sigma, spec, block, table),
                                     assembly.thermal_of(source, spec, on.name))

    assert assembly.layer_loads(source, spec, mesh.upper)  # the upper half is loaded, the lower one displaced
    for block, half in enumerate(mesh.halves):
        for first, last in assembly.row_ranges(len(half.points), 3):
            whole = system(half, (first, last), block)
            piece = pieces.cut(half, first // 2, last // 2)
            owned = piece.owned_nodes
            mine = assembly.renumbered(system(piece.half, (2 * owned.start, 2 * owned.stop), block), piece.nodes,
                                       len(half.points))
            for key in ("indptr", "indices", "trace_dofs"):
                assert np.array_equal(getattr(mine, key), getattr(whole, key)), key
            assert (mine.first, mine.size) == (whole.first, whole.size)
            np.testing.assert_allclose(mine.data, whole.data, rtol=0, atol=1e-13 * np.abs(whole.data).max())
            np.testing.assert_allclose(mine.rhs, whole.rhs, rtol=0, atol=1e-13 * np.abs(whole.rhs).max())
            assert mine.energy_offset == pytest.approx(whole.energy_offset, rel=1e-12, abs=1e-15)
