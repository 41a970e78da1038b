"""Quasi-static growth of the cracks along Σ by Griffith's criterion (``ddsolve grow``).

A control factor λ multiplies every mechanical load of the scene (:meth:`ddsolve.problem.scene.Scene.scaled`:
tractions, pressures and prescribed displacements; a temperature change stays as given).  It rises in
``steps`` equal steps to ``limit``, with the initiation factor (the smallest critical factor of the
tips, :func:`ddsolve.post.toughness.critical_factor`) inserted as a step of its own.  At every step each
tip with G ≥ G_c (the scene's ``[fracture]`` toughness, mode-dependent if it says so) advances along Σ
until G = G_c again: a root solve in the tip's position, all growing tips at once (one solve per
iteration), bracketed by doubling the advance and closed by regula falsi (Illinois), to
``|G/G_c − 1| ≤ tolerance``.  Where G rises as the tip advances at a fixed control the growth is
unstable (a snap-through under load control, a jump under displacement control): the step says so
and the tip jumps to where G falls back to G_c (crack arrest), or to what stops it.  A tip stops for
good one Σ edge before a clamped Σ node or Σ's end and the others grow on (the run ends when every tip
has stopped); two tips that meet merge their cracks (with one toughness per crack the run ends there
instead).  Under displacement
control the stable branch is thereby followed step by step.

The contact problem is positively homogeneous: without a temperature change or a Tresca bound on the faces'
friction (:attr:`~ddsolve.problem.scene.Scene.proportional`) the fields at λ are λ times those at 1 and G is λ²G(1), so one solve per crack configuration serves every control (nothing
is solved before initiation).  The mesh is made once (the scene's mesh settings); each configuration
moves the nearest Σ vertex onto each new tip (:func:`ddsolve.mesh.cracks.with_cracks`), so the mesh
follows the tips without re-meshing.

The control is a load factor when the scene has loads, a displacement factor when it prescribes
non-zero displacements (not both).  ``load`` and ``displacement`` of a step are the control and its work
conjugate: under load control the displacement Δ = ∫ t₁·u ds over the loaded boundaries (t₁ the
scene's tractions at λ = 1), under displacement control the load F = Σ R·ū₁ over the displaced
boundaries (R the reactions, ū₁ the scene's constant prescribed displacements), so that the work done
is ∫ load d(displacement) either way.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Iterable, Mapping

import numpy as np

from ddsolve.errors import DDSolveError, SceneError, UsageError
from ddsolve.fem import assembly, supports
from ddsolve.mesh import cracks as crack_mesh
from ddsolve.mesh.mesh import Mesh, blocks
from ddsolve.parallel import distribution
from ddsolve.parallel.exchange import collective
from ddsolve.post import toughness
from ddsolve.problem import expressions
from ddsolve.problem.scene import LAYERS, Load, Scene
from ddsolve.solvers.growth_files import Outputs

#: The most root-solve iterations of one step, and of rounds of steps at one control (growth of one tip
#: changing the G of another).
MAX_ITERATIONS = 60
MAX_ROUNDS = 10
#: A bracket narrower than this (in Σ edges at the tip) ends the root solve on its side below G_c.
SMALLEST_MOVE = 1e-6
#: The first trial advance of a growing tip, in Σ edges at the tip.
FIRST_ADVANCE = 2.0
#: The most control steps of a run (as sweeps have ``MAX_RUNS``): each is a record, a line and a root solve.
MAX_STEPS = 1000
#: The most pictures of the deformed structure (each step drawn is solved again).
MAX_PICTURES = 100
#: The smallest ``tolerance`` on |G/G_c − 1|: G itself is not computed closer.
SMALLEST_TOLERANCE = 1e-8
#: Without a limit the control rises to this multiple of the initiation factor.
DEFAULT_MULTIPLE = 2.0


@dataclass
class State:
    """One crack configuration at one control: what a step records (on every rank)."""

    cracks: tuple[tuple[float, float], ...]
    control: float
    tips: np.ndarray  # arc length of every tip along Σ
    heading: np.ndarray  # +1: the tip grows towards larger arc length, −1 towards smaller
    spacing: np.ndarray  # Σ edge length at each tip
    G: np.ndarray
    G_I: np.ndarray
    G_II: np.ndarray
    G_c: np.ndarray
    energy: float
    load: float
    displacement: float
    #: every controlled boundary (``LAYER.NAME``): its force (x, y; the load, or the reaction where the
    #: displacement is prescribed) and its mean displacement (x, y)
    boundaries: dict[str, np.ndarray] = field(default_factory=dict)
    #: a damaging bond's run (:mod:`ddsolve.solvers.bond_growth`): the damage at every Σ node and the length of Σ
    #: where 0 < d < 1
    damage: np.ndarray | None = None
    process_zone: float = float("nan")

    @property
    def ratio(self) -> np.ndarray:
        """G/G_c at every tip."""
        return self.G / self.G_c


@dataclass
class Step:
    """A recorded step: the state, what happened, and the solves it took."""

    state: State
    unstable: bool = False
    events: list[str] = field(default_factory=list)
    solves: int = 0
    bond_solves: int = 0  # a damaging bond's run: the linear problems on Σ of its nonlinear one (Newton's steps)


def control_kind(scene: Scene) -> str:
    """``load`` or ``displacement``: which mechanical action the control factor scales."""
    moving = [d.key for d in scene.displacements.values()
              if any(not (part.constant and float(part(0.0, 0.0)) == 0.0) for part in d.parts.values())]
    if scene.loads and moving:
        raise SceneError(f"grow: the scene has loads ({next(iter(scene.loads.values())).key}) and non-zero "
                         f"prescribed displacements ({moving[0]}); the control scales one kind: keep one")
    if not scene.loads and not moving:
        raise SceneError("grow: the scene has no load and no non-zero prescribed displacement to scale")
    if moving:
        for d in scene.displacements.values():
            if d.normal is not None and d.key in moving:
                raise SceneError(f"grow: {d.key}.normal: displacement control takes x and y components")
            for name, part in d.parts.items():
                if not part.constant:
                    raise SceneError(f"grow: {d.key}.{name} varies along the boundary; displacement control needs "
                                     "constant prescribed displacements (their work conjugate is R·ū)")
    return "displacement" if moving else "load"


def _parts(mesh: Mesh, layer: str, name: str):
    """(block name, half, edges) of the boundary ``name`` of ``layer`` on every block that has it."""
    for spec in blocks(len(LAYERS)):  # the blocks of ``layer`` are the same in any structure that has it
        half = mesh.half(spec.side)
        if spec.layer == layer and name in half.boundaries:
            yield spec.name, half, half.edges(name)


def conjugate(scene: Scene, kind: str, mesh: Mesh, solution: dict[str, np.ndarray],
              forces: dict[str, dict[str, np.ndarray]]) -> float:
    """The control's work conjugate for a solution (``scene`` unscaled; see the module's docstring)."""
    if kind == "load":
        return sum(float(assembly.load_vector(half, load) @ solution[block].ravel())
                   for (layer, name), load in scene.loads.items() for block, half, _ in _parts(mesh, layer, name))
    work = 0.0
    for (layer, name), prescribed in scene.displacements.items():
        reaction = forces.get(layer, {}).get(name)
        if reaction is None or prescribed.normal is not None:  # a zero normal component does no work
            continue
        values = [0.0 if part is None else float(part(0.0, 0.0)) for part in (prescribed.x, prescribed.y)]
        work += float(np.dot(reaction, values))
    return work


def controlled(scene: Scene, kind: str) -> list[tuple[str, str]]:
    """The boundaries the control acts on: (layer, name) of every load, or of every non-zero prescribed
    displacement."""
    if kind == "load":
        return list(scene.loads)
    return [key for key, d in scene.displacements.items()
            if any(part is not None and float(part(0.0, 0.0)) != 0.0 for part in (d.x, d.y))]


def boundary_values(scene: Scene, kind: str, mesh: Mesh, solution: dict[str, np.ndarray],
                    forces: dict[str, dict[str, np.ndarray]], control: float) -> dict[str, np.ndarray]:
    """``LAYER.NAME`` -> (force x, force y, mean displacement x, mean displacement y) at every controlled
    boundary of a solution at ``control``: the load's resultant, or the reaction of a prescribed
    displacement, and ∫u ds over the boundary's length."""
    unit = Load("unit", x=expressions.parse("1"))
    out = {}
    for layer, name in controlled(scene, kind):
        force, moved, length = np.zeros(2), np.zeros(2), 0.0
        for block, half, edges in _parts(mesh, layer, name):
            weights = assembly.boundary_load(half.points, edges, unit).reshape(-1, 2)[:, 0]  # ∫φ ds per node
            moved += weights @ solution[block]
            length += float(weights.sum())
            if kind == "load":
                force += control * assembly.boundary_load(half.points, edges, scene.loads[layer, name]).reshape(-1, 2).sum(axis=0)
        if kind == "displacement":
            force = np.asarray(forces.get(layer, {}).get(name, np.full(2, np.nan)), dtype=np.float64)
        out[f"{layer}.{name}"] = np.concatenate([force, moved / length if length > 0 else np.full(2, np.nan)])
    return out


