"""The version and the distribution name of LavenderSim, in one place (pyproject.toml reads the version
from here; tests/test_distribution_name.py checks that pyproject's ``name`` is ``DISTRIBUTION``).

The import name is ``lavendersim``; the distribution name (what ``pip`` installs, lists and
uninstalls) is ``DISTRIBUTION``. ``lavendersim`` on PyPI is a different, unrelated project with the
same import name; one environment holds one of the two.
"""

__version__ = "0.2.0"
DISTRIBUTION = "lavender-rigid-body"
