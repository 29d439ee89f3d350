"""Running the command line in tests: the exit code and output, and the one error line."""

from openfdk.cli import main


def run_cli(capsys, *argv):
    """(exit code, stdout, stderr) of ``openfdk *argv``."""
    code = main([*map(str, argv)])
    out = capsys.readouterr()
    return code, out.out, out.err


def error_line(err):
    """The single ``openfdk: error:`` line of ``err`` (asserts there is exactly one and no
    traceback)."""
    lines = [ln for ln in err.splitlines() if ln.startswith("openfdk: error:")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]
