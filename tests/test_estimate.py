"""The error estimate (SPR recovery per block, contact term) and P2 interpolation."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import MATERIALS, structured_mesh

from ddsolve.fem.assembly import element_dofs, strain_operator
from ddsolve.mesh import element, geometry, pieces
from ddsolve.mesh.element import element_geometry
from ddsolve.mesh.mesh import HalfMesh
from ddsolve.post import analysis, estimate
from ddsolve.problem import scene
from ddsolve.problem.materials import Isotropic, elasticity
from ddsolve.problem.scene import Geometry
from ddsolve.solvers import reference

D, _ = elasticity(Isotropic(E=200.0, nu=0.28), "plane_strain")
CRACKED = Geometry()


def quadratic(p):  # harmonic and divergence-free: an elastic field without body force
    x, y = p[:, 0], p[:, 1]
    return np.column_stack([x * x - y * y + 0.3 * y, -2 * x * y + 0.1])


def cubic(p):
    x, y = p[:, 0], p[:, 1]
    return np.column_stack([x ** 3 - 3 * x * y * y, -(3 * x * x * y - y ** 3)]) + quadratic(p)


def cubic_strain(p):
    x, y = p[..., 0], p[..., 1]
    exx = 3 * x * x - 3 * y * y + 2 * x
    eyy = -(3 * x * x - 3 * y * y) - 2 * x
    gxy = (-6 * x * y - 2 * y + 0.3) + (-6 * x * y - 2 * y)
    return np.stack([exx, eyy, gxy], axis=-1)


def quadratic_strain(p):
    x, y = p[..., 0], p[..., 1]
    return np.stack([2 * x, -2 * x, -2 * y + 0.3 - 2 * y], axis=-1)


@pytest.mark.parametrize("degree, field", [(1, lambda p: np.column_stack([1 + 2 * p[:, 0] - p[:, 1], 3 * p[:, 1]])),
                                           (2, quadratic)])
def test_fields_of_the_element_space_have_zero_estimate(degree, field):
    """SPR reproduces strains of the fitted degree: P1 with a linear field, P2 with a quadratic one."""
    for half in structured_mesh(8, 4, shear=0.3, degree=degree).halves:
        u = field(half.points)
        error, energy = estimate.block_indicators(half.points, half.cells, D, u)
        assert error.sum() < 1e-24 * energy.sum()
        assert np.allclose(estimate.recovered_strain(half.points, half.cells, u)[:, 2],
                           (quadratic_strain(half.points)[:, 2] if degree == 2 else -1.0), atol=1e-11)


@pytest.mark.parametrize("degree", [1, 2])
def test_a_half_s_known_outer_edges_give_the_indicators_found_from_its_cells(degree):
    half = structured_mesh(8, 4, shear=0.3, degree=degree).lower
    u = cubic(half.points)
    assert np.array_equal(estimate.half_indicators(half, D, u), estimate.block_indicators(half.points, half.cells, D, u))


def test_every_point_is_located_in_a_cell_that_holds_it_on_a_strongly_graded_mesh():
    """Cells from 1e-6 to 0.1 across (a tip's grading, exaggerated): each point inside is in the cell
    found for it, each point outside is reported outside."""
    half = structured_mesh(40, 20, shear=0.3).lower
    graded = half.points.copy()
    graded[:, 0] = np.sign(graded[:, 0]) * np.abs(graded[:, 0]) ** 4  # cells shrink towards x = 0
    half = HalfMesh(graded, half.cells, half.side, half.sigma)
    rng = np.random.default_rng(6)
    inside = np.column_stack([np.sign(rng.standard_normal(4000)) * rng.random(4000) ** 6, -rng.random(4000)])
    outside = np.column_stack([rng.uniform(-1.0, 1.0, 500), rng.uniform(0.05, 1.0, 500)])  # above y = 0
    cell, out = analysis.locate(half, np.vstack([inside, outside]))
    assert not out[:len(inside)].any() and out[len(inside):].all()
    corners = half.points[half.corners[cell[:len(inside)]]]  # (q, 3, 2)
    first, second, offset = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], inside - corners[:, 0]
    det = first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]
    s = (offset[:, 0] * second[:, 1] - offset[:, 1] * second[:, 0]) / det
    t = (first[:, 0] * offset[:, 1] - first[:, 1] * offset[:, 0]) / det
    assert np.all(s >= -1e-9) and np.all(t >= -1e-9) and np.all(s + t <= 1.0 + 1e-9)


def _true_interpolation_error(half, u, exact_strain) -> float:
    xi, weights = element.TRIANGLE_RULES[6]  # degree 4: exact for the squared difference on straight cells
    det, gradients = element_geometry(half.points, half.cells, xi)
    strain = np.einsum("mqij,mj->mqi", strain_operator(gradients), u.reshape(-1)[element_dofs(half.cells)])
    shapes = estimate.shape_functions(half.cells.shape[1], xi)[0]
    where = np.einsum("qk,mkd->mqd", shapes, half.points[half.cells])
    difference = exact_strain(where) - strain
    return float(np.sum(np.einsum("mqi,ij,mqj->mq", difference, D, difference) * det * weights))


@pytest.mark.parametrize("degree, field, strain", [(1, quadratic, quadratic_strain), (2, cubic, cubic_strain)])
def test_the_estimate_of_a_smooth_field_matches_its_true_error(degree, field, strain):
    """For the interpolant of a smooth field on an unstructured mesh, η / true error is close to 1."""
    half = structured_mesh(16, 8, shear=0.4, degree=degree).lower
    u = field(half.points)
    eta = np.sqrt(estimate.block_indicators(half.points, half.cells, D, u)[0].sum())
    true = np.sqrt(_true_interpolation_error(half, u, strain))
    print(f"effectivity {eta / true:.3f}")
    assert 0.8 < eta / true < 1.25


def test_the_contact_term_measures_complementarity_between_nodes():
    mesh = structured_mesh(8, 4, degree=1, geometry=CRACKED)
    sigma = mesh.sigma
    k = len(sigma.multiplier_nodes)
    crack = sigma.crack[sigma.multiplier_nodes]
    u_minus, u_plus = np.zeros((len(mesh.lower.points), 2)), np.zeros((len(mesh.upper.points), 2))
    mu_c = np.zeros(k)
    x = sigma.points[sigma.multiplier_nodes, 0]
    # Pressure on the crack nodes with x < 0, opening on those with x > 0: complementary at every node.
    mu_c[crack & (x < -0.1)] = 2.0
    opening = np.zeros(len(sigma.points))
    opening[sigma.multiplier_nodes[crack & (x > 0.1)]] = 1e-3
    u_plus[mesh.upper.sigma, 1] = opening
    lower, upper = estimate.contact_indicators(mesh, u_minus, u_plus, mu_c)
    assert lower.sum() == upper.sum() == 0.0  # the pressure and the opening never share an edge
    opening[sigma.multiplier_nodes[crack & (np.abs(x + 0.25) < 1e-9)]] = 1e-3  # now they do, on two edges
    u_plus[mesh.upper.sigma, 1] = opening
    lower, upper = estimate.contact_indicators(mesh, u_minus, u_plus, mu_c)
    # Crack nodes at x = -0.25, 0, 0.25 (the tips carry no μᶜ): μ = 2 and g = 1e-3 at x = -0.25 only, so
    # on the two edges at it ∫ μ_h g_h ds = (1/4)(2 · 1e-3)/3 each; each half gets ½ of 2|∫|.
    assert lower.sum() == pytest.approx(2 * 0.25 * 2.0 * 1e-3 / 3) and upper.sum() == pytest.approx(lower.sum())
    assert np.count_nonzero(lower) == 2


@pytest.mark.parametrize("degree", [1, 2])
def test_interpolation_reproduces_fields_of_the_element_on_curved_cells(degree):
    """P2 on the arc geometry's curved cells: the isoparametric field is evaluated exactly."""
    mesh = geometry.build(scene.load("arc-bond", ["mesh.size=0.25", f"mesh.degree={degree}"]))
    half = mesh.upper
    rng = np.random.default_rng(1)
    values = rng.normal(size=(len(half.points), 2))
    # A point in every cell (its reference centroid) and the exact value there.
    xi = np.full((len(half.cells), 2), 1.0 / 3.0)
    shapes = estimate.shape_functions(half.cells.shape[1], xi)[0]
    points = np.einsum("qk,qkd->qd", shapes, half.points[half.cells])
    expected = np.einsum("qk,qkc->qc", shapes, values[half.cells])
    assert np.allclose(analysis.interpolate(half, values, points), expected, atol=1e-9)


@pytest.mark.solve
def test_reference_results_carry_the_estimate():
    result = reference.solve_monolithic(scene.load("partial-closure", ["mesh.sigma_vertices=13", "mesh.boundary_vertices=32"]),
                             geometry.build(scene.load("partial-closure", ["mesh.sigma_vertices=13",
                                                                           "mesh.boundary_vertices=32"])))
    assert 0.05 < result.attrs["error_estimate"] < 1.0
    for name, values in result.indicators.items():
        assert values.shape == (len(result.half(name).cells),) and np.all(values >= 0)


@pytest.mark.solve
@pytest.mark.parametrize("degree", [1, 2])
def test_compare_on_different_meshes_interpolates_the_coarse_solution(degree):
    """A coarse solution against a finer one: the distance is what the estimates say is between them."""
    def solve(P, M):
        sc = scene.load("linear", [f"mesh.sigma_vertices={P}", f"mesh.boundary_vertices={M}", f"mesh.degree={degree}"])
        return reference.solve_monolithic(sc, geometry.build(sc))

    coarse, fine = solve(13, 32), solve(48, 80)
    assert analysis.compare(fine, fine).energy_error == 0.0
    distance = analysis.compare(coarse, fine).energy_error
    expected = np.sqrt(coarse.attrs["error_estimate"] ** 2 - fine.attrs["error_estimate"] ** 2)
    assert 0.7 < distance / expected < 1.4


def test_locate_agrees_with_a_trapezoid_map_on_a_graded_mesh_with_a_hole():
    """Point location by the nearest cells: same inside/outside verdicts as matplotlib's exact trapezoid
    map, each found cell holds its point, on a strongly graded mesh with a hole and points off the mesh."""
    from types import SimpleNamespace

    from matplotlib.tri import Triangulation

    t = np.linspace(0.0, 1.0, 41) ** 3  # spacing from 1.6e-5 to 0.07
    x, y = np.meshgrid(t, t)
    index = np.arange(41 * 41).reshape(41, 41)
    a, b, c, d = index[:-1, :-1].ravel(), index[:-1, 1:].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel()
    corners = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    points = np.column_stack([x.ravel(), y.ravel()])
    centre = points[corners].mean(axis=1)
    corners = corners[np.hypot(*(centre - 0.6).T) > 0.2]  # the hole
    rng = np.random.default_rng(3)
    queries = np.concatenate([rng.uniform(-0.1, 1.1, (3000, 2)), rng.uniform(0.0, 0.01, (2000, 2)), points])
    half = SimpleNamespace(points=points, corners=corners)
    cell, outside = analysis.locate(half, queries)
    exact = Triangulation(points[:, 0], points[:, 1], corners).get_trifinder()(queries[:, 0], queries[:, 1])
    found = exact >= 0
    assert np.all(outside[found] == False) and np.count_nonzero(~found) > 500  # noqa: E712
    triangles = points[corners[cell[found]]]
    first, second, offset = (triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0],
                             queries[found] - triangles[:, 0])
    det = first[:, 0] * second[:, 1] - first[:, 1] * second[:, 0]
    s = (offset[:, 0] * second[:, 1] - offset[:, 1] * second[:, 0]) / det
    r = (first[:, 0] * offset[:, 1] - first[:, 1] * offset[:, 0]) / det
    assert min(s.min(), r.min(), (1.0 - s - r).min()) > -1e-9
    far = ~found & ((queries < -0.01) | (queries > 1.01)).any(axis=1)
    assert np.all(outside[far])


