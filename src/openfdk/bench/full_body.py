"""Full-body benchmarks of the OpenSim import: a Gait2392-sized ``.osim`` (12 bodies,
23 coordinates, spline-coupled knees, 40 markers) that openfdk writes itself
(:mod:`openfdk.fixtures.full_body_osim`), and a 2 s walking-like trial of it at 100 Hz
(200 frames; ``--quick``: 100) with 0.5 mm marker noise, written as a ``.trc`` in mm.

Records:

* ``osim_import_full_body_s``: :func:`~openfdk.io.modelfile.load_model_and_settings`
  of the ``.osim``, warm (one load first: numba kernels compiled or loaded from the
  cache, the file in the OS cache), median of 7 loads (``--quick``: 5). Target ≤ 1 s.
* ``full_body_tracking_ms``: openfdk's marker tracking
  (:func:`~openfdk.kinematics.analysis.run_tracking`, what ``openfdk kinematics MODEL
  TRIAL`` runs: positions, velocities and accelerations of every frame) per frame, warm
  (a 5-frame run first), median of 5 runs (``--quick``: 1). The markers are used
  unfiltered (``cutoff_hz`` 0), because OpenSim's IK fits the raw samples and the two
  must solve the same problem; reading and filtering the trial are not timed.
* ``full_body_tracking_vs_opensim``: that time divided by OpenSim 4.6's inverse
  kinematics per frame on the same ``.osim`` and ``.trc``, measured in the same process
  and alternated with openfdk's runs (this machine's speed drifts by ±50 % from hour
  to hour; alternating puts both under the same drift). Median of the per-pair ratios.
  Target ≤ 0.5 (twice as fast as OpenSim).
* ``full_body_tracking_max_diff_deg``: the largest difference, over every frame and
  every rotational coordinate, between the coordinates of the two solutions (degrees;
  the pelvis translations' largest difference, in mm, is in the record's ``detail``).
* ``full_body_tracking_vs_opensim_default_accuracy`` and
  ``full_body_tracking_max_diff_deg_opensim_default_accuracy``: the same against
  OpenSim at its default IK accuracy (1e-5), what most users run.

How OpenSim is timed. ``InverseKinematicsTool.run()`` reads the ``.trc``, builds its
references, solves, then writes the ``.mot`` (and marker errors); its solve is the loop
``InverseKinematicsSolver.assemble(state)`` at the first frame then ``track(state)`` at
every following one. That loop is what is timed here (CPU time of the calls), with the
solver built as the tool builds it: a ``MarkersReference`` of the ``.trc`` with every
model marker at weight 1 (an IK task set of all markers, weight 1, no coordinate tasks)
and an infinite constraint weight. Model loading, ``initSystem`` and the references are
left out on OpenSim's side as reading the model and the trial are on openfdk's; the
frame-0 assembly from the default pose is in, as openfdk's frame-0 initial guess is.
openfdk's time includes the velocities and accelerations, which OpenSim's IK does not
compute: the ratio is conservative.

Accuracy. openfdk's default tolerance stops Gauss–Newton when max |Δq̂| < 1e-9 (m, rad),
i.e. at the least-squares optimum to ≈ 1e-9. OpenSim's ``accuracy`` is the convergence
tolerance of Simbody's Assembler, here an L-BFGS optimiser (no constraint equations, no
bounds), a bound on the cost's gradient, not on the coordinates. Measured on this model
and trial (one BLAS thread, OpenSim CPU ms per frame, largest difference from openfdk's
solution): accuracy 1e-5: 2.7 ms, 1.7°; 1e-6: 5.4 ms, 0.1°; 1e-7: 5.8 ms, 0.017°;
1e-8: 6.6 ms, 0.0015°; 1e-9: 6.7 ms, 0.00012°; 1e-10: 7.5 ms, 1e-6° (1e-11, 1e-12:
≈ 8 ms, 1e-6°). The ratio is quoted against :data:`OPENSIM_ACCURACY` = 1e-9, the
loosest power of ten at which OpenSim's coordinates are within 0.001° of the optimum
openfdk converges to (tighter costs OpenSim 10–20 % more time); the default-accuracy
figures show the other end.

Clamped coordinates. The model does not clamp its coordinates (``<clamped>false``).
With clamped coordinates Simbody's Assembler gives its optimiser the ranges as bounds,
which makes it an L-BFGS-B; on this model and trial that one stops far from the optimum
at every accuracy from 1e-5 to 1e-12 (median cost 1.45× the least-squares minimum, the
toes up to 12° off, in 2.1 ms per frame) although every true coordinate lies well inside
its range. openfdk's tracking holds clamped coordinates in their ranges too
(:mod:`openfdk.kinematics.coordinate_bounds`) but reaches the optimum, so clamped, the
comparison would time two different answers (``write_full_body_osim(path,
clamped=True)`` writes that variant).

Threads. The measurements run in a child process with one BLAS thread
(``OPENBLAS_NUM_THREADS=1``, as docs/studies.md advises for serial runs and
:mod:`openfdk.bench.study` does). With the default multi-threaded OpenBLAS on this
2-core machine, the observability check that every ``run_tracking`` call makes once
(``undetermined_coordinates``: a full SVD, ``full_matrices=True``, of the 169 × 72
stacked marker and constraint Jacobian) took 150–725 ms instead of 1.3 ms, i.e. up to
3.6 ms per frame of a 200-frame trial, more than the tracking itself; the reduced SVD
of the same matrix takes 1 ms either way. CPU time (``time.process_time``) is the
measure as in the other benchmarks; the record's ``detail`` has the wall times too.

``full_body_tracking_ms_default_blas_threads`` is ``full_body_tracking_ms`` measured
in a second child process that keeps the environment's BLAS threads (median of 3 runs,
``--quick``: 1): what ``openfdk kinematics`` costs a user who did not set them.

When ``opensim`` cannot be imported the OpenSim figures are NaN with a ``note``.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

OPENSIM_ACCURACY = 1e-9
OPENSIM_DEFAULT_ACCURACY = 1e-5
NOISE_M = 5e-4
RATE_HZ = 100.0
SINGLE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
SKIP_NOTE = "skipped: the opensim package (OpenSim 4.6 Python bindings) is not installed"


# -- openfdk ------------------------------------------------------------------------
def coordinate_table(model, kinematics):
    """(names, (nf, n_coordinates) SI) of the model's coordinates at every converged
    frame of ``kinematics`` (NaN elsewhere)."""
    from ..model.compiled import CompiledMeasures

    names = [c.name for c in model.coordinates]
    program = CompiledMeasures([c.measure for c in model.coordinates])
    state = model.initial_state()
    out = np.full((len(kinematics.time), len(names)), np.nan)
    for k in range(len(kinematics.time)):
        if kinematics.converged[k]:
            state.set_q(kinematics.q[k])
            out[k] = program.evaluate(state, 0)[0]
    return names, out


def time_import(path, repeats):
    """Median wall time (s) of ``load_model_and_settings(path)`` after one warm-up load."""
    from ..io.modelfile import load_model_and_settings

    from .timing import timed_runs

    load_model_and_settings(path)
    return statistics.median(timed_runs(lambda: load_model_and_settings(path), repeats)[1])


class OpenfdkTracking:
    """openfdk's tracking of the trial, loaded once; :meth:`run` times one run."""

    def __init__(self, model_path, trc_path):
        from ..io.modelfile import load_model_and_settings
        from ..analysis.jobs import load_trajectories
        from ..kinematics.analysis import run_tracking

        self.run_tracking = run_tracking
        self.model, _ = load_model_and_settings(model_path)
        trial, self.traj = load_trajectories(self.model, trc_path, cutoff_hz=0)
        self.times = np.asarray(trial.time, float)
        run_tracking(self.model, self.traj, self.times[:5])  # warm-up

    def run(self):
        """(CPU ms per frame, wall ms per frame, KinematicsResult)."""
        c0, w0 = time.process_time(), time.perf_counter()
        res = self.run_tracking(self.model, self.traj, self.times)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        if not res.converged.all():
            raise RuntimeError(f"full-body tracking did not converge: {res.failed_frames()[:1]}")
        n = len(self.times)
        return 1e3 * cpu / n, 1e3 * wall / n, res


