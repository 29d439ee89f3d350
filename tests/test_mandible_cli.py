"""`openfdk subject` on the command line (issue 28): one help per subcommand, and a
study report that names only the files it wrote."""

import pytest

from openfdk.cli import main
from openfdk.mandible.demo import report


def _help(capsys, *argv):
    with pytest.raises(SystemExit) as info:
        main([*argv, "--help"])
    assert info.value.code == 0
    return capsys.readouterr().out


def test_subject_help_is_per_subcommand(capsys):
    """`openfdk subject --help` lists the three actions and none of their options; each
    action's help lists its own options only."""
    top = _help(capsys, "subject")
    assert all(a in top for a in ("create", "record", "study"))
    assert not any(o in top for o in ("--resolution", "--noise", "--no-parameter-study", "--workers"))
    own = {"create": ("--resolution", "--asymmetric", "--seed"),
           "record": ("--realistic", "--noise", "--cycles", "--quick", "--seed"),
           "study": ("--out", "--force", "--workers", "--scheduler", "--no-parameter-study", "--cycles", "--quick")}
    for action, options in own.items():
        text = _help(capsys, "subject", action)
        assert all(o in text for o in options), action
        others = {o for a, opts in own.items() if a != action for o in opts} - set(options)
        assert not any(o in text for o in others), (action, [o for o in others if o in text])


def test_subject_without_an_action_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as info:
        main(["subject"])
    assert info.value.code == 2


def _result(parameter_study):
    runs = {"open_close": {}} | ({"parameter_study": {"cases": 2}} if parameter_study else {})
    row = {"task": "open_close", "side": "left", "direction": "AP", "n_cycles": 2, "reference": "FDK", "unit": "N"}
    for name in ("RMSD", "r2", "M", "P"):
        row[f"POP_{name}_mean"], row[f"POP_{name}_sd"] = 1.0, 0.1
    t1 = dict(row, reference="measured", unit="mm")
    for name in ("RMSD", "r2", "M", "P"):
        t1[f"FDK_{name}_mean"], t1[f"FDK_{name}_sd"] = 1.0, 0.1
    return {"summary": {"runs": runs, "task_kinds": {"open_close": "open_close"}}, "table1": [t1],
            "table2": [row], "figures": []}


def test_report_names_the_parameter_study_only_when_it_ran(tmp_path):
    """--no-parameter-study (no parameter_study run in the summary): no line naming
    parameter_study/summary.csv; with it: the line. Table 2 is printed beside the
    paper's either way."""
    for ran in (False, True):
        lines = []
        report(_result(ran), tmp_path, lines.append)
        text = "\n".join(lines)
        assert ("parameter_study/summary.csv" in text) == ran
        assert "paper (Andersen et al. 2017)" in text and "RMSD range: openfdk 1.00–1.00 N" in text
