"""The scaling page's floor of a whole launch: start-up and one assembly against the solve phase."""
import math

import pytest

from experiments.scaling import bare_start, floor_rows


def launch(**phases) -> dict:
    return {"kind": "launch", "label": "case", "solve_phase": 2.0, "startup": 0.5, "assembly": 0.5, "sum": 4.0} | phases


def test_the_floor_adds_start_up_and_one_assembly_to_the_solve_phase():
    rows = floor_rows([launch(), {"kind": "meshing"}, launch(label="other", assembly=1.5)], bare=0.25)
    assert rows == ["| case | 2.00 | 0.50 | 0.50 | 1.50 | 1.38 | 2.00 |",  # (2 + 0.5 + 0.5) / 2, (2 + 0.25 + 0.5) / 2
                    "| other | 2.00 | 0.50 | 1.50 | 2.00 | 1.88 | 2.00 |"]


@pytest.mark.mpi
def test_a_bare_start_is_measured_from_mpiexecs_start():
    seconds = bare_start(2, repeats=1)
    assert math.isfinite(seconds) and seconds > 0.0
