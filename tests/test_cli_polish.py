"""The command line as a new user meets it (issue 29): --quiet everywhere, a description
in every --help, pluralised progress lines, and ``run`` refusing a model with redundant
rows as ``check`` does."""

import io
import re
from pathlib import Path

import pytest

from openfdk.trial import progress
from openfdk.cli.commands import build_parser, main

ROOT = Path(__file__).resolve().parents[1]


def _subparsers(parser):
    """(name, parser) of every subcommand, nested ones (``subject create``) included."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield name, sub
                for inner, subsub in _subparsers(sub):
                    yield f"{name} {inner}", subsub


def test_every_subcommand_has_a_description_and_quiet():
    names = []
    for name, sub in _subparsers(build_parser()):
        names.append(name)
        assert sub.description and len(sub.description) > 30, f"openfdk {name} --help has no description"
        options = {o for a in sub._actions for o in a.option_strings}
        if name != "subject":  # the group: its actions take -q
            assert {"-q", "--quiet"} <= options, f"openfdk {name} has no -q/--quiet"
    for name in ("run", "kinematics", "demo", "bench", "check", "plot", "view", "export-opensim", "cache",
                 "subject create", "subject record", "subject study", "study", "import-opensim"):
        assert name in names


def test_run_help_prints_its_description(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "--help"])
    assert exc.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "inverse dynamics with muscle recruitment (Eqs. 11-14)" in out
    assert "checked first as by `openfdk check`" in out


def test_readme_documents_the_cache_command():
    readme = (ROOT / "README.md").read_text()
    assert "openfdk cache info" in readme and "openfdk cache clear" in readme


@pytest.fixture(scope="module")
def slider_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("slider") / "run"
    assert main(["run", str(ROOT / "examples/slider_crank.yaml"), "--out", str(out), "-q"]) == 0
    return out


@pytest.mark.parametrize("command", [
    ["plot", "{run}", "--out", "{tmp}/plots", "-q"],
    ["export-opensim", "{run}", "--out", "{tmp}/osim", "-q"],
    ["view", "{run}", "--out", "{tmp}/view.html", "--quiet"],
])
def test_quiet_output_commands_print_nothing(slider_run, tmp_path, capsys, command):
    capsys.readouterr()
    args = [a.format(run=slider_run, tmp=tmp_path) for a in command]
    assert main(args) == 0
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
    assert any(tmp_path.iterdir())  # the files are still written
    # and without -q the command says what it wrote
    assert main([a for a in args if a not in ("-q", "--quiet")]) == 0
    assert len(capsys.readouterr().out.splitlines()) == 1


def test_quiet_run_prints_nothing(tmp_path, capsys):
    assert main(["run", str(ROOT / "examples/slider_crank.yaml"), "--out", str(tmp_path / "r"), "-q"]) == 0
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""


def test_quiet_subject_create_prints_nothing(tmp_path, capsys):
    assert main(["subject", "create", str(tmp_path / "sc"), "--resolution", "coarse", "-q"]) == 0
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""
    assert (tmp_path / "sc" / "subject.yaml").is_file()
    assert main(["subject", "create", str(tmp_path / "sc2"), "--resolution", "coarse"]) == 0
    assert capsys.readouterr().out.startswith("virtual subject written to ")


def test_quiet_log_keeps_warnings_and_failures_on_stderr(capsys):
    from argparse import Namespace

    from openfdk.cli.commands import _log

    log = _log(Namespace(quiet=True))
    log("running the mandible study -> out/")
    log("  chewing: POP and FDK ...")
    log("  warning: chewing: 2 of 5 cycles found")
    log("  chewing failed: no markers")
    out = capsys.readouterr()
    assert out.out == ""
    assert out.err.splitlines() == ["openfdk: warning: chewing: 2 of 5 cycles found",
                                    "openfdk: chewing failed: no markers"]
    assert _log(Namespace(quiet=False)) is print


def test_progress_lines_pluralise_the_unit():
    out = io.StringIO()
    bar = progress.progress(51, "FDK", "frame", stream=out)
    bar.update(6)
    bar.update(45)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("FDK: 10% (6/51 frames, ")
    assert lines[-1].startswith("FDK: 100% (51/51 frames, ")
    out = io.StringIO()
    progress.progress(1, "chunks", "chunk", stream=out).update(1)
    assert out.getvalue().startswith("chunks: 100% (1/1 chunk, ")
    assert [progress.plural(u, 2) for u in ("frame", "case", "chunk", "body", "frames")] == \
        ["frames", "cases", "chunks", "bodies", "frames"]


def test_pop_stage_is_labelled(tmp_path, capsys):
    """A model without FDK DOFs: kinematics and inverse dynamics in one loop, labelled so."""
    assert main(["run", str(ROOT / "examples/slider_crank.yaml"), "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "%" in line]
    assert lines and all(line.startswith("kinematics + inverse dynamics: ") for line in lines)
    assert re.search(r"\(\d+/\d+ frames, ", lines[-1])
    assert not any(line.startswith("frames:") for line in err.splitlines())


def _redundant_knee(tmp_path):
    """The knee of the springs tutorial with its translations held twice: a revolute joint
    *and* FDK DOFs on the joint's x and y."""
    text = (ROOT / "examples/knee/knee_springs.yaml").read_text()
    text = text.replace("child: shank.knee, fdk: [x, y]}", "child: shank.knee}")
    text = text.replace("\nfdk:\n", "\nfdk_dofs:\n  knee_x: {measure: knee.position, component: 0}\n"
                                    "  knee_y: {measure: knee.position, component: 1}\n\nfdk:\n")
    assert "fdk_dofs:" in text and "shank.knee, fdk" not in text
    path = tmp_path / "knee_redundant.yaml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("command", [["run"], ["kinematics"], ["run", "--chunks", "2", "--workers", "0"]])
