"""The Python API as a notebook user meets it (issue 29): ``result.fdk`` holds the FDK
solver's columns only, with units in their names; the settings are typed objects at the
top level whose misspelt fields are named with a did-you-mean; the marker cut-off has the
same name on the command line as in the API."""

import dataclasses

import pytest

import openfdk
from openfdk.cli.commands import build_parser
from openfdk.results.run import read_results


def test_result_fdk_columns(mandible_run):
    res = read_results(mandible_run[0])
    fdk = res.fdk
    springs = [c for c in res.forces.columns if c.startswith("fdk_spring")]
    assert springs  # the mandible model's FDK springs are force elements of .forces ...
    assert not [c for c in fdk.columns if c.startswith("fdk_spring")]  # ... not FDK columns
    dofs = res.fdk_dofs()
    assert list(fdk.columns[: 2 * len(dofs)]) == [c for d in dofs for c in (f"fdk.{d}.alpha_m", f"fdk.{d}.residual_N")]
    assert list(fdk.columns[2 * len(dofs):]) == ["fdk_converged", "fdk_iterations", "fdk_evaluations",
                                                  "fdk_jacobians", "fdk_restarts", "fdk_backward", "fdk_reason"]
    d = dofs[0]
    assert (fdk[f"fdk.{d}.alpha_m"].to_numpy() == res.forces[f"fdk.{d}.alpha"].to_numpy()).all()


def test_settings_exported_at_the_top_level():
    from openfdk.fdk.settings import FDKSettings
    from openfdk.forces.elements import RecruitmentSettings
    from openfdk.model.settings import AnalysisSettings

    assert openfdk.RecruitmentSettings is RecruitmentSettings
    assert openfdk.FDKSettings is FDKSettings
    assert openfdk.AnalysisSettings is AnalysisSettings
    assert {"RecruitmentSettings", "FDKSettings", "AnalysisSettings"} <= set(dir(openfdk))


def test_fdk_settings_are_typed_and_typos_are_named():
    s = openfdk.AnalysisSettings(fdk={"jacobian": "central"})
    assert isinstance(s.fdk, openfdk.FDKSettings) and s.fdk.jacobian == "central"
    with pytest.raises(ValueError, match=r"^FDKSettings: unknown key 'tolerence'; did you mean 'tolerance'\?$"):
        openfdk.FDKSettings(tolerence=1e-4)
    with pytest.raises(ValueError, match=r"^FDKSettings: unknown key 'jacobain'; did you mean 'jacobian'\?$"):
        openfdk.AnalysisSettings(fdk={"jacobain": "central"})
    with pytest.raises(ValueError, match=r"^FDKSettings: unknown key 'max_iteration'; did you mean 'max_iterations'"):
        dataclasses.replace(s.fdk, max_iteration=3)
    with pytest.raises(ValueError, match=r"^AnalysisSettings: unknown key 'recruitmnt'; did you mean 'recruitment'"):
        openfdk.AnalysisSettings(recruitmnt=None)
    with pytest.raises(ValueError, match=r"^RecruitmentSettings: unknown key 'powr'; did you mean 'power'\?$"):
        openfdk.RecruitmentSettings(powr=2)
    assert openfdk.RecruitmentSettings(power=2).power == 2
    with pytest.raises(ValueError, match="fdk.jacobian must be 'analytic' or 'central', got 'centre'"):
        openfdk.FDKSettings(jacobian="centre")


def test_fdk_settings_of_a_model(tmp_path, request):
    from openfdk.fdk.settings import fdk_settings

    path = request.config.rootpath / "examples" / "knee" / "knee_springs.yaml"
    model, settings = openfdk.load_model(path), openfdk.load_settings(path)
    assert isinstance(settings.fdk, openfdk.FDKSettings) and settings.fdk.tolerance == 1e-3  # the file's value
    solver = fdk_settings(model, dataclasses.replace(settings, fdk=openfdk.FDKSettings(jacobian="central")))
    assert solver.jacobian == "central" and solver.max_step == (1e-3, 1e-3)  # per-DOF defaults filled in
    with pytest.raises(ValueError, match="did you mean 'line_search'"):
        fdk_settings(model, settings, line_serch=False)


def test_cutoff_spelling_is_the_apis():
    parser = build_parser()
    for option in ("--cutoff-hz", "--cutoff"):
        args = parser.parse_args(["run", "m.yaml", "t.c3d", "--out", "o", option, "4"])
        assert args.cutoff == 4.0
    text = " ".join(parser._subparsers._group_actions[0].choices["run"].format_help().split())
    assert "--cutoff-hz HZ, --cutoff HZ" in text and "cutoff_hz" in text
    with pytest.raises(TypeError, match=r"unknown option\(s\) \['cutof'\]; did you mean 'cutoff_hz'\?"):
        openfdk.run("nowhere.yaml", cutof=3)
