"""A structure of several interfaces as one record (:class:`StackResult`): its blocks (the layers × regions, u1,
u2, .., then v1, ..), and each interface seen as the structure of its two regions (a :class:`Result` of its own,
with G at its tips).  What is done with such a record once solved or read back: its mesh from the interfaces'
views, the comparison of two of them (the energy norm over every block, G at every tip) and its blocks drawn.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ddsolve.errors import DDSolveError
from ddsolve.mesh.mesh import Mesh, blocks
from ddsolve.post import analysis, plots
from ddsolve.post.result import Fracture, Result
from ddsolve.problem.schema import LAYERS, REGIONS
from ddsolve.problem.scene import Scene


@dataclass
class StackResult:
    """The solution of several interfaces: the blocks' displacements ``(n, 2)`` by name (:func:`block_names`),
    the potential energy, and each interface's view solved, with G at its tips; ``fracture`` joins them
    (:func:`ddsolve.post.fracture.of_interfaces`)."""

    scene: Scene
    mesh: Mesh
    solution: dict[str, np.ndarray]
    energy: float
    interfaces: list[Result]
    fracture: Fracture
    converged: bool
    message: str
    iterations: int
    timings: dict[str, float]

    @property
    def wall_time(self) -> float:
        return self.timings["total"]

    @property
    def method(self) -> str:
        return self.interfaces[0].method


def block_names(layers: int, count: int) -> list[tuple[str, str, int]]:
    """(name, layer, region index) of the blocks of ``layers`` layers on ``count`` regions, layer by layer, the
    lowest region first."""
    return [(f"{letter}{region + 1}", layer, region) for layer, letter in zip(LAYERS[:layers], "uv")
            for region in range(count)]


def view_blocks(interface: int, layers: int) -> list[str]:
    """The structure's block names of the blocks of interface ``interface``'s view, in the view's order
    (:func:`ddsolve.mesh.mesh.blocks`: u⁻, u⁺, then v⁻, v⁺)."""
    return [f"{'uv'[LAYERS.index(spec.layer)]}{interface + 1 + (spec.side > 0)}" for spec in blocks(layers)]


def view_scene(scene: Scene, interface: int, cracks: slice) -> Scene:
    """The scene of interface ``interface`` alone: its Σ and cracks, its two regions' materials as those of
    ``lower`` and ``upper``, its ``cracks`` of a toughness given per crack."""
    shape, options = scene.geometry, scene.fracture
    names = shape.region_names[interface:interface + 2]
    toughness = options.toughness[cracks] if isinstance(options.toughness, tuple) else options.toughness
    return dataclasses.replace(
        scene, geometry=dataclasses.replace(shape, sigma=shape.sigmas[interface],
                                            cracks=shape.crack_lists[interface], above=()),
        fracture=dataclasses.replace(options, toughness=toughness),
        regions={(layer, region): scene.material(layer, name) for layer in scene.layers
                 for region, name in zip(REGIONS, names)})


def crack_counts(mesh: Mesh) -> list[int]:
    """The number of cracks on each interface, bottom to top."""
    return [len(line.pieces(line.crack)) for line in mesh.sigmas]


def crack_slices(counts: list[int]) -> list[slice]:
    """Each interface's cracks among the structure's (counted interface by interface, bottom to top)."""
    first = np.concatenate([[0], np.cumsum(counts)]).astype(int)
    return [slice(first[k], first[k + 1]) for k in range(len(counts))]


def mesh_of_views(scene: Scene, views: list[Result], origin: str) -> Mesh:
    """The structure's mesh from its interfaces' views (bottom to top): the lowest region is the first view's
    lower half, region k + 1 the upper half of view k, with its nodes on the Σ above it (the lower half of the
    view above)."""
    names = scene.geometry.region_names
    regions = [dataclasses.replace(views[0].lower, region=names[0])]
    for k, view in enumerate(views):
        above = views[k + 1].lower.sigma if k + 1 < len(views) else np.zeros(0, dtype=np.int64)
        regions.append(dataclasses.replace(view.upper, region=names[k + 1], sigma_above=above))
    lines = [view.mesh.sigma for view in views]
    return Mesh(regions[0], regions[1], lines[0], origin, tuple(zip(lines[1:], regions[2:])))


def structure(result: StackResult | Result) -> str:
    """The structure of a result in words: its interfaces and blocks."""
    if isinstance(result, StackResult):
        return f"{len(result.interfaces)} interfaces, blocks {', '.join(result.solution)}"
    return f"one interface, blocks {', '.join(spec.name for spec in result.blocks)}"


def compare(a: StackResult, b: StackResult, names: tuple[str, str] = ("the result", "the reference")
            ) -> analysis.Comparison:
    """Error of ``a`` against ``b`` over every block (:func:`ddsolve.post.analysis.compare`'s definition, each
    block once); results of different structures are refused in one line."""
    if not (isinstance(a, StackResult) and isinstance(b, StackResult)) or list(a.solution) != list(b.solution):
        raise DDSolveError(f"{names[0]} and {names[1]} are results of different structures ({structure(a)}; "
                           f"{structure(b)}): compare results of one structure")
    layers = len(a.scene.layers)
    errors = {}
    for k, (mine, theirs) in enumerate(zip(a.interfaces, b.interfaces)):
        of_view = analysis.block_errors(mine, theirs, names)
        errors.update(zip(view_blocks(k, layers), (of_view[spec.name] for spec in theirs.blocks)))
    return analysis.combined(errors.values())


def tip_lines(a: Fracture, b: Fracture, names: tuple[str, str] = ("the result", "the reference")) -> list[str]:
    """G of ``a`` against ``b`` at every tip (of every interface), one line each: both values and the relative
    difference; tips that are not the same (count or place) are refused in one line."""
    if len(a.G) != len(b.G) or not np.allclose(a.points, b.points, rtol=0.0, atol=1e-9 * max(np.ptp(b.points), 1.0)):
        raise DDSolveError(f"{names[0]} and {names[1]} have different crack tips ({len(a.G)} and {len(b.G)} tips): "
                           "compare results of one geometry")
    return [f"G at tip ({x:.6g}, {y:.6g}) of crack {c}{b.on_interface(c)}: {g:.6e} against {h:.6e}, "
            + (f"relative difference {abs(g - h) / abs(h):.3e}" if h else f"difference {abs(g - h):.3e}")
            for (x, y), c, g, h in zip(b.points, b.crack, a.G, b.G)]


def cell_fields(stacked: StackResult) -> dict[str, analysis.CellFields]:
    """Block name -> its per-cell fields (:func:`ddsolve.post.analysis.block_cell_fields`), with its region's
    material."""
    out = {}
    for name, layer, region in block_names(stacked.scene.geometry.layers, len(stacked.mesh.regions)):
        half = stacked.mesh.regions[region]
        out[name] = analysis.block_cell_fields(stacked.scene, layer, half.name, half.points, half.cells,
                                               stacked.solution[name])
    return out


def drawn(stacked: StackResult) -> list[plots.Drawn]:
    """The blocks of a result of several interfaces, to draw (:func:`ddsolve.post.plots.deformed_blocks`)."""
    fields = cell_fields(stacked)
    return [plots.Drawn(layer, stacked.mesh.regions[region].points, stacked.mesh.regions[region].cells,
                        stacked.solution[name], fields[name].von_mises)
            for name, layer, region in block_names(stacked.scene.geometry.layers, len(stacked.mesh.regions))]
