"""Growth of a damaging bond (``[interface] law = "bilinear"``) as the control follows a path: ``ddsolve grow``.

The control (a load or displacement factor, :func:`ddsolve.solvers.grow.control_kind`) goes from 0 to each target
of ``--to`` in turn (``--to 0.2`` rises to 0.2; ``--to 0.2,0.05,0.3`` rises to 0.2, unloads to 0.05 and reloads to
0.3) in steps of at most (the largest target)/``--steps``; each step is the bond's nonlinear problem on Σ from the
damage of the step before (Newton's method on ``schur``'s interface stiffness, the secant fixed point with the
iterative methods: :mod:`ddsolve.dd.cohesive`), on blocks factored once for the whole run (:func:`ddsolve.solvers.driver.prepare`,
new loads by :func:`~ddsolve.solvers.driver.reload`).  A step that moves a vertex by more than
:data:`DAMAGE_STEP` along the law's softening branch (:func:`ddsolve.dd.cohesive.softening`), or whose solve
fails, is halved (at most :data:`HALVINGS` times), and the step grows back to its size when the damage moves
less than a quarter of that.  The crack is where the damage has reached 1 (with the scene's
cracks); its tip is the last broken vertex.  The run is recorded as a Griffith run is
(:mod:`ddsolve.solvers.growth_files`), with the damage along Σ and the process zone's length per step (the
length of Σ where 0 < d < 1); G is not computed (the bond's traction is not a crack's singular field).

Unloading keeps the damage (it never heals) and follows the secant: every vertex's traction falls along
k(1 − d) δ, so under displacement control a structure whose bond alone has softened unloads linearly to the
origin; reloading retraces that line to the old peak, after which the damage grows again.
"""
from __future__ import annotations

import math
import numbers
from pathlib import Path
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from ddsolve.dd.cohesive import softening
from ddsolve.dd.interface import BROKEN
from ddsolve.errors import DDSolveError, SolverError, UsageError
from ddsolve.mesh.mesh import Mesh
from ddsolve.parallel import distribution
from ddsolve.parallel.exchange import collective
from ddsolve.solvers import driver
from ddsolve.solvers.grow import State, Step, boundary_values, check_controls, conjugate, control_kind
from ddsolve.solvers.growth_files import Outputs

#: The largest advance of a vertex along the law's softening branch in one step
#: (:func:`ddsolve.dd.cohesive.softening`); a step that moves more, or whose solve fails, is halved.
DAMAGE_STEP = 0.5
#: The most halvings of the step size --to/--steps.
HALVINGS = 12
#: The most targets of a path (``--to T1,T2,...``).
MAX_TARGETS = 100


def open_runs(mesh: Mesh, broken: np.ndarray) -> list[tuple[float, float]]:
    """The cracks as arc-length intervals: runs of Σ nodes that are a crack's or ``broken`` ``(s,)``, each end
    at the last broken node, or at the glued tip node beyond a crack's node."""
    sigma, s = mesh.sigma, mesh.sigma.arclength
    out = []
    for first, last in sigma.pieces(sigma.crack | broken):
        if first > 0 and sigma.tip[first - 1] and not broken[first]:
            first -= 1
        if last + 1 < len(s) and sigma.tip[last + 1] and not broken[last]:
            last += 1
        out.append((float(s[first]), float(s[last])))
    return out


def process_zone(mesh: Mesh, damage: np.ndarray) -> float:
    """The length of Σ where 0 < d < 1 (``damage`` ``(s,)``), each such node counting to the midpoints of its
    neighbours."""
    s = mesh.sigma.arclength
    middles = np.concatenate([[s[0]], 0.5 * (s[1:] + s[:-1]), [s[-1]]])
    softening = (damage > 0.0) & (damage < BROKEN)
    return float(np.sum((middles[1:] - middles[:-1])[softening]))


