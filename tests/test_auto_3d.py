"""``auto`` in a 3-D box (ddsolve/dd/solid_costs.py): the candidates, the choice the fitted laws make on small and
large boxes, and what the scene's keys, the ranks and the memory limit leave to it (no timing decides these)."""
from __future__ import annotations

import pytest

from ddsolve.dd import solid_costs
from ddsolve.dd.solid_costs import Box, Candidate
from experiments import three_d

#: The 3-D page's partly shut crack (three_d.scene_of) at mesh.size 0.14: 3,714 unknowns.
CLOSURE = three_d.scene_of("partial closure", 0.14, 3)


@pytest.mark.unit
def test_the_candidates_are_schur_on_the_halves_and_feti_on_every_slab_count():
    """schur on whole halves only (and only where its matrices fit), feti with Dirichlet's preconditioner on the
    halves, with either on slabs."""
    made = solid_costs.candidates([1, 2, 4], schur_fits=True)
    assert made == [Candidate("schur", 1, "dirichlet"), Candidate("feti", 1, "dirichlet"),
                    Candidate("feti", 2, "lumped"), Candidate("feti", 2, "dirichlet"),
                    Candidate("feti", 4, "lumped"), Candidate("feti", 4, "dirichlet")]
    assert Candidate("schur", 1, "dirichlet") not in solid_costs.candidates([1, 2], schur_fits=False)
    assert all(c.method == "feti" for c in solid_costs.candidates([2, 4], schur_fits=True))


@pytest.mark.unit
def test_the_model_follows_its_laws():
    """Made-up laws: blocks whose factorization grows fast with their size favour slabs; rounds that grow fast with
    the slabs favour the halves whole; a schur factorization that costs nothing takes schur."""
    def laws(factor: float, slab_rounds: float, schur: float) -> solid_costs.Laws:
        kinds = {"factor": (1e-9, factor, 0.0), "solve": (1e-8, 1.0, 0.0), "columns": (3e-8, 1.0, 0.0),
                 "dirichlet_factor": (1e-9, factor, 0.0),
                 "dirichlet_solve": (1e-8, 1.0, 0.0), "schur_factor": (schur, factor, 0.0)}
        return solid_costs.Laws(blocks={1: kinds}, dense=(1e-10, 2.0), steps=(1.0, 0.0),
                                update={"dirichlet": (1e-9, 1.0), "lumped": (1e-9, 1.0)},
                                rounds={"dirichlet": (30.0, slab_rounds, 0.0, 0.0),
                                        "lumped": (20.0, slab_rounds, 0.0, 0.0)})

    box = Box(unknowns=300_000, sigma=2000, contact_rows=0, degree=1)
    options = solid_costs.candidates(list(solid_costs.PIECES), schur_fits=True)
    steep = solid_costs.ranked(box, 2, options, laws(2.0, 0.2, 1e-8))[0]
    assert steep == Candidate("feti", max(solid_costs.PIECES), "lumped")
    assert solid_costs.ranked(box, 2, options, laws(1.0, 2.0, 1e-6))[0] == Candidate("feti", 1, "dirichlet")
    assert solid_costs.ranked(box, 2, options, laws(1.0, 2.0, 1e-12))[0].method == "schur"
    solves, held = solid_costs.feti_rounds(box, 2, "dirichlet", laws(1.0, 0.0, 1.0))
    assert (solves, held) == (pytest.approx(16.5), pytest.approx(13.5))  # 30 rounds: 13.5 iterations, 3 more


@pytest.mark.unit
def test_the_fitted_laws_take_schur_on_small_boxes_and_slabs_on_the_baseline():
    """With the laws fitted by ./run scaling-3d: the small extruded crack (8 k unknowns) on 2 ranks by schur on the
    halves, the bench's 0.3 M box (4 slabs per half, lumped, meets the 2x) by feti on 4 slabs, lumped."""
    small = Box(unknowns=8094, sigma=165, contact_rows=25, degree=1)
    options = solid_costs.candidates(list(solid_costs.PIECES), schur_fits=True)
    assert solid_costs.ranked(small, 2, options)[0] == Candidate("schur", 1, "dirichlet")
    baseline = Box(unknowns=291_597, sigma=2_056, contact_rows=0, degree=1)
    assert solid_costs.ranked(baseline, 2, options)[0] == Candidate("feti", 4, "lumped")


@pytest.mark.unit
def test_auto_leaves_what_the_scene_fixes_and_what_the_ranks_and_memory_refuse(monkeypatch):
    """The ranking keeps the scene's method and preconditioner, the slab counts the ranks can share (10 ranks: the
    halves only; 6: the halves and 4 slabs, not 2; a method the model does not know: the halves whole), and drops
    schur above its memory limit (auto then takes feti)."""
    from ddsolve.mesh import solid
    from ddsolve.solvers import solid_dd

    mesh = solid.build(CLOSURE)
    whole = solid_dd.decomposition(CLOSURE, mesh, 1)
    box = solid_dd.box_of(CLOSURE, whole)
    assert (box.unknowns, box.sigma, box.degree) == (mesh.unknowns, len(mesh.sigma.points), 1) and box.contact_rows
    pieces = list(solid_costs.PIECES)
    assert {c.method for c in solid_dd.ranking(CLOSURE.with_({"solver.method": "feti"}), box, 2, pieces)} == {"feti"}
    lumped = solid_dd.ranking(CLOSURE.with_({"solver.preconditioner": "lumped"}), box, 2, pieces)
    assert {c.preconditioner for c in lumped if c.method == "feti"} == {"lumped"}
    assert {c.pieces for c in solid_dd.ranking(CLOSURE, box, 10, pieces)} == {1}
    assert {c.pieces for c in solid_dd.ranking(CLOSURE, box, 6, pieces)} == {1, 4}
    assert {c.pieces for c in solid_dd.ranking(CLOSURE.with_({"solver.method": "mprgp"}), box, 2, pieces)} == {1}
    assert [c.method for c in solid_dd.ranking(CLOSURE.with_({"solver.method": "schur"}), box, 2, [2])] == ["feti"] * 2
    monkeypatch.setattr(solid_dd, "SCHUR_MEMORY_SHARE", 0.5 * solid_dd.schur_bytes(3 * box.sigma - 3)
                        / solid_dd.physical_memory())
    assert all(c.method == "feti" for c in solid_dd.ranking(CLOSURE, box, 2, pieces))
    chosen = solid_dd.method_of(CLOSURE, whole, solid_dd.kernels_of(whole), 2).solver
    assert (chosen.method, chosen.pieces, chosen.preconditioner) == ("feti", 1, "dirichlet")
