"""Figures of the report laid out once, by margins in inches: no layout engine (constrained
or tight layout draws every figure twice when it is saved, to measure it, and costs more than
the drawing), and titles where they are put (not moved above the tick labels at each draw,
which measures every tick label again). Made by pyplot, so that a notebook shows them."""

from __future__ import annotations

from dataclasses import dataclass

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure


@dataclass(frozen=True)
class Margins:
    """Space [in] around and between the panels of a grid: beside the grid (``left``,
    ``right``), above it (``top``: the panels' titles, a suptitle), below it (``bottom``: tick
    labels and the x label), between columns (``across``: the y tick labels and label of the
    next column) and between lines (``between``: x tick labels, x label and the next title)."""

    left: float = 0.8
    right: float = 0.2
    bottom: float = 0.55
    top: float = 0.35
    across: float = 0.8
    between: float = 0.75


def new_figure(size: tuple[float, float]) -> Figure:
    """An empty figure of ``size`` [in], made by pyplot (closed by :func:`figure_png
    <brdf_infer.report._raytrace.figure_png>` once saved)."""
    return plt.figure(figsize=size)


def panels(
    size: tuple[float, float],
    lines: int = 1,
    columns: int = 1,
    margins: Margins = Margins(),
    **subplots,
) -> tuple[Figure, np.ndarray]:
    """A figure of ``size`` [in] and its ``lines`` × ``columns`` panels (an array of that shape),
    placed by ``margins``; ``subplots``: Figure.subplots' keywords (sharex, subplot_kw, …).
    A panel's title sits its pad (``set_title(pad=…)``) above the panel."""
    width, height = size
    figure = new_figure(size)
    panel_width = (width - margins.left - margins.right - margins.across * (columns - 1)) / columns
    panel_height = (height - margins.top - margins.bottom - margins.between * (lines - 1)) / lines
    figure.subplots_adjust(
        left=margins.left / width,
        right=1.0 - margins.right / width,
        bottom=margins.bottom / height,
        top=1.0 - margins.top / height,
        wspace=margins.across / panel_width,
        hspace=margins.between / panel_height,
    )
    with matplotlib.rc_context({"axes.titley": 1.0}):
        return figure, figure.subplots(lines, columns, squeeze=False, **subplots)


def colour_bar_axis(
    figure: Figure, beside: list[Axes], gap: float = 0.15, width: float = 0.15, shrink: float = 1.0
) -> Axes:
    """An axis for a colour bar ``gap`` [in] right of the panels ``beside``, ``width`` [in]
    wide and ``shrink`` times as tall as they span, centred on them."""
    boxes = [axis.get_position() for axis in beside]
    low, high = min(b.y0 for b in boxes), max(b.y1 for b in boxes)
    right = max(b.x1 for b in boxes)
    inches = figure.get_figwidth()
    height = shrink * (high - low)
    return figure.add_axes(
        (right + gap / inches, (low + high - height) / 2, width / inches, height)
    )
