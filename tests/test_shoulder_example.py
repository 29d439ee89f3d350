"""The shoulder example (examples/shoulder/, docs/tutorial-shoulder.md), a model written
from the docs by a new user: it runs through a marker gap, recovers the synthetic motion,
and its FDK solution balances the arm. The balance is written here from the outputs alone:
gravity, inertia, the tensions of the muscles that start on the thorax and of the
capsule ligaments along their first segments, and the glenoid contact force must sum to
zero on the humerus + forearm (the elbow is internal)."""

import importlib.util
import shutil
from pathlib import Path

import numpy as np
import pytest

import openfdk
from openfdk.model.state import BodyStates

SHOULDER = Path(__file__).resolve().parents[1] / "examples" / "shoulder"


def _make(tmp_path):
    spec = importlib.util.spec_from_file_location("make_shoulder", SHOULDER / "make_shoulder.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path)
    shutil.copy(SHOULDER / "shoulder.yaml", tmp_path / "shoulder.yaml")
    return mod


def _world_path(model, path, state):
    """World points (k, 3) m of a muscle/ligament path: its straight segments' ends, or
    for a wrapped path the polyline drawn by the viewer (tangent points included)."""
    if hasattr(path, "nodes"):
        from openfdk.viewer.wrapview import polyline

        return np.asarray(polyline(path, state))
    from openfdk.viewer.scene import _path_points

    return np.array([state.p_WB[b] + state.R_WB[b] @ p for b, p in _path_points(model, path)])


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("shoulder")
    return tmp, _make(tmp)


@pytest.fixture(scope="module")
def reach(folder):
    tmp, mod = folder
    model = openfdk.load_model(tmp / "shoulder.yaml")
    result = openfdk.run(model, tmp / "reach.trc", start=0.78, end=0.88)   # across the gap of H3
    return mod, model, result


def test_kinematics_track_through_the_marker_gap_and_recover_the_motion(folder):
    from openfdk.cli import main

    tmp, _ = folder
    code = main(["kinematics", str(tmp / "shoulder.yaml"), str(tmp / "reach.trc"), "--start", "0.78", "--end", "0.88",
                 "--out", str(tmp / "kin"), "-q"])
    assert code == 0
    result = openfdk.read_results(tmp / "kin")
    k, m = result.kinematics, result.measures
    assert len(k) == 11 and bool(k["converged"].all())
    gap = (k.index >= 0.80 - 1e-9) & (k.index < 0.86 - 1e-9)     # H3 is missing 0.80-0.86 s
    assert gap.sum() == 6 and k.loc[gap, "H3.residual_x_m"].isna().all()
    assert k.loc[~gap, "H3.residual_x_m"].notna().all()
    # the synthetic motion (make_shoulder.trial): elbow flexion 10 + 80 s(t) deg and shoulder
    # flexion 60 s(t) deg, s = (1 - cos(pi t / 2)) / 2; 1 mm marker noise
    t = m.index.to_numpy()
    s = 0.5 * (1 - np.cos(np.pi * t / 2.0))
    assert np.max(np.abs(m["elbow.angle_rad"].to_numpy() - np.deg2rad(10 + 80 * s))) < np.deg2rad(0.3)
    # no translation in the synthetic head: the FDK DOFs stay at their initial value 0
    assert np.max(np.abs(m[[f"gh.position[{i}]_m" for i in range(3)]].to_numpy())) < 1e-12


def test_fdk_solution_balances_the_arm(reach):
    _, model, result = reach
    k, f = result.kinematics, result.forces
    names = [b.name for b in model.bodies]
    column = np.array([b.column for b in model.bodies])
    arm = ("humerus", "forearm")
    thorax_points = [model.frame(q) for q in model.frames if q.startswith("thorax.")]
    weight = sum(model.body(b).mass for b in arm) * 9.81
    assert len(k) == 11 and bool(f["converged"].all()) and len(result.failed_frames) == 0
    assert k.loc[0.80:0.85, "H3.residual_x_m"].isna().all()          # FDK tracked without H3
    for i in range(len(k)):
        pose = np.zeros((len(names), 7))
        pose[:, 3] = 1.0
        for j, b in enumerate(model.bodies):
            pose[j, :3] = b.p_WB0
            if b.name in arm:
                pose[j] = [k[f"{b.name}.{c}"].iloc[i] for c in ("x_m", "y_m", "z_m", "e0", "e1", "e2", "e3")]
        state = BodyStates(pose[:, :3], pose[:, 3:], column)
        thorax = state.p_WB[names.index("thorax")]
        F = np.zeros(3)
        for b in arm:
            a = np.array([k[f"{b}.a{c}_m_s2"].iloc[i] for c in "xyz"])
            F += model.body(b).mass * (model.gravity_W - a)
        pulled = 0
        for el, tension in [(m, f[f"{m.name}.force_N"].iloc[i] + f[f"{m.name}.passive_N"].iloc[i])
                            for m in model.muscles] + [(g, f[f"{g.name}.force_N"].iloc[i]) for g in model.ligaments]:
            P = _world_path(model, el.path, state)
            if not any(np.allclose(P[0], thorax + fr.p_BF) for fr in thorax_points):
                continue                       # starts and ends on the arm: internal
            nxt = next(p for p in P[1:] if np.linalg.norm(p - P[0]) > 1e-9)
            F += tension * (P[0] - nxt) / np.linalg.norm(P[0] - nxt)
            pulled += tension > 1.0
        contact = np.array([f[f"glenohumeral.F{c}_N"].iloc[i] for c in "xyz"])
        F += contact
        assert pulled >= 4 and np.linalg.norm(contact) > 3 * weight   # a compressed, muscle-held joint
        assert np.linalg.norm(F) < 0.01, (i, F)                        # FDK tolerance 1e-3 N per DOF


def test_the_tutorial_quotes_the_example_file():
    """Every line of the YAML blocks in docs/tutorial-shoulder.md is in shoulder.yaml."""
    import re

    doc = (Path(__file__).resolve().parents[1] / "docs" / "tutorial-shoulder.md").read_text()
    blocks = re.findall(r"```yaml\n(.*?)```", doc, flags=re.S)
    model = (SHOULDER / "shoulder.yaml").read_text().splitlines()
    lines = [ln for b in blocks for ln in b.splitlines() if ln.strip()]
    assert len(lines) >= 10
    for ln in lines:
        assert ln in model, ln
