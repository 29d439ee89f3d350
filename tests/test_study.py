"""Parameter studies on Dask: override paths, study files, and running studies serially
and on a 2-process LocalCluster on loopback — same results, a killed worker, a broken
case, a rerun after an interruption, chunked cases, the command line."""

import argparse
import json
import os
import signal
import threading
import time

import numpy as np
import pytest
import yaml

from openfdk.io.c3d import write_c3d
from openfdk.study import (
    CaseKind,
    Override,
    OverrideError,
    StudyError,
    add_study_parser,
    apply_overrides,
    load_study,
    parameter_band,
    read_table,
    register_case_kind,
    run_study,
    study_from_dict,
)
from openfdk.study.cluster import dask_client
from openfdk.study.kinds import prepare_model_case
from openfdk.fixtures.synthetic_jaw import jaw_fdk_model_dict, jaw_markers, write_jaw_meshes

EPS_L = 0.03  # Blankevoort toe-region parameter ε_l (docs/design.md §1)
LIGAMENTS = [f"tmj_ligament_{s}{e}" for s in "rl" for e in (1, 2, 3)]


# -- fixtures ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """TMJ-like FDK model (meshes next to it) and a 30-frame open–close trial."""
    d = tmp_path_factory.mktemp("study")
    write_jaw_meshes(d / "meshes")
    (d / "tmj.yaml").write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes"), sort_keys=False))
    _t, labels, x, _ = jaw_markers(30, noise=1e-4, seed=11)
    write_c3d(d / "trial.c3d", labels, x, 100.0)
    return d


def study_data(**extra):
    """A 2 × 2 grid on the TMJ ligaments (whole-ligament stiffness split over its 3
    elements, as in the paper) over the first 20 frames (0–0.19 s at 100 Hz)."""
    data = {
        "openfdk_study": 1,
        "name": "tmj-test",
        "models": {"tmj": "tmj.yaml"},
        "trials": {"oc": "trial.c3d"},
        "parameters": {
            "stiffness": {"set": "ligaments.tmj_ligament_*.stiffness", "scale": 1 / 3},
            "reference_strain": "ligaments.tmj_ligament_*.reference_strain",
        },
        "grid": {"stiffness": [136.2, 544.8], "reference_strain": [-0.04, 0.04]},
        "run": {"end": 0.19, "retries": 1},
    }
    data.update(extra)
    return data


@pytest.fixture(scope="module")
def serial(files, tmp_path_factory):
    """The reference: the small study run case after case in this process."""
    out = tmp_path_factory.mktemp("serial")
    res = run_study(study_from_dict(study_data(), "tmj-test.yaml", files), out, workers=0, progress=False)
    return res


@pytest.fixture(scope="module")
def client():
    """A LocalCluster of 2 worker processes (1 thread each) on 127.0.0.1."""
    with dask_client(workers=2) as c:
        yield c


def slow_prepare(case):
    """A case kind for the killed-worker test: the model kind after a 1.5 s pause, so a
    kill lands while the case runs."""
    time.sleep(1.5)
    return prepare_model_case(case)


def _forces(out, case_id):
    return read_table(out / "cases" / case_id / "forces.csv")


# -- override paths --------------------------------------------------------------------


def test_override_paths_globs_lists_and_new_keys():
    data = {"ligaments": {"a1": {"stiffness": 1.0}, "a2": {"stiffness": 2.0, "reference_strain": 0.1},
                          "b1": {"stiffness": 3.0}},
            "bodies": {"jaw": {"position": [1.0, 2.0, 3.0]}}}
    out = apply_overrides(data, [Override("ligaments.a*.stiffness", 9.0),
                                 Override("ligaments.*.reference_strain", -0.02),
                                 Override("bodies.jaw.position.2", 7.5),
                                 Override("ligaments.b1.stiffness", 2.0, "multiply")])
    assert [out["ligaments"][k]["stiffness"] for k in ("a1", "a2", "b1")] == [9.0, 9.0, 6.0]
    # a plain last segment adds the key where it is missing (overriding a default)
    assert all(v["reference_strain"] == -0.02 for v in out["ligaments"].values())
    assert out["bodies"]["jaw"]["position"] == [1.0, 2.0, 7.5]
    assert data["ligaments"]["a1"] == {"stiffness": 1.0}  # the input is not modified
    # multiply also reads YAML 1.1 numeric strings and lists
    out = apply_overrides({"c": {"p": "1.0e10", "v": [1, 2]}}, [Override("c.p", 0.5, "multiply"),
                                                                 Override("c.v", 3, "multiply")])
    assert out["c"] == {"p": 5e9, "v": [3.0, 6.0]}


