"""A bond on the bonded part of Σ: an elastic layer or a cohesive law, and the damage fixed point of a load step.

``[interface]`` sets the law of the μᵍ rows (the gluing u⁻ − u⁺ of layer 1's two halves; the gluing of the layers'
halves, μ⁻ and μ⁺, stays rigid).  The traction is t = k(1 − d) δ on the jump δ = u⁺ − u⁻ in the local frame:

- ``elastic``: d = 0 for ever (a compliant adhesive layer of stiffness k, in tension and compression alike);
- ``bilinear``: d grows with the effective opening δₑ = √(⟨δₙ⟩² + δₜ²) (the opening's positive part and the
  slide) once it passes δ₀ = σ_c/k, to 1 at δ_f = 2G_c/σ_c (the area under the law is G_c), and never heals:

      d = δ_f (δₘ − δ₀) / (δₘ (δ_f − δ₀)),   δₘ the largest δₑ of the history.

  With ``mode_mix = "benzeggagh-kenane"`` (Camanho–Dávila), B = δₜ²/(δₙ² + δₜ²) sets
  δ₀ = √(δ₀ₙ² + (δ₀ₜ² − δ₀ₙ²) B^η) (δ₀ₙ = σ_c/k, δ₀ₜ = τ_c/k) and G_c(B) = G_Ic + (G_IIc − G_Ic) B^η,
  δ_f = 2 G_c(B)/(k δ₀); without it the law is the same in both modes.  A pressed normal row (δₙ < 0) keeps the
  undamaged k (non-penetration by a penalty), and a broken vertex (d = 1) keeps it as a contact row.

A load step is a nonlinear problem on Σ only.  ``schur`` solves it on rank 0 by Newton's method with the law's
tangent (:func:`response`; :class:`ddsolve.dd.schur.SpringDual`).  The iterative methods solve it by the secant
fixed point (:func:`secant`): solve the linear problem with the springs k(1 − d) of the current damage, update d
from the new jumps (never below the history's), repeat until no vertex's traction changes by more than
:data:`DAMAGE_TOLERANCE` σ_c and no normal row changes from opening to pressed.  Unloading follows the secant
(d is kept).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ddsolve.dd.dual import Outcome
from ddsolve.dd.interface import BROKEN, Interface
from ddsolve.problem.scene import Bond

#: The fixed point has converged when no vertex's traction changes by more than this times the strength (by the
#: change of its damage).
DAMAGE_TOLERANCE = 1e-6
#: At most this many linear solves per load step.
MAX_SECANT = 500


def jumps(interface: Interface, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The slide δₜ and the opening δₙ ``(k,)`` of every vertex from the bond's multipliers ``lam``, δ = c λ
    with the opening positive (μᵍ·ν < 0 pulls the faces together); 0 where a row is broken or absent."""
    compliance = interface.compliance
    out = []
    for component, sign in ((0, 1.0), (1, -1.0)):
        rows = interface.bond_rows(component)
        values = np.zeros(len(interface.weights))
        values[interface.vertex[rows]] = sign * compliance[rows] * lam[rows]
        out.append(values)
    return out[0], out[1]


