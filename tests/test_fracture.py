"""The energy release rate G at the crack tips: the discrete derivative of the energy, finite differences
with re-meshing, independence of the θ radii, a centre crack in a plate against the handbook value,
curved Σ with contact, the tips and radii themselves, and G through the parallel solve and the files."""
from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import MATERIALS, ddsolve, solved_reference

from ddsolve.errors import SceneError
from experiments.fracture import PLATE, example_scene, handbook, plate_scene
from ddsolve.io import hdf5, save
from ddsolve.mesh import geometry
from ddsolve.mesh.mesh import HalfMesh, make_mesh
from ddsolve.post import fracture
from ddsolve.problem import scene
from ddsolve.solvers import reference

SMALL = ["mesh.sigma_vertices=25", "mesh.boundary_vertices=48"]
#: A small graded mesh: P2, size 0.01 at the tips growing to 0.1, tips in patches meshed apart.
GRADED = {"h_tip": 0.01, "h_far": 0.1, "fine": 0.02, "grow": 0.12, "patch": 0.2}


def solved(source: scene.Scene):
    return reference.solve_monolithic(source, geometry.build(source))


@pytest.mark.solve
def test_the_reference_presses_only_where_the_faces_touch():
    """Open crack nodes carry no contact pressure, exactly, not the residuals' round-off: ``mu_c > 0`` in a
    user's script finds the contact zone the solver prints."""
    result = solved(scene.load("partial-closure", SMALL))
    pressure = np.asarray(result.multipliers["mu_c"])
    assert np.count_nonzero(pressure) == result.attrs["closed_vertices"] > 0


def moved(mesh, tip, step: float, normals: np.ndarray | None = None):
    """The mesh with every node moved by step·θ (θ of ``tip``); the same cells, flags and, if given, normals."""
    halves = [HalfMesh(h.points + step * fracture.theta(tip, mesh.sigma, h.points), h.cells, h.side, h.sigma,
                       h.boundaries) for h in mesh.halves]
    return make_mesh(*halves, "moved", exact_normals=normals)


@pytest.mark.solve
@pytest.mark.parametrize("name, degree", [("partial-closure", 1), ("full-opening", 1), ("partial-closure", 2),
                                          ("linear", 2)])
def test_g_is_the_derivative_of_the_discrete_energy(name, degree):
    """Moving the nodes by ±δθ: −ΔΠ/2δ equals G at every tip to 1e-6 of the largest G (P1 and P2, open,
    closed and overlapping tips)."""
    source = scene.load(name, [*SMALL, f"mesh.degree={degree}"])
    mesh = geometry.build(source)
    result = reference.solve_monolithic(source, mesh)
    G = result.fracture.G
    step = 1e-4
    for tip, rate in zip(fracture.find_tips(mesh), G):
        energies = [reference.solve_monolithic(source, moved(mesh, tip, s)).attrs["energy"] for s in (step, -step)]
        assert -(energies[0] - energies[1]) / (2 * step) == pytest.approx(rate, abs=1e-6 * np.abs(G).max())


@pytest.mark.solve
@pytest.mark.parametrize("degree", [1, 2])
def test_curved_sigma_with_contact_needs_the_turning_normals(degree):
    """On the arc (arc-bond.geo, P1 and curved P2) with layer 1 pressed (a pressure on top and bottom) the faces
    touch along the whole crack: G equals the derivative of the discrete energy when the nodes move along Σ and
    their normals turn with them, at both tips, and the contact term (the work on the turning normals) is far
    larger than that agreement."""
    source = scene.load("arc-bond", ["mesh.size=0.1", f"mesh.degree={degree}",
                                     "loads.layer1.bottom={pressure = 0.05}", "loads.layer1.top={pressure = 0.05}"])
    mesh = geometry.build(source)
    result = reference.solve_monolithic(source, mesh)
    assert len(result.fracture.zones) == 1
    sigma = mesh.sigma
    turning = np.gradient(sigma.normals, sigma.arclength, axis=0)
    step, tolerance = 1e-5, 1e-5
    scale = np.abs(result.fracture.G).max()
    for tip, rate, contact in zip(fracture.find_tips(mesh), result.fracture.G, result.fracture.contact):
        speed = np.einsum("kd,kd->k", fracture.theta(tip, sigma, sigma.points), sigma.frames[:, 0])
        energies = []
        for s in (step, -step):
            normals = sigma.normals + s * speed[:, None] * turning
            energies.append(reference.solve_monolithic(source, moved(mesh, tip, s, normals)).attrs["energy"])
        assert -(energies[0] - energies[1]) / (2 * step) == pytest.approx(rate, abs=tolerance * scale)
        assert abs(contact) > 1000 * tolerance * scale