# -- OpenSim ------------------------------------------------------------------------
def opensim_available():
    try:
        import opensim  # noqa: F401
    except Exception:  # ImportError, or a broken installation (missing shared libraries)
        return False
    return True


def opensim_ik(model_path, trc_path, times, accuracy):
    """OpenSim's inverse kinematics of the trial, solved frame by frame as
    InverseKinematicsTool does (module docstring). Returns (coordinate names,
    (nf, n) SI values, CPU ms per frame, wall ms per frame) of the solve loop only."""
    import opensim as osim

    model = osim.Model(str(model_path))
    state = model.initSystem()
    weights = osim.SetMarkerWeights()
    markers = model.getMarkerSet()
    for i in range(markers.getSize()):
        weights.cloneAndAppend(osim.MarkerWeight(markers.get(i).getName(), 1.0))
    reference = osim.MarkersReference(str(trc_path), weights)
    solver = osim.InverseKinematicsSolver(model, reference, osim.SimTKArrayCoordinateReference(), math.inf)
    solver.setAccuracy(accuracy)
    coords = model.getCoordinateSet()
    handles = [coords.get(i) for i in range(coords.getSize())]
    names = [c.getName() for c in handles]
    out = np.empty((len(times), len(names)))
    cpu = wall = 0.0
    for k, t in enumerate(times):
        state.setTime(float(t))
        c0, w0 = time.process_time(), time.perf_counter()
        if k == 0:
            solver.assemble(state)
        else:
            solver.track(state)
        cpu += time.process_time() - c0
        wall += time.perf_counter() - w0
        out[k] = [c.getValue(state) for c in handles]
    n = len(times)
    return names, out, 1e3 * cpu / n, 1e3 * wall / n


