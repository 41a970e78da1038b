"""Pictures of a result (matplotlib, Agg): deformed layers coloured by von Mises stress,
the normal jump of layer 1 across Σ, and convergence histories."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from . import scene as scenes
from .analysis import layer_stresses, normal_jump
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


def deformed_layers(result: Result, path: Path, scale: float) -> None:
    """Both layers side by side, displacements magnified by ``scale``, cells coloured by von Mises."""
    plt = _pyplot()
    stresses = layer_stresses(result)
    fig, axes = plt.subplots(1, 2, figsize=(11, 5), constrained_layout=True)
    for ax, layer, title in zip(axes, ("layer1", "layer2"), ("layer 1 (u)", "layer 2 (v)")):
        names = [spec.name for spec in BLOCKS if spec.layer == layer]
        top = max(stresses[name].max() for name in names) or 1.0
        for name in names:
            half = result.half(name)
            moved = half.points + scale * result.solution[name]
            triangles, parent = linear_triangles(half.cells)
            image = ax.tripcolor(moved[:, 0], moved[:, 1], triangles, facecolors=stresses[name][parent],
                                 cmap="viridis", vmin=0.0, vmax=top, edgecolors="none")
        fig.colorbar(image, ax=ax, shrink=0.8, label="von Mises stress")
        ax.set_title(f"{title}, displacements x{scale:g}")
        ax.set_aspect("equal")
    fig.suptitle(scenes.loads(result.scene).title)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def interface_jumps(results: list[tuple[str, Result]], path: Path) -> None:
    """[u]·ν along Σ for one or more results (e.g. contact against the linear problem)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    for label, result in results:
        ax.plot(result.interface_x, normal_jump(result), marker=".", markersize=3, label=label)
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.set_xlabel("x on Σ")
    ax.set_ylabel("normal jump [u]·ν (negative: overlap)")
    ax.legend()
    ax.grid(alpha=0.3)
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
