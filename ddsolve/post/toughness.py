"""Will the tip grow, and at which load?  The toughness G_c at every crack tip and the critical load factor.

Griffith: a tip grows where G ≥ G_c.  G_c is the scene's ``[fracture] toughness`` (one value for every tip,
or one per crack in order along Σ), or a mode-dependent law of G's split into modes I and II
(:func:`ddsolve.post.fracture.mode_split`):

- Benzeggagh–Kenane: G_c = G_Ic + (G_IIc − G_Ic)(G_II/G)^η;
- Hutchinson–Suo: G_c(ψ) = G_Ic (1 + tan²((1 − λ)ψ)), ψ the phase angle (G_Ic where G ≈ 0 leaves ψ undefined).

The contact problem is positively homogeneous: scaling every mechanical load by λ > 0 scales the solution
by λ, G by λ² and keeps the mode mix, so without a temperature change a tip starts to grow at the load
factor λ_c = √(G_c/G) (:func:`critical_factor`; Coulomb's friction scales too, Tresca's given bound does not).
With a temperature change or a Tresca bound kept fixed, λ_c comes from a
root solve over scaled solves (:mod:`ddsolve.solvers.critical`).  No PETSc or MPI here.
"""
from __future__ import annotations

import numpy as np

from ddsolve.errors import SceneError
from ddsolve.post.result import Fracture
from ddsolve.problem.scene import FractureOptions, Scene


def given(scene: Scene) -> bool:
    """Whether the scene asks for a toughness (``fracture.toughness`` or ``fracture.law``)."""
    return scene.fracture.toughness is not None or scene.fracture.law is not None


def check_cracks(scene: Scene, cracks: int) -> None:
    """Refuse a per-crack ``fracture.toughness`` whose length is not the number of ``cracks`` of the mesh."""
    values = scene.fracture.toughness
    if isinstance(values, tuple) and len(values) != cracks:
        raise SceneError(f"{scene.origin}: fracture.toughness lists {len(values)} values for the {cracks} "
                         f"crack{'' if cracks == 1 else 's'} of the mesh (one per crack, in order along Σ)")


def law(options: FractureOptions, crack: np.ndarray, G: np.ndarray, G_II: np.ndarray, phase: np.ndarray
        ) -> np.ndarray:
    """G_c of the toughness ``options`` at tips of cracks ``crack`` with G, G_II and the phase angle ψ
    (degrees); NaN where no toughness is given, or where the law needs a mode mix G does not define
    (Benzeggagh–Kenane at G ≤ 0).  Hutchinson–Suo where ψ is undefined (G ≈ 0: no mode mix) gives its
    least value G_Ic: such a tip's critical factor √(G_c/G) is then large or inf (G ≤ 0), never NaN."""
    crack, G = np.asarray(crack, dtype=np.int64), np.asarray(G, dtype=np.float64)
    if options.toughness is not None:
        if not isinstance(options.toughness, tuple):
            return np.full(G.shape, float(options.toughness))
        return np.asarray(options.toughness, dtype=np.float64)[crack]
    if options.law == "benzeggagh-kenane":
        positive = G > 0
        ratio = np.where(positive, np.clip(np.asarray(G_II) / np.where(positive, G, 1.0), 0.0, 1.0), np.nan)
        return options.G_Ic + (options.G_IIc - options.G_Ic) * ratio ** options.eta
    if options.law == "hutchinson-suo":  # no mode mix (G ≈ 0): the law's least toughness, G_Ic at ψ = 0
        phase = np.nan_to_num(np.asarray(phase, dtype=np.float64), nan=0.0)
        return options.G_Ic * (1.0 + np.tan((1.0 - options.lambda_) * np.radians(phase)) ** 2)
    return np.full(G.shape, np.nan)


def resistance(scene: Scene, fracture: Fracture) -> np.ndarray:
    """G_c at every tip of ``fracture`` (per crack by ``fracture.crack``, mode-dependent by ``G_II/G`` and
    ``phase``); NaN everywhere when the scene gives no toughness."""
    return law(scene.fracture, fracture.crack, fracture.G, fracture.G_II, fracture.phase)


def critical_factor(G: np.ndarray, G_c: np.ndarray) -> np.ndarray:
    """The load factor at which each tip starts to grow under proportional loading: √(G_c/G) where G > 0
    (NaN where G_c is NaN), inf where G ≤ 0 (the tip never grows, whatever G_c), NaN where G is NaN."""
    G, G_c = np.broadcast_arrays(np.asarray(G, dtype=np.float64), np.asarray(G_c, dtype=np.float64))
    out = np.where(np.isnan(G), np.nan, np.inf)
    positive = G > 0
    with np.errstate(over="ignore"):  # a G of a few denormals: inf, it does not grow
        out[positive] = np.sqrt(G_c[positive] / G[positive])
    return out


def judge(fracture: Fracture, scene: Scene, factors: np.ndarray | None = None) -> Fracture:
    """``fracture`` with its ``toughness`` and ``critical_factor`` filled in (NaN without a toughness):
    ``factors`` where given (a root solve, with a temperature change or a Tresca bound), else √(G_c/G) when the
    scene is :attr:`~ddsolve.problem.scene.Scene.proportional`, else NaN (the factor needs the root solve)."""
    fracture.toughness = resistance(scene, fracture)
    if not given(scene):
        fracture.critical_factor = np.full(len(fracture.G), np.nan)
    elif factors is not None:
        fracture.critical_factor = np.asarray(factors, dtype=np.float64).copy()
    elif scene.proportional:
        fracture.critical_factor = critical_factor(fracture.G, fracture.toughness)
    else:
        fracture.critical_factor = np.full(len(fracture.G), np.nan)
    return fracture