def test_override_that_matches_nothing_is_an_error_naming_it():
    data = {"ligaments": {"tmj_ligament_r1": {"stiffness": 1.0}}, "contacts": {"tmj_r": {"pressure_modulus": 1e10}}}
    pattern = r"'ligaments\.tmj_ligamnt_\*\.stiffness' matches nothing.*'tmj_ligamnt_\*'"
    with pytest.raises(OverrideError, match=pattern):
        apply_overrides(data, [Override("ligaments.tmj_ligamnt_*.stiffness", 2.0)])
    with pytest.raises(OverrideError, match="did you mean 'contacts'"):
        apply_overrides(data, [Override("contact.tmj_r.pressure_modulus", 2.0)])
    with pytest.raises(OverrideError, match=r"no entry matches 'damp\*'"):  # a glob last segment must match
        apply_overrides(data, [Override("ligaments.*.damp*", 2.0)])
    with pytest.raises(OverrideError, match="matches nothing"):  # multiply needs an existing number
        apply_overrides(data, [Override("ligaments.tmj_ligament_r1.damping", 2.0, "multiply")])


# -- study files -----------------------------------------------------------------------


def test_paper_parameter_study_expands_to_15_cases(files):
    data = study_data(grid={"stiffness": [136.2, 272.4, 544.8], "reference_strain": [-0.04, -0.02, 0.0, 0.02, 0.04]})
    study = study_from_dict(data, "s.yaml", files)
    assert len(study.cases) == 15 and study.parameter_names == ["stiffness", "reference_strain"]
    assert [c.case_id for c in study.cases[:2]] == ["tmj-oc-000", "tmj-oc-001"]
    c = study.cases[7]  # last parameter varies fastest: 272.4 × 0.0
    assert c.parameters == {"stiffness": 272.4, "reference_strain": 0.0}
    ov = {o.path: o.value for o in c.overrides}
    assert ov["ligaments.tmj_ligament_*.stiffness"] == pytest.approx(272.4 / 3)  # per element
    assert len({x.fingerprint for x in study.cases}) == 15
    # explicit cases are appended after the grid; a dotted key is a direct path
    data["cases"] = [{"contacts.tmj_r.pressure_modulus": 2.0e10}]
    study = study_from_dict(data, "s.yaml", files)
    assert len(study.cases) == 16 and study.cases[-1].overrides[0].path == "contacts.tmj_r.pressure_modulus"


def test_study_file_errors_name_the_entry(files, tmp_path):
    with pytest.raises(StudyError, match=r"grid\.stifness: unknown parameter.*did you mean 'stiffness'"):
        study_from_dict(study_data(grid={"stifness": [1.0]}), "s.yaml", files)
    with pytest.raises(StudyError, match=r"trials\.oc: 'missing\.c3d' not found"):
        study_from_dict(study_data(trials={"oc": "missing.c3d"}), "s.yaml", files)
    bad = study_data(parameters={"k": "ligaments.tmj_ligamnt_*.stiffness"}, grid={"k": [1.0]})
    with pytest.raises(StudyError, match=r"case tmj-oc-000: .*'ligaments\.tmj_ligamnt_\*\.stiffness' matches nothing"):
        study_from_dict(bad, "s.yaml", files)
    with pytest.raises(StudyError, match=r"run\.chunk: unknown key; did you mean 'chunks'"):
        study_from_dict(study_data(run={"chunk": 2}), "s.yaml", files)
    path = tmp_path / "s.yaml"
    path.write_text("models: [a\n")
    with pytest.raises(StudyError, match="s.yaml: malformed YAML at line"):
        load_study(path)


