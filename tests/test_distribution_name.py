"""The distribution name is ours, not the package index's `lavendersim`.

On PyPI, `lavendersim` is another, older project (a robotics simulator with the same import name).
This project's distribution is ``lavender-rigid-body`` (free on PyPI when chosen, session 15); the import
name stays ``lavendersim``. These tests fail if pyproject's name goes back to the taken one, or if the
name pyproject declares, the one the code reads (``lavendersim._version.DISTRIBUTION``) and the one
the installed metadata carries disagree.
"""
from __future__ import annotations

import re
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

import lavendersim
from lavendersim import _install, _version

ROOT = Path(__file__).resolve().parents[1]
TAKEN = "lavendersim"   # on PyPI: https://pypi.org/project/lavendersim/ (not this project)


def _normalize(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()   # PEP 503


def _project() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def test_pyproject_name_is_not_the_taken_one():
    name = _project()["name"]
    assert _normalize(name) != TAKEN, f"pyproject's name {name!r} is the PyPI name of another project"
    assert _normalize(name) == _normalize(_version.DISTRIBUTION) == "lavender-rigid-body"


def test_installed_metadata_agrees_with_pyproject():
    dist = metadata.distribution(_version.DISTRIBUTION)   # PackageNotFoundError: installed under another name
    assert _normalize(dist.metadata["Name"]) == _normalize(_project()["name"])
    assert dist.version == lavendersim.__version__
    assert "lavendersim" in (dist.read_text("top_level.txt") or "lavendersim").split()


def test_the_extras_refer_to_this_distribution():
    """`test` and `all` pull the other extras by the distribution's name: under the taken name, pip would
    fetch the other project from the index."""
    extras = _project()["optional-dependencies"]
    self_refs = [r for reqs in extras.values() for r in reqs if r.split("[")[0].strip() in (TAKEN, _version.DISTRIBUTION)]
    assert self_refs, "the test/all extras no longer refer to the project itself"
    assert all(r.startswith(_version.DISTRIBUTION + "[") for r in self_refs), self_refs


def test_install_messages_never_send_users_to_the_taken_name(monkeypatch):
    monkeypatch.setattr(_install, "_direct_url", lambda: {"url": "https://files.example/x.whl", "archive_info": {}})
    assert _install.extra_command("control") == "pip install 'lavender-rigid-body[control]'"
    assert _install.rebuild_command().endswith(" lavender-rigid-body")


@pytest.mark.parametrize("doc", ["README.md", "docs/install.md"])
def test_the_docs_say_how_the_two_names_relate(doc):
    text = (ROOT / doc).read_text()
    assert "lavender-rigid-body" in text and "pip install lavendersim" in text
    assert "one environment holds one of the two" in " ".join(text.split())
