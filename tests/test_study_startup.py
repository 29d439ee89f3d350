"""Start-up work done once per process rather than once per study case: meshes and
parsed model files memoised by file stamp, metrics computed in the worker, cases handed
out longest first, and a study driver that does not import the analysis layers."""

import os
import subprocess
import sys
import time
import warnings
from dataclasses import replace

import numpy as np
import pytest
import trimesh
import yaml

from openfdk.contact.mesh import MeshWarning, load_mesh
from openfdk.contact.mesh_cache import cached_load_mesh, clear_mesh_cache, mesh_cache_size
from openfdk.contact.shapes import sphere_cap
from openfdk.fixtures.synthetic_jaw import jaw_fdk_model_dict, jaw_markers, write_jaw_meshes
from openfdk.io.c3d import write_c3d
from openfdk.model.model import ModelError
from openfdk.study.case import case_dir, run_case
from openfdk.study.kinds import read_model_mapping
from openfdk.io.trials import recorded_duration_s
from openfdk.study.runner import analysed_duration_s, longest_first
from openfdk.study.spec import study_from_dict
from openfdk.study.summary import case_metrics


def _touch_later(path):
    """Give ``path`` a modification time 2 s later than now (file stamps change even on
    file systems with a coarse clock)."""
    t = time.time() + 2.0
    os.utime(path, (t, t))


def test_mesh_is_read_once_and_the_same_as_an_uncached_load(tmp_path):
    cap = sphere_cap(10.0, 0.6, 1.0, pole=(0.0, 0.0, 1.0))
    path = tmp_path / "cap.ply"
    trimesh.Trimesh(cap.vertices_B, cap.faces, process=False).export(path)
    clear_mesh_cache()
    placement = (np.array([0.01, 0.0, -0.02]), np.eye(3))
    first = cached_load_mesh(path, units="mm", placement=placement, name="cap")
    again = cached_load_mesh(path, units="mm", placement=placement, name="cap")
    assert again is first and mesh_cache_size() == 1
    reference = load_mesh(path, units="mm", placement=placement, name="cap")
    np.testing.assert_array_equal(first.vertices_B, reference.vertices_B)
    np.testing.assert_array_equal(first.faces, reference.faces)
    np.testing.assert_array_equal(first.vertex_areas, reference.vertex_areas)
    # other options are other meshes: 1 mm = 1e-3 m, so the "m" mesh is 1000 times larger
    in_m = cached_load_mesh(path, units="m", placement=placement, name="cap")
    assert in_m is not first and mesh_cache_size() == 2
    assert in_m.area == pytest.approx(first.area * 1e6, rel=1e-12)
    # an edited file is read again: the same cap scaled by 2 has 4 times the area
    trimesh.Trimesh(2.0 * cap.vertices_B, cap.faces, process=False).export(path)
    _touch_later(path)
    edited = cached_load_mesh(path, units="mm", placement=placement, name="cap")
    assert edited is not first
    assert edited.area == pytest.approx(4.0 * first.area, rel=1e-9)


def test_cached_mesh_repeats_its_repair_warnings(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 2, 0], [3, 3, 0.0]])
    F = np.array([[0, 1, 2], [1, 3, 2], [0, 3, 4], [3, 4, 5]])  # the last two are collinear
    path = tmp_path / "degenerate.obj"
    trimesh.Trimesh(V, F, process=False).export(path)
    clear_mesh_cache()
    for _ in range(2):  # every model built from the file reports the repair
        with pytest.warns(MeshWarning, match="degenerate.obj.*removed 2 degenerate"):
            mesh = cached_load_mesh(path, units="mm")
        assert mesh.n_faces == 2
    with pytest.raises(Exception, match="does not exist"):
        cached_load_mesh(tmp_path / "missing.stl")


