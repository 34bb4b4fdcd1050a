"""The documentation site builds with warnings as errors, and its pages link what they name.

Slow set (issue 31, test time): its Sphinx build (the structure: notebooks as stored, no gallery, no source pages)
cost ~30 s CPU, the largest setup of the README's `pytest` after the shared derivation and lab sweeps, and it
checks the documentation, not the code a test run exercises. CI still builds and checks the site three ways:
`pytest -m slow` runs this module and tests/test_docs_site.py (the full site: notebooks executed, the gallery),
and .ci/run's `sphinx-build -W`. The names the docstrings point to are resolved quickly by
tests/test_docstring_names.py, the numpydoc sections checked by tests/test_docstrings.py, in the default set."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.needs("docs"), pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("docs-html")
    # the structure only: notebooks rendered as stored, the gallery's labs not run, no highlighted source pages
    # (_modules/: none is checked here) (the executed site with its pictures and sources: tests/test_docs_site.py, in
    # the slow set, and .ci/run's sphinx-build)
    env = {**os.environ, "LAVENDERSIM_DOCS_EXECUTE": "off", "LAVENDERSIM_GALLERY": "skip",
           "LAVENDERSIM_DOCS_VIEWCODE": "off"}
    r = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(out)],
                       capture_output=True, text=True, cwd=ROOT, timeout=1200, env=env)
    assert r.returncode == 0, f"sphinx-build -W failed (exit {r.returncode}):\n{r.stdout}\n{r.stderr}"
    return out


def _xrefs(html: str) -> list[tuple[bool, str]]:
    """(resolved, text) of every Python cross-reference on a page."""
    pat = r'(<a class="reference internal" href="[^"]*"[^>]*>)?<code class="xref py[^>]*><span class="pre">([^<]*)'
    return [(bool(m.group(1)), m.group(2)) for m in re.finditer(pat, html)]


def test_pages_exist(site):
    for page in ("index", "concepts", "extending", "symbolic", "chapter_names", "notebooks", "api", "api/lavendersim.sim",
                 "api/lavendersim.derive.symbolic", "api/lavendersim.backends",
                 "api/lavendersim.generated.kernels_numpy"):
        assert (site / f"{page}.html").is_file(), page


def test_notebooks_are_rendered(site):
    """Every notebook in notebooks/ is a page (docs/nb links there), its cells rendered as stored, and
    the notebooks page lists each."""
    index = (site / "notebooks.html").read_text(encoding="utf-8")
    notebooks = sorted((ROOT / "notebooks").glob("*.ipynb"))
    assert notebooks
    for nb in notebooks:
        page = site / "nb" / f"{nb.stem}.html"
        assert page.is_file(), nb.name
        html = page.read_text(encoding="utf-8")
        assert "## Predict" not in html and "<h2>Predict<" in html, nb.name       # markdown cells rendered
        assert 'class="cell docutils container"' in html, nb.name                 # code cells rendered
        assert f'href="nb/{nb.stem}.html"' in index, nb.name


def test_api_reference_comes_from_the_docstrings(site):
    sim = (site / "api" / "lavendersim.sim.html").read_text(encoding="utf-8")
    for name in ("Sim.run", "Sim.record", "Sim.set_state", "Trajectory.body"):
        assert f'id="lavendersim.sim.{name}"' in sim, name
    assert "DivergenceError" in sim and "Parameters" in sim
    K = (site / "api" / "lavendersim.generated.kernels_numpy.html").read_text(encoding="utf-8")
    assert 'id="lavendersim.generated.kernels_numpy.apply_inv_inertia"' in K


def test_chapter_names_page_links_every_name(site):
    chapter = Path(__file__).resolve().parents[2] / "shared" / "chapter-03-rigid-body-mechanics.txt"
    html = (site / "chapter_names.html").read_text(encoding="utf-8")
    refs = _xrefs(html)
    assert refs and all(ok for ok, _ in refs), [t for ok, t in refs if not ok]
    named = {"apply_inv_inertia", "integrate_orientation", "publish_frame"}
    if chapter.is_file():   # beside the repository on the course machines; the three names otherwise
        named |= set(re.findall(r"(?<![.\w])([a-z_][a-z0-9_]*)\(\)", chapter.read_text(encoding="utf-8")))
    texts = " ".join(t for _, t in refs)
    for name in sorted(named):
        assert f"{name}()" in texts or f".{name}()" in texts, f"the chapter names {name}() but the page does not link it"


def test_symbolic_and_concepts_pages(site):
    sym = (site / "symbolic.html").read_text(encoding="utf-8")
    refs = _xrefs(sym)
    assert refs and all(ok for ok, _ in refs), [t for ok, t in refs if not ok]
    concepts = (site / "concepts.html").read_text(encoding="utf-8")
    assert "Conventions" in concepts and "extending.html" in concepts