def coordinate_differences(ours_names, ours, theirs_names, theirs, model):
    """(max |Δ| of the rotational coordinates in degrees, max |Δ| of the translational
    ones in mm, name of the coordinate of the largest angle difference)."""
    units = {c.name: c.unit for c in model.coordinates}
    idx = {n: i for i, n in enumerate(ours_names)}
    worst, worst_name, worst_mm = 0.0, "", 0.0
    for j, name in enumerate(theirs_names):
        d = ours[:, idx[name]] - theirs[:, j]
        if units[name] == "angle":
            d = np.degrees(np.abs((d + np.pi) % (2 * np.pi) - np.pi))
            if d.max() >= worst:
                worst, worst_name = float(d.max()), name
        else:
            worst_mm = max(worst_mm, 1e3 * float(np.abs(d).max()))
    return worst, worst_mm, worst_name


# -- the measurement (child process) ------------------------------------------------
def measure(directory, quick=False):
    """Every figure, measured in this process on the model and trial in ``directory``
    (written by :func:`write_inputs`). Returns the records."""
    model_path, trc_path = Path(directory) / "full_body.osim", Path(directory) / "walk.trc"
    repeats = 1 if quick else 5
    records = [{"name": "osim_import_full_body_s", "value": time_import(model_path, 5 if quick else 7),
                "unit": "s", "target": 1.0}]
    fdk = OpenfdkTracking(model_path, trc_path)
    n_frames = len(fdk.times)
    have_opensim = opensim_available()
    if have_opensim:
        import opensim as osim

        osim.Logger.setLevelString("warn")
        opensim_ik(model_path, trc_path, fdk.times[:5], OPENSIM_ACCURACY)  # warm-up (libraries, caches)
    ours_cpu, ours_wall, ratios, ratios_default = [], [], [], []
    theirs = {OPENSIM_ACCURACY: [], OPENSIM_DEFAULT_ACCURACY: []}
    res, solutions = None, {}
    for _ in range(repeats):
        cpu, wall, res = fdk.run()
        ours_cpu.append(cpu)
        ours_wall.append(wall)
        if not have_opensim:
            continue
        for acc in (OPENSIM_ACCURACY, OPENSIM_DEFAULT_ACCURACY):
            names, values, o_cpu, o_wall = opensim_ik(model_path, trc_path, fdk.times, acc)
            theirs[acc].append((o_cpu, o_wall))
            solutions[acc] = (names, values)
            (ratios if acc == OPENSIM_ACCURACY else ratios_default).append(cpu / o_cpu)
    detail = (f"{n_frames} frames at {RATE_HZ:g} Hz, {NOISE_M * 1e3:g} mm noise, unfiltered markers; "
              f"{float(np.mean(res.iterations)):.2f} Gauss-Newton iterations per frame; "
              f"CPU ms/frame of {repeats} runs {[round(x, 3) for x in ours_cpu]}, "
              f"wall {[round(x, 3) for x in ours_wall]}; one BLAS thread")
    records.append({"name": "full_body_tracking_ms", "value": statistics.median(ours_cpu), "unit": "ms/frame",
                    "runs": repeats, "detail": detail})
    figures = [("full_body_tracking_vs_opensim", "full_body_tracking_max_diff_deg", OPENSIM_ACCURACY, ratios, 0.5),
               ("full_body_tracking_vs_opensim_default_accuracy",
                "full_body_tracking_max_diff_deg_opensim_default_accuracy", OPENSIM_DEFAULT_ACCURACY, ratios_default,
                None)]
    if not have_opensim:
        for ratio_name, diff_name, acc, _, target in figures:
            rec = {"name": ratio_name, "value": float("nan"), "unit": "ratio", "note": SKIP_NOTE}
            if target is not None:
                rec["target"] = target
            records += [rec, {"name": diff_name, "value": float("nan"), "unit": "deg", "note": SKIP_NOTE}]
        return records
    ours_names, ours = coordinate_table(fdk.model, res)
    for ratio_name, diff_name, acc, rs, target in figures:
        names, values = solutions[acc]
        deg, mm, worst = coordinate_differences(ours_names, ours, names, values, fdk.model)
        o_cpu = [c for c, _ in theirs[acc]]
        o_wall = [w for _, w in theirs[acc]]
        rec = {"name": ratio_name, "value": statistics.median(rs), "unit": "ratio", "runs": repeats,
               "opensim_ms": statistics.median(o_cpu),
               "detail": (f"OpenSim 4.6 InverseKinematicsSolver, accuracy {acc:g}, all {len(names)} coordinates "
                          f"unclamped, 40 markers at weight 1; OpenSim CPU ms/frame {[round(x, 3) for x in o_cpu]}, "
                          f"wall {[round(x, 3) for x in o_wall]}; openfdk/OpenSim per run "
                          f"{[round(x, 3) for x in rs]}")}
        if target is not None:
            rec["target"] = target
        records.append(rec)
        records.append({"name": diff_name, "value": deg, "unit": "deg", "largest_in": worst,
                        "detail": f"OpenSim accuracy {acc:g}; pelvis translations differ by at most {mm:.2g} mm"})
    return records