@pytest.mark.solve
@pytest.mark.parametrize("example", [1, 2])
def test_finite_differences_with_remeshing(tmp_path, example):
    """Extending the open tip by ±δ on re-meshed graded meshes (P2): −(Π(a + δ) − Π(a − δ))/2δ within 2 %
    of G (1341 nodes per half; the examples' fine meshes agree to 1 %, docs/fracture.md)."""
    delta = 0.05
    central = solved(example_scene(example, (-0.5, 0.5), tmp_path, sizes=GRADED))
    longer = solved(example_scene(example, (-0.5 - delta, 0.5), tmp_path, sizes=GRADED)).attrs["energy"]
    shorter = solved(example_scene(example, (-0.5 + delta, 0.5), tmp_path, sizes=GRADED)).attrs["energy"]
    G = central.fracture.G[0]
    assert G > 0
    assert -(longer - shorter) / (2 * delta) == pytest.approx(G, rel=0.02)


@pytest.mark.solve
@pytest.mark.parametrize("name", ["partial-closure", "full-opening"])
def test_three_radii_agree(name):
    """On the built-in mesh (P2, P = 49) three pairs of θ radii give G within 0.5 % at open tips; a closed
    tip's G is zero to 1e-3 of the open ones with every pair (the discretization error)."""
    result = solved(scene.load(name, ["mesh.sigma_vertices=49", "mesh.boundary_vertices=80", "mesh.degree=2"]))
    values = np.array([fracture.evaluate(result, inner, outer).G for inner, outer in ((0.05, 0.1), (0.1, 0.2),
                                                                                       (0.2, 0.4))])
    scale = np.abs(values).max()
    for column in values.T:
        if np.abs(column).max() > 1e-2 * scale:
            assert np.ptp(column) < 0.005 * np.abs(column).max()
        else:
            assert np.abs(column).max() < 1e-3 * scale


@pytest.mark.solve
def test_centre_crack_in_a_plate(tmp_path):
    """Two identical layers under the same remote tension: G at each tip is the sum of the two single-plate
    values 2πσ²a/E′·F(a/W)² within 2 % on a small P2 mesh; under compression the faces close and G vanishes."""
    plate = dict(PLATE, h_tip=0.01, h_far=0.25)
    expected = handbook(plate, 0.0)["tada"]
    tension = solved(plate_scene(tmp_path, ("left",), 0.05, 0.0, 1.0, plate=plate))
    assert tension.fracture.G == pytest.approx([expected, expected], rel=0.02)
    assert len(tension.fracture.zones) == 0
    compression = solved(plate_scene(tmp_path, ("left",), 0.05, 0.0, -1.0, plate=plate))
    assert np.abs(compression.fracture.G).max() < 1e-6 * expected
    assert len(compression.fracture.zones) == 1


def test_handbook_values():
    """Tada's factor lies between the infinite plate and Feddersen's secant for a/W = 0.2."""
    values = handbook({"W": 1.0, "a": 0.2, "E": 1.0, "stress": 1.0}, 0.0)
    assert values["infinite"] == pytest.approx(0.4 * math.pi)
    assert values["infinite"] < values["tada"] < values["feddersen"]
    assert values["feddersen"] / values["infinite"] == pytest.approx(1.0 / math.cos(0.1 * math.pi))


