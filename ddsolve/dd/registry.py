"""The contact methods: one description each (:class:`Method`: the solver keys it reads, its rounds, what it
needs of the blocks), the only place that tells one method from another, and ``auto``'s choice among them.

The driver asks a method's description what to factor and whether it solves floating blocks; a scene is
validated against the same descriptions' options (:mod:`ddsolve.problem.method_options`, which the problem
stage can read)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from ddsolve.dd import feti, gradient, schur, uzawa
from ddsolve.dd.dual import Outcome
from ddsolve.problem.method_options import OPTIONS, MethodOptions
from ddsolve.problem.scene import Solver

#: How a method solves a floating block (a singular stiffness, held only through Σ).
INTERIOR = "its interior, from the traces the method predicts"
GENERALIZED_INVERSE = "a generalized inverse K⁺ and the kernels' coarse problem"


def _never(solver: Solver) -> bool:
    return False


def _always(solver: Solver) -> bool:
    return True


def _lower_tol(solver: Solver) -> str:
    return "lower solver.tol"


@dataclass(frozen=True)
class Method:
    """A contact method.  ``run(rounds, interface, solver, progress[, start])`` -> its multipliers."""

    options: MethodOptions  # the solver keys it reads
    run: Callable[..., Outcome]
    #: The blocks' factorization package by default: the iterative methods make one solve per round with one
    #: factorization, where PETSc's own Cholesky is about 3x faster than MUMPS; ``schur`` needs MUMPS for the
    #: Schur complements (``./run bench factor`` measures both).
    factorization: str = "petsc"
    floating: str | None = None  # how it solves floating blocks (INTERIOR, GENERALIZED_INVERSE); None: it cannot
    schur_complements: bool = False  # it needs the blocks' Schur complements on Σ with their factorization
    dirichlet: bool = False  # it needs a Dirichlet solve on every block (its preconditioner)
    #: Whether it can go on from its multipliers to a lower tol (its criterion relative to the uncoupled
    #: blocks' gap), which :func:`~ddsolve.dd.final_check.checked_solve` asks when the final check finds it short.
    resumes: Callable[[Solver], bool] = _never
    remedy: Callable[[Solver], str] = _lower_tol  # what to change when its final check fails
    #: Whether it iterates Coulomb's friction itself, on rank 0 (else :func:`~ddsolve.dd.friction.coulomb` around it).
    fixed_point: bool = False
    #: Whether it takes a bond's compliance on the dual problem (``[interface]``, :mod:`ddsolve.dd.cohesive`).
    compliant: bool = False

    @property
    def name(self) -> str:
        return self.options.name


METHODS: dict[str, Method] = {method.name: method for method in (
    Method(OPTIONS["schur"], schur.schur, "mumps", floating=INTERIOR, schur_complements=True, remedy=schur.remedy,
           fixed_point=True, compliant=True),
    Method(OPTIONS["mprgp"], gradient.mprgp, resumes=_always, compliant=True),
    Method(OPTIONS["fista"], gradient.fista, resumes=_always, compliant=True),
    Method(OPTIONS["uzawa"], uzawa.uzawa, resumes=uzawa.resumes, remedy=uzawa.remedy),
    Method(OPTIONS["feti"], feti.feti, "mumps", floating=GENERALIZED_INVERSE, dirichlet=True, resumes=_always))}


def floating_methods() -> list[str]:
    """The methods that solve floating blocks."""
    return [name for name, method in METHODS.items() if method.floating]


def compliant_methods() -> list[str]:
    """The methods that take a bond's compliance."""
    return [name for name, method in METHODS.items() if method.compliant]


def iterating_methods() -> list[str]:
    """The methods that iterate (read ``solver.max_iterations``), the paper's (the one with a step) first."""
    return [method.name for method in sorted(METHODS.values(), key=lambda method: not method.options.step)
            if method.options.iterates]


def stepping_methods() -> list[str]:
    """The methods that take a step ``solver.theta``."""
    return [name for name, method in METHODS.items() if method.options.step]


# --- auto: schur or feti ------------------------------------------------------------------------
#: Per-block costs (seconds, n = block unknowns, c = columns, m = multiplier rounds) fitted by
#: ``./run scaling`` on one rank (docs/scaling.md): the interface matrix of a distributed block by
#: multi-column solves c·(n·2kΣ)^p; one block solve; a plain factorization; rank 0's dense solve of
#: ``schur`` on its interface unknowns (3 per Σ node); rank 0's update per round of an iterative method on its
#: multipliers (6 per Σ node); and, fitted to ``./run bench contact``'s steps, one active-set step of
#: ``schur``'s contact problem on its crack rows (a dense factorization of at most that size).
COST_LAWS = {"columns": (1.16e-08, 1.09), "solve": (1.18e-07, 1.10), "factor": (3.46e-08, 1.49),
             "rank0": (4.14e-09, 2.40), "update": (2.3e-07, 1.0), "contact_step": (1.25e-09, 2.30)}
#: ``feti``'s rounds, fitted on Example 1 with its contact (rounds against P: 19.2·P^0.16, docs/scaling.md);
#: long pressed zones take more (``./run bench contact``: 2.5× its rounds with the faces free on the ENF, 6.9× on
#: the closed strip, 1.35× on Example 1), which Σ's length alone does not predict: the model keeps Example 1's.
FETI_ROUNDS = 60
#: With non-penetration on the crack, ``schur`` takes at most this many active-set steps (the most
#: ``./run bench contact`` measured: 24, the ENF).
CONTACT_STEPS = 25


def predicted_costs(ranks: int, unknowns: int, sigma_nodes: int, crack_rows: int = 0, count: int = 4
                    ) -> dict[str, float]:
    """Seconds of what ``schur`` and ``feti`` do on ``ranks`` ranks beyond the factorization both need, for
    blocks of ``unknowns``, ``sigma_nodes`` on Σ and ``crack_rows`` contact multipliers (0: no contact; ``schur``'s
    contact steps), ``count`` blocks: the block work of a rank's blocks shared ideally among a block's ranks, as in
    the cost model."""
    law = {key: (lambda x, a=a, p=p: a * x ** p) for key, (a, p) in COST_LAWS.items()}
    per_block = max(1, ranks // count)
    share = max(1, count // ranks) / per_block  # the blocks of a rank, over the ranks of a block
    schur = law["rank0"](3 * sigma_nodes) + (CONTACT_STEPS * law["contact_step"](crack_rows) if crack_rows else 0.0)
    if per_block > 1:  # no Schur complement from a distributed factorization: the Dirichlet problem's, 2kΣ columns
        schur += share * (law["factor"](unknowns) + law["columns"](unknowns * 2 * sigma_nodes))
    feti = (share * (law["factor"](unknowns) + FETI_ROUNDS * law["solve"](unknowns))  # + the Dirichlet problem
            + FETI_ROUNDS * law["update"](6 * sigma_nodes))
    return {"schur": schur, "feti": feti}


def choose(ranks: int, unknowns: int, sigma_nodes: int, crack_rows: int = 0, count: int = 4) -> str:
    """The default method: whichever of ``schur`` and ``feti`` :func:`predicted_costs` finds cheaper (``schur``,
    exact in three rounds with its Schur complements from the factorization, for every structure measured
    on whole blocks; ``feti`` where rank 0's dense interface problem outgrows the block work)."""
    costs = predicted_costs(ranks, unknowns, sigma_nodes, crack_rows, count)
    return min(costs, key=costs.get)
