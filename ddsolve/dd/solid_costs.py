"""``auto`` in a 3-D box: the slabs per half (``solver.pieces``), the method and feti's preconditioner chosen together
as the candidate whose solve phase (factorization and rounds) the model predicts shortest.

Candidates: ``schur`` on the halves whole, ``feti`` on the halves whole with Dirichlet's preconditioner, ``feti`` on
k slabs per half with the lumped or Dirichlet preconditioner.  The laws are fitted on 3-D measurements by
``./run scaling-3d`` (docs/scaling.md, section *scaling-3d*): a block's seconds against n, the box's unknowns over its
blocks, and s, Σ's vertices (a slab's face), per element degree; rank 0's dense Cholesky factorization against its
unknowns; feti's rounds against the slabs, the box's unknowns and whether the crack faces press; schur's
active-set steps against the crack's contact rows (:class:`Laws`).  ``schur`` stays refused above its memory
limit, which the caller decides (``schur_fits``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ddsolve.dd.registry import COST_LAWS


@dataclass(frozen=True)
class Laws:
    """The fitted laws (``./run scaling-3d``).  ``blocks``: per element degree and kind, a block's seconds on one rank
    a·n^p·s^q (n: the box's unknowns over its 2k blocks, s: Σ's vertices) for ``factor`` (plain MUMPS), ``solve``,
    ``dirichlet_factor``, ``dirichlet_solve`` (its Dirichlet problem) and ``schur_factor`` (a half's factorization
    with its Schur complement on Σ); ``dense``: rank 0's Cholesky factorization of ``schur``'s interface stiffness,
    a·m^p on m = 3s unknowns; ``rounds``: feti's rounds at the default solver.tol per preconditioner,
    a·k^b·N^c·e^(d·contact) (k slabs per half, N the box's unknowns, contact: the crack faces press), with the
    coarse directions of :data:`COARSE_DEGREE`, whose multi-column solve of :func:`coarse_columns` columns per block
    is the block kind ``columns``; ``update``:
    feti's rank 0 per round outside the block solves, a·m^p on its m multipliers (:func:`multipliers`), per
    preconditioner (the lumped one is applied there); ``steps``:
    schur's active-set steps a·c^p on c contact rows."""

    blocks: dict[int, dict[str, tuple[float, float, float]]]
    dense: tuple[float, float]
    rounds: dict[str, tuple[float, float, float, float]]
    update: dict[str, tuple[float, float]]
    steps: tuple[float, float]


#: The laws measured on this machine by ``./run scaling-3d`` (docs/scaling.md, section *scaling-3d*).
FITTED = Laws(blocks={1: {"factor": (3.72e-09, 1.84, -0.0447), "solve": (2.56e-08, 1.35, -0.0175),
                          "columns": (1.21e-07, 1.2, 0.112), "dirichlet_factor": (4.15e-09, 1.83, -0.0412),
                          "dirichlet_solve": (3.1e-08, 1.28, 0.0688), "schur_factor": (1.53e-09, 1.98, 0)},
                      2: {"factor": (6.35e-09, 1.81, -0.0827), "solve": (1.1e-08, 1.44, -0.0477),
                          "columns": (5.88e-08, 1.26, 0.123), "dirichlet_factor": (6.62e-09, 1.8, -0.0631),
                          "dirichlet_solve": (1.27e-08, 1.35, 0.104), "schur_factor": (1.93e-09, 1.95, 0)}},
              dense=(7.13e-11, 2.74), steps=(1.63, 0.259),
              update={"dirichlet": (3.89e-05, 0.374), "lumped": (8.72e-06, 0.64)},
              rounds={"dirichlet": (1.19, 0.635, 0.29, 0.445), "lumped": (4.05, 0.472, 0.151, 0.217)})
#: feti's polynomial coarse directions in a 3-D box (``solver.coarse_degree = auto``): degree 1 (three monomials on a
#: joint's plane, three components).  On the 0.3 M bench box in four slabs per half they cut feti's iterations from
#: 59 to 43 for one multi-column round; degree 2 cuts them to 36 but its twice as many columns cost what they save.
COARSE_DEGREE = 1


def coarse_columns(degree: int = COARSE_DEGREE) -> int:
    """The multi-column round's columns per block: three components of the monomials of degree ≤ ``degree`` on each
    of its two joints (plane)."""
    return 2 * 3 * math.comb(degree + 2, 2)


#: Slabs per half the model considers.  Eight are left out: on every mesh measured (to 0.3 M unknowns) their slabs
#: are one or two elements thick and feti's rounds explode (``./run scaling-3d``: 167 to 3,104 rounds at 48 k
#: unknowns, where four slabs take 51 to 119), which no law of the slab count follows.
PIECES = (1, 2, 4)


@dataclass(frozen=True)
class Box:
    """What the model reads of a 3-D box: its unknowns, Σ's vertices, the crack's contact rows (0 where the crack
    faces are free) and the element degree."""

    unknowns: int
    sigma: int
    contact_rows: int
    degree: int


@dataclass(frozen=True)
class Candidate:
    """A decomposition and its method: ``pieces`` slabs per half, ``method``, feti's ``preconditioner`` (``schur``
    reads none: ``dirichlet``)."""

    method: str
    pieces: int
    preconditioner: str


def candidates(pieces: list[int], schur_fits: bool) -> list[Candidate]:
    """The candidates on the slab counts ``pieces`` (``schur`` on whole halves where its matrices fit)."""
    made = [Candidate("schur", 1, "dirichlet")] if schur_fits and 1 in pieces else []
    for count in pieces:
        made += [Candidate("feti", count, preconditioner)
                 for preconditioner in (("dirichlet",) if count == 1 else ("lumped", "dirichlet"))]
    return made


def _block(box: Box, kind: str, pieces: int, laws: Laws) -> float:
    a, p, q = laws.blocks[box.degree][kind]
    return a * (box.unknowns / (2 * pieces)) ** p * box.sigma ** q


def multipliers(box: Box, pieces: int) -> int:
    """feti's multipliers with ``pieces`` slabs per half: three per vertex of Σ and of every cut (about Σ's size)."""
    return 3 * box.sigma * (2 * pieces - 1)


def feti_rounds(box: Box, pieces: int, preconditioner: str, laws: Laws = FITTED) -> tuple[float, float]:
    """feti's predicted rounds of block solves and of Dirichlet solves (a Dirichlet iteration takes one of each,
    a lumped one a solve; three more solves)."""
    a, b, c, d = laws.rounds[preconditioner]
    rounds = a * pieces ** b * box.unknowns ** c * math.exp(d if box.contact_rows else 0.0)
    held = (rounds - 3) / 2 if preconditioner == "dirichlet" else 0.0
    return rounds - held, held


def predicted_seconds(box: Box, candidate: Candidate, ranks: int, laws: Laws = FITTED) -> float:
    """The candidate's solve phase on ``ranks`` ranks: the busiest rank's share of the blocks' factorizations and
    solves (2k blocks dealt over the ranks, some holding one more where the ranks do not divide them; a block's work
    shared ideally among its ranks) and rank 0's work."""
    count = 2 * candidate.pieces
    share = math.ceil(count / ranks) if ranks <= count else count / ranks  # the busiest rank's blocks, or block share
    solve = _block(box, "solve", candidate.pieces, laws)
    if candidate.method == "schur":
        return _schur_seconds(box, share, solve, distributed=ranks > count, laws=laws)
    solves, held = feti_rounds(box, candidate.pieces, candidate.preconditioner, laws)
    factor = _block(box, "factor", candidate.pieces, laws)
    if candidate.preconditioner == "dirichlet":
        factor += _block(box, "dirichlet_factor", candidate.pieces, laws)
    block_rounds = (solves * solve + held * _block(box, "dirichlet_solve", candidate.pieces, laws)
                    + _block(box, "columns", candidate.pieces, laws))
    a, p = laws.update[candidate.preconditioner]
    return share * (factor + block_rounds) + (solves + held) * a * multipliers(box, candidate.pieces) ** p


def _schur_seconds(box: Box, share: float, solve: float, distributed: bool, laws: Laws) -> float:
    """``schur`` on the halves whole: their factorizations with the Schur complements on Σ (a distributed half: a
    plain one, its Dirichlet problem's and a solve per trace entry), three rounds, and rank 0's dense factorization
    and active-set steps."""
    trace = 3 * box.sigma
    if distributed:
        blocks = _block(box, "factor", 1, laws) + _block(box, "dirichlet_factor", 1, laws) + trace * solve
    else:
        blocks = _block(box, "schur_factor", 1, laws)
    seconds = share * (blocks + 3 * solve) + laws.dense[0] * trace ** laws.dense[1]
    if box.contact_rows:
        (a, p), (c, q) = laws.steps, COST_LAWS["contact_step"]
        seconds += a * box.contact_rows ** p * c * box.contact_rows ** q
    return seconds


def ranked(box: Box, ranks: int, options: list[Candidate], laws: Laws = FITTED) -> list[Candidate]:
    """``options`` cheapest first by :func:`predicted_seconds`."""
    return sorted(options, key=lambda candidate: predicted_seconds(box, candidate, ranks, laws))
