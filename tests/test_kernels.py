"""Rigid-body kernels of the blocks and of the glued structure (issue 18: floating blocks)."""
from __future__ import annotations

import numpy as np
import pytest
from conftest import MATERIALS, structured_mesh

from ddsolve.dd import kernels
from ddsolve.dd.interface import for_mesh
from ddsolve.errors import SceneError
from ddsolve.fem import supports
from ddsolve.mesh import geometry
from ddsolve.problem import scene
from ddsolve.problem.scene import Geometry


def grid(nx: int = 5, ny: int = 3) -> np.ndarray:
    x, y = np.meshgrid(np.linspace(0.0, 4.0, nx), np.linspace(0.0, 1.0, ny))
    return np.column_stack([x.ravel(), y.ravel()])


def dofs_of(nodes: np.ndarray) -> np.ndarray:
    return np.stack([2 * nodes, 2 * nodes + 1], axis=1).ravel()


def test_a_block_clamped_on_one_side_has_no_kernel():
    points = grid()
    frame = kernels.frame_of(points)
    bottom = np.flatnonzero(points[:, 1] == 0.0)
    assert kernels.block_kernel(points, dofs_of(bottom), frame).shape == (3, 0)


def test_a_block_without_supports_has_the_three_rigid_motions():
    points = grid()
    kernel = kernels.block_kernel(points, np.zeros(0, dtype=np.int64), kernels.frame_of(points))
    assert kernel.shape == (3, 3)
    assert np.allclose(kernel.T @ kernel, np.eye(3))


def test_a_single_clamped_node_leaves_the_rotation_about_it():
    points = grid()
    frame = kernels.frame_of(points)
    node = 7  # (2, 0.5)
    kernel = kernels.block_kernel(points, dofs_of(np.array([node])), frame)
    assert kernel.shape == (3, 1)
    motion = (frame.modes(points).T @ kernel[:, 0]).reshape(-1, 2)
    assert np.allclose(motion[node], 0.0, atol=1e-14)
    radius = points - points[node]
    assert np.allclose(np.einsum("nc,nc->n", motion, radius), 0.0, atol=1e-14)  # perpendicular: a rotation
    whole = np.zeros(12)
    whole[:3] = kernel[:, 0]
    assert kernels.describe(whole[:, None], frame).endswith("rotate about (2, 0.5) relative to the rest")


def test_a_roller_direction_removes_one_translation():
    points = grid()
    frame = kernels.frame_of(points)
    bottom = np.flatnonzero(points[:, 1] == 0.0)
    rollers = (bottom, np.tile([0.0, 1.0], (len(bottom), 1)))  # y = 0 along the bottom: x and nothing else free
    kernel = kernels.block_kernel(points, np.zeros(0, dtype=np.int64), frame, directions=rollers)
    assert kernel.shape == (3, 1) and np.allclose(np.abs(kernel[:, 0]), [1.0, 0.0, 0.0])


def structure(clamped: tuple[str, ...], cracks=((-0.5, 0.5),)):
    mesh = structured_mesh(8, 4, geometry=Geometry(cracks=cracks, clamped=clamped))
    return mesh, for_mesh(mesh.sigma, True)


SQUARE = """
[geometry]
crack = [-0.5, 0.5]
clamped = %s
[mesh]
size = 0.5
""" + MATERIALS

#: Both layers on a roller (u_y = 0) on the left and on the right side.
ROLLERS = "".join(f"[displacements.{layer}.{side}]\ny = 0.0\n" for layer in ("layer1", "layer2")
                  for side in ("left", "right"))


def scene_kernels(clamped: str, displacements: str = "") -> kernels.Kernels:
    """The blocks' kernels of the paper's square with these supports, as the solvers find them."""
    source = scene.loads(SQUARE % clamped + displacements)
    mesh = geometry.build(source)
    return kernels.of_scene(source, mesh, supports.check(source, mesh))


def test_the_paper_square_is_supported_with_no_floating_block():
    assert scene_kernels('["left", "right"]').floating == []


def test_a_half_held_only_by_the_glue_floats_but_the_structure_is_supported():
    found = scene_kernels('["bottom"]')
    assert found.floating == [1, 3] and found.names() == "u_plus, v_plus"
    assert all(found.kernels[block].shape == (3, 3) for block in (1, 3))


def test_a_half_on_a_roller_floats_along_it():
    """The upper half's top side on a roller (u_y = 0): its blocks can translate in x only."""
    found = scene_kernels('["bottom"]', "".join(f"[displacements.{layer}.top]\ny = 0.001\n"
                                                 for layer in ("layer1", "layer2")))
    assert found.floating == [1, 3]
    assert all(np.allclose(np.abs(found.kernels[block][:, 0]), [1.0, 0.0, 0.0]) for block in (1, 3))


def test_a_pin_and_a_roller_hold_every_block():
    pinned = ROLLERS.replace("[displacements.layer1.left]\n", "[displacements.layer1.left]\nx = 0.0\n")
    assert scene_kernels("[]", pinned).floating == []


@pytest.mark.parametrize("clamped, displacements, message", [
    ("[]", "", "the structure can translate in x"),
    ("[]", ROLLERS, "the structure can translate in x"),
])
def test_a_structure_without_supports_is_refused_naming_the_motion(clamped, displacements, message):
    with pytest.raises(SceneError, match=message + ": add a support"):
        scene_kernels(clamped, displacements)


def test_a_structure_pinned_at_one_node_can_rotate_about_it():
    mesh, interface = structure(())
    frame = kernels.frame_of(np.vstack([mesh.lower.points, mesh.upper.points]))
    pin = int(np.argmin(np.hypot(*(mesh.lower.points - [-1.0, -1.0]).T)))  # the corner (-1, -1)
    rows = [kernels.constraint_rows(frame.modes(mesh.half(side).points),
                                    dofs_of(np.array([pin])) if side < 0 else np.zeros(0, dtype=np.int64))
            for side in (-1, 1, -1, 1)]
    kernel = kernels.structure_kernel(rows, interface, mesh.sigma, frame)
    assert kernel.shape[1] == 1
    assert kernels.describe(kernel, frame) == "the structure can rotate about (-1, -1)"


def test_fixing_dofs_leave_the_kernel_independent():
    points = grid()
    frame = kernels.frame_of(points)
    vectors = frame.modes(points)
    fixed = kernels.fixing_dofs(vectors, excluded=np.arange(4))
    assert len(fixed) == 3 and not np.isin(fixed, np.arange(4)).any()
    assert abs(np.linalg.det(vectors[:, fixed])) > 1e-3
