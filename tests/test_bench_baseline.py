"""The account of `bench baseline` (no run: a synthetic record)."""
import pytest

from experiments.bench import ACCOUNT_PHASES, account_lines, account_table, structure_bound


def record(ranks: int = 2) -> dict:
    dd = dict.fromkeys(ACCOUNT_PHASES, 0.25) | {"assembly": 9.0, "interface solve": 0.5}
    mono = dict.fromkeys(ACCOUNT_PHASES, 0.0) | {"assembly": 7.0, "numeric factorization": 2.0, "solves": 1.0}
    pairs = [{"solve_phase": 1.0, "cpu": 2.0, "method": "schur"}] * 3
    return {"scene": "linear", "P": 400, "unknowns": 1000, "ranks": ranks, "load": 0.5, "dd": pairs,
            "mono AMF": [{"solve_phase": 1.5, "cpu": 2.2}] * 3, "account": {"dd": dd, "mono": mono}}


@pytest.mark.parametrize("ranks", [1, 2, 4])
def test_the_bound_shares_block_work_and_adds_rank_0s_interface_solve(ranks):
    # block work (no assembly): five phases of 0.25 s; rank 0 alone: 0.5 s; the monolithic: 3 s (no assembly)
    assert structure_bound(record(ranks)["account"], ranks) == pytest.approx(3.0 / (1.25 / ranks + 0.5))


def test_the_account_is_printed_and_tabulated_per_phase():
    lines = account_lines(record())
    assert len(lines) == len(ACCOUNT_PHASES) + 2 and "DD / monolithic CPU 0.58" in lines[-1]
    table = account_table([record(), record()])
    assert table.count("| linear | 400 | DD |") == 2 and "| 1.50 |" in table  # wall ratio 1.5 / 1.0
