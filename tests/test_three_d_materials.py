"""Materials of a 3-D body: transversely isotropic plies about a fibre direction, per region, and temperature
changes in the P1 and P2 tetrahedra (free expansion, patch test, rotation invariance, a bimaterial bar)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg
from test_three_d import PLANE, SOLID, elevated_grid

from ddsolve.errors import SceneError
from ddsolve.fem import tetra
from ddsolve.problem import expressions, materials
from ddsolve.problem.scene import loads

#: A ply whose fibre points along (1, 2, 2)/3, with different expansions along and across it.
PLY = materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3, nu23=0.4, alpha1=-1e-6, alpha2=3e-5,
                            fibre=(1.0, 2.0, 2.0))


def tensor(voigt: np.ndarray) -> np.ndarray:
    """The symmetric 3 × 3 strain of Voigt strains (engineering shears)."""
    xx, yy, zz, yz, xz, xy = voigt
    return np.array([[xx, xy / 2, xz / 2], [xy / 2, yy, yz / 2], [xz / 2, yz / 2, zz]])


def clamped_solve(K: scipy.sparse.csr_matrix, f: np.ndarray, fixed: np.ndarray, values: np.ndarray) -> np.ndarray:
    """K u = f with the dofs ``fixed`` at ``values``."""
    u = np.zeros(len(f))
    u[fixed] = values
    free = np.setdiff1d(np.arange(len(f)), fixed)
    u[free] = scipy.sparse.linalg.spsolve(K[free][:, free].tocsc(), f[free] - K[free][:, fixed] @ values)
    return u


def boundary_dofs(points: np.ndarray) -> np.ndarray:
    """The dofs of the nodes on the unit cube's sides."""
    nodes = np.flatnonzero(np.any(np.isclose(points, 0.0) | np.isclose(points, 1.0), axis=1))
    return tetra.element_dofs(nodes[:, None]).ravel()


@pytest.mark.unit
def test_a_ply_s_law_is_transversely_isotropic_about_its_fibre():
    """Along the fibre the ply is E1, across it E2 in every direction; a fibre of huge numbers is a direction; the
    angle key is the plane's fibre."""
    C = materials.solid_stiffness(PLY)
    fibre = np.array([1.0, 2.0, 2.0]) / 3.0
    across = np.cross(fibre, [1.0, 0.0, 0.0])
    for direction, modulus in ((fibre, 140.0), (across / np.linalg.norm(across), 10.0),
                               (np.cross(fibre, across) / np.linalg.norm(across), 10.0)):
        d = direction
        stretch = np.array([d[0] ** 2, d[1] ** 2, d[2] ** 2, d[1] * d[2], d[0] * d[2], d[0] * d[1]])  # σ = n ⊗ n
        assert np.isclose(1.0 / (stretch @ np.linalg.solve(C, stretch)), modulus, rtol=1e-12)
    huge = materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3, fibre=(1e308, 1e308, 0.0))
    assert np.allclose(materials.fibre_direction(huge), [0.5 ** 0.5, 0.5 ** 0.5, 0.0], rtol=1e-15)  # no overflow
    angled = materials.Orthotropic(E1=140.0, E2=10.0, G12=5.0, nu12=0.3, angle=30.0)
    plane, _ = materials.elasticity(angled)
    assert np.allclose(materials.solid_stiffness(angled)[np.ix_([0, 1, 5], [0, 1, 5])], plane, rtol=1e-13, atol=0)


