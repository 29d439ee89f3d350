"""The run figures' layout from measured text extents (openfdk.plots.layout), checked on the
drawn figure: every decoration inside the figure, no two axes' decorations overlapping,
the suptitle above and the caption below every axes, and the margins as tight as the
padding says (the widest legend ends PAD_IN from the right edge, the widest y labels
start PAD_IN from the left, LEFT_SLACK_IN more at most)."""

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from openfdk.plots.layout import LEFT_SLACK_IN, PAD_IN, stack_layout
from openfdk.plots.run import TITLE_TOP_IN, make_figures
from openfdk.results.run import read_results


def _drawn(fig):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def _check_layout(fig, tight=True, title_gap=False):
    renderer = _drawn(fig)
    W, H, dpi = fig.bbox.width, fig.bbox.height, fig.dpi
    axes = sorted(fig.axes, key=lambda ax: -ax.get_position().y0)
    boxes = [ax.get_tightbbox(renderer) for ax in axes]  # tick labels, labels, titles and legends
    for ax, box in zip(axes, boxes):
        assert box.x0 >= -1 and box.x1 <= W + 1 and box.y0 >= -1 and box.y1 <= H + 1, (ax.get_ylabel(), box)
    for upper, lower, a in zip(boxes, boxes[1:], axes):
        # the upper axes' decorations (x ticks, legend) end above where the lower's begin
        assert upper.y0 >= lower.y1 - 1, f"{a.get_ylabel()!r} overlaps the axes below it"
    if fig._suptitle is not None:
        title = fig._suptitle.get_window_extent(renderer)
        assert title.y0 >= boxes[0].y1 - 1, "suptitle overlaps the top axes"
        assert title.y1 <= H + 1
        if title_gap:  # the run figures' title TITLE_TOP_IN below the top edge, whatever the height
            assert H - title.y1 <= (TITLE_TOP_IN + 0.05) * dpi, ("blank above the title", (H - title.y1) / dpi)
    caption = fig.texts[-1].get_window_extent(renderer)
    assert caption.y1 <= min(b.y0 for b in boxes) + 1, "caption overlaps the axes"
    if tight:
        pad = PAD_IN * dpi
        tol = 2.0 + 0.02 * dpi  # text extents at another dpi differ by the font's hinting
        left = min(ax.yaxis.get_tightbbox(renderer).x0 for ax in axes)
        right = max([ax.get_legend().get_window_extent(renderer).x1 for ax in axes if ax.get_legend()] or [np.nan])
        # (LEFT_SLACK_IN more where the final heights' ticks are narrower than the measured)
        assert pad - tol <= left <= pad + LEFT_SLACK_IN * dpi + tol, "the widest y labels start PAD_IN from the left"
        if np.isfinite(right):
            assert right == pytest.approx(W - pad, abs=tol), "the widest legend ends PAD_IN from the right edge"


def test_every_run_figure_fits(mandible_run, slider_run):
    heights = set()
    for out in (mandible_run[0], slider_run[0]):
        for name, fig in make_figures(read_results(out)).items():
            _check_layout(fig, title_gap=True)
            heights.add(round(fig.get_size_inches()[1], 1))
    assert max(heights) > 2.5 * min(heights)  # short and tall figures alike (the title's gap above)


def test_titles_wide_legends_and_dpi():
    """Left-aligned titles get room above their axes, a long legend label widens the right
    margin, and a layout made at one dpi holds when drawn at another (extents in points): every
    decoration still inside the figure and apart."""
    fig = Figure(figsize=(8.0, 7.0), dpi=100)
    axes = list(fig.subplots(3, 1, sharex=True, squeeze=False)[:, 0])
    fig.suptitle("three panels", fontsize=11)
    x = np.linspace(0.0, 1.0, 50)
    for i, ax in enumerate(axes):
        ax.plot(x, (10.0 ** (2 * i)) * np.sin(6 * x), label="a much longer legend label than usual" if i == 1 else "y")
        ax.set_ylabel(f"panel {i}\n(units)")
        ax.set_title(f"panel {i}: a left title", loc="left", fontsize=8)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7, borderaxespad=0.0)
    axes[-1].set_xlabel("x")
    fig.text(0.01, 0.01, "caption", fontsize=7, va="bottom")
    stack_layout(fig, axes, 0.3)
    assert fig.get_layout_engine() is None
    _check_layout(fig)
    width_ax = axes[0].get_position().width * 8.0
    fig.set_dpi(200)
    _check_layout(fig, tight=False)  # inside and apart; the fonts' hinting moves extents a little
    assert axes[0].get_position().width * 8.0 == pytest.approx(width_ax)  # positions are fixed fractions
    assert width_ax < 8.0 - 2.0  # the long legend label took its room from the axes
