"""The README tells the truth: its Python snippets run as written, it opens with the two commands
that .ci/run executes, and it names the six integrators there are."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import require

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
SNIPPETS = re.findall(r"```python\n(.*?)```", README, re.S)


def test_readme_opens_with_the_two_commands_ci_runs():
    first = re.search(r"```bash\n(.*?)```", README, re.S).group(1).strip().splitlines()
    assert first == ["pip install -e . && lavendersim lab all", "pip install -e '.[test]' && pytest"]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert "pip install -e '.[test]' && pytest\n" in ci
    assert "lavendersim lab all" in ci


def test_integrator_count_matches():
    from lavendersim.backends import INTEGRATORS

    words = {6: "Six", 7: "Seven", 8: "Eight", 9: "Nine", 10: "Ten"}
    assert f"({len(INTEGRATORS)} integrators)" in README
    assert f"{words[len(INTEGRATORS)]} integrators" in README


@pytest.mark.parametrize("index", range(len(SNIPPETS)))
def test_python_snippet_runs_as_written(index, capsys):
    code = SNIPPETS[index]
    if "lavendersim.viewer" in code:
        require("viewer")
        # the README's fixed port may be taken on a shared machine; any free port shows the same thing
        code = code.replace("Viewer(port=8080)", "Viewer(port=0)")
    exec(compile(code, f"README.md python snippet {index}", "exec"), {"__name__": "readme_snippet"})