@pytest.mark.parametrize("degree", [1, 2])
def test_pieces_give_the_indicators_of_the_whole_half(degree):
    """The cells owned by the ranks of a distributed block (contiguous ranges: the cells whose smallest node
    they own), each with two rings of neighbours (:func:`ddsolve.mesh.pieces.cut`), have the indicators of
    the whole half; every cell is owned once."""
    source = scene.load("partial-closure", ["mesh.sigma_vertices=49", "mesh.boundary_vertices=64",
                                            f"mesh.degree={degree}"])
    half = geometry.build(source).lower
    x, y = half.points.T
    u = np.column_stack([np.sin(3 * x) * y ** 2 + 0.1 * x * y, np.cos(2 * y) * x + 0.01 * np.exp(x)])
    whole = estimate.half_indicators(half, D, u)
    for ranks in (2, 3):
        bounds = np.linspace(0, len(half.points), ranks + 1).astype(int)
        owners = np.zeros(len(half.cells), dtype=int)
        found = np.empty_like(whole)
        for first, stop in zip(bounds[:-1], bounds[1:]):
            piece = pieces.cut(half, first, stop)
            assert len(piece.cells) < len(half.cells)
            mine = np.arange(piece.cell_first, piece.cell_stop)
            smallest = half.cells[mine].min(axis=1)  # ... those whose smallest node is owned (make_half's order)
            assert np.all((smallest >= first) & (smallest < stop))
            owners[mine] += 1
            found[:, mine] = estimate.block_indicators(piece.points, piece.cells, D, u[piece.nodes],
                                                       piece.outer_edges)[:, :piece.owned]
        assert np.all(owners == 1)
        np.testing.assert_allclose(found, whole, rtol=0, atol=1e-12 * whole.max())


