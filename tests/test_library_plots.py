"""The library's own plots (issue 31): the closed loop's four panels (Response.plot, what `lqr --plot` writes) in
the house palette, drawn into the caller's axes with ``axes=``, components told apart by line style as well as
colour, legends below the data, and a returned figure whose ``show()`` works headless."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.colors import to_hex

from lavendersim import figures as F
from lavendersim.validate import LavenderInputError

pytestmark = pytest.mark.needs("control")
ROOT = Path(__file__).resolve().parents[1]
PALETTE = {c.lower() for c in F.OKABE_ITO.values()} | {F.GREY.lower()}


@pytest.fixture(scope="module")
def response():
    from lavendersim import control as lc

    scene = lc.chapter_cube("center")
    ctrl = lc.design(scene, period=0.01)
    return lc.closed_loop(scene, ctrl, T=1.0, q0=lc.rotated(ctrl.q_ref, (1.0, -1.0, 2.0), 20.0), backend="c")


def _colours(ax) -> set[str]:
    return {to_hex(line.get_color()).lower() for line in ax.lines}


def test_plot_uses_the_palette_and_styles(response):
    fig = response.plot(title="t")
    axes = fig.axes
    assert len(axes) == 4
    for a in axes:
        assert _colours(a) <= PALETTE, _colours(a)
        data = [ln for ln in a.lines if not ln.get_label().startswith(("_", "limit"))]
        # lines a reader must tell apart differ in colour AND line style
        assert len({to_hex(ln.get_color()) for ln in data}) == len(data)
        assert len({str(ln.get_linestyle()) for ln in data}) == len(data), [ln.get_label() for ln in data]
        leg = a.get_legend()
        assert leg is not None and leg.get_bbox_to_anchor().y0 < a.bbox.y0 - 1   # anchored below the axes, off the data
    rates = axes[1]
    assert [ln.get_label() for ln in rates.lines[:3]] == ["ω_x", "ω_y", "ω_z"]
    assert to_hex(rates.lines[0].get_color()) == F.AXIS_STYLE["x"]["color"].lower()


def test_plot_draws_into_the_callers_axes(response):
    mine, ax = F.new_figure(2, 2)
    got = response.plot(axes=ax.ravel())
    assert got is mine
    np.testing.assert_array_equal(ax[0, 0].lines[0].get_ydata(), np.maximum(response.error_deg, 1e-9))
    np.testing.assert_array_equal(ax[0, 1].lines[2].get_ydata(), response.omega_b[:, 2])
    assert len(ax[1, 1].lines) >= response.Omega.shape[1]
    assert mine._suptitle is None                 # the caller's figure keeps its own title
    with pytest.raises(LavenderInputError, match="ax"):
        response.plot(axes=ax.ravel()[:3])


def test_plot_figure_shows_headless_and_writes(response, tmp_path):
    fig = response.plot(tmp_path / "r.png")
    fig.show()                                      # a bare Agg Figure without a manager raised here
    assert (tmp_path / "r.png").stat().st_size > 10_000


def test_no_library_plot_picks_a_colour_outside_the_palette():
    """matplotlib's tab10 names and C0..C9 indices are not colour-blind safe; the library draws with figures'."""
    for path in (ROOT / "lavendersim").rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        assert not re.search(r"""["']tab:\w+["']|color=f?["']C\{?\d""", text), path.relative_to(ROOT)