def test_fingerprint_follows_parameters_options_and_model_content(files, tmp_path):
    (tmp_path / "tmj.yaml").write_text((files / "tmj.yaml").read_text())
    (tmp_path / "trial.c3d").write_bytes((files / "trial.c3d").read_bytes())
    a = study_from_dict(study_data(), "s.yaml", tmp_path).cases
    b = study_from_dict(study_data(grid={"stiffness": [136.2, 500.0], "reference_strain": [-0.04, 0.04]}),
                        "s.yaml", tmp_path).cases
    assert [x.fingerprint == y.fingerprint for x, y in zip(a, b)] == [True, True, False, False]
    c = study_from_dict(study_data(run={"end": 0.19, "chunks": 2}), "s.yaml", tmp_path).cases
    assert all(x.fingerprint != y.fingerprint for x, y in zip(a, c))
    d = study_from_dict(study_data(run={"end": 0.19, "retries": 5}), "s.yaml", tmp_path).cases
    assert all(x.fingerprint == y.fingerprint for x, y in zip(a, d))  # retries do not change results
    (tmp_path / "tmj.yaml").write_text((files / "tmj.yaml").read_text() + "\ndescription: edited\n")
    e = study_from_dict(study_data(), "s.yaml", tmp_path).cases
    assert all(x.fingerprint != y.fingerprint for x, y in zip(a, e))


# -- running studies -------------------------------------------------------------------


def test_serial_study_overrides_reach_the_model(serial):
    """Every case's ligament forces follow the Blankevoort law with that case's
    per-element stiffness k/3, and its slack length l0 = l/(1+ε) satisfies
    l0 (1 + ε_r) = l_r, the same reference length for every case (docs/design.md §1)."""
    assert serial.ok and len(serial.records) == 4
    l_ref = {}
    for rec in serial.records:
        k = rec["parameters"]["stiffness"] / 3
        eps_r = rec["parameters"]["reference_strain"]
        table = _forces(serial.out_dir, rec["case_id"])
        assert len(table["time"]) == 20
        for lig in LIGAMENTS:
            eps, length, force = table[f"{lig}.strain"], table[f"{lig}.length_m"], table[f"{lig}.force_N"]
            l0 = length / (1 + eps)
            expected = np.where(eps < 0, 0.0, np.where(eps <= 2 * EPS_L, k * l0 * eps**2 / (4 * EPS_L),
                                                       k * l0 * (eps - EPS_L)))
            np.testing.assert_allclose(force, expected, rtol=1e-8, atol=1e-12)
            l_ref.setdefault(lig, []).append(l0 * (1 + eps_r))
    for lig, values in l_ref.items():
        np.testing.assert_allclose(np.concatenate(values), values[0][0], rtol=1e-8)
    # the taut ligaments (ε_r = +0.04) actually pull
    taut = [r for r in serial.records if r["parameters"]["reference_strain"] > 0]
    assert all(r["metrics"]["tmj_ligament_r3.peak_force_N"] > 0 for r in taut)


def test_local_cluster_study_gives_the_serial_results(files, serial, client, tmp_path):
    assert all(a.startswith("tcp://127.0.0.1:") for a in client.scheduler_info()["workers"])
    res = run_study(study_from_dict(study_data(), "tmj-test.yaml", files), tmp_path, client=client, progress=False)
    assert res.ok and [r["case_id"] for r in res.records] == [r["case_id"] for r in serial.records]
    workers = {r["worker"] for r in res.records}
    assert os.getpid() not in {int(w.rsplit(":", 1)[1]) for w in workers}  # ran in the worker processes
    for rec in res.records:
        a, b = _forces(tmp_path, rec["case_id"]), _forces(serial.out_dir, rec["case_id"])
        # the same deterministic computation in another process: equal to round-off
        for col in ("fdk.tmj_r_normal.alpha", "fdk.ml_shift.alpha", "tmj_r.Fz_N", "anterior_temporalis_r.force_N",
                    "superficial_masseter_r.passive_N"):
            np.testing.assert_allclose(a[col], b[col], rtol=1e-7, atol=1e-10)
    header = (tmp_path / "summary.csv").read_text().splitlines()[0].split(",")
    assert header[:7] == ["case_id", "status", "reused", "model", "trial", "stiffness", "reference_strain"]
    summary = read_table(tmp_path / "summary.csv")
    np.testing.assert_array_equal(summary["convergence_rate"], 1.0)
    assert summary["status"] == ["completed"] * 4


