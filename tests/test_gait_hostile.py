"""Hostile inputs of the gait readers: OpenSim ExternalLoads files, their data files
and coordinate (--motion) files. Each ends in exit code 2 with one line naming the file
and the entry; none is accepted silently."""

from __future__ import annotations

import os

import pytest

from openfdk.cli import main
from openfdk.fixtures.full_body_osim import write_full_body_osim

GRF = "grf\nversion=1\nnRows=3\nnColumns=4\ninDegrees=no\nendheader\ntime\tf_vx\tf_vy\tf_vz\n0\t1\t2\t3\n0.5\t1\t2\t3\n1\t1\t2\t3\n"
LOADS = ("<OpenSimDocument Version=\"40000\"><ExternalLoads><objects><ExternalForce name=\"a\">"
         "<applied_to_body>tibia_r</applied_to_body><force_expressed_in_body>ground</force_expressed_in_body>"
         "<point_expressed_in_body>tibia_r</point_expressed_in_body><force_identifier>f_v</force_identifier>"
         "</ExternalForce></objects><datafile>grf.mot</datafile></ExternalLoads></OpenSimDocument>")


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return write_full_body_osim(tmp_path_factory.mktemp("m") / "full_body.osim")


CASES = {
    "unknown body": (LOADS.replace(">tibia_r</applied", ">hand_r</applied"), GRF, "hand_r"),
    "point in another body": (LOADS.replace("<point_expressed_in_body>tibia_r", "<point_expressed_in_body>femur_r"),
                              GRF, "femur_r"),
    "unknown column": (LOADS.replace(">f_v<", ">g_v<"), GRF, "g_vx"),
    "missing data file": (LOADS.replace("grf.mot", "nothere.mot"), GRF, "nothere.mot"),
    "no datafile": (LOADS.replace("<datafile>grf.mot</datafile>", ""), GRF, "no data file"),
    "NaN force": (LOADS, GRF.replace("0.5\t1\t2", "0.5\tnan\t2"), "non-finite"),
    "one sample": (LOADS, "grf\nendheader\ntime\tf_vx\tf_vy\tf_vz\n0\t1\t2\t3\n", "fewer than 2 samples"),
    "DOCTYPE": ("<!DOCTYPE x [<!ENTITY a \"b\">]>" + LOADS, GRF, "DOCTYPE"),
    "not ExternalLoads": ("<OpenSimDocument Version=\"40000\"><Model/></OpenSimDocument>", GRF, "ExternalLoads"),
    "two forces, one name": (LOADS.replace("</objects>", LOADS.split("<objects>")[1].split("</objects>")[0]
                                           + "</objects>"), GRF, "second external force"),
    "times not increasing": (LOADS, GRF.replace("0.5\t1", "0\t1"), "increasing"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_bad_external_loads_end_in_one_line(model, tmp_path, capsys, case):
    xml, mot, words = CASES[case]
    (tmp_path / "loads.xml").write_text(xml)
    (tmp_path / "grf.mot").write_text(mot)
    code = main(["check", str(model), "--ignore", "Mesh", "--external-loads", str(tmp_path / "loads.xml"), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0], err
    assert "Traceback" not in err[0]


@pytest.mark.parametrize("text, words", [
    ("m\nendheader\ntime\tpelvis_tilt\n0\t1\n1\t2\n", "no column for the coordinates"),
    ("m\nendheader\ntime\tfoo\n0\t1\n", "no column"),
    ("not a storage file\n", "endheader"),
])
def test_bad_motion_files_end_in_one_line(model, tmp_path, capsys, text, words):
    (tmp_path / "m.mot").write_text(text)
    code = main(["check", str(model), "--motion", str(tmp_path / "m.mot"), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0], err


def test_a_fifo_is_refused_without_blocking(model, tmp_path, capsys):
    fifo = tmp_path / "loads.xml"
    os.mkfifo(fifo)
    code = main(["check", str(model), "--external-loads", str(fifo), "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "regular file" in err[0], err


def test_a_whole_trial_leaves_out_the_samples_before_and_after_the_load_data():
    """A force-plate file that starts one plate sample after the markers (the Grand
    Challenge's: markers from 0.75 s, loads from 0.750833 s): with no start or end given,
    the trial's samples outside the loads' data are left out with one warning, instead of
    the run stopping at its first frame with the loads' spline's message; the same with a
    start or end the user gives outside the data, which the warning names."""
    import warnings
    from types import SimpleNamespace

    import numpy as np

    from openfdk.analysis.jobs import _within_load_data
    from openfdk.forces.data_loads import DataLoad
    from openfdk.model.plausibility import PlausibilityWarning
    from openfdk.model.timefunctions import Constant, SplineThroughData

    t_data = np.linspace(0.750833, 3.924167, 50)
    load = DataLoad("plate", 1, SplineThroughData(t_data, np.ones((50, 3))), Constant([0.0, 0.0, 0.0]),
                    Constant([0.0, 0.0, 0.0]))
    model = SimpleNamespace(external_loads=(load,))
    times = 0.75 + np.arange(382) / 120.0  # 0.75 … 3.925 s
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        kept = _within_load_data(model, times)
    assert kept[0] == pytest.approx(0.75 + 1 / 120) and kept[-1] <= 3.924167 < kept[-1] + 1 / 120
    assert len(kept) == len(times) - 2
    (w,) = [c for c in caught if issubclass(c.category, PlausibilityWarning)]
    assert "2 trial sample(s) outside the measured loads' data" in str(w.message)
    # a window the user gives that reaches outside the data: the same samples are left
    # out, and the warning names the end the user gave (the run cannot evaluate the loads there)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        given = _within_load_data(model, times, start=0.75, end=3.925)
    np.testing.assert_array_equal(given, kept)
    (w,) = [c for c in caught if issubclass(c.category, PlausibilityWarning)]
    assert ("outside the measured loads' data (0.750833–3.92417 s), where the window's start (0.75 s) and the "
            "window's end (3.925 s) lie, are left out") in str(w.message), w.message
    inside = times[(times > 1.0) & (times < 2.0)]
    np.testing.assert_array_equal(_within_load_data(model, inside, start=1.0, end=2.0), inside)