def test_tips_directions_and_radii():
    """The paper's square: two tips extending outwards, radii from the clamped sides (half of 1/2, then half
    again); an edge crack has one tip; several cracks each have their own."""
    mesh = geometry.build(scene.load("partial-closure", SMALL))
    tips = fracture.find_tips(mesh)
    assert [tuple(t.point) for t in tips] == [(-0.5, 0.0), (0.5, 0.0)]
    assert [tuple(t.direction) for t in tips] == [(-1.0, 0.0), (1.0, 0.0)]
    assert [(t.inner, t.outer) for t in tips] == [(0.125, 0.25)] * 2
    assert "outer boundary" in tips[0].obstacle
    edge = geometry.build(scene.loads(f'[geometry]\nbox = [0.0, 4.0, -1.0, 1.0]\ncracks = [[3.0, 4.0]]\n'
                                      f'clamped = ["left"]\n[mesh]\nsize = 0.25\n{MATERIALS}'))
    (tip,) = fracture.find_tips(edge)
    assert tuple(tip.point) == (3.0, 0.0) and tuple(tip.direction) == (-1.0, 0.0)
    several = geometry.build(scene.loads(f'[geometry]\nbox = [0.0, 8.0, -0.5, 0.5]\ncracks = [[1.0, 2.0], '
                                         f'[3.5, 4.5]]\nclamped = ["left"]\n[mesh]\nsize = 0.1\n{MATERIALS}'))
    tips = fracture.find_tips(several)
    assert [t.crack for t in tips] == [0, 0, 1, 1]
    assert all(t.outer <= 0.5 * 0.5 + 1e-12 for t in tips)  # half the distance to the top and bottom sides


@pytest.mark.solve
def test_coarse_tips_are_flagged():
    """Fewer than two Σ edges within the inner radius: the printed line says so; a finer mesh does not."""
    coarse = solved(scene.load("partial-closure", ["mesh.sigma_vertices=13", "mesh.boundary_vertices=32"]))
    assert coarse.fracture.spacing == pytest.approx([1 / 6, 1 / 6])
    assert all("elements within the inner radius: refine near this tip" in line
               for line in coarse.fracture.lines()[:2])
    fine = solved(scene.load("partial-closure", ["mesh.sigma_vertices=49", "mesh.boundary_vertices=80"]))
    assert not any("refine" in line for line in fine.fracture.lines())


def test_given_radii_are_checked():
    """[fracture] radii are used as given; a disc reaching the boundary or inner ≥ outer is a one-line error."""
    mesh = geometry.build(scene.load("partial-closure", SMALL))
    assert {(t.inner, t.outer) for t in fracture.find_tips(mesh, 0.1, 0.3)} == {(0.1, 0.3)}
    with pytest.raises(SceneError, match=r"fracture\.outer = 0\.6: .*reaches the outer boundary"):
        fracture.find_tips(mesh, None, 0.6)
    with pytest.raises(SceneError, match=r"fracture\.inner = 0\.3 must be below"):
        scene.load("partial-closure", ["fracture.inner=0.3", "fracture.outer=0.2"])
    with pytest.raises(SceneError, match=r"fracture\.inner = 0\.3 must be below the outer radius 0\.25"):
        fracture.find_tips(mesh, 0.3, None)


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 4])
def test_parallel_solve_writes_and_prints_g(tmp_path, ranks):
    """The DD solve sums the blocks' terms from the ranks that own them: the same G as the reference to 1e-8,
    printed per tip, stored in /fracture with the contact zones, the opening and the pressure along Σ."""
    out, ref = tmp_path / "dd.h5", tmp_path / "ref.h5"
    sets = [part for item in SMALL for part in ("--set", item)]
    run = ddsolve("solve", "partial-closure", *sets, "-o", str(out), ranks=ranks)
    solved_reference("partial-closure", *sets, "-o", str(ref))
    dd, exact = hdf5.read(out), hdf5.read(ref)
    assert dd.fracture.G == pytest.approx(exact.fracture.G, abs=1e-8 * np.abs(exact.fracture.G).max())
    assert run.stdout.count("G at tip") == 2 and "crack faces in contact" in run.stdout
    np.testing.assert_array_equal(dd.fracture.points, [[-0.5, 0.0], [0.5, 0.0]])
    assert len(dd.fracture.zones) == 1 and dd.fracture.zone_crack.tolist() == [0]
    import h5py

    with h5py.File(out) as f:
        opening, pressure = f["fracture/opening"][()], f["fracture/pressure"][()]
        arc = f["fracture/arclength"][()]
    start, end = dd.fracture.zones[0]
    touching = (arc >= start) & (arc <= end)
    assert np.all(np.abs(opening[touching]) < 1e-9 * np.abs(opening).max()) and np.all(pressure[touching] >= 0)