def test_model_mapping_is_parsed_once_and_each_caller_gets_its_own_copy(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("bodies: {a: {mass: 1.0}}\n")
    first = read_model_mapping(path)
    first["bodies"]["a"]["mass"] = 99.0  # a caller edits its copy
    assert read_model_mapping(path) == {"bodies": {"a": {"mass": 1.0}}}
    path.write_text("bodies: {a: {mass: 2.5}}\n")
    _touch_later(path)
    assert read_model_mapping(path) == {"bodies": {"a": {"mass": 2.5}}}
    path.write_text("- not a mapping\n")
    _touch_later(path)
    with pytest.raises(ModelError, match="m.yaml: a model file must contain a mapping"):
        read_model_mapping(path)


def _jaw_study(d, windows):
    write_jaw_meshes(d / "meshes")
    (d / "tmj.yaml").write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes"), sort_keys=False))
    _t, labels, x, _ = jaw_markers(40, noise=1e-4, seed=11)
    write_c3d(d / "trial.c3d", labels, x, 100.0)
    cases = []
    for end in windows:
        data = {"openfdk_study": 1, "name": "t", "models": {"tmj": "tmj.yaml"}, "trials": {"oc": "trial.c3d"},
                "parameters": {"k": "ligaments.tmj_ligament_*.stiffness"}, "grid": {"k": [40.0]},
                "run": {"end": end, "metrics": ["tmj_r.Fz_N"]}}
        cases += study_from_dict(data, "t.yaml", d).cases
    return cases


def test_cases_go_to_the_workers_longest_window_first(tmp_path):
    cases = _jaw_study(tmp_path, [0.1, 0.3, 0.2, 0.3])
    order = [c.options.end for c in longest_first(cases)]
    assert order == [0.3, 0.3, 0.2, 0.1]
    assert longest_first(cases)[0] is cases[1]  # equal windows keep the study order
    whole = replace(cases[0], options=replace(cases[0].options, end=None))
    assert longest_first([*cases, whole])[0] is whole  # an open window counts as longest


def test_whole_trial_cases_go_longest_recording_first(tmp_path):
    """Open windows are ranked by the trial's recorded length (read from its header),
    and a window's end past the recording counts only up to the recording's end."""
    write_jaw_meshes(tmp_path / "meshes")
    (tmp_path / "tmj.yaml").write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes"), sort_keys=False))
    for name, n in (("short", 40), ("long", 100)):
        _t, labels, x, _ = jaw_markers(n, noise=1e-4, seed=11)
        write_c3d(tmp_path / f"{name}.c3d", labels, x, 100.0)
    cases = []
    for end in (None, 5.0, 0.5):
        data = {"openfdk_study": 1, "name": "t", "models": {"tmj": "tmj.yaml"},
                "trials": {"short": "short.c3d", "long": "long.c3d"},
                "parameters": {"k": "ligaments.tmj_ligament_*.stiffness"}, "grid": {"k": [40.0]},
                "run": {"end": end}}
        cases += study_from_dict(data, "t.yaml", tmp_path).cases
    assert recorded_duration_s(tmp_path / "short.c3d") == pytest.approx(0.39, abs=1e-9)   # (40 − 1)/100 Hz
    assert recorded_duration_s(tmp_path / "long.c3d") == pytest.approx(0.99, abs=1e-9)
    durations = [round(analysed_duration_s(c), 6) for c in cases]
    trials = [c.names["trials"] for c in cases]
    assert sorted(zip(trials, durations)) == sorted([("short", 0.39), ("long", 0.99), ("short", 0.39),
                                                     ("long", 0.99), ("short", 0.39), ("long", 0.5)])
    order = longest_first(cases)
    assert [round(analysed_duration_s(c), 6) for c in order] == [0.99, 0.99, 0.5, 0.39, 0.39, 0.39]
    assert [c.options.end for c in order if c.names["trials"] == "short"] == [None, 5.0, 0.5]  # study order


def test_recorded_duration_from_a_trc_header_and_unknown_files(tmp_path):
    trc = tmp_path / "t.trc"
    trc.write_text("PathFileType\t4\t(X/Y/Z)\tt.trc\n"
                   "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\n"
                   "250\t250\t501\t1\tmm\n"
                   "Frame#\tTime\tA\n\t\tX1\tY1\tZ1\n")
    assert recorded_duration_s(trc) == pytest.approx(2.0)            # (501 − 1)/250 Hz
    (tmp_path / "bad.trc").write_text("PathFileType\n")
    (tmp_path / "bad.c3d").write_bytes(b"not a c3d")
    assert recorded_duration_s(tmp_path / "bad.trc") is None
    assert recorded_duration_s(tmp_path / "bad.c3d") is None
    assert recorded_duration_s(tmp_path / "missing.c3d") is None
    assert recorded_duration_s(tmp_path / "t.csv") is None


def test_worker_metrics_are_the_driver_metrics_of_the_folder(tmp_path):
    (case,) = _jaw_study(tmp_path, [0.05])
    record = run_case(case, tmp_path / "out", force=True)
    metrics, warns = case_metrics(case_dir(tmp_path / "out", case.case_id), ["tmj_r.Fz_N"])
    assert record["metric_columns"] == ["tmj_r.Fz_N"] and record["metric_warnings"] == warns == []
    assert record["metrics"] == metrics
    assert metrics["frames"] == 6 and metrics["convergence_rate"] == 1.0
    assert metrics["tmj_r.Fz_N.min"] <= metrics["tmj_r.Fz_N.mean"] <= metrics["tmj_r.Fz_N.max"]
    assert abs(metrics["tmj_r.Fz_N.mean"]) > 0.1  # N: the contact carries load


def test_study_driver_imports_no_analysis_layer():
    """The driver of a study (runner, case folders, the study benchmark's script) starts
    without numba, scipy or trimesh: only the workers need them."""
    code = ("import sys, openfdk.study.runner, openfdk.bench.study\n"
            "print(sorted(m for m in ('numba', 'scipy', 'trimesh', 'openfdk.model.model') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from openfdk.model.errors import ModelError as light
    assert light is ModelError


def test_a_case_path_imports_none_of_the_libraries_openfdk_replaced(tmp_path):
    """Reading and filtering a trial (openfdk.io.butterworth, openfdk.numerics.cubic_spline),
    loading an STL mesh (openfdk.contact.stl) and importing the spline drivers and the
    recruitment do not import scipy.signal/stats (≈ 0.3 s), scipy.interpolate (≈ 0.2 s,
    with scipy.special and scipy.optimize), scipy.sparse or trimesh (≈ 0.25 s): each
    was used for one function and cost every openfdk process its import time."""
    cap = sphere_cap(10.0, 0.6, 1.0, pole=(0.0, 0.0, 1.0))
    stl = tmp_path / "cap.stl"
    trimesh.Trimesh(cap.vertices_B, cap.faces, process=False).export(stl)
    code = ("import sys, numpy as np\n"
            "from openfdk.io.c3d import MarkerTrial\n"
            "from openfdk.io.markers import MarkerTrajectories\n"
            "from openfdk.contact.mesh import load_mesh\n"
            "import openfdk.model.timefunctions, openfdk.recruitment\n"
            "t = np.arange(200) / 100.0\n"
            "p = np.stack([np.sin(t), np.cos(t), t], axis=1)[:, None, :] * np.ones((1, 2, 1))\n"
            "m = MarkerTrajectories(MarkerTrial(('a', 'b'), 100.0, t, p, 'x.c3d'), cutoff_hz=6.0)\n"
            "assert np.isfinite(m.filtered_positions).all() and np.isfinite(m.positions(0.2)).all()\n"
            f"assert load_mesh({str(stl)!r}, units='mm').n_faces == {cap.n_faces}\n"
            "heavy = ('scipy.signal', 'scipy.stats', 'scipy.interpolate', 'scipy.optimize', 'scipy.sparse', 'trimesh')\n"
            "print(sorted(k for k in sys.modules if k in heavy))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_second_local_cluster_starts_without_the_busy_port_warning():
    """Port 8787 held by another program (another cluster's HTTP endpoint): the local
    cluster takes any free port, so Dask's 'Port 8787 is already in use' never reaches
    the user, and the cluster still runs a task."""
    import socket

    from openfdk.study.cluster import dask_client

    holder = socket.socket()
    try:
        holder.bind(("127.0.0.1", 8787))
        holder.listen()
    except OSError:
        pass  # already held by someone else: the situation this test needs
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            with dask_client(workers=1) as client:
                assert client.submit(sum, [1, 2, 3]).result() == 6
        busy = [w for w in caught if "already in use" in str(w.message)]
        assert busy == []
    finally:
        holder.close()


def test_workers_are_pinned_only_when_each_can_have_a_cpu(monkeypatch):
    from openfdk.study.cluster import PIN_ENVIRONMENT, pinnable_cpus

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {5, 2, 7}, raising=False)
    monkeypatch.delenv(PIN_ENVIRONMENT, raising=False)
    assert pinnable_cpus(3) == [2, 5, 7]     # one worker per CPU: each gets its own
    assert pinnable_cpus(4) is None          # more workers than CPUs: the OS balances them
    assert pinnable_cpus(2) is None          # a CPU to spare: pinned workers could leave it idle
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})
    assert pinnable_cpus(1) is None          # one worker: nothing to keep apart
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    assert pinnable_cpus(2) == [0, 1]
    monkeypatch.setenv(PIN_ENVIRONMENT, "0")
    assert pinnable_cpus(2) is None