def law_openings(bond: Bond, slide: np.ndarray, opening: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """δ₀ and δ_f of every vertex at its mode mix (module docstring)."""
    k = bond.stiffness
    if bond.mode_mix is None:
        start = np.full(len(slide), bond.strength / k)
        return start, np.full(len(slide), 2.0 * bond.toughness / bond.strength)
    normal, shear = np.maximum(opening, 0.0) ** 2, slide ** 2
    mix = np.divide(shear, normal + shear, out=np.zeros(len(slide)), where=normal + shear > 0.0) ** bond.eta
    first, second = bond.strength / k, bond.shear_strength / k
    start = np.sqrt(first ** 2 + (second ** 2 - first ** 2) * mix)
    toughness = bond.toughness + (bond.G_IIc - bond.toughness) * mix
    return start, 2.0 * toughness / (k * start)


def damage_of(bond: Bond, slide: np.ndarray, opening: np.ndarray) -> np.ndarray:
    """The damage the jumps alone make (0 for the elastic law), in [0, 1]."""
    if bond.law == "elastic":
        return np.zeros(len(slide))
    effective = np.sqrt(np.maximum(opening, 0.0) ** 2 + slide ** 2)
    start, end = law_openings(bond, slide, opening)
    past = effective > start
    out = np.zeros(len(slide))
    out[past] = end[past] * (effective[past] - start[past]) / (effective[past] * (end[past] - start[past]))
    return np.clip(out, 0.0, 1.0)


def softening(bond: Bond, damage: np.ndarray) -> np.ndarray:
    """How far along the softening branch each vertex is, (δₘ − δ₀)/(δ_f − δ₀) in [0, 1], from its damage (the
    pure mode I law's openings; 0 for the elastic law): the damage d is near 1 on most of that branch when
    δ₀ ≪ δ_f, this moves with the traction."""
    if bond.law == "elastic":
        return np.zeros(len(damage))
    start, end = bond.strength / bond.stiffness, 2.0 * bond.toughness / bond.strength
    largest = start * end / (end - damage * (end - start))
    return np.clip((largest - start) / (end - start), 0.0, 1.0)


@dataclass
class Response:
    """The law at the jumps of m vertices: ``traction`` ``(m, 2)`` (the multipliers μᵍ, tangential and normal:
    k(1 − d)(u⁻ − u⁺), k(u⁻ − u⁺)·ν where pressed), its derivative ``tangent`` ``(m, 2, 2)`` in the jump u⁻ − u⁺,
    the ``damage`` and whether the normal row is ``pressed``."""

    traction: np.ndarray
    tangent: np.ndarray
    damage: np.ndarray
    pressed: np.ndarray


def response(bond: Bond, history: np.ndarray, gap: np.ndarray) -> Response:
    """The law at the jumps ``gap`` ``(m, 2)`` = u⁻ − u⁺ (tangential, normal) from the damage ``history``: the
    damage max(history, d(δ)); where it grows, the tangent has the damage's derivative (with δ₀ and δ_f of the
    present mode mix held: a quasi-Newton tangent under Benzeggagh–Kenane)."""
    k = bond.stiffness
    slide, opening = gap[:, 0], -gap[:, 1]
    fresh = damage_of(bond, slide, opening)
    damage = np.maximum(history, fresh)
    pressed = opening < 0.0
    secant_stiffness = k * (1.0 - damage)
    normal = np.where(pressed, k, secant_stiffness)
    traction = np.column_stack([secant_stiffness * slide, normal * gap[:, 1]])
    tangent = np.zeros((len(gap), 2, 2))
    tangent[:, 0, 0], tangent[:, 1, 1] = secant_stiffness, normal
    growing = (fresh > history) & (fresh < 1.0)
    if growing.any():
        effective = np.sqrt(np.maximum(opening, 0.0) ** 2 + slide ** 2)[growing]
        start, end = (value[growing] for value in law_openings(bond, slide, opening))
        slope = end * start / (effective ** 2 * (end - start))  # d'(δₑ)
        direction = np.column_stack([slide[growing], -np.maximum(opening[growing], 0.0)]) / effective[:, None]
        acted = np.column_stack([slide[growing], np.where(pressed[growing], 0.0, gap[growing, 1])])
        tangent[growing] -= k * slope[:, None, None] * acted[:, :, None] * direction[:, None, :]
    return Response(traction, tangent, damage, pressed)


def secant(interface: Interface, solve: Callable[[Interface, np.ndarray | None], Outcome], label: str) -> Outcome:
    """A load step of the bond (module docstring) from the history's damage ``interface.damage``: ``solve(the
    interface with the current damage, start)`` solves one linear problem from the multipliers ``start``.  The
    outcome of the last, its iterations summed, with ``bond_solves`` (the linear problems) and ``damage`` (the
    vertices' new damage, the history for the next step) in its details."""
    history, state, start = interface.damage, interface, None
    total, record = 0, []
    for solves in range(1, MAX_SECANT + 1):
        outcome = solve(state, start)
        total += outcome.iterations
        record += outcome.history
        if outcome.diverged or not outcome.converged:
            break
        slide, opening = jumps(state, outcome.lam)
        broken = state.damage >= BROKEN  # its jump is not seen in its multipliers: it stays broken
        damage = np.where(broken, 1.0, np.maximum(history, damage_of(interface.bond, slide, opening)))
        pressed = np.where(broken, state.pressed, opening < 0.0)
        effective = np.hypot(np.maximum(opening, 0.0), slide)
        change = float((np.abs(damage - state.damage) * effective).max(initial=0.0)) * interface.bond.stiffness
        if change <= DAMAGE_TOLERANCE * interface.bond.strength and np.array_equal(pressed, state.pressed):
            break
        state, start = interface.with_damage(damage, pressed), outcome.lam
    else:
        outcome.converged = False
        outcome.message = (f"{label}: the bond's damage found no fixed point in {MAX_SECANT} solves (largest change of "
                           f"a traction {change:.3e})")
    outcome.iterations, outcome.history, outcome.state = total, record, state
    outcome.details["bond_solves"] = solves
    return outcome
