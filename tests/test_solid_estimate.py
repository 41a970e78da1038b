"""The 3-D error estimate (ddsolve.post.solid_estimate): zero for a field the elements hold exactly, the rate of the
error and an effectivity near one for smooth fields on uniform tetrahedra."""
from types import SimpleNamespace

import numpy as np
import pytest

from ddsolve.fem import tetra
from ddsolve.mesh.solid import assemble, elevated
from ddsolve.post import solid_estimate

#: The six tetrahedra of a cube (Kuhn's), by the cube's corners numbered x + 2 y + 4 z.
KUHN = np.array([[0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]])
D = tetra.isotropic(type("Steel", (), {"E": 2.0, "nu": 0.3})())


def cube(cells_per_side: int, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit cube in cells_per_side³ cubes of six tetrahedra each, P1 or P2."""
    k = cells_per_side
    axis = np.linspace(0.0, 1.0, k + 1)
    points = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    index = np.arange((k + 1) ** 3).reshape(k + 1, k + 1, k + 1)
    corners = np.stack([index[i:k + i, j:k + j, l:k + l].ravel() for l in (0, 1) for j in (0, 1) for i in (0, 1)],
                       axis=1)
    tetrahedra = corners[:, KUHN].reshape(-1, 4)
    volumes = np.einsum("ij,ij->i", np.cross(points[tetrahedra[:, 1]] - points[tetrahedra[:, 0]],
                                             points[tetrahedra[:, 2]] - points[tetrahedra[:, 0]]),
                        points[tetrahedra[:, 3]] - points[tetrahedra[:, 0]])
    tetrahedra[volumes < 0] = tetrahedra[volumes < 0][:, [1, 0, 2, 3]]
    if degree == 2:
        points, tetrahedra, _ = elevated(points, tetrahedra)
    return points, tetrahedra


def smooth(at: np.ndarray) -> np.ndarray:
    x, y, z = at.T
    return np.column_stack([np.sin(2 * x) * np.cos(y) + z * z, np.exp(0.5 * y) * np.sin(z + x), np.cos(x * y * z)])


def smooth_strain(at: np.ndarray) -> np.ndarray:
    """The Voigt strain of :func:`smooth`, by central differences (accurate to 1e-10)."""
    step = 1e-5
    G = np.stack([(smooth(at + step * e) - smooth(at - step * e)) / (2 * step) for e in np.eye(3)], axis=-1)
    return np.stack([G[:, 0, 0], G[:, 1, 1], G[:, 2, 2], G[:, 1, 2] + G[:, 2, 1], G[:, 0, 2] + G[:, 2, 0],
                     G[:, 0, 1] + G[:, 1, 0]], axis=-1)


def true_error(points: np.ndarray, cells: np.ndarray, u: np.ndarray) -> float:
    """∫ (ε(u) − ε_h)ᵀ D (ε(u) − ε_h) over the mesh."""
    xi, w = solid_estimate.collapsed_rule(5)
    at = np.einsum("qk,mkd->mqd", tetra.tetra_shapes(4, xi)[0], points[cells[:, :4]])
    difference = smooth_strain(at.reshape(-1, 3)).reshape(len(cells), len(w), 6) \
        - solid_estimate.strains(points, cells, u, xi)
    dets = tetra.gradients(points, cells, xi[:1])[1]
    return float(np.einsum("cqi,ij,cqj,q,c->", difference, D, difference, w, np.abs(dets)))


@pytest.mark.unit
@pytest.mark.parametrize("degree", [1, 2])
def test_a_field_the_elements_hold_has_no_error(degree):
    points, cells = cube(3, degree)
    rng = np.random.default_rng(1)
    gradient, shift = rng.normal(size=(3, 3)), rng.normal(size=3)
    u = points @ gradient.T + shift
    if degree == 2:  # a quadratic field: its linear strain is recovered exactly too
        u = u + 0.3 * points[:, [1, 2, 0]] ** 2
    eta2, energy = solid_estimate.half_indicators(points, cells, D, u)
    assert eta2.sum() <= 1e-20 * energy.sum()


@pytest.mark.unit
@pytest.mark.parametrize("degree, sizes", [(1, (4, 8)), (2, (3, 6))])
def test_rate_and_effectivity_on_a_smooth_field(degree, sizes):
    """The interpolant of a smooth field: the estimate falls as h^p with the true error, their ratio near 1."""
    estimates, errors = [], []
    for k in sizes:
        points, cells = cube(k, degree)
        u = smooth(points)
        eta2, _ = solid_estimate.half_indicators(points, cells, D, u)
        estimates.append(np.sqrt(eta2.sum()))
        errors.append(np.sqrt(true_error(points, cells, u)))
    rate = np.log2(estimates[0] / estimates[1])
    true_rate = np.log2(errors[0] / errors[1])
    assert abs(true_rate - degree) < 0.25
    assert abs(rate - degree) < 0.3
    assert 0.7 < estimates[1] / errors[1] < 1.3, estimates[1] / errors[1]


@pytest.mark.unit
def test_the_contact_term_goes_to_the_tetrahedra_on_each_side_of_the_crack():
    """μᶜ = [u]·ν = 1 over a crack covering Σ (area 1): |∫ μ [u]·ν| = 1 in each half, on tetrahedra with a face on Σ."""
    points, cells = cube(2, 1)
    upper = points[cells].mean(axis=1)[:, 1] > 0.5
    mesh = assemble(points, cells, upper, (0.0, 1.0, 0.0, 1.0, 0.0, 1.0), 0.5, ((0.0, 1.0, 0.0, 1.0),))
    ones = np.ones(len(mesh.sigma.points))
    terms = solid_estimate.contact_indicators(SimpleNamespace(mesh=mesh, pressure=ones, normal_opening=ones))
    for term, half in zip(terms, mesh.halves):
        assert term.sum() == pytest.approx(1.0)
        on_sigma = np.isin(half.tetrahedra, half.sigma_nodes).sum(axis=1) == 3
        assert np.all(on_sigma[term > 0]) and np.count_nonzero(term) == len(mesh.sigma.triangles)
    nothing = SimpleNamespace(mesh=mesh, pressure=0 * ones, normal_opening=ones)
    assert all(not term.any() for term in solid_estimate.contact_indicators(nothing))
