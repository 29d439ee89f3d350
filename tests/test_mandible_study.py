"""The mandible study end to end on the virtual subject (`openfdk demo --quick`), the
symmetry of a symmetric subject's open–close, and clear errors for broken inputs."""

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from openfdk.cli import main


@pytest.fixture(scope="module")
def demo_dir(tmp_path_factory):
    """``openfdk demo --quick -q`` as a user runs it (its output kept in OUT.stdout/.stderr)."""
    out = tmp_path_factory.mktemp("demo")
    done = subprocess.run([sys.executable, "-m", "openfdk.cli", "demo", "--quick", "-q", "--out", str(out)],
                          capture_output=True, text=True, timeout=1800)
    (out.parent / f"{out.name}.stdout").write_text(done.stdout)
    (out.parent / f"{out.name}.stderr").write_text(done.stderr)
    assert done.returncode == 0, done.stderr[-2000:]
    return out


def test_demo_quick_quiet_prints_only_warnings(demo_dir):
    """-q: nothing on stdout; stderr holds warnings (one line each) and nothing else."""
    assert (demo_dir.parent / f"{demo_dir.name}.stdout").read_text() == ""
    err = (demo_dir.parent / f"{demo_dir.name}.stderr").read_text().splitlines()
    assert all(line.startswith("openfdk: warning: ") for line in err), [
        line for line in err if not line.startswith("openfdk: warning: ")]


def _rows(path):
    return list(csv.DictReader(open(path)))


def test_demo_quick_tables_and_figures(demo_dir):
    study = demo_dir / "study"
    t1, t2 = _rows(study / "table1.csv"), _rows(study / "table2.csv")
    assert len(t1) == 3 * 2 * 3 and len(t2) == 3 * 2 * 3  # task × side × direction
    for name in ("chewing", "protrusion", "open_close"):
        for kind in ("kinematics", "forces"):
            assert (study / "figures" / f"{name}_{kind}.png").stat().st_size > 20_000
    assert (study / "table1.md").read_text().count("±") > 30


def test_demo_quick_physically_meaningful(demo_dir):
    study = demo_dir / "study"
    summary = json.loads((study / "summary.json").read_text())
    for task in ("chewing", "protrusion", "open_close"):
        runs = summary["runs"][task]
        assert runs["FDK"]["fdk"]["convergence_rate"] >= 0.99
        assert runs["POP"]["forces_converged"] == runs["POP"]["frames"]
    # kinematic RMSD within a few millimetres for both models (Table 1)
    for row in _rows(study / "table1.csv"):
        for model in ("FDK", "POP"):
            key = next(k for k in row if k.startswith(f"{model}") and "RMSD" in k and "mean" in k)
            assert 0 <= float(row[key]) < 3.0
    # TMJ forces are compressive: the fossa pushes the condyle down (SI < 0 on the mandible)
    for task in ("open_close", "protrusion"):
        for kind in ("pop", "fdk"):
            forces = _rows(study / task / kind / "forces.csv")
            if kind == "fdk":
                fz = np.array([float(r["tmj_r.Fz_N"]) for r in forces])
                assert np.nanmedian(fz) < 0
            else:
                f = np.array([float(r["tmj_r_compression.reaction"]) for r in forces])
                assert np.all(f >= 0) and np.median(f) > 0