@pytest.mark.unit
@pytest.mark.parametrize("degree", [1, 2])
def test_a_free_ply_expands_without_stress(degree):
    """A uniform ΔT on a free body (rigid motions removed): u = ε₀ x exactly, the strain is the eigenstrain and
    the energy zero."""
    points, cells = elevated_grid((2, 2, 2), degree)
    D = tetra.elastic_matrix(PLY)
    K = tetra.stiffness(points, cells, D)
    f, offset = tetra.thermal_load(points, cells, D, materials.solid_expansion(PLY), expressions.constant(40.0))
    eigenstrain = 40.0 * materials.solid_expansion(PLY)
    modes = tetra.rigid_modes(points)
    exact = (points @ tensor(eigenstrain)).ravel()
    saddle = scipy.sparse.bmat([[K, modes.T], [modes, None]]).tocsc()
    u = scipy.sparse.linalg.spsolve(saddle, np.concatenate([f, modes @ exact]))[:len(f)]
    assert np.abs(u - exact).max() < 1e-12 * np.abs(exact).max()
    assert np.abs(tetra.strains(points, cells, u) - eigenstrain).max() < 1e-10 * np.abs(eigenstrain).max()
    assert abs(0.5 * u @ (K @ u) - f @ u + offset) < 1e-10 * offset


@pytest.mark.unit
@pytest.mark.parametrize("degree", [1, 2])
def test_ply_tetrahedra_pass_the_patch_test(degree):
    """A linear field prescribed on the boundary of a ply is reproduced exactly inside, its stress C ε."""
    points, cells = elevated_grid((2, 2, 2), degree)
    K = tetra.stiffness(points, cells, tetra.elastic_matrix(PLY))
    A = np.array([[1e-3, 2e-3, -1e-3], [0.5e-3, -2e-3, 1e-3], [3e-3, 1e-3, 2e-3]])
    exact = (points @ A.T).ravel()
    fixed = boundary_dofs(points)
    u = clamped_solve(K, np.zeros(len(exact)), fixed, exact[fixed])
    assert np.abs(u - exact).max() < 1e-12
    sym = 0.5 * (A + A.T)
    strain = np.array([sym[0, 0], sym[1, 1], sym[2, 2], 2 * sym[1, 2], 2 * sym[0, 2], 2 * sym[0, 1]])
    assert np.allclose(tetra.strains(points, cells, u), strain, rtol=0, atol=1e-14)


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """The rotation by ``angle`` radians about ``axis`` (Rodrigues)."""
    k = axis / np.linalg.norm(axis)
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * cross @ cross


@pytest.mark.unit
@pytest.mark.parametrize("degree", [1, 2])
def test_a_rotated_ply_under_a_rotated_temperature_gives_the_rotated_answer(degree):
    """A clamped cube of ply heated by ΔT(x) = 1 + x² + y z: the body, its fibre and ΔT rotated by R give
    u_R(R x) = R u(x) at every node."""
    R = rotation(np.array([1.0, -2.0, 0.5]), 0.7)
    points, cells = elevated_grid((2, 2, 2), degree)
    fields = []
    for turn in (np.eye(3), R):
        here = points @ turn.T
        x, y, z = (" + ".join(f"({turn[j, i]!r}) * {name}" for j, name in enumerate("xyz")) for i in range(3))
        change = expressions.parse(f"1 + ({x})^2 + ({y}) * ({z})")  # ΔT at Rᵀ x
        ply = materials.Orthotropic(**{**PLY.__dict__, "fibre": tuple(turn @ PLY.fibre)})
        D = tetra.elastic_matrix(ply)
        f, _ = tetra.thermal_load(here, cells, D, materials.solid_expansion(ply), change)
        fixed = boundary_dofs(points)
        fields.append(clamped_solve(tetra.stiffness(here, cells, D), f, fixed, np.zeros(len(fixed))).reshape(-1, 3))
    assert np.abs(fields[0]).max() > 1e-6
    assert np.abs(fields[1] - fields[0] @ R.T).max() < 1e-12 * np.abs(fields[0]).max()


