"""Benchmark: peak memory of ``openfdk run`` on a long FDK trial of the mandible model.

A virtual subject is generated and an open–close trial of 48 cycles (0.8 Hz, ≈ 61 s at
100 Hz) is recorded; ``openfdk run`` then analyses its first 60 s (6 001 frames, FDK
model: two condyle–fossa contacts, 3 FDK DOFs, 6 ligaments, 24 Hill muscles) in a child
process, which reports its own peak resident set size (VmHWM of /proc/self/status) —
``run_60s_trial_peak_rss_mb``, in MB (10⁶ bytes). The child's wall
time is reported as ``run_60s_trial_wall_s``. ``--quick``: 8 cycles, the first 10 s
(``run_10s_trial_*``).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path


# Runs ``openfdk.cli.main(argv)`` and writes the process's own peak resident set size
# (VmHWM of /proc/self/status, kB) to the file named by the first argument. The rusage
# of a child (``ru_maxrss``) would not do: Linux carries the high-water mark of the
# forked copy of the parent across exec, so a child of a large parent reports the
# parent's size.
_WRAPPER = """
import sys
from openfdk.cli import main
code = 1
try:
    code = main(sys.argv[2:])
finally:
    with open('/proc/self/status') as status:
        peak = [line.split()[1] for line in status if line.startswith('VmHWM')][0]
    with open(sys.argv[1], 'w') as out:
        out.write(peak)
sys.exit(code)
"""


def peak_rss_of(cli_args, workdir):
    """Run ``openfdk <cli_args>`` in a child process; returns (exit status, its own peak
    RSS in MB (10⁶ bytes), wall s, stderr tail). workdir: a folder for the report file."""
    report = Path(workdir) / "peak_rss_kb.txt"
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", _WRAPPER, str(report), *cli_args],
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    err = proc.stderr.decode(errors="replace")[-2000:]
    if not report.exists():
        return proc.returncode, float("nan"), wall, err
    return proc.returncode, int(report.read_text()) * 1024 / 1e6, wall, err


def run(quick=False):
    from ..mandible.experiment import record_experiment
    from ..mandible.generator import create_subject
    from ..mandible.models import write_models
    from ..mandible.registration import register_braces
    from ..mandible.subject import load_subject

    seconds = 10 if quick else 60
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        create_subject(d / "subject", resolution="default")
        record_experiment(d / "subject", tasks=("open_close",), cycles=8 if quick else 48)
        subject = load_subject(d / "subject")
        reg = register_braces(subject, d / "subject" / "trials" / "reference.c3d")
        paths = write_models(subject, reg, d / "models")
        trial = d / "subject" / "trials" / "open_close.c3d"
        command = ["run", str(paths["fdk"]), str(trial), "--out", str(d / "out"), "--no-progress",
                   "--start", "0", "--end", str(float(seconds))]
        code, rss, wall, err = peak_rss_of(command, d)
        if code != 0:
            raise RuntimeError(f"openfdk run failed (exit {code}): {err}")
    tag = f"run_{seconds}s_trial"
    return [{"name": f"{tag}_peak_rss_mb", "value": rss, "unit": "MB"},
            {"name": f"{tag}_wall_s", "value": wall, "unit": "s"}]
