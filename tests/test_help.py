"""``ddsolve --help``, ``python -m experiments --help`` and ``./run --help``: every command, one line
each; the experiments are their own command line, which ./run dispatches to."""
import argparse
import re
import subprocess
import sys

import pytest
from conftest import ROOT

from ddsolve import cli
from experiments import commands

pytestmark = pytest.mark.mpi


def subcommands(top: argparse.ArgumentParser) -> dict:
    return next(a for a in top._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_help_lists_every_command(capsys):
    top = cli.parser()
    help_text = subprocess.run([sys.executable, "-m", "ddsolve", "--help"], capture_output=True, text=True,
                               check=True, timeout=60).stdout
    listed = re.findall(r"^  (\S+) +\S", help_text.split("commands:\n")[1], re.M)
    assert sorted(listed) == sorted(subcommands(top))
    assert not set(listed) & set(commands.EXPERIMENTS), "the solver's command line knows no experiment"
    for name in subcommands(top):
        with pytest.raises(SystemExit) as exit_status:
            top.parse_args([name, "--help"])
        assert exit_status.value.code == 0
        assert capsys.readouterr().out.startswith(f"usage: ddsolve {name}")


def test_the_experiments_have_their_own_command_line_and_run_knows_them_all():
    experiments = subcommands(commands.parser())
    assert list(experiments) == [*commands.EXPERIMENTS, "bench"]
    help_text = subprocess.run([sys.executable, "-m", "experiments", "--help"], capture_output=True, cwd=ROOT,
                               text=True, check=True, timeout=60).stdout
    assert re.findall(r"^  (\S+) +\S", help_text.split("experiments (")[1], re.M) == list(experiments)
    dispatched = re.search(r"^    ([a-z0-9|-]+)\)\n        .*exec \"\$PY\" -m experiments", (ROOT / "run").read_text(),
                           re.M).group(1).split("|")
    assert sorted(dispatched) == sorted(experiments)


@pytest.mark.parametrize("flag", ["--help", "-h", "help"])
def test_run_help_is_clean_usage(flag):
    completed = subprocess.run([str(ROOT / "run"), flag], capture_output=True, text=True, timeout=60,
                               stdin=subprocess.DEVNULL)
    assert completed.returncode == 0 and completed.stderr == ""
    out = completed.stdout
    assert out.startswith("usage: ./run COMMAND")
    for line in ("  setup ", "  demo ", "  test ", "  solve -n N", "  COMMAND [ARGS]"):
        assert line in out
    assert cli.parser().epilog in out and commands.parser().epilog in out
    assert not re.search(r"^(set |#)", out, re.M)
