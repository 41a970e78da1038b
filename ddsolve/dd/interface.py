"""The interface Σ: the blocks, the Lagrange multipliers that couple them, and their signs.

Every block has the same *trace*: the displacements of the k Σ nodes that are not clamped, in order
along Σ, each in its local frame (tangential, normal) — a vector of length 2k (for a straight Σ
along x the frame is (x, y)).  On the plane Σ (y = const) of a 3-D box a vertex has d = 3 entries
(x, ν = y, z: the normal stays component 1) and the trace d k; every vector family below then has three
components (``components``).  The multipliers are nodal values (densities, as in the paper) stacked
into one vector λ = [μᶜ | μᵍ | μ⁻ | μ⁺], vectors in the same local frames:

==========  ======================  ===================  ========================
multiplier  vertices                gap it enforces      admissible set
==========  ======================  ===================  ========================
μᶜ          crack                   (u⁻ − u⁺)·ν ≤ 0      0 ≤ μᶜ ≤ p
μᵍ (x, y)   glued (not crack)       u⁻ − u⁺ = 0          −p ≤ μᵍ ≤ p
μ⁻ (x, y)   all                     u⁻ − v⁻ = 0          −p ≤ μ⁻ ≤ p
μ⁺ (x, y)   all                     u⁺ − v⁺ = 0          −p ≤ μ⁺ ≤ p
μ_t         crack, with friction    (u⁻ − u⁺)·τ = 0      −g ≤ μ_t ≤ g (and |μ_t| ≤ p)
            (x only: tangential)    unless |μ_t| = g
==========  ======================  ===================  ========================

Several interfaces make one :class:`Interface` (:meth:`Interface.joined`): its trace the interfaces' traces
concatenated, its rows theirs family by family, each row knowing its two blocks of the structure (``row_blocks``)
and each block the face of every trace entry it holds (``faces``; 0 where it holds none).

A one-layer structure has the blocks u⁻ and u⁺ only, and μᶜ, μᵍ (and μ_t) only: the families that glue a region's
layers together (μ⁻, μ⁺) come from the pairs :func:`ddsolve.mesh.mesh.glued_layers` lists.

With the lumped weights w (∫Σ φ_k ds: half the length of the Σ edges at a P1 vertex) the discrete coupling is
gap = Σ_b C_b t_b and block b receives the nodal force −C_bᵀ W λ on its trace.  μᶜ exists only
when the scene has a crack and non-penetration; without it the crack faces are simply free.

μ_t exists only on crack vertices with friction (``contact.friction`` μ or ``contact.slip_bound`` g > 0): the
tangential traction between the faces, the lower face receiving −μ_t τ and the upper +μ_t τ.  Its box is
Tresca's (g given) or, for Coulomb, g = μ × the contact pressure μᶜ of a fixed-point iteration
(:mod:`ddsolve.dd.friction`).  The dual problem's optimality makes the slip s = (u⁻ − u⁺)·τ vanish where
|μ_t| < g and have the sign of μ_t where |μ_t| = g: the friction on each face opposes its slip relative to
the other.

With a bond law on Σ (``[interface]``, :mod:`ddsolve.dd.cohesive`) the μᵍ rows are compliant: their gap is
u⁻ − u⁺ = c λ (c = 1/k, per row; :attr:`Interface.compliance`, 0 for the rigid bond), the spring k of the law's
secant at the vertex's damage d, k(1 − d), where the normal row opens (μᵍ·ν < 0) and the undamaged k where it is
pressed.  A fully damaged vertex keeps its normal row as a penalized contact (μᵍ·ν ≥ 0) and frees its tangential
row (μᵍ·τ = 0).  The dual problem's matrix gains the diagonal c (in the W-scaled variable y = W^½ λ too).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import scipy.sparse

from ddsolve.errors import SceneError
from ddsolve.mesh.mesh import U_MINUS, U_PLUS, BlockSpec, SigmaLine, blocks, glued_layers
from ddsolve.problem.scene import Bond, Friction

#: A vertex whose damage reaches this is broken (its tangential row freed, its normal row a penalized contact).
BROKEN = 1.0 - 1e-9

#: The families on Σ's faces (layer1's blocks u⁻ and u⁺), and the family that glues a region's layers, by its side.
SIGMA_FAMILIES = ("mu_c", "mu_g", "mu_t")
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
                 modulus: float = 0.0, data: float = 0.0, friction: np.ndarray | None = None, coulomb: bool = False,
                 specs: tuple[BlockSpec, ...] = blocks(2), bond: Bond | None = None, components: int = 2,
                 points: np.ndarray | None = None):
        """``weights`` and ``crack`` (bool) of the k multiplier nodes; ``contact``: non-penetration holds;
        ``specs``: the structure's blocks (:func:`ddsolve.mesh.mesh.blocks`); ``components``: d, the trace
        entries per vertex (2 in the plane, 3 on a 3-D box's Σ: (τ₁, ν, τ₂), the normal component 1 always);
        ``fixed`` ``(blocks, d k)``: the blocks' prescribed trace entries (:mod:`ddsolve.fem.supports`): a
        multiplier between two prescribed entries has nothing to enforce and does not exist; ``modulus``:
        the largest elastic modulus of the layers (the scale of the stresses a displacement makes, for the
        KKT check); ``data``: the displacement the scene's data would make
        (:func:`ddsolve.fem.assembly.data_displacement`, the KKT check's scale when the solution is zero);
        ``friction`` ``(k,)``: Coulomb's μ (``coulomb``) or Tresca's bound g at each node (0: none); ``bond``: the
        law of the bonded vertices (None: rigid), undamaged until :meth:`with_damage`; ``points`` ``(k, dim)``: the
        nodes' coordinates (for feti's polynomial coarse directions, :func:`ddsolve.dd.feti.polynomial_directions`)."""
        self.points = None if points is None else np.asarray(points, dtype=np.float64)
        self.modulus = float(modulus)
        self.data = float(data)
        self.components = int(components)
        self.weights = np.asarray(weights, dtype=np.float64)
        self.crack = np.asarray(crack, dtype=bool)
        k = len(self.weights)
        self.contact = bool(contact and self.crack.any())
        contact_vertices = np.flatnonzero(self.crack) if self.contact else np.zeros(0, dtype=np.int64)
        glued_vertices = np.flatnonzero(~self.crack)
        all_vertices = np.arange(k)

        self.blocks = tuple(specs)
        # Multiplier rows: (vertex, component) and the blocks (minuend, subtrahend) of the gap of each family, in
        # the order of the class docstring: Σ's faces, each region's layers glued, the friction.
        families = {
            "mu_c": (contact_vertices, np.ones(len(contact_vertices), dtype=np.int64), (U_MINUS, U_PLUS)),
            "mu_g": (*self._every_component(glued_vertices), (U_MINUS, U_PLUS)),
            **{LAYER_FAMILIES[self.blocks[first].side]: (*self._every_component(all_vertices), (first, other))
               for first, other in glued_layers(self.blocks)},
        }
        friction = np.zeros(k) if friction is None else np.asarray(friction, dtype=np.float64)
        sliding = contact_vertices[friction[contact_vertices] > 0]
        if len(sliding):
            families["mu_t"] = (sliding, np.zeros(len(sliding), dtype=np.int64), (U_MINUS, U_PLUS))
        #: The crack faces' normal entries (trace positions) that both faces prescribe, so that no contact row
        #: holds them: the KKT check measures their penetration from the traces alone.
        self.prescribed_contact = np.zeros(0, dtype=np.int64)
        if fixed is not None:
            normals = self.components * contact_vertices + 1
            self.prescribed_contact = normals[fixed[U_MINUS, normals] & fixed[U_PLUS, normals]]
            for name, (vertices, components, pair) in families.items():
                entries = self.components * vertices + components
                kept = ~(fixed[pair[0], entries] & fixed[pair[1], entries])
                families[name] = (vertices[kept], components[kept], pair)
        #: ``(blocks, d k)``: the face of Σ each block's trace entry lies on (−1 lower, +1 upper)
        self.faces = np.array([np.full(self.components * k, spec.side) for spec in self.blocks], dtype=np.int64)
        self._lay_out({name: (vertices, components, np.broadcast_to(np.array(pair), (len(vertices), 2)))
                       for name, (vertices, components, pair) in families.items()}, friction, coulomb)
        self.bond = bond
        self.damage = np.zeros(k)
        self.pressed = np.zeros(k, dtype=bool)

    @classmethod
    def joined(cls, parts: list[Interface], members: list[tuple[int, ...]], specs: tuple[BlockSpec, ...]
               ) -> Interface:
        """The interfaces ``parts`` of a structure of several interfaces as one: its trace the parts' traces
        concatenated (part i's entries follow those of the parts below it), its rows the parts' rows family by
        family (every μᶜ row first, then μᵍ, ...), ``members[i]``: the structure's block (of ``specs``) of each of
        part i's blocks.  ``part_rows[i]``: the rows of part i, in its own order.  Neither friction nor a bond."""
        out = cls.__new__(cls)
        out.modulus = max(part.modulus for part in parts)
        out.components = d = parts[0].components
        out.data = max(part.data for part in parts)
        out.weights = np.concatenate([part.weights for part in parts])
        out.points = (None if any(part.points is None for part in parts) else
                      np.concatenate([part.points for part in parts]))
        out.crack = np.concatenate([part.crack for part in parts])
        out.contact = any(part.contact for part in parts)
        out.blocks = tuple(specs)
        nodes = np.cumsum([0] + [len(part.weights) for part in parts])
        out.prescribed_contact = np.concatenate([d * first + part.prescribed_contact
                                                 for first, part in zip(nodes, parts)])
        out.faces = np.zeros((len(specs), d * nodes[-1]), dtype=np.int64)
        families: dict[str, list] = {}
        for first, part, blocks in zip(nodes, parts, members):
            for own, block in enumerate(blocks):
                out.faces[block, d * first:d * first + part.trace_size] = part.faces[own]
            for name, rows in part.slices.items():
                families.setdefault(name, []).append((first + part.vertex[rows], part.component[rows],
                                                      np.asarray(blocks)[part.row_blocks[rows]]))
        out._lay_out({name: tuple(np.concatenate(column) for column in zip(*lists))
                      for name, lists in families.items()}, np.zeros(nodes[-1]), False)
        before = {name: np.cumsum([0] + [part.slices[name].stop - part.slices[name].start for part in parts])
                  for name in out.slices}  # each family's rows of the parts below
        out.part_rows = [np.concatenate([np.arange(rows.start, rows.stop) - rows.start + out.slices[name].start
                                         + before[name][index] for name, rows in part.slices.items()])
                         for index, part in enumerate(parts)]
        out.bond, out.damage, out.pressed = None, np.zeros(nodes[-1]), np.zeros(nodes[-1], dtype=bool)
        return out

    def _lay_out(self, families: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], friction: np.ndarray,
                 coulomb: bool) -> None:
        """The rows of ``families`` (name -> each row's vertex, component and blocks (minuend, subtrahend)), one
        family after another, and each block's coupling: a row's gap is its minuend's trace less its
        subtrahend's."""
        self.slices: dict[str, slice] = {}
        start = 0
        for name, (vertices, _, _) in families.items():
            self.slices[name] = slice(start, start + len(vertices))
            start += len(vertices)
        self.size = start
        self.vertex = np.concatenate([v for v, _, _ in families.values()])
        self.component = np.concatenate([c for _, c, _ in families.values()])
        #: ``(size, 2)``: the blocks (minuend, subtrahend) of each row's gap
        self.row_blocks = np.concatenate([np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
                                          for _, _, pairs in families.values()])
        self.trace_index = self.components * self.vertex + self.component
        self.row_weights = self.weights[self.vertex]
        self.is_contact = np.zeros(self.size, dtype=bool)
        self.is_contact[self.slices["mu_c"]] = True
        self._friction_rows(friction, coulomb)
        self.couplings = []
        for block in range(len(self.blocks)):  # family after family, as the rows are
            taking = np.flatnonzero((self.row_blocks == block).any(axis=1))
            sign = np.where(self.row_blocks[taking, 0] == block, 1.0, -1.0)
            self.couplings.append(Coupling(taking, self.trace_index[taking], sign))
        #: per block C_bᵀ ``(2k, size)``, sparse: the interface loads of multipliers
        self.spreads = [scipy.sparse.csr_matrix((c.sign, (c.trace, c.rows)), shape=(self.trace_size, self.size))
                        for c in self.couplings]

    def _friction_rows(self, friction: np.ndarray, coulomb: bool) -> None:
        """The μ_t rows' data: ``is_friction``, Coulomb's μ or Tresca's g per row, the row of the contact
        multiplier at the same vertex (−1: none) and ``slip``, the bound g of the rows (Coulomb: None until a
        fixed-point iteration gives it, :meth:`with_slip`)."""
        rows = self.slices.get("mu_t", slice(self.size, self.size))
        self.is_friction = np.zeros(self.size, dtype=bool)
        self.is_friction[rows] = True
        self.coulomb = bool(coulomb)
        self.friction_values = friction[self.vertex[rows]]
        normal = np.full(len(self.weights), -1)
        normal[self.vertex[self.slices["mu_c"]]] = np.arange(self.size)[self.slices["mu_c"]]
        self.normal_row = normal[self.vertex[rows]]
        self.slip = None if self.coulomb else self.friction_values.copy()

    def _every_component(self, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A row per component of each of ``vertices``: their vertices and components."""
        return np.repeat(vertices, self.components), np.tile(np.arange(self.components), len(vertices))

    @property
    def friction(self) -> bool:
        """Whether any crack vertex carries a friction multiplier μ_t."""
        return bool(self.is_friction.any())

    def with_slip(self, slip: np.ndarray) -> Interface:
        """This interface with the bounds ``slip`` (one per μ_t row) on its friction multipliers."""
        out = copy.copy(self)
        out.slip = np.asarray(slip, dtype=np.float64)
        return out

    def slip_bounds(self, lam: np.ndarray) -> np.ndarray:
        """g of each μ_t row: Tresca's (given, or a Coulomb fixed point's iterate, :meth:`with_slip`), else Coulomb's
        μ max(μᶜ, 0) at the same vertex of the multipliers ``lam``."""
        if self.slip is not None:
            return self.slip
        normal = np.where(self.normal_row >= 0, lam[np.maximum(self.normal_row, 0)], 0.0)
        return self.friction_values * np.maximum(normal, 0.0)

    def with_damage(self, damage: np.ndarray, pressed: np.ndarray) -> Interface:
        """This interface with the bond's ``damage`` ``(k,)`` and its normal rows ``pressed`` ``(k,)`` (bool)."""
        out = copy.copy(self)
        out.damage, out.pressed = np.asarray(damage, dtype=np.float64), np.asarray(pressed, dtype=bool)
        return out

    def bond_rows(self, component: int) -> np.ndarray:
        """The μᵍ rows of ``component`` (0: tangential, 1: normal)."""
        rows = np.arange(self.size)[self.slices["mu_g"]]
        return rows[self.component[rows] == component]

    @property
    def compliance(self) -> np.ndarray:
        """``(size,)``: c of each row (gap = c λ; 0: rigid): 1/(k(1 − d)) on the bond's rows, 1/k on a pressed normal
        row and on a broken vertex's (a penalized contact), 0 on a broken vertex's freed tangential row."""
        out = np.zeros(self.size)
        if self.bond is None:
            return out
        for component in (0, 1):
            rows = self.bond_rows(component)
            damage = self.damage[self.vertex[rows]]
            if component == 1:
                damage = np.where(self.pressed[self.vertex[rows]] | (damage >= BROKEN), 0.0, damage)
            intact = damage < BROKEN
            out[rows[intact]] = 1.0 / (self.bond.stiffness * (1.0 - damage[intact]))
        return out

    @property
    def trace_size(self) -> int:
        return self.components * len(self.weights)

    def bounds(self, p: float | None) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of λ: μᶜ in [0, p], μ_t in [−g, g] (g: :attr:`slip`, 0 where Coulomb's is not
        set yet; at most p), the others in [−p, p] (p = None: unbounded)."""
        p = np.inf if p is None else p
        lower = np.full(self.size, -p)
        lower[self.is_contact] = 0.0
        upper = np.full(self.size, p)
        upper[self.is_friction] = np.minimum(0.0 if self.slip is None else self.slip, p)
        lower[self.is_friction] = -upper[self.is_friction]
        if self.bond is not None:
            tangential, normal = self.bond_rows(0), self.bond_rows(1)
            broken = self.damage >= BROKEN
            lower[tangential[broken[self.vertex[tangential]]]] = 0.0
            upper[tangential[broken[self.vertex[tangential]]]] = 0.0
            lower[normal[broken[self.vertex[normal]]]] = 0.0
        return lower, upper

    def gap(self, traces: np.ndarray) -> np.ndarray:
        """Constraint values Σ_b C_b t_b for traces ``(blocks, 2k)``."""
        out = np.zeros(self.size)
        for coupling, trace in zip(self.couplings, traces):
            out[coupling.rows] += coupling.sign * trace[coupling.trace]
        return out

    def loads(self, lam: np.ndarray) -> np.ndarray:
        """Interface nodal forces −C_bᵀ W λ on each block's trace, ``(blocks, 2k)``."""
        force = self.row_weights * lam
        return np.array([-(spread @ force) for spread in self.spreads])

    def column_loads(self, lam: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """For the columns of ``lam`` ``(size, m)``, per block: the columns that load it and their loads
        −C_bᵀ W λ ``(2k, those columns)``."""
        force = self.row_weights[:, None] * lam
        out = []
        for coupling, spread in zip(self.couplings, self.spreads):
            taken = np.flatnonzero(np.any(force[coupling.rows] != 0.0, axis=0))
            out.append((taken, -(spread @ force[:, taken])))
        return out

    def column_gap(self, traces: list[tuple[np.ndarray, np.ndarray]], columns: int) -> np.ndarray:
        """Σ_b C_b t_b ``(size, columns)`` for, per block, the columns it has traces ``(2k, those columns)`` of (zero in
        the others), as :meth:`column_loads` lists them."""
        out = np.zeros((self.size, columns))
        for coupling, (taken, trace) in zip(self.couplings, traces):
            out[np.ix_(coupling.rows, taken)] += coupling.sign[:, None] * trace[coupling.trace]
        return out

    def multipliers(self, loads: np.ndarray) -> np.ndarray:
        """The λ with ``self.loads(λ) == loads`` when ``loads`` is in the range of that map.

        A row gluing a region's layers is the only one its subtrahend (v⁻, v⁺: force +W μ) carries at its
        entry; a row of Σ's faces then follows from its minuend's load, −W(μᶜν + μᵍ + the layers' rows it
        carries there).
        """
        lam = np.zeros(self.size)
        carried = np.zeros((len(self.blocks), self.trace_size))  # the layers' rows each block carries as minuend
        for name, rows in self.slices.items():
            if name in SIGMA_FAMILIES:
                continue
            first, other = self.row_blocks[rows].T
            entries = self.trace_index[rows]
            lam[rows] = loads[other, entries] / self.row_weights[rows]
            carried[first, entries] += lam[rows]
        for name in SIGMA_FAMILIES:
            rows = self.slices.get(name, slice(0, 0))
            first, entries = self.row_blocks[rows, 0], self.trace_index[rows]
            lam[rows] = -loads[first, entries] / self.row_weights[rows] - carried[first, entries]
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
        v⁺ (upper face), and also the faces' normal components where ``closed`` (per μᶜ row).  Entries a block
        does not hold (:attr:`faces` 0, several interfaces) take the lower face's unknown.
        """
        k, d = len(self.weights), self.components
        lower = np.arange(d * k)
        upper = lower + d * k
        glued = np.repeat(~self.crack, d)
        upper[glued] = lower[glued]
        if closed is not None:
            normal = d * self.vertex[self.slices["mu_c"]][closed] + 1
            upper[normal] = lower[normal]
        _, numbers = np.unique(np.concatenate([lower, upper]), return_inverse=True)
        lower, upper = numbers[:d * k], numbers[d * k:]
        return np.where(self.faces > 0, upper, lower)

    def split(self, lam: np.ndarray, frames: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Per-node arrays: mu_c ``(k,)``, mu_g, mu_minus, mu_plus ``(k, 2)``; 0 where absent (a one-layer
        structure has no mu_minus, mu_plus: they are left out); with friction mu_t ``(k,)`` (the tangential
        traction, along τ) too; with a bond law its ``damage`` and ``pressed`` ``(k,)``.

        The vectors are in the nodes' local frames, or in (x, y) when their ``frames`` ``(k, 2, 2)`` are given.
        """
        k = len(self.weights)
        out = {"mu_c": np.zeros(k)}
        out["mu_c"][self.vertex[self.slices["mu_c"]]] = lam[self.slices["mu_c"]]
        if self.bond is not None:  # the bond's state: its damage, and its pressed normal rows (0 or 1)
            out["damage"], out["pressed"] = self.damage.copy(), self.pressed.astype(np.float64)
        if self.friction:
            out["mu_t"] = np.zeros(k)
            out["mu_t"][self.vertex[self.slices["mu_t"]]] = lam[self.slices["mu_t"]]
        for name in (name for name in self.slices if name not in ("mu_c", "mu_t")):
            values = np.zeros((k, self.components))
            rows = self.slices[name]
            values[self.vertex[rows], self.component[rows]] = lam[rows]
            out[name] = values if frames is None else np.einsum("nab,na->nb", frames, values)
        return out


def for_mesh(sigma: SigmaLine, contact: bool, fixed: np.ndarray | None = None, modulus: float = 0.0,
             data: float = 0.0, friction: Friction | None = None, specs: tuple[BlockSpec, ...] = blocks(2),
             bond: Bond | None = None) -> Interface:
    """The interface of a mesh's Σ (``contact``: the scene's non-penetration condition; ``fixed``: the
    blocks' prescribed trace entries; ``modulus``: the layers' largest modulus; ``data``: the displacement
    the data would make; ``friction``: the scene's, on its cracks in order along Σ; ``specs``: the structure's
    blocks; ``bond``: the law on the bonded part of Σ, which must exist; see :class:`Interface`)."""
    nodes = sigma.multiplier_nodes
    values = None if friction is None else friction_values(sigma, friction)[nodes]
    if bond is not None and sigma.crack[nodes].all():
        raise SceneError("interface.law: the law acts on the bonded part of Σ, and the cracks cover all of Σ (a "
                         "crack's faces take contact.friction or contact.slip_bound instead)")
    return Interface(sigma.weights[nodes], sigma.crack[nodes], contact, fixed, modulus, data, values,
                     friction is not None and friction.coulomb, specs, bond, points=sigma.points[nodes])


def friction_values(sigma: SigmaLine, friction: Friction) -> np.ndarray:
    """``(s,)``: the scene's friction value (μ or g) of each Σ node's crack, 0 off the cracks; the cracks are the
    runs of crack nodes in order along Σ."""
    values = np.zeros(len(sigma.points))
    runs = sigma.pieces(sigma.crack)
    for value, (first, last) in zip(friction.per_crack(len(runs)), runs):
        values[first:last + 1] = value
    return values
