"""Reactions: the force each support or displaced boundary exerts on each layer, r = K u − f summed.

At a prescribed dof the residual K u − f of a block's equations is the force its support applies (no
multiplier acts there: :mod:`ddsolve.fem.supports`).  It is computed element by element on the cells
touching the prescribed nodes, in x and y, projected on the prescribed directions (a roller carries no
force along itself), and summed per boundary and layer.  At a Σ node that the gluing ties to a prescribed
one, the tied blocks' residuals belong to the layers whose own conditions prescribe it.  Each boundary sums
its nodes' forces on the directions it prescribes there (none at a node of Γ_D for a displaced one): a
direction that two boundaries prescribe at a shared node counts in both.  No PETSc or MPI here.
"""
from __future__ import annotations

import numpy as np

from ddsolve.fem import assembly, supports
from ddsolve.mesh.mesh import CLAMPED, BlockSpec, HalfMesh, Mesh, SigmaLine, blocks
from ddsolve.problem.scene import Scene


def residual(scene: Scene, half: HalfMesh, layer: str, u: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """``(n, 2)``: K u − f of ``layer``'s block on ``half`` (its region) in x and y, exact at ``nodes`` (elsewhere
    partial)."""
    near = np.zeros(len(half.points), dtype=bool)
    near[nodes] = True
    cells = half.cells[near[half.cells].any(axis=1)]
    D, _ = assembly.elasticity(scene, layer, half.name)
    forces = np.einsum("mij,mj->mi", assembly.element_stiffness(half.points, cells, D),
                       u.reshape(-1)[assembly.element_dofs(cells)])
    out = np.bincount(assembly.element_dofs(cells).ravel(), forces.ravel(),
                      minlength=2 * len(half.points)).astype(np.float64, copy=False)  # none near: no weights, ints
    for load in assembly.layer_loads(scene, layer, half):
        out -= assembly.load_vector(half, load)
    thermal = assembly.thermal_of(scene, layer, half.name)
    if thermal is not None:
        out -= thermal.vector(half.points, cells, D)
    return out.reshape(-1, 2)


def supported_boundaries(scene: Scene, names: set[str], layer: str) -> list[str]:
    """The layer's supported boundaries among ``names``: the clamped sides of a box (or ``clamped``), then its
    displaced ones."""
    clamped = [side for side in scene.geometry.clamped if side in names] if scene.mesh.kind == "box" else \
        ([CLAMPED] if CLAMPED in names else [])
    return clamped + [name for (owner, name) in scene.displacements if owner == layer and name in names]


def block_forces(scene: Scene, half: HalfMesh, sigma: SigmaLine, block: int, u: np.ndarray,
                 table: supports.SigmaSupports) -> tuple[np.ndarray, np.ndarray]:
    """Block ``block``'s support forces ``(n, 2)`` in its dof frames, on the prescribed directions only
    (a roller carries no force along itself), and which of them its own conditions prescribe."""
    layer = blocks(scene.geometry.layers)[block].layer
    fixed, _ = supports.block_supports(scene, half, sigma, layer, block, table)
    own, _ = supports.own_supports(scene, half, sigma, layer)
    held = np.flatnonzero(fixed.any(axis=1))
    # a block with no prescribed dof (held only through Σ) has no reaction
    r = residual(scene, half, layer, u, held) if len(held) else np.zeros(fixed.shape)
    return np.einsum("nab,nb->na", supports.node_frames(half, sigma), r) * fixed, own & fixed


def tie(sigma: SigmaLine, entries: list[np.ndarray], own: list[np.ndarray], specs: tuple[BlockSpec, ...]
        ) -> list[np.ndarray]:
    """The blocks' (``specs``) forces at the Σ multiplier nodes ``(k, 2)`` after those at entries the gluing ties
    to a prescribed one go to the tied blocks prescribing them on their own (equal shares)."""
    entries = list(entries)
    crack = np.repeat(sigma.crack[sigma.multiplier_nodes], 2).reshape(-1, 2)
    for group, on_crack in supports.tie_groups(specs):
        where = crack if on_crack else ~crack
        owning = np.array([own[b] for b in group]) & where
        count = owning.sum(axis=0)
        total = np.where(where, sum(entries[b] for b in group), 0.0)
        for position, b in enumerate(group):
            moved = np.where(count > 0, np.where(owning[position], total / np.maximum(count, 1), 0.0), entries[b])
            entries[b] = np.where(where, moved, entries[b])
    return entries


def boundary_sums(scene: Scene, half: HalfMesh, sigma: SigmaLine, layer: str, forces: np.ndarray
                  ) -> dict[str, np.ndarray]:
    """Boundary (or point support) name -> the sum ``(2,)`` in x, y of a block's support forces (in its dof
    frames) on it, each projected on the directions that boundary prescribes at its node (a clamped side:
    both)."""
    vectors = np.einsum("nab,na->nb", supports.node_frames(half, sigma), forces)
    displaced = supports.projectors(scene, half, layer)
    return {name: displaced[name][1] @ vectors[displaced[name][0]].sum(axis=0) if name in displaced
            else vectors[half.nodes(name)].sum(axis=0)
            for name in supported_boundaries(scene, set(half.boundaries) | set(displaced), layer)}


def ordered(scene: Scene, parts: list[tuple[str, dict[str, np.ndarray]]]) -> dict[str, dict[str, np.ndarray]]:
    """layer -> boundary -> reaction: the blocks' ``(layer, boundary sums)`` added up, every layer's boundaries
    in the scene's order."""
    out: dict[str, dict[str, np.ndarray]] = {layer: {} for layer in scene.layers}
    for layer, sums in parts:
        for name, force in sums.items():
            out[layer][name] = out[layer].get(name, np.zeros(2)) + force
    names = set().union(*(named for named in out.values()))
    return {layer: {name: named[name] for name in supported_boundaries(scene, names, layer) if name in named}
            for layer, named in out.items()}


def reactions(scene: Scene, mesh: Mesh, solution: dict[str, np.ndarray],
              table: supports.SigmaSupports | None = None) -> dict[str, dict[str, np.ndarray]]:
    """layer -> boundary name -> the reaction ``(2,)`` (x, y) on that layer; ``solution``: block name ->
    ``(n, 2)`` nodal displacements in x, y (as in a result)."""
    table = table if table is not None else supports.sigma_supports(scene, mesh)
    sigma, specs = mesh.sigma, blocks(scene.geometry.layers)
    at = sigma.multiplier_nodes
    forces, own = zip(*(block_forces(scene, mesh.half(spec.side), sigma, b, solution[spec.name], table)
                        for b, spec in enumerate(specs)))
    positions = [mesh.half(spec.side).sigma[at] for spec in specs]
    tied = tie(sigma, [f[p] for f, p in zip(forces, positions)], [o[p] for o, p in zip(own, positions)], specs)
    parts = []
    for b, spec in enumerate(specs):
        forces[b][positions[b]] = tied[b]
        parts.append((spec.layer, boundary_sums(scene, mesh.half(spec.side), sigma, spec.layer, forces[b])))
    return ordered(scene, parts)


def of_result(result, table: supports.SigmaSupports | None = None) -> dict[str, dict[str, np.ndarray]]:
    """:func:`reactions` of a result."""
    return reactions(result.scene, result.mesh, result.solution, table)


def lines(values: dict[str, dict[str, np.ndarray]]) -> list[str]:
    """One line per supported boundary and layer, as printed after a solve."""
    return [f"reaction on {layer} at {name}: ({force[0]:.6e}, {force[1]:.6e})"
            for layer, named in values.items() for name, force in named.items()]
