"""Pictures of a result (matplotlib, Agg): deformed layers coloured by von Mises stress,
the normal jump of layer 1 across Σ, and convergence histories.

Units are those of the scene: lengths in its geometry's unit, stresses (and the contact pressure,
a traction) in the unit of its elastic moduli.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ddsolve.post.analysis import along_sigma, layer_stresses, normal_jump
from ddsolve.post.result import NO_PHASE, SPLIT_DRIFT

if TYPE_CHECKING:
    from ddsolve.post.result import Result


#: Axis-label units.
LENGTH, STRESS = "length unit", "unit of E"
#: Stress colours run up to this percentile of the cells' values: the singularities at clamped
#: corners and crack tips would otherwise take the whole colour range.
STRESS_PERCENTILE = 99.0


def stress_ceiling(values: np.ndarray, total: int | None = None) -> float:
    """Top of the stress colour range: the STRESS_PERCENTILE-th percentile (1 when all is zero) of
    ``values``, or (``total`` given) of ``total`` values whose :func:`largest_values` parts are ``values``."""
    values = np.sort(np.asarray(values, dtype=np.float64))
    total = len(values) if total is None else total
    top = 0.0
    if total:
        position = STRESS_PERCENTILE / 100.0 * (total - 1)  # numpy's linear percentile
        low, high = (int(np.floor(position)) - (total - len(values)), int(np.ceil(position)) - (total - len(values)))
        top = float(values[low] + (values[high] - values[low]) * (position - np.floor(position)))
    return top if top > 0.0 and np.isfinite(top) else 1.0


def largest_values(values: np.ndarray, total: int) -> np.ndarray:
    """The values of a part of ``total`` values that :func:`stress_ceiling` of the whole may need."""
    keep = total - int(np.floor(STRESS_PERCENTILE / 100.0 * (total - 1)))
    return np.sort(values)[-keep:] if len(values) > keep else np.asarray(values)


#: The longest scene title drawn in a picture (a line across it); a longer one ends in an ellipsis.
TITLE_LENGTH = 120
#: matplotlib text arguments for the user's words: plain text, no math between dollar signs, no LaTeX.
PLAIN_TEXT = {"parse_math": False, "usetex": False}


def drawn_title(result: Result) -> str:
    """The scene's title as a picture shows it (with PLAIN_TEXT): on one line, at most TITLE_LENGTH
    characters."""
    words = "".join(char if char.isprintable() else " " for char in result.scene.title)
    return words if len(words) <= TITLE_LENGTH else words[:TITLE_LENGTH - 1].rstrip() + "…"


def _pyplot():
    import warnings

    import matplotlib

    matplotlib.use("Agg")
    # A character of a title that the font lacks is drawn as a box, without a warning per picture.
    warnings.filterwarnings("ignore", message=r"Glyph \d+ .*missing from current font")
    import matplotlib.pyplot as plt

    return plt


def linear_triangles(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles to draw: the cells (P1), or each P2 cell cut into four at its midpoints; and the cell
    each triangle comes from."""
    if cells.shape[1] == 3:
        return cells, np.arange(len(cells))
    pieces = cells[:, [[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]]]  # (m, 4, 3)
    return pieces.reshape(-1, 3), np.repeat(np.arange(len(cells)), 4)


def magnification(result: Result, fraction: float = 0.08) -> float:
    """A displacement magnification from the data: the largest displacement drawn as ``fraction`` of
    the domain's size, rounded to one significant digit (1 when nothing moves)."""
    points = np.vstack([result.lower.points, result.upper.points])
    return scale_for(np.ptp(points, axis=0).max(), result.on_sigma.largest, fraction)


def block_magnification(blocks: list[Drawn], fraction: float = 0.08) -> float:
    """:func:`magnification` of the blocks ``blocks`` (:class:`Drawn`)."""
    points = np.vstack([block.points for block in blocks])
    return scale_for(np.ptp(points, axis=0).max(), max(np.abs(block.u).max(initial=0.0) for block in blocks), fraction)


def scale_for(size: float, largest: float, fraction: float = 0.08) -> float:
    """:func:`magnification` for a domain of ``size`` and a largest nodal displacement ``largest``."""
    if largest == 0.0 or not np.isfinite(largest):
        return 1.0
    raw = fraction * size / largest
    return float(f"{raw:.0e}")


