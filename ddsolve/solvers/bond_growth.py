"""Growth of a damaging bond (``[interface] law = "bilinear"``) as the control rises: ``ddsolve grow`` on such a scene.

The control (a load or displacement factor, :func:`ddsolve.solvers.grow.control_kind`) rises to ``--to`` in steps of
at most ``--to``/``--steps``; each step is the bond's nonlinear problem on Σ from the damage of the step before
(Newton's method on ``schur``'s interface stiffness, the secant fixed point with the iterative methods:
:mod:`ddsolve.dd.cohesive`), on blocks factored once for the whole run (:func:`ddsolve.solvers.driver.prepare`,
new loads by :func:`~ddsolve.solvers.driver.reload`).  A step that moves a vertex by more than
:data:`DAMAGE_STEP` along the law's softening branch (:func:`ddsolve.dd.cohesive.softening`), or whose solve
fails, is halved (at most :data:`HALVINGS` times), and the step grows back to its size when the damage moves
less than a quarter of that.  The crack is where the damage has reached 1 (with the scene's
cracks); its tip is the last broken vertex.  The run is recorded as a Griffith run is
(:mod:`ddsolve.solvers.growth_files`), with the damage along Σ and the process zone's length per step (the
length of Σ where 0 < d < 1); G is not computed (the bond's traction is not a crack's singular field).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable, Mapping

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
        self.history: dict[float, tuple[np.ndarray, np.ndarray]] = {}  # control -> (damage, pressed) it started from

    def mesh_for(self, cracks) -> Mesh:
        return self.base

    def result(self, mesh: Mesh, control: float, start: tuple[np.ndarray, np.ndarray] | None = None):
        """The result at ``control`` from the damage ``start`` (or the one its step started from; rank 0)."""
        damage, pressed = start if start is not None else self.history[control]
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
        result = self.result(self.base, control, (damage, pressed))

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


def grow(scene, comm, limit: float | None, steps: int, progress: Callable[[str], None] = print,
         output: Path | None = None, pictures: int = 0, inputs: Iterable[Path] | Mapping[Path, str] = ()
         ) -> list[Step] | None:
    """Grow the damaging bond of ``scene`` as the control rises to ``limit`` in steps of at most ``limit/steps``
    (module docstring), with the files of :class:`~ddsolve.solvers.growth_files.Outputs`; the steps on rank 0."""
    check_controls(limit, steps, 1e-4, pictures)
    if limit is None:
        error = UsageError("grow: interface.law = \"bilinear\" has no initiation factor to multiply: give --to")
        error.collective = True
        raise error
    files = Outputs(Path(output)) if output is not None else None
    if files is not None:
        collective(comm, lambda: files.check(inputs), root_only=True)
    growth = BondGrowth(scene, comm)
    try:
        records = climb(growth, limit, steps, progress)
        if files is not None:
            files.commit(growth, records, limit, 0.0, pictures)
    finally:
        growth.setup.destroy()
    return records if comm.rank == 0 else None


def climb(growth: BondGrowth, limit: float, steps: int, progress: Callable[[str], None]) -> list[Step]:
    """The steps of a run from the unloaded, undamaged state to ``limit``."""
    k = len(growth.nodes)
    damage, pressed = np.zeros(k), np.zeros(k, dtype=bool)
    state, damage, pressed, solves = growth.step(0.0, damage, pressed)
    growth.history[0.0] = (np.zeros(k), np.zeros(k, dtype=bool))
    records, control, largest = [Step(state, solves=solves[0], bond_solves=solves[1])], 0.0, limit / steps
    size = largest
    while control < limit * (1.0 - 1e-12):
        target = min(control + size, limit)
        try:
            state, new, opening, solves = growth.step(target, damage, pressed)
            moved = float(np.abs(softening(growth.scene.bond, new) - softening(growth.scene.bond, damage)).max(initial=0.0))
        except SolverError as error:  # Newton's method on too long a step
            if size <= largest / 2 ** HALVINGS:
                raise
            state, moved, reason = None, np.inf, str(error)
        if moved > DAMAGE_STEP and size > largest / 2 ** HALVINGS:
            size /= 2.0
            continue
        if state is None:
            raise SolverError(reason)
        events = [event for event, happened in (("damage starts", damage.max(initial=0.0) == 0.0 < new.max()),
                                                ("the crack grows", np.sum(new >= BROKEN) > np.sum(damage >= BROKEN)))
                  if happened]
        growth.history[target] = (damage, pressed)
        records.append(Step(state, events=events, solves=solves[0], bond_solves=solves[1]))
        control, damage, pressed = target, new, opening
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
