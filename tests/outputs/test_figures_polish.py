"""Figures without rough edges (issue 29), read back from matplotlib's objects: y labels
without repeated words, captions inside the figure, integer iteration ticks, no all-zero
panel, displacements in a lab frame, component names instead of [0] [1] [2], constant
components listed instead of drawn as round-off, distinct line styles for many lines."""

import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.ticker import MaxNLocator

from openfdk.plots.run import component_labels, line_styles, make_figures
from openfdk.results.run import read_results


def _drawn(fig):
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def _caption_inside_and_below_axes(fig):
    renderer = _drawn(fig)
    caption = fig.texts[-1].get_window_extent(renderer)
    assert caption.y0 >= 0 and caption.x0 >= 0, "caption cut off at the figure's edge"
    assert caption.x1 <= fig.bbox.width + 1, "caption runs off the right edge"
    lowest = min(ax.get_tightbbox(renderer).y0 for ax in fig.axes)
    assert caption.y1 <= lowest + 1, "caption overlaps the axes (tick labels or x label)"


def test_captions_fit_in_every_figure(mandible_run, slider_run):
    for out in (mandible_run[0], slider_run[0]):
        for name, fig in make_figures(read_results(out)).items():
            _caption_inside_and_below_axes(fig)


def test_reaction_labels_without_a_model_do_not_repeat(slider_run):
    res = read_results(slider_run[0])
    res.summary = {k: v for k, v in res.summary.items() if k != "input"}  # no model file to find
    assert res.model() is None
    labels = [ax.get_ylabel().replace("\n", " ") for ax in make_figures(res, measures=[])["reactions"].axes]
    assert labels == ["reaction (N or N·m, constraint frame)"]
    res = read_results(slider_run[0])
    labels = [ax.get_ylabel().split("\n")[0] for ax in make_figures(res, measures=[])["reactions"].axes]
    assert labels == ["reaction force", "reaction moment"]


def test_convergence_integer_ticks_no_zero_panel_legend_clear(mandible_run, slider_run):
    for out in (mandible_run[0], slider_run[0]):
        fig = make_figures(read_results(out), measures=[])["convergence"]
        renderer = _drawn(fig)
        for ax in fig.axes:
            ys = np.concatenate([np.asarray(line.get_ydata(), float) for line in ax.get_lines()] or [[]])
            assert np.any(np.nan_to_num(ys) != 0), f"all-zero panel {ax.get_ylabel()!r}"
            if "iterations" in ax.get_ylabel():
                locator = ax.yaxis.get_major_locator()
                assert isinstance(locator, MaxNLocator) and locator._integer
                ticks = [t for t in ax.get_yticks() if ax.get_ylim()[0] <= t <= ax.get_ylim()[1]]
                assert all(float(t).is_integer() for t in ticks), ticks
            legend = ax.get_legend()
            if legend is not None:  # the legend covers no tick label of any axes of the figure
                box = legend.get_window_extent(renderer)
                for other in fig.axes:
                    for label in other.get_yticklabels() + other.get_xticklabels():
                        if label.get_visible() and label.get_text():
                            assert not box.overlaps(label.get_window_extent(renderer)), label.get_text()
    # the slider-crank is determinate: zero kinematics iterations and no recruitment are not drawn,
    # and the caption says so
    fig = make_figures(read_results(slider_run[0]), measures=[])["convergence"]
    labels = [ax.get_ylabel().split("\n")[0] for ax in fig.axes]
    caption = fig.texts[-1].get_text().replace("\n", " ")
    assert labels == ["kinematics", "constraint"]
    assert caption.endswith("Zero on every frame, not drawn: recruitment.")


def test_lab_frame_positions_are_displacements(mandible_run):
    res = read_results(mandible_run[0])
    fig = make_figures(res, measures=[])["kinematics"]
    k = res.kinematics
    for b, body in enumerate(res.bodies()):
        ax = fig.axes[2 * b]
        assert "displacement" in ax.get_ylabel() and "first frame" in ax.get_ylabel()
        for line in ax.get_lines():
            c = line.get_label()[0]
            r = 1e3 * k[f"{body}.{c}_m"].to_numpy()
            assert f"from {r[0]:.1f} mm" in line.get_label()
            np.testing.assert_allclose(line.get_ydata(), r - r[0], atol=1e-9)
        low, high = ax.get_ylim()
        assert high - low < 100  # millimetre motion of a body ~1 m from the lab origin stays visible