@pytest.mark.mpi
def test_bad_radius_is_one_line(tmp_path):
    run = ddsolve("solve", "partial-closure", "--set", "fracture.outer=0.7", "-o", str(tmp_path / "x.h5"),
                  ranks=2, check=False)
    assert run.returncode == 1
    assert run.stderr.strip().splitlines() == [
        "ddsolve: error: fracture.outer = 0.7: the θ disc around the crack tip at (-0.5, 0) reaches the outer "
        "boundary (at distance 0.5); θ must vanish there"]
    assert not (tmp_path / "x.h5").exists()


@pytest.mark.solve
def test_faces_without_non_penetration_overlap_rather_than_touch(tmp_path, monkeypatch):
    """Without non-penetration (the linear problem) the faces pass through each other on the right part of
    the crack: no contact zone, an overlap zone there instead (negative opening throughout), which the summary
    and the crack-face picture call an overlap, not contact, and the file keeps; Example 1 touches there."""
    from matplotlib.figure import Figure

    from ddsolve.post import plots

    linear = solved(scene.load("linear", SMALL))
    f = linear.fracture
    assert len(f.zones) == 0 and f.overlap_crack.tolist() == [0]
    (start, end), = f.overlaps
    arc = linear.mesh.sigma.arclength[linear.multiplier_nodes]
    inside = (arc >= start) & (arc <= end)
    assert inside.sum() > 3 and np.all(linear.on_sigma.opening[inside] < 0.0)
    text = "\n".join(f.lines())
    assert "in contact" not in text
    assert f"crack faces overlap (no non-penetration condition; arc length along Σ): [{start:.4g}, {end:.4g}] on " \
           "crack 0" in text
    save(linear, tmp_path / "linear.h5")
    back = hdf5.read(tmp_path / "linear.h5").fracture
    np.testing.assert_array_equal(back.overlaps, f.overlaps)
    assert len(back.zones) == 0 and back.overlap_crack.tolist() == [0]
    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda figure, *args, **kwargs: saved.append(figure))
    plots.crack_faces(linear, tmp_path / "faces.png")
    label = saved[-1].axes[-1].get_xlabel()
    assert "orange: faces overlap" in label and "contact" not in label

    closed = solved(scene.load("partial-closure", SMALL))
    contact = closed.fracture
    assert len(contact.zones) == 1 and len(contact.overlaps) == 0
    assert "crack faces in contact" in contact.lines()[-1] and "overlap" not in "\n".join(contact.lines())
    plots.crack_faces(closed, tmp_path / "contact.png")
    assert "red: faces in contact" in saved[-1].axes[-1].get_xlabel()


@pytest.mark.mpi
def test_two_ranks_say_where_free_faces_overlap(tmp_path):
    """``solve -n 2 linear``: the summary says where the faces overlap and claims no contact; the file written
    by the ranks holds the reference's overlap zone and no contact zone."""
    sets = [part for item in SMALL for part in ("--set", item)]
    run = ddsolve("solve", "linear", *sets, "-o", str(tmp_path / "dd.h5"), ranks=2)
    dd = hdf5.read(tmp_path / "dd.h5").fracture
    exact = solved(scene.load("linear", SMALL)).fracture
    assert "crack faces in contact" not in run.stdout
    assert run.stdout.count("crack faces overlap (no non-penetration condition; arc length along Σ)") == 1
    assert len(dd.zones) == 0 and dd.overlap_crack.tolist() == exact.overlap_crack.tolist() == [0]
    np.testing.assert_allclose(dd.overlaps, exact.overlaps, rtol=1e-12)
