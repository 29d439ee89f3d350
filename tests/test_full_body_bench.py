"""The full-body benchmark's model and trial (openfdk.fixtures.full_body_osim) and the
benchmark module (openfdk.bench.full_body): the written ``.osim`` is a Gait2392-sized
OpenSim 4 model that openfdk and OpenSim 4.6 both read, openfdk's tracking of the
synthetic trial recovers the coordinates the trial was made from, and ``openfdk bench
--only full_body`` reports its figures. No timing is asserted here (targets live in the
benchmark)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from openfdk.bench.full_body import OpenfdkTracking, coordinate_table
from openfdk.fixtures.full_body_osim import (
    BODIES,
    COORDINATES,
    MARKERS,
    full_body_coordinates,
    marker_positions,
    write_full_body_osim,
    write_full_body_trial,
)
from openfdk.io.modelfile import load_model_and_settings
from openfdk.io.opensim.document import read_document

NOISE_M = 5e-4


@pytest.fixture(scope="module")
def model_path(tmp_path_factory):
    return write_full_body_osim(tmp_path_factory.mktemp("full_body") / "full_body.osim")


def test_written_model_loads_with_12_bodies_23_coordinates_40_markers(model_path):
    model, _ = load_model_and_settings(model_path)
    moving = [b.name for b in model.bodies if not b.fixed]
    assert sorted(moving) == sorted(BODIES) and len(moving) == 12
    assert sorted(c.name for c in model.coordinates) == sorted(COORDINATES)
    assert len(model.coordinates) == 23
    assert model.markers.size == 40 and sorted(model.markers.labels) == sorted(MARKERS)
    # every body carries >= 3 markers that are not collinear (each body observable alone)
    for i, b in enumerate(model.bodies):
        if b.fixed:
            continue
        p = model.markers.p_BM[model.markers.body == i]
        assert len(p) >= 3 and np.linalg.matrix_rank(p - p.mean(0), tol=1e-3) >= 2, b.name
    # the knees' translations are splines of the knee angle, a few mm
    doc = read_document(model_path)
    knee = next(j for j in doc.joints if j.name == "knee_r")
    assert [ax.function["type"] for ax in knee.translations[:2]] == ["simm_spline", "simm_spline"]
    assert 0.002 < max(abs(y) for ax in knee.translations[:2] for y in ax.function["y"]) < 0.01
    # the trial stays inside every coordinate's range
    q = full_body_coordinates(np.arange(200) / 100.0)
    for c in model.coordinates:
        assert c.range[0] < q[c.name].min() and q[c.name].max() < c.range[1], c.name


def test_opensim_reads_the_model_without_warnings_and_places_the_markers_as_openfdk(model_path):
    osim = pytest.importorskip("opensim")
    old = osim.Logger.getLevelString()
    sink = osim.StringLogSink()
    osim.Logger.setLevelString("info")
    osim.Logger.addSink(sink)
    try:
        model = osim.Model(str(model_path))
        state = model.initSystem()
    finally:
        osim.Logger.removeSink(sink)
        osim.Logger.setLevelString(old)
    lines = [x for x in sink.getString().splitlines() if x.strip()]
    usual = ("Updating Model file from 40000 to latest format", "Loaded model ")
    assert lines and all(x.startswith(usual) for x in lines), lines
    assert (model.getNumBodies(), model.getNumCoordinates(), model.getMarkerSet().getSize()) == (12, 23, 40)
    # OpenSim's marker positions at three poses of the trial = openfdk's forward kinematics
    times = np.array([0.0, 0.43, 1.37])
    q = full_body_coordinates(times)
    ours = marker_positions(read_document(model_path), q)
    coords, markers = model.getCoordinateSet(), model.getMarkerSet()
    for k in range(len(times)):
        for name in COORDINATES:
            coords.get(name).setValue(state, float(q[name][k]), False)
        model.realizePosition(state)
        theirs = np.array([[markers.get(i).getLocationInGround(state).get(j) for j in range(3)]
                           for i in range(markers.getSize())])
        np.testing.assert_allclose(theirs, ours[k], atol=1e-12)


def _tracked(model_path, tmp_path, noise, seed=0, n_frames=60):
    trc, times, q, _ = write_full_body_trial(model_path, tmp_path / "walk.trc", n_frames=n_frames, seed=seed,
                                             noise_m=noise)
    fdk = OpenfdkTracking(model_path, trc)
    _, _, res = fdk.run()  # raises unless every frame converged
    names, values = coordinate_table(fdk.model, res)
    return names, values - np.array([q[n] for n in names]).T


def test_tracking_recovers_the_true_coordinates_without_noise(model_path, tmp_path):
    """Exact markers (written to 1 nm in the .trc): every coordinate to <= 1e-6 rad or m."""
    _, err = _tracked(model_path, tmp_path, noise=0.0)
    assert np.abs(err).max() <= 1e-6


def test_tracking_error_with_noise_is_what_least_squares_predicts(model_path, tmp_path):
    """0.5 mm Gaussian noise per axis: the coordinates' errors over 60 frames have the
    spread that linearised least squares predicts, σ_q = σ sqrt(diag((JᵀJ)⁻¹)) with J the
    markers' Jacobian with respect to the coordinates (by central differences of the
    fixture's forward kinematics): RMS within 1.5 σ_q (measured 0.87–1.23 σ_q over three
    seeds) and no bias (|mean| < 0.6 σ_q; the mean of 60 frames has σ_q/7.7)."""
    names, err = _tracked(model_path, tmp_path, noise=NOISE_M)
    doc = read_document(model_path)
    times = np.arange(60) / 100.0
    q = full_body_coordinates(times)
    var = np.zeros(len(names))
    frames = range(0, 60, 10)
    h = 1e-6
    for k in frames:
        base = {n: q[n][k:k + 1] for n in names}
        J = np.empty((3 * len(MARKERS), len(names)))
        for j, n in enumerate(names):
            up, down = dict(base), dict(base)
            up[n], down[n] = base[n] + h, base[n] - h
            J[:, j] = ((marker_positions(doc, up) - marker_positions(doc, down)) / (2 * h)).ravel()
        var += NOISE_M**2 * np.diag(np.linalg.inv(J.T @ J))
    sigma = np.sqrt(var / len(frames))
    rms = np.sqrt((err**2).mean(axis=0))
    assert np.all(rms <= 1.5 * sigma), dict(zip(names, (rms / sigma).round(2)))
    assert np.all(np.abs(err.mean(axis=0)) <= 0.6 * sigma), dict(zip(names, (err.mean(0) / sigma).round(2)))


def test_bench_quick_json_prints_the_figures(capsys):
    from openfdk.cli import main

    assert main(["bench", "--only", "full_body", "--quick", "--json"]) == 0
    records = {r["name"]: r for r in (json.loads(x) for x in capsys.readouterr().out.splitlines()
                                      if x.startswith("{"))}
    expected = {"osim_import_full_body_s", "full_body_tracking_ms", "full_body_tracking_vs_opensim",
                "full_body_tracking_max_diff_deg", "full_body_tracking_vs_opensim_default_accuracy",
                "full_body_tracking_max_diff_deg_opensim_default_accuracy",
                "full_body_tracking_ms_default_blas_threads"}
    assert set(records) == expected
    assert records["osim_import_full_body_s"]["value"] > 0 and records["full_body_tracking_ms"]["value"] > 0
    try:
        import opensim  # noqa: F401
    except ImportError:
        assert all("not installed" in records[n]["note"] for n in expected if "opensim" in n or "diff" in n)
    else:
        assert records["full_body_tracking_vs_opensim"]["value"] > 0
        # same weights, same data, both converged: the same coordinates
        assert records["full_body_tracking_max_diff_deg"]["value"] < 0.01


def test_bench_without_opensim_skips_the_comparison_with_a_note(tmp_path, monkeypatch):
    from openfdk.bench import full_body

    full_body.write_inputs(tmp_path, quick=True)
    monkeypatch.setattr(full_body, "opensim_available", lambda: False)
    records = {r["name"]: r for r in full_body.measure(tmp_path, quick=True)}
    assert records["full_body_tracking_ms"]["value"] > 0
    for name in ("full_body_tracking_vs_opensim", "full_body_tracking_max_diff_deg"):
        assert np.isnan(records[name]["value"]) and "opensim" in records[name]["note"]
