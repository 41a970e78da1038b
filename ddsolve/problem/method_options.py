"""The contact methods a scene can name (``solver.method``) and the solver keys each reads.

This is the part of a method's description a scene is validated against; :mod:`ddsolve.dd.registry` pairs
each of these with how the method runs and what it needs of the blocks (the problem stage comes before dd,
so the scene reads these, and the registry builds on them)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class MethodOptions:
    """What a scene can set for one ``solver.method``."""

    name: str
    stops: tuple[str, ...] = ("kkt",)  # the stopping rules (``solver.stop``) it takes, its default first
    step: bool = False  # it reads ``solver.theta``, and needs it
    iterates: bool = True  # it reads ``solver.max_iterations`` (a method that does not is exact in a few rounds)


#: Not a method but the choice of one, ``schur`` or ``feti`` (:func:`ddsolve.dd.registry.choose`), made
#: with the mesh: it reads what either of them reads.
AUTO = MethodOptions("auto")
#: Every ``solver.method`` a scene can name, in the order messages list them.
OPTIONS = {options.name: options for options in (
    AUTO, MethodOptions("schur", iterates=False), MethodOptions("mprgp"), MethodOptions("fista"),
    MethodOptions("uzawa", stops=("paper", "relative", "kkt"), step=True), MethodOptions("feti"))}
