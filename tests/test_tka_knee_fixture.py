"""The bench knee of ``tka_knee_gait`` (openfdk.fixtures.tka_knee) and, when the DM files
are present (``OPENFDK_DM_DIR``), DM itself in stance.

The synthetic knee: its sizes are the issue's (11 FDK DOFs, 149 strands, 45 muscles, 2
contacts), its STL meshes are closed and wound outward (read back from the files here:
every edge shared by exactly two triangles that run it in opposite directions, and a
positive enclosed volume equal to the solid's closed form), and the first frame of its
stance converges at the default FDK settings with a knee contact force between the
ground reaction and 3 body weights.
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from openfdk.fixtures import tka_knee as tk
from openfdk.fixtures import tka_knee_meshes as tkm

# ≈ 20 s with the distance grids in openfdk's disk cache, ≈ 45 s without
pytestmark = pytest.mark.slow


def _read_stl(path):
    """(triangles' corners (m, 3, 3) float64) of a binary STL."""
    data = Path(path).read_bytes()
    n = int(np.frombuffer(data[80:84], "<u4")[0])
    rec = np.frombuffer(data[84:84 + 50 * n], dtype=[("n", "<f4", (3,)), ("v", "<f4", (3, 3)), ("a", "<u2")])
    assert len(data) == 84 + 50 * n
    return rec["v"].astype(float)


def _closed_and_outward(corners):
    """(closed and consistently wound, enclosed volume m³): vertices welded by their exact
    coordinates; the volume Σ a · (b × c) / 6 is positive when the normals face out."""
    _, index = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    tri = index.reshape(-1, 3)
    directed = np.r_[tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]
    forward = {tuple(e) for e in directed}
    closed = len(forward) == len(directed) and all((b, a) in forward for a, b in forward)
    volume = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])).sum() / 6.0
    return closed, volume


