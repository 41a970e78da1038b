"""``ddsolve --help`` and ``./run --help``: every command, one line each, experiments apart."""
import argparse
import re
import subprocess
import sys

import pytest
from conftest import ROOT

from ddsolve import cli


def test_help_lists_every_command_with_experiments_apart(capsys):
    top = cli.parser()
    commands = next(a for a in top._actions if isinstance(a, argparse._SubParsersAction)).choices
    help_text = subprocess.run([sys.executable, "-m", "ddsolve", "--help"], capture_output=True, text=True,
                               check=True, timeout=60).stdout
    listed = re.findall(r"^  (\S+) +\S", help_text.split("experiments (")[0].split("commands:\n")[1], re.M)
    experiments = re.findall(r"^  (\S+) +\S", help_text.split("experiments (")[1], re.M)
    assert sorted(listed + experiments) == sorted(commands)
    assert experiments == [*cli.EXPERIMENTS, "bench"]
    for name in commands:
        with pytest.raises(SystemExit) as exit_status:
            top.parse_args([name, "--help"])
        assert exit_status.value.code == 0
        assert capsys.readouterr().out.startswith(f"usage: ddsolve {name}")


@pytest.mark.parametrize("flag", ["--help", "-h", "help"])
def test_run_help_is_clean_usage(flag):
    completed = subprocess.run([str(ROOT / "run"), flag], capture_output=True, text=True, timeout=60,
                               stdin=subprocess.DEVNULL)
    assert completed.returncode == 0 and completed.stderr == ""
    out = completed.stdout
    assert out.startswith("usage: ./run COMMAND")
    for line in ("  setup ", "  demo ", "  test ", "  solve -n N", "  COMMAND [ARGS]"):
        assert line in out
    assert cli.parser().epilog in out
    assert not re.search(r"^(set |#)", out, re.M)
