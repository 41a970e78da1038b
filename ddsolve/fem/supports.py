"""Supports: which degrees of freedom a scene prescribes, with which values, in every block.

A block's dof frame is (x, y) at every node but the Σ nodes that carry multipliers, whose dofs are in
Σ's (tangent, normal) frame.  Γ_D (``geometry.clamped``, the boundary named ``clamped``) fixes both
components of both layers to zero, and wins where it meets a displaced boundary.  A boundary in
``[displacements.LAYER.NAME]`` fixes x and/or y, or the normal component (a straight boundary whose
normal is along a dof axis: x or y away from Σ, Σ's tangent or normal at a multiplier node).  Where
several boundaries meet, their conditions are combined; two that fix the same direction must agree.  A point
support (a gmsh physical point of that name, or ``point = [x, y]``) fixes x and/or y at the vertex there,
found by its coordinates (:func:`displaced_nodes`).

At a Σ multiplier node the gluing ties the dofs of the blocks: every block at a glued vertex, the
blocks of one face (u⁻ with v⁻, u⁺ with v⁺) at a crack vertex.  A dof that one block prescribes is
prescribed in every block tied to it (:func:`sigma_supports`), so that every multiplier either couples
free dofs or only prescribed ones; the latter rows are dropped (:class:`ddsolve.dd.interface.Interface`),
and the discrete problem is exactly the monolithic one with those unknowns prescribed.  A contact row
between a prescribed and a free crack-face normal is refused.  No PETSc or MPI here.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ddsolve.errors import SceneError
from ddsolve.mesh.mesh import (CLAMPED, CRACK, SIGMA, U_MINUS, U_PLUS, BlockSpec, HalfMesh, Mesh, SigmaLine, blocks,
                               point_nodes)
from ddsolve.problem.expressions import Expression
from ddsolve.problem.scene import Displacement, Scene

#: Directions closer than this (1 − |cos|) are the same; values agreeing to this (relative) are equal.
ALIGNED = 1e-9
AGREE = 1e-10


@dataclass(frozen=True)
class SigmaSupports:
    """Prescribed trace entries of the structure's blocks, ``fixed`` ``(blocks, 2k)`` and ``values`` ``(blocks, 2k)``
    (the k multiplier nodes, in their Σ frames), after the gluing's ties."""

    fixed: np.ndarray
    values: np.ndarray


def node_frames(half: HalfMesh, sigma: SigmaLine) -> np.ndarray:
    """``(n, 2, 2)``: every node's dof frame (rows: the dof directions), identity off the Σ multiplier nodes."""
    frames = np.broadcast_to(np.eye(2), (len(half.points), 2, 2)).copy()
    frames[half.sigma[sigma.multiplier_nodes]] = sigma.frames[sigma.multiplier_nodes]
    return frames


def _conditions(scene: Scene, half: HalfMesh, layer: str
                ) -> Iterator[tuple[Displacement, np.ndarray, dict[str, tuple[Expression, np.ndarray]]]]:
    """The layer's displaced boundaries on this half: the displacement, the nodes it prescribes (Γ_D wins at
    its own) and its components, component -> (expression, unit direction in x, y)."""
    clamped = np.zeros(len(half.points), dtype=bool)
    clamped[half.clamped()] = True
    for (name_layer, name), displacement in scene.displacements.items():
        where = displaced_nodes(half, displacement) if name_layer == layer else ()
        if len(where) == 0:
            continue
        edges = half.edges(name)
        parts = {"x": (displacement.x, np.array([1.0, 0.0])), "y": (displacement.y, np.array([0.0, 1.0]))}
        if displacement.normal is not None:
            parts = {"normal": (displacement.normal, _normal(half, edges, f"{displacement.key}.normal"))}
        given = {component: part for component, part in parts.items() if part[0] is not None}
        yield displacement, where[~clamped[where]], given


def displaced_nodes(half: HalfMesh, displacement: Displacement) -> np.ndarray:
    """The nodes of ``half`` a displacement prescribes: those of its boundary, or the vertex at its point
    (``point``, or the mesh's named point of its name: :attr:`~ddsolve.mesh.mesh.HalfMesh.named_points`)."""
    if displacement.point is not None:
        return point_nodes(half.points, displacement.point)
    name = displacement.boundary
    if name in half.named_points:
        return np.unique(np.concatenate([point_nodes(half.points, xy) for xy in half.named_points[name]]
                                        + [np.unique(half.edges(name))]).astype(np.int64))
    return np.unique(half.edges(name))