def test_demo_quick_parameter_study_runs_through_the_study_machinery(demo_dir):
    """The quick parameter study (k = 136.2 and 544.8 N/m at ε_r = 0 on open–close) is an
    openfdk.study study: one row per case in summary.csv, every case converged, and —
    since the ligaments are far too weak to move the joint — the kinematics are nearly
    the same, so every ligament's peak force scales with the stiffness (ratio ≤ 4, > 3)."""
    ps = demo_dir / "study" / "parameter_study"
    rows = _rows(ps / "summary.csv")
    assert [r["case_id"] for r in rows] == ["fdk-open_close-000", "fdk-open_close-001"]
    assert [float(r["stiffness"]) for r in rows] == [136.2, 544.8]
    for r in rows:
        assert r["status"] == "completed" and float(r["convergence_rate"]) >= 0.99
        assert (ps / "cases" / r["case_id"] / "forces.csv").is_file()
    peaks = [k for k in rows[0] if k.startswith("tmj_ligament") and k.endswith(".peak_force_N")]
    assert len(peaks) == 6
    # the ligaments are weak beside the joint's tens of newtons in this unloaded
    # open–close (docs/mandible-study.md, "TMJ forces"), so a 4× stiffer ligament stretches slightly
    # less: the ratio is at most 4 (5 % tolerance) and well above 3 for every element
    for k in peaks:
        lo, hi = float(rows[0][k]), float(rows[1][k])
        assert lo > 0 and 3.0 < hi / lo <= 1.05 * 544.8 / 136.2, k
    summary = json.loads((demo_dir / "study" / "summary.json").read_text())
    assert summary["runs"]["parameter_study"]["cases"] == 2 and not summary["runs"]["parameter_study"]["failed"]


def test_subject_study_command_serial_matches_the_demo_on_dask(demo_dir, tmp_path):
    """`openfdk subject study` on the demo's subject folder, parameter study in this
    process (--workers 0): same tables and same parameter-study metrics as the demo's
    2-worker LocalCluster run."""
    out = tmp_path / "study"
    assert main(["subject", "study", str(demo_dir / "subject"), "--out", str(out), "--cycles", "2", "--quick",
                 "--workers", "0", "--no-progress"]) == 0
    for table in ("table1.csv", "table2.csv"):
        assert _rows(out / table) == _rows(demo_dir / "study" / table)
    serial, dask = _rows(out / "parameter_study" / "summary.csv"), _rows(demo_dir / "study" / "parameter_study" / "summary.csv")
    assert [r["case_id"] for r in serial] == [r["case_id"] for r in dask]
    for a, b in zip(serial, dask):
        for k in a:
            if k.endswith("_N") or k.endswith("_min") or k.endswith("_max") or k == "convergence_rate":
                assert float(a[k]) == pytest.approx(float(b[k]), rel=1e-6, abs=1e-9), k
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs"]["parameter_study"]["execution"]["mode"] == "serial"


