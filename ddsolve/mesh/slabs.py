"""The halves of a 3-D box cut into slabs parallel to Σ: the blocks of its domain decomposition (``solver.pieces``).

A half's tetrahedra are banded by the distance of their centroids from Σ, bands of equal counts, the tetrahedra
touching Σ in the first: slab 0 holds Σ and slab j + 1 lies beyond slab j.  Neighbouring slabs share the vertices
of the cut between them (the *cut*), glued in the decomposition as Σ's faces are off the crack; a vertex of more
than two slabs, a slab in pieces or an empty one means that many slabs do not fit (:func:`slabs` says None).  A cut's
vertices carry the lumped area of the cut's triangles (a third of each, as Σ's weights), at least half the cut's
median weight where a vertex touches the other slab only along an edge.  A factorization's work in 3-D grows like
n² with the top separator, so a slab's factorization is much cheaper than its half's (the work falls faster than
the count grows: docs/methods.md).  No PETSc or MPI here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from ddsolve.mesh.solid import SolidHalf

#: The vertices of each face of a tetrahedron (its first four nodes), face i opposite vertex i.
TETRA_FACES = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


@dataclass(frozen=True, eq=False)
class Slab:
    """One slab of a half: ``piece``, a half of its own (the half's name and material; its nodes, tetrahedra and
    side triangles, its Σ nodes if it touches Σ, else none) and ``nodes``, the half's node of each of its nodes."""

    piece: SolidHalf
    nodes: np.ndarray


@dataclass(frozen=True, eq=False)
class Cut:
    """The vertices two slabs of a half share: ``points`` (c, 3), ``weights`` (c,) and each slab's node of every
    vertex (``nodes``: the slab nearer Σ first)."""

    points: np.ndarray
    weights: np.ndarray
    nodes: tuple[np.ndarray, np.ndarray]


def slabs(half: SolidHalf, sigma: float, count: int) -> tuple[list[Slab], list[Cut]] | None:
    """``half`` cut into ``count`` slabs and the cuts between neighbours (cut j between slabs j and j + 1); None
    where that many do not fit."""
    if count == 1:
        return [Slab(half, np.arange(len(half.points)))], []
    band = _bands(half, sigma, count)
    return None if band is None else _cut(half, band, count)


