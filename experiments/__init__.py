"""Experiments around the solver: the paper's tables and figures, benchmarks, scaling, robustness.

They live beside the package, not in it: ddsolve never imports them, and an install does not carry them.
Each experiment is a command (``./run table1``, ``./run bench methods``, ...; ``python -m experiments
COMMAND`` with the repository on PYTHONPATH) that launches MPI jobs of ``python -m experiments PART ...``
(one measurement each), keeps HDF5 records in ``results/`` and rewrites its section of ``docs/``.
"""
from pathlib import Path

#: The repository: ddsolve/, experiments/ and docs/ side by side.  Children started with
#: ``PYTHONPATH=ROOT`` import this checkout's ddsolve and experiments.
ROOT = Path(__file__).resolve().parents[1]
