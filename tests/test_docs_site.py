"""The documentation site as CI builds it: notebooks executed (cached) with their figures on the pages,
and a gallery holding every plot of every lab (issue 31). Slow: it runs the notebooks and the labs once
per checkout (the cache in docs/_build and docs/_gallery then serves .ci/run's own sphinx-build)."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.needs("docs", "control", "viewer"), pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("docs-site")
    env = {k: v for k, v in os.environ.items() if k not in ("LAVENDERSIM_DOCS_EXECUTE", "LAVENDERSIM_GALLERY",
                                                                 "LAVENDERSIM_DOCS_VIEWCODE")}
    r = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(out)],
                       capture_output=True, text=True, cwd=ROOT, timeout=3600, env=env)
    assert r.returncode == 0, f"sphinx-build -W failed (exit {r.returncode}):\n{r.stdout}\n{r.stderr[-5000:]}"
    return out


def test_every_notebook_page_shows_its_outputs(site):
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        html = (site / "nb" / f"{nb.stem}.html").read_text(encoding="utf-8")
        assert re.search(r'<img [^>]*src="[^"]*\.png"', html), f"{nb.name}: no output image on its page"
        assert 'class="cell_output' in html, nb.name


def test_gallery_holds_every_lab_plot(site):
    from lavendersim.labs import LABS

    html = (site / "gallery.html").read_text(encoding="utf-8")
    for name in LABS:
        pngs = sorted((DOCS / "_gallery" / name).glob("*.png"))
        assert pngs, name
        for png in pngs:
            assert f"{png.name}" in html and (site / "_images" / png.name).is_file(), f"{name}/{png.name}"


def test_math_renders_as_display_math(site):
    """$$…$$ inside a notebook's paragraph (the cards of labs 01 and 02) is display math, not $ \\(…\\) $."""
    for page in ("lab01_equal_torque", "lab02_orientation"):
        html = (site / "nb" / f"{page}.html").read_text(encoding="utf-8")
        assert "$<span class=\"math" not in html and "\\[" in html, page
