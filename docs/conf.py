"""Sphinx configuration of the LavenderSim documentation.

Build (warnings are errors, as in CI):  sphinx-build -W --keep-going -b html docs docs/_build/html
Needs the `docs` extra: pip install -e '.[docs]'.
"""
from __future__ import annotations

import os

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
]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**/.ipynb_checkpoints"]

# The notebooks (docs/nb -> ../notebooks) are stored with outputs stripped and rendered as they are:
# their source cells, never executed here (CI executes every one in tests/test_notebooks.py).
nb_execution_mode = "off"

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
myst_heading_anchors = 3
# the README's headings skip levels (H1 -> H3) where it is included as the concepts page
# the types "ndarray, shape (3,)" would cross-reference the two attributes named shape
suppress_warnings = ["myst.header", "ref.python"]

html_theme = "alabaster"
html_title = f"LavenderSim {release}"


# Docstrings write norms as |x| (plain text reads best in help()); in reStructuredText |x| would be a
# substitution reference. Escape each | outside ``literals`` and doctest lines before parsing.
def _escape_bars(app, what, name, obj, options, lines):
    for i, line in enumerate(lines):
        if line.lstrip().startswith((">>>", "...")) or "|" not in line:
            continue
        parts = line.split("``")
        lines[i] = "``".join(p.replace("|", r"\|") if k % 2 == 0 else p for k, p in enumerate(parts))


def setup(app):
    app.connect("autodoc-process-docstring", _escape_bars, priority=100)
