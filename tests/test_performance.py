"""What the speed work must not break: meshing ends at once on SIGTERM; the Schur round needs no solve."""
from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.mpi


def test_sigterm_ends_meshing_at_once():
    """gmsh meshes in a thread, so the signal handler runs while it meshes (P = 1600 takes a minute)."""
    process = subprocess.Popen([sys.executable, "-m", "ddsolve", "mesh", "partial-closure", "--set",
                                "mesh.sigma_vertices=1600", "--set", "mesh.boundary_vertices=2048", "--set",
                                "mesh.refine=0"],  # gmsh, not a coarse mesh refined in a second
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)  # imports and gmsh's set-up are over: it is meshing
    sent = time.perf_counter()
    process.send_signal(signal.SIGTERM)
    try:
        _, stderr = process.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        pytest.fail("SIGTERM did not end the meshing within 10 s")
    assert process.returncode == 143 and "ddsolve: terminated" in stderr
    assert time.perf_counter() - sent < 10
