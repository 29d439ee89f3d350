"""Mistakes a new user made writing the shoulder example (examples/shoulder/), each with
the exact one-line warning that now names the file, the entry and the likely cause."""

import re
from pathlib import Path

import pytest

from openfdk.cli import main

SHOULDER = Path(__file__).resolve().parents[1] / "examples" / "shoulder"
BASE = (SHOULDER / "shoulder.yaml").read_text()


@pytest.fixture
def folder(tmp_path):
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_shoulder", SHOULDER / "make_shoulder.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(tmp_path)
    return tmp_path, mod


def _check(capsys, path):
    code = main(["check", str(path)])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, [ln for ln in err.splitlines() if ln.startswith("openfdk: warning:")]


def test_degrees_in_a_radians_file(folder, capsys):
    tmp, _ = folder
    text = BASE.replace("units: {length: mm, angle: deg}", "units: {length: mm}")
    text = text.replace("    position: [0, -420, 180]\n", "    position: [0, -420, 180]\n    orientation: [0, 0, 30]\n")
    (tmp / "model.yaml").write_text(text)
    code, warnings = _check(capsys, tmp / "model.yaml")
    assert code == 0
    assert warnings[0] == ("openfdk: warning: model.yaml: bodies.forearm.orientation: 30 rad is more than a full "
                           "turn; the file's angles are in rad (the default): are these degrees? "
                           "(set units: {angle: deg})")
    # 6.2 rad (< 2 pi) is a legal angle in rad: no warning
    (tmp / "ok.yaml").write_text(text.replace("orientation: [0, 0, 30]", "orientation: [0, 0, 6.2]"))
    assert not [w for w in _check(capsys, tmp / "ok.yaml")[1] if "full turn" in w]


def test_muscle_lengths_in_metres_in_a_mm_file(folder, capsys):
    tmp, _ = folder
    text = BASE.replace("optimal_fibre_length: 70, tendon_slack_length: 40",
                        "optimal_fibre_length: 0.07, tendon_slack_length: 0.04")
    (tmp / "model.yaml").write_text(text)
    code, warnings = _check(capsys, tmp / "model.yaml")
    assert code == 0 and len(warnings) == 1
    # supraspinatus: thorax (-30, 40, 90) mm to the greater tubercle (0, 20, 200) mm
    length = ((0 + 30) ** 2 + (20 - 40) ** 2 + (200 - 90) ** 2) ** 0.5
    assert f"(path length {length:.1f} mm); optimal_fibre_length + tendon_slack_length = 0.11 mm as written: " \
           "muscle lengths are in the file's length unit (mm), not in m" in warnings[0]
    assert warnings[0].startswith("openfdk: warning: model.yaml: muscles.supraspinatus: passive force ")


def test_fdk_dofs_held_by_nothing(folder, capsys):
    tmp, _ = folder
    text = re.sub(r"^(ligaments|springs|contacts):.*?\n\n", "", BASE, flags=re.S | re.M)
    (tmp / "model.yaml").write_text(text)
    code, warnings = _check(capsys, tmp / "model.yaml")
    assert code == 0
    assert warnings == ["openfdk: warning: model.yaml: fdk_dofs: no spring, bushing, ligament or contact in the "
                        "model holds the FDK DOFs ['gh_x', 'gh_y', 'gh_z']: their residual has no restoring "
                        "force and FDK will not converge; add springs (the paper uses 0.1 N/m), ligaments or "
                        "contact"]
    (tmp / "held.yaml").write_text(BASE)                    # the example itself is not warned
    assert _check(capsys, tmp / "held.yaml")[1] == []


def test_trc_in_metres_declared_mm_names_the_trc_field(folder, capsys):
    tmp, mod = folder
    t, labels, x = mod.trial(duration=0.1)
    mod.write_trc(tmp / "metres.trc", t, labels, x / 1000.0, 100.0)     # numbers in m, header says mm
    (tmp / "model.yaml").write_text(BASE)
    code = main(["kinematics", str(tmp / "model.yaml"), str(tmp / "metres.trc"), "--out", str(tmp / "o"), "-q"])
    err = capsys.readouterr().err
    assert code == 3 and "Traceback" not in err
    unit = [ln for ln in err.splitlines() if "likely the wrong units" in ln]
    assert len(unit) == 1 and unit[0].endswith("(a factor 0.001; check Units on line 3)")
