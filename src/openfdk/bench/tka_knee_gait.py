"""The knee in gait (issue 27): FDK of a total knee replacement over stance, at the default
FDK settings, 11 FDK DOFs (knee_add, knee_rot, knee_tx, knee_ty, knee_tz and the
patella's six), two implant contacts, 149 Blankevoort ligament strands, 45 muscles.

The model: DM of the 6th Knee Grand Challenge when ``OPENFDK_DM_DIR`` names a folder with
the overlay (``dm.yaml``, or the file ``OPENFDK_DM_OVERLAY`` names, e.g. the tutorial's
``dm_pt.yaml`` with an inextensible patellar tendon; docs/tutorial-knee-gait.md), ``DM.osim``, ``Geometry/``,
``DM_ngait_og1_new.trc`` and the trial's ground reactions; the FDK then tracks the
markers over right stance from t = DM_START (DM_FRAMES frames at the trial's 120 Hz;
``--quick``: DM_FRAMES_QUICK). Otherwise (CI, the normal case) the bench's own model of
the same size, :mod:`openfdk.fixtures.tka_knee` (record field ``model: "synthetic"``):
determinate kinematics of the driven hip, knee and ankle angles, the stance from
t = 0.10 s at 100 Hz, SYNTHETIC_FRAMES frames (``--quick``: SYNTHETIC_FRAMES_QUICK).

Records (each with ``model``, ``frames``, ``converged_frames``, ``wall_time_s``, and
``first_frame_evaluations`` and ``later_evaluations_per_frame``: on DM the window's first
frame, a cold start after its lead-in, was 141 of the 247 evaluations at stop 48; by
pseudo-transient continuation, 18 of 124 at stop 58):

* ``tka_knee_gait_fdk_fps``: frames per second of :func:`openfdk.fdk.analysis.run_fdk`
  over the window, one BLAS thread (measured in a child process), after loading the
  model (distance grids from the disk cache) and a warm-up run of two frames: the median
  of REPEATS timed runs (``wall_times_s``; ``--quick``: one). Target ≥ 50.
* ``tka_knee_gait_fdk_evaluations_per_frame``: mean residual evaluations per frame
  (each a kinematic analysis and a recruitment solve; the analytic Jacobians and the
  contacts-exact step's contact evaluations, :mod:`openfdk.fdk.contact_step`, are not
  counted). Target ≤ 4.
* ``tka_knee_gait_convergence_rate``: the fraction of the frames converged (max |f^FDK|
  < 1e-3 N, N m) at the default FDK settings. Target ≥ 0.995.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

SYNTHETIC_FRAMES, SYNTHETIC_FRAMES_QUICK = 50, 20
SYNTHETIC_RATE_HZ = 100.0
DM_START, DM_FRAMES, DM_FRAMES_QUICK = 2.5, 31, 8
DM_TRIAL = "DM_ngait_og1_new.trc"
#: timed runs of the window (``--quick``: one); the frame rate is their median (the machine's
#: speed varies by ±10 % from run to run, more from hour to hour)
REPEATS = 3
TARGETS = {"tka_knee_gait_fdk_fps": 50.0, "tka_knee_gait_fdk_evaluations_per_frame": 4.0,
           "tka_knee_gait_convergence_rate": 0.995}


def dm_overlay():
    """The DM overlay file named by ``OPENFDK_DM_DIR`` (and ``OPENFDK_DM_OVERLAY``, default
    ``dm.yaml``), or None without ``OPENFDK_DM_DIR``. FileNotFoundError, one line, when
    the folder is named but the overlay or the trial is not in it: the bench ran the
    synthetic knee instead, and said so only in its records' ``model``."""
    folder = os.environ.get("OPENFDK_DM_DIR")
    if not folder:
        return None
    overlay = Path(folder) / os.environ.get("OPENFDK_DM_OVERLAY", "dm.yaml")
    for path, name in ((overlay, "OPENFDK_DM_OVERLAY"), (Path(folder) / DM_TRIAL, "the trial")):
        if not path.is_file():
            raise FileNotFoundError(f"OPENFDK_DM_DIR={folder}: no {path.name} ({name}) there "
                                    "(docs/tutorial-knee-gait.md, section 8); unset OPENFDK_DM_DIR for the bench's own knee")
    return overlay


