"""Figures of a run: `openfdk run` writes them (slider–crank, mandible FDK model); every
axis is labelled with a unit (checked on matplotlib's objects), lines carry the result
files' numbers, failed frames are marked."""

import re

import numpy as np
import pytest
import yaml

from openfdk.cli import main
from openfdk.io.c3d import write_c3d
from openfdk.plots.run import make_figures
from openfdk.results.run import read_results
from openfdk.fixtures.synthetic import synthetic_markers, two_body_model_dict

UNIT = re.compile(r"\((mm|deg|N|N·m|N or N·m|–|m or rad|mm²|SI: m or rad)[,)]")


def check_axes(figures):
    """Every axis: y label with a unit in parentheses, x label 'time (s)'; every
    figure: a caption stating conventions. Returns the number of axes checked."""
    n = 0
    for name, fig in figures.items():
        assert fig.texts and len(fig.texts[-1].get_text()) > 60, name  # the caption
        for ax in fig.axes:
            assert ax.get_xlabel() == "time (s)", (name, ax.get_xlabel())
            label = ax.get_ylabel().replace("\n", " ")
            assert UNIT.search(label), (name, label)
            n += 1
    return n


def _lines(ax):
    return {line.get_label(): line.get_ydata() for line in ax.get_lines()}


def test_run_writes_figures_for_the_slider_crank(slider_run):
    out, _ = slider_run
    assert sorted(p.name for p in (out / "plots").glob("*.png")) == [
        "convergence.png", "kinematics.png", "measures.png", "reactions.png"]
    assert all(p.stat().st_size > 20_000 for p in (out / "plots").glob("*.png"))
    res = read_results(out)
    figs = make_figures(res)
    # measures: crank_angles, small_end_offset, 4 joint measures; convergence: kinematics iterations and
    # constraint violation (no muscles: zero recruitment iterations on every frame, not drawn)
    assert check_axes(figs) == 2 * 3 + 6 + 2 + 2
    f = res.forces
    # the drive torque is a moment (N·m, an angle driver); joint x/y rows are forces
    ax_force, ax_moment = figs["reactions"].axes
    assert "N," in ax_force.get_ylabel() and "N·m" in ax_moment.get_ylabel()
    np.testing.assert_array_equal(_lines(ax_moment)["crank_drive"], f["crank_drive.reaction"].to_numpy())
    # positions are drawn in mm of the world frame, as displacements from the first frame
    # (the legend gives where each component starts): the crank centre circles at r = 50 mm
    ax_pos = figs["kinematics"].axes[0]
    assert "world W" in ax_pos.get_ylabel() and "displacement" in ax_pos.get_ylabel()
    lines = {label.split()[0]: (y, float(re.search(r"from (-?[\d.]+) mm", label).group(1)))
             for label, y in _lines(ax_pos).items() if len(y)}
    assert sorted(lines) == ["x", "y"]  # z is constant: listed in the legend, not drawn
    (x, x0), (y, y0) = lines["x"], lines["y"]
    assert x[0] == y[0] == 0.0
    np.testing.assert_allclose(np.hypot(x + x0, y + y0), 50.0, atol=0.06)  # x0, y0 printed to 0.1 mm
    # measures: crank_angles component 2 is the driven angle 360°/s·t (wrapped to ±180°)
    ax = figs["measures"].axes[0]
    assert ax.get_ylabel().startswith("crank_angles") and "deg" in ax.get_ylabel()
    assert [a.get_ylabel().split("\n")[0] for a in figs["measures"].axes][:2] == ["crank_angles", "small_end_offset"]
    assert {label for label, y in _lines(ax).items() if len(y)} == {"about z''"}  # about x and y' are constant (planar): not drawn
    angle = _lines(ax)["about z''"]
    expected = (360.0 * res.time + 180.0) % 360.0 - 180.0
    ok = np.abs(np.abs(expected) - 180.0) > 1e-6
    np.testing.assert_allclose(angle[ok], expected[ok], atol=1e-6)


