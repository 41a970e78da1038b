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
FITTED = Laws(blocks={1: {"factor": (2.36e-09, 1.77, 0.111), "solve": (1.59e-09, 1.47, 0.177),
                          "columns": (5.2e-09, 1.47, 0.177),
                          "dirichlet_factor": (2.25e-09, 1.75, 0.146), "dirichlet_solve": (2.55e-09, 1.43, 0.178),
                          "schur_factor": (2.5e-09, 1.93, 0)},
                      2: {"factor": (3e-09, 1.94, -0.144), "solve": (6.91e-10, 1.7, -0.0505),
                          "columns": (2.3e-09, 1.7, -0.0505),
                          "dirichlet_factor": (1.3e-08, 2.18, -0.716), "dirichlet_solve": (9.06e-10, 1.6, 0.0987),
                          "schur_factor": (3.26e-09, 1.91, 0)}},
              dense=(7.9e-11, 2.73), steps=(1.63, 0.259),
              update={"dirichlet": (3.86e-05, 0.431), "lumped": (5.06e-05, 0.509)},
              rounds={"dirichlet": (1.23, 0.782, 0.301, 0.468), "lumped": (2.91, 0.634, 0.191, 0.273)})
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
    """The candidate's solve phase on ``ranks`` ranks: each rank's share of its blocks' factorizations and solves
    (2k blocks over the ranks, a block's work shared ideally among its ranks) and rank 0's work."""
    count = 2 * candidate.pieces
    share = count / ranks  # blocks per rank, or the fraction of one block a rank holds
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