def test_run_refuses_redundant_rows_like_check(tmp_path, capsys, command):
    model = _redundant_knee(tmp_path)
    assert main(["check", str(model)]) == 2
    check_err = capsys.readouterr().err.strip().splitlines()
    out = tmp_path / "out"
    assert main([*command[:1], str(model), "--out", str(out), *command[1:]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"openfdk: error: {model}: constraint Jacobian is singular at the reference pose "
                             "(rank 12 of 14 rows): redundant or inconsistent rows ")
    for row in ("knee.x", "knee.y", "fdk.knee_x", "fdk.knee_y"):
        assert repr(row) in err[0]
    assert err[0].split("rows [")[1].split("]")[0] == check_err[0].split("rows [")[1].split("]")[0]
    assert not (out / "kinematics.csv").exists()


def test_api_run_refuses_redundant_rows(tmp_path):
    import openfdk
    from openfdk.model.model import ModelError

    model = _redundant_knee(tmp_path)
    with pytest.raises(ModelError, match=r"^knee-springs: constraint Jacobian is singular .* redundant or inconsistent rows"):
        openfdk.run(str(model))


def test_a_non_square_system_fails_its_frames_instead_of_corrupting_memory(tmp_path, monkeypatch):
    """Past the rank refusal (monkeypatched away), the redundant knee's determinate
    system has 14 rows for 12 coordinates: the square-system kernels are never entered
    (they do no bounds checks: this model crashed the process with a corrupted heap);
    every frame fails with its reason."""
    import openfdk.analysis.jobs as jobs

    monkeypatch.setattr(jobs, "_refuse_redundant_rows", lambda model, label: None)
    kin, _, _ = jobs.run_job(_redundant_knee(tmp_path), progress=False)
    assert not kin.converged.any()
    assert all("14 constraint rows for 12 coordinates" in m for m in kin.messages)


@pytest.mark.parametrize("command", [["run"], ["kinematics"], ["run", "--chunks", "2", "--workers", "0"]])
def test_a_command_reads_its_model_once(tmp_path, monkeypatch, command):
    """The model file is read once per command, for the analysis and its outputs: a model's
    load-time warnings (DM's raw force-plate samples) were printed twice by `openfdk
    kinematics` and by `openfdk run --chunks`, which read the file again to write their
    measures."""
    import openfdk.analysis.jobs as jobs
    import openfdk.io.modelfile as modelfile

    reads = []
    real = modelfile.load_model_and_settings

    def counted(path):
        reads.append(str(path))
        return real(path)

    monkeypatch.setattr(modelfile, "load_model_and_settings", counted)
    monkeypatch.setattr(jobs, "load_model_and_settings", counted)
    model = ROOT / "examples/knee/knee_springs.yaml"
    window = ["--out", str(tmp_path / "out"), "--no-progress", "--end", "0.1"]  # 6 of its 51 frames
    assert main([command[0], str(model), *window, *(["--no-plots"] if command[0] == "run" else []),
                 *command[1:]]) == 0
    assert reads == [str(model)]


def test_result_commands_do_not_repeat_the_runs_input_warnings(tmp_path, capsys):
    """`openfdk plot`, `view` and `export-opensim` read the model file again only to draw
    or export a finished run: its load-time warnings (here the length unit that looks
    wrong; on DM the raw force-plate samples) were given by the run and are not printed
    again. The run itself still gives them, and a model that cannot be read is still an
    error."""
    text = (ROOT / "examples/slider_crank.yaml").read_text()
    assert "units: {length: mm, angle: deg}" in text
    model = tmp_path / "metres.yaml"  # the slider-crank's mm read as m: a 400 m model
    model.write_text(text.replace("units: {length: mm, angle: deg}", "units: {length: m, angle: deg}"))
    run = tmp_path / "run"
    assert main(["run", str(model), "--out", str(run), "--no-progress", "--no-plots", "--end", "0.1"]) == 0
    err = capsys.readouterr().err
    assert err.count("the numbers look like mm") == 1  # the run warns, once
    for command in (["plot", str(run), "--out", str(tmp_path / "plots")],
                    ["view", str(run), "--out", str(tmp_path / "view.html")],
                    ["export-opensim", str(run), "--out", str(tmp_path / "osim")],
                    ["plot", str(run), "--out", str(tmp_path / "plots2"), "--model", str(model)]):
        assert main(command) == 0
        out = capsys.readouterr()
        assert "warning" not in out.err, (command, out.err)
        assert out.out.startswith(command[0] + ":")  # and it says what it wrote
    model.write_text(text.replace("bodies:", "bodies: 3\nnot_bodies:"))  # now unreadable
    assert main(["plot", str(run), "--out", str(tmp_path / "plots3")]) != 0
    assert "metres.yaml" in capsys.readouterr().err