class BondGrowth:
    """A damaging bond's run on one mesh and one factorization, on ``comm`` (every rank)."""

    def __init__(self, scene, comm):
        self.scene, self.comm = scene, comm
        self.kind = collective(comm, lambda: control_kind(scene))
        self.base = distribution.build_mesh(scene, comm)
        self.setup = driver.prepare(scene, comm, self.base)
        self.nodes = self.base.sigma.multiplier_nodes
        self.solves = 0
        self.starts: list[tuple[np.ndarray, np.ndarray]] = []  # per recorded step: the (damage, pressed) it began at

    def result_of(self, records: list[Step], index: int):
        """The whole result of the recorded step ``records[index]`` solved again from its start (rank 0)."""
        return self.result(records[index].state.control, self.starts[index])

    def result(self, control: float, start: tuple[np.ndarray, np.ndarray]):
        """The result at ``control`` from the damage and pressed rows ``start`` (rank 0)."""
        damage, pressed = start
        scaled = self.scene.scaled(control)
        driver.reload(self.setup, scaled)
        self.setup.interface = self.setup.interface.with_damage(damage, pressed)
        result = driver.solve_decomposed(scaled, self.comm, None, progress=lambda line: None, setup=self.setup)
        self.solves += 1
        return result

    def step(self, control: float, damage: np.ndarray, pressed: np.ndarray
             ) -> tuple[State, np.ndarray, np.ndarray, tuple[int, int]]:
        """The state at ``control`` from ``damage`` and ``pressed``: the state, the new damage and pressed rows, and
        the block solves and linear problems on Σ it took (every rank)."""
        result = self.result(control, (damage, pressed))

        def numbers():
            if not result.converged:
                raise DDSolveError(f"grow: the bond's step at factor {control:.6g} did not converge: {result.message}")
            new = np.asarray(result.multipliers["damage"])
            opening = np.asarray(result.multipliers["pressed"]) > 0.5
            return (self.state(control, result, new), new, opening,
                    (int(result.solves), int(result.attrs.get("bond_solves", 0))))

        return self.comm.bcast(collective(self.comm, numbers, root_only=True), root=0)

    def state(self, control: float, result, damage: np.ndarray) -> State:
        """The recorded state of a step (rank 0)."""
        along = np.zeros(len(self.base.sigma.points))
        along[self.nodes] = damage
        work = conjugate(self.scene, self.kind, self.base, result.solution, result.reactions)
        load, displacement = (control, work) if self.kind == "load" else (work, control)
        empty = np.zeros(0)
        return State(cracks=tuple(open_runs(self.base, along >= BROKEN)), control=control, tips=empty, heading=empty,
                     spacing=empty, G=empty, G_I=empty, G_II=empty, G_c=empty, energy=float(result.attrs["energy"]),
                     load=load, displacement=displacement,
                     boundaries=boundary_values(self.scene, self.kind, self.base, result.solution, result.reactions,
                                                control),
                     damage=along, process_zone=process_zone(self.base, along))


def damaging(scene) -> bool:
    """Whether ``scene`` grows by its bond's damage (here) rather than by Griffith's criterion."""
    return scene.bond is not None and scene.bond.law != "elastic"


def control_path(limit: float | Sequence[float]) -> tuple[float, ...]:
    """The targets of ``--to`` (one number, or several: a path), or a collective UsageError naming what is wrong:
    at most :data:`MAX_TARGETS` finite numbers ≥ 0, the first above 0, none equal to the one before."""
    path = tuple(limit) if isinstance(limit, (tuple, list)) else (limit,)
    numeric = all(isinstance(t, numbers.Real) and not isinstance(t, bool) and math.isfinite(t) for t in path)
    if (not path or len(path) > MAX_TARGETS or not numeric or min(path) < 0.0 or path[0] <= 0.0
            or any(a == b for a, b in zip(path, path[1:]))):
        error = UsageError(f"grow: --to {','.join(str(t) for t in path)}: a path is 1 to {MAX_TARGETS} control "
                           "targets, numbers ≥ 0 (the first above 0), each different from the one before")
        error.collective = True
        raise error
    return tuple(float(t) for t in path)


