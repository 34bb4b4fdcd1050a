"""One figure style for every plot of the library and the labs: headless figures, one colour-blind-safe
palette, line styles that tell lines apart without colour.

The palette is Okabe & Ito's eight colours ("Color Universal Design", 2008), distinguishable under the
common colour-vision deficiencies. Lines a reader must tell apart also differ in line style or marker
(:data:`AXIS_STYLE` for x/y/z components, :data:`STATUS_STYLE` for pass/fail maps), so a figure still
reads in greyscale or under deuteranopia. Figures are made without pyplot (no global state, nothing
needed on screen); :meth:`LabFigure.show` hands one to pyplot when you want a window.
"""
from __future__ import annotations

from typing import Any

#: Okabe–Ito colours by name.
OKABE_ITO: dict[str, str] = {
    "black": "#000000", "orange": "#E69F00", "sky_blue": "#56B4E9", "green": "#009E73",
    "yellow": "#F0E442", "blue": "#0072B2", "vermillion": "#D55E00", "purple": "#CC79A7",
}
BLACK, ORANGE, SKY_BLUE, GREEN, YELLOW, BLUE, VERMILLION, PURPLE = OKABE_ITO.values()
GREY = "#999999"

#: The colour cycle of every axes: most distinct first (yellow last: weak on white).
CYCLE: tuple[str, ...] = (BLUE, ORANGE, GREEN, VERMILLION, PURPLE, SKY_BLUE, BLACK, YELLOW)
#: Line styles and markers to pair with CYCLE when lines must be told apart without colour.
LINESTYLES: tuple[Any, ...] = ("-", "--", "-.", ":", (0, (5, 1, 1, 1, 1, 1)), (0, (1, 3)))
MARKERS: tuple[str, ...] = ("o", "s", "^", "D", "v", "P", "X", "*")

#: Components x, y, z (body or world axes): colour, line style and marker differ.
AXIS_STYLE: dict[str, dict[str, Any]] = {
    "x": {"color": VERMILLION, "ls": "-", "marker": "o"},
    "y": {"color": BLUE, "ls": "--", "marker": "s"},
    "z": {"color": GREEN, "ls": "-.", "marker": "^"},
}
#: Outcomes of a check or a cell: colour and hatch differ (bars, patches, heat-map cells).
STATUS_STYLE: dict[str, dict[str, Any]] = {
    "pass": {"color": BLUE, "hatch": ""},
    "fail": {"color": VERMILLION, "hatch": "xx"},
    "error": {"color": BLACK, "hatch": ""},
    "skipped": {"color": "#DDDDDD", "hatch": ".."},
}

def axis_style(k: int | str, **overrides: Any) -> dict[str, Any]:
    """Plot keywords of component ``k`` (0/1/2 or "x"/"y"/"z"): colour, line style, marker.

    Parameters
    ----------
    k : int or str
        Component index or name.
    **overrides
        Keywords replacing the style's (e.g. ``marker=None``).

    Returns
    -------
    dict
        Keywords for ``Axes.plot``.
    """
    name = "xyz"[k] if isinstance(k, int) else k
    return {**AXIS_STYLE[name], **overrides}


def _figure_class():
    from matplotlib.figure import Figure

    class LabFigure(Figure):
        """A matplotlib Figure made headless (Agg) that ``show()`` can still display.

        ``show()`` adopts the figure into pyplot (its current backend) on first use, then shows it as a
        pyplot figure would; until then nothing is registered with pyplot.
        """

        def show(self, warn: bool = True) -> None:  # noqa: D102 (matplotlib's docstring)
            if self.canvas.manager is None:
                import matplotlib.pyplot as plt
                from matplotlib import _pylab_helpers

                try:
                    plt.figure(self)          # matplotlib >= 3.10 adopts a figure pyplot did not make
                except ValueError:            # older: the same through the backend module
                    num = max(plt.get_fignums(), default=0) + 1
                    manager = plt._get_backend_mod().new_figure_manager_given_figure(num, self)
                    _pylab_helpers.Gcf._set_new_active_manager(manager)
            super().show(warn)

    LabFigure.__qualname__ = "LabFigure"
    return LabFigure


_LAB_FIGURE = None


def __getattr__(name: str):
    """``LabFigure``: the figure class of :func:`new_figure`, built on first use (importing this module does not
    import matplotlib)."""
    global _LAB_FIGURE
    if name == "LabFigure":
        if _LAB_FIGURE is None:
            _LAB_FIGURE = _figure_class()
        return _LAB_FIGURE
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def new_figure(nrows: int = 1, ncols: int = 1, *, size=(8.0, 4.5), title: str | None = None, ax=None,
               layout: str | None = "constrained"):
    """A headless matplotlib Figure in the house style and its axes array, or the caller's axes.

    Parameters
    ----------
    nrows, ncols : int, default 1
        Grid of axes.
    size : tuple (float, float), default (8.0, 4.5)
        Figure size, inches.
    title : str, optional
        Figure title (suptitle; not set on a figure the caller passed ``ax`` of).
    ax : matplotlib Axes or sequence of Axes, optional
        Draw into these instead (``nrows * ncols`` of them, in row order); the figure is theirs.
    layout : {"constrained", None}, default "constrained"
        The figure's layout engine; None for a caller that places the axes itself (``subplots_adjust``).

    Returns
    -------
    fig : matplotlib.figure.Figure
        A :class:`LabFigure` (``show()`` works) unless ``ax`` was given.
    axes : ndarray (nrows, ncols) of Axes

    Raises
    ------
    lavendersim.validate.LavenderInputError
        ``ax`` holds another number of axes than the plot draws.
    """
    import numpy as np

    if ax is not None:
        axes = np.asarray(ax, dtype=object).reshape(-1)
        if axes.size != nrows * ncols:
            from .validate import LavenderInputError

            raise LavenderInputError("ax", f"this plot draws {nrows * ncols} axes ({nrows} × {ncols})",
                                     f", got {axes.size}")
        return axes[0].get_figure(), axes.reshape(nrows, ncols)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    global _LAB_FIGURE
    if _LAB_FIGURE is None:
        _LAB_FIGURE = _figure_class()
    fig = _LAB_FIGURE(figsize=size, layout=layout)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    for a in axes.flat:
        style_axes(a)
    if title:
        fig.suptitle(title)
    return fig, axes


def style_axes(ax) -> None:
    """Apply the house colour cycle to axes made elsewhere (e.g. the caller's ``ax=``).

    Parameters
    ----------
    ax : matplotlib Axes
    """
    ax.set_prop_cycle(color=list(CYCLE))


def legend_below(ax, ncols: int = 2, handles=None, labels=None, **kw: Any):
    """A legend under the axes, outside the data (constrained layout makes room for it).

    Parameters
    ----------
    ax : matplotlib Axes
    ncols : int, default 2
        Legend columns.
    handles, labels : list, optional
        As for ``Axes.legend`` (default: the axes' labelled artists).
    **kw
        Further ``Axes.legend`` keywords (``fontsize`` defaults to 8).

    Returns
    -------
    matplotlib.legend.Legend
    """
    kw.setdefault("fontsize", 8)
    args = () if handles is None else ((handles,) if labels is None else (handles, labels))
    return ax.legend(*args, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncols=ncols, frameon=False, **kw)