def test_core_pinning_pins_every_thread_of_the_worker_process():
    """Run in a child process (pinning is per process): a thread started before and one
    started after setup() end up on the worker's CPU, worker k on cpus[k % len]. (openfdk
    pins on Linux only: /proc and sched_setaffinity.)"""
    code = (
        "import os, threading, types\n"
        "from openfdk.study.pinning import CorePinning\n"
        "cpus = sorted(os.sched_getaffinity(0))\n"
        "stop = threading.Event()\n"
        "before = threading.Thread(target=stop.wait); before.start()\n"
        "CorePinning(cpus).setup(types.SimpleNamespace(name=len(cpus) + 1))\n"
        "seen = {}\n"
        "after = threading.Thread(target=lambda: seen.update(a=os.sched_getaffinity(0))); after.start(); after.join()\n"
        "pinned = {frozenset(os.sched_getaffinity(int(t))) for t in os.listdir('/proc/self/task')}\n"
        "stop.set(); before.join()\n"
        "want = {cpus[(len(cpus) + 1) % len(cpus)]}\n"
        "print(pinned == {frozenset(want)} and seen['a'] == want)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "True"


def test_local_cluster_workers_run_on_cpus_of_their_own(monkeypatch):
    """A 2-worker cluster started from a process allowed 2 CPUs (this one, restricted to
    its first two for the test): every thread of each worker on one CPU, the two workers
    on different CPUs. On a 1-CPU machine pinning must stay off and the cluster still
    runs its task there."""
    from openfdk.study.cluster import PIN_ENVIRONMENT, dask_client, pinnable_cpus

    monkeypatch.delenv(PIN_ENVIRONMENT, raising=False)
    allowed = sorted(os.sched_getaffinity(0))

    def affinities():
        return {frozenset(os.sched_getaffinity(int(t))) for t in os.listdir("/proc/self/task")}

    try:
        os.sched_setaffinity(0, allowed[:2])
        expected = pinnable_cpus(2)
        with dask_client(workers=2) as client:
            per_worker = list(client.run(affinities).values())
            task_thread = client.submit(lambda: frozenset(os.sched_getaffinity(0)), pure=False).result()
    finally:
        os.sched_setaffinity(0, allowed)
    if len(allowed) == 1:
        assert expected is None and task_thread == frozenset(allowed)
        return
    assert expected == allowed[:2]
    assert all(len(a) == 1 for a in per_worker)                        # each worker: one CPU for all threads
    assert set().union(*per_worker) == {frozenset({allowed[0]}), frozenset({allowed[1]})}  # not the same one
    assert {task_thread} in per_worker                                # the analysis thread is on it too
