"""Pictures of a result (matplotlib, Agg): deformed layers coloured by von Mises stress,
the normal jump of layer 1 across Σ, and convergence histories."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from . import scene as scenes
from .analysis import along_sigma, layer_stresses, normal_jump
from .interface import BLOCKS

if TYPE_CHECKING:
    from .result import Result


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
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
    size = np.ptp(points, axis=0).max()
    largest = max(np.abs(u).max(initial=0.0) for u in result.solution.values())
    if largest == 0.0 or not np.isfinite(largest):
        return 1.0
    raw = fraction * size / largest
    return float(f"{raw:.0e}")


def deformed_layers(result: Result, path: Path, scale: float | None = None) -> float:
    """Both layers, displacements magnified by ``scale`` (from the data by default), cells coloured by
    von Mises stress on a range that ignores the stress singularities (99th percentile); returns the scale."""
    plt = _pyplot()
    scale = magnification(result) if scale is None else scale
    stresses = layer_stresses(result)
    moved = np.vstack([half.points + scale * result.solution[name] for name in result.solution
                       for half in [result.half(name)]])
    width, height = np.ptp(moved, axis=0)
    wide = width > 2.0 * height  # one layer above the other, else side by side
    panel = (8.5, 8.5 * height / width) if wide else (4.6 * min(width / height, 1.6), 4.6)
    fig, axes = plt.subplots(2 if wide else 1, 1 if wide else 2, constrained_layout=True,
                             figsize=(panel[0] + 2.5, 2 * (panel[1] + 1.0) + 0.4) if wide
                             else (2 * (panel[0] + 2.2), panel[1] + 1.2))
    for ax, layer, title in zip(axes, ("layer1", "layer2"), ("layer 1 (u)", "layer 2 (v)")):
        names = [spec.name for spec in BLOCKS if spec.layer == layer]
        values = np.concatenate([stresses[name] for name in names])
        top = np.percentile(values, 99.0) if len(values) else 1.0
        for name in names:
            half = result.half(name)
            moved = half.points + scale * result.solution[name]
            triangles, parent = linear_triangles(half.cells)
            image = ax.tripcolor(moved[:, 0], moved[:, 1], triangles, facecolors=stresses[name][parent],
                                 cmap="viridis", vmin=0.0, vmax=top or 1.0, edgecolors="none")
        fig.colorbar(image, ax=ax, shrink=0.9, label="von Mises stress" if wide else
                     "von Mises stress (top: 99th percentile)")
        ax.set_title(f"{title}, displacements ×{scale:g}")
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        ax.set_aspect("equal")
    fig.suptitle(scenes.loads(result.scene).title)
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
    ax.set_xlabel(axis_label)
    ax.set_ylabel("normal jump [u]·ν of layer 1 (negative: overlap)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def crack_faces(result: Result, path: Path) -> None:
    """Along Σ: the opening [u]·ν of layer 1 and the contact pressure μᶜ, cracks shaded; with the result's
    fracture data, the contact zones shaded red and G written at each crack tip."""
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
    if fracture is not None:  # contact zones and G at the tips
        arc = result.mesh.sigma.arclength[result.multiplier_nodes]
        for start, end in fracture.zones:
            for ax in (top, bottom):
                ax.axvspan(*np.interp([start, end], arc, position), color="tab:red", alpha=0.15, linewidth=0)
        if len(fracture.zones):
            shading += "; red: faces in contact"
        for point, rate in zip(fracture.points, fracture.G):
            nearest = int(np.argmin(np.linalg.norm(result.interface_points - point, axis=1)))
            top.axvline(position[nearest], color="0.4", linestyle=":", linewidth=0.8)
            top.annotate(f"G = {rate:.3e}", (position[nearest], 0.0), xytext=(3, 6), textcoords="offset points",
                         fontsize=8, rotation=90, va="bottom")
    top.axhline(0.0, color="black", linewidth=0.6)
    top.set_ylabel("opening [u]·ν")
    bottom.set_ylabel("contact pressure μᶜ")
    bottom.set_xlabel(f"{axis_label} ({shading})")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    top.set_title(scenes.loads(result.scene).title, fontsize=9)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def convergence(results: list[tuple[str, Result]], path: Path) -> None:
    """Stopping-rule value against iteration."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    for label, result in results:
        ax.semilogy(np.arange(1, len(result.history) + 1), result.history, label=label)
    ax.set_xlabel("iteration")
    ax.set_ylabel("stopping criterion")
    ax.legend()
    ax.grid(alpha=0.3, which="both")
    fig.savefig(path, dpi=130)
    plt.close(fig)