class Growth:
    """The crack configurations of one scene on one mesh, solved on ``comm`` (every rank)."""

    def __init__(self, scene: Scene, comm):
        self.scene, self.comm = scene, comm
        self.kind = collective(comm, lambda: control_kind(scene))
        if not toughness.given(scene):
            error = SceneError("grow: the scene has no toughness: give [fracture] toughness = G_c (or a law)")
            error.collective = True
            raise error
        if scene.mesh.target_error is not None:
            error = SceneError("grow: mesh.target_error: growth moves the tips on one mesh; give mesh.size "
                               "(and mesh.degree) instead")
            error.collective = True
            raise error
        self.proportional = scene.proportional  # one solve per configuration, scaled to the control
        self.base = distribution.build_mesh(scene, comm)
        self.length = float(self.base.sigma.arclength[-1])
        self.stops = collective(comm, lambda: stops(scene, self.base))
        self.cache: dict[tuple, State] = {}
        self.solves = 0
        self.stopped: list[tuple[float, float]] = []  # (arc length, heading): tips before a support or Σ's end

    # --- one configuration --------------------------------------------------------------------------
    def mesh_for(self, cracks) -> Mesh:
        return crack_mesh.with_cracks(self.base, cracks)

    def state(self, cracks: tuple, control: float) -> State:
        """The state of ``cracks`` at ``control`` (one solve per configuration without a temperature
        change, scaled to the control; else a solve at the control)."""
        key = (cracks, 1.0 if self.proportional else control)
        if key not in self.cache:
            self.cache[key] = self.solve(cracks, key[1])
        unit = self.cache[key]
        if not self.proportional:
            return unit
        factor = control / unit.control
        return replace(unit, control=control, G=unit.G * factor ** 2, G_I=unit.G_I * factor ** 2,
                       G_II=unit.G_II * factor ** 2, energy=unit.energy * factor ** 2, load=unit.load * factor,
                       displacement=unit.displacement * factor,
                       boundaries={key: values * factor for key, values in unit.boundaries.items()})

    def result_of(self, records: list[Step], index: int):
        """The whole result of the recorded step ``records[index]`` solved again (rank 0; None elsewhere)."""
        state = records[index].state
        return self.result(self.mesh_for(state.cracks), state.control)

    def result(self, mesh: Mesh, control: float):
        """The whole result on ``mesh`` (from :meth:`mesh_for`) at ``control`` (rank 0; None elsewhere)."""
        from ddsolve.solvers import driver

        result = driver.solve_decomposed(self.scene.scaled(control), self.comm, None, progress=lambda line: None, mesh=mesh)
        self.solves += 1
        return result

    def solve(self, cracks: tuple, control: float) -> State:
        """A solve of ``cracks`` at ``control``, its numbers on every rank."""
        mesh = self.mesh_for(cracks)
        result = self.result(mesh, control)
        state = collective(self.comm, lambda: self.numbers(mesh, cracks, control, result), root_only=True)
        return self.comm.bcast(state, root=0)

    def numbers(self, mesh: Mesh, cracks: tuple, control: float, result) -> State:
        """The state from a result (rank 0)."""
        if not result.converged:
            raise DDSolveError(f"grow: the solve with cracks {describe(cracks)} did not converge: {result.message}")
        fracture = result.fracture
        arc = mesh.sigma.arclength
        nearest = np.argmin(np.linalg.norm(mesh.sigma.points[None, :, :] - fracture.points[:, None, :], axis=2),
                            axis=1) if len(fracture.G) else np.zeros(0, dtype=np.int64)
        tangent = np.gradient(mesh.sigma.points, arc, axis=0)[nearest] if len(nearest) else np.zeros((0, 2))
        work = conjugate(self.scene, self.kind, mesh, result.solution, result.reactions)
        load, displacement = (control, work) if self.kind == "load" else (work, control)
        return State(cracks=cracks, control=control, tips=arc[nearest],
                     heading=np.sign(np.einsum("ij,ij->i", fracture.directions, tangent)),
                     spacing=np.asarray(fracture.spacing), G=np.asarray(fracture.G), G_I=np.asarray(fracture.G_I),
                     G_II=np.asarray(fracture.G_II), G_c=np.asarray(fracture.toughness),
                     energy=float(result.attrs["energy"]), load=load, displacement=displacement,
                     boundaries=boundary_values(self.scene, self.kind, mesh, result.solution, result.reactions, control))

    # --- growth -------------------------------------------------------------------------------------
    def initiation(self, cracks: tuple) -> float:
        """The smallest control at which a tip of ``cracks`` starts to grow (inf if none does)."""
        if self.proportional:
            unit = self.state(cracks, 1.0)
            factors = toughness.critical_factor(unit.G, unit.G_c)
        else:
            from ddsolve.solvers import critical

            factors = critical.factors(self.scene, self.comm, self.mesh_for(cracks))
        return float(np.min(factors, initial=math.inf))

    def control_range(self) -> tuple[float, float, str]:
        """The control factors at which the scene, scaled, passes :func:`ddsolve.fem.assembly.check_range`:
        the displacements the scaled loads or prescribed displacements drive
        (:func:`ddsolve.fem.assembly.driven_displacements`, λ times those at 1) within DISPLACEMENT_RANGE and
        their energies within ENERGY_RANGE (a temperature change, not scaled, keeps the structure's
        displacements up at small factors); and the key that drives the largest of them."""
        size = float(np.ptp(np.vstack([half.points for half in self.base.halves]), axis=0).max())
        scaled = {load.key for load in self.scene.loads.values()} | {d.key for d in self.scene.displacements.values()}
        driven, stiffness = [], assembly.modulus(self.scene)
        for layer, region in ((layer, region) for layer in self.scene.layers
                              for region in self.scene.geometry.region_names):
            block_stiffness = float(np.abs(assembly.elasticity(self.scene, layer, region)[0]).max())
            driven += assembly.driven_displacements(self.scene, self.base, (layer, region), size, layer,
                                                    block_stiffness)
        orders = [(order, cause) for order, cause, _ in driven if cause in scaled]
        fixed = max((order for order, cause, _ in driven if cause not in scaled), default=0.0)
        if not orders:
            return 0.0, math.inf, ""
        low = max(assembly.DISPLACEMENT_RANGE[0], math.sqrt(assembly.ENERGY_RANGE[0] / stiffness))
        high = min(assembly.DISPLACEMENT_RANGE[1], math.sqrt(assembly.ENERGY_RANGE[1] / stiffness))
        largest = max(orders)
        return (0.0 if fixed >= low else low / largest[0]), high / largest[0], largest[1]

    def check_limit(self, limit: float, steps: int, option: str) -> None:
        """Refuse a limit whose largest control or first step lies outside :meth:`control_range`."""
        low, high, key = self.control_range()
        if limit > high:
            bad = f"{option} {limit:g}: scales {key} beyond what a double-precision solve represents (factors " \
                  f"up to {high:.3g}): give {option} at most {high:.3g}"
        elif limit / steps < low:
            bad = f"{option} {limit:g} in {steps} steps: the first step {limit / steps:.3g} scales {key} below what " \
                  f"a double-precision solve represents (factors from {low:.3g}): give {option} at least {low * steps:.3g}"
        else:
            return
        error = UsageError(f"grow: {bad}")
        error.collective = True
        raise error

    def limit_of(self, state: State, tip: int) -> tuple[float, str]:
        """How far tip ``tip`` may advance, and what is there: one Σ edge before a support or Σ's end, or
        up to another crack's tip (where the two merge)."""
        position, heading, edge = state.tips[tip], state.heading[tip], state.spacing[tip]
        ahead = [(abs(s - position) - edge, f"{what} at arc length {s:.6g}") for s, what in self.stops
                 if (s - position) * heading > 0]
        ahead += [(abs(s - position), f"the tip at arc length {s:.6g}") for s in np.delete(state.tips, tip)
                  if (s - position) * heading > 0]
        room, what = min(ahead)
        return max(room, 0.0), what

    def has_stopped(self, state: State, tip: int) -> bool:
        """Whether tip ``tip`` of ``state`` is one that reached a support or Σ's end (it grows no further)."""
        return any(abs(state.tips[tip] - position) <= 0.25 * state.spacing[tip] and state.heading[tip] == heading
                   for position, heading in self.stopped)

    def advanced(self, cracks: tuple, state: State, moves: dict[int, float]) -> tuple:
        """``cracks`` with tip i moved by ``moves[i]`` along its heading; cracks that meet are merged."""
        ends = [list(piece) for piece in cracks]
        for tip, distance in moves.items():
            position = state.tips[tip]
            piece, end = min(((i, j) for i in range(len(ends)) for j in range(2)),
                             key=lambda ij: abs(ends[ij[0]][ij[1]] - position))
            ends[piece][end] = position + state.heading[tip] * distance
        ends.sort()
        merged: list[list[float]] = []
        for a, b in ends:  # a glued piece shorter than its Σ edges is no piece: the cracks meet
            if merged and a - merged[-1][1] < max(self.edge_at(a), self.edge_at(merged[-1][1])):
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        return tuple((float(a), float(b)) for a, b in merged)

    def edge_at(self, s: float) -> float:
        """The length of the Σ edge (corner to corner) of the mesh that holds arc length ``s``."""
        corners = self.base.sigma.arclength[self.base.sigma.corner]
        right = int(np.clip(np.searchsorted(corners, s), 1, len(corners) - 1))
        return float(corners[right] - corners[right - 1])

    def at_control(self, cracks: tuple, control: float, tolerance: float, probe: bool = False
                   ) -> tuple[tuple, Step]:
        """Grow every critical tip at ``control`` until G ≤ G_c everywhere (to ``tolerance``).  With
        ``probe`` (the initiation step) a tip at G = G_c is advanced by a trial step: if G rises there the
        growth is unstable and goes on at this control."""
        solves = self.solves
        step = Step(self.state(cracks, control))
        def free(tips: np.ndarray) -> list[int]:
            return [int(i) for i in tips if not self.has_stopped(step.state, i)]

        if probe:
            critical = free(np.flatnonzero(np.abs(step.state.ratio - 1.0) <= tolerance))
            if critical:
                cracks, step = self.advance(cracks, step.state, critical, control, tolerance, step, probe=True)
        for _ in range(MAX_ROUNDS):
            if any(event.startswith("end") for event in step.events):
                break
            growing = free(np.flatnonzero(step.state.ratio - 1.0 > tolerance))
            if not growing:
                break
            cracks, step = self.advance(cracks, step.state, growing, control, tolerance, step)
        tips = range(len(step.state.tips))
        if tips and all(self.has_stopped(step.state, i) for i in tips) and not any(
                event.startswith("end") for event in step.events):
            step.events.append("end: every tip has stopped before a support or the end of Σ")
        step.solves = self.solves - solves
        return cracks, step

    def advance(self, cracks: tuple, start: State, growing: list[int], control: float, tolerance: float,
                step: Step, probe: bool = False) -> tuple[tuple, Step]:
        """The root solve: the growing tips' advances x with G/G_c − 1 = f(x) = 0, bracketed by doubling x
        from two Σ edges, closed by regula falsi (Illinois); all tips at once, one solve per iteration.
        Rank 0 proposes every trial and broadcasts it.  f rising with x (at a fixed control) is unstable
        growth; with ``probe`` a tip whose f does not rise stays where it is."""
        limits = {i: self.limit_of(start, i) for i in growing}
        low = {i: 0.0 for i in growing}
        f_low = {i: float(start.ratio[i] - 1.0) for i in growing}
        bracket: dict[int, tuple[float, float]] = {}  # tip -> (x, f) with f < 0
        trial = {i: min(FIRST_ADVANCE * start.spacing[i], limits[i][0]) for i in growing}
        last = {i: 0 for i in growing}  # the side regula falsi moved last (Illinois halves the other's f)
        settled: dict[int, float] = {}
        halted: list[str] = []  # the tips that reached a support or Σ's end above G_c
        for iteration in range(MAX_ITERATIONS):
            proposal = self.comm.bcast({**trial, **settled} if self.comm.rank == 0 else None, root=0)
            trial_cracks = self.advanced(cracks, start, proposal)
            listed = per_crack_keys(self.scene)
            if len(trial_cracks) < len(cracks) and listed:
                step.events.append(f"end: cracks meet ({describe(trial_cracks)}), and {' and '.join(listed)} "
                                   f"give{'s' if len(listed) == 1 else ''} one value per crack: the merged crack has none")
                return cracks, step
            try:
                state = self.state(trial_cracks, control)
            except SceneError as exc:  # the merged crack frees a part: the run ends with the steps before
                motion = getattr(exc, "free_motion", None)
                if motion is None or len(trial_cracks) >= len(cracks):
                    raise
                step.events.append(f"end: the cracks would meet as {describe(trial_cracks)} and free a part: {motion}; "
                                   "growth stops before they meet")
                return cracks, step
            if len(trial_cracks) < len(cracks):  # two cracks met
                step.state = state
                step.events.append(f"cracks merge: {describe(trial_cracks)}")
                return trial_cracks, step
            values = self.match(start, state, proposal)
            # while bracketing, G rising with the advance at this control is unstable growth
            step.unstable |= any(i not in bracket and values[i] > f_low[i] for i in trial)
            if probe and iteration == 0:
                stable = [i for i in trial if values[i] <= f_low[i]]
                if len(stable) == len(trial):
                    step.state = start
                    return cracks, step
                settled.update({i: 0.0 for i in stable})
                for i in stable:
                    del trial[i]
            self.narrow(start, proposal, values, limits, tolerance, trial, settled, low, f_low, bracket, last, halted)
            if not trial:
                break
        else:
            error = DDSolveError(f"grow: the root solve at control {control:.6g} did not reach |G/G_c − 1| ≤ "
                                 f"{tolerance:g} in {MAX_ITERATIONS} solves")
            error.collective = True
            raise error
        moved = ", ".join(f"tip {start.tips[i]:.6g} → {start.tips[i] + start.heading[i] * x:.6g}"
                          for i, x in settled.items() if x > SMALLEST_MOVE * start.spacing[i])
        if moved:
            step.events.append(("unstable: " if step.unstable else "") + moved)
        step.events.extend(halted)
        step.state = state
        return trial_cracks, step

    def narrow(self, start: State, proposal: dict[int, float], values: dict[int, float], limits: dict,
               tolerance: float, trial: dict[int, float], settled: dict[int, float], low: dict[int, float],
               f_low: dict[int, float], bracket: dict, last: dict[int, int], halted: list[str]) -> None:
        """One iteration of :meth:`advance`'s root solve for every tip on trial, given f = G/G_c − 1 at its
        trial advance (``values``): a tip within ``tolerance`` settles; while bracketing, f > 0 doubles the
        advance (or stops the tip where it can go no further); once bracketed, regula falsi (Illinois)
        proposes the next advance, or the tip settles below G_c where the bracket is narrower than
        SMALLEST_MOVE.  Updates :meth:`advance`'s records of the tips in place."""
        for i in list(trial):
            x, f = proposal[i], values[i]
            if abs(f) <= tolerance:
                settled[i] = x
                del trial[i]
                continue
            if f > 0.0:
                if i not in bracket:  # still bracketing
                    if x >= limits[i][0] * (1.0 - 1e-12):  # above G_c where it cannot go further: it stops
                        settled[i] = x
                        del trial[i]
                        end = float(start.tips[i] + start.heading[i] * x)
                        self.stopped.append((end, float(start.heading[i])))
                        halted.append(f"tip {start.tips[i]:.6g} stops at {end:.6g}: {limits[i][1]} ahead "
                                      f"(G/G_c = {f + 1.0:.4g} there)")
                        continue
                    low[i], f_low[i] = x, f
                    trial[i] = min(2.0 * x, limits[i][0])
                    continue
                low[i], f_low[i] = x, f
                if last[i] > 0:
                    bracket[i] = (bracket[i][0], 0.5 * bracket[i][1])
                last[i] = 1
            else:
                if i in bracket and last[i] < 0:
                    f_low[i] *= 0.5
                bracket[i] = (x, f)
                last[i] = -1
            high, f_high = bracket[i]
            if high - low[i] <= SMALLEST_MOVE * start.spacing[i]:  # G jumps here (a mesh effect): stay below G_c
                settled[i] = high
                del trial[i]
                continue
            trial[i] = low[i] + (high - low[i]) * f_low[i] / (f_low[i] - f_high)

    def match(self, start: State, state: State, moves: dict[int, float]) -> dict[int, float]:
        """G/G_c − 1 at the new position of every moved tip (the tip of ``state`` nearest to it with the
        same heading)."""
        out = {}
        for i, x in moves.items():
            target = start.tips[i] + start.heading[i] * x
            same = np.flatnonzero(state.heading == start.heading[i])
            nearest = same[np.argmin(np.abs(state.tips[same] - target))]
            out[i] = float(state.ratio[nearest] - 1.0)
        return out