def test_parameter_study_case_series_in_the_skull_frame(tmp_path):
    """The figures' grey band is built from the case folders' CSV files: a hand-made case
    (skull turned 90° about z, mandible sliding 2 mm along world x) gives the condyle
    displacement and contact force in the skull frame worked out by hand."""
    from types import SimpleNamespace

    from openfdk.mandible.parameter_study import case_tmj_series

    subject = SimpleNamespace(mandible=SimpleNamespace(center_of_mass=np.zeros(3)),
                              condyle_top=lambda tag: np.array([0.01, 0.05 if tag == "r" else -0.05, 0.0]))
    t = np.linspace(0.0, 1.0, 11)
    folder = tmp_path / "case"
    folder.mkdir()
    head = ["time"] + [f"{b}.{c}" for b in ("skull", "mandible") for c in ("x_m", "y_m", "z_m", "e0", "e1", "e2", "e3")]
    with open(folder / "kinematics.csv", "w") as fh:
        fh.write(",".join(head) + "\n")
        for ti in t:
            # skull turned 90° about z (e = [cos 45°, 0, 0, sin 45°]); mandible translated 2 mm along world x
            s = [0.0, 0.0, 0.0, np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)]
            m = [0.002 * ti, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
            fh.write(",".join(str(x) for x in [ti] + s + m) + "\n")
    with open(folder / "forces.csv", "w") as fh:
        fh.write("time,tmj_r.Fx_N,tmj_r.Fy_N,tmj_r.Fz_N\n")
        for ti in t:
            fh.write(f"{ti},10.0,0.0,-5.0\n")
    time, kin, forces = case_tmj_series(folder, subject)
    # world x is the skull's −y: p_S = R_WSᵀ p_W; displacement = p_S − condyle top
    p_W = np.array([0.01, 0.05, 0.0])
    expected_r = np.array([p_W[1], -p_W[0], 0.0])[None, :] + np.outer(0.002 * t, [0.0, -1.0, 0.0]) - [0.01, 0.05, 0]
    np.testing.assert_allclose(kin["right"], expected_r, atol=1e-12)
    np.testing.assert_allclose(forces["right"], np.tile([0.0, -10.0, -5.0], (11, 1)), atol=1e-12)
    assert np.all(np.isnan(forces["left"]))  # no left contact columns: NaN, not zero


def test_symmetric_subject_symmetric_open_close(tmp_path):
    """A symmetric subject, a symmetric open–close without noise, head motion or
    model–truth differences: left and right TMJ kinematics and forces mirror each other
    (AP and SI equal, ML opposite) for both models."""
    from openfdk.mandible.experiment import TruthOptions, record_experiment
    from openfdk.mandible.generator import create_subject
    from openfdk.mandible.models import write_models
    from openfdk.mandible.registration import register_braces
    from openfdk.mandible.study import analyse_trial
    from openfdk.mandible.subject import load_subject

    d = create_subject(tmp_path / "subject", resolution="coarse", symmetric=True)
    record_experiment(d, tasks=("open_close",), cycles=1, noise_mm=0.0, head_motion=False, truth=TruthOptions.exact())
    subject = load_subject(d)
    reg = register_braces(subject, d / "trials" / "reference.c3d")
    models = write_models(subject, reg, tmp_path / "models")
    # the virtual lab holds the head pitched 5° and yawed 30°, which puts ≈ 4 % of the
    # mandible's weight along the skull's medio-lateral axis: a real, asymmetric load.
    # Symmetry is checked without gravity.
    import yaml

    for path in models.values():
        data = yaml.safe_load(path.read_text())
        data["gravity"] = [0.0, 0.0, 0.0]
        path.write_text(yaml.safe_dump(data))
    # the whole one-cycle trial (no cycle split: one cycle has no autocorrelation peak)
    series, runs = analyse_trial(subject, reg, models, d / "trials" / "open_close.c3d", tmp_path / "out")
    mirror = np.array([1.0, -1.0, 1.0])
    for model in ("measured", "POP"):
        k = series["kinematics"][model]
        np.testing.assert_allclose(k["left"], k["right"] * mirror, atol=2e-5, err_msg=model)  # 0.02 mm
    # FDK: near the unloaded turning points of the movement the medio-lateral DOF's
    # stiffness is a few N/m, so the force tolerance (1e-3 N) leaves it determined to a
    # few hundredths of a mm there; elsewhere AP and SI mirror to 0.05 mm
    k = series["kinematics"]["FDK"]
    diff = np.abs(k["left"][:, [0, 2]] - k["right"][:, [0, 2]])
    assert np.median(diff) < 5e-5 and np.max(diff) < 5e-4
    shift = 0.5 * (k["left"][:, 1] + k["right"][:, 1])  # common sideways shift of the mandible
    assert np.median(np.abs(shift)) < 2e-5 and np.max(np.abs(shift)) < 5e-4
    for model in ("POP", "FDK"):
        f = series["forces"][model]
        scale = np.nanmax(np.abs(f["right"]))
        assert scale > 1.0
        np.testing.assert_allclose(f["left"], f["right"] * mirror, atol=0.02 * scale, err_msg=model)


def test_missing_trial_is_named(tmp_path):
    from openfdk.mandible.generator import create_subject
    from openfdk.mandible.study import StudyError, run_study

    d = create_subject(tmp_path / "subject", resolution="coarse")
    with pytest.raises(StudyError, match=r"task .chewing.: trial file trials/chewing.c3d is missing"):
        run_study(d, tmp_path / "out", log=lambda *a: None)


def test_demo_writes_a_3d_viewer_per_task(demo_dir):
    for task in ("chewing", "protrusion", "open_close"):
        page = demo_dir / "study" / task / "fdk" / "view.html"
        text = page.read_text()
        assert 'id="openfdk-data"' in text and page.stat().st_size < 30e6
        data = json.loads(text.split('id="openfdk-data">', 1)[1].split("</script>", 1)[0])
        assert len(data["scene"]["contacts"]) == 2 and len(data["scene"]["paths"]) >= 24
