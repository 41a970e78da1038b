"""Errors a user can cause or meet; each carries a one-line message and an exit status."""


class DDSolveError(Exception):
    """Base class: reported as one line, never as a traceback.

    ``collective`` is set when every rank raises the same error (then all exit normally);
    an error raised on one rank only aborts the MPI job.
    """

    exit_status = 1
    collective = False


class UsageError(DDSolveError):
    """The command line is wrong (an unknown option, a missing argument)."""

    exit_status = 2


class ArgumentError(DDSolveError, TypeError):
    """An argument of a function of the Python API has the wrong type (``grow(limit="2")``)."""


class SceneError(DDSolveError):
    """A scene file or an override is invalid."""


class MeshError(DDSolveError):
    """A mesh cannot be generated, read, or fails a check."""


class SolverError(DDSolveError):
    """A block solve failed (singular block, KSP not converged)."""


class DivergedError(DDSolveError):
    """The multiplier iteration diverged."""

    exit_status = 4


class NotConvergedError(DDSolveError):
    """max_iterations was reached, or the final solution failed its KKT check; the result is written
    with converged = false."""

    exit_status = 3

    @classmethod
    def collective_with(cls, message: str, result) -> "NotConvergedError":
        """The error every rank raises together, carrying the (unconverged) ``result``."""
        error = cls(message)
        error.collective = True
        error.result = result
        return error
