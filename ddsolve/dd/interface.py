"""The interface Σ: the blocks, the Lagrange multipliers that couple them, and their signs.

Every block has the same *trace*: the displacements of the k Σ nodes that are not clamped, in order
along Σ, each in its local frame (tangential, normal) — a vector of length 2k (for a straight Σ
along x the frame is (x, y)).  The multipliers are nodal values (densities, as in the paper) stacked
into one vector λ = [μᶜ | μᵍ | μ⁻ | μ⁺], vectors in the same local frames:

==========  ======================  ===================  ========================
multiplier  vertices                gap it enforces      admissible set
==========  ======================  ===================  ========================
μᶜ          crack                   (u⁻ − u⁺)·ν ≤ 0      0 ≤ μᶜ ≤ p
μᵍ (x, y)   glued (not crack)       u⁻ − u⁺ = 0          −p ≤ μᵍ ≤ p
μ⁻ (x, y)   all                     u⁻ − v⁻ = 0          −p ≤ μ⁻ ≤ p
μ⁺ (x, y)   all                     u⁺ − v⁺ = 0          −p ≤ μ⁺ ≤ p
==========  ======================  ===================  ========================

A one-layer structure has the blocks u⁻ and u⁺ only, and μᶜ, μᵍ only: the families that glue a region's layers
together (μ⁻, μ⁺) come from the pairs :func:`ddsolve.mesh.mesh.glued_layers` lists.

With the lumped weights w (∫Σ φ_k ds: half the length of the Σ edges at a P1 vertex) the discrete coupling is
gap = Σ_b C_b t_b and block b receives the nodal force −C_bᵀ W λ on its trace.  μᶜ exists only
when the scene has a crack and non-penetration; without it the crack faces are simply free.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddsolve.mesh.mesh import U_MINUS, U_PLUS, BlockSpec, SigmaLine, blocks, glued_layers


#: The families on Σ's faces (layer1's blocks u⁻ and u⁺), and the family that glues a region's layers, by its side.
SIGMA_FAMILIES = ("mu_c", "mu_g")
LAYER_FAMILIES = {-1: "mu_minus", +1: "mu_plus"}


@dataclass(frozen=True)
class Coupling:
    """Entries of C_b: multiplier row, trace position, sign."""

    rows: np.ndarray
    trace: np.ndarray
    sign: np.ndarray


class Interface:
    """Multiplier layout and the maps between traces, gaps, multipliers and interface loads."""

    def __init__(self, weights: np.ndarray, crack: np.ndarray, contact: bool, fixed: np.ndarray | None = None,
                 modulus: float = 0.0, data: float = 0.0, specs: tuple[BlockSpec, ...] = blocks(2)):
        """``weights`` and ``crack`` (bool) of the k multiplier nodes; ``contact``: non-penetration holds;
        ``specs``: the structure's blocks (:func:`ddsolve.mesh.mesh.blocks`);
        ``fixed`` ``(blocks, 2k)``: the blocks' prescribed trace entries (:mod:`ddsolve.fem.supports`): a
        multiplier between two prescribed entries has nothing to enforce and does not exist; ``modulus``:
        the largest elastic modulus of the layers (the scale of the stresses a displacement makes, for the
        KKT check); ``data``: the displacement the scene's data would make
        (:func:`ddsolve.fem.assembly.data_displacement`, the KKT check's scale when the solution is zero)."""
        self.modulus = float(modulus)
        self.data = float(data)
        self.weights = np.asarray(weights, dtype=np.float64)
        self.crack = np.asarray(crack, dtype=bool)
        k = len(self.weights)
        self.contact = bool(contact and self.crack.any())
        contact_vertices = np.flatnonzero(self.crack) if self.contact else np.zeros(0, dtype=np.int64)
        glued_vertices = np.flatnonzero(~self.crack)
        all_vertices = np.arange(k)

        self.blocks = tuple(specs)
        # Multiplier rows: (vertex, component) and the blocks (minuend, subtrahend) of the gap of each family, in
        # the order of the class docstring: Σ's faces, then each region's layers glued.
        families = {
            "mu_c": (contact_vertices, np.ones(len(contact_vertices), dtype=np.int64), (U_MINUS, U_PLUS)),
            "mu_g": (*_both_components(glued_vertices), (U_MINUS, U_PLUS)),
            **{LAYER_FAMILIES[self.blocks[first].side]: (*_both_components(all_vertices), (first, other))
               for first, other in glued_layers(self.blocks)},
        }
        #: The crack faces' normal entries (trace positions) that both faces prescribe, so that no contact row
        #: holds them: the KKT check measures their penetration from the traces alone.
        self.prescribed_contact = np.zeros(0, dtype=np.int64)
        if fixed is not None:
            normals = 2 * contact_vertices + 1
            self.prescribed_contact = normals[fixed[U_MINUS, normals] & fixed[U_PLUS, normals]]
            for name, (vertices, components, pair) in families.items():
                entries = 2 * vertices + components
                kept = ~(fixed[pair[0], entries] & fixed[pair[1], entries])
                families[name] = (vertices[kept], components[kept], pair)
        #: family -> the blocks (minuend, subtrahend) of its gap
        self.pairs = {name: pair for name, (_, _, pair) in families.items()}
        self.slices: dict[str, slice] = {}
        start = 0
        for name, (vertices, _, _) in families.items():
            self.slices[name] = slice(start, start + len(vertices))
            start += len(vertices)
        self.size = start
        self.vertex = np.concatenate([v for v, _, _ in families.values()])
        self.component = np.concatenate([c for _, c, _ in families.values()])
        self.trace_index = 2 * self.vertex + self.component
        self.row_weights = self.weights[self.vertex]
        self.is_contact = np.zeros(self.size, dtype=bool)
        self.is_contact[self.slices["mu_c"]] = True

        # (family, block, sign): a family's gap rows are its minuend's trace less its subtrahend's.
        signs = [(name, block, sign) for name, pair in self.pairs.items() for block, sign in zip(pair, (1.0, -1.0))]
        self.couplings = []
        for block in range(len(self.blocks)):
            rows = np.concatenate([np.arange(self.size)[self.slices[f]] for f, b, _ in signs if b == block])
            sign = np.concatenate([np.full(self.slices[f].stop - self.slices[f].start, s)
                                   for f, b, s in signs if b == block])
            self.couplings.append(Coupling(rows, self.trace_index[rows], sign))

    @property
    def trace_size(self) -> int:
        return 2 * len(self.weights)

    def bounds(self, p: float | None) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of λ: μᶜ in [0, p], the others in [−p, p] (p = None: unbounded)."""
        p = np.inf if p is None else p
        lower = np.full(self.size, -p)
        lower[self.is_contact] = 0.0
        return lower, np.full(self.size, p)

    def gap(self, traces: np.ndarray) -> np.ndarray:
        """Constraint values Σ_b C_b t_b for traces ``(blocks, 2k)``."""
        out = np.zeros(self.size)
        for coupling, trace in zip(self.couplings, traces):
            out[coupling.rows] += coupling.sign * trace[coupling.trace]
        return out

    def loads(self, lam: np.ndarray) -> np.ndarray:
        """Interface nodal forces −C_bᵀ W λ on each block's trace, ``(blocks, 2k)``."""
        out = np.zeros((len(self.blocks), self.trace_size))
        force = self.row_weights * lam
        for coupling, load in zip(self.couplings, out):
            np.add.at(load, coupling.trace, -coupling.sign * force[coupling.rows])
        return out

    def multipliers(self, loads: np.ndarray) -> np.ndarray:
        """The λ with ``self.loads(λ) == loads`` when ``loads`` is in the range of that map.

        v⁻ and v⁺ carry only μ⁻ and μ⁺ (force +W μ); u⁻ carries −W(μᶜν + μᵍ + μ⁻).
        """
        lam = np.zeros(self.size)
        minus = np.zeros(self.trace_size)  # indexed by trace position: the layer families u⁻ carries
        for name, (first, other) in self.pairs.items():
            if name in SIGMA_FAMILIES:
                continue
            rows = self.slices[name]
            lam[rows] = loads[other][self.trace_index[rows]] / self.row_weights[rows]
            if first == U_MINUS:
                minus[self.trace_index[rows]] += lam[rows]
        for name in SIGMA_FAMILIES:
            rows = self.slices[name]
            traces = self.trace_index[rows]
            lam[rows] = -loads[U_MINUS][traces] / self.row_weights[rows] - minus[traces]
        return lam

    def dual_matrix(self, flexibilities: np.ndarray) -> np.ndarray:
        """F = Σ_b W C_b G_b C_bᵀ W from the blocks' flexibilities G_b ``(blocks, 2k, 2k)``."""
        F = np.zeros((self.size, self.size))
        for coupling, G in zip(self.couplings, flexibilities):
            scaled = coupling.sign * self.row_weights[coupling.rows]
            F[np.ix_(coupling.rows, coupling.rows)] += np.outer(scaled, scaled) * G[np.ix_(coupling.trace, coupling.trace)]
        return F

    def trace_unknowns(self, closed: np.ndarray | None = None) -> np.ndarray:
        """``(blocks, 2k)``: one interface unknown per trace entry, tied entries sharing it.

        Glued vertices tie all the blocks; a crack vertex ties u⁻ with v⁻ (lower face) and u⁺ with
        v⁺ (upper face), and also the faces' normal components where ``closed`` (per μᶜ row).
        """
        k = len(self.weights)
        lower = np.arange(2 * k)
        upper = lower + 2 * k
        glued = np.repeat(~self.crack, 2)
        upper[glued] = lower[glued]
        if closed is not None:
            normal = 2 * self.vertex[self.slices["mu_c"]][closed] + 1
            upper[normal] = lower[normal]
        _, numbers = np.unique(np.concatenate([lower, upper]), return_inverse=True)
        lower, upper = numbers[:2 * k], numbers[2 * k:]
        return np.array([lower if spec.side < 0 else upper for spec in self.blocks])

    def split(self, lam: np.ndarray, frames: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Per-node arrays: mu_c ``(k,)``, mu_g, mu_minus, mu_plus ``(k, 2)``; 0 where absent (a one-layer
        structure has no mu_minus, mu_plus: they are left out).

        The vectors are in the nodes' local frames, or in (x, y) when their ``frames`` ``(k, 2, 2)`` are given.
        """
        k = len(self.weights)
        out = {"mu_c": np.zeros(k)}
        out["mu_c"][self.vertex[self.slices["mu_c"]]] = lam[self.slices["mu_c"]]
        for name in (name for name in self.slices if name != "mu_c"):
            values = np.zeros((k, 2))
            rows = self.slices[name]
            values[self.vertex[rows], self.component[rows]] = lam[rows]
            out[name] = values if frames is None else np.einsum("nab,na->nb", frames, values)
        return out


def for_mesh(sigma: SigmaLine, contact: bool, fixed: np.ndarray | None = None, modulus: float = 0.0,
             data: float = 0.0, specs: tuple[BlockSpec, ...] = blocks(2)) -> Interface:
    """The interface of a mesh's Σ (``contact``: the scene's non-penetration condition; ``fixed``: the
    blocks' prescribed trace entries; ``modulus``: the layers' largest modulus; ``data``: the displacement
    the data would make; ``specs``: the structure's blocks; see :class:`Interface`)."""
    nodes = sigma.multiplier_nodes
    return Interface(sigma.weights[nodes], sigma.crack[nodes], contact, fixed, modulus, data, specs)


def _both_components(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.repeat(vertices, 2), np.tile(np.array([0, 1]), len(vertices))
