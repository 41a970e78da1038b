"""What a run produces: the same schema for the DD solve and the monolithic reference."""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from ddsolve.fem import assembly
from ddsolve.mesh.mesh import BlockSpec, HalfMesh, Mesh, SigmaLine, blocks
from ddsolve.problem import scene as scenes


@dataclass
class Result:
    """Displacements of the structure's blocks (x, y components; :attr:`blocks`) on the mesh, multipliers per
    Σ node, history.

    ``multipliers``: ``mu_c`` ``(k,)`` (the contact pressure), ``mu_g``, ``mu_minus``, ``mu_plus``
    ``(k, 2)`` in (x, y), over the k multiplier nodes (0 where a multiplier does not exist; a one-layer
    structure has no ``mu_minus``, ``mu_plus``: they are absent); with friction ``mu_t`` ``(k,)``, the tangential
    traction between the crack faces along τ (the lower face receives −μ_t τ; where they slip and stick:
    :func:`ddsolve.post.analysis.friction_zones`).
    ``history``: the stopping criterion per iteration; ``active_set_changes``: per iteration of an
    active-set method (``schur``, the reference), how many constraints changed state (else empty).
    ``cell_data``: name -> block -> per-cell values ``(m,)`` or ``(m, c)`` of the block's half; the
    viewer files show every entry as a cell array of its layer.
    ``indicators``: block name -> ``(m,)`` error indicator η_K per cell (see :mod:`ddsolve.post.estimate`);
    ``levels``: column -> ``(levels,)`` values of an adaptive run, one entry per mesh.
    ``reactions``: layer -> boundary -> the force ``(2,)`` its support exerts on the layer
    (:mod:`ddsolve.post.reactions`).
    ``scene``: the scene solved (a result file holds its text, ``scene.text``).
    """

    scene: scenes.Scene
    method: str
    converged: bool
    iterations: int
    solves: int
    wall_time: float
    ranks: int
    mesh: Mesh | None  # None on rank 0 of a run whose ranks wrote the result (see ``held``)
    solution: dict[str, np.ndarray]  # block name -> (n, 2) nodal displacements
    multipliers: dict[str, np.ndarray]
    history: np.ndarray
    active_set_changes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    cell_data: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    memory: dict = field(default_factory=dict)  # peak memory per phase and rank, bytes per unknown
    message: str = ""
    attrs: dict = field(default_factory=dict)
    fracture: Fracture | None = None  # G at the crack tips and the contact zones
    #: layer -> supported or displaced boundary name -> the reaction force (x, y) on that layer
    reactions: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    indicators: dict[str, np.ndarray] = field(default_factory=dict)
    levels: dict[str, np.ndarray] = field(default_factory=dict)
    held: OnSigma | None = None  # rank 0 of a run whose ranks wrote the result: all it holds (no mesh, no solution)
    #: The files the run read (scene, mesh and the files it reaches) -> how: :func:`ddsolve.io.save` never replaces them.
    inputs: dict[Path, str] = field(default_factory=dict, compare=False)
    #: The result file this result was last read from or saved to, if any.
    path: Path | None = field(default=None, compare=False)

    def __repr__(self) -> str:
        """A few lines: what was solved, how, the energy, G and the file (the arrays are attributes)."""
        title = self.scene.title
        state = "converged" if self.converged else "NOT converged"
        G = self.G
        tips = ("no crack tips" if len(G) == 0 else f"G at {len(G)} tip{'s' * (len(G) > 1)} "
                + ", ".join(f"{g:.4e}" for g in G[:4]) + (", ..." if len(G) > 4 else ""))
        size = "" if self.mesh is None else f", {self.unknowns} unknowns"
        return (f"<Result of {title!r}: {self.method}, {state} after {self.iterations} iterations on {self.ranks} "
                f"rank{'s' * (self.ranks != 1)}{size}; energy {self.energy:.10e}; {tips}"
                f"{'' if self.path is None else f'; file {self.path}'}>")

    @property
    def blocks(self) -> tuple[BlockSpec, ...]:
        """The structure's blocks (:func:`ddsolve.mesh.mesh.blocks`): u⁻, u⁺ and, with two layers, v⁻, v⁺."""
        return blocks(self.scene.geometry.layers)

    @property
    def unknowns(self) -> int:
        """Displacement unknowns of the blocks: two per node of each block's half (needs the mesh)."""
        return 2 * sum(len(self.mesh.half(spec.side).points) for spec in self.blocks)

    @property
    def energy(self) -> float:
        """The potential energy Π = ½ a(u, u) − L(u) of the discrete solution, prescribed values included; with a
        thermal load the mechanical energy ½ ∫ (ε − ε₀):D:(ε − ε₀) less the work of the tractions."""
        return float(self.attrs.get("energy", np.nan))

    @property
    def error_estimate(self) -> float:
        """The estimated relative discretization error in the energy norm (ZZ recovery plus contact)."""
        return float(self.attrs.get("error_estimate", np.nan))

    @property
    def G(self) -> np.ndarray:
        """``(tips,)``: the energy release rate at every crack tip (see :attr:`tips`)."""
        return self.fracture.G if self.fracture is not None else np.zeros(0)

    @property
    def tips(self) -> np.ndarray:
        """``(tips, 2)``: the crack tips, in the order of :attr:`G`."""
        return self.fracture.points if self.fracture is not None else np.zeros((0, 2))

    @property
    def contact_zones(self) -> np.ndarray:
        """``(zones, 2)``: where the crack faces touch, as arc length along Σ from its first node (none
        without non-penetration: see :attr:`Fracture.overlaps`)."""
        return self.fracture.zones if self.fracture is not None else np.zeros((0, 2))

    @classmethod
    def from_blocks(cls, scene: scenes.Scene, method: str, mesh: Mesh, fields: list[np.ndarray], interface, lam: np.ndarray,
                    **record) -> "Result":
        """The one way a run makes its result: the blocks' nodal displacements ``fields`` (in the order of
        ``interface.blocks``, Σ nodes in their (tangent, normal) frames) and the multipliers ``lam`` of ``interface``,
        turned into (x, y) values on ``mesh``; ``record``: the result's other fields."""
        sigma = mesh.sigma
        frames = sigma.frames[sigma.multiplier_nodes]
        solution = {spec.name: assembly.to_global(u, assembly.trace_nodes(mesh.half(spec.side), sigma), frames)
                    for spec, u in zip(interface.blocks, fields)}
        return cls(scene=scene, method=method, mesh=mesh, solution=solution,
                   multipliers=interface.split(lam, frames), **record)

    def not_finite(self) -> list[str]:
        """What of this result is not a finite number: its energy, G at a tip, a displacement or multiplier field
        (what it holds: rank 0 of a run whose ranks wrote the result has no displacements)."""
        fields = {f"the displacement of {name}": u for name, u in self.solution.items()}
        fields |= {f"the multipliers {name}": values for name, values in self.multipliers.items()}
        fields |= {"the energy": np.array([self.energy]) if "energy" in self.attrs else np.zeros(0), "G": self.G}
        return [what for what, values in fields.items() if not np.all(np.isfinite(values))]

    def claim(self) -> str:
        """Withdraw ``converged`` from a result that is not finite (:meth:`not_finite`): every run's last step
        before its result is written, so that no file says converged = true over NaN or inf.  Returns the
        message set ("" when the result is finite)."""
        bad = self.not_finite()
        if not bad:
            return ""
        self.converged = False
        self.message = (f"{self.method}: not converged: {', '.join(bad)} {'is' if len(bad) == 1 else 'are'} not "
                        "finite (NaN or inf): the problem's values are beyond double precision")
        return self.message

    @cached_property
    def on_sigma(self) -> OnSigma:
        """What the Σ post-processing (G, contact zones, the opening) needs of this result."""
        if self.held is not None:
            return self.held
        return OnSigma(self.mesh.sigma, self.multipliers,
                       {name: u[self.half(name).sigma] for name, u in self.solution.items()},
                       max(np.abs(u).max(initial=0.0) for u in self.solution.values()))

    @property
    def lower(self) -> HalfMesh:
        return self.mesh.lower

    @property
    def upper(self) -> HalfMesh:
        return self.mesh.upper

    def half(self, block: str) -> HalfMesh:
        return self.lower if block.endswith("minus") else self.upper

    @property
    def multiplier_nodes(self) -> np.ndarray:
        """Positions along Σ of the k nodes that carry multipliers."""
        return self.mesh.sigma.multiplier_nodes

    def interface_nodes(self, block: str) -> np.ndarray:
        """The block's mesh nodes at the k multiplier nodes."""
        return self.half(block).sigma[self.multiplier_nodes]

    @property
    def crack(self) -> np.ndarray:
        """``(k,)``: which multiplier nodes are crack nodes."""
        return self.mesh.sigma.crack[self.multiplier_nodes]

    @property
    def interface_points(self) -> np.ndarray:
        return self.mesh.sigma.points[self.multiplier_nodes]

    @property
    def normals(self) -> np.ndarray:
        return self.mesh.sigma.normals[self.multiplier_nodes]

    @property
    def interface_x(self) -> np.ndarray:
        return self.interface_points[:, 0]


