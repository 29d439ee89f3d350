"""A run of an ``.osim`` read with options (``--ignore``, ``--with``, ``--external-loads``
…) records them in summary.json, and the commands that read the run's model again in
another process (``openfdk view``, ``plot``, ``export-opensim``, ``RunResults.model``)
read it with them: the model they draw is the model that ran."""

from __future__ import annotations

import json

import numpy as np
import pytest

from openfdk.cli import main
from openfdk.fixtures.full_body_osim import write_full_body_osim
from test_opensim_inverse_dynamics import N, RATE, _motion, _overlay


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run_options")
    model = write_full_body_osim(folder / "muscles.osim", muscles=True)
    times = np.arange(N) / RATE + 0.2
    overlay = _overlay(folder, _motion(np.random.default_rng(7)), times)
    out = folder / "id"
    assert main(["run", str(model), "--with", str(overlay), "--ignore", "forces", "--out", str(out),
                 "--no-plots", "-q"]) == 0
    return folder, model, overlay, out


def _copy(out, tmp_path):
    """A copy of the run's folder (its summary is then edited)."""
    import shutil

    shutil.copytree(out, tmp_path / "copy")
    return tmp_path / "copy"


def _forget(model):
    """This process forgets the options registered for ``model`` (as a new process)."""
    from openfdk.io.opensim import overlay

    overlay._REGISTERED.pop(overlay._key(model), None)


def test_the_run_records_its_import_options(run):
    folder, model, overlay, out = run
    options = json.loads((out / "summary.json").read_text())["input"]["opensim_import"]["options"]
    assert options == {"ignore": ["forces"], "overlay": str(overlay.resolve())}


def test_view_and_results_read_the_model_as_the_run_did(run):
    from openfdk.results.run import read_results
    from openfdk.viewer import view_data

    folder, model, overlay, out = run
    _forget(model)
    assert read_results(out).model().muscles == ()  # --ignore forces, as in the run
    assert {d.name for d in read_results(out).model().constraints if d.kind == "driver"} >= {"knee_angle_r_motion"}
    _forget(model)
    data, _ = view_data(out)
    assert data["scene"]["paths"] == []  # no muscle drawn that the run did not have


def test_without_the_record_the_osim_is_read_plain(run, tmp_path):
    """A summary from before the record: the .osim is read without options, 92 muscles."""
    from openfdk.results.run import read_results

    folder, model, overlay, out = run
    copy = _copy(out, tmp_path)
    summary = json.loads((copy / "summary.json").read_text())
    del summary["input"]["opensim_import"]["options"]
    (copy / "summary.json").write_text(json.dumps(summary))
    _forget(model)
    assert len(read_results(copy).model().muscles) == 92


def test_a_recorded_file_that_moved_is_named_and_left_out(run, tmp_path):
    """The run's overlay deleted since: the model is read without it, with a warning
    naming it, not refused (the view still shows the run)."""
    from openfdk.results.run import read_results

    folder, model, overlay, out = run
    copy = _copy(out, tmp_path)
    summary = json.loads((copy / "summary.json").read_text())
    summary["input"]["opensim_import"]["options"]["overlay"] = str(tmp_path / "gone.yaml")
    (copy / "summary.json").write_text(json.dumps(summary))
    _forget(model)
    with pytest.warns(UserWarning, match=r"muscles\.osim: the run read it with overlay '.*gone\.yaml', which no longer"):
        loaded = read_results(copy).model()
    assert loaded.muscles == ()  # --ignore forces still applies


def test_the_python_api_takes_the_import_options(run, tmp_path):
    """openfdk.load_model takes the command line's import options as keywords; the run
    gives the command line's numbers, and a saved run is read again with the options."""
    import openfdk
    from openfdk.io.results import read_table
    from openfdk.results.run import read_results

    folder, model, overlay, out = run
    _forget(model)
    fdk_model = openfdk.load_model(str(model), overlay=overlay, ignore="forces")
    assert fdk_model.muscles == ()
    result = openfdk.run(fdk_model)
    cli = read_table(out / "joint_loads.csv")
    np.testing.assert_allclose(result.joint_loads["knee_r_on_tibia_r_in_ground_fy"].to_numpy(),
                               cli["knee_r_on_tibia_r_in_ground_fy"], rtol=1e-8, atol=1e-8)
    assert float(np.max(np.abs(cli["knee_r_on_tibia_r_in_ground_fy"]))) > 50.0  # the leg's weight and motion
    result.save(tmp_path / "saved")
    options = json.loads((tmp_path / "saved" / "summary.json").read_text())["input"]["opensim_import"]["options"]
    assert options == {"ignore": ["forces"], "overlay": str(overlay.resolve())}
    _forget(model)
    assert read_results(tmp_path / "saved").model().muscles == ()  # read again with --ignore forces


@pytest.mark.parametrize("call, message", [
    (lambda openfdk, model: openfdk.load_model(model, overlays="x.yaml"), "unknown option(s) ['overlays']; did you "
                                                                          "mean 'overlay'?"),
    (lambda openfdk, model: openfdk.load_settings(model, motion_cutoff=6), "did you mean 'motion_cutoff_hz'?"),
])
def test_the_python_api_names_an_unknown_option(run, call, message):
    import openfdk

    import re

    with pytest.raises(TypeError, match=re.escape(message)):
        call(openfdk, str(run[1]))


def test_import_options_of_a_model_file_that_is_not_osim(tmp_path):
    import yaml

    import openfdk
    from openfdk.fixtures.synthetic import two_body_model_dict

    path = tmp_path / "model.yaml"
    path.write_text(yaml.safe_dump(two_body_model_dict(), sort_keys=False))
    with pytest.raises(TypeError, match=r"\['motion'\] are options of an OpenSim model \(\.osim\); model\.yaml is not"):
        openfdk.load_model(path, motion="walk.mot")