#: How pictures and viewer files title each layer.
LAYER_TITLES = {"layer1": "layer 1 (u)", "layer2": "layer 2 (v)"}


def one_above_the_other(points: np.ndarray) -> bool:
    """Whether to draw the two layers one above the other (a domain more than twice as wide as tall)
    rather than side by side."""
    width, height = np.ptp(points, axis=0)
    return bool(width > 2.0 * height)


@dataclass(frozen=True)
class Drawn:
    """One block as :func:`deformed_blocks` draws it: its layer, its half's (or region's) nodes and cells, its
    displacements ``(n, 2)`` and its cells' von Mises stress."""

    layer: str
    points: np.ndarray
    cells: np.ndarray
    u: np.ndarray
    stress: np.ndarray


def drawn_blocks(result: Result) -> list[Drawn]:
    """The blocks of a result, to draw."""
    stresses = layer_stresses(result)
    return [Drawn(spec.layer, result.half(spec.name).points, result.half(spec.name).cells, result.solution[spec.name],
                  stresses[spec.name]) for spec in result.blocks]


def deformed_layers(result: Result, path: Path, scale: float | None = None, heading: str | None = None) -> float:
    """The layers (one panel each), displacements magnified by ``scale`` (from the data by default), cells coloured by
    von Mises stress on a range that ignores the stress singularities (:func:`stress_ceiling`), under
    ``heading`` (default: the scene's title); returns the scale."""
    return deformed_blocks(drawn_blocks(result), result.scene.layers, path, magnification(result) if scale is None
                           else scale, drawn_title(result) if heading is None else heading)


def deformed_blocks(blocks: list[Drawn], layers: tuple[str, ...], path: Path, scale: float, heading: str) -> float:
    """:func:`deformed_layers` of ``blocks``: a panel per layer of ``layers``; returns the scale."""
    plt = _pyplot()
    moved = np.vstack([block.points + scale * block.u for block in blocks])
    width, height = np.ptp(moved, axis=0)
    wide = one_above_the_other(moved)
    panel = (8.5, 8.5 * height / width) if wide else (4.6 * min(width / height, 1.6), 4.6)
    fig, axes = plt.subplots(len(layers) if wide else 1, 1 if wide else len(layers), constrained_layout=True,
                             squeeze=False, figsize=(panel[0] + 2.5, len(layers) * (panel[1] + 1.0) + 0.4) if wide
                             else (len(layers) * (panel[0] + 2.2), panel[1] + 1.2))
    for ax, layer in zip(axes.ravel(), layers):
        own = [block for block in blocks if block.layer == layer]
        top = stress_ceiling(np.concatenate([block.stress for block in own]))
        for block in own:
            moved = block.points + scale * block.u
            triangles, parent = linear_triangles(block.cells)
            image = ax.tripcolor(moved[:, 0], moved[:, 1], triangles, facecolors=block.stress[parent],
                                 cmap="viridis", vmin=0.0, vmax=top, edgecolors="none")
        fig.colorbar(image, ax=ax, shrink=0.9, label=f"von Mises stress ({STRESS})" if wide else
                     f"von Mises stress ({STRESS}; top: {STRESS_PERCENTILE:g}th percentile)")
        ax.set_title(f"{LAYER_TITLES[layer]}, displacements ×{scale:g}")
        ax.set_xlabel(f"x ({LENGTH})")
        ax.set_ylabel(f"y ({LENGTH})")
        ax.set_aspect("equal")
    fig.suptitle(heading, **PLAIN_TEXT)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return scale


