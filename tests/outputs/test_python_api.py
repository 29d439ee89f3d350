"""docs/python-api.md runs: every ```python block, in order, in one namespace, in an
empty folder (a ```python viewer block only when the 3D viewer package is present).
Then the namespace it leaves is checked against the result files."""

import importlib.util
import re
import sys

import numpy as np
import pytest

BLOCK = re.compile(r"^```python( viewer)?\n(.*?)^```", re.S | re.M)


def doc_blocks(path):
    return [(bool(m.group(1)), m.group(2)) for m in BLOCK.finditer(path.read_text())]


def test_import_openfdk_is_light():
    import subprocess

    code = "import sys, openfdk; assert callable(openfdk.run); print(sorted(m for m in ('numpy', 'pandas', " \
           "'matplotlib', 'scipy') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_python_api_docs_session_runs(request, tmp_path, monkeypatch, capsys):
    blocks = doc_blocks(request.config.rootpath / "docs" / "python-api.md")
    assert len(blocks) >= 8
    has_viewer = importlib.util.find_spec("openfdk.viewer") is not None
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "python_api_doc"}
    ran = 0
    for is_viewer, code in blocks:
        if is_viewer and not has_viewer:
            continue
        exec(compile(code, f"docs/python-api.md block {ran}", "exec"), namespace)
        ran += 1
    printed = capsys.readouterr().out
    assert "RunResults('synthetic FDK jaw': 8 frames, 0 failed" in printed
    result = namespace["result"]
    # the tables equal the files the command line wrote for the same inputs
    import pandas as pd

    cli = pd.read_csv(tmp_path / "jaw-cli" / "forces.csv", index_col="time")
    for col in ("fdk.tmj_r_normal.alpha", "tmj_l.Fz_N", "superficial_masseter_r.force_N"):
        np.testing.assert_allclose(result.forces[col].to_numpy(), cli[col].to_numpy(), rtol=1e-8, atol=1e-12)
    assert set(result.fdk_dofs()) == {"ml_shift", "tmj_l_normal", "tmj_r_normal"}
    assert (tmp_path / "jaw-run" / "kinematics.sto").is_file()
    assert sorted(namespace["figures"]) == ["contact", "convergence", "fdk_dofs", "kinematics", "ligaments",
                                            "measures", "muscles"]
    # the model file was recorded, so the saved run finds its model again (units of α)
    assert namespace["again"].model_path() == tmp_path / "jaw.yaml"
    assert len(list((tmp_path / "jaw-opensim").glob("*.osim"))) == 1
    if has_viewer:
        assert (tmp_path / "jaw-run" / "view.html").is_file()


def test_run_rejects_unknown_options():
    import openfdk

    with pytest.raises(TypeError, match="cutof"):
        openfdk.run("nowhere.yaml", cutof=3)


def test_view_without_the_viewer_package_says_so(monkeypatch):
    from openfdk.api.result import Result

    monkeypatch.setitem(sys.modules, "openfdk.viewer", None)  # as if not installed
    with pytest.raises(ImportError, match="openfdk.viewer"):
        Result(None, None, {}).view("x.html")