def _bands(half: SolidHalf, sigma: float, count: int) -> np.ndarray | None:
    """Each tetrahedron's slab, or None where ``count`` slabs do not fit (a vertex in more than two slabs or in
    two that are not neighbours, an empty slab, a slab in pieces)."""
    tetrahedra = half.tetrahedra[:, :4]
    distance = np.abs(half.points[tetrahedra].mean(axis=1)[:, 1] - sigma)
    at_sigma = np.isin(tetrahedra, half.sigma_nodes).any(axis=1)
    ranks = np.empty(len(distance), dtype=np.int64)
    ranks[np.argsort(distance, kind="stable")] = np.arange(len(distance))
    band = np.minimum(ranks * count // len(distance), count - 1)
    band[at_sigma] = 0
    counts = np.bincount(band, minlength=count)
    if np.any(counts == 0):
        return None
    nodes = len(half.points)
    member = np.zeros((count, nodes), dtype=bool)
    for slab in range(count):
        member[slab, half.tetrahedra[band == slab]] = True
    low, high = np.argmax(member, axis=0), count - 1 - np.argmax(member[::-1], axis=0)
    if np.any(high - low > 1):
        return None
    for slab in range(count):
        if not _connected(half.tetrahedra[band == slab][:, :4], nodes):
            return None
    return band


def _connected(tetrahedra: np.ndarray, nodes: int) -> bool:
    """Whether ``tetrahedra`` form one piece (joined through shared vertices): one component of the graph of
    tetrahedra and their vertices, the vertices of none aside."""
    rows = np.repeat(np.arange(len(tetrahedra)), 4)
    graph = scipy.sparse.csr_matrix((np.ones(rows.size), (rows, len(tetrahedra) + tetrahedra.ravel())),
                                    shape=(len(tetrahedra) + nodes,) * 2)
    _, label = scipy.sparse.csgraph.connected_components(graph, directed=False)
    return len(np.unique(label[:len(tetrahedra)])) == 1


def _cut(half: SolidHalf, band: np.ndarray, count: int) -> tuple[list[Slab], list[Cut]]:
    """The slabs of the tetrahedra's ``band`` and the cuts between neighbours."""
    faces, owner = _faces(half.tetrahedra[:, :4], len(half.points))
    side_bands = {name: band[_owners(triangles, faces, owner, len(half.points))]
                  for name, triangles in half.faces.items()}
    local = []
    made = []
    for slab in range(count):
        mine = band == slab
        nodes, renumbered = np.unique(half.tetrahedra[mine], return_inverse=True)
        number = np.full(len(half.points), -1, dtype=np.int64)
        number[nodes] = np.arange(len(nodes))
        sides = {name: number[triangles[side_bands[name] == slab]] for name, triangles in half.faces.items()}
        sigma_nodes = number[half.sigma_nodes] if slab == 0 else np.zeros(0, dtype=np.int64)
        made.append(Slab(SolidHalf(half.name, half.points[nodes], renumbered.reshape(-1, half.tetrahedra.shape[1]),
                                   sides, sigma_nodes), nodes))
        local.append(number)
    return made, [_cut_between(half, faces, owner, band, slab, local) for slab in range(count - 1)]


def _cut_between(half: SolidHalf, faces: np.ndarray, owner: np.ndarray, band: np.ndarray, slab: int,
                 local: list[np.ndarray]) -> Cut:
    """The cut between slabs ``slab`` and ``slab + 1``: their shared vertices (in x, then z order), weighted by the
    lumped area of the faces between them."""
    near, far = local[slab], local[slab + 1]
    shared = np.flatnonzero((near >= 0) & (far >= 0))
    shared = shared[np.lexsort((half.points[shared, 2], half.points[shared, 0]))]
    twice = np.flatnonzero(owner[:, 1] >= 0)
    between = twice[np.all(np.sort(band[owner[twice]], axis=1) == [slab, slab + 1], axis=1)]
    nodes = len(half.points)
    triangles = np.stack([faces[between] // (nodes * nodes), faces[between] // nodes % nodes, faces[between] % nodes],
                         axis=1)
    a, b, c = (half.points[triangles[:, k]] for k in range(3))
    areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    lumped = np.bincount(triangles.ravel(), np.repeat(areas / 3.0, 3), minlength=len(half.points))[shared]
    floor = 0.5 * np.median(lumped[lumped > 0]) if np.any(lumped > 0) else 1.0
    return Cut(half.points[shared], np.maximum(lumped, floor), (near[shared], far[shared]))


def _faces(tetrahedra: np.ndarray, nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """The distinct faces of ``tetrahedra`` (of ``nodes`` nodes) as sorted keys (:func:`_keys`) and their one or two
    tetrahedra (f, 2; −1: a boundary face's missing second)."""
    every = _keys(tetrahedra[:, TETRA_FACES].reshape(-1, 3), nodes)
    order = np.argsort(every, kind="stable")
    ordered = every[order]
    starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])
    owner = np.full((len(starts), 2), -1, dtype=np.int64)
    owner[:, 0] = order[starts] // 4
    second = np.flatnonzero(np.r_[ordered[1:] == ordered[:-1], False])  # a face's first of two
    owner[np.searchsorted(starts, second), 1] = order[second + 1] // 4
    return ordered[starts], owner


def _keys(triangles: np.ndarray, nodes: int) -> np.ndarray:
    """One integer per triangle of vertices ``triangles`` (any order): its sorted vertices in base ``nodes``."""
    if float(nodes) ** 3 >= 2.0 ** 63:
        raise ValueError(f"{nodes} nodes: too many for a face key")
    a, b, c = np.sort(triangles, axis=1).astype(np.int64).T
    return (a * nodes + b) * nodes + c


def _owners(triangles: np.ndarray, faces: np.ndarray, owner: np.ndarray, nodes: int) -> np.ndarray:
    """The tetrahedron of each boundary triangle (corner nodes) among the distinct face keys ``faces``."""
    return owner[np.searchsorted(faces, _keys(triangles[:, :3], nodes)), 0]