def interface_jumps(results: list[tuple[str, Result]], path: Path) -> None:
    """[u]·ν along Σ for one or more results (e.g. contact against the linear problem)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    for label, result in results:
        position, axis_label = along_sigma(result)
        ax.plot(position, normal_jump(result), marker=".", markersize=3, label=label)
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.set_xlabel(f"{axis_label} ({LENGTH})")
    ax.set_ylabel(f"normal jump [u]·ν of layer 1 ({LENGTH}; negative: overlap)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def crack_faces(result: Result, path: Path) -> None:
    """Along Σ: the opening [u]·ν of layer 1 and the contact pressure μᶜ, cracks shaded; with the result's
    fracture data, the contact zones shaded red (without non-penetration: where the faces overlap, orange) and
    G with its split into modes written at each crack tip."""
    plt = _pyplot()
    position, axis_label = along_sigma(result)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, constrained_layout=True)
    top.plot(position, normal_jump(result), marker=".", markersize=3, color="tab:blue")
    bottom.plot(position, result.multipliers["mu_c"], marker=".", markersize=3, color="tab:red")
    for first, last in result.mesh.sigma.pieces(result.crack):
        for ax in (top, bottom):
            ax.axvspan(position[max(first - 1, 0)], position[min(last + 1, len(position) - 1)], color="0.9")
    shading = "shaded: cracks"
    fracture = result.fracture
    if fracture is not None:  # contact (or overlap) zones and G at the tips
        arc = result.mesh.sigma.arclength[result.multiplier_nodes]
        for zones, colour, words in ((fracture.zones, "tab:red", "red: faces in contact"),
                                     (fracture.overlaps, "tab:orange", "orange: faces overlap")):
            for start, end in zones:
                first, last = np.interp([start, end], arc, position)
                for ax in (top, bottom):
                    if last > first:
                        ax.axvspan(first, last, color=colour, alpha=0.15, linewidth=0)
                    else:  # a zone of one node: a line, which a span of no width would not show
                        ax.axvline(first, color=colour, alpha=0.4, linewidth=2)
            if len(zones):
                shading += f"; {words}"
        for point, text in zip(fracture.points, tip_labels(fracture)):
            nearest = int(np.argmin(np.linalg.norm(result.interface_points - point, axis=1)))
            top.axvline(position[nearest], color="0.4", linestyle=":", linewidth=0.8)
            top.annotate(text, (position[nearest], 1.0), xycoords=("data", "axes fraction"), xytext=(2, -3),
                         textcoords="offset points", fontsize=7, rotation=90, va="top", ha="left",
                         bbox={"facecolor": "white", "alpha": 0.75, "linewidth": 0, "pad": 1})
    top.axhline(0.0, color="black", linewidth=0.6)
    top.set_ylabel(f"opening [u]·ν\n({LENGTH})")
    bottom.set_ylabel(f"contact pressure μᶜ\n({STRESS})")
    fig.align_ylabels((top, bottom))
    bottom.set_xlabel(f"{axis_label} ({LENGTH}; {shading})")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    top.set_title(drawn_title(result), fontsize=9, **PLAIN_TEXT)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def tip_labels(fracture) -> list[str]:
    """Per tip, what the crack-face picture writes at it: G and, where split, G_I, G_II, ψ (NO_PHASE where
    undefined; and how far their sum misses G when the split is not resolved), short enough to stand beside
    the tip's line."""
    labels = []
    for g, g1, g2, psi, drift in zip(fracture.G, fracture.G_I, fracture.G_II, fracture.phase, fracture.split_drift()):
        lines = [f"G = {g:.3e}"]
        if not np.isnan(g1):  # older results have no split
            split = f"G_I {g1:.2e}, G_II {g2:.2e}"
            lines += [f"{split}, ψ {psi:.1f}°"] if np.isfinite(psi) else [split, NO_PHASE]  # a line of its own
            if abs(drift) > SPLIT_DRIFT:
                lines.append(f"G_I + G_II off G by {drift:+.0%}")
        labels.append("\n".join(lines))
    return labels


@dataclass(frozen=True)
class Curve:
    """What one line of a plot shows."""

    axis: str  # the y-axis label of its panel
    label: str
    x: np.ndarray
    y: np.ndarray


CRITERION_AXIS = "stopping criterion (dimensionless)"
CHANGES_AXIS = "active-set changes (constraints)"


