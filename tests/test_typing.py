"""Types reach users (issue 31): a type checker sees LavenderSim through an editable install, and the public
signatures survive the validation decorator (`validate.keywords` is typed with ParamSpec).

Setuptools' default editable install puts an import hook in site-packages, which neither mypy nor pyright runs
(they never execute code), and LavenderSim's package-dir remap (lavendersim.generated -> generated/, ...) rules
out a plain path entry. The strict editable mode installs a tree of links that both follow; docs/install.md says
so. This test installs a copy of the tree that way into a venv and runs mypy on a user's snippet against it."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import require

ROOT = Path(__file__).resolve().parents[1]

SNIPPET = '''\
import lavendersim as lv

reveal_type(lv.Body.box)
reveal_type(lv.Sim)
cube = lv.Body.box(name="cube", mass="heavy", size=(0.1, 0.1, 0.1))
'''


def _copy_tree(dst: Path) -> None:
    shutil.copytree(ROOT, dst, ignore=shutil.ignore_patterns(".git", "build", "*.so", "__pycache__", "*.egg-info",
                                                               ".pytest_cache", ".mypy_cache", "_build", ".hypothesis"))


@pytest.mark.slow
def test_mypy_sees_an_editable_install_and_the_real_signatures(tmp_path):
    require("mypy")
    from mypy import api

    src, venv = tmp_path / "src", tmp_path / "venv"
    _copy_tree(src)
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], check=True)
    run = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--no-deps", "-q", "-e", str(src),
                          "--config-settings", "editable_mode=strict"], capture_output=True, text=True, timeout=3600)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    snippet = tmp_path / "user_code.py"
    snippet.write_text(SNIPPET)
    out, err, status = api.run(["--python-executable", str(venv / "bin" / "python"), "--follow-imports=silent",
                                "--cache-dir", str(tmp_path / "mypy_cache"), str(snippet)])
    assert "import-not-found" not in out and "import-untyped" not in out, out
    lines = out.splitlines()
    # mypy spells builtins "builtins.float" up to 1.13 and "float" after: either is the real signature
    box = next(l for l in lines if ":3: note: Revealed type is" in l)
    assert re.search(r"mass: (builtins\.)?float\b", box) and "-> lavendersim.bodies.Body" in box, box
    sim = next(l for l in lines if ":4: note: Revealed type is" in l)
    assert "scene: lavendersim.scene.Scene" in sim and re.search(r"integrator: (builtins\.)?str\b", sim), sim
    assert any(':5: error: Argument "mass" to "box" of "Body" has incompatible type "str"' in l for l in lines), out
    assert status == 1, (out, err)


def test_keywords_keeps_the_signature_for_type_checkers():
    """Without a type checker: the decorator's annotations carry the wrapped function's ParamSpec."""
    import typing

    from lavendersim import validate

    hints = typing.get_type_hints(validate.keywords)
    assert "ParamSpec" in repr(typing.get_args(hints["fn"])[0]) or "_P" in repr(hints["fn"])
    assert hints["return"] == hints["fn"]