def test_killed_worker_does_not_lose_the_study(files, client, tmp_path):
    register_case_kind(CaseKind("slow_model", inputs=("models", "trials"), optional=("trials",),
                                paths=("models", "trials"), prepare="test_study:slow_prepare"))
    data = study_data(kind="slow_model", grid={"stiffness": [136.2, 272.4, 408.6, 544.8]}, run={"end": 0.09})
    study = study_from_dict(data, "slow.yaml", files)
    pids = client.run(os.getpid)  # worker address -> pid
    killed = {}

    def kill_a_busy_worker():
        deadline = time.time() + 30
        while time.time() < deadline and not killed:
            for address, keys in client.processing().items():
                if keys and address in pids:
                    killed.update(pid=pids[address], keys=list(keys))
                    os.kill(pids[address], signal.SIGKILL)
                    return
            time.sleep(0.02)

    killer = threading.Thread(target=kill_a_busy_worker)
    killer.start()
    try:
        res = run_study(study, tmp_path, client=client, progress=False, retries=0)  # no driver retries
    finally:
        killer.join()
    assert killed, "no worker was seen processing a case"
    assert res.ok and [r["status"] for r in res.records] == ["completed"] * 4
    assert all((tmp_path / "cases" / c.case_id / "forces.csv").is_file() for c in study.cases)
    # the case that was running in the killed process finished in another one
    assert all(int(r["worker"].rsplit(":", 1)[1]) != killed["pid"] for r in res.records)
    assert not list((tmp_path / "cases").glob(".*"))  # no half-written folders left


def test_broken_case_is_reported_and_the_others_complete(files, client, tmp_path):
    data = study_data(cases=[{"stiffness": -3.0, "reference_strain": 0.0}])  # 4 grid cases + a negative stiffness
    res = run_study(study_from_dict(data, "s.yaml", files), tmp_path, client=client, progress=False)
    assert [r["status"] for r in res.records] == ["completed"] * 4 + ["failed"]
    bad = res.records[-1]
    assert bad["attempts"] == 2  # retried once (run.retries: 1)
    assert "ModelError" in bad["error"] and "tmj_ligament_r1.stiffness: must be > 0" in bad["error"]
    assert not (tmp_path / "cases" / bad["case_id"]).exists()
    summary = read_table(tmp_path / "summary.csv")
    assert summary["status"][-1] == "failed" and "must be > 0" in summary["error"][-1]
    assert json.loads((tmp_path / "summary.json").read_text())["counts"]["failed"] == 1


def test_chunked_case_on_the_cluster_matches_the_serial_case(files, serial, client, tmp_path):
    data = study_data(run={"end": 0.19, "chunks": 2, "overlap": 2})
    res = run_study(study_from_dict(data, "s.yaml", files), tmp_path, client=client, progress=False)
    assert res.ok
    for rec in res.records:
        a, b = _forces(tmp_path, rec["case_id"]), _forces(serial.out_dir, rec["case_id"])
        np.testing.assert_array_equal(a["time"], b["time"])
        assert np.all(np.abs(a["fdk.tmj_r_normal.residual"]) < 1e-3)  # the FDK tolerance holds at every frame
        np.testing.assert_allclose(a["tmj_r.Fz_N"], b["tmj_r.Fz_N"], atol=5e-2)  # 50 × FDK tolerance (test_chunks)
        case = json.loads((tmp_path / "cases" / rec["case_id"] / "summary.json").read_text())
        assert case["input"]["chunks"] == 2


