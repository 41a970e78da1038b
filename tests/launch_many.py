"""Several ddsolve command lines in one MPI launch, so that a test that checks one scene on 1 to 8 ranks
starts mpiexec once per rank count instead of once per command: :func:`launch` writes the command lines
to a file and runs ``mpiexec -n N python -m launch_many FILE``, in which every rank runs each command as
``python -m ddsolve ARGS`` would (:func:`ddsolve.cli.main`), rank 0's standard output going to a file per
command.  The launch stops at the first command that fails."""
from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: The sockets of each command's interrupt watcher, open until the process ends (the next command's watcher
#: replaces them, and a watcher whose sockets close ends with an error).
WATCHERS: list = []


def launch(commands: list[list[str]], ranks: int, folder: Path, timeout: float = 600) -> list[str]:
    """Run the ddsolve ``commands`` (argument lists) one after the other in one launch on ``ranks``
    ranks; their standard outputs, in order.  A failure (a nonzero status, a traceback) raises AssertionError
    with the launch's output."""
    from ddsolve.cli import mpiexec_command

    listing = folder / f"commands-{ranks}.json"
    outputs = [folder / f"stdout-{ranks}-{i}.txt" for i in range(len(commands))]
    listing.write_text(json.dumps([[command, str(output)] for command, output in zip(commands, outputs)]))
    completed = subprocess.run(mpiexec_command(ranks, [str(listing)], module="launch_many"), capture_output=True,
                               text=True, timeout=timeout, stdin=subprocess.DEVNULL,
                               env={**os.environ, "MPLBACKEND": "Agg",
                                    "PYTHONPATH": os.pathsep.join([str(HERE), *sys.path])})
    assert completed.returncode == 0 and "Traceback" not in completed.stderr, \
        f"{listing.read_text()}\n{completed.stdout}\n{completed.stderr}"
    return [output.read_text() for output in outputs]


def main(listing: Path) -> None:
    from ddsolve.cli import main as ddsolve_main
    from ddsolve.parallel import runtime
    from ddsolve.parallel.launch import world_position

    rank = world_position()[0]  # before MPI starts, as ddsolve's own start-up needs
    for command, output in json.loads(listing.read_text()):
        with open(output if rank == 0 else os.devnull, "w") as stream, contextlib.redirect_stdout(stream):
            status = ddsolve_main(command)
            sys.stdout.flush()
        WATCHERS.append(getattr(runtime.watch_interrupts, "sockets", None))
        if status != 0:
            sys.exit(status)


if __name__ == "__main__":
    main(Path(sys.argv[1]))
