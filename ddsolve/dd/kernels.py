"""Rigid-body motions the supports do not remove: the kernels of the blocks and of the glued structure.

A block's stiffness K_b is singular exactly when one of the plane rigid motions (translations in x
and y, the rotation; :func:`ddsolve.fem.assembly.rigid_body_modes`) satisfies all of its Dirichlet
conditions: its *kernel* is the span of those motions, a basis of coefficients ``(3, m)`` for the modes
about a common centre.  A block with a kernel is *floating*: its supports leave it rigid motions that
only Σ holds (no support at all, a single pin, rollers in one direction).  The structure
as a whole is supported when no combination of the four blocks' motions satisfies every support and
every gluing equality on Σ (the contact inequality on the crack faces holds nothing: the faces may part).

Constraints are nodal: dof indices ``2·node + component`` (x = 0, y = 1), and constrained directions (a
node and a unit vector d: d·u = 0, e.g. a roller, or a prescribed component of a Σ node's frame).  A
scene's constraints are the blocks' prescribed dofs (:mod:`ddsolve.fem.supports`: Γ_D, every
``[displacements.LAYER.NAME]`` component, the Σ ties) whatever their values: a kernel is a motion of the
homogeneous problem, and nonzero values are lifted into the loads.  The frame, the constraint and gluing rows
and the free motions take the dimension from the points: in 3-D six modes (translations in x, y, z, rotations
about the axes), the halves of a box (:mod:`ddsolve.solvers.solid_dd`).  No PETSc or MPI here.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ddsolve.dd.interface import Interface, for_mesh
from ddsolve.errors import SceneError
from ddsolve.fem import supports, tetra
from ddsolve.fem.assembly import rigid_body_modes, rotate_vector
from ddsolve.fem.supports import SigmaSupports
from ddsolve.mesh.mesh import BlockSpec, HalfMesh, Mesh, SigmaLine, blocks
from ddsolve.problem.scene import Scene

#: A singular value of the (scaled) constraint matrix below this fraction of the largest one is a free motion.
KERNEL_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Frame:
    """The common reference of the rigid modes: ``centre`` (rotations about it) and ``length`` (the
    rotation mode scaled by 1/length, so that the three modes have comparable sizes)."""

    centre: np.ndarray
    length: float

    def modes(self, points: np.ndarray) -> np.ndarray:
        """The modes at ``points``, rotations (scaled) about the centre: in the plane ``(3, 2n)``, translations in
        x and y and the rotation; in 3-D ``(6, 3n)``, translations in x, y and z and rotations about them."""
        if points.shape[1] == 3:
            modes = tetra.rigid_modes(points, centre=self.centre)
            modes[3:] /= self.length
            return modes
        modes = rigid_body_modes(points, centre=self.centre)
        modes[2] /= self.length
        return modes


def frame_of(points: np.ndarray) -> Frame:
    """The frame of a structure whose nodes are ``points``: its bounding-box centre and largest side."""
    low, high = points.min(axis=0), points.max(axis=0)
    return Frame(0.5 * (low + high), float(max(np.max(high - low), np.finfo(float).tiny)))


def constraint_rows(modes: np.ndarray, dofs: np.ndarray,
                    directions: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """The values ``(c, M)`` of the M modes ``(M, dim n)`` at the constrained ``dofs``, and d·mode at the
    constrained ``directions`` (nodes ``(d,)``, unit vectors ``(d, dim)``)."""
    rows = [modes[:, np.asarray(dofs, dtype=np.int64)].T]
    if directions is not None:
        nodes, vectors = directions
        dimension = 2 if len(modes) == 3 else 3  # 3 modes in the plane, 6 in 3-D
        vectors = np.asarray(vectors, dtype=np.float64).reshape(len(nodes), dimension)
        pairs = modes.reshape(len(modes), -1, dimension)[:, np.asarray(nodes, dtype=np.int64)]  # (M, d, dim)
        rows.append(np.einsum("mdc,dc->dm", pairs, vectors))
    return np.concatenate(rows, axis=0)


def null_space(matrix: np.ndarray, columns: int) -> np.ndarray:
    """Orthonormal basis ``(columns, m)`` of the null space of ``matrix`` ``(r, columns)`` (r may be 0),
    whose entries are of order one at most (values of the modes of a :class:`Frame`)."""
    if len(matrix) == 0:
        return np.eye(columns)
    # R of a QR factorization has the singular values and right singular vectors of the tall matrix, at a
    # cost linear in its rows (the full SVD of the tall matrix would make an r × r factor)
    _, values, vt = np.linalg.svd(np.linalg.qr(matrix, mode="r"), full_matrices=True)
    # entries are mode values, of order one at most: a floor of one keeps round-off out of the rank
    rank = int(np.sum(values > KERNEL_TOLERANCE * max(values.max(initial=0.0), 1.0)))
    return vt[rank:].T


def block_kernel(points: np.ndarray, dofs: np.ndarray, frame: Frame,
                 directions: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Coefficients ``(3, m)`` (modes of ``frame``) of the rigid motions of a block with nodes ``points``
    that its constrained ``dofs`` and ``directions`` do not remove: its kernel (m = 0: invertible)."""
    modes = frame.modes(points)
    return null_space(constraint_rows(modes, dofs, directions), len(modes))