@dataclass(frozen=True)
class OnSigma:
    """Σ-sized data of a result: Σ, the multipliers over its k multiplier nodes, every block's nodal
    displacement (x, y) at the Σ nodes ``(s, 2)``, and the largest nodal |u| of the blocks.  A run
    that writes its result from the ranks holds only this (and its own blocks) on rank 0."""

    sigma: SigmaLine
    multipliers: dict[str, np.ndarray]
    traces: dict[str, np.ndarray]
    largest: float

    @property
    def gap(self) -> np.ndarray:
        """``(k, 2)``: u⁻ − u⁺ (layer 1) at the multiplier nodes."""
        nodes = self.sigma.multiplier_nodes
        return self.traces["u_minus"][nodes] - self.traces["u_plus"][nodes]

    @property
    def opening(self) -> np.ndarray:
        """``(k,)``: [u]·ν = (u⁺ − u⁻)·ν of layer 1 at the multiplier nodes (negative: overlap)."""
        return -np.einsum("kd,kd->k", self.gap, self.sigma.normals[self.sigma.multiplier_nodes])


#: Fewer Σ edges than this within the inner radius: G is printed with a note to refine near the tip.
FEW_ELEMENTS = 2.0
#: G_I + G_II further than this from G (relative): the split is printed with a warning.
SPLIT_DRIFT = 0.05
#: G at most this fraction of the largest |G| of the scene's tips is no release rate: zero up to rounding and
#: the discretization error of a closed tip.  Such a tip has no mode mix (ψ NaN) and no split drift.
RELEASE = 1e-6
#: What the summary says of ψ at a tip that is no release rate.
NO_PHASE = "ψ undefined: G ≈ 0"