def test_rerun_after_an_interruption_skips_completed_cases(files, tmp_path):
    study = study_from_dict(study_data(run={"end": 0.05}), "s.yaml", files)
    done = []

    def interrupt_after_two(rec):
        done.append(rec["case_id"])
        if len(done) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_study(study, tmp_path, workers=0, progress=False, on_case_done=interrupt_after_two)
    assert not (tmp_path / ".study.lock").exists()
    assert json.loads((tmp_path / "summary.json").read_text())["counts"] == {
        "cases": 4, "completed": 2, "reused": 0, "failed": 0, "not_run": 2}
    stamps = {c: (tmp_path / "cases" / c / "case.json").stat().st_mtime_ns for c in done}
    # what a process killed while writing a case leaves behind
    (tmp_path / "cases" / ".tmj-oc-002.tmp-deadbeef").mkdir()
    (tmp_path / "cases" / ".tmj-oc-002.tmp-deadbeef" / "kinematics.csv").write_text("time\n0.0\n")
    ran = []
    res = run_study(study, tmp_path, workers=0, progress=False, on_case_done=lambda r: ran.append(r["case_id"]))
    assert res.ok and sorted(ran) == sorted({c.case_id for c in study.cases} - set(done))
    assert [r["reused"] for r in res.records] == [c.case_id in done for c in study.cases]
    assert {c: (tmp_path / "cases" / c / "case.json").stat().st_mtime_ns for c in done} == stamps
    assert not (tmp_path / "cases" / ".tmj-oc-002.tmp-deadbeef").exists()
    # a changed parameter value makes that case stale: it alone is run again
    edited = study_data(run={"end": 0.05}, grid={"stiffness": [136.2, 600.0], "reference_strain": [-0.04, 0.04]})
    ran.clear()
    res = run_study(study_from_dict(edited, "s.yaml", files), tmp_path, workers=0, progress=False,
                    on_case_done=lambda r: ran.append(r["case_id"]))
    assert sorted(ran) == ["tmj-oc-002", "tmj-oc-003"]
    case = json.loads((tmp_path / "cases" / "tmj-oc-002" / "case.json").read_text())
    assert case["parameters"]["stiffness"] == 600.0
    # --force runs complete cases again
    ran.clear()
    res = run_study(study_from_dict(edited, "s.yaml", files), tmp_path, workers=0, progress=False, force=True,
                    on_case_done=lambda r: ran.append(r["case_id"]))
    assert len(ran) == 4 and not any(r["reused"] for r in res.records)


def test_study_on_a_running_scheduler_by_address(files, client, tmp_path):
    data = study_data(grid={"stiffness": [272.4]}, run={"end": 0.03})
    res = run_study(study_from_dict(data, "s.yaml", files), tmp_path, scheduler=client.scheduler.address,
                    progress=False)
    assert res.ok and res.summary["execution"]["scheduler"] == client.scheduler.address
    assert len(_forces(tmp_path, "tmj-oc-000")["time"]) == 4


def test_example_studies_load(tmp_path):
    """The example study files parse and their override paths resolve in their models."""
    import importlib.util
    import shutil
    from pathlib import Path

    examples = Path(__file__).resolve().parents[1] / "examples" / "studies"
    study = load_study(examples / "slider_crank_speed_and_mass.yaml")
    assert len(study.cases) == 6 and study.options.metrics == ("crank_drive.reaction",)
    spec = importlib.util.spec_from_file_location("make_tmj_inputs", examples / "make_tmj_inputs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.make_tmj_inputs(tmp_path / "tmj")
    for name, n_cases in (("tmj_ligament_parameter_study.yaml", 15), ("tmj_long_trial_chunks.yaml", 3)):
        shutil.copy(examples / name, tmp_path / name)
        assert len(load_study(tmp_path / name).cases) == n_cases


def test_parameter_band_envelopes_the_cases(serial):
    time_s, lower, upper, _mean = parameter_band(serial.out_dir, "tmj_ligament_r3.force_N")
    values = np.vstack([_forces(serial.out_dir, r["case_id"])["tmj_ligament_r3.force_N"] for r in serial.records])
    np.testing.assert_array_equal(lower, values.min(axis=0))
    np.testing.assert_array_equal(upper, values.max(axis=0))
    assert len(time_s) == 20 and np.all(upper - lower > 0)  # the parameters change the ligament force


def test_command_line_study(files, tmp_path, capsys):
    parser = argparse.ArgumentParser(prog="openfdk")
    add_study_parser(parser.add_subparsers(dest="command", required=True))
    data = study_data(grid=None, cases=[{"stiffness": 272.4}, {"stiffness": -1.0}], run={"end": 0.03, "retries": 0})
    del data["grid"]
    path = files / "cli-study.yaml"
    path.write_text(yaml.safe_dump(data))
    args = parser.parse_args(["study", str(path), "--out", str(tmp_path), "--list"])
    assert args.func(args) == 0
    assert "tmj-oc-000: models=tmj trials=oc stiffness=272.4" in capsys.readouterr().out
    args = parser.parse_args(["study", str(path), "--out", str(tmp_path), "--workers", "0", "--no-progress"])
    assert args.func(args) == 3  # one case failed, the other completed
    captured = capsys.readouterr()
    assert "1/2 cases completed" in captured.out and "failed: tmj-oc-001 after 1 attempts" in captured.err
    assert (tmp_path / "study.yaml").read_text() == path.read_text()