def write_inputs(directory, quick=False, seed=0):
    """Write the model (``full_body.osim``) and the trial (``walk.trc``) into
    ``directory``; returns (model path, trc path)."""
    from ..fixtures.full_body_osim import write_full_body_osim, write_full_body_trial

    directory = Path(directory)
    model_path = write_full_body_osim(directory / "full_body.osim")
    trc_path, *_ = write_full_body_trial(model_path, directory / "walk.trc", n_frames=100 if quick else 200,
                                         rate_hz=RATE_HZ, seed=seed, noise_m=NOISE_M)
    return model_path, trc_path


def child_records(module, directory, flags, env, what="full-body benchmark"):
    """The records (a JSON list on the last line starting with '[{') printed by
    ``python -m <module> directory *flags`` in a child process with environment ``env``
    (OpenSim's log lines, which also start with '[', are skipped)."""
    cmd = [sys.executable, "-m", module, str(directory)] + list(flags)
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=directory, timeout=1800, check=False)
    lines = [x for x in proc.stdout.splitlines() if x.startswith("[{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"the {what} process failed (exit {proc.returncode}): {tail}")
    return json.loads(lines[-1])


def _child(directory, flags, env):
    """The records printed by ``python -m openfdk.bench.full_body directory *flags``."""
    return child_records("openfdk.bench.full_body", directory, flags, env)


def measure_default_threads(directory, quick=False):
    """``full_body_tracking_ms_default_blas_threads``: openfdk's tracking as in
    :func:`measure` but with the BLAS threads the environment gives (module docstring,
    Threads)."""
    fdk = OpenfdkTracking(Path(directory) / "full_body.osim", Path(directory) / "walk.trc")
    runs = [fdk.run()[:2] for _ in range(1 if quick else 3)]
    threads = os.environ.get("OPENBLAS_NUM_THREADS") or os.environ.get("OMP_NUM_THREADS") or "unset"
    return [{"name": "full_body_tracking_ms_default_blas_threads", "value": statistics.median(c for c, _ in runs),
             "unit": "ms/frame", "runs": len(runs),
             "detail": (f"OPENBLAS_NUM_THREADS {threads}, {os.cpu_count()} CPUs; CPU ms/frame "
                        f"{[round(c, 3) for c, _ in runs]}, wall {[round(w, 3) for _, w in runs]}")}]


def run(quick=False):
    """The full-body records (module docstring), measured in a child process with one
    BLAS thread, then openfdk's tracking again in one with the BLAS threads of this
    process's environment."""
    with tempfile.TemporaryDirectory() as d:
        write_inputs(d, quick)
        flags = ["--quick"] if quick else []
        records = _child(d, flags, {**os.environ, **SINGLE_THREAD})
        records += _child(d, flags + ["--default-threads"], dict(os.environ))
    notes = sorted({r["note"] for r in records if r.get("note")})
    for note in notes:  # the text output shows only name, value, unit
        print(f"full_body: {note}", file=sys.stderr, flush=True)
    return records


if __name__ == "__main__":  # the child processes of run()
    _quick = "--quick" in sys.argv[2:]
    _measure = measure_default_threads if "--default-threads" in sys.argv[2:] else measure
    print(json.dumps(_measure(sys.argv[1], quick=_quick)), flush=True)
