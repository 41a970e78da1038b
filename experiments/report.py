"""Plumbing shared by the experiments: MPI launches that return JSON, HDF5 records, docs sections."""
from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np

from ddsolve.errors import DDSolveError
from experiments import ROOT


def run(ranks: int, arguments: list[str], module: str = "ddsolve") -> None:
    """Run ``python -m MODULE ARGUMENTS`` on ``ranks`` MPI ranks, raising if it fails.

    The calling process must not have started MPI (mpiexec cannot be nested in an MPI process);
    the child gets Python's view of the environment, without what an MPI library added in C, and the
    repository first on PYTHONPATH (the experiments are not installed).
    """
    from ddsolve.parallel.launch import mpiexec_command

    path = os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))
    completed = subprocess.run(mpiexec_command(ranks, arguments, module), env={**os.environ, "PYTHONPATH": path})
    if completed.returncode != 0:
        raise DDSolveError(f"{' '.join(arguments)}: the launch failed (exit {completed.returncode})")


def launch(ranks: int, arguments: list[str], part: Path) -> dict:
    """Run the experiment part ``ARGUMENTS PART`` on ``ranks`` ranks; return the JSON record it wrote to PART."""
    run(ranks, [*arguments, str(part)], module="experiments")
    record = json.loads(part.read_text())
    part.unlink()
    return record


def write_records(path: Path, records: list[dict], attrs: dict) -> None:
    """One HDF5 group per record: scalars as attributes, lists of numbers and of dicts as datasets."""
    import h5py

    from ddsolve.io.safe import atomic

    def store(group, record: dict) -> None:
        for key, value in record.items():
            if isinstance(value, dict):
                store(group.create_group(key), value)
            elif isinstance(value, list) and value and isinstance(value[0], dict):
                for field in value[0]:
                    column = [item[field] for item in value]
                    group[f"{key}/{field}"] = np.array(column, dtype="S" if isinstance(column[0], str) else None)
            elif isinstance(value, list):
                group[key] = np.array(value)
            elif value is not None:
                group.attrs[key] = value

    def write(name):
        with h5py.File(name, "w") as f:
            for key, value in attrs.items():
                f.attrs[key] = value
            for index, record in enumerate(records):
                store(f.create_group(f"{index:03d}"), record)

    atomic(path, write)


def section(path: Path, name: str, text: str) -> None:
    """Replace (or append) the block between ``<!-- name:start -->`` and ``<!-- name:end -->``."""
    begin, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    block = f"{begin}\n{text.rstrip()}\n{end}"
    content = path.read_text() if path.exists() else "# Results\n"
    if begin in content and end in content:
        content = content[:content.index(begin)] + block + content[content.index(end) + len(end):]
    else:
        content = content.rstrip() + "\n\n" + block + "\n"
    path.write_text(content)
