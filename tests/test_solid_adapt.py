"""mesh.target_error on a 3-D box (ddsolve.solvers.solid_adapt): levels meshed again by gmsh until the estimate is at
most the target, the reference and the DD ending on one mesh with one solution; bad input refused in one line."""
import numpy as np
import pytest
from mpi4py import MPI
from test_solid_estimate import cube

from ddsolve.errors import SceneError
from ddsolve.mesh.solid import assemble, signed_volumes
from ddsolve.post.estimate import Estimate
from ddsolve.problem.scene import loads
from ddsolve.solvers import solid, solid_adapt, solid_dd

BOX = """
[geometry]
box = [-1, 1, -1, 1, 0, 0.5]
crack = [-0.5, 0.5]
[mesh]
size = 0.5
{mesh}
[materials.layer1]
E = 200.0
nu = 0.28
[loads.layer1.top]
y = [0.078125]
[loads.layer1.bottom]
y = [-0.078125]
[displacements.layer1.front]
z = 0.0
[displacements.layer1.back]
z = 0.0
"""


@pytest.mark.unit
def test_target_error_chooses_p2_and_grading_and_refuses_extrusion():
    scene = loads(BOX.format(mesh="target_error = 0.2"))
    assert (scene.mesh.degree, scene.mesh.target_error) == (2, 0.2) and scene.mesh.grading is not None
    assert loads(BOX.format(mesh="target_error = 0.2\ndegree = 1\ngrading = false")).mesh.grading is None
    for mesh, key in (("target_error = 0.2\nextrude = 2", "mesh.target_error: "),
                      ("target_error = 0", "mesh.target_error must be")):
        with pytest.raises(SceneError, match=key) as refused:
            loads(BOX.format(mesh=mesh))
        assert "\n" not in str(refused.value)


@pytest.mark.solve
def test_levels_reach_the_target_and_the_dd_ends_on_the_references_mesh():
    scene = loads(BOX.format(mesh="target_error = 0.3\ndegree = 1"))
    lines = []
    reference = solid_adapt.solve_adaptively(scene, MPI.COMM_SELF, lambda mesh: solid.reference_on(scene, mesh),
                                             None, lines.append)
    assert len(lines) >= 2 and all(line.startswith(f"level {k}: ") for k, line in enumerate(lines))
    assert float(lines[-1].split("estimated error ")[1].split(" %")[0]) <= 30.0
    assert float(lines[0].split("estimated error ")[1].split(" %")[0]) > 30.0
    assert reference.attrs["levels"] == len(lines) and reference.levels["error_estimate"][-1] <= 0.3
    assert reference.levels["unknowns"][-1] == reference.mesh.unknowns
    decomposed = solid_adapt.solve_adaptively(scene, MPI.COMM_SELF, lambda mesh: solid_dd.solve(
        scene, MPI.COMM_SELF, None, lambda _line: None, mesh), None, lambda _line: None)
    assert solid.comparison(decomposed, reference)[0] < 1e-8


@pytest.mark.unit
def test_a_uniform_error_density_asks_for_uniform_sizes_that_meet_the_target():
    """η_K² = c h^(2p) V_K everywhere: one size s with Σ c s^(2p) V = η_T², and the unknowns scaled by (h/s)³."""
    points, cells = cube(4, 1)
    upper = points[cells].mean(axis=1)[:, 1] > 0.5
    mesh = assemble(points, cells, upper, (0.0, 1.0, 0.0, 1.0, 0.0, 1.0), 0.5, (), degree=2)
    h = 0.25 * (3 + 2 * 2 ** 0.5 + 3 ** 0.5) / 6  # the mean edge of Kuhn's tetrahedra in a cube of side 0.25
    c, energy, target = 3.0, 2.0, 0.05
    indicators = {half.name: np.sqrt(c * h ** 4 * np.abs(signed_volumes(half.points, half.tetrahedra[:, :4])))
                  for half in mesh.halves}
    field, predicted = solid_adapt.planned(mesh, Estimate(indicators, energy), target, 1.0, 1e-4)
    aim = target / solid_adapt.SAFETY
    size = (aim ** 2 * energy / (1 - aim ** 2) / c) ** 0.25  # the box's volume is 1
    assert field.sizes[np.unique(field.tetrahedra)] == pytest.approx(size, rel=1e-3)
    assert predicted == pytest.approx(mesh.unknowns * (h / size) ** 3, rel=1e-9)
