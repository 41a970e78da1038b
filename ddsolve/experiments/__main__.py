"""One MPI launch of an experiment: ``python -m ddsolve.experiments PART ARGS... OUTPUT``.

Internal to the experiments (they start these under mpiexec); not a user command.
"""
import sys

from ddsolve.experiments.parts import main

sys.exit(main())
