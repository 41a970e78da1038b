"""Pictures of a 3-D result (matplotlib, Agg): the opening of Σ as a map over its x-z plane, the cracks outlined
and their vertices in contact marked, and the deformed body in perspective, coloured by the displacement's size."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ddsolve.mesh.solid import boundary_faces
from ddsolve.post.plots import LENGTH, _pyplot
from ddsolve.post.solid import SolidResult

#: A 6-node triangle (v0 v1 v2 m01 m12 m20) as four 3-node ones, for drawing.
SUBTRIANGLES = np.array([[0, 3, 5], [3, 1, 4], [5, 4, 2], [3, 4, 5]])
#: The default magnification draws the largest displacement at this fraction of the body's largest side.
DRAWN_FRACTION = 0.1


def flat_triangles(triangles: np.ndarray) -> np.ndarray:
    """3-node triangles of 3- or 6-node ones (each 6-node one split in four at its mid-edge nodes)."""
    if triangles.shape[1] == 3:
        return triangles
    return triangles[:, SUBTRIANGLES].reshape(-1, 3)


def magnification(result: SolidResult) -> float:
    """The displacement factor that draws the largest displacement at :data:`DRAWN_FRACTION` of the body's
    largest side, to one significant digit (1 for a body that does not move)."""
    largest = max(float(np.abs(u).max(initial=0.0)) for u in result.fields)
    size = float(np.ptp(np.vstack([half.points for half in result.mesh.regions]), axis=0).max())
    return float(f"{DRAWN_FRACTION * size / largest:.1g}") if largest > 0.0 else 1.0


def opening_map(result: SolidResult, target: Path) -> None:
    """Σ seen from above (x across, z up the page): the normal opening [u]·ν filled in, the cracks outlined
    (dashed), the crack vertices in contact (a positive pressure) marked red."""
    plt = _pyplot()
    from matplotlib.tri import Triangulation

    surface = result.mesh.sigma
    x, z = surface.points[:, 0], surface.points[:, 2]
    fig, ax = plt.subplots(figsize=(8, 5.5), constrained_layout=True)
    filled = ax.tricontourf(Triangulation(x, z, flat_triangles(surface.triangles)), result.normal_opening, levels=20,
                            cmap="viridis", extend="both")  # round-off below 0 filled too
    fig.colorbar(filled, ax=ax, label=f"opening [u]·ν ({LENGTH})")
    for a, b, c, d in result.scene.geometry.cracks:
        ax.plot([a, b, b, a, a], [c, c, d, d, c], color="white", linestyle="--", linewidth=1.2)
    if result.scene.geometry.solid_file:  # a gmsh file's cracks: their fronts
        ends = surface.points[surface.front][:, :, [0, 2]]  # (k, 2 ends, x z)
        ax.plot(*np.transpose(ends, (2, 1, 0)), color="white", linestyle="--", linewidth=1.2)
    closed = result.pressure > 0.0
    ax.plot(x[closed], z[closed], "o", color="tab:red", markersize=3, linestyle="none",
            label=f"in contact ({int(closed.sum())} vertices)")
    ax.set_aspect("equal")
    ax.set_xlabel(f"x ({LENGTH})")
    ax.set_ylabel(f"z ({LENGTH})")
    ax.set_title(f"Σ (y = {float(surface.points[0, 1]):g}): the crack opening; dashed: cracks")
    ax.legend(loc="upper right", fontsize=8)
    fig.savefig(target, dpi=120)
    plt.close(fig)


def deformed_body(result: SolidResult, target: Path, scale: float) -> None:
    """Both halves' (every region's) boundaries displaced by ``scale`` × u, in perspective with y up, each
    triangle coloured by the size of its nodes' mean displacement."""
    plt = _pyplot()
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fig = plt.figure(figsize=(8, 6.5), constrained_layout=True)
    ax = fig.add_subplot(projection="3d")
    largest = max(float(np.linalg.norm(u, axis=1).max(initial=0.0)) for u in result.fields) or 1.0
    colours = plt.get_cmap("viridis")
    corners = []
    for half, u in zip(result.mesh.regions, result.fields):
        faces = boundary_faces(half.tetrahedra[:, :4])
        drawn = (half.points + scale * u)[:, [0, 2, 1]]  # y drawn upwards
        size = np.linalg.norm(u[faces], axis=2).mean(axis=1) / largest
        ax.add_collection3d(Poly3DCollection(drawn[faces], facecolors=colours(size), edgecolors="0.3",
                                             linewidths=0.2))
        corners += [drawn.min(axis=0), drawn.max(axis=0)]
    low, high = np.min(corners, axis=0), np.max(corners, axis=0)
    for limits, lo, hi in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), low, high):
        limits(lo, hi)
    ax.set_box_aspect(high - low)
    ax.set_xlabel("x")
    ax.set_ylabel("z")
    ax.set_zlabel("y")
    ax.view_init(elev=20, azim=-60)
    mappable = plt.cm.ScalarMappable(cmap=colours, norm=plt.Normalize(0.0, largest))
    fig.colorbar(mappable, ax=ax, shrink=0.6, label=f"|u| ({LENGTH})")
    ax.set_title(f"deformed body (displacements ×{scale:g}), energy {result.energy:.6g}")
    fig.savefig(target, dpi=120)
    plt.close(fig)
