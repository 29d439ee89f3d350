"""Benchmarks of the mandible study on the virtual subject: FDK and POP frames per second
on the open–close trial (FDK model: two condyle–fossa contacts with the generated
meshes, 3 FDK DOFs, 6 ligaments, 24 Hill muscles, marker tracking; model loading
excluded; median of 3 runs of 400 frames after a 5-frame first call, whose time — numba
loading its cached kernels — is reported as ``mandible_*_first_call_s``), the wall
time of the whole demo (``--quick``: the reduced demo, one run of 60 frames), and
``mandible_realistic_study_wall_s``: the whole study (registration, models, POP and FDK
on every task, cycles, tables, figures; no parameter study) on the realistic virtual
subject (:mod:`openfdk.mandible.realistic`; default meshes; ``--quick``: coarse meshes and
the quick recordings), with the share of feasible/converged frames per model. From the
same study (no extra run), issue 28's force benchmarks: ``mandible_table2_rmsd_min_N``
and ``mandible_table2_rmsd_max_N``, Table 2's smallest and largest row RMSD (POP vs
FDK; target inside [0.5, 30] N, the paper's rows span 0.75–24.7 N), and
``mandible_realistic_feasible_share``, the share of all analysed frames (every task,
POP and FDK) that are feasible/converged (target ≥ 0.995), with the failed frames per
task and model and their incisal openings. Frames per second are per CPU second of the
process (``time.process_time``: the one-core rate, robust on a shared machine); the
demo and study times are wall time."""

from __future__ import annotations

import statistics
import tempfile
import time
from pathlib import Path


def run(quick=False):
    from ..analysis.jobs import load_trajectories
    from ..fdk.analysis import run_fdk
    from ..analysis.inverse_dynamics import run_inverse_dynamics
    from ..kinematics.analysis import run_tracking
    from ..io.modelfile import load_model_and_settings
    from ..mandible.demo import run_demo
    from ..mandible.experiment import record_experiment
    from ..mandible.generator import create_subject
    from ..mandible.models import write_models
    from ..mandible.registration import register_braces
    from ..mandible.subject import load_subject

    out = []
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        create_subject(d / "subject", resolution="coarse" if quick else "default")
        record_experiment(d / "subject", tasks=("open_close",), cycles=1 if quick else 3)
        subject = load_subject(d / "subject")
        reg = register_braces(subject, d / "subject" / "trials" / "reference.c3d")
        paths = write_models(subject, reg, d / "models")
        trial = d / "subject" / "trials" / "open_close.c3d"
        for kind in ("fdk", "pop"):
            model, settings = load_model_and_settings(paths[kind])
            _, traj = load_trajectories(model, trial, settings=settings)
            times = traj.time[: (60 if quick else 400)]

            def analyse(frames):
                if kind == "fdk":
                    return float(run_fdk(model, traj, frames, settings).converged.mean())
                kin = run_tracking(model, traj, frames)
                return float(run_inverse_dynamics(model, kin, settings=settings).converged.mean())

            # first call: numba's cached kernels are loaded from disk (once per process)
            t0 = time.perf_counter()
            analyse(times[:5])
            warmup = time.perf_counter() - t0
            rates = []
            for _ in range(1 if quick else 3):
                t0 = time.process_time()
                conv = analyse(times)
                rates.append(len(times) / (time.process_time() - t0))
            out.append({"name": f"mandible_{kind}_fps", "value": statistics.median(rates), "unit": "frames/s",
                        "convergence_rate": conv})
            out.append({"name": f"mandible_{kind}_first_call_s", "value": warmup, "unit": "s"})
        t0 = time.perf_counter()
        run_demo(d / "demo", quick=quick, progress=False, log=lambda *a, **k: None)
        out.append({"name": "demo_quick_wall_s" if quick else "demo_wall_s", "value": time.perf_counter() - t0, "unit": "s"})
        out.extend(realistic_study(d, quick))
    return out


def realistic_study(d, quick=False):
    """``mandible_realistic_study_wall_s`` (run_study without the parameter study on a
    freshly recorded realistic subject in ``d``; recording excluded) and the force
    benchmarks of the same study (module docstring); a list of records."""
    from ..mandible.generator import create_subject
    from ..mandible.realistic import record_realistic
    from ..mandible.study import run_study

    subject = create_subject(Path(d) / "realistic", resolution="coarse" if quick else "default")
    record_realistic(subject, quick=quick)
    t0 = time.perf_counter()
    result = run_study(subject, Path(d) / "realistic-study", parameter_study=False, progress=False,
                       log=lambda *a, **k: None)
    wall = time.perf_counter() - t0
    return [{"name": "mandible_realistic_study_wall_s", "value": wall, "unit": "s",
             "frames": _frames(result["summary"]), "feasible_share": result["summary"]["feasible_share"],
             "failed": result["summary"]["failed"]}] + force_records(result)


def _frames(summary):
    return {task: {m: r[m]["frames"] for m in ("POP", "FDK")} for task, r in summary["runs"].items()
            if task in summary["completed"]}


def force_records(result):
    """The Table 2 RMSD range and the feasible share of a :func:`run_study` result."""
    summary = result["summary"]
    rmsd = [row["POP_RMSD_mean"] for row in result["table2"]]
    rows = {f"{r['task']}/{r['side']}/{r['direction']}": round(r["POP_RMSD_mean"], 3) for r in result["table2"]}
    runs = {task: r for task, r in summary["runs"].items() if task in summary["completed"]}
    frames = sum(r[m]["frames"] for r in runs.values() for m in ("POP", "FDK"))
    feasible = sum(r[m]["forces_converged"] for r in runs.values() for m in ("POP", "FDK"))
    failed = {f"{task}/{m}": r[m]["failed_frames"] for task, r in runs.items() for m in ("POP", "FDK")
              if r[m]["failed_frames"]["frames"]}
    return [
        {"name": "mandible_table2_rmsd_min_N", "value": min(rmsd) if rmsd else None, "unit": "N",
         "target": [0.5, 30.0], "paper": [0.75, 24.7], "rows": rows},
        {"name": "mandible_table2_rmsd_max_N", "value": max(rmsd) if rmsd else None, "unit": "N",
         "target": [0.5, 30.0], "paper": [0.75, 24.7]},
        {"name": "mandible_realistic_feasible_share", "value": feasible / frames if frames else None, "unit": "",
         "target": ">= 0.995", "frames": frames, "feasible": feasible, "failed_frames": failed},
    ]