def grow(scene, comm, limit: float | Sequence[float] | None, steps: int, progress: Callable[[str], None] = print,
         output: Path | None = None, pictures: int = 0, inputs: Iterable[Path] | Mapping[Path, str] = ()
         ) -> list[Step] | None:
    """Grow the damaging bond of ``scene`` as the control follows ``limit`` (a target, or a path of targets) in
    steps of at most (its largest target)/``steps`` (module docstring), with the files of
    :class:`~ddsolve.solvers.growth_files.Outputs`; the steps on rank 0."""
    if limit is None:
        error = UsageError("grow: interface.law = \"bilinear\" has no initiation factor to multiply: give --to")
        error.collective = True
        raise error
    path = control_path(limit)
    check_controls(max(path), steps, 1e-4, pictures)
    files = Outputs(Path(output)) if output is not None else None
    if files is not None:
        collective(comm, lambda: files.check(inputs), root_only=True)
    growth = BondGrowth(scene, comm)
    try:
        records = climb(growth, path, steps, progress)
        if files is not None:
            files.commit(growth, records, path if len(path) > 1 else path[0], 0.0, pictures)
    finally:
        growth.setup.destroy()
    return records if comm.rank == 0 else None


def climb(growth: BondGrowth, path: tuple[float, ...], steps: int, progress: Callable[[str], None]) -> list[Step]:
    """The steps of a run from the unloaded, undamaged state along the targets of ``path``."""
    k = len(growth.nodes)
    damage, pressed = np.zeros(k), np.zeros(k, dtype=bool)
    state, damage, pressed, solves = growth.step(0.0, damage, pressed)
    growth.starts.append((np.zeros(k), np.zeros(k, dtype=bool)))
    records, control, largest = [Step(state, solves=solves[0], bond_solves=solves[1])], 0.0, max(path) / steps
    size = largest
    for number, end in enumerate(path):
        turn = ([f"the control turns {'down' if end < control else 'up'} towards {end:.6g}"] if number else [])
        while abs(end - control) > 1e-12 * max(path):
            target = control + np.sign(end - control) * min(size, abs(end - control))
            try:
                state, new, opening, solves = growth.step(target, damage, pressed)
                moved = float(np.abs(softening(growth.scene.bond, new) - softening(growth.scene.bond, damage)).max(
                    initial=0.0))
            except SolverError as error:  # Newton's method on too long a step
                if size <= largest / 2 ** HALVINGS:
                    raise
                state, moved, reason = None, np.inf, str(error)
            if moved > DAMAGE_STEP and size > largest / 2 ** HALVINGS:
                size /= 2.0
                continue
            if state is None:
                raise SolverError(reason)
            events = turn + [event for event, happened in (
                ("damage starts", damage.max(initial=0.0) == 0.0 < new.max()),
                ("the crack grows", np.sum(new >= BROKEN) > np.sum(damage >= BROKEN))) if happened]
            growth.starts.append((damage, pressed))
            records.append(Step(state, events=events, solves=solves[0], bond_solves=solves[1]))
            control, damage, pressed, turn = target, new, opening, []
            if growth.comm.rank == 0:
                progress(line(len(records) - 1, growth.kind, records[-1]))
            if moved < DAMAGE_STEP / 4:
                size = min(2.0 * size, largest)
    return records


def line(number: int, kind: str, step: Step) -> str:
    state = step.state
    cracks = ", ".join(f"({a:.6g}, {b:.6g})" for a, b in state.cracks) or "none"
    return (f"grow {number}: {kind} factor {state.control:.6g}, load {state.load:.6e}, displacement "
            f"{state.displacement:.6e}; cracks {cracks}; process zone {state.process_zone:.4g}; largest damage "
            f"{state.damage.max(initial=0.0):.6f}" + (f"; {'; '.join(step.events)}" if step.events else "")
            + f"; {step.solves} block solves, {step.bond_solves} on Σ")
