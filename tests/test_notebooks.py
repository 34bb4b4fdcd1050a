"""The chapter notebooks: outputs stripped in git, and every one executes top to bottom.

Execution repeats the labs end to end (each notebook runs its lab plus the same experiment with the
public API), so it is in the slow set: `.ci/run` runs it with `pytest -m slow`; run one with
`pytest -m slow tests/test_notebooks.py -k force`.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import missing

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
EXPECTED = {"force", "momentum", "lab01_equal_torque", "lab02_orientation", "lab03_torque_free",
            "lab04_reaction_wheel", "accuracy", "hard_cases", "spacecraft_cubesat"}
ALL = sorted(NOTEBOOKS.glob("*.ipynb"))


def test_one_notebook_per_chapter_lab():
    assert {p.stem for p in ALL} == EXPECTED


@pytest.mark.parametrize("path", ALL, ids=[p.stem for p in ALL])
def test_outputs_are_stripped(path):
    nb = json.loads(path.read_text(encoding="utf-8"))
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] == "code":
            assert cell.get("outputs") == [] and cell.get("execution_count") is None, f"{path.name} cell {i} has outputs"


@pytest.mark.parametrize("path", ALL, ids=[p.stem for p in ALL])
def test_reads_like_a_card(path):
    text = path.read_text(encoding="utf-8")
    for section in ("**Question.**", "## Predict", "## Run", "## Paw-check"):
        assert section in text, f"{path.name} lacks {section}"


@pytest.mark.slow
@pytest.mark.needs("notebooks")
@pytest.mark.parametrize("path", ALL, ids=[p.stem for p in ALL])
def test_notebook_executes(path, tmp_path, monkeypatch):
    import nbformat
    from nbclient import NotebookClient

    assert missing("notebooks") is None
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
    images = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if "image/png" in o.get("data", {})]
    assert images, f"{path.name} drew no plot inline"