def convergence(results: list[tuple[str, Result]], path: Path) -> list[Curve]:
    """The stopping criterion per iteration (log scale; symmetric-log when a value is 0) and, for
    active-set methods (``schur``, the reference), the constraints that changed state per step.
    Returns the curves drawn."""
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    curves = [Curve(CRITERION_AXIS, label, np.arange(1, len(r.history) + 1), np.asarray(r.history, dtype=float))
              for label, r in results if len(r.history)]
    curves += [Curve(CHANGES_AXIS, label, np.arange(1, len(r.active_set_changes) + 1),
                     np.asarray(r.active_set_changes, dtype=float))
               for label, r in results if len(r.active_set_changes)]
    panels = [axis for axis in (CRITERION_AXIS, CHANGES_AXIS) if any(c.axis == axis for c in curves)]
    fig, axes = plt.subplots(max(len(panels), 1), 1, figsize=(7, 3.2 + 2.3 * len(panels)), sharex=True,
                             constrained_layout=True, squeeze=False)
    axes = axes[:, 0]
    for ax, axis in zip(axes, panels):
        mine = [c for c in curves if c.axis == axis]
        for curve in mine:
            ax.plot(curve.x, curve.y, marker="o", markersize=3, label=curve.label,
                    drawstyle="steps-mid" if axis == CHANGES_AXIS else "default")
        values = np.concatenate([c.y for c in mine])
        if axis == CRITERION_AXIS:
            positive = values[values > 0]
            if len(positive) == len(values):
                ax.set_yscale("log")
            elif len(positive):  # zeros (exact solutions) stay visible on a symmetric log scale
                ax.set_yscale("symlog", linthresh=positive.min())
        ax.set_ylabel(axis)
        if axis == CHANGES_AXIS:
            ax.yaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
        ax.legend()
        ax.grid(alpha=0.3, which="both")
    if not panels:
        axes[0].text(0.5, 0.5, "no iterations: the starting point satisfied the stopping rule",
                     ha="center", va="center", transform=axes[0].transAxes)
        axes[0].set_ylabel(CRITERION_AXIS)
    steps = " (active-set step for schur and the reference)" if any(c.axis == CHANGES_AXIS for c in curves) else ""
    axes[-1].set_xlabel("iteration" + steps)
    axes[-1].xaxis.set_major_locator(MaxNLocator(integer=True, min_n_ticks=1))
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return curves


def growth_curves(growth: dict, path: Path) -> None:
    """The curves of a growth file (:func:`ddsolve.solvers.growth_files.read`): load against displacement, every
    crack's length against the load, and G/G_c at the tips against their crack's length (the R-curve);
    unstable steps are marked.  The title gives the tolerance every growing tip meets."""
    plt = _pyplot()
    load, displacement, cracks = growth["load"], growth["displacement"], growth["cracks"]
    lengths = cracks[:, :, 1] - cracks[:, :, 0]
    unstable = growth["unstable"].astype(bool)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.3), constrained_layout=True)
    ax = axes[0]
    ax.plot(displacement, load, marker="o", markersize=3)
    if unstable.any():
        ax.plot(displacement[unstable], load[unstable], "rx", label="unstable growth at this step")
    ax.set_xlabel("displacement (work conjugate of the load)" if growth["attrs"]["control_kind"] == "load"
                  else "prescribed displacement factor")
    ax.set_ylabel("load factor" if growth["attrs"]["control_kind"] == "load" else "load (work conjugate of the factor)")
    ax = axes[1]
    for c in range(lengths.shape[1]):
        ax.plot(load, lengths[:, c], marker="o", markersize=3, label=f"crack {c + 1}")
    ax.set_xlabel("load")
    ax.set_ylabel(f"crack length ({LENGTH})")
    ax = axes[2]
    ratio = growth["G"] / growth["G_c"]
    tips = growth["tips"]
    # the length of the crack each tip ends (steps, tips, cracks: the tip within the crack's interval)
    inside = (cracks[:, None, :, 0] <= tips[:, :, None] + 1e-9) & (tips[:, :, None] - 1e-9 <= cracks[:, None, :, 1])
    owner = np.broadcast_to(lengths[:, None, :], inside.shape)
    tip_lengths = np.where(inside.any(axis=2),
                           np.take_along_axis(owner, inside.argmax(axis=2)[..., None], axis=2)[..., 0], np.nan)
    for t in range(ratio.shape[1]):
        ax.plot(tip_lengths[:, t], ratio[:, t], marker="o", markersize=3, linestyle="none", label=f"tip {t + 1}")
    ax.axhline(1.0, color="k", linewidth=0.8)
    ax.set_xlabel(f"crack length ({LENGTH})")
    ax.set_ylabel("G / G_c")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.ticklabel_format(style="sci", scilimits=(-3, 4), useMathText=True)  # 0.00015 as 1.5 × 10⁻⁴
        if ax.get_legend_handles_labels()[0]:
            ax.legend()
    fig.suptitle(f"growth of {growth['attrs']['scene']}: {growth['attrs']['control_kind']} control, "
                 f"|G/G_c − 1| ≤ {growth['attrs']['tolerance']:g} at every growing tip", **PLAIN_TEXT)
    fig.savefig(path, dpi=130)
    plt.close(fig)
