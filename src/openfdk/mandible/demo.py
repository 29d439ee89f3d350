"""``openfdk demo``: the mandible study on the virtual subject, end to end.

Creates the virtual subject and its recordings in ``OUT/subject`` if they are absent,
runs the study (POP and FDK on chewing, protrusion and half open–close, five cycles
each, Tables 1–2, Figures 5–7, the 15-model ligament parameter study), prints the
tables and says where the figures are. ``quick``: coarse meshes, two cycles, a 2-model
parameter study — still end to end (used by the test suite).
"""

from __future__ import annotations

import time as _time
from pathlib import Path


def run_demo(out="openfdk-demo", quick=False, progress=True, log=print, workers=None, scheduler=None):
    """Subject, recordings and study in ``out`` (see the module docstring); ``workers`` /
    ``scheduler``: where the parameter study runs (:func:`.study.run_study`). Returns the
    study's result dict."""
    from .experiment import record_experiment
    from .generator import create_subject
    from .study import run_study

    t0 = _time.perf_counter()
    out = Path(out)
    subject = out / "subject"
    cycles = 2 if quick else 5
    if not (subject / "subject.yaml").is_file():
        log(f"creating the virtual subject in {subject}/ ...")
        create_subject(subject, resolution="coarse" if quick else "default")
    if not (subject / "trials" / "open_close.c3d").is_file():
        # more cycles than analysed: the study takes the first complete ones, as the paper did
        log(f"recording the virtual experiment ({cycles + 2} cycles per task) ...")
        record_experiment(subject, cycles=cycles + 2)
    log(f"running the mandible study -> {out}/")
    result = run_study(subject, out / "study", n_cycles=cycles, quick=quick, progress=progress, log=log,
                       workers=workers, scheduler=scheduler)
    report(result, out / "study", log)
    from ..viewer import write_view

    for run in sorted(p.parent for p in (out / "study").glob("*/fdk/kinematics.csv")):  # a 3D viewer per task
        log(f"viewer: {write_view(run)}")
    log(f"done in {_time.perf_counter() - t0:.0f} s")
    return result


def report(result, study_dir, log=print):
    """Print Tables 1 and 2 of a finished study and where its files are."""
    from .paper import format_table2_with_paper
    from .tables import format_text

    log("")
    log("Table 1: TMJ kinematics of the FDK and POP models vs measured (mean ± SD over cycles; RMSD in mm)")
    log(format_text(result["table1"]))
    log("")
    log("Table 2: TMJ reaction forces, POP vs FDK (mean ± SD over cycles; RMSD in N), beside the paper's")
    log(format_table2_with_paper(result["table2"], result["summary"].get("task_kinds")))
    log("")
    log(f"tables: {study_dir}/table1.md, {study_dir}/table2.md (and .csv)")
    if "parameter_study" in result["summary"].get("runs", {}):      # not with --no-parameter-study
        log(f"parameter study: {study_dir}/parameter_study/summary.csv (one row per case)")
    log(f"figures: {study_dir}/figures/")
    for f in result["figures"]:
        log(f"  {f}")
