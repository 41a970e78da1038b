"""Local refinement by newest-vertex bisection (ddsolve.mesh.bisection) and the projector onto a gmsh
geometry's curves (ddsolve.mesh.curves)."""
from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from conftest import structured_mesh

from ddsolve.mesh import bisection, curves
from ddsolve.mesh.element import CELL_EDGES, boundary_nodes, crowded_edges, edge_keys, outer_edges
from ddsolve.mesh.mesh import SIGMA, edge_lengths, statistics
from ddsolve.problem import scene as scenes
from ddsolve.problem.scene import Geometry

CRACKED = Geometry()  # the paper's square with the crack (−½, ½) on Σ


def _cells(mesh) -> int:
    return len(mesh.lower.cells) + len(mesh.upper.cells)


def _conforming(mesh, before) -> None:
    """Every edge in one or two cells of its half, every named boundary edge on the half's outline, and the
    outline as long as ``before``'s (a hanging node would add edges of one cell inside the half); the two
    halves' Σ nodes at the same places."""
    for half, old in zip(mesh.halves, before.halves):
        assert crowded_edges(half.corners) == 0
        outline = outer_edges(half.corners)
        named = np.concatenate([edges[:, :2] for edges in half.boundaries.values()])
        assert np.isin(edge_keys(named, len(half.points)), edge_keys(outline, len(half.points))).all()
        perimeter = edge_lengths(old.points, old.boundary_edges[:, :2]).sum()
        assert edge_lengths(half.points, outline).sum() == pytest.approx(perimeter, rel=1e-13)
    assert np.allclose(mesh.lower.points[mesh.lower.sigma], mesh.upper.points[mesh.upper.sigma], atol=1e-14)


@pytest.mark.parametrize("degree", [1, 2])
def test_marked_cells_are_bisected_conformingly_and_the_area_and_boundaries_stay(degree):
    mesh = structured_mesh(8, 4, shear=0.2, degree=degree, geometry=CRACKED)
    marked = np.zeros(_cells(mesh), dtype=bool)
    lower_cells = len(mesh.lower.cells)
    sigma_cell = np.flatnonzero(np.isin(mesh.lower.corners, mesh.lower.sigma).sum(axis=1) == 2)[0]
    marked[[sigma_cell, 3, lower_cells + 7]] = True
    tri, parent, _ = bisection.bisect(bisection.triangulation(mesh), marked)
    tri, _, _ = bisection.bisect(tri, parent == sigma_cell)  # its children: one has the Σ edge to bisect
    refined = bisection.to_mesh(tri)
    assert _cells(bisection.refine(mesh, marked)) == len(parent)
    _conforming(refined, mesh)
    assert _cells(refined) > _cells(mesh) + 3
    assert len(refined.sigma.points) > len(mesh.sigma.points)  # the Σ cell's refinement crossed to the upper half
    for old, new in zip(mesh.halves, refined.halves):
        assert new.areas().sum() == pytest.approx(old.areas().sum(), rel=1e-13)
        assert new.areas().min() > 0  # counter-clockwise
        assert new.degree == degree and set(new.boundaries) == set(old.boundaries)
        for name, edges in old.boundaries.items():
            length = edge_lengths(old.points, edges).sum()
            assert edge_lengths(new.points, new.edges(name)).sum() == pytest.approx(length)
    # the marked cells are gone: no cell of the result has all three of their corners
    def corner_sets(points):
        return {tuple(sorted(map(tuple, p.round(12).tolist()))) for p in points}

    old_corners = corner_sets(mesh.lower.points[mesh.lower.corners[[sigma_cell, 3]]])
    new_corners = corner_sets(refined.lower.points[refined.lower.corners])
    assert not old_corners & new_corners
    # crack tips stay Σ vertices, tips
    assert np.allclose(sorted(refined.sigma.points[refined.sigma.tip][:, 0]), [-0.5, 0.5])


def test_p2_midpoints_are_the_middles_of_straight_edges():
    mesh = structured_mesh(4, 2, degree=2, geometry=CRACKED)
    refined = bisection.refine(mesh, np.ones(_cells(mesh), dtype=bool))
    for half in refined.halves:
        p = half.points[half.cells]
        assert np.allclose(p[:, 3:], 0.5 * (p[:, [0, 1, 2]] + p[:, [1, 2, 0]]), atol=1e-14)


def test_the_smallest_angle_stays_bounded_under_repeated_refinement_of_a_corner():
    mesh = first_mesh = structured_mesh(4, 2, shear=0.3, geometry=CRACKED)
    first = min(statistics(half).min_angle for half in mesh.halves)
    for round_ in range(20):
        tri = bisection.triangulation(mesh, longest_edge=round_ == 0)
        corner = np.flatnonzero(np.all(np.isclose(tri.points, [-0.5, 0.0]), axis=1))
        tri, _, _ = bisection.bisect(tri, np.isin(tri.cells, corner).any(axis=1))
        mesh = bisection.to_mesh(tri)
    _conforming(mesh, first_mesh)
    smallest = np.sqrt(min(half.areas().min() for half in mesh.halves))
    assert smallest < 1e-2  # 20 bisections towards the tip
    # newest-vertex bisection: at most four similarity classes per initial triangle
    assert min(statistics(half).min_angle for half in mesh.halves) >= first / 2 - 1e-9


