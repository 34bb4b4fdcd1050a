"""Sphinx configuration of the LavenderSim documentation.

Build (warnings are errors, as in CI):  sphinx-build -W --keep-going -b html docs docs/_build/html
Needs the `docs` extra: pip install -e '.[docs]'.
"""
from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

import lavendersim  # noqa: E402

project = "LavenderSim"
author = "The LavenderSim authors"
copyright = "The LavenderSim authors (MIT)"
release = version = lavendersim.__version__

extensions = [
    "myst_nb",   # MyST Markdown (it loads myst_parser itself) and the notebooks in nb/ (a link to ../notebooks)
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "sphinx.ext.intersphinx",
]
# LAVENDERSIM_DOCS_VIEWCODE=off leaves out the highlighted source pages (_modules/, a [source] link per object):
# tests/test_docs checks the structure without them (4 s of its 32 s CPU); the full site (.ci/run, test_docs_site) has them
if os.environ.get("LAVENDERSIM_DOCS_VIEWCODE") == "off":
    extensions.remove("sphinx.ext.viewcode")
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**/.ipynb_checkpoints"]

# The notebooks (docs/nb -> ../notebooks) are stored with outputs stripped; the build executes them
# (their plots and tables appear on the pages) through jupyter-cache, in a cache keyed by the sources the
# outputs depend on (the package, the labs, the printed kernels, the notebooks), so a rebuild re-runs a
# notebook only when one of those changed. LAVENDERSIM_DOCS_EXECUTE=off renders the stored cells only
# (quick edits; no [viewer]/[control] extras needed); =force re-executes everything.
nb_execution_mode = os.environ.get("LAVENDERSIM_DOCS_EXECUTE", "cache")
nb_execution_timeout = 900            # per cell, s (the hard-cases notebook runs its lab)
nb_execution_raise_on_error = True    # a failing cell fails the build
nb_execution_show_tb = True

# numpydoc-style docstrings, read by napoleon
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_preprocess_types = False

autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "none"          # the docstrings state types, shapes, frames and units
autodoc_mock_imports: list[str] = []
add_module_names = False

myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_dmath_double_inline = True     # $$…$$ inside a paragraph (the notebooks' cards) is display math
myst_heading_anchors = 3
# the README's headings skip levels (H1 -> H3) where it is included as the concepts page
# the types "ndarray, shape (3,)" would cross-reference the two attributes named shape
suppress_warnings = ["myst.header", "ref.python"]

html_theme = "alabaster"
html_title = f"LavenderSim {release}"
html_static_path = ["_static"]
html_css_files = ["lavendersim.css"]
html_theme_options = {"page_width": "1200px", "sidebar_width": "260px"}


# Docstrings write norms as |x| (plain text reads best in help()); in reStructuredText |x| would be a
# substitution reference. Escape each | outside ``literals`` and doctest lines before parsing.
def _escape_bars(app, what, name, obj, options, lines):
    for i, line in enumerate(lines):
        if line.lstrip().startswith((">>>", "...")) or "|" not in line:
            continue
        parts = line.split("``")
        lines[i] = "``".join(p.replace("|", r"\|") if k % 2 == 0 else p for k, p in enumerate(parts))


# ---------------------------------------------------------------------------------------------------
# The gallery (gallery.md): every plot of every lab, as `lavendersim lab all` draws it. Drawn at build
# time into docs/_gallery/ (ignored by git) and cached there, keyed by the sources that draw it (labs/,
# the figure style, the printed kernels), so a rebuild costs nothing until one of them changes. With
# LAVENDERSIM_LAB_OUT=DIR (the --out of a `lavendersim lab all` run) the PNGs are copied from there
# instead of re-running the labs. LAVENDERSIM_GALLERY=skip builds the page without images (quick edits).
DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
GALLERY = DOCS / "_gallery"
GALLERY_LABS = ("force", "momentum", "01", "02", "03", "04", "hard", "accuracy", "atlas")
GALLERY_DPI = 110                                    # what LabResult.save writes


