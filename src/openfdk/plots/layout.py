"""Layout of a column of stacked axes from measured text extents.

The run's figures are a column of shared-x axes with the legends outside on the right, a
suptitle above and a caption below. Matplotlib's constrained layout places them well,
but it measures every axes' decorations twice at each draw and was about a third of the
time to save a figure: 3.2 s of the DM knee's 46-panel body-pose figure, 7 s for the nine
figures of a gait cycle, a fifth of `openfdk run`'s time for it. Here the decorations
are measured once, when the figure is finished, and the axes are fixed where they fit:

* left margin: the widest y tick labels and y label (`yaxis.get_tightbbox`);
* right margin: the widest legend or left-aligned title past the axes' right edge;
* gaps between rows: what hangs below the upper axes (visible x tick labels and label,
  the lowest y tick label's lower half, a legend taller than its axes) and what stands
  above the lower one (a title, the highest y tick label's upper half);
* top: below the suptitle; bottom: above the caption's ``bottom_in`` inches, with the
  last axes' x tick labels and label.

Text extents are in points, so the layout in inches holds at any dpi the figure is saved
or shown at. Tick labels are measured once, after a first placement with typical margins, where the
axes' heights, and so their tick locations, are within a few per cent of the final ones;
the left margin keeps LEFT_SLACK_IN for a tick label that the final heights make wider.
"""

from __future__ import annotations

#: inches between decorations and the figure's edge or each other
PAD_IN = 0.08
#: inches added to the measured left margin: at the final axes heights the locators may
#: pick other y ticks ("−0.0005" where "0.000" was measured), about one character wider
#: at the tick labels' 10 points (measuring again cost as much as the layout saved)
LEFT_SLACK_IN = 0.12


def _extent_in(artist, renderer, dpi):
    """(x0, y0, x1, y1) inches of an artist's drawn extent, or None when it draws nothing."""
    if artist is None or not artist.get_visible():
        return None
    if hasattr(artist, "get_text") and not artist.get_text():
        return None
    box = artist.get_window_extent(renderer)
    if box.width <= 0 and box.height <= 0:
        return None
    return box.x0 / dpi, box.y0 / dpi, box.x1 / dpi, box.y1 / dpi


def _axis_extent_in(axis, renderer, dpi):
    """(x0, y0, x1, y1) inches of an axis' tick labels and label, or None."""
    box = axis.get_tightbbox(renderer)
    if box is None or (box.width <= 0 and box.height <= 0):
        return None
    return box.x0 / dpi, box.y0 / dpi, box.x1 / dpi, box.y1 / dpi


def _margins(fig, axes, renderer, bottom_in, pad_in):
    """(left, right, top, gap, bottom) inches the decorations of ``axes`` (top to bottom)
    need at their current placement (module docstring)."""
    dpi, height = fig.dpi, fig.get_size_inches()[1]
    left = right = top_title = above = below = last_below = 0.0
    for i, ax in enumerate(axes):
        x0, y0, x1, y1 = (v / dpi for v in ax.bbox.extents)
        y_box = _axis_extent_in(ax.yaxis, renderer, dpi)
        if y_box is not None:
            left = max(left, x0 - y_box[0])
        titles = [_extent_in(a, renderer, dpi) for a in (ax.title, ax._left_title, ax._right_title)]
        legend = _extent_in(ax.get_legend(), renderer, dpi)
        for e in titles + [legend]:
            if e is not None:
                right = max(right, e[2] - x1)
        # above the axes: a title, or the top y tick label's upper half; below: the x tick
        # labels and label, the bottom y tick label's lower half, a legend taller than the axes
        ups = [e[3] - y1 for e in titles + [y_box] if e is not None]
        x_box = _axis_extent_in(ax.xaxis, renderer, dpi)
        downs = [y0 - e[1] for e in (x_box, y_box, legend) if e is not None]
        title = max(ups + [0.0])
        x_below = max(downs + [0.0])
        if i == 0:
            top_title = title
        else:
            above = max(above, title)
        if i < len(axes) - 1:
            below = max(below, x_below)
        else:
            last_below = x_below
    suptitle = _extent_in(fig._suptitle, renderer, dpi)
    top = (height - suptitle[1] if suptitle is not None else 0.0) + top_title + pad_in
    return left + pad_in, right + pad_in, top, above + below + 2 * pad_in, bottom_in + last_below + pad_in


def stack_layout(fig, axes, bottom_in, pad_in=PAD_IN):
    """Place ``axes`` (a list, top to bottom, one column filling the width) of ``fig``
    (module docstring); ``bottom_in``: inches kept free at the bottom (the caption).
    Sets no layout engine: the positions are fixed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig.set_layout_engine(None)
    width, height = fig.get_size_inches()
    n = len(axes)

    def place(left, right, top, gap, bottom):
        axes_height = max((height - top - bottom - (n - 1) * gap) / n, 0.1)
        fig.subplots_adjust(left=left / width, right=1.0 - right / width, top=1.0 - top / height,
                            bottom=bottom / height, hspace=gap / axes_height if n > 1 else 0.0)

    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    renderer = canvas.get_renderer()
    place(1.0, 1.6, 0.5, 0.3, bottom_in + 0.5)  # typical margins: the axes' heights nearly the final ones
    left, right, top, gap, bottom = _margins(fig, axes, renderer, bottom_in, pad_in)
    place(left + LEFT_SLACK_IN, right, top, gap, bottom)
    return fig


__all__ = ["stack_layout", "PAD_IN", "LEFT_SLACK_IN"]
