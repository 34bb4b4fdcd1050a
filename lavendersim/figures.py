"""Headless matplotlib figures for the library's and the labs' plots (an Agg canvas, no pyplot state)."""
from __future__ import annotations


def new_figure(nrows: int = 1, ncols: int = 1, *, size=(8.0, 4.5), title: str | None = None):
    """A headless matplotlib Figure (Agg canvas) and its axes array.

    Parameters
    ----------
    nrows, ncols : int, default 1
        Grid of axes.
    size : tuple (float, float), default (8.0, 4.5)
        Figure size, inches.
    title : str, optional
        Figure title (suptitle).

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray (nrows, ncols) of Axes
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    if title:
        fig.suptitle(title)
    return fig, axes
