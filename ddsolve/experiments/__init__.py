"""Experiments around the solver: the paper's tables and figures, benchmarks, scaling, robustness.

The solver never imports this package.  Each experiment is a ``ddsolve`` command (``./run table1``,
``./run bench methods``, ...) that launches MPI jobs of ``python -m ddsolve.experiments PART ...``
(one measurement each), keeps HDF5 records in ``results/`` and rewrites its section of ``docs/``.
"""