#: A bar across Σ pulled along y on rollers: isotropic below, a ply with its fibre along y above, ν/E the same.
BAR = """
[geometry]
box = [0, 1, -1, 0.5, 0, 1]
sigma = 0.0
clamped = []
[mesh]
size = 0.5
[materials.layer1]
E = 100.0
nu = 0.1
[materials.layer1.upper]
E1 = 250.0
E2 = 20.0
G12 = 5.0
nu12 = 0.25
fibre = [0, 1, 0]
[loads.layer1.top]
y = 0.5
[displacements.layer1.left]
x = 0.0
[displacements.layer1.bottom]
y = 0.0
[displacements.layer1.front]
z = 0.0
"""


@pytest.mark.solve
def test_a_bimaterial_bar_across_sigma_and_a_free_thermal_expansion_are_solved_exactly():
    """The bar: u_y = s (y + 1)/E below, s/E + s y/E1 above, u_x = −ν s x/E, u_z = −ν s z/E; Π = −½ s² (1/E + 0.5/E1).
    Heated on its rollers instead (ΔT = 20, α = 1e-5 in both halves): u = α ΔT (x, y + 1, z), Π = 0."""
    from ddsolve.solvers import solid as solid_solver

    s, E, nu, E1 = 0.5, 100.0, 0.1, 250.0
    bar = solid_solver.reference(loads(BAR))
    for half, u in zip(bar.mesh.halves, bar.fields):
        x, y, z = half.points.T
        exact = np.column_stack([-nu * s * x / E, s * np.where(y < 1e-12, (y + 1) / E, 1 / E + y / E1),
                                 -nu * s * z / E])
        assert np.abs(u - exact).max() < 1e-12
    assert bar.converged and np.isclose(bar.energy, -0.5 * s ** 2 * (1 / E + 0.5 / E1), rtol=1e-12)
    heated = BAR.replace("[loads.layer1.top]\ny = 0.5", "[temperature]\nlayer1 = 20.0").replace(
        "nu = 0.1", "nu = 0.1\nalpha = 1e-5").replace("nu12 = 0.25", "nu12 = 0.25\nalpha1 = 1e-5\nalpha2 = 1e-5")
    free = solid_solver.reference(loads(heated))
    for half, u in zip(free.mesh.halves, free.fields):
        assert np.abs(u - 2e-4 * (half.points + [0.0, 1.0, 0.0])).max() < 1e-15
    assert free.converged and abs(free.energy) < 1e-15


@pytest.mark.unit
def test_ply_keys_are_refused_where_they_mean_nothing():
    """A fibre in the plane, a ply not transversely isotropic, a fibre given twice or zero, a plane matrix in 3-D."""
    def upper(keys: str) -> str:
        return SOLID.format(crack="[]").replace("E = 100.0\nnu = 0.25\n", keys)

    ply = "E1 = 2.0\nE2 = 1.0\nG12 = 0.5\nnu12 = 0.3\n"
    bad = {"[mesh]\nsize = 0.5\n" + PLANE.replace("E = 1.0\nnu = 0.3\n", ply + "fibre = [1, 0, 0]\n", 1):
           "materials.layer1.fibre: a fibre direction in 3-D",
           upper(ply + "E3 = 2.0\n"): "materials.layer1.upper.E3: a 3-D ply is transversely isotropic",
           upper(ply + "angle = 10\nfibre = [0, 0, 1]\n"): "materials.layer1.upper.fibre: give the fibre by fibre or",
           upper(ply + "fibre = [0, 0, 0]\n"): "materials.layer1.upper.fibre: a direction, not zero",
           upper("D = [[2, 1, 0], [1, 2, 0], [0, 0, 1]]\n"): "materials.layer1.upper: a 3-D body takes isotropic"}
    for text, message in bad.items():
        with pytest.raises(SceneError) as error:
            loads(text)
        assert message in str(error.value) and "\n" not in str(error.value)
    scene = loads(upper(ply + "fibre = [0, 3, 4]\n"))
    assert scene.material("layer1", "upper").fibre == (0.0, 3.0, 4.0) and loads(scene.text) == scene


