"""``python -m experiments COMMAND ...``: an experiment (``./run COMMAND``), or one MPI launch of a
part of one (``PART ARGS... OUTPUT``, which the experiments start under mpiexec themselves)."""
import sys

from experiments import commands, parts

sys.exit(parts.main() if sys.argv[1:2] and sys.argv[1] in parts.PARTS else commands.main())
