"""One figure style: the Okabe–Ito palette everywhere, plots drawn into the caller's axes, lab figures
that show() (issue 31)."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from lavendersim import figures as F
from lavendersim.validate import LavenderInputError

ROOT = Path(__file__).resolve().parents[1]


def test_palette_is_okabe_ito_and_axis_styles_differ_in_more_than_colour():
    assert set(F.CYCLE) == set(F.OKABE_ITO.values())
    styles = [F.axis_style(k) for k in range(3)]
    assert len({s["ls"] for s in styles}) == 3 and len({s["marker"] for s in styles}) == 3
    assert F.STATUS_STYLE["pass"]["hatch"] != F.STATUS_STYLE["fail"]["hatch"]


def test_no_plot_picks_a_colour_outside_the_palette():
    """matplotlib's tab10 names and C0..C9 cycle indices are not colour-blind safe; the labs use figures'."""
    for path in ROOT.glob("labs/*.py"):
        text = path.read_text(encoding="utf-8")
        assert not re.search(r"""["']tab:\w+["']|color=f?["']C\{?\d""", text), path.name


def test_new_figure_shows_and_draws_into_given_axes():
    fig, axes = F.new_figure(1, 2, title="t")
    assert axes.shape == (1, 2)
    fig.show()                                   # headless Agg: no window, but no AttributeError either
    fig2, mine = F.new_figure(2, 1)
    got_fig, got = F.new_figure(1, 2, ax=mine.ravel())
    assert got_fig is fig2 and got[0, 1] is mine[1, 0]
    with pytest.raises(LavenderInputError, match="ax"):
        F.new_figure(2, 2, ax=mine.ravel())


def test_lab_figure_into_the_callers_axes():
    from lavendersim import labs

    r = labs.compute("01")
    fig = r.figure()
    assert len(fig.axes) == 2
    mine, axes = F.new_figure(1, 2)
    assert r.figure("equal_torque", ax=axes.ravel()) is mine
    assert len(axes[0, 0].lines) == len(fig.axes[0].lines) > 0
    np.testing.assert_array_equal(axes[0, 0].lines[0].get_ydata(), fig.axes[0].lines[0].get_ydata())


@pytest.mark.parametrize("module, fn", [("force", "_plot"), ("momentum", "_plot"), ("lab01_equal_torque", "_plot"),
                                        ("lab02_orientation", "_plot"), ("lab03_torque_free", "_plot"),
                                        ("lab04_reaction_wheel", "_plot"), ("hard_cases", "_plots"),
                                        ("accuracy", "_plot_one"), ("atlas", "_plot_one")])
def test_every_lab_plot_takes_ax(module, fn):
    import importlib
    import inspect

    f = getattr(importlib.import_module(f"lavendersim.labs.{module}"), fn)
    p = inspect.signature(f).parameters.get("ax")
    assert p is not None and p.default is None, f"{module}.{fn}"