@pytest.fixture(scope="module")
def knee(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tka")
    overlay = tk.write_tka_knee(folder)
    from openfdk.analysis.jobs import model_and_settings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, settings, _ = model_and_settings(str(overlay))
    return folder, model, settings


def test_sizes_are_the_issues(knee):
    _, model, _ = knee
    assert [d.name for d in model.fdk_dofs] == list(tk.FDK_DOFS) and len(model.fdk_dofs) == 11
    assert len(model.ligaments) == 149
    assert len(model.muscles) == 45
    assert len(model.contacts) == 2


def test_meshes_are_closed_outward_and_implant_sized(knee):
    folder, _, _ = knee
    f = tkm.FEMUR
    # the femoral component: ∫ π r(z)² dz of the solid of revolution, the polygon of n
    # sides inscribed in each circle having (n / 2π) sin(2π / n) of its area
    z = np.linspace(-(f["W"] + f["a"]), f["W"] + f["a"], 200001)
    r = f["R_s"] - f["rho"] + np.sqrt(f["rho"] ** 2 - (np.abs(z) - f["W"]) ** 2)
    n_theta = 240
    femur = np.trapezoid(np.pi * r**2, z) * n_theta / (2 * np.pi) * math.sin(2 * np.pi / n_theta)
    # the insert: the integral of its height over the rectangle (midpoint rule, fine grid)
    s = tkm.INSERT
    x = (np.arange(2000) + 0.5) / 2000 * 2 * s["half_ap"] - s["half_ap"]
    zz = (np.arange(2000) + 0.5) / 2000 * 2 * s["half_ml"] - s["half_ml"]
    X, Z = np.meshgrid(x, zz, indexing="ij")
    top = (s["R_i"] - np.sqrt(s["R_i"] ** 2 - X**2)) + (s["rho_i"] - np.sqrt(s["rho_i"] ** 2 - (np.abs(Z) - f["W"]) ** 2))
    insert = np.mean(top + s["thickness"]) * 4 * s["half_ap"] * s["half_ml"]
    # the button: half an ellipsoid, (2/3) π h a_y a_z
    b = tkm.BUTTON
    button = 2.0 / 3.0 * np.pi * b["h"] * b["a_y"] * b["a_z"]
    for name, expected in (("femoral_component", femur), ("tibial_insert", insert), ("patellar_button", button)):
        corners = _read_stl(folder / "Geometry" / f"{name}.stl")
        assert 10_000 <= len(corners) <= 50_000, (name, len(corners))
        closed, volume = _closed_and_outward(corners)
        assert closed, name
        # positive (outward normals) and the solid's own to 0.2 % (measured 0.04 %,
        # 0.014 % and 0.05 %: the facets' chords across the curved surfaces)
        assert volume == pytest.approx(expected, rel=2e-3), name


def test_first_stance_frame_converges_at_default_settings(knee):
    from openfdk.fdk.analysis import run_fdk

    _, model, settings = knee
    res = run_fdk(model, None, np.array([tk.FIRST_TIME]), settings)
    assert res.converged.all(), res.messages
    assert res.settings.tolerance == 1e-3  # the default
    assert np.abs(res.f_fdk).max() < res.settings.tolerance
    cols = res.forces.extra["columns"]
    contact = np.linalg.norm([cols[f"knee_contact.F{c}_N"][0] for c in "xyz"])
    # the knee carries the ground reaction (less the shank's and foot's weight, 48 N)
    # and the muscles' compression on top of it: more than the reaction, under 3 BW
    times, force, _ = tk.ground_reaction()
    grf = np.linalg.norm([np.interp(tk.FIRST_TIME, times, force[:, j]) for j in range(3)])
    assert grf > 0.3 * tk.BW
    assert grf < contact < 3.0 * tk.BW


DM_DIR = os.environ.get("OPENFDK_DM_DIR")


def _dm_as_published():
    """(model, settings, the og1 trial's times (nf,) s, trajectories) of ``dm.yaml``, the
    model as OpenSim-JAM publishes it (docs/tutorial-knee-gait.md, section 2)."""
    from openfdk.analysis.jobs import load_trajectories, model_and_settings

    folder = Path(DM_DIR)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, settings, _ = model_and_settings(str(folder / "dm.yaml"))
        trial, traj = load_trajectories(model, str(folder / "DM_ngait_og1_new.trc"), settings=settings)
    return model, settings, np.asarray(trial.time, float), traj


@pytest.mark.slow
@pytest.mark.skipif(not (DM_DIR and (Path(DM_DIR) / "dm.yaml").is_file()),
                    reason="the DM files are not part of openfdk: set OPENFDK_DM_DIR (docs/tutorial-knee-gait.md)")
def test_dm_stance_frames_converge_with_a_plausible_knee_force():
    """Three frames of DM's right stance from t = 2.55 s converge at the tolerance the
    tutorial uses (20 N, N m; 100 iterations), and the tibiofemoral contact force is
    0.5–3 body weights (BW from the model's own masses)."""
    from openfdk.fdk.analysis import run_fdk

    model, settings, times, traj = _dm_as_published()
    first = int(np.searchsorted(times, 2.55 - 1e-9))
    res = run_fdk(model, traj, times[first:first + 3], settings, tolerance=20.0, max_iterations=100)
    assert res.converged.all(), res.messages
    body_weight = sum(b.mass for b in model.bodies) * 9.80665
    cols = res.forces.extra["columns"]
    force = np.linalg.norm(np.c_[[cols[f"knee_contact.F{c}_N"] for c in "xyz"]].T, axis=1)
    assert np.all((0.5 * body_weight < force) & (force < 3.0 * body_weight)), force / body_weight


#: the tutorial's inextensible patellar tendon (docs/tutorial-knee-gait.md): the centroids
#: of the 30 PT strands' attachments in the OpenSim bodies' frames (m), and its length
PATELLAR_TENDON = """
frames:
  patella_r: {pt_proximal: [0.00935, -0.01716, -0.00512]}
  tibia_r: {pt_distal: [0.04017, -0.09219, 0.00772]}
measures:
  pt_length: {type: distance, from: patella_r.pt_proximal, to: tibia_r.pt_distal}
constraints:
  patellar_tendon: {measure: pt_length, value: 0.07819}
"""


def _dm_pt(tmp_path, trial):
    """(model, settings, trial, trajectories) of the tutorial's ``dm_pt.yaml`` (DM's
    overlay, default FDK settings, pf_ty_r held by the inextensible patellar tendon) with
    the overground trial ``trial`` ('og1', 'og3', …) and its external loads."""
    import re
    import shutil

    from openfdk.analysis.jobs import load_trajectories, model_and_settings

    folder = Path(DM_DIR)
    text = (folder / "dm.yaml").read_text()
    text = re.sub(r"^fdk:\s*\{[^}]*\}\s*$", "", text, flags=re.M)  # the default FDK settings
    text = text.replace("pf_ty_r, ", "").replace(", pf_ty_r", "").replace("_og1_", f"_{trial}_") + PATELLAR_TENDON
    for name in ("DM.osim", f"DM_ngait_{trial}_new.trc", f"DM_ngait_{trial}_external_loads.xml",
                 f"DM_ngait_{trial}_grf.sto"):
        (tmp_path / name).symlink_to(folder / name)
    (tmp_path / "Geometry").symlink_to(folder / "Geometry")
    for xml in folder.glob("*.xml"):
        if not (tmp_path / xml.name).exists():
            shutil.copy(xml, tmp_path / xml.name)
    (tmp_path / "dm_pt.yaml").write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, settings, _ = model_and_settings(str(tmp_path / "dm_pt.yaml"))
        trial, traj = load_trajectories(model, str(tmp_path / f"DM_ngait_{trial}_new.trc"), settings=settings)
    return model, settings, trial, traj


@pytest.mark.slow
@pytest.mark.skipif(not (DM_DIR and (Path(DM_DIR) / "dm.yaml").is_file()),
                    reason="the DM files are not part of openfdk: set OPENFDK_DM_DIR (docs/tutorial-knee-gait.md)")
def test_dm_a_window_starting_in_late_swing_converges_from_its_first_frame(tmp_path):
    """og3 from 3.47 s (late swing; where the second of two chunks starts): the 12-frame
    lead-in from the DOFs' initial values leaves the first frame at 236 N and 11 of 16
    frames failed; with the longer lead-ins (fdk/approach.py) the first six frames
    converge at the default settings."""
    from openfdk.fdk.analysis import run_fdk

    model, settings, trial, traj = _dm_pt(tmp_path, "og3")
    times = np.asarray(trial.time, float)
    first = int(np.searchsorted(times, 3.4697 - 1e-9))
    res = run_fdk(model, traj, times[first:first + 6], settings)
    assert res.converged.all(), res.messages
    assert np.abs(res.f_fdk).max() < 1e-3


@pytest.mark.slow
@pytest.mark.skipif(not (DM_DIR and (Path(DM_DIR) / "dm.yaml").is_file()),
                    reason="the DM files are not part of openfdk: set OPENFDK_DM_DIR (docs/tutorial-knee-gait.md)")
def test_dm_a_one_frame_window_gets_the_lead_in_at_the_trials_rate(tmp_path):
    """og1 at 2.5 s alone (``--start 2.5 --end 2.5``): before, a one-frame window had no
    frame spacing and so no lead-in; its first frame started cold from the initial values
    and failed after 100 iterations (155 N). With the lead-in at the trial's 120 Hz it
    converges, to the same root as the same frame at the start of a two-frame window."""
    from openfdk.fdk.analysis import run_fdk

    model, settings, trial, traj = _dm_pt(tmp_path, "og1")
    times = np.asarray(trial.time, float)
    first = int(np.searchsorted(times, 2.5 - 1e-9))
    one = run_fdk(model, traj, times[first:first + 1], settings)
    assert one.converged.all(), one.messages
    two = run_fdk(model, traj, times[first:first + 2], settings)
    assert two.converged.all(), two.messages
    # the same root to what the tolerance leaves free: max |f| < 1e-3 N (N m) in both,
    # and along the knee's soft coupled modes (a few N m/rad, a few hundred N/m: the
    # tibia's axial rotation with the patella) that allows up to 1e-3 rad and 1e-5 m
    # (measured: 7e-5 rad, 4e-6 m)
    rotational = np.array(["tx" not in n and "ty" not in n and "tz" not in n for n in one.dof_names])
    gap = np.abs(one.alpha[0] - two.alpha[0])
    assert gap[rotational].max() < 1e-3 and gap[~rotational].max() < 1e-5, dict(zip(one.dof_names, gap))


@pytest.mark.slow
@pytest.mark.skipif(not (DM_DIR and (Path(DM_DIR) / "dm.yaml").is_file()),
                    reason="the DM files are not part of openfdk: set OPENFDK_DM_DIR (docs/tutorial-knee-gait.md)")
def test_dm_with_a_patellar_tendon_converges_at_the_default_settings(tmp_path):
    """DM's overlay with pf_ty_r no longer an FDK DOF but held by an inextensible patellar
    tendon: the vasti are recruitable (check names no muscle FDK cannot recruit), and six
    frames of stance from t = 2.5 s converge at the DEFAULT settings (1e-3 N, N m), the
    first one cold, with the vasti carrying > 100 N and the tibiofemoral contact 1–3 BW."""
    from openfdk.dynamics.inverse import InverseDynamics
    from openfdk.fdk.absorbed import fdk_absorbed_muscles
    from openfdk.fdk.analysis import run_fdk
    from openfdk.kinematics.system import ConstraintSystem

    model, settings, trial, traj = _dm_pt(tmp_path, "og1")
    assert len(model.fdk_dofs) == 10 and "pf_ty_r" not in [d.name for d in model.fdk_dofs]
    assert fdk_absorbed_muscles(InverseDynamics(model, ConstraintSystem(model), settings),
                                model.initial_state()) == []
    times = np.asarray(trial.time, float)
    first = int(np.searchsorted(times, 2.5 - 1e-9))
    res = run_fdk(model, traj, times[first:first + 6], settings)
    assert res.settings.tolerance == 1e-3 and res.converged.all(), res.messages
    assert np.abs(res.f_fdk).max() < 1e-3
    body_weight = sum(b.mass for b in model.bodies) * 9.80665
    cols = res.forces.extra["columns"]
    force = np.linalg.norm(np.c_[[cols[f"knee_contact.F{c}_N"] for c in "xyz"]].T, axis=1)
    assert np.all((1.0 * body_weight < force) & (force < 3.0 * body_weight)), force / body_weight
    names = list(res.forces.column_names)
    vasti = sum(res.forces.forces[:, names.index(m)] for m in ("vasmed_r", "vaslat_r", "vasint_r"))
    assert np.all(vasti > 100.0), vasti


@pytest.mark.slow
@pytest.mark.skipif(not (DM_DIR and (Path(DM_DIR) / "dm.yaml").is_file()),
                    reason="the DM files are not part of openfdk: set OPENFDK_DM_DIR (docs/tutorial-knee-gait.md)")
def test_dm_as_published_converges_from_heel_strike_through_loading_response():
    """DM as published (dm.yaml: the elastic patellar tendon, 11 FDK DOFs) on og1 from
    heel strike (2.406 s) to 2.80 s, at the default settings: every frame converges,
    2.692 s among them, where the patella's branch ends and the frame converges on
    another after its restarts (docs/knee-gait-records.md)."""
    from openfdk.fdk.analysis import run_fdk

    model, settings, times, traj = _dm_as_published()
    times = times[(times >= 2.406 - 1e-9) & (times <= 2.80 + 1e-9)]
    res = run_fdk(model, traj, times, settings)
    assert len(times) == 48 and res.converged.all(), res.messages


@pytest.mark.skipif(not (DM_DIR and (Path(DM_DIR) / "DM_ngait_tmf_slow1_new.trc").is_file()),
                    reason="the DM files are not part of openfdk: set OPENFDK_DM_DIR (docs/tutorial-knee-gait.md)")
def test_dm_treadmill_trc_reads_with_its_windows_nan_and_rounded_times():
    """DM's treadmill TRC (`DM_ngait_tmf_slow1_new.trc`) as written: its sync-bar markers
    are '-nan(ind)' (missing, as OpenSim reads them) and its times are 120 Hz frame times
    rounded to 1 ms plus a 0.439997 s sync offset (read onto the 1/120 s grid)."""
    from openfdk.io.trc import read_trc

    path = Path(DM_DIR) / "DM_ngait_tmf_slow1_new.trc"
    text = path.read_text()
    assert text.count("-nan(ind)") > 1000
    trial = read_trc(path)
    assert trial.rate == 120.0 and trial.positions.shape == (1962, 72, 3)
    np.testing.assert_allclose(trial.time, 0.439997 + np.arange(1962) / 120.0, rtol=0, atol=1e-12)
    printed = np.array([float(line.split("\t")[1]) for line in text.splitlines()[6:] if line.strip()])
    assert np.max(np.abs(printed - trial.time)) <= 1e-3 and np.ptp(np.diff(printed)) > 5e-4
    seen = ~np.isnan(trial.positions).any(axis=2)
    rows = [line.split("\t") for line in text.splitlines()[6:] if line.strip()]
    for k in range(1, 5):  # a bar is missing exactly where a cell of it is not a decimal number
        m = trial.labels.index(f"synch_bar{k}")
        cells = [r[2 + 3 * m: 5 + 3 * m] + [""] * max(0, 5 + 3 * m - len(r)) for r in rows]
        odd = np.array([any(c in ("", "nan", "-nan(ind)") for c in row) for row in cells])
        assert odd.sum() > 500 and np.array_equal(~seen[:, m], odd)
    knee = [trial.labels.index(lab) for lab in ("R_Thigh_Superior", "R_Shank_Inferior", "R_Heel")]
    assert seen[:, knee].mean() > 0.99


def test_the_bench_records_say_where_the_evaluations_go():
    """The three records share the window's counts; the first frame's evaluations (its
    lead-in included) and the later frames' mean are split out: 175 and (4 + 5 + 3) / 3."""
    from types import SimpleNamespace

    from openfdk.bench.tka_knee_gait import TARGETS, records

    result = SimpleNamespace(converged=np.array([True, True, True, False]), iterations=np.array([150, 3, 4, 2]),
                             jacobians=np.array([100, 1, 2, 1]), restarts=np.array([0, 1, 0, 1]),
                             backward=np.array([0, 1, 0, 0]), evaluations=np.array([175, 4, 5, 3]), reasons=("converged",) * 3 + ("line_search",))
    out = {r["name"]: r for r in records("stub", result, 2.0)}
    assert set(out) == set(TARGETS)
    fps = out["tka_knee_gait_fdk_fps"]
    assert fps["value"] == 2.0 and fps["converged_frames"] == 3 and fps["failed"] == ["line_search"]
    assert fps["first_frame_evaluations"] == 175 and fps["later_evaluations_per_frame"] == 4.0
    assert fps["restarted_frames"] == 2 and fps["backward_frames"] == 1
    assert out["tka_knee_gait_fdk_evaluations_per_frame"]["value"] == (175 + 4 + 5 + 3) / 4


def test_the_bench_times_repeated_runs_each_on_its_own():
    """timed_runs calls the run ``repeats`` times and times each call alone, between the
    clock's readings before and after it: with readings 0, 3, 10, 11, 20, 22 the walls are
    3, 1 and 2 s (median 2, not the 22 s from first to last reading), and every run's
    result is kept in order; at least one run even when asked for none."""
    from openfdk.bench.timing import timed_runs

    readings = [0.0, 3.0, 10.0, 11.0, 20.0, 22.0]
    ticks = iter(readings)
    calls = []
    results, walls = timed_runs(lambda: calls.append(len(calls)) or len(calls), 3, clock=lambda: next(ticks))
    assert walls == [b - a for a, b in zip(readings[0::2], readings[1::2])]
    assert np.median(walls) < readings[-1] - readings[0]
    assert results == [1, 2, 3]
    assert calls == [0, 1, 2]
    ticks = iter([5.0, 5.5])
    results, walls = timed_runs(lambda: "once", 0, clock=lambda: next(ticks))
    assert results == ["once"]
    assert walls == [0.5]


@pytest.mark.skipif(not (DM_DIR and (Path(DM_DIR) / "DM_ngait_og1_grf.sto").is_file()),
                    reason="the DM files are not part of openfdk: set OPENFDK_DM_DIR (docs/tutorial-knee-gait.md)")
def test_dm_overground_ground_reactions_are_raw_and_the_filter_makes_them_smooth():
    """DM's overground GRF file holds raw 1200 Hz plate samples (noise ratio > 1: second
    differences larger than first, white noise gives √3); filtered at 6 Hz as a wrench its
    loaded runs are smooth (ratio ≈ 2 sin(π f / 1200) for their few-hertz content)."""
    from openfdk.forces.load_filter import NOISY_RATIO, filter_load, noise_ratio
    from openfdk.io.storage import read_storage

    t, cols, _ = read_storage(Path(DM_DIR) / "DM_ngait_og1_grf.sto")
    F = np.column_stack([cols[f"ground_force_1_v{a}"] for a in "xyz"])
    P = np.column_stack([cols[f"ground_force_1_p{a}"] for a in "xyz"])
    T = np.column_stack([cols[f"ground_torque_1_{a}"] for a in "xyz"])
    assert noise_ratio(F) > 1.0 > NOISY_RATIO
    _, F_f, P_f, T_f = filter_load(t, F, P, T, True, 6.0)
    assert noise_ratio(F_f) < 0.05
    # the wrench about the origin is the filtered one; the centre of pressure is on the plate
    loaded = np.linalg.norm(F_f, axis=1) > 100.0
    np.testing.assert_allclose(P_f[loaded, 1], np.median(P[np.linalg.norm(F, axis=1) >= 20.0, 1]), atol=1e-12)
    np.testing.assert_allclose(T_f[loaded][:, [0, 2]], 0.0, atol=1e-6)


def test_a_named_dm_folder_without_the_overlay_is_an_error(tmp_path, monkeypatch):
    """OPENFDK_DM_OVERLAY=dm_pt_og1.yaml, a name the tutorial used but never defined, ran
    the synthetic knee in silence (found walking the tutorial at stop 72). A DM folder
    named without the overlay or the trial is now one line naming the missing file."""
    from openfdk.bench import tka_knee_gait as tk

    monkeypatch.delenv("OPENFDK_DM_DIR", raising=False)
    assert tk.dm_overlay() is None
    monkeypatch.setenv("OPENFDK_DM_DIR", str(tmp_path))
    monkeypatch.setenv("OPENFDK_DM_OVERLAY", "dm_pt_og1.yaml")
    with pytest.raises(FileNotFoundError, match=r"no dm_pt_og1\.yaml \(OPENFDK_DM_OVERLAY\) there"):
        tk.dm_overlay()
    (tmp_path / "dm_pt_og1.yaml").write_text("opensim: DM.osim\n")
    with pytest.raises(FileNotFoundError, match=rf"no {tk.DM_TRIAL} \(the trial\) there"):
        tk.dm_overlay()
    (tmp_path / tk.DM_TRIAL).write_text("")
    assert tk.dm_overlay() == tmp_path / "dm_pt_og1.yaml"
