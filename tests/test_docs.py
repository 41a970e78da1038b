"""The Python examples of docs/usage.md run as written."""
from __future__ import annotations

import re

import pytest
from conftest import ROOT, SMALL, solved_reference

pytestmark = pytest.mark.mpi


def python_blocks(section: str) -> list[str]:
    """The ```python blocks of one ``## section`` of docs/usage.md."""
    text = (ROOT / "docs" / "usage.md").read_text(encoding="utf-8")
    start = text.index(f"\n## {section}\n")
    end = text.find("\n## ", start + 1)
    return re.findall(r"```python\n(.*?)```", text[start:end if end > 0 else None], flags=re.S)


def test_post_processing_examples_run(tmp_path, monkeypatch, capsys):
    solved_reference("partial-closure", *SMALL, "-o", str(tmp_path / "partial-closure.h5"))
    blocks = python_blocks("Post-processing in Python")
    assert len(blocks) == 2
    monkeypatch.chdir(tmp_path)
    for block in blocks:
        exec(compile(block, "docs/usage.md", "exec"), {})
    printed = capsys.readouterr().out.splitlines()
    assert len(printed) == 4
    assert printed[0].startswith("reference: ") and "crack faces in contact for" in printed[0]
    assert printed[2].startswith("layer 1: ") and "strain energy" in printed[2]