def test_new_boundary_vertices_are_projected_and_named():
    mesh = structured_mesh(4, 2, degree=2, geometry=CRACKED)
    centre, radius = np.array([0.0, 10.0]), np.hypot(0.5, 11.0)  # a circle through the bottom's vertices at x = ±½
    seen = []

    def onto_circle(points, names):  # a synthetic projector: the bottom onto the circle, the rest stays
        seen.extend(names.tolist())
        bottom = names == "bottom"
        moved = points.copy()
        moved[bottom] = centre + radius * (points[bottom] - centre) / np.linalg.norm(points[bottom] - centre, axis=1,
                                                                                     keepdims=True)
        return moved

    tri = bisection.triangulation(mesh)
    for _ in range(2):  # two sweeps of every cell: uniform refinement, boundary edges bisected
        tri, parent, splits = bisection.bisect(tri, np.ones(len(tri.cells), dtype=bool))
        assert np.all(splits >= 1)
    assert set(tri.names[tri.names != ""]) == {"bottom", "top", "clamped", SIGMA}
    projected = bisection.to_mesh(tri, onto_circle)
    assert {"bottom", "top", "clamped", SIGMA} <= set(seen)
    bottom = projected.lower.edges("bottom")
    new = bottom[~np.isin(bottom, np.flatnonzero(np.isin(projected.lower.points[:, 0], [-1.0, -0.5, 0.0, 0.5, 1.0])
                                                 & np.isclose(projected.lower.points[:, 1], -1.0)))]
    assert len(new) > 4
    assert np.allclose(np.linalg.norm(projected.lower.points[new] - centre, axis=1), radius)  # vertices, midpoints
    assert np.allclose(projected.upper.points[projected.upper.edges("top")][..., 1], 1.0)  # others unmoved


def test_the_projector_keeps_points_on_the_arc_of_arc_bond():
    scene = scenes.load("arc-bond")
    project = curves.projector(scene)
    assert curves.projector(scenes.load("partial-closure")) is None
    x = np.linspace(-0.9, 0.9, 7)
    points = np.column_stack([x, np.full_like(x, 0.1)])
    moved = project(points, np.array([SIGMA] * len(x)))
    assert np.allclose(np.hypot(moved[:, 0], moved[:, 1] + 2.4), 2.6, atol=1e-12)  # Σ: the circle (0, −2.4), r 2.6
    top = project(np.array([[0.3, 0.99]]), np.array(["top"]))
    assert np.allclose(top, [[0.3, 1.0]], atol=1e-15)  # a straight line: exact


SPLINE_GEO = """
Point(1) = {-1, -1, 0}; Point(2) = {1, -1, 0}; Point(3) = {1, 1, 0}; Point(4) = {-1, 1, 0};
Point(5) = {-1, 0, 0}; Point(6) = {1, 0, 0}; Point(7) = {-0.3, 0.3, 0}; Point(8) = {0.4, -0.2, 0};
Line(1) = {1, 2}; Line(2) = {2, 6}; Line(3) = {6, 3}; Line(4) = {3, 4}; Line(5) = {4, 5}; Line(6) = {5, 1};
BSpline(7) = {5, 7, 8, 6};
Curve Loop(1) = {1, 2, -7, 6}; Plane Surface(1) = {1};
Curve Loop(2) = {7, 3, 4, 5}; Plane Surface(2) = {2};
Physical Surface("lower") = {1}; Physical Surface("upper") = {2};
Physical Curve("sigma") = {7}; Physical Curve("clamped") = {2, 3, 5, 6};
"""


def test_the_projector_leaves_other_curves_to_gmsh(tmp_path):
    path = tmp_path / "spline.geo"
    path.write_text(SPLINE_GEO)
    project = curves.GeometryProjector(path)
    points = np.column_stack([np.linspace(-0.8, 0.8, 9), np.zeros(9)])
    moved = project(points, np.array([SIGMA] * 9))
    assert np.allclose(project(moved, np.array([SIGMA] * 9)), moved, atol=1e-9)  # on the curve: they stay
    assert np.all(np.linalg.norm(moved - points, axis=1) < 0.3) and not np.allclose(moved, points)
    left = project(np.array([[-1.2, 0.5]]), np.array(["clamped"]))
    assert np.allclose(left, [[-1.0, 0.5]], atol=1e-15)



def _edge_uses(corners: np.ndarray) -> Counter:
    return Counter(frozenset(edge) for edge in corners[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2).tolist())


@pytest.mark.parametrize("degree", [1, 2])
def test_outer_edges_and_boundary_nodes_are_those_one_cell_uses(degree):
    half = structured_mesh(8, 4, shear=0.2, degree=degree, geometry=CRACKED).lower
    n = len(half.points)
    edges = half.cells[:, CELL_EDGES[half.cells.shape[1]]].reshape(-1, degree + 1)
    uses = _edge_uses(half.corners)
    once = np.array([uses[frozenset(edge)] == 1 for edge in edges[:, :2].tolist()])
    assert np.array_equal(outer_edges(half.cells), edges[once])  # each in its cell's orientation and order
    expected = np.zeros(n, dtype=bool)
    expected[edges[once][:, :2].ravel()] = True
    assert np.array_equal(boundary_nodes(half.corners, n), expected)
    assert crowded_edges(half.corners) == 0
    for extra in ([0], [0, 0], [0, 5, 5]):  # cells listed again: their edges in three or more cells
        corners = np.vstack([half.corners, half.corners[extra]])
        assert crowded_edges(corners) == sum(count > 2 for count in _edge_uses(corners).values()) > 0
