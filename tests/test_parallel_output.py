"""Issue 20, no gather: the ranks write their parts of the result file and of the VTU viewer files
together (parallel HDF5); a reader sees the file the serial writer makes of the same result, and rank
0 holds no more than its blocks and Σ at output."""
from __future__ import annotations

import h5py
import meshio
import numpy as np
import pytest
from conftest import ddsolve

from ddsolve.io import hdf5
from ddsolve.io.viewer import VIEWER_MESHES

MESH = ["--set", "mesh.sigma_vertices=40", "--set", "mesh.boundary_vertices=64"]
#: Attributes that differ between two writes of one result: the seconds the write took.
WRITE_TIMES = {("timings", "write")}


def listing(path) -> dict[str, tuple]:
    """Every group and dataset of an HDF5 file: shape, type, attributes with their values (float datasets
    by their bytes, so that NaN, as in /fracture/toughness without a toughness, compares equal)."""
    out = {}
    with h5py.File(path, "r") as f:
        def visit(name, item):
            attrs = {key: np.asarray(value).tolist() for key, value in item.attrs.items()
                     if (name, key) not in WRITE_TIMES}
            values = None
            if isinstance(item, h5py.Dataset):
                data = np.asarray(item[()])
                values = data.tobytes() if data.dtype.kind == "f" else data.tolist()
            out[name] = (getattr(item, "shape", None), str(getattr(item, "dtype", "")), attrs, values)
        f.visititems(visit)
        visit("/", f)
    return out


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [1, 2, 4, 8])
def test_the_ranks_write_the_file_the_serial_writer_writes(tmp_path, ranks):
    written = tmp_path / "dd.h5"
    ddsolve("solve", "partial-closure", *MESH, "-o", str(written), ranks=ranks)
    serial = tmp_path / "serial.h5"
    hdf5.write(serial, hdf5.read(written))  # the same result by the one-process writer
    assert listing(written) == listing(serial)
    for mesh in VIEWER_MESHES:
        a, b = meshio.read(tmp_path / f"dd-{mesh}.vtu"), meshio.read(tmp_path / f"serial-{mesh}.vtu")
        assert np.array_equal(a.points, b.points)
        assert [c.type for c in a.cells] == [c.type for c in b.cells]
        assert all(np.array_equal(c.data, d.data) for c, d in zip(a.cells, b.cells))
        assert a.point_data.keys() == b.point_data.keys() and a.cell_data.keys() == b.cell_data.keys()
        assert all(np.array_equal(a.point_data[key], b.point_data[key]) for key in a.point_data)
        assert all(np.array_equal(a.cell_data[key][0], b.cell_data[key][0]) for key in a.cell_data)
    script = (tmp_path / "dd-paraview.py").read_text().replace("dd-", "serial-")
    assert script == (tmp_path / "serial-paraview.py").read_text()


@pytest.mark.mpi
def test_rank_0_holds_its_blocks_and_sigma_at_output(tmp_path):
    output = tmp_path / "dd.h5"
    ddsolve("solve", "partial-closure", *MESH, "-o", str(output), ranks=4)
    memory = hdf5.read(output).memory
    held = memory["rank_held_bytes"]
    assert len(held) == 4 and held[0] <= 0.6 * memory["whole_held_bytes"], (held, memory["whole_held_bytes"])
