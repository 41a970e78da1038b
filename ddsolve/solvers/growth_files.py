"""The files and pictures of a growth run (``ddsolve grow --output``): the HDF5 file of its steps, the CSV
of its curve, the picture of its curves and pictures of the deformed structure at chosen steps, written
together (:class:`Outputs`), and the growth file read back (:func:`read`).

A run's steps are :class:`ddsolve.solvers.grow.Step` records and its configurations a
:class:`ddsolve.solvers.grow.Growth`; this module takes them as they come, without importing
:mod:`ddsolve.solvers.grow` (which writes its files through it).
"""
from __future__ import annotations

import csv
import glob
import io
import re
from pathlib import Path
from typing import Callable, Iterable, Mapping

import numpy as np

from ddsolve.errors import DDSolveError
from ddsolve.io import safe
from ddsolve.parallel.exchange import collective
from ddsolve.problem.scene import Scene


class Outputs:
    """The set of files of a run on ``OUT.h5``: the HDF5 file, ``OUT.csv`` (the curve), ``OUT.png`` (the
    curves) and ``OUT-step<k>.png`` (the deformed structure at step k); written together."""

    def __init__(self, h5: Path):
        self.h5 = h5
        self.csv, self.curves = h5.with_suffix(".csv"), h5.with_suffix(".png")

    def step(self, index: int) -> Path:
        return self.h5.with_name(f"{self.h5.stem}-step{index}.png")

    def step_pictures(self) -> list[Path]:
        """The step pictures of this output present now (of an earlier run)."""
        pattern = re.compile(re.escape(self.h5.stem) + r"-step[0-9]+\.png")
        folder = self.h5.parent
        if not folder.is_dir():
            return []
        return sorted(path for path in folder.glob(f"{glob.escape(self.h5.stem)}-step*.png")
                      if pattern.fullmatch(path.name))

    def check(self, inputs: Iterable[Path] | Mapping[Path, str] = ()) -> None:
        """Refuse the set before any work: a name given twice, an input, a directory or FIFO at one of its
        names (step pictures of an earlier run included: they are replaced or removed), an unwritable folder."""
        safe.check_targets([self.h5, self.csv, self.curves, *self.step_pictures()], inputs)

    def commit(self, growth, records: list, limit: float | tuple[float, ...], tolerance: float, pictures: int) -> None:
        """Draw every picture (the step pictures' solves on every rank), then replace the previous set with
        the new one at once on rank 0 (step pictures it no longer has removed with it)."""
        from ddsolve.post import plots

        images = draw(growth, records, pictures)

        def work() -> None:
            data = table(growth.scene, growth.kind, limit, tolerance, records)
            curves = io.BytesIO()
            plots.growth_curves(data, curves)
            writers = {self.h5: lambda name: write_table(name, data), self.csv: lambda name: write_csv(name, data),
                       self.curves: _bytes(curves.getvalue())}
            writers.update({self.step(index): _bytes(image) for index, image in images.items()})
            stale = [path for path in self.step_pictures() if path not in writers]
            safe.replace_together(writers, final=True, remove=stale)

        collective(growth.comm, work, root_only=True)


def _bytes(data: bytes) -> Callable[[str], None]:
    return lambda name: Path(name).write_bytes(data)


def draw(growth, records: list, pictures: int) -> dict[int, bytes]:
    """The deformed structure at ``pictures`` steps spread over the run (the last included), each solved
    again, at one magnification (the last step's), titled with the step, the control and the crack lengths:
    step index -> PNG (rank 0; empty elsewhere)."""
    from ddsolve.post import plots

    chosen = sorted({int(round(k)) for k in np.linspace(len(records) - 1, 0, pictures, endpoint=False)})
    scale, images = None, {}
    for index in reversed(chosen):
        state = records[index].state
        result = growth.result_of(records, index)
        title = (f"{growth.scene.title or growth.scene.origin}: step {index}, λ = {state.control:.6g}, crack length"
                 f"{'s' if len(state.cracks) > 1 else ''} " + ", ".join(f"{b - a:.6g}" for a, b in state.cracks))
        image = io.BytesIO()
        scale = collective(growth.comm, lambda: plots.deformed_layers(result, image, scale, title), root_only=True)
        scale = growth.comm.bcast(scale, root=0)
        images[index] = image.getvalue()
    return images if growth.comm.rank == 0 else {}