def synthetic_inputs(directory, quick=False):
    """(model, settings, trajectories None, times (nf,) s) of the bench's own knee
    written into ``directory``."""
    from ..analysis.jobs import model_and_settings
    from ..fixtures.tka_knee import FIRST_TIME, write_tka_knee

    overlay = write_tka_knee(directory)
    model, settings, _ = model_and_settings(str(overlay))
    n = SYNTHETIC_FRAMES_QUICK if quick else SYNTHETIC_FRAMES
    return model, settings, None, FIRST_TIME + np.arange(n) / SYNTHETIC_RATE_HZ


def dm_inputs(overlay, quick=False):
    """(model, settings, trajectories, times (nf,) s) of DM in right stance from DM_START."""
    from ..analysis.jobs import load_trajectories, model_and_settings

    model, settings, _ = model_and_settings(str(overlay))
    trial, traj = load_trajectories(model, str(overlay.parent / DM_TRIAL), settings=settings)
    times = np.asarray(trial.time, float)
    first = int(np.searchsorted(times, DM_START - 1e-9))
    return model, settings, traj, times[first:first + (DM_FRAMES_QUICK if quick else DM_FRAMES)]


def records(which, result, wall):
    """The three records (module docstring) of an FDKResult ``result`` timed ``wall`` s."""
    nf = len(result.converged)
    common = {"model": which, "frames": nf, "converged_frames": int(result.converged.sum()), "wall_time_s": wall,
              "mean_newton_iterations_per_frame": float(np.mean(result.iterations)),
              "mean_jacobians_per_frame": float(np.mean(result.jacobians)),
              "restarted_frames": int(np.count_nonzero(result.restarts)),
              "backward_frames": int(np.count_nonzero(result.backward)),
              # where the evaluations go: the window's first frame (a cold start: the
              # transient start, or a lead-in when that fails) and the frames after it
              "first_frame_evaluations": int(result.evaluations[0]) if nf else 0,
              "later_evaluations_per_frame": float(np.mean(result.evaluations[1:])) if nf > 1 else 0.0,
              "failed": sorted(set(r for r, ok in zip(result.reasons, result.converged) if not ok))}
    values = {"tka_knee_gait_fdk_fps": (nf / wall, "frames/s"),
              "tka_knee_gait_fdk_evaluations_per_frame": (float(np.mean(result.evaluations)), "evaluations/frame"),
              "tka_knee_gait_convergence_rate": (float(result.converged.mean()), "fraction")}
    return [{"name": name, "value": value, "unit": unit, "target": TARGETS[name], **common}
            for name, (value, unit) in values.items()]


def measure(directory, quick=False):
    """The records, measured in this process (one BLAS thread: see :func:`run`)."""
    from ..fdk.analysis import run_fdk
    from .timing import timed_runs

    overlay = dm_overlay()
    if overlay is not None:
        which, (model, settings, traj, times) = f"DM ({overlay.name})", dm_inputs(overlay, quick)
    else:
        which, (model, settings, traj, times) = "synthetic", synthetic_inputs(directory, quick)
    # warm-up: the cached kernels loaded (compiled, on a machine's first run), on DM with
    # the window's cold start, so that the timed run measures the solver, not numba
    run_fdk(model, traj, times[:2], settings)
    # the records' counts from the first run (the runs solve the same window: their counts
    # agree, repeat_evaluations shows it), the frame rate from the median wall time
    results, walls = timed_runs(lambda: run_fdk(model, traj, times, settings), 1 if quick else REPEATS)
    out = records(which, results[0], float(np.median(walls)))
    for r in out:
        r["window_s"] = [float(times[0]), float(times[-1])]
        r["wall_times_s"] = walls
        r["repeat_evaluations"] = [int(np.sum(res.evaluations)) for res in results]
    return out


def run(quick=False):
    """The records (module docstring), measured in a child process with one BLAS thread."""
    from .full_body import SINGLE_THREAD, child_records

    with tempfile.TemporaryDirectory() as d:
        return child_records("openfdk.bench.tka_knee_gait", d, ["--quick"] if quick else [],
                             {**os.environ, **SINGLE_THREAD}, "tka knee gait benchmark")


if __name__ == "__main__":  # the child process of run()
    import warnings

    warnings.simplefilter("ignore")  # the models' plausibility warnings: not the bench's output
    _records = measure(sys.argv[1], quick="--quick" in sys.argv[2:])
    print(json.dumps(_records), flush=True)