def _rows(scene: Scene, half: HalfMesh, layer: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """The layer's displacement conditions on this half as rows (node, direction in x, y, value, key)."""
    nodes, directions, values, keys = [], [], [], []
    for displacement, where, parts in _conditions(scene, half, layer):
        x, y = half.points[where].T
        for component, (expression, direction) in parts.items():
            value = np.broadcast_to(np.asarray(expression(x, y), dtype=np.float64), x.shape)
            if not np.all(np.isfinite(value)):
                bad = np.flatnonzero(~np.isfinite(value))[0]
                raise SceneError(f"{displacement.key}.{component}: the displacement is not finite at (x, y) = "
                                 f"({x[bad]:.6g}, {y[bad]:.6g})")
            nodes.append(where)
            directions.append(np.broadcast_to(direction, (len(where), 2)))
            values.append(value)
            keys += [f"{displacement.key}.{component}"] * len(where)
    if not nodes:
        return np.zeros(0, np.int64), np.zeros((0, 2)), np.zeros(0), []
    return np.concatenate(nodes), np.concatenate(directions), np.concatenate(values), keys


def _normal(half: HalfMesh, edges: np.ndarray, key: str) -> np.ndarray:
    """The outward unit normal of a straight boundary (edges counter-clockwise around the half)."""
    chord = half.points[edges[:, 1]] - half.points[edges[:, 0]]
    normals = np.column_stack([chord[:, 1], -chord[:, 0]]) / np.linalg.norm(chord, axis=1)[:, None]
    if np.abs(normals - normals[0]).max() > ALIGNED ** 0.5:
        raise SceneError(f"{key}: the boundary is not straight (its normal turns): give x and y")
    return normals[0]


def fold(count: int, nodes: np.ndarray, directions: np.ndarray, values: np.ndarray, keys: list[str],
         frames: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of conditions u·e = g at ``nodes`` -> ``fixed`` ``(count, 2)`` and ``values`` ``(count, 2)`` in
    the nodes' ``frames``: both components where two directions are fixed, else the one axis of the
    frame the direction lies along; a SceneError naming the key when the direction lies along no axis or
    two conditions disagree."""
    fixed, out = np.zeros((count, 2), dtype=bool), np.zeros((count, 2))
    if len(nodes) == 0:
        return fixed, out
    local = np.einsum("nab,nb->na", frames[nodes], directions)  # the direction in the node's frame
    normal = np.zeros((count, 2, 2))
    np.add.at(normal, nodes, np.einsum("na,nb->nab", local, local))
    moment = np.zeros((count, 2))
    np.add.at(moment, nodes, local * values[:, None])
    scale = max(float(np.abs(values).max()), 1e-300)
    full = np.abs(np.linalg.det(normal)) > ALIGNED
    solved = np.linalg.solve(normal[full], moment[full][..., None])[..., 0] if full.any() else np.zeros((0, 2))
    out[full], fixed[full] = solved, True
    axis = np.argmax(np.abs(local), axis=1)
    partial = ~full[nodes]
    loose = partial & (np.abs(local).max(axis=1) < 1.0 - ALIGNED)
    if loose.any():
        i = np.flatnonzero(loose)[0]
        x, y = points[nodes[i]]
        raise SceneError(f"{keys[i]}: at ({x:.6g}, {y:.6g}) the direction fixed is along neither dof axis there "
                         "(x and y, or Σ's tangent and normal at a Σ node): give both components")
    sign = np.sign(local[np.arange(len(nodes)), axis])
    fixed[nodes[partial], axis[partial]] = True
    out[nodes[partial], axis[partial]] = (sign * values)[partial]
    implied = np.einsum("na,na->n", local, out[nodes])
    bad = np.abs(implied - values) > AGREE * scale
    if bad.any():
        i = np.flatnonzero(bad)[0]
        x, y = points[nodes[i]]
        raise SceneError(f"{keys[i]}: at ({x:.6g}, {y:.6g}) it disagrees with another prescribed displacement "
                         f"there ({values[i]:.6g} against {implied[i]:.6g})")
    return fixed, out


def projectors(scene: Scene, half: HalfMesh, layer: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Displaced boundary name -> (the nodes it prescribes to ``layer``, the orthogonal projector ``(2, 2)``
    in x, y onto the directions it prescribes there, the same at each of them)."""
    return {displacement.boundary: (where, sum(np.outer(direction, direction) for _, direction in parts.values()))
            for displacement, where, parts in _conditions(scene, half, layer)}


def own_supports(scene: Scene, half: HalfMesh, sigma: SigmaLine, layer: str) -> tuple[np.ndarray, np.ndarray]:
    """The block's own prescribed dofs ``(n, 2)`` and values ``(n, 2)`` in its dof frames: Γ_D and the layer's
    displacements (before the gluing's ties)."""
    nodes, directions, values, keys = _rows(scene, half, layer)
    fixed, out = fold(len(half.points), nodes, directions, values, keys, node_frames(half, sigma), half.points)
    fixed[half.clamped()] = True
    out[half.clamped()] = 0.0
    return fixed, out


def sigma_supports(scene: Scene, mesh: Mesh) -> SigmaSupports:
    """The prescribed trace entries of the structure's blocks after the gluing's ties (needs both halves)."""
    sigma = mesh.sigma
    nodes = sigma.multiplier_nodes
    k = len(nodes)
    specs = blocks(scene.geometry.layers)
    fixed, values = np.zeros((len(specs), 2 * k), dtype=bool), np.zeros((len(specs), 2 * k))
    for b, spec in enumerate(specs):
        half = mesh.half(spec.side)
        own, prescribed = own_supports(scene, half, sigma, spec.layer)
        fixed[b], values[b] = own[half.sigma[nodes]].ravel(), prescribed[half.sigma[nodes]].ravel()
    crack = np.repeat(sigma.crack[nodes], 2)
    points = sigma.points[np.repeat(nodes, 2)]
    scale = max(float(np.abs(values).max(initial=0.0)), 1e-300)
    for group, on_crack in tie_groups(specs):
        where = crack if on_crack else ~crack
        any_fixed = fixed[group].any(axis=0) & where
        if not any_fixed.any():
            continue
        count = fixed[group].sum(axis=0)
        value = np.where(count > 0, (values[group] * fixed[group]).sum(axis=0) / np.maximum(count, 1), 0.0)
        spread = np.where(fixed[group], np.abs(values[group] - value), 0.0).max(axis=0)
        bad = any_fixed & (spread > AGREE * scale)
        if bad.any():
            x, y = points[np.flatnonzero(bad)[0]]
            raise SceneError(f"displacements: the layers' prescribed displacements differ at the glued Σ node "
                             f"({x:.6g}, {y:.6g}); glued layers move together there")
        for member in group:
            values[member, any_fixed] = value[any_fixed]
            fixed[member, any_fixed] = True
    if scene.nonpenetration:
        normal = np.flatnonzero(crack & (np.arange(2 * k) % 2 == 1))
        lone = fixed[0, normal] != fixed[1, normal]
        if lone.any():
            x, y = sigma.points[nodes[normal[lone][0] // 2]]
            raise SceneError(f"displacements: the normal displacement of one crack face is prescribed at "
                             f"({x:.6g}, {y:.6g}) and the other face's is free; with contact.nonpenetration "
                             "prescribe both faces or neither there")
    return SigmaSupports(fixed, values)


def tie_groups(specs: tuple[BlockSpec, ...]) -> list[tuple[list[int], bool]]:
    """The groups of blocks (indices in ``specs``) the gluing ties at a Σ node, each with whether it holds at crack
    nodes: all the blocks at a glued node, each face's (u⁻ with v⁻, u⁺ with v⁺) at a crack node."""
    return [(list(range(len(specs))), False)] + [([b for b, spec in enumerate(specs) if spec.side == side], True)
                                                 for side in (-1, +1)]


def block_supports(scene: Scene, half: HalfMesh, sigma: SigmaLine, layer: str, block: int,
                   table: SigmaSupports) -> tuple[np.ndarray, np.ndarray]:
    """A block's prescribed dofs and values ``(n, 2)``: its own, and at the Σ multiplier nodes the tied ones."""
    fixed, values = own_supports(scene, half, sigma, layer)
    at = half.sigma[sigma.multiplier_nodes]
    fixed[at] = table.fixed[block].reshape(-1, 2)
    values[at] = table.values[block].reshape(-1, 2)
    return fixed, values


def check(scene: Scene, mesh: Mesh) -> SigmaSupports:
    """Every displacement names a boundary or a named point of the mesh, or gives a point that is a vertex on
    the boundary of a half (outer or Σ); returns the Σ table (:func:`sigma_supports`).  Whether the supports
    hold the structure is :func:`ddsolve.dd.kernels.of_scene`'s question."""
    names = mesh.boundary_names()
    spots = mesh.named_points
    for (_, name), displacement in scene.displacements.items():
        if displacement.point is not None:
            if name in names or name in spots or name in (SIGMA, CRACK):
                raise SceneError(f"{displacement.key}: {name!r} names a boundary or a point of {mesh.origin}; give the "
                                 "point support a name of its own")
            _check_point(mesh, [displacement.point], f"{displacement.key}.point")
        elif name in spots:
            if displacement.normal is not None:
                raise SceneError(f"{displacement.key}.normal: {name!r} is a point, which has no normal; give x and/or y")
            _check_point(mesh, spots[name], f"{displacement.key}: the point {name!r} of {mesh.origin}")
        elif name not in names or name in (CLAMPED, SIGMA, CRACK):
            listed = ", ".join(n for n in names if n != CLAMPED)
            points = f"; points: {', '.join(sorted(spots))}" if spots else ""
            raise SceneError(f"{displacement.key}: no boundary named {name!r} in {mesh.origin} "
                             f"(boundaries: {listed}{points})")
    table = sigma_supports(scene, mesh)
    check_prescribed_contact(scene, mesh, table)
    return table


def check_prescribed_contact(scene: Scene, mesh: Mesh, table: SigmaSupports) -> None:
    """Under non-penetration, refuse prescribed displacements that push the crack faces through each other: at a
    crack node where both faces' normal components are prescribed no contact row remains, so the data alone
    decide, (u⁻ − u⁺)·ν > 0 (beyond round-off of the values) is an overlap no solve can undo."""
    sigma = mesh.sigma
    nodes = sigma.multiplier_nodes
    normal = 2 * np.flatnonzero(sigma.crack[nodes]) + 1
    if not scene.nonpenetration or not len(normal):
        return
    lower, upper = U_MINUS, U_PLUS  # the faces that touch are layer 1's (the contact rows)
    both = table.fixed[lower, normal] & table.fixed[upper, normal]
    overlap = np.where(both, table.values[lower, normal] - table.values[upper, normal], 0.0)
    scale = max(float(np.abs(table.values).max(initial=0.0)), 1e-300)
    if overlap.max(initial=0.0) <= AGREE * scale:
        return
    worst = int(np.argmax(overlap))
    node = nodes[normal[worst] // 2]
    keys = [displacement.key for half in mesh.halves for layer in scene.layers
            for displacement, where, _ in _conditions(scene, half, layer) if half.sigma[node] in where]
    x, y = sigma.points[node]
    raise SceneError(f"{', '.join(dict.fromkeys(keys)) or 'displacements'}: the prescribed displacements push "
                     f"the crack faces through each other at ({x:.6g}, {y:.6g}): the lower face moves "
                     f"{table.values[lower, normal[worst]]:.6g} along Σ's normal, the upper face "
                     f"{table.values[upper, normal[worst]]:.6g} (an overlap of {overlap[worst]:.3g}), which "
                     "contact.nonpenetration forbids: change the prescribed values")


def _check_point(mesh: Mesh, points, what: str) -> None:
    """Each of ``points`` is a vertex of a half of the layer, on that half's boundary (outer or Σ)."""
    for xy in points:
        found = False
        for half in mesh.halves:
            nodes = point_nodes(half.points, xy)
            if len(nodes) and not np.isin(nodes, np.concatenate([half.boundary_edges.ravel(), half.sigma])).all():
                raise SceneError(f"{what} at ({xy[0]:.6g}, {xy[1]:.6g}) is inside the {half.name} half, off its "
                                 "boundary: a point support must lie on the boundary or on Σ")
            found = found or len(nodes) > 0
        if not found:
            raise SceneError(f"{what} at ({xy[0]:.6g}, {xy[1]:.6g}) is not a vertex of the mesh (off the layer, or "
                             "a mesh file without a vertex there): put it on a vertex of the boundary or of Σ")