@dataclass
class Fracture:
    """G at every tip and where the crack faces touch.

    Tips: ``points``, ``directions`` (unit, away from the crack), ``crack`` (index), ``inner`` and
    ``outer`` radii, ``spacing`` (the mean length of the Σ edges at the tip), ``G`` and its part
    ``contact`` from the forces on the crack faces: the contact pressure on the turning normals (zero on a
    straight Σ) and the friction (:func:`ddsolve.post.fracture.friction_terms`); its split into opening ``G_I`` and
    sliding ``G_II``, the phase angle ``phase`` ψ = atan(√(G_II/G_I)) in degrees, signed as K_II/K_I
    (NaN where G is no release rate, :meth:`released`: a tip at G ≈ 0 has no mode mix), and ``symmetric``:
    split by the mirror symmetry about Σ (else by virtual crack closure; see
    :func:`ddsolve.post.fracture.mode_split`).  Results written before the split have NaN there.
    ``toughness``: G_c at every tip, and ``critical_factor``: the load factor at which the tip starts to
    grow (inf: never), both NaN without a toughness or in files written before them
    (:mod:`ddsolve.post.toughness`).
    Contact zones: ``zones`` ``(z, 2)`` as arc length along Σ from its first node (first and last
    touching node), ``zone_crack`` the crack of each; with non-penetration only.  Without it the faces do
    not touch but may overlap: ``overlaps`` ``(o, 2)`` and ``overlap_crack`` the same for the runs of
    overlapping nodes (empty with non-penetration, and in files written before them).
    An interface crack between different materials (:mod:`ddsolve.post.interface_crack`): ``epsilon`` ε per
    tip (material 1 on the side of the tip frame's y; 0 where each layer has one law on both sides of Σ),
    ``K`` ``(t, 2)`` the complex stress intensity (K₁, K₂) and ψ = arg(K l^{iε}) at ``reference_length`` l,
    G_I = G cos²ψ, G_II = G sin²ψ; K is NaN where the classical split applies, and in older files.
    With several interfaces, ``interface`` numbers each tip's interface (1 the lowest; None with one interface),
    the cracks are counted interface by interface, bottom to top, and ``crack_interface`` holds each crack's
    (:func:`ddsolve.post.fracture.of_interfaces`).
    """

    points: np.ndarray
    directions: np.ndarray
    crack: np.ndarray
    inner: np.ndarray
    outer: np.ndarray
    spacing: np.ndarray
    G: np.ndarray
    contact: np.ndarray
    zones: np.ndarray
    zone_crack: np.ndarray
    G_I: np.ndarray | None = None
    G_II: np.ndarray | None = None
    phase: np.ndarray | None = None
    symmetric: np.ndarray | None = None
    toughness: np.ndarray | None = None
    critical_factor: np.ndarray | None = None
    overlaps: np.ndarray | None = None
    overlap_crack: np.ndarray | None = None
    noise: np.ndarray | None = None
    epsilon: np.ndarray | None = None
    K: np.ndarray | None = None
    reference_length: float = 1.0
    interface: np.ndarray | None = None
    crack_interface: np.ndarray | None = None

    def __post_init__(self) -> None:
        count = len(self.G)
        if self.K is None:
            self.K = np.full((count, 2), np.nan)
        for name in ("G_I", "G_II", "phase", "toughness", "critical_factor", "noise", "epsilon"):
            if getattr(self, name) is None:
                setattr(self, name, np.full(count, np.nan))
        if self.symmetric is None:
            self.symmetric = np.zeros(count, dtype=bool)
        if self.overlaps is None:
            self.overlaps = np.zeros((0, 2))
        if self.overlap_crack is None:
            self.overlap_crack = np.zeros(0, dtype=np.int64)

    def __repr__(self) -> str:
        return (f"<Fracture: {len(self.G)} tips, G {np.array2string(np.asarray(self.G), precision=4, threshold=8)}, "
                f"{len(self.zones)} contact zones, {len(self.overlaps)} overlaps>")

    def released(self) -> np.ndarray:
        """Per tip whether G is a release rate: above RELEASE × the largest |G| of the tips."""
        G = np.asarray(self.G, dtype=float)
        return G > RELEASE * np.abs(G).max(initial=0.0)

    def within_noise(self) -> np.ndarray:
        """Per tip whether G is at most its noise level (``noise``, the discretization error:
        :func:`ddsolve.post.fracture.release_and_noise`; NaN in older files: never)."""
        return np.asarray(self.G, dtype=float) <= np.nan_to_num(np.asarray(self.noise, dtype=float), nan=-np.inf)

    def reported(self) -> dict[str, np.ndarray]:
        """G, G_I and G_II as reported: G is 0 where it is no release rate or within its noise; G_I and G_II are
        clamped at 0 (a negative part is the split's error), 0 where G is, and where the split is resolved
        (G_I + G_II as computed within SPLIT_DRIFT of G) scaled to sum to G.  The fields keep what was computed
        (G the exact derivative of the discrete energy; G, G_I, G_II quadratics in a load factor)."""
        zero = ~self.released() | self.within_noise()
        G = np.where(zero, 0.0, np.asarray(self.G, dtype=float))
        G_I, G_II = np.maximum(self.G_I, 0.0), np.maximum(self.G_II, 0.0)
        total = G_I + G_II
        resolved = ~zero & (np.abs(self.split_drift()) <= SPLIT_DRIFT) & (total > 0)
        scale = np.where(resolved, G / np.where(total > 0, total, 1.0), np.where(zero, 0.0, 1.0))
        return {"G": G, "G_I": np.where(np.isnan(self.G_I), np.nan, G_I * scale),
                "G_II": np.where(np.isnan(self.G_II), np.nan, G_II * scale)}

    def modes(self) -> list[str]:
        """Per tip: «(G_I ..., G_II ..., ψ = ...°)» (NO_PHASE where ψ is NaN), with «by crack closure» where
        not split by symmetry, the reference length, ε and K of an interface crack, and a warning where
        G_I + G_II is more than SPLIT_DRIFT off G (:meth:`split_drift`); empty where there is no split (a result written before it)."""
        def warning(drift: float) -> str:
            return (f"; G_I + G_II is {drift:+.0%} off G: the split is not resolved, refine near this tip"
                    if abs(drift) > SPLIT_DRIFT else "")

        def method(by_symmetry: bool, epsilon: float, K: np.ndarray) -> str:
            if np.all(np.isfinite(K)):
                return (f" at l = {self.reference_length:g}, ε = {epsilon:.4f}, K = ({K[0]:.4e}, {K[1]:.4e}) "
                        "by the interaction integral")
            return "" if by_symmetry else ", by crack closure"

        shown = self.reported()
        phase = np.where(self.within_noise(), np.nan, self.phase)
        return ["" if np.isnan(g1) else
                f"(G_I {g1:.3e}, G_II {g2:.3e}, {f'ψ = {psi:.1f}°' if np.isfinite(psi) else NO_PHASE}"
                f"{method(by_symmetry, epsilon, K)}{warning(drift)})"
                for g1, g2, psi, by_symmetry, epsilon, K, drift in zip(
                    shown["G_I"], shown["G_II"], phase, self.symmetric, self.epsilon, self.K, self.split_drift())]

    def split_drift(self) -> np.ndarray:
        """Per tip (G_I + G_II)/G − 1 of the split as computed, where G is a release rate (:meth:`released`);
        0 elsewhere."""
        G = np.asarray(self.G, dtype=float)
        released = self.released() & np.isfinite(self.G_I) & np.isfinite(self.G_II)
        return np.where(released, (np.asarray(self.G_I) + np.asarray(self.G_II)) / np.where(released, G, 1.0) - 1.0,
                        0.0)

    def growth(self) -> list[str]:
        """Per tip: «G/G_c = ..., grows at λ = ...» (the critical load factor; «does not grow at any λ» where
        it is inf); each part left out where it is NaN: empty where no toughness is given."""
        def parts(g: float, toughness: float, factor: float) -> str:
            ratio = [] if np.isnan(toughness) else [f"G/G_c = {g / toughness:.6g}"]
            grows = [] if np.isnan(factor) else [f"grows at λ = {factor:.6g}" if np.isfinite(factor) else
                                                 "does not grow at any λ"]
            return ", ".join(ratio + grows)

        return [parts(*values) for values in zip(self.G, self.toughness, self.critical_factor)]

    def quoted(self, G: float, noise: float) -> str:
        """G as printed: the value (± its noise level where known), or 0 where within the noise."""
        if not np.isfinite(noise):
            return f"{G:.6e}"
        if G <= noise:
            return f"0 (G ≈ 0: computed {G:.3e}, within the discretization noise {noise:.2g})"
        return f"{G:.6e} (± {noise:.2g})"

    def lines(self) -> list[str]:
        """One line per tip and one for the contact zones (without non-penetration: where the faces overlap),
        as printed after a solve."""
        lines = []
        for (x, y), c, g, n, a, b, h, modes, growth in zip(self.points, self.crack, self.G, self.noise, self.inner,
                                                            self.outer, self.spacing, self.modes(), self.growth()):
            note = f"; only {a / h:.1f} elements within the inner radius: refine near this tip" \
                if a < FEW_ELEMENTS * h else ""
            lines.append(f"G at tip ({x:.6g}, {y:.6g}) of crack {c}{self.on_interface(c)}: {self.quoted(g, n)}"
                         f"{' ' * bool(modes)}{modes}"
                         f"{'; ' * bool(growth)}{growth}   (θ radii {a:.4g}, {b:.4g}{note})")
        for title, zones, cracks in (("crack faces in contact (arc length along Σ): ", self.zones, self.zone_crack),
                                     ("crack faces overlap (no non-penetration condition; arc length along Σ): ",
                                      self.overlaps, self.overlap_crack)):
            if np.size(cracks):
                lines.append(title + ", ".join(
                    f"[{a:.4g}, {b:.4g}] on crack {c}{self.on_interface(c)}" for (a, b), c in zip(zones, cracks)))
        return lines

    def on_interface(self, crack: int) -> str:
        """« on interface i» after crack ``crack`` with several interfaces, else nothing."""
        return "" if self.crack_interface is None else f" on interface {int(self.crack_interface[crack])}"