def stops(scene: Scene, mesh: Mesh) -> list[tuple[float, str]]:
    """Where growing tips stop (arc length along Σ, what is there): Σ's ends and the ends of every run of
    Σ nodes that are clamped or have a prescribed displacement."""
    sigma = mesh.sigma
    table = supports.sigma_supports(scene, mesh)
    held = np.zeros(len(sigma.points), dtype=bool)
    held[sigma.multiplier_nodes] = table.fixed.reshape(len(table.fixed), -1, 2).any(axis=(0, 2))
    supported = sigma.clamped | held
    arc = sigma.arclength
    return [(float(s), "a support" if supported[np.argmin(np.abs(arc - s))] else "the end of Σ")
            for s in crack_mesh.stops(mesh, held)]


def per_crack_keys(scene: Scene) -> list[str]:
    """The keys of ``scene`` that give one value per crack (a merged crack has none of them)."""
    friction = scene.friction
    return [key for key, listed in (("fracture.toughness", isinstance(scene.fracture.toughness, tuple)),
                                    (friction.key if friction else "", friction is not None
                                     and isinstance(friction.values, tuple))) if listed]


def describe(cracks) -> str:
    return ", ".join(f"({a:.6g}, {b:.6g})" for a, b in cracks) or "none"


def check_controls(limit: float | None, steps: int, tolerance: float, pictures: int) -> None:
    """Raise UsageError for a bad ``--to``, ``--steps``, ``--tolerance`` or ``--pictures`` (every rank checks
    the same values: the error is collective, reported once).  ``limit`` None: a multiple of initiation."""
    def whole(value) -> bool:
        return isinstance(value, numbers.Integral) and not isinstance(value, bool)

    def number(value) -> bool:
        return isinstance(value, numbers.Real) and not isinstance(value, bool)

    path = isinstance(limit, (tuple, list))
    problems = [(path, f"--to {','.join(str(target) for target in limit) if path else limit}: a path of several "
                 "targets unloads a damaging bond (interface.law = \"bilinear\") only; Griffith growth rises to one "
                 "--to"),
                (limit is not None and not path and not (number(limit) and math.isfinite(limit) and limit > 0.0),
                 f"--to {limit}: the control's limit must be a positive number"),
                (not whole(steps) or not 1 <= steps <= MAX_STEPS, f"--steps {steps}: a whole number of steps, at "
                 f"least one and at most {MAX_STEPS:,} (each is a record of the output and a root solve)"),
                (not (number(tolerance) and SMALLEST_TOLERANCE <= tolerance < 1.0), f"--tolerance {tolerance}: "
                 f"between {SMALLEST_TOLERANCE:g} (G is not computed closer) and 1"),
                (not whole(pictures) or not 0 <= pictures <= MAX_PICTURES, f"--pictures {pictures}: a whole number "
                 f"of pictures, 0 to {MAX_PICTURES} (each is a solve again)")]
    for bad, message in problems:
        if bad:
            error = UsageError(f"grow: {message}")
            error.collective = True
            raise error


