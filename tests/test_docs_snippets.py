"""The guide pages' Python snippets run as written (what the README carried before it moved to docs/).

Covers the pages without a test of their own; docs/extending.md has tests/test_extending.py, the
spacecraft pages their notebook.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import require

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGES = ("getting_started", "concepts", "labs", "wheels", "viewer")
SNIPPETS = [(page, i, code) for page in PAGES
            for i, code in enumerate(re.findall(r"```python\n(.*?)```", (DOCS / f"{page}.md").read_text(encoding="utf-8"), re.S))]


def test_every_page_has_a_snippet():
    assert {page for page, _, _ in SNIPPETS} == set(PAGES)


@pytest.mark.parametrize("page, index, code", SNIPPETS, ids=[f"{p}-{i}" for p, i, _ in SNIPPETS])
def test_python_snippet_runs_as_written(page, index, code, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)          # a snippet may write a file (labs.md saves a PNG)
    if "lavendersim.viewer" in code:
        require("viewer")
        code = code.replace("Viewer(port=8080)", "Viewer(port=0)")   # the fixed port may be taken here
    if "lavendersim import control" in code:
        require("control")
    exec(compile(code, f"docs/{page}.md python snippet {index}", "exec"), {"__name__": "docs_snippet"})