def prescribed_directions(fixed: np.ndarray, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A block's prescribed dofs ``fixed`` ``(n, 2)`` in its dof ``frames`` ``(n, 2, 2)`` as constrained
    directions: nodes ``(d,)`` and unit vectors ``(d, 2)`` in x, y (:func:`constraint_rows`)."""
    nodes, axis = np.nonzero(fixed)
    return nodes, frames[nodes, axis]


def kernel_vectors(half: HalfMesh, sigma: SigmaLine, coefficients: np.ndarray, frame: Frame) -> np.ndarray:
    """The kernel ``(m, 2n)`` of a block on ``half`` in its own dofs: the modes combined by ``coefficients``,
    rotated into the local frames at its trace nodes (as :func:`ddsolve.fem.assembly.block_system` numbers them)."""
    vectors = (frame.modes(half.points).T @ coefficients).T
    nodes = sigma.multiplier_nodes
    return np.array([rotate_vector(v, half.sigma[nodes], sigma.frames[nodes]) for v in vectors]).reshape(len(vectors), -1)


def trace_modes(sigma: SigmaLine, frame: Frame) -> np.ndarray:
    """``(2k, 3)``: the traces of the three modes (the same for every block), in the nodes' local frames."""
    nodes = sigma.multiplier_nodes
    modes = frame.modes(sigma.points[nodes])
    return np.array([rotate_vector(mode, np.arange(len(nodes)), sigma.frames[nodes]) for mode in modes]).T


def gluing_rows(interface: Interface, traces: np.ndarray) -> np.ndarray:
    """``(equalities, blocks·M)``: the gluing gaps (every multiplier row but the contact ones) of rigid motions
    of the blocks with mode traces ``traces`` ``(trace size, M)``, per block coefficient."""
    size = traces.shape[1]
    rows = np.zeros((interface.size, len(interface.blocks), size))
    for block, coupling in enumerate(interface.couplings):
        rows[coupling.rows, block] += coupling.sign[:, None] * traces[coupling.trace]
    return rows[~interface.is_contact].reshape(-1, size * len(interface.blocks))


def structure_kernel(blocks: list[np.ndarray], interface: Interface, sigma: SigmaLine, frame: Frame) -> np.ndarray:
    """``(blocks·3, m)``: the rigid motions of the blocks (coefficients per block, in ``frame``) that satisfy
    every support (``blocks``: each block's constraint rows ``(c, 3)``, :func:`constraint_rows`) and every
    gluing equality: the free motions of the structure."""
    return free_motions(blocks, gluing_rows(interface, trace_modes(sigma, frame)))


def free_motions(blocks: list[np.ndarray], gluing: np.ndarray) -> np.ndarray:
    """``(blocks·M, m)``: the rigid motions of the blocks that satisfy each block's constraint rows ``blocks``
    ``(c, M)`` and the ``gluing`` rows ``(equalities, blocks·M)``."""
    count, size = len(blocks), blocks[0].shape[1]
    supports = np.zeros((sum(len(rows) for rows in blocks), size * count))
    start = 0
    for block, rows in enumerate(blocks):
        supports[start:start + len(rows), size * block:size * (block + 1)] = rows
        start += len(rows)
    return null_space(np.vstack([supports, gluing]), size * count)


def refuse_motion(kernel: np.ndarray, frame: Frame, specs: tuple[BlockSpec, ...]) -> None:
    """A SceneError naming the free motion when the structure kernel ``kernel`` of the blocks ``specs`` is not
    zero (the structure is not supported)."""
    if kernel.shape[1]:
        motion = describe(kernel, frame, specs)
        error = SceneError(f"{motion}: add a support (geometry.clamped, a clamped boundary in the mesh, or "
                           "[displacements.LAYER.NAME])")
        error.free_motion = motion  # what a caller that changes the cracks reports (ddsolve grow)
        raise error


def describe(kernel: np.ndarray, frame: Frame, specs: tuple[BlockSpec, ...] = blocks(2)) -> str:
    """What a nonzero structure kernel ``(blocks·3, m)`` of the blocks ``specs`` lets move, in words: a rigid
    motion of the whole structure if there is one (translations first), else the blocks that move relative to
    the rest."""
    count = len(specs)
    size = kernel.shape[0] // count  # M modes: 3 in the plane, 6 in 3-D
    together = np.tile(np.eye(size), (count, 1))  # (blocks·M, M): one rigid motion of every block
    projector = np.eye(size * count) - kernel @ kernel.T
    common = null_space(projector @ together, size)  # (M, g): motions of the whole structure in the kernel
    if common.shape[1]:
        for axis, name in enumerate("xyz"[:len(frame.centre)]):
            unit = np.eye(size)[axis]
            if np.linalg.norm(unit - common @ (common.T @ unit)) < 1e-6:
                return f"the structure can translate in {name}"
        motion = common[:, 0]
        return "the structure can " + _motion(motion, frame)
    motions = kernel.reshape(count, size, -1)  # per block, the span of its part of every free motion
    moving = [spec.name for spec, part in zip(specs, motions) if np.linalg.norm(part) > 1e-6]
    span = motions[[spec.name for spec in specs].index(moving[0])]
    return f"blocks {', '.join(moving)} can {_motions(span, frame)} relative to the rest"


def _motions(span: np.ndarray, frame: Frame) -> str:
    """The rigid motions of a block whose coefficients span ``span`` ``(M, m)``, in words: every motion,
    both translations, one direction of translation, or a rotation about a point (in 3-D: how many motions)."""
    basis = null_space(null_space(span.T, len(span)).T, len(span))  # orthonormal basis of the span
    if len(span) == 6:
        return _motion(basis[:, 0], frame) if basis.shape[1] == 1 else f"move rigidly ({basis.shape[1]} of six motions)"
    if basis.shape[1] == 3:
        return "translate and rotate freely"
    if basis.shape[1] == 2 and np.linalg.norm(basis[2]) < 1e-6:
        return "translate in x and y"
    if basis.shape[1] == 2:
        return f"{_motion(basis[:, 0], frame)} and {_motion(basis[:, 1], frame)}"
    return _motion(basis[:, 0], frame)


def _motion(coefficients: np.ndarray, frame: Frame) -> str:
    """A rigid motion (tx, ty, ω/length about the centre; in 3-D tx, ty, tz, ω/length) in words."""
    if len(coefficients) == 6:
        return _motion_3d(coefficients)
    tx, ty, omega = coefficients
    omega = omega / frame.length
    if abs(omega) * frame.length < 1e-6 * max(abs(tx), abs(ty)):
        direction = np.array([tx, ty]) / np.hypot(tx, ty)
        if direction[0] < -1e-12 or (abs(direction[0]) <= 1e-12 and direction[1] < 0):
            direction = -direction  # a line of motion: either sign
        return f"translate along ({direction[0] + 0.0:.3g}, {direction[1] + 0.0:.3g})"
    # velocity (tx − ω(y − cy), ty + ω(x − cx)) vanishes at the centre of rotation
    x, y = frame.centre[0] - ty / omega, frame.centre[1] + tx / omega
    return f"rotate about ({x + 0.0:.6g}, {y + 0.0:.6g})"


def _motion_3d(coefficients: np.ndarray) -> str:
    """A 3-D rigid motion (tx, ty, tz, ω/length) in words: a translation, or a rotation about an axis's direction."""
    translation, rotation = coefficients[:3], coefficients[3:]
    moving = translation if np.linalg.norm(rotation) < 1e-6 * np.linalg.norm(translation) else rotation
    direction = moving / np.linalg.norm(moving)
    direction[np.abs(direction) < 1e-9] = 0.0  # round-off off the axes
    first = direction[np.flatnonzero(direction)[0]]
    direction = direction if first > 0 else -direction  # a line: either sign
    words = "translate along" if moving is translation else "rotate about an axis along"
    return f"{words} ({', '.join(f'{value + 0.0:.3g}' for value in direction)})"


@dataclass(frozen=True)
class Kernels:
    """The kernels of the blocks ``specs``, ``(3, m_b)`` coefficients in ``frame`` (m_b = 0: invertible)."""

    kernels: list[np.ndarray]
    frame: Frame
    specs: tuple[BlockSpec, ...] = blocks(2)

    @property
    def floating(self) -> list[int]:
        """The blocks with a kernel."""
        return [block for block, kernel in enumerate(self.kernels) if kernel.shape[1]]

    def names(self) -> str:
        return ", ".join(self.specs[block].name for block in self.floating)


def block_kernels(halves: dict[int, HalfMesh], sigma: SigmaLine, interface: Interface,
                  constraints: list[tuple[np.ndarray, np.ndarray]]) -> Kernels:
    """The blocks' kernels under their ``constraints`` (per block of ``interface.blocks``, the constrained directions
    of :func:`prescribed_directions`); a SceneError naming the free motion when the structure as a whole
    is not supported (its rigid motions are not all removed by the supports and the gluing together)."""
    frame = frame_of(np.vstack([half.points for half in halves.values()]))
    rows = [constraint_rows(frame.modes(halves[spec.side].points), np.zeros(0, dtype=np.int64), directions)
            for spec, directions in zip(interface.blocks, constraints)]
    return held_kernels(rows, trace_modes(sigma, frame), interface, frame)


def held_kernels(rows: list[np.ndarray], traces: np.ndarray, interface: Interface, frame: Frame) -> Kernels:
    """The blocks' kernels under their constraint ``rows`` ``(c, M)`` (:func:`constraint_rows`), the modes'
    ``traces`` ``(trace size, M)`` gluing them; a SceneError naming the free motion when the structure as a whole
    is not supported."""
    refuse_motion(free_motions(rows, gluing_rows(interface, traces)), frame, interface.blocks)
    return Kernels([null_space(block_rows, block_rows.shape[1]) for block_rows in rows], frame, interface.blocks)


def of_scene(scene: Scene, mesh: Mesh, table: SigmaSupports) -> Kernels:
    """The blocks' kernels under the scene's supports (each block's prescribed dofs, with the Σ ties of
    ``table``, :func:`ddsolve.fem.supports.block_supports`); refuses a structure that can move rigidly."""
    constraints, specs = [], blocks(scene.geometry.layers)
    for block, spec in enumerate(specs):
        half = mesh.half(spec.side)
        fixed, _ = supports.block_supports(scene, half, mesh.sigma, spec.layer, block, table)
        constraints.append(prescribed_directions(fixed, supports.node_frames(half, mesh.sigma)))
    interface = for_mesh(mesh.sigma, scene.nonpenetration, table.fixed, specs=specs)
    return block_kernels({-1: mesh.lower, 1: mesh.upper}, mesh.sigma, interface, constraints)


def fixing_dofs(vectors: np.ndarray, excluded: np.ndarray) -> np.ndarray:
    """m dofs of a floating block (not ``excluded``) at which its kernel ``vectors`` ``(m, 2n)`` are
    independent, chosen far apart (QR with column pivoting): fixing them leaves an invertible matrix."""
    import scipy.linalg

    allowed = np.ones(vectors.shape[1], dtype=bool)
    allowed[np.asarray(excluded, dtype=np.int64)] = False
    candidates = np.flatnonzero(allowed)
    _, _, pivots = scipy.linalg.qr(vectors[:, candidates], pivoting=True, mode="economic")
    return np.sort(candidates[pivots[:len(vectors)]])
