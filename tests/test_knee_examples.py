"""The knee examples (examples/knee/) run, and the springs version matches an
independent planar static computation: the wrap geometry (tangents to the condyle
circle) and the shank's equilibrium written here, solved by fixed-point iteration on
the knee translation α."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from openfdk.fdk.analysis import run_fdk
from openfdk.io.modelfile import model_and_settings_from_dict

KNEE = Path(__file__).resolve().parents[1] / "examples" / "knee"
G = 9.81


def _load(name, flexion_deg=None):
    data = yaml.safe_load((KNEE / name).read_text())
    if flexion_deg is not None:
        data["drivers"]["flexion"]["function"] = {"type": "constant", "value": float(flexion_deg)}
    model, settings = model_and_settings_from_dict(data, source=name, base_dir=str(KNEE))
    return model, settings, data


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


def _rot(phi):
    return np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])


def _anterior_tangent(P, C, r):
    """Tangent point on the circle (centre C, radius r) seen from P on the anterior (+x)
    side: the two tangent points are at angles β ± acos(r/|P−C|) about C, β the angle of
    P; the one with the larger x is the anterior one."""
    d = P - C
    beta = np.arctan2(d[1], d[0])
    a = np.arccos(r / np.linalg.norm(d))
    cands = [C + r * np.array([np.cos(beta + s * a), np.sin(beta + s * a)]) for s in (1, -1)]
    return max(cands, key=lambda T: T[0])


def planar_knee_statics(data, flexion_rad):
    """α (2,) m of the knee (shank knee origin in the thigh knee frame) and the quadriceps
    force (N), everything in the thigh's frame (x anterior, y proximal; gravity along −x
    because the thigh is horizontal), quasi-static."""
    mm = 1e-3
    b = data["bodies"]
    K = np.array(b["thigh"]["frames"]["knee"][:2]) * mm
    O = np.array(b["thigh"]["frames"]["quad_origin"][:2]) * mm
    knee_in_shank = np.array(b["shank"]["frames"]["knee"][:2]) * mm
    tub = np.array(b["shank"]["frames"]["tuberosity"][:2]) * mm - knee_in_shank
    com = -knee_in_shank
    r = data["wrapping"]["condyle"]["radius"] * mm
    k = float(data["springs"]["knee_ap"]["stiffness"])
    assert float(data["springs"]["knee_si"]["stiffness"]) == k
    m_s = float(b["shank"]["mass"])
    g = np.array([-G, 0.0])
    R = _rot(flexion_rad)
    alpha = np.zeros(2)
    for _ in range(200):
        C = K + alpha  # the shank's knee origin
        S_tub, S_com = C + R @ tub, C + R @ com
        # the quadriceps pulls the tuberosity toward the condyle tangent point, or straight
        # toward its origin when the line O–S_tub clears the circle on the anterior side
        T2 = _anterior_tangent(S_tub, K, r)
        # running distally from O, the condyle centre lies to the right (posterior) of the
        # line at distance d; the line touches the circle when d < r
        d_right = -_cross(S_tub - O, K - O) / np.linalg.norm(S_tub - O)
        wraps = d_right < r
        u = (T2 - S_tub) if wraps else (O - S_tub)
        u = u / np.linalg.norm(u)
        # moments about C: F (S_tub − C) × u + (S_com − C) × m g = 0
        F = -_cross(S_com - C, m_s * g) / _cross(S_tub - C, u)
        # forces: F u + m g − k α = 0 (the springs carry the in-plane joint force)
        new = (F * u + m_s * g) / k
        if np.max(np.abs(new - alpha)) < 1e-13:
            break
        alpha = new
    return alpha, F, wraps


@pytest.mark.parametrize("flexion_deg", [-5.0, -40.0, -70.0])
def test_springs_knee_matches_independent_planar_statics(flexion_deg):
    model, settings, data = _load("knee_springs.yaml", flexion_deg)
    res = run_fdk(model, None, np.array([0.0]), settings, jacobian="analytic")
    assert res.converged.all(), res.messages
    alpha, F, wraps = planar_knee_statics(data, np.radians(flexion_deg))
    names = [d.name for d in model.fdk_dofs]
    got = dict(zip(names, res.alpha[0]))
    np.testing.assert_allclose([got["knee_x"], got["knee_y"]], alpha, atol=1e-4)  # 0.1 mm
    col = list(res.forces.column_names).index("quadriceps")
    assert res.forces.forces[0, col] == pytest.approx(F, abs=1.0)  # 1 N
    assert np.linalg.norm(alpha) > 2e-4 and F > 20
    assert wraps == (flexion_deg < -20)  # lift-off near extension, wrapped in flexion


def test_springs_example_runs_from_the_command_line(tmp_path):
    import json

    from openfdk.cli import main

    assert main(["run", str(KNEE / "knee_springs.yaml"), "--out", str(tmp_path), "--no-progress"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["fdk"]["converged_frames"] == summary["fdk"]["frames"] == 51


def test_contact_example_with_generated_meshes_runs(tmp_path, capsys):
    """make_meshes.py writes the STL surfaces; every frame converges and the condyle
    carries the joint compression: the contact force balances the quadriceps' pull
    along the shank at full extension. The condyle's rounded ends keep the contact
    line inside its mesh: no rim-truncation warning. The tutorial's table
    (docs/tutorial-knee.md §6) holds."""
    import csv
    import shutil
    import subprocess
    import sys

    from openfdk.cli import main

    shutil.copy(KNEE / "knee_contact.yaml", tmp_path / "knee_contact.yaml")
    subprocess.run([sys.executable, str(KNEE / "make_meshes.py"), str(tmp_path / "meshes")], check=True,
                   capture_output=True)
    out = tmp_path / "out"
    capsys.readouterr()
    assert main(["run", str(tmp_path / "knee_contact.yaml"), "--out", str(out), "--no-progress"]) == 0
    assert "warning" not in capsys.readouterr().err
    rows = list(csv.DictReader(open(out / "forces.csv")))
    # the tutorial's table: flexion (deg), quadriceps (N), α_x, α_y (mm), area (mm²), peak pressure (MPa)
    table = [(0, 185.2, -1.26, 0.10, 375, 0.74), (18, 259.6, -2.42, 0.75, 420, 0.90),
             (36, 219.7, -1.94, 1.37, 377, 0.78), (54, 159.4, -1.23, 1.65, 330, 0.59),
             (72, 83.0, -0.42, 1.29, 203, 0.30), (90, 0.0, -1.80, 0.00, 0, 0.00)]
    text = (Path(__file__).resolve().parents[1] / "docs" / "tutorial-knee.md").read_text()
    for flexion, quad_n, ax, ay, area, peak in table:
        r = rows[int(round(flexion / 90 * 50))]
        assert float(r["quadriceps.force_N"]) == pytest.approx(quad_n, abs=0.1)
        assert 1e3 * float(r["fdk.knee_x.alpha"]) == pytest.approx(ax, abs=0.01)
        assert 1e3 * float(r["fdk.knee_y.alpha"]) == pytest.approx(ay, abs=0.01)
        assert 1e6 * float(r["tibiofemoral.area_m2"]) == pytest.approx(area, abs=1)
        assert 1e-6 * float(r["tibiofemoral.peak_pressure_Pa"]) == pytest.approx(peak, abs=0.01)
        peak_text = f"{peak:.2f}" if peak else "0"
        row = f"| {flexion} | {quad_n:.1f} | {ax:.2f} | {ay:.2f} | {area} | {peak_text} |".replace("-", "−")
        assert row in text, row
    assert len(rows) == 51 and all(r["fdk_converged"] == "1" for r in rows)
    first = rows[0]
    # at full extension thigh and shank lie along the world x axis; the quadriceps pulls
    # the shank toward the hip (−x) and the plateau pushes the condyle (the thigh's
    # surface, the contact's body a) toward the hip too: it carries nearly all of the pull
    F_on_thigh = np.array([float(first[f"tibiofemoral.F{c}_N"]) for c in "xyz"])
    quad = float(first["quadriceps.force_N"])
    assert quad > 100
    assert -F_on_thigh[0] == pytest.approx(quad, rel=0.05)
    assert abs(F_on_thigh[2]) < 1e-6


def test_knee_benchmark_reports_frames_per_second(capsys):
    import json

    from openfdk.cli import main

    assert main(["bench", "--quick", "--json", "--only", "knee"]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines() if x.startswith("{")]
    fps = [x for x in lines if x["name"] == "knee_example_contact_fdk_fps"]
    assert len(fps) == 1 and fps[0]["value"] > 0 and fps[0]["convergence_rate"] == 1.0


def test_tibiofemoral_3dof_example_runs_and_balances_the_load(tmp_path):
    """Every frame converges; at extension the two condyle contacts carry the 500 N
    compression (plus the small ligament pull, < 25 N) and the 5 N m varus moment splits
    them: (F_medial − F_lateral) × 22 mm ≈ 5 N m."""
    import csv
    import shutil
    import subprocess
    import sys

    from openfdk.cli import main

    shutil.copy(KNEE / "tibiofemoral_3dof.yaml", tmp_path / "tf.yaml")
    subprocess.run([sys.executable, str(KNEE / "make_meshes.py"), str(tmp_path / "meshes")], check=True,
                   capture_output=True)
    assert main(["run", str(tmp_path / "tf.yaml"), "--out", str(tmp_path / "out"), "--no-progress"]) == 0
    rows = list(csv.DictReader(open(tmp_path / "out" / "forces.csv")))
    assert len(rows) == 31 and all(r["fdk_converged"] == "1" for r in rows)
    first = rows[0]
    ligaments = sum(float(first[f"{n}.force_N"]) for n in ("acl", "pcl", "mcl", "lcl"))
    F_m, F_l = float(first["medial.Fy_N"]), float(first["lateral.Fy_N"])
    assert ligaments < 25
    assert F_m + F_l == pytest.approx(500.0, abs=ligaments + 1.0)
    assert (F_m - F_l) * 0.022 == pytest.approx(5.0, abs=0.6)
