"""``./run bench contact`` (experiments/contact.py): its scenes are what the issue describes, and its page
section has a row per run with the ratios the acceptance reads."""
from __future__ import annotations

import re

import pytest

from ddsolve.problem import scene as scenes
from experiments import contact


@pytest.mark.parametrize("specimen", list(contact.SWEEP))
@pytest.mark.parametrize("free", [False, True])
def test_every_specimen_writes_a_scene_with_its_crack_and_contact_choice(tmp_path, specimen, free):
    crack = contact.SWEEP[specimen][-1]
    path = contact.scene_file(tmp_path, specimen, crack, 0.5, free=free)
    scene = scenes.load(path)
    assert scene.nonpenetration is not free
    if specimen == "closed strip":  # centred, pressed by the top traction, clamped at both ends
        (start, stop), = scene.geometry.cracks
        assert stop - start == pytest.approx(crack) and start + stop == pytest.approx(contact.STRIP_LENGTH)
    else:
        geo = (tmp_path / scene.mesh.file).read_text()
        assert 'Physical Curve("crack")' in geo and f"{crack!r}, 0.0" in geo
    if specimen == "ENF":  # a pin and a roller on the bottom, nothing on the upper half
        assert {name for layer, name in scene.displacements if layer == "layer1"} == {"pin", "roller"}


def test_the_page_has_a_row_per_run_and_the_acceptance_ratios():
    runs = [contact.Run("ENF", 12.5, 0.2, method, True, seconds, seconds + 1.0, 10, 5, 3, 1000, 2.5, 1e-11)
            for method, seconds in (("reference", 4.0), ("schur", 1.0))]
    rows = [{"specimen": "ENF", "crack": 12.5, "size": 0.1, "method": "schur", "steps": 24, "contact_length": 0.5,
             "error": 5e-10, "contact_solve": 2.0, "free_solve": 1.0, "reference_solve": 16.0, "contact_launch": 3.0,
             "reference_launch": 18.0}]
    text = contact.table(runs, rows)
    assert len(re.findall(r"^\| ENF \| 12\.5 \|", text, flags=re.M)) == 2
    assert "| ENF, crack 12.5, size 0.1 | schur | 24 | 0.50 | 2.00 | 1.00 | 2.00 | 16.00 | 0.12 | 0.17 | 5.0e-10 |" in text
    for line in text.splitlines():
        if line.startswith("|"):
            header = next(h for h in text.splitlines() if h.startswith("|") and h.count("|") == line.count("|"))
            assert line.count("|") == header.count("|")