@pytest.mark.solve
def test_a_3d_result_equals_the_decomposition_s_and_is_read_back_exported_and_plotted(tmp_path):
    """A heated P2 body with a ply above Σ and a crack rectangle, partly shut: the domain decomposition (schur, one
    rank) gives the reference's solution to 1e-8 in energy norm, its energy (the thermal offset counted) and its G
    along the front (the eigenstrain's term), each printing its progress lines stage by stage; the
    reference's file read back gives the same result; export writes VTU files meshio reads (tetra10, 6-node triangles); plot writes the opening map and the
    deformed body; XDMF files (arrays inline) read back to the last bit."""
    import meshio
    from mpi4py import MPI

    from ddsolve.cli import parser
    from ddsolve.io import solid as solid_files
    from ddsolve.solvers import solid as solid_solver, solid_dd

    text = BAR.replace("clamped = []", "crack = [0.2, 0.8, 0.2, 0.8]\nclamped = [\"right\"]").replace(
        "[loads.layer1.top]\ny = 0.5", "[temperature]\nlayer1 = \"20 * x\"").replace(
        "nu = 0.1", "nu = 0.1\nalpha = 1e-5").replace("nu12 = 0.25", "nu12 = 0.25\nalpha1 = 3e-5\nalpha2 = 1e-6")
    scene = loads(text).with_({"mesh.degree": 2, "mesh.size": 0.8})
    lines = []
    solved = solid_solver.reference(scene, tmp_path / "hot.h5", progress=lines.append)
    assert [line.split(":")[0] for line in lines] == ["mesh", "the merged system", "G along the crack fronts"]
    lines.clear()
    assert solved.converged and solved.closed > 0 and solved.normal_opening.max() > 0
    decomposed = solid_dd.solve(scene.with_({"solver.method": "schur"}), MPI.COMM_SELF, tmp_path / "dd.h5",
                                progress=lines.append)
    assert decomposed.converged and solid_solver.energy_error(decomposed, solved) < 1e-8
    assert abs(decomposed.energy - solved.energy) < 1e-10 * abs(solved.energy)
    assert np.allclose(decomposed.fracture.G, solved.fracture.G, rtol=0.0, atol=1e-7 * np.abs(solved.fracture.G).max())
    assert [line.split(":")[0] for line in lines] == ["mesh", "rank 0's blocks (schur)", "schur",
                                                      "G along the crack fronts"]
    read = solid_files.read(tmp_path / "hot.h5")
    assert read.energy == solved.energy and read.scene == scene and read.checks == solved.checks
    assert all(np.array_equal(a, b) for a, b in zip(read.fields, solved.fields))
    assert np.array_equal(read.pressure, solved.pressure)
    def command(*words: str) -> int:
        args = parser().parse_args(list(words))
        return args.run(args, [])

    out = tmp_path / "out"
    out.mkdir()
    assert command("export", str(tmp_path / "hot.h5"), "-o", str(out)) == 0
    upper, sigma = meshio.read(out / "hot-upper.vtu"), meshio.read(out / "hot-sigma.vtu")
    assert upper.cells[0].type == "tetra10" and sigma.cells[0].type == "triangle6"
    assert np.allclose(upper.point_data["displacement"], solved.fields[1])
    assert np.allclose(sigma.point_data["contact_pressure"], solved.pressure)
    assert command("plot", str(tmp_path / "hot.h5")) == 0
    assert all((tmp_path / f"hot-{name}.png").stat().st_size > 10_000 for name in ("opening", "deformed"))
    assert command("export", str(tmp_path / "hot.h5"), "--format", "xdmf", "-o", str(out)) == 0
    lower, sigma = meshio.read(out / "hot-lower.xdmf"), meshio.read(out / "hot-sigma.xdmf")
    assert lower.cells[0].type == "tetra10" and np.array_equal(lower.point_data["displacement"], solved.fields[0])
    assert np.array_equal(sigma.point_data["cracked"], solved.mesh.sigma.cracked)
