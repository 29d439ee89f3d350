"""Benchmark: peak memory of ``openfdk run`` on a long FDK trial of the mandible model.

A virtual subject is generated and an open–close trial of 48 cycles (0.8 Hz, ≈ 61 s at
100 Hz) is recorded; ``openfdk run`` then analyses its first 60 s (6 001 frames, FDK
model: two condyle–fossa contacts, 3 FDK DOFs, 6 ligaments, 24 Hill muscles) in a child
process, whose peak resident set size is read from the kernel (``os.wait4``'s
``ru_maxrss``) — ``run_60s_trial_peak_rss_mb``, in MB (10⁶ bytes). The child's wall
time is reported as ``run_60s_trial_wall_s``. ``--quick``: 8 cycles, the first 10 s
(``run_10s_trial_*``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def peak_rss_of(command, env=None):
    """Run ``command`` (list) to completion; returns (exit status, peak RSS MB, wall s,
    stderr tail). The peak is the child's own ``ru_maxrss`` (KiB on Linux)."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    # read stderr before waiting so that a chatty child cannot block on a full pipe
    err = proc.stderr.read().decode(errors="replace")
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, usage.ru_maxrss * 1024 / 1e6, time.perf_counter() - t0, err[-2000:]


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
        command = [sys.executable, "-m", "openfdk.cli", "run", str(paths["fdk"]), str(trial),
                   "--out", str(d / "out"), "--no-progress", "--start", "0", "--end", str(float(seconds))]
        code, rss, wall, err = peak_rss_of(command)
        if code != 0:
            raise RuntimeError(f"openfdk run failed (exit {code}): {err}")
    tag = f"run_{seconds}s_trial"
    return [{"name": f"{tag}_peak_rss_mb", "value": rss, "unit": "MB"},
            {"name": f"{tag}_wall_s", "value": wall, "unit": "s"}]
