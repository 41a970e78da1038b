"""Reactions: the force each support or displaced boundary exerts on each layer, r = K u − f summed.

At a prescribed dof the residual K u − f of a block's equations is the force its support applies (no
multiplier acts there: :mod:`ddsolve.fem.supports`).  It is computed element by element on the cells
touching the prescribed nodes, in x and y, projected on the prescribed directions (a roller carries no
force along itself), and summed per boundary and layer.  At a Σ node that the gluing ties to a prescribed
one, the tied blocks' residuals belong to the layers whose own conditions prescribe it.  A node on two
supported boundaries counts in both.  No PETSc or MPI here.
"""
from __future__ import annotations

import numpy as np

from ddsolve.fem import assembly, supports
from ddsolve.mesh.mesh import BLOCKS, CLAMPED, Mesh
from ddsolve.problem.scene import LAYERS, Scene


def residual(scene: Scene, mesh: Mesh, block: int, u: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """``(n, 2)``: K u − f of block ``block`` in x and y, exact at ``nodes`` (elsewhere partial)."""
    spec = BLOCKS[block]
    half = mesh.half(spec.side)
    near = np.zeros(len(half.points), dtype=bool)
    near[nodes] = True
    cells = half.cells[near[half.cells].any(axis=1)]
    D, _ = assembly.elasticity(scene, spec.layer)
    forces = np.einsum("mij,mj->mi", assembly.element_stiffness(half.points, cells, D),
                       u.reshape(-1)[assembly.element_dofs(cells)])
    out = np.bincount(assembly.element_dofs(cells).ravel(), forces.ravel(), minlength=2 * len(half.points))
    for load in assembly.layer_loads(scene, spec.layer, half):
        out -= assembly.boundary_load(half.points, half.edges(load.boundary), load)
    thermal = assembly.thermal_of(scene, spec.layer)
    if thermal is not None:
        out -= assembly.thermal_load(half.points, cells, D, *thermal)
    return out.reshape(-1, 2)


def supported_boundaries(scene: Scene, mesh: Mesh, layer: str) -> list[str]:
    """The layer's supported boundaries: the clamped sides of a box (or ``clamped``), then its displaced ones."""
    names = mesh.boundary_names()
    clamped = [side for side in scene.geometry.clamped if side in names] if scene.mesh.kind == "box" else \
        ([CLAMPED] if any(len(half.edges(CLAMPED)) for half in mesh.halves) else [])
    return clamped + [name for (owner, name) in scene.displacements if owner == layer]


def reactions(scene: Scene, mesh: Mesh, solution: dict[str, np.ndarray],
              table: supports.SigmaSupports | None = None) -> dict[str, dict[str, np.ndarray]]:
    """layer -> boundary name -> the reaction ``(2,)`` (x, y) on that layer; ``solution``: block name ->
    ``(n, 2)`` nodal displacements in x, y (as in a result)."""
    table = table if table is not None else supports.sigma_supports(scene, mesh)
    sigma = mesh.sigma
    at = sigma.multiplier_nodes
    forces, owned = [], []
    for b, spec in enumerate(BLOCKS):
        half = mesh.half(spec.side)
        fixed, _ = supports.block_supports(scene, half, sigma, spec.layer, b, table)
        own, _ = supports.own_supports(scene, half, sigma, spec.layer)
        frames = supports.node_frames(half, sigma)
        held = np.flatnonzero(fixed.any(axis=1))
        # a block with no prescribed dof (held only through Σ) has no reaction
        r = residual(scene, mesh, b, solution[spec.name], held) if len(held) else np.zeros(fixed.shape)
        local = np.einsum("nab,nb->na", frames, r) * fixed  # on the prescribed directions only
        forces.append(local)
        owned.append(own & fixed)
    # Σ entries tied to a prescribed one: their force goes to a tied block prescribing it on its own.
    crack = np.repeat(sigma.crack[at], 2)
    entries = [f[half_sigma] for f, half_sigma in
               zip(forces, [mesh.half(spec.side).sigma[at] for spec in BLOCKS])]
    own_entries = [o[mesh.half(spec.side).sigma[at]] for o, spec in zip(owned, BLOCKS)]
    for group in ([0, 1, 2, 3], [0, 2], [1, 3]):
        where = (~crack if len(group) == 4 else crack).reshape(-1, 2)
        own = np.array([own_entries[b] for b in group]) & where
        count = own.sum(axis=0)
        total = np.where(where, sum(entries[b] for b in group), 0.0)
        for position, b in enumerate(group):
            moved = np.where(count > 0, np.where(own[position], total / np.maximum(count, 1), 0.0), entries[b])
            entries[b] = np.where(where, moved, entries[b])
    out: dict[str, dict[str, np.ndarray]] = {layer: {} for layer in LAYERS}
    for b, spec in enumerate(BLOCKS):
        half = mesh.half(spec.side)
        frames = supports.node_frames(half, sigma)
        forces[b][half.sigma[at]] = entries[b]
        vectors = np.einsum("nab,na->nb", frames, forces[b])  # back to x, y
        for name in supported_boundaries(scene, mesh, spec.layer):
            nodes = half.nodes(name)
            out[spec.layer][name] = out[spec.layer].get(name, np.zeros(2)) + vectors[nodes].sum(axis=0)
    return out


def of_result(result, table: supports.SigmaSupports | None = None) -> dict[str, dict[str, np.ndarray]]:
    """:func:`reactions` of a result."""
    return reactions(result.parsed_scene, result.mesh, result.solution, table)


def lines(values: dict[str, dict[str, np.ndarray]]) -> list[str]:
    """One line per supported boundary and layer, as printed after a solve."""
    return [f"reaction on {layer} at {name}: ({force[0]:.6e}, {force[1]:.6e})"
            for layer, named in values.items() for name, force in named.items()]