def test_run_writes_figures_for_the_mandible_fdk_model(mandible_run):
    out, _ = mandible_run
    names = sorted(p.stem for p in (out / "plots").glob("*.png"))
    assert names == ["contact", "convergence", "fdk_dofs", "kinematics", "ligaments", "measures", "muscles"]
    res = read_results(out)
    figs = make_figures(res)
    assert check_axes(figs) > 15
    f = res.forces
    # FDK DOFs of the mandible model are plane distances / a medio-lateral offset: mm
    ax_alpha, ax_res = figs["fdk_dofs"].axes
    assert "(mm" in ax_alpha.get_ylabel() and "(N," in ax_res.get_ylabel()
    for dof in res.fdk_dofs():
        np.testing.assert_allclose(_lines(ax_alpha)[dof], 1e3 * f[f"fdk.{dof}.alpha"].to_numpy())
    # contact force and centre of pressure (mm) along the jaw's axes (test_figures_polish.py)
    ax_F, ax_cop, _ = figs["contact"].axes
    assert "(N, body frame B)" in ax_F.get_ylabel().replace("\n", " ")
    assert "(mm, body frame B)" in ax_cop.get_ylabel().replace("\n", " ")
    lines = _lines(ax_F)
    for c in res.contacts():
        F = np.column_stack([f[f"{c}.F{k}_N"] for k in "xyz"])
        np.testing.assert_allclose(lines[f"{c} |F|"], np.linalg.norm(F, axis=1))
        assert np.nanmax(lines[f"{c} |F|"]) > 1.0  # the condyles are loaded
    # muscles: 24, activations = force / strength
    ax_f, ax_a = figs["muscles"].axes
    assert len(ax_f.get_lines()) == len(res.muscles()) == 24
    m = res.muscles()[0]
    np.testing.assert_allclose(_lines(ax_a)[f"_{m}"], f[f"{m}.force_N"] / f[f"{m}.strength_N"])


def test_failed_frames_are_marked_and_no_plots_flag(tmp_path, capsys):
    """Two-body model (no muscles) with the jaw markers occluded for 5 frames:
    `--no-plots` writes no figures; `openfdk plot` then marks exactly the failed frames."""
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(two_body_model_dict()))
    t, labels, x, _ = synthetic_markers(25, rate=100.0, noise=0.0)
    x = x.copy()
    x[12:17, 4:8] = np.nan
    write_c3d(tmp_path / "trial.c3d", labels, x, 100.0)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "m.yaml"), str(tmp_path / "trial.c3d"), "--out", str(out), "--no-progress",
                 "--no-plots", "--cutoff", "0"]) == 3   # frames failed: exit 3 (issue 16), results written
    assert not (out / "plots").exists()
    assert main(["plot", str(out), "--out", str(tmp_path / "figs")]) == 0
    assert "figures" in capsys.readouterr().out
    assert (tmp_path / "figs" / "convergence.png").is_file()
    res = read_results(out)
    failed = res.failed_frames
    # the occlusion fails the kinematics of frames 12–16; this model has no muscles, so
    # the inverse dynamics of every other frame fails too (not enough strength)
    assert list(failed.loc[failed["stage"] == "kinematics", "frame"]) == [12, 13, 14, 15, 16]
    assert list(failed["frame"]) == list(range(25))
    assert all("not enough strength" in r for r in failed.loc[failed["stage"] == "inverse_dynamics", "reason"])
    ax = make_figures(res)["convergence"].axes[0]
    marked = [line for line in ax.get_lines() if line.get_label() == "failed frame"]
    assert len(marked) == 1
    np.testing.assert_allclose(marked[0].get_xdata(), failed["time"])
    shaded = [p for p in ax.patches]
    assert len(shaded) == len(failed)


def test_plot_unknown_measure_is_one_line(slider_run, tmp_path, capsys):
    out, _ = slider_run
    assert main(["plot", str(out), "--out", str(tmp_path), "--measures", "nope"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nope" in err and "crank_angles" in err
