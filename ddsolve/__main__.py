"""``python -m ddsolve``.  Until the command's own handlers are in place (:func:`ddsolve.parallel.runtime.guarded`),
SIGINT and SIGTERM end the process at once, quietly, with their status: nothing has been written yet, and
a handler that raised inside the imports could be printed as "Exception ignored" and lost."""
import os
import signal
import sys


def _quit(signum: int, _frame) -> None:
    os._exit(128 + signum)


for _signum in (signal.SIGINT, signal.SIGTERM):
    signal.signal(_signum, _quit)

from ddsolve.cli import main  # noqa: E402 -- after the handlers

sys.exit(main())