#: The paper's square with layer 1's sides moved by one rigid motion (a translation and a small rotation).
RIGID = """title = "a rigid motion prescribed"
[geometry]
crack = [-0.5, 0.5]
clamped = []
[mesh]
sigma_vertices = 25
boundary_vertices = 48
""" + MATERIALS + "".join(f'[displacements.layer1.{side}]\nx = "0.001 - 0.0002*y"\ny = "0.003 + 0.0002*x"\n'
                          for side in ("left", "right"))


@pytest.mark.solve
def test_a_rigid_motion_has_nothing_to_estimate():
    """Supports that move the structure rigidly: the solution is exact, its strains rounding, and so is η:
    the relative estimate is 0, not the ratio of two roundings (47 %), and an adaptive run stops at once."""
    from mpi4py import MPI

    from ddsolve.solvers import adapt

    source = scene.loads(RIGID)
    result = reference.solve_monolithic(source, geometry.build(source))
    assert abs(result.attrs["energy"]) < 1e-15 and result.attrs["error_estimate"] == 0.0
    adaptive = adapt.solve_adaptively(source.with_({"mesh.target_error": 0.01}), MPI.COMM_SELF, None, progress=lambda line: None)
    assert len(adaptive.levels["unknowns"]) == 1 and adaptive.attrs["error_estimate"] == 0.0
