"""The generalisation matrix (benchmarks/evals/generalisation.py): cells, a tiny run and its
resume."""

from __future__ import annotations

import csv
import json

import pytest

from benchmarks.evals import generalisation
from peghole_mjx.core.errors import UserInputError
from peghole_mjx.geometry.specs import PRESETS, get_preset, with_changes


def test_cells_are_the_presets_of_the_policy_kind_and_a_held_out_geometry():
    cells = generalisation.cells("rect", None, custom=True)
    assert list(cells) == ["rect-1", "rect-2", "rect-3", "custom"]
    for kind, changes in generalisation.HELD_OUT.items():
        spec = with_changes(get_preset(f"{kind}-2"), **changes)  # valid, and not a preset
        assert all(spec != p for p in PRESETS.values())
    with pytest.raises(UserInputError, match="not a rect geometry"):
        generalisation.cells("rect", ["dual-1"], custom=False)


@pytest.mark.slow
def test_generalisation_command_runs_a_cell_and_resumes(tmp_path, capsys):
    """Two episodes on the held-out geometry: policy and baseline on the same episodes, the
    difference from the training env recorded, JSON and CSV written; a rerun loads the cell.
    On the ``mujoco`` engine (a cross evaluation of the MJX-trained policy: its MJX rollout
    graphs took two minutes of the suite to compile, 2026-12-03)."""
    out = tmp_path / "g.json"
    argv = ["--policy", "rect", "--presets", "--episodes", "2", "--engine", "mujoco"]
    argv += ["--no-progress"]
    argv += ["--parts", str(tmp_path / "parts"), "--out", str(out)]
    assert generalisation.main(argv) == 0
    doc = json.loads(out.read_text())
    assert {"device", "versions", "date", "episodes_per_cell", "seed"} <= set(doc)
    assert doc["complete"] and doc["cells_planned"] == ["custom"]
    (cell,) = doc["cells"]
    assert cell["cell"] == "custom" and not cell["trained_on"]
    assert set(cell["differs_from_training"]) == {"geometry"}  # the engine: provenance
    assert doc["engine"] == "mujoco"
    assert "49.9 x 29.9" in cell["describe"]
    for who in ("policy", "baseline"):
        assert cell[who]["episodes"] == 2
        assert set(generalisation.METRICS) <= set(cell[who])
    rows = list(csv.DictReader(out.with_suffix(".csv").open()))
    assert [r["method"] for r in rows] == ["policy", "baseline"]
    assert all(r["device"] and r["versions"] and r["date"] for r in rows)
    capsys.readouterr()
    assert generalisation.main(argv) == 0  # the finished cell is loaded, not run again
    assert "custom: loaded from" in capsys.readouterr().err
    assert json.loads(out.read_text())["cells"] == doc["cells"]