def table(scene: Scene, kind: str, limit: float | tuple[float, ...], tolerance: float, steps: list) -> dict:
    """The datasets of a run as :func:`read` returns them (``attrs``, ``/growth`` by name, ``boundaries``);
    ``limit``: the control's last value, or a damaging bond's path of targets (``attrs['path']``)."""
    count = len(steps)
    cracks = max(len(s.state.cracks) for s in steps)
    tips = max(len(s.state.G) for s in steps)

    def per_tip(name: str) -> np.ndarray:
        out = np.full((count, tips), np.nan)
        for i, s in enumerate(steps):
            values = getattr(s.state, name)
            out[i, :len(values)] = values
        return out

    data = {name: np.array([getattr(s.state, name) for s in steps])
            for name in ("control", "load", "displacement", "energy")}
    data["cracks"] = np.full((count, cracks, 2), np.nan)
    for i, s in enumerate(steps):
        data["cracks"][i, :len(s.state.cracks)] = np.reshape(s.state.cracks, (-1, 2))  # none yet: (0,)
    data.update({name: per_tip(name) for name in ("G", "G_I", "G_II", "G_c", "tips")})
    data["unstable"] = np.array([s.unstable for s in steps])
    data["solves"] = np.array([s.solves for s in steps], dtype=np.int64)
    data["events"] = np.array(["; ".join(s.events) for s in steps], dtype=object)
    keys = list(dict.fromkeys(key for s in steps for key in s.state.boundaries))
    values = {key: np.array([s.state.boundaries.get(key, np.full(4, np.nan)) for s in steps]).reshape(count, 4)
              for key in keys}
    data["boundaries"] = {key: {"force": v[:, :2], "displacement": v[:, 2:]} for key, v in values.items()}
    if steps[0].state.damage is not None:  # a damaging bond's run
        data["damage"] = np.array([s.state.damage for s in steps])
        data["process_zone"] = np.array([s.state.process_zone for s in steps])
        data["bond_solves"] = np.array([s.bond_solves for s in steps], dtype=np.int64)
    path = np.atleast_1d(np.asarray(limit, dtype=np.float64))  # a damaging bond's path of targets, or one
    data["attrs"] = {"scene": scene.origin, "scene_text": scene.text, "control_kind": kind, "limit": float(path.max()),
                     "tolerance": tolerance, "steps": count, **({"path": path} if len(path) > 1 else {})}
    return data


def write_table(name: str, data: dict) -> None:
    """The HDF5 file of a run's :func:`table` (``/growth/...``, see docs/growth.md)."""
    import h5py

    from ddsolve.parallel.launch import provenance

    with h5py.File(name, "w") as f:
        for key, value in {**provenance(), **data["attrs"]}.items():
            f.attrs[key] = value
        g = f.create_group("growth")
        for key, value in data.items():
            if key == "events":
                g[key] = np.array(list(value), dtype=h5py.string_dtype())
            elif key == "boundaries":
                for boundary, quantities in value.items():
                    for quantity, array in quantities.items():
                        g[f"boundaries/{boundary}/{quantity}"] = array
            elif key != "attrs":
                g[key] = value


def write_csv(name: str, data: dict) -> None:
    """The curve of a run as CSV: per step the control, load and displacement, the force and mean
    displacement (x, y) of every controlled boundary, the crack intervals, the energy, and what happened."""
    header = ["step", "control", "load", "displacement"]
    columns = [np.arange(len(data["control"])), data["control"], data["load"], data["displacement"]]
    for key, quantities in data["boundaries"].items():
        for quantity, array in quantities.items():
            header += [f"{key} {quantity} x", f"{key} {quantity} y"]
            columns += [array[:, 0], array[:, 1]]
    for c in range(data["cracks"].shape[1]):
        header += [f"crack {c + 1} start", f"crack {c + 1} end"]
        columns += [data["cracks"][:, c, 0], data["cracks"][:, c, 1]]
    if "process_zone" in data:
        header.append("process zone")
        columns.append(data["process_zone"])
    header += ["energy", "unstable", "events"]
    columns += [data["energy"], data["unstable"].astype(int), data["events"]]
    with open(name, "w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow(header)
        for row in zip(*columns):
            writer.writerow([value if isinstance(value, str) else f"{value + 0.0:.10g}" for value in row])


def write(path: Path, scene: Scene, kind: str, limit: float, tolerance: float, steps: list) -> None:
    """The HDF5 file of a run alone (replaced whole)."""
    safe.atomic(path, lambda name: write_table(name, table(scene, kind, limit, tolerance, steps)), final=True)


def read(path: Path) -> dict:
    """A growth file as a dict: ``attrs`` and the ``/growth`` datasets by name."""
    import h5py

    from ddsolve.problem.scene import readable

    path = readable(path, "growth file")
    try:
        with h5py.File(path, "r") as f:
            out = {name: f["growth"][name][()] for name in f["growth"] if name != "boundaries"}
            out["boundaries"] = {key: {quantity: group[quantity][()] for quantity in group}
                                 for key, group in f["growth"].get("boundaries", {}).items()}
            out["attrs"] = dict(f.attrs)
    except (OSError, KeyError) as exc:
        raise DDSolveError(f"{path}: not a growth file ({exc})") from None
    out["events"] = np.array([e.decode() if isinstance(e, bytes) else e for e in out["events"]])
    return out