def default_limit(initiation: float) -> float:
    """The limit without ``--to``: ``DEFAULT_MULTIPLE`` times the initiation factor; a UsageError where there
    is none to multiply."""
    if 0.0 < initiation < math.inf:
        return DEFAULT_MULTIPLE * initiation
    why = ("no tip reaches G_c at any control (G ≤ 0 at every tip)" if initiation == math.inf else
           "the temperature change alone makes a tip grow (initiation at factor 0)" if initiation == 0.0 else
           "the initiation factor is not a number")
    error = UsageError(f"grow: without --to the control rises to {DEFAULT_MULTIPLE:g} × the initiation factor, "
                       f"but {why}: give --to")
    error.collective = True
    raise error


def grow(scene: Scene, comm, limit: float | None, steps: int, tolerance: float = 1e-4,
         progress: Callable[[str], None] = print, output: Path | None = None, pictures: int = 0,
         inputs: Iterable[Path] | Mapping[Path, str] = ()) -> list[Step] | None:
    """Grow the cracks of ``scene`` as the control rises to ``limit`` (None: ``DEFAULT_MULTIPLE`` × the
    initiation factor) in ``steps`` steps (every rank); with ``output`` writes its set of files
    (:class:`ddsolve.solvers.growth_files.Outputs`: the HDF5 file, the CSV and picture of the curves and
    ``pictures`` pictures of the deformed structure at steps spread over the run), checked before any work
    (none may be one of ``inputs``) and replaced together at the end.  Returns the steps on rank 0, None elsewhere."""
    check_controls(limit, steps, tolerance, pictures)
    files = Outputs(Path(output)) if output is not None else None
    if files is not None:
        collective(comm, lambda: files.check(inputs), root_only=True)
    growth = Growth(scene, comm)
    cracks = tuple(tuple(piece) for piece in crack_mesh.intervals(growth.base))
    initiation = growth.initiation(cracks)
    given = limit is not None
    limit = limit if given else default_limit(initiation)
    growth.check_limit(limit, steps, "--to" if given else f"the default limit ({DEFAULT_MULTIPLE:g} × initiation)")
    controls = [limit * k / steps for k in range(1, steps + 1)]
    if initiation < limit:  # a step of its own (one that falls within 1e-9 of it becomes it)
        controls = sorted([c for c in controls if abs(c - initiation) > 1e-9 * limit] + [initiation])
    if comm.rank == 0:
        progress(f"grow: {growth.kind} control to {limit:g}" + ("" if given else f" ({DEFAULT_MULTIPLE:g} × "
                 "initiation)") + f" in {len(controls)} control steps; cracks {describe(cracks)}; initiation at "
                 f"{initiation:.6g}")
    records = [] if initiation == 0.0 else [Step(growth.state(cracks, 0.0))]  # 0: the temperature alone grows it
    for number, control in enumerate(controls, 1):
        before = len(records)
        if control == initiation:  # the state at initiation, before any growth, is a step of its own
            records.append(Step(growth.state(cracks, control), events=["initiation"]))
        cracks, step = growth.at_control(cracks, control, tolerance, probe=control == initiation)
        if control == initiation and step.unstable:
            records[-1].unstable = True
            records[-1].events = ["initiation (unstable)"]
        if control != initiation or step.events:
            records.append(step)
        else:  # a stable initiation: its trial advance's solve counts with it
            records[-1].solves += step.solves
        if comm.rank == 0:
            for record in records[before:]:
                progress(line(number, len(controls), growth.kind, record))
        if any(event.startswith("end") for event in step.events):
            break
    if files is not None:
        files.commit(growth, records, limit, tolerance, pictures)
    return records if comm.rank == 0 else None


def line(number: int, total: int, kind: str, step: Step) -> str:
    state = step.state
    ratios = ", ".join(f"{g:.4e} ({r:.3f} G_c)" for g, r in zip(state.G, state.ratio))
    what = "; ".join(step.events)
    return (f"grow {number}/{total}: {kind} factor {state.control:.6g}, load {state.load:.6e}, displacement "
            f"{state.displacement:.6e}; cracks {describe(state.cracks)}; G {ratios or 'none'}"
            + (f"; {what}" if what else "") + f"; {step.solves} solves")