def _gallery_key() -> str:
    h = hashlib.sha256(lavendersim.__version__.encode())
    for f in sorted([*ROOT.glob("labs/*.py"), ROOT / "lavendersim" / "figures.py", ROOT / "generated" / "manifest.json"]):
        h.update(f.name.encode() + f.read_bytes())
    return h.hexdigest()[:16]


def _gallery_images(name: str, source: Path | None) -> list[str]:
    """Draw (or copy) lab `name`'s PNGs into _gallery/NAME/; their file names."""
    dest = GALLERY / name
    dest.mkdir(parents=True, exist_ok=True)
    if source is not None and sorted((source / name).glob("*.png")):
        pngs = sorted((source / name).glob("*.png"))
        for png in pngs:
            shutil.copyfile(png, dest / png.name)
        return [png.name for png in pngs]
    from lavendersim import labs

    result = labs.compute(name, **labs.ALL_OPTIONS.get(name, {}))
    for fname in result.plot_names:
        result.figure(fname).savefig(dest / fname, dpi=GALLERY_DPI)
    return result.plot_names


def _make_gallery(app) -> None:
    key = _gallery_key()
    index = GALLERY / "index.md"
    stamp = GALLERY / "key.txt"
    if os.environ.get("LAVENDERSIM_GALLERY") == "skip":
        GALLERY.mkdir(exist_ok=True)
        index.write_text("*(gallery skipped: LAVENDERSIM_GALLERY=skip)*\n", encoding="utf-8")
        stamp.unlink(missing_ok=True)
        return
    if stamp.is_file() and stamp.read_text() == key and index.is_file():
        return
    source = os.environ.get("LAVENDERSIM_LAB_OUT")
    from lavendersim import labs

    GALLERY.mkdir(exist_ok=True)
    (GALLERY / ".gitignore").write_text("*\n")
    lines = []
    for name in GALLERY_LABS:
        title = labs.lab_module(name).TITLE
        lines += [f"## `lavendersim lab {name}`", "", title[0].upper() + title[1:] + ".", ""]
        for png in _gallery_images(name, Path(source) if source else None):
            lines += [f"```{{image}} _gallery/{name}/{png}", f":alt: lab {name}: {png}", ":width: 100%", "```", ""]
    index.write_text("\n".join(lines), encoding="utf-8")
    stamp.write_text(key)


exclude_patterns.append("_gallery")

# Links into Python, NumPy, python-control and Gymnasium. The build runs offline (CI has no network), so
# the inventories are local: docs/_inv/*.inv list the objects the pages link, with the projects' URLs
# (docs/_inv/make_inventories.py writes them).
intersphinx_mapping = {
    "python": ("https://docs.python.org/3/", str(DOCS / "_inv" / "python.inv")),
    "numpy": ("https://numpy.org/doc/stable/", str(DOCS / "_inv" / "numpy.inv")),
    "control": ("https://python-control.readthedocs.io/en/latest/", str(DOCS / "_inv" / "control.inv")),
    "gymnasium": ("https://gymnasium.farama.org/", str(DOCS / "_inv" / "gymnasium.inv")),
}
intersphinx_timeout = 5


def _sources_key() -> str:
    """What the notebooks' outputs depend on: the package, the labs, the printed kernels, the notebooks."""
    h = hashlib.sha256(lavendersim.__version__.encode())
    files = [*ROOT.glob("lavendersim/**/*.py"), *ROOT.glob("labs/*.py"), *ROOT.glob("generated/*.py"),
             ROOT / "generated" / "manifest.json", *ROOT.glob("notebooks/*.ipynb")]
    for f in sorted(files):
        h.update(str(f.relative_to(ROOT)).encode() + f.read_bytes())
    return h.hexdigest()[:16]


# in the source tree (docs/_build, ignored by git), so every build of this checkout shares it, whatever
# its output folder (tests/test_docs.py builds into a temporary one)
nb_execution_cache_path = str(DOCS / "_build" / "jupyter_cache" / _sources_key())


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars, priority=100)
    app.connect("builder-inited", _make_gallery)