def test_centre_of_pressure_and_force_are_in_the_frame_of_the_body_pressed_on(mandible_run):
    """With the model, the centre of pressure and the force are drawn in the frame B of
    the body carrying the contact's vertices (the jaw's condyles), p_B = R_WBᵀ (p_W −
    r_WB) and F_B = R_WBᵀ F_W: checked with scipy's own quaternion rotation on
    kinematics.csv's poses. Without the model the world displacement from the first frame
    in contact is drawn, as before."""
    from scipy.spatial.transform import Rotation

    from openfdk.results.run import RunResults

    res = read_results(mandible_run[0])
    model = res.model()
    ax_cop = make_figures(res, measures=[])["contact"].axes[1]
    assert ax_cop.get_ylabel().replace("\n", " ") == "centre of pressure (mm, body frame B)"
    f, k = res.forces, res.kinematics
    lines = [line for line in ax_cop.get_lines() if len(line.get_xdata())]
    assert len(lines) == 3 * len(res.contacts())
    bodies = {c.name: model.bodies[c.body_a].name for c in model.contacts}
    for line in lines:
        name, c = line.get_label().split()[:2]
        body = bodies[name]
        assert line.get_label() == f"{name} {c} ({body})"
        p_W = np.column_stack([f[f"{name}.cop_{a}_m"].to_numpy() for a in "xyz"])
        r_WB = np.column_stack([k[f"{body}.{a}_m"].to_numpy() for a in "xyz"])
        q = np.column_stack([k[f"{body}.e{j}"].to_numpy() for j in (1, 2, 3, 0)])  # scipy: scalar last
        ok = np.all(np.isfinite(p_W), axis=1)
        p_B = np.full_like(p_W, np.nan)
        p_B[ok] = Rotation.from_quat(q[ok]).inv().apply(p_W[ok] - r_WB[ok])
        np.testing.assert_allclose(line.get_ydata(), 1e3 * p_B[:, "xyz".index(c)], atol=1e-9)
    # the force's components along the same body's axes, F_B = R_WBᵀ F_W; |F| unchanged
    ax_F = make_figures(res, measures=[])["contact"].axes[0]
    assert ax_F.get_ylabel().replace("\n", " ") == "contact force (N, body frame B)"
    forces = {line.get_label(): line.get_ydata() for line in ax_F.get_lines()}
    for name in res.contacts():
        body = bodies[name]
        F_W = np.column_stack([f[f"{name}.F{a}_N"].to_numpy() for a in "xyz"])
        q = np.column_stack([k[f"{body}.e{j}"].to_numpy() for j in (1, 2, 3, 0)])
        F_B = Rotation.from_quat(q).inv().apply(F_W)
        for j, a in enumerate("xyz"):
            np.testing.assert_allclose(forces[f"{name} F{a} ({body})"], F_B[:, j], atol=1e-9 * np.max(np.abs(F_W)))
        np.testing.assert_allclose(forces[f"{name} |F|"], np.linalg.norm(F_W, axis=1), rtol=1e-12)
    # without the model: the world displacement from the first frame in contact
    bare = RunResults(res.kinematics, res.forces, {})
    assert bare.model() is None
    ax_world = make_figures(bare, measures=[])["contact"].axes[1]
    assert "from first contact (mm, world W)" in ax_world.get_ylabel().replace("\n", " ")
    for line in [line for line in ax_world.get_lines() if len(line.get_xdata())]:
        name, c = line.get_label().split()[:2]
        cop = 1e3 * f[f"{name}.cop_{c}_m"].to_numpy()
        first = cop[np.isfinite(cop)][0]
        assert f"(from {first:.1f} mm)" in line.get_label()
        np.testing.assert_allclose(line.get_ydata(), cop - first, atol=1e-9)


def test_components_named_and_constant_components_listed(slider_run):
    res = read_results(slider_run[0])
    fig = make_figures(res, measures=["crank_angles", "small_end_offset"])["measures"]
    ax = fig.axes[0]
    drawn = [line.get_label() for line in ax.get_lines() if len(line.get_xdata())]
    listed = [t.get_text() for t in ax.get_legend().get_texts()]
    assert drawn == ["about z''"]
    assert any(t.startswith("about x: constant ") for t in listed)
    assert any(t.startswith("about y': constant ") for t in listed)
    for a in fig.axes:
        for t in a.get_legend().get_texts() if a.get_legend() else []:
            assert not t.get_text().startswith("["), t.get_text()
    # small_end_offset is held at zero by the slider's constraint: ~1e-17 m of round-off in
    # measures.csv, listed as constant zeros, nothing drawn
    fig = make_figures(res, measures=["small_end_offset"])["measures"]
    assert not [line for line in fig.axes[0].get_lines() if len(line.get_xdata())]
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == [
        "x: constant 0 mm", "y: constant 0 mm", "z: constant 0 mm"]
    assert component_labels(None, [("[0]", "length", None)] * 3) == ["x", "y", "z"]
    assert component_labels(None, [("[0]", "1", None)] * 2) == ["[0]", "[0]"]


def test_many_lines_get_distinct_styles(mandible_run):
    res = read_results(mandible_run[0])
    ax_f, ax_a = make_figures(res, measures=[])["muscles"].axes
    styles = [(tuple(line.get_color()), line.get_linestyle()) for line in ax_f.get_lines()]
    assert len(styles) == 24 and len(set(styles)) == 24
    assert [(tuple(line.get_color()), line.get_linestyle()) for line in ax_a.get_lines()] == styles
    for n in (5, 12, 24, 80, 200):
        pairs = [(tuple(c), ls) for c, ls in line_styles(n)]
        assert len(set(pairs)) == n
