"""Scene files: one problem (geometry, mesh, materials, loads, contact, solver) in TOML.

A scene is parsed into plain dataclasses after every key has been checked against ``SCHEMA``;
unknown keys, wrong types and out-of-range values raise :class:`SceneError` with a one-line
message naming the key.  ``--set section.key=value`` overrides are applied to the raw tables
before validation, so they are checked exactly like the file.

This module is the scene's face: the dataclasses, reading a scene (:func:`load`, :func:`loads`), the
built-in scenes; the schema (:mod:`~ddsolve.problem.schema`), the rules between keys
(:mod:`~ddsolve.problem.rules`), the overrides (:mod:`~ddsolve.problem.overrides`) and the input files
(:mod:`~ddsolve.problem.reading`) are re-exported from here.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Sequence

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

from ddsolve.errors import DDSolveError, SceneError
from ddsolve.problem import expressions, materials
from ddsolve.problem.expressions import Expression
from ddsolve.problem.overrides import REPLACES, apply_overrides, dumps, override_items, parse_override
from ddsolve.problem.reading import file_structure, physical_names, printable, readable, utf8_text
from ddsolve.problem.rules import COARSE, CONDITIONING, SAME_COMPONENT, coarse_size, cross_checks
from ddsolve.problem.shapes import Ellipse
from ddsolve.problem.solid_rules import solid_checks
from ddsolve.problem.schema import (ADAPTIVE_DEGREE, DEFAULT_TOL, GEOMETRIC_TOLERANCE,
                                    GRADING, LAWS, LAYERS, MAX_ANGLE, MAX_SPACING_RATIO, OPTIONAL_TABLES,
                                    PAPER_BOX, PAPER_CRACK, REGIONS, REQUIRED, SCHEMA, SIDES, STOP_RULES, Invalid,
                                    STRUCTURE_KEYS, Tables, check_table, is_solid, layer_material, layers_of,
                                    region_materials, region_names, structure_schema)


#: The public face of the problem stage's scene modules (schema, rules, overrides, reading), as before the split.
__all__ = ["ADAPTIVE_DEGREE", "COARSE", "CONDITIONING", "DEFAULT_TOL",
           "GEOMETRIC_TOLERANCE", "GRADING", "LAWS", "LAYERS", "MAX_ANGLE", "MAX_SPACING_RATIO",
           "OPTIONAL_TABLES", "PAPER_BOX", "PAPER_CRACK", "REGIONS", "REPLACES", "REQUIRED", "SAME_COMPONENT", "SCHEMA",
           "SIDES", "STOP_RULES", "Components", "Displacement", "Bond", "FractureOptions", "Friction", "Geometry", "Invalid", "Load", "MeshOptions",
           "Scene", "Solver", "Tables", "apply_overrides", "builtin_folder", "builtin_scenes", "coarse_size", "dumps", "load",
           "loads", "override_items", "parse_override", "printable", "readable", "utf8_text"]


@dataclass(frozen=True)
class Geometry:
    """A box (x0, x1, y0, y1) cut by Σ at height ``sigma``, cracks as x intervals on Σ, clamped sides; a 3-D
    box (x0, x1, y0, y1, z0, z1) has its cracks as rectangles (a, b, c, d): a < x < b, c < z < d on Σ.

    A ``.geo`` or ``.msh`` file with physical groups replaces all of it but ``layers``; ``given`` lists the
    box's keys the scene wrote, so that such a file can refuse them.
    """

    box: tuple[float, ...] = PAPER_BOX
    sigma: float = 0.0
    cracks: tuple[tuple[float, ...], ...] = (PAPER_CRACK,)
    clamped: tuple[str, ...] = ("left", "right")
    #: 2: two sheets (layer1 and layer2) glued on Σ; 1: one body (layer1) cut by Σ.
    layers: int = 2
    given: frozenset[str] = field(default=frozenset(), compare=False)
    #: The interfaces above the first (``sigma``, ``cracks``), bottom to top: (height, cracks) each (a gmsh file's:
    #: placeholders, its curves give them).
    above: tuple[tuple[float, tuple[tuple[float, float], ...]], ...] = ()
    #: A gmsh file's region surfaces, bottom to top, when it has several interfaces (else the regions are numbered).
    regions: tuple[str, ...] = ()
    #: A 3-D gmsh file (physical volumes) gives the body: its groups replace the box, Σ's height and the cracks.
    solid_file: bool = False

    @property
    def dimension(self) -> int:
        """2 for a plane box (or a plane mesh file), 3 for a 3-D box or a 3-D gmsh file."""
        return 3 if self.solid_file else len(self.box) // 2

    @property
    def sigmas(self) -> tuple[float, ...]:
        """The heights of the interfaces, bottom to top."""
        return (self.sigma, *(height for height, _ in self.above))

    @property
    def crack_lists(self) -> tuple[tuple[tuple[float, float], ...], ...]:
        """The cracks of each interface, bottom to top."""
        return (self.cracks, *(cracks for _, cracks in self.above))

    @property
    def region_names(self) -> tuple[str, ...]:
        """The regions of Ω, bottom to top (a gmsh file's, else :func:`ddsolve.problem.schema.region_names`)."""
        return self.regions or region_names(len(self.above) + 2)


@dataclass(frozen=True)
class MeshOptions:
    """How the halves are meshed: the paper's family (P, M), a size, or a file; element degree.

    ``grading`` is the exponent μ of the grading towards the singular points (None: no grading);
    ``target_error`` the relative energy-norm error at which adaptive refinement stops (None: no
    adaptivity); ``refine`` the levels of uniform refinement of a coarse gmsh mesh that make the mesh
    (None: chosen by size, see :func:`ddsolve.mesh.geometry.refinement`; 0: gmsh makes the mesh itself).
    """

    file: Path | None = None
    sigma_vertices: int | None = None
    boundary_vertices: int | None = None
    size: float | None = None
    degree: int = 1
    grading: float | None = None
    target_error: float | None = None
    refine: int | None = None
    #: A 3-D box's section meshed in the plane and extruded in this many layers along z (None: gmsh's tetrahedra).
    extrude: int | None = None

    @property
    def kind(self) -> str:
        """``box`` (generated), ``geo`` (a gmsh script, meshed here) or ``file`` (a mesh to read)."""
        if self.file is None:
            return "box"
        return "geo" if self.file.suffix.lower() == ".geo" else "file"


class Components:
    """A kind of boundary condition described once: its components (each an expression in x and y, or None)
    by name, ``COMPONENTS``, and the noun messages use for it, ``NOUN``."""

    COMPONENTS: tuple[str, ...] = ()
    NOUN = ""
    key: str

    @property
    def boundary(self) -> str:
        """The boundary (or named point) its key ends with: ``loads.LAYER.NAME`` -> NAME."""
        return self.key.rsplit(".", 1)[1]

    @property
    def parts(self) -> dict[str, Expression]:
        """The components the scene gives, by name in ``COMPONENTS`` order."""
        return {name: getattr(self, name) for name in self.COMPONENTS if getattr(self, name) is not None}

    def scaled(self, factor: float):
        """This condition with every component times ``factor``."""
        return dataclasses.replace(self, **{name: None if getattr(self, name) is None else
                                            expressions.scaled(getattr(self, name), factor)
                                            for name in self.COMPONENTS})


@dataclass(frozen=True)
class Load(Components):
    """A traction (x and y components) or a normal pressure on the boundary ``key`` names.

    Each part is an expression in x and y, or None (zero).  ``key`` is ``loads.LAYER.NAME``.
    """

    COMPONENTS = ("x", "y", "z", "pressure")
    NOUN = "load"

    key: str
    x: Expression | None = None
    y: Expression | None = None
    z: Expression | None = None  # 3-D only
    pressure: Expression | None = None


@dataclass(frozen=True)
class Displacement(Components):
    """Prescribed displacement components on the boundary or named point ``key`` names
    (``displacements.LAYER.NAME``), or at ``point`` (x, y), a mesh vertex on the boundary or Σ: x and y,
    or the normal component (boundaries only); each an expression in x and y, or None (that component
    is free)."""

    COMPONENTS = ("x", "y", "z", "normal")
    NOUN = "displacement"

    key: str
    x: Expression | None = None
    y: Expression | None = None
    z: Expression | None = None  # 3-D only
    normal: Expression | None = None
    point: tuple[float, float] | None = None

    @property
    def layer(self) -> str:
        return self.key.split(".")[1]


@dataclass(frozen=True)
class Solver:
    method: str
    theta: float | str | None  # Uzawa's step, or "auto"; the other methods need none
    p: float | None  # multiplier bound; None: μᶜ ≥ 0 only
    tol: float
    stop: str
    max_iterations: int
    out_of_core: bool = False  # MUMPS keeps the blocks' factors on disk
    pieces: int | str = "auto"  # slabs per half of a 3-D box in its domain decomposition (ddsolve.mesh.slabs)
    preconditioner: str = "auto"  # feti's: dirichlet, lumped (K on the traces), or auto (by the structure)
    coarse_degree: int | str = "auto"  # feti's polynomial coarse directions on each joint (0: none), or auto


@dataclass(frozen=True)
class FractureOptions:
    """Radii of the θ field of the energy release rate (None: from the geometry, see ddsolve.post.fracture),
    and the toughness G_c (see :mod:`ddsolve.post.toughness`): ``toughness`` one value for every tip or one
    per crack in order along Σ, or a mode-dependent ``law`` (:data:`LAWS`) with its constants ``G_Ic``,
    ``G_IIc``, ``eta`` (Benzeggagh–Kenane) or ``G_Ic``, ``lambda_`` (Hutchinson–Suo; the key ``lambda``);
    ``reference_length`` l of an interface crack's phase ψ = arg(K l^{iε}) (None: 1)."""

    inner: float | None = None
    outer: float | None = None
    toughness: float | tuple[float, ...] | None = None
    law: str | None = None
    G_Ic: float | None = None
    G_IIc: float | None = None
    eta: float | None = None
    lambda_: float | None = None
    reference_length: float | None = None


@dataclass(frozen=True)
class Friction:
    """Friction on crack faces in contact: ``coulomb`` (``contact.friction``: |τ| ≤ μ × the contact pressure) or
    Tresca's given bound (``contact.slip_bound``: |τ| ≤ g); ``values`` one for every crack, or one per crack in
    order along Σ."""

    coulomb: bool
    values: float | tuple[float, ...]

    @property
    def key(self) -> str:
        return "contact.friction" if self.coulomb else "contact.slip_bound"

    def per_crack(self, cracks: int) -> tuple[float, ...]:
        """The value of each of ``cracks`` cracks; a list of another length, or a mesh without cracks, is refused
        naming the key."""
        if cracks == 0:
            raise SceneError(f"{self.key}: the mesh has no crack, so there are no crack faces for friction to act on: "
                             "leave it out")
        if not isinstance(self.values, tuple):
            return (float(self.values),) * cracks
        if len(self.values) != cracks:
            raise SceneError(f"{self.key} lists {len(self.values)} values for the {cracks} crack"
                             f"{'' if cracks == 1 else 's'} of the mesh (one per crack, in order along Σ)")
        return self.values

    @classmethod
    def of(cls, contact: dict) -> Friction | None:
        """From the checked ``contact`` table; None without friction (a zero everywhere is none)."""
        for key, coulomb in (("friction", True), ("slip_bound", False)):
            values = contact[key]
            if values is not None and any(v > 0 for v in (values if isinstance(values, tuple) else (values,))):
                return cls(coulomb, values)
        return None


@dataclass(frozen=True)
class Bond:
    """The traction–separation law of ``[interface]`` on the bonded part of Σ (:mod:`ddsolve.dd.cohesive`):
    ``elastic`` (traction = ``stiffness`` × jump, no damage) or ``bilinear`` (peak ``strength`` σ_c, area
    ``toughness`` G_c, initial slope ``stiffness``; mixed mode by Benzeggagh–Kenane with ``G_IIc``, ``eta`` and
    ``shear_strength``)."""

    law: str
    stiffness: float
    strength: float | None = None
    toughness: float | None = None
    mode_mix: str | None = None
    G_IIc: float | None = None
    eta: float | None = None
    shear_strength: float | None = None

    @classmethod
    def of(cls, table: dict) -> Bond | None:
        """From the checked ``interface`` table (its stiffness filled in); None without a law."""
        return None if table["law"] is None else cls(**table)


@dataclass(frozen=True)
class Scene:
    title: str
    geometry: Geometry
    mesh: MeshOptions
    #: layer -> its material, the default of each of its regions (:meth:`material`)
    materials: dict[str, materials.Material]
    model: str  # plane_strain | plane_stress
    loads: dict[tuple[str, str], Load]  # (layer, boundary name) -> load
    nonpenetration: bool
    solver: Solver
    fracture: FractureOptions = FractureOptions()
    #: (layer, boundary name) -> prescribed displacement; ``geometry.clamped`` is the shorthand for zero.
    displacements: dict[tuple[str, str], Displacement] = field(default_factory=dict)
    #: layer -> temperature change ΔT (an expression in x and y); absent: no thermal load.
    temperature: dict[str, Expression] = field(default_factory=dict)
    #: (layer, region) -> the material of a region that overrides its layer's (``[materials.LAYER.REGION]``).
    regions: dict[tuple[str, str], materials.Material] = field(default_factory=dict)
    #: Friction on the crack faces in contact (``contact.friction`` or ``contact.slip_bound``); None: they slide freely.
    friction: Friction | None = None
    #: The cohesive (or elastic) bond on the bonded part of Σ (``[interface]``); None: a rigid bond.
    bond: Bond | None = None
    text: str = field(repr=False, default="")
    #: The text the scene was read from and the ``--set`` items applied to it, in order: what
    #: :meth:`with_` reads again, so that defaults that follow other keys follow the new values too.
    source: str = field(repr=False, default="", compare=False)
    overrides: tuple[str, ...] = field(repr=False, default=(), compare=False)
    #: Where the scene came from (named in messages) and the folder its file names are relative to.
    origin: str = field(repr=False, default="scene", compare=False)
    base: Path | None = field(repr=False, default=None, compare=False)

    @classmethod
    def load(cls, source: str | Path, overrides: dict[str, Any] | Sequence[str] = ()) -> Scene:
        """A scene from a file path or a built-in name (``ddsolve scenes``), with ``overrides``: dotted
        keys and values (``{"solver.tol": 1e-10}``) or ``KEY=VALUE`` items as ``--set`` takes them."""
        return load(source, override_items(overrides))

    def with_(self, overrides: dict[str, Any] | Sequence[str] = (), **more: Any) -> Scene:
        """This scene with some keys changed, validated as a scene file is:
        ``scene.with_({"materials.layer2.E": 20.0})`` or ``scene.with_(**{"solver.tol": 1e-10})``.
        The same scene as :meth:`load` with all the overrides: its source is read again with them, so a
        default that follows another key (``mesh.target_error`` chooses P2) follows the new value."""
        items = override_items(overrides) + override_items(more)
        return loads(self.source or self.text, [*self.overrides, *items], origin=self.origin, base=self.base)

    @property
    def layers(self) -> tuple[str, ...]:
        """The structure's layers, bottom to top (``geometry.layers`` of :data:`LAYERS`)."""
        return LAYERS[:self.geometry.layers]

    def material(self, layer: str, region: str) -> materials.Material:
        """The material of ``layer`` in ``region`` (one of ``geometry.region_names``): the region's own, else the
        layer's."""
        return self.regions.get((layer, region), self.materials[layer])

    def material_key(self, layer: str, region: str) -> str:
        """The scene key that gives :meth:`material`: ``materials.LAYER.REGION`` or ``materials.LAYER``."""
        return f"materials.{layer}.{region}" if (layer, region) in self.regions else f"materials.{layer}"

    def dissimilar_layers(self, thermal: bool = True) -> list[str]:
        """The layers whose regions have different plane laws: stiffness, and with ``thermal`` thermal strain
        (:func:`ddsolve.problem.materials.same_law`)."""
        return materials.differing({layer: [self.material(layer, region) for region in self.geometry.region_names]
                                    for layer in self.layers}, self.model, thermal)

    @property
    def proportional(self) -> bool:
        """Whether the solution scales with the mechanical loads (:meth:`scaled`): no temperature change, and no
        Tresca bound on the crack faces' friction (a given traction, which does not scale; Coulomb's does)."""
        return not self.temperature and (self.friction is None or self.friction.coulomb)

    def scaled(self, factor: float) -> Scene:
        """This scene with every mechanical load (tractions, pressures, prescribed displacements) times
        ``factor``; the temperature change (and a Tresca bound) is kept.  The contact problem is positively
        homogeneous, so where the scene is :attr:`proportional` the solution scales by ``factor`` and G by its square.  ``text`` is
        the unscaled scene's: a scaled scene is solved, not saved."""
        return dataclasses.replace(self, loads={key: load.scaled(factor) for key, load in self.loads.items()},
                                   displacements={key: displacement.scaled(factor)
                                                  for key, displacement in self.displacements.items()})


def _pieces(cracks: list) -> tuple:
    """One interface's cracks as tuples: intervals and rectangles as tuples of numbers, ellipses as they are."""
    return tuple(piece if isinstance(piece, Ellipse) else tuple(piece) for piece in cracks)


def _to_scene(data: dict, raw: dict, text: str, base: Path | None, origin: str, source: str,
              overrides: tuple[str, ...]) -> Scene:
    mesh = dict(data["mesh"])
    if mesh["file"] is not None:
        mesh["file"] = Path(mesh["file"])
        if not mesh["file"].is_absolute() and base is not None:
            mesh["file"] = base / mesh["file"]
    geometry = data["geometry"]
    given = (frozenset(raw["geometry"]) - frozenset(STRUCTURE_KEYS) if isinstance(raw.get("geometry"), dict)
             else frozenset())
    loads = {
        (layer, name): Load(key=f"loads.{layer}.{name}", **table)
        for layer, tables in data.get("loads", {}).items()
        for name, table in tables.items()
    }
    displacements = {
        (layer, name): Displacement(key=f"displacements.{layer}.{name}", **table)
        for layer, tables in data.get("displacements", {}).items()
        for name, table in tables.items()
    }
    temperature = {layer: value for layer, value in data.get("temperature", {}).items() if value is not None}
    return Scene(
        title=data["title"],
        geometry=Geometry(box=tuple(geometry["box"]), sigma=geometry["sigma"],
                          cracks=_pieces(geometry["cracks"]),
                          clamped=tuple(geometry["clamped"]), layers=geometry["layers"], given=given,
                          above=tuple((height, _pieces(cracks)) for height, cracks in geometry["above"]),
                          regions=tuple(geometry.get("regions", ())), solid_file=geometry.get("solid_file", False)),
        mesh=MeshOptions(**mesh),
        materials={layer: layer_material(data["materials"][layer]) for layer in layers_of(data)},
        regions=region_materials(data["materials"]),
        model=data["materials"]["model"],
        loads=loads,
        nonpenetration=data["contact"]["nonpenetration"],
        friction=Friction.of(data["contact"]),
        bond=Bond.of(data["interface"]),
        solver=Solver(**data["solver"]),
        fracture=FractureOptions(**{"lambda_" if key == "lambda" else key: value
                                    for key, value in data["fracture"].items()}),
        displacements=displacements,
        temperature=temperature,
        text=text,
        source=source,
        overrides=overrides,
        origin=origin,
        base=base,
    )


def _gmsh_file(raw: dict, base: Path | None) -> Path | None:
    """The scene's gmsh file (.geo, .msh), found from ``base``; None where ``mesh.file`` is no such path (its checks
    say what is wrong)."""
    mesh = raw.get("mesh")
    name = mesh.get("file") if isinstance(mesh, dict) else None
    if not isinstance(name, str) or not name.lower().endswith((".geo", ".msh")):
        return None
    return Path(name) if Path(name).is_absolute() or base is None else base / name


def _unread(path: Path) -> str:
    """Why the scene's gmsh file cannot be read, in :func:`readable`'s words."""
    try:
        readable(path, "mesh file")
    except DDSolveError as error:
        return str(error)
    return f"{printable(str(path))}: cannot read mesh file"


def builtin_folder() -> Path:
    """Where the scenes shipped with ddsolve (and their .geo files) are."""
    return Path(str(resources.files("ddsolve.problem") / "scenes"))


def builtin_scenes() -> dict[str, str]:
    """Names of the scenes shipped with ddsolve -> their TOML text."""
    return {entry.stem: entry.read_text() for entry in builtin_folder().iterdir() if entry.suffix == ".toml"}


def load(source: str | Path, overrides: list[str] = ()) -> Scene:
    """Read a scene from a file path or a built-in name, apply overrides, validate; the scene file
    and its mesh file must be readable (:func:`readable`)."""
    path = Path(source)
    shipped = builtin_scenes()
    if str(source) in shipped and not os.path.isfile(path):
        text, base = shipped[str(source)], builtin_folder()
    else:
        names = ", ".join(sorted(shipped))
        readable(path, "scene file", SceneError, f"no such scene file or built-in scene (built-in: {names})")
        text = utf8_text(path, "scene file", SceneError)
        base = path.parent
    scene = loads(text, overrides, origin=str(source), base=base)
    if scene.mesh.file is not None:
        readable(scene.mesh.file, "mesh file", SceneError)  # the scene names it: a scene error
    return scene


def _written_geometry(geometry: dict) -> dict:
    """A checked geometry table as a scene writes it: one interface as ``sigma = y``, ``cracks = [[a, b], ...]``;
    several as ``sigma = [y1, ...]``, ``cracks = [[[a, b], ...], ...]``."""
    written = {key: value for key, value in geometry.items() if key not in ("above", "regions")}
    if geometry["above"]:
        written["sigma"] = [geometry["sigma"], *(height for height, _ in geometry["above"])]
        written["cracks"] = [geometry["cracks"], *(cracks for _, cracks in geometry["above"])]
    return written


def loads(text: str, overrides: list[str] = (), origin: str = "scene", base: Path | None = None) -> Scene:
    """Parse and validate scene text."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{origin}: malformed TOML: {' '.join(str(exc).split())}") from None
    except RecursionError:  # tomllib's parser recurses into arrays and tables
        raise SceneError(f"{origin}: malformed TOML: arrays or tables nested too deeply") from None
    apply_overrides(raw, list(overrides))
    path = _gmsh_file(raw, base)
    where = f"{origin}: mesh.file {printable(raw['mesh']['file'])}" if path else origin
    names = physical_names(path, where) if path else {}
    volumes = names if names and 3 in names else None  # a 3-D gmsh file's physical groups
    structure = file_structure(names, where, 3 if volumes is not None else 2) if names else None
    solid = is_solid(raw) or volumes is not None
    try:
        data = check_table(raw, structure_schema(raw, origin, structure.regions if structure else (), solid), (),
                           origin)
        if solid:
            solid_checks(data, raw, origin, volumes, where, structure)
        else:
            cross_checks(data, raw, origin, structure)
    except SceneError as error:
        if names is None:  # the file that names the structure is not there: the error may come from its absence
            raise SceneError(f"{error}; and {_unread(path)} (its physical groups name the structure)") from None
        raise
    written = {key: value for key, value in data.items() if key != "geometry"}
    if structure or volumes:  # its text names the file wherever it is read: the file gives the structure
        written["mesh"] = {**written["mesh"], "file": str(path.absolute())}
    if structure or volumes or data["mesh"]["file"] is not None and data["mesh"]["file"].lower().endswith(".geo"):
        written["geometry"] = {key: data["geometry"][key] for key in STRUCTURE_KEYS}
    else:
        written["geometry"] = _written_geometry(data["geometry"])
    return _to_scene(data, raw, dumps(written), base, origin, text, tuple(overrides))
