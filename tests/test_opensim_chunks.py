"""``openfdk run --chunks`` on OpenSim models: an overlay YAML naming an ``.osim``, and a
bare ``.osim`` whose import options (``--with``, ``--ignore``, …) were given on the
command line, reach every segment's process as the serial run imports them.

The project's full-body ``.osim`` (12 bodies, 23 coordinates) is driven along analytic
coordinate trajectories q(t) = a + b sin(2π f t + φ) by an overlay's drivers, so every
frame's pose is exact and the chunked run must equal the serial one frame by frame."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from openfdk.analysis.jobs import run_job
from openfdk.cli import main
from openfdk.fixtures.full_body_osim import COORDINATES, sine_drivers, sine_trajectories, write_full_body_osim
from openfdk.io.opensim import overlay
from openfdk.io.results import read_table
from openfdk.study.cli import job_case, run_chunked_job

N_FRAMES = 13


def _drivers(rng):
    """Overlay drivers of every coordinate: q = a + b sin(2π f t + φ) as a Fourier series."""
    return sine_drivers(sine_trajectories(rng))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("osim_chunks")
    write_full_body_osim(folder / "full_body.osim")
    data = {"drivers": _drivers(np.random.default_rng(3)),
            "analysis": {"start": 0.1, "end": 0.1 + (N_FRAMES - 1) / 50, "frames": N_FRAMES}}
    (folder / "drivers.yaml").write_text(yaml.safe_dump(data))  # for --with
    (folder / "overlay.yaml").write_text(yaml.safe_dump({"opensim": "full_body.osim", **data}))
    return folder


def test_an_overlay_yaml_runs_in_chunks_as_it_runs_serially(files):
    kin, dyn, info = run_job(files / "overlay.yaml", None, progress=False)
    kc, dc, ic = run_chunked_job(files / "overlay.yaml", None, 3, workers=0, progress=False, overlap=1)
    keeps = [s["keep"] for s in ic["segments"]]
    assert ic["chunks"] == 3 and len(keeps) == 3 and keeps[0][0] == 0 and keeps[-1][1] == N_FRAMES
    assert all(a[1] == b[0] for a, b in zip(keeps, keeps[1:]))  # every frame solved in exactly one chunk
    np.testing.assert_array_equal(kc.time, kin.time)
    assert len(kin.time) == N_FRAMES
    np.testing.assert_allclose(kc.q, kin.q, atol=1e-9)
    # the generalised forces carry the drivers' reactions: large, and the same in both runs
    assert np.max(np.abs(dyn.forces)) > 10.0
    np.testing.assert_allclose(dc.forces, dyn.forces, atol=1e-6 * np.max(np.abs(dyn.forces)))


def test_an_osim_s_command_line_options_travel_with_the_case(files):
    """What ``--with`` registered in the command's process is what a worker process (here:
    this one with its registry emptied) imports."""
    from openfdk.study.kinds import prepare_model_case

    model = files / "full_body.osim"
    overlay.register(model, overlay=files / "drivers.yaml")
    try:
        case = job_case(model, None, 2)
        assert case.import_options is not None and case.import_options.overlay == files / "drivers.yaml"
        overlay._REGISTERED.clear()  # a fresh worker process knows nothing of the command line
        prepared = prepare_model_case(case)
        assert set(prepared.model_data) >= {"drivers", "analysis"}
        assert set(prepared.model_data["drivers"]) == {f"{n}_motion" for n in COORDINATES}
    finally:
        overlay._REGISTERED.clear()
    # without the options the .osim imports bare: no drivers
    bare = prepare_model_case(job_case(model, None, 2))
    assert "drivers" not in bare.model_data


def test_run_chunks_of_an_osim_with_an_overlay_on_the_command_line(files, tmp_path, capsys):
    serial, chunked = tmp_path / "serial", tmp_path / "chunked"
    common = [str(files / "full_body.osim"), "--with", str(files / "drivers.yaml"), "--no-plots", "-q"]
    assert main(["run", *common, "--out", str(serial)]) == 0, capsys.readouterr().err
    assert main(["run", *common, "--out", str(chunked), "--chunks", "2"]) == 0, capsys.readouterr().err
    a, b = read_table(serial / "generalized_forces.csv"), read_table(chunked / "generalized_forces.csv")
    assert set(a) == set(b) and len(a["time"]) == N_FRAMES
    scale = max(np.max(np.abs(v)) for v in a.values())
    for key in a:
        np.testing.assert_allclose(b[key], a[key], atol=1e-6 * scale, err_msg=key)


def test_a_chunked_run_records_its_measured_loads_as_the_serial_one(files, tmp_path):
    """A run in chunks records the measured loads as applied (forces.csv's
    ``<load>.external_F?_N``) and their bodies and the gravity (summary.json's input),
    as the serial run does: ``openfdk cycles`` reads them (DM's tm_med1 in two chunks
    had lost them until stop 75)."""
    from openfdk.io.storage import write_storage
    from test_load_filter import LOADS_XML  # one ground reaction on calcn_r

    t = np.linspace(0.0, 1.0, 201)
    cols = {"g_vx": 10 + 0 * t, "g_vy": 300 + 100 * t, "g_vz": 0 * t, "g_px": 0 * t, "g_py": 0 * t, "g_pz": 0 * t,
            "g_tx": 0 * t, "g_ty": 0 * t, "g_tz": 0 * t}
    write_storage(tmp_path / "grf.mot", t, cols, name="grf")
    (tmp_path / "loads.xml").write_text(LOADS_XML)
    data = yaml.safe_load((files / "overlay.yaml").read_text())
    data["opensim"] = str(files / "full_body.osim")
    data["external_loads"] = "loads.xml"
    (tmp_path / "loaded.yaml").write_text(yaml.safe_dump(data))
    kin, dyn, info = run_job(tmp_path / "loaded.yaml", None, progress=False)
    kc, dc, ic = run_chunked_job(tmp_path / "loaded.yaml", None, 2, workers=0, progress=False, overlap=1)
    for record in (info, ic):
        assert record["external_loads"] == {"grf_r": {"body": "calcn_r"}}
        np.testing.assert_allclose(record["gravity_W_m_s2"], [0.0, -9.80665, 0.0], rtol=0, atol=1e-12)
    for res in (dyn, dc):
        columns = res.extra["columns"]
        np.testing.assert_allclose(columns["grf_r.external_Fy_N"], 300 + 100 * kin.time, rtol=1e-9)
        np.testing.assert_allclose(columns["grf_r.external_Fx_N"], 10.0, rtol=1e-9)
