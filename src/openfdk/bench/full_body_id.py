"""Full-body inverse dynamics against OpenSim 4.6's InverseDynamicsTool: the run
``openfdk run full_body.osim --motion motion.mot --external-loads grf.xml`` and
OpenSim's tool on the same three files, in the same process, alternated.

Inputs (:mod:`openfdk.fixtures.full_body_osim`, written by openfdk): the Gait2392-sized
model of :mod:`openfdk.bench.full_body` (12 bodies, 23 coordinates, spline-coupled
knees; 69.7 kg), its walking-like motion as a coordinate file in OpenSim's IK output
format (``motion.mot``, degrees, 200 frames at 100 Hz; ``--quick``: 100) and two force
plates' ground reactions (``grf.mot`` at 1000 Hz with OpenSim's example column names,
``grf.xml``: two ExternalForces on calcn_r and calcn_l, expressed in the ground). The
reactions are plausible (body weight on average, double hump, shear, centre of pressure
heel to toe, free torque) but not consistent with the made-up motion, so the pelvis
residuals are large (≈ 200 N); that changes nothing in what is timed or compared.

Records:

* ``full_body_inverse_dynamics_ms``: openfdk's analysis of the run, warm, CPU ms per
  frame, median of 7 runs (``--quick``: 3): :func:`openfdk.analysis.jobs.run_job` on the model
  loaded with the import options ``--motion`` and ``--external-loads`` register
  (:func:`openfdk.io.opensim.overlay.register`), i.e. determinate kinematics driven by
  the 23 coordinate splines (positions by Newton's method, velocities, accelerations),
  then the inverse dynamics of every frame (the reactions of every joint and driver,
  the ExternalForces applied). Loading the model, reading the files and building the
  splines are not timed (done once before; one 5-frame run first compiles or loads the
  numba kernels). The run is given the motion file's sample times (``analysis``
  start/end/frames = the file's first and last time and its number of rows), so both
  programs report the same frames.
* ``full_body_id_vs_opensim``: that time divided by OpenSim's per frame (below),
  measured in the same process and alternated with openfdk's runs (this machine's speed
  drifts by ±50 % from hour to hour). Median of the per-pair ratios. Target ≤ 0.5.
* ``full_body_id_max_diff_nm``: the largest difference, over every frame and every
  coordinate, between openfdk's ``generalized_forces`` and the ``.sto`` that OpenSim's
  InverseDynamicsTool writes from the same files, both unfiltered (the tool's
  ``lowpass_cutoff_frequency_for_coordinates`` −1, no ``--motion-cutoff``); N m (N for
  the three pelvis translations).

How OpenSim is timed. ``InverseDynamicsTool.run()`` loads the model, adds the
ExternalForces (reading the GRF file), calls ``initSystem``, reads the coordinate file,
converts it to radians, fits a quintic GCV spline through each coordinate
(``GCVSplineSet(5, …)``), then solves: for each time of the file,
``InverseDynamicsSolver.solve(state, functions, time)`` sets q, u and u̇ from the
splines and their derivatives and returns the generalised forces (Simbody's
``calcResidualForceIgnoringConstraints``); then it writes the ``.sto``. Only that solve
loop is the analysis that openfdk's timed run performs, so the timed loop is that one:
the tool's own steps up to the solver (its ``createExternalLoads``, ``initSystem``,
``Storage``, ``convertDegreesToRadians``, ``GCVSplineSet(5, …)``, the functions put in
the state's q order as the tool orders them), then the same ``solve`` call per frame
from Python (CPU time of the loop; the Python call and the returned Vector's proxy cost
≈ 1.5 µs, ≈ 2 % of OpenSim's time per frame, which counts against OpenSim). Its
generalised forces are checked against the tool's ``.sto`` (the record's
``loop_vs_tool_nm``; the ``.sto`` has 8 decimals).

The first ``solve`` of a newly set-up tool takes ≈ 120 ms here (the next ones
≈ 0.075 ms): OpenSim builds the SimTK splines of its GCVSplines (the 18 GRF columns'
cubic GCV splines of 2000 samples, the 23 coordinates' quintic ones) when a function is
first evaluated. That is input preparation — openfdk builds its splines when it loads
the model, outside its timed run — so one solve at the first frame precedes the timed
loop. The tool's own stopwatch includes it: ``InverseDynamicsTool.run()`` is also run
once per repeat (on a model loaded beforehand, the tool then reads the files, builds
the splines, solves and writes) and the record gives the solve time its log reports
(``opensim_tool_log_ms``, from whole milliseconds of wall time: ≈ 0.67 ms per frame
of 200 frames, of which ≈ 0.6 ms is the one-off spline construction) and the CPU time
of the whole ``run()`` (``opensim_tool_run_ms``), per frame.

openfdk's run does more than the tool's solve: it places the bodies from the
coordinates (forward kinematics through the joints' SpatialTransforms, with the spline
couplings' chain rule), checks the constraint rows at that pose (max |Φ| ≤ 1e-10) and
computes the reaction force of every joint and driver, which the tool does not. The run
takes the compiled path of :mod:`openfdk.analysis.tree_trial` (docs/inverse-dynamics.md):
one compiled call for the frames, per frame the forward kinematics, one order-1
evaluation of the constraint program (Φ, Φ_q̂) and C f = d solved by twelve 6×6 blocks
read from Φ_q̂'s pattern. Measured per frame, December 2026, in one process alternated
with the frame-by-frame path (9 pairs, machine loaded: load average ≈ 6 on 2 cores):
0.051 ms against 0.336 (medians); against OpenSim in one bench run ``full_body_id_vs_opensim``
0.385 (per-run ratios 0.32–0.50; openfdk 0.059 ms, OpenSim 0.165 ms on the loaded
machine, ≈ 0.085 when idle). The earlier rounds: 0.71–0.87 ms (ratio 9.1–10.7), then
0.2 ms (2.1–2.7) with the program cache and block solves, frame by frame. What remains
per frame is compiled (≈ 15 µs for the program's evaluation, a few µs each for the
forward kinematics, the loads and the blocks) plus ≈ 10 µs of per-run Python (the
model's layouts, the loads' and drivers' samples at every frame, the results).

Why the two agree. Since stop 64 ``--motion`` processes the coordinate file as the tool
does (:mod:`openfdk.io.opensim.coordinate_filter`): the same natural quintic spline
(GCVSpline of degree 5, error variance 0) through the same samples, so q, q̇ and q̈ are
OpenSim's, and the generalised forces agree to the ``.sto``'s 8 decimals (5.5e-9 N m).
Until then openfdk differentiated a cubic not-a-knot spline and the two differed by
≈ 9 N at an end frame and ≈ 0.2 in the interior. The motion is analytic
(:func:`~openfdk.fixtures.full_body_osim.full_body_coordinate_rates`), so the record
also gives each program's largest difference from the inverse dynamics with the exact
q̇, q̈, over all frames and over the interior ones (10 frames, 0.1 s, from either end):
10 frames or more from the ends the quintic is within 1e-3 of the exact forces (4e-5
from 20 frames on; the cubic was 0.1–0.18 N m off everywhere, its q̈ being O(h²)
wrong, h = 10 ms); at the two ends its natural end conditions (q‴ = q⁗ = 0) are worse
(10 N off at the last frame, the cubic 0.9). Trim a trial's first and last 0.1 s, or
pass a longer coordinate file than the analysed window, where the ends matter.

Threads. As in :mod:`openfdk.bench.full_body`, the measurements run in a child process
with one BLAS thread; CPU time (``time.process_time``) is the measure, wall times are in
the records' ``detail``.

When ``opensim`` cannot be imported the OpenSim figures are NaN with a ``note``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .full_body import SINGLE_THREAD, SKIP_NOTE, opensim_available

RATE_HZ = 100.0
GRF_RATE_HZ = 1000.0
END_FRAMES = 10  # frames at either end left out of the "interior" figures
TOOL_OUTPUT = "inverse_dynamics.sto"
MODEL, MOTION, LOADS = "full_body.osim", "motion.mot", "grf.xml"


def write_inputs(directory, quick=False):
    """Write the model, the coordinate file (100 Hz) and the ground reactions (1000 Hz,
    over the same interval) into ``directory``; returns (model, motion, loads xml)."""
    from ..fixtures.full_body_osim import write_full_body_grf, write_full_body_motion, write_full_body_osim

    directory = Path(directory)
    n = 100 if quick else 200
    model = write_full_body_osim(directory / MODEL)
    motion = write_full_body_motion(directory, np.arange(n) / RATE_HZ, name=MOTION)
    grf_times = np.arange(int(round(n * GRF_RATE_HZ / RATE_HZ))) / GRF_RATE_HZ
    loads, _ = write_full_body_grf(model, directory, grf_times, name=Path(LOADS).stem)
    return model, motion, loads


# -- openfdk ------------------------------------------------------------------------
class TimedRun:
    """openfdk's run of a model loaded once (``model``, ``settings`` as
    :func:`~openfdk.io.modelfile.load_model_and_settings` gives them) over the sample
    times of ``motion_path``; one warm-up run of 5 frames; :meth:`run` times one run.
    ``what`` names the run in the error of a failed frame."""

    def __init__(self, model, settings, motion_path, what):
        from ..analysis.jobs import run_job
        from ..io.storage import read_storage

        self.model, self.what = model, what
        self.times = np.asarray(read_storage(motion_path)[0], float)
        self.run_job = run_job

        def window(n):
            kin = {**settings.kinematics, "start": float(self.times[0]), "end": float(self.times[n - 1]), "frames": n}
            return dataclasses.replace(settings, kinematics=kin)

        self.settings = window(len(self.times))
        run_job(self.model, settings=window(5), progress=False)  # warm-up

    def run(self):
        """(CPU ms per frame, wall ms per frame, KinematicsResult, InverseDynamicsResult)."""
        c0, w0 = time.process_time(), time.perf_counter()
        kin, dyn, _ = self.run_job(self.model, settings=self.settings, progress=False)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        if not (np.all(kin.converged) and np.all(dyn.converged)):
            raise RuntimeError(f"openfdk's full-body {self.what} failed at some frames")
        n = len(self.times)
        return 1e3 * cpu / n, 1e3 * wall / n, kin, dyn


class OpenfdkInverseDynamics(TimedRun):
    """openfdk's run of the model with ``--motion`` and ``--external-loads``, loaded
    once; :meth:`run` times one run over the motion file's sample times."""

    def __init__(self, model_path, motion_path, loads_path):
        from ..io.modelfile import load_model_and_settings
        from ..io.opensim.overlay import register

        register(model_path, external_loads=loads_path, motion=motion_path)
        super().__init__(*load_model_and_settings(model_path), motion_path, "inverse dynamics")

    def generalized_forces(self, dyn):
        """{OpenSim column: (nf,)} of a run (what generalized_forces.csv holds)."""
        from ..io.generalized_forces import generalized_forces

        return generalized_forces(self.model, dyn)


# -- OpenSim ------------------------------------------------------------------------
def _column(coordinate):
    import opensim as osim

    return coordinate.getName() + ("_moment" if coordinate.getMotionType() == osim.Coordinate.Rotational else "_force")


class OpensimInverseDynamics:
    """OpenSim's InverseDynamicsTool's solve, set up as the tool sets it up (module
    docstring); :meth:`run` times the per-frame loop over the coordinate file's times."""

    def __init__(self, model_path, motion_path, loads_path):
        import opensim as osim

        self.osim = osim
        self.model = osim.Model(str(model_path))
        self.tool = osim.InverseDynamicsTool()  # kept: it owns the ExternalLoads
        self.tool.createExternalLoads(str(loads_path), self.model)
        self.state = self.model.initSystem()
        storage = osim.Storage(str(motion_path))
        if storage.isInDegrees():
            self.model.getSimbodyEngine().convertDegreesToRadians(storage)
        splines = osim.GCVSplineSet(5, storage)
        coords = self.model.getCoordinateSet()
        self.coordinates = [coords.get(i) for i in range(coords.getSize())]
        nq, nu = self.state.getNQ(), self.state.getNU()
        if not nq == nu == len(self.coordinates):
            raise RuntimeError(f"OpenSim model: nq {nq}, nu {nu}, {len(self.coordinates)} coordinates")
        self.slot = {}  # coordinate -> its entry of q (= of u: these joints have q̇ = u)
        for c in self.coordinates:
            self.state.setQ(osim.Vector(nq, 0.0))
            c.setValue(self.state, 0.5, False)
            q = np.array([self.state.getQ().get(i) for i in range(nq)])
            k = int(np.argmax(np.abs(q)))
            if q[k] != 0.5 or np.count_nonzero(q) != 1:
                raise RuntimeError(f"OpenSim model: coordinate {c.getName()} is not one entry of q")
            self.slot[c.getName()] = k
        by_slot = {k: name for name, k in self.slot.items()}
        self.functions = osim.FunctionSet()
        for k in range(nq):
            self.functions.cloneAndAppend(splines.get(by_slot[k]))
        self.times = [storage.getStateVector(i).getTime() for i in range(storage.getSize())]
        self.solver = osim.InverseDynamicsSolver(self.model)
        self.solver.solve(self.state, self.functions, self.times[0])  # builds the SimTK splines (docstring)

    def run(self):
        """(CPU ms per frame, wall ms per frame, {column: (nf,)} generalised forces)."""
        solve, state, functions = self.solver.solve, self.state, self.functions
        c0, w0 = time.process_time(), time.perf_counter()
        out = [solve(state, functions, t) for t in self.times]
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        n = len(self.times)
        columns = {_column(c): np.array([tau.get(self.slot[c.getName()]) for tau in out]) for c in self.coordinates}
        return 1e3 * cpu / n, 1e3 * wall / n, columns

    def exact(self, times):
        """{column: (nf,)} the inverse dynamics at ``times`` with the motion's exact q, q̇,
        q̈ (:func:`~openfdk.fixtures.full_body_osim.full_body_coordinate_rates`)."""
        from ..fixtures.full_body_osim import full_body_coordinate_rates

        osim, state = self.osim, self.state
        q, qd, qdd = full_body_coordinate_rates(times)
        n = state.getNQ()
        out = {_column(c): np.empty(len(times)) for c in self.coordinates}
        for k, t in enumerate(times):
            vq, vu, vudot = osim.Vector(n, 0.0), osim.Vector(n, 0.0), osim.Vector(n, 0.0)
            for name, j in self.slot.items():
                vq.set(j, float(q[name][k]))
                vu.set(j, float(qd[name][k]))
                vudot.set(j, float(qdd[name][k]))
            state.setTime(float(t))
            state.setQ(vq)
            state.setU(vu)
            tau = self.solver.solve(state, vudot)
            for c in self.coordinates:
                out[_column(c)][k] = tau.get(self.slot[c.getName()])
        return out


_LOGGED = re.compile(r"InverseDynamicsTool: (\d+) time frames in (\d+) (second|millisecond|microsecond|nanosecond)")
_UNIT_MS = {"second": 1e3, "millisecond": 1.0, "microsecond": 1e-3, "nanosecond": 1e-6}


def opensim_tool(model_path, motion_path, loads_path, results_dir):
    """Run ``InverseDynamicsTool`` on the files (no filter, the file's whole time range)
    with its model loaded beforehand. Returns (times (nf,), {column: (nf,)} of its .sto,
    CPU ms per frame of ``run()``, ms per frame of the solve as its log reports it)."""
    import opensim as osim

    from ..io.storage import read_storage

    model = osim.Model(str(model_path))
    coordinates = osim.Storage(str(motion_path))
    start, end = coordinates.getFirstTime(), coordinates.getLastTime()
    tool = osim.InverseDynamicsTool()
    tool.setModel(model)
    tool.setCoordinatesFileName(str(motion_path))
    tool.setExternalLoadsFileName(str(loads_path))
    tool.setLowpassCutoffFrequency(-1)
    tool.setStartTime(start)
    tool.setEndTime(end)
    tool.setResultsDir(str(results_dir))
    tool.setOutputGenForceFileName(TOOL_OUTPUT)
    sink, level = osim.StringLogSink(), osim.Logger.getLevelString()
    osim.Logger.addSink(sink)
    osim.Logger.setLevelString("info")  # for the line that reports the solve time
    try:
        c0 = time.process_time()
        ok = tool.run()
        cpu = time.process_time() - c0
    finally:
        osim.Logger.setLevelString(level)
        osim.Logger.removeSink(sink)
    if not ok:
        raise RuntimeError("OpenSim's InverseDynamicsTool failed")
    times, columns, _ = read_storage(Path(results_dir) / TOOL_OUTPUT)
    found = _LOGGED.search(sink.getString())
    logged = float("nan") if found is None else float(found[2]) * _UNIT_MS[found[3]] / int(found[1])
    return times, columns, 1e3 * cpu / len(times), logged


def differences(times, ours, theirs_times, theirs):
    """(largest |Δ|, its column, its time, largest |Δ| over the interior frames) of two
    {column: (nf,)} tables at their common times."""
    theirs_times = np.asarray(theirs_times, float)
    idx = np.searchsorted(theirs_times, times)
    idx = np.clip(idx, 0, len(theirs_times) - 1)
    common = np.abs(theirs_times[idx] - times) <= 1e-9
    if not common.any():
        raise RuntimeError("no common frames between openfdk's and OpenSim's inverse dynamics")
    inner = common & (np.arange(len(times)) >= END_FRAMES) & (np.arange(len(times)) < len(times) - END_FRAMES)
    worst, column, at, interior = -1.0, "", float("nan"), 0.0
    for name, theirs_col in theirs.items():
        d = np.abs(np.asarray(ours[name], float) - np.asarray(theirs_col, float)[idx])
        d[~common] = 0.0
        k = int(np.argmax(d))
        if d[k] > worst:
            worst, column, at = float(d[k]), name, float(times[k])
        if inner.any():
            interior = max(interior, float(d[inner].max()))
    return worst, column, at, interior


# -- the measurement (child process) ------------------------------------------------
def measure(directory, quick=False):
    """Every figure, measured in this process on the inputs in ``directory`` (written
    by :func:`write_inputs`). Returns the records."""
    directory = Path(directory)
    model_path, motion, loads = directory / MODEL, directory / MOTION, directory / LOADS
    repeats = 3 if quick else 7
    fdk = OpenfdkInverseDynamics(model_path, motion, loads)
    n_frames = len(fdk.times)
    have_opensim = opensim_available()
    theirs = None
    if have_opensim:
        import opensim as osim

        osim.Logger.setLevelString("warn")
        theirs = OpensimInverseDynamics(model_path, motion, loads)
        theirs.run()  # warm-up (libraries, caches)
    ours_cpu, ours_wall, o_cpu, o_wall, ratios, tool_cpu, tool_logged = [], [], [], [], [], [], []
    dyn = kin = loop = tool = None
    for _ in range(repeats):
        cpu, wall, kin, dyn = fdk.run()
        ours_cpu.append(cpu)
        ours_wall.append(wall)
        if not have_opensim:
            continue
        c, w, loop = theirs.run()
        o_cpu.append(c)
        o_wall.append(w)
        ratios.append(cpu / c)
        tool = opensim_tool(model_path, motion, loads, directory / "opensim")
        tool_cpu.append(tool[2])
        tool_logged.append(tool[3])
    detail = (f"{n_frames} frames at {RATE_HZ:g} Hz, 23 coordinates driven by OpenSim's quintic splines of {MOTION} (unfiltered), "
              f"two ExternalForces from {LOADS} ({GRF_RATE_HZ:g} Hz); "
              f"{float(np.mean(kin.iterations)):.2f} Newton iterations per frame (0: forward kinematics); "
              f"CPU ms/frame of {repeats} runs {[round(x, 3) for x in ours_cpu]}, "
              f"wall {[round(x, 3) for x in ours_wall]}; one BLAS thread")
    records = [{"name": "full_body_inverse_dynamics_ms", "value": statistics.median(ours_cpu), "unit": "ms/frame",
                "runs": repeats, "detail": detail}]
    if not have_opensim:
        records += [{"name": "full_body_id_vs_opensim", "value": float("nan"), "unit": "ratio", "target": 0.5,
                     "note": SKIP_NOTE},
                    {"name": "full_body_id_max_diff_nm", "value": float("nan"), "unit": "N m", "note": SKIP_NOTE}]
        return records
    ours = fdk.generalized_forces(dyn)
    tool_times, tool_columns = tool[0], tool[1]
    loop_vs_tool = differences(np.asarray(theirs.times), loop, tool_times, tool_columns)[0]
    records.append({
        "name": "full_body_id_vs_opensim", "value": statistics.median(ratios), "unit": "ratio", "target": 0.5,
        "runs": repeats, "opensim_ms": statistics.median(o_cpu),
        "opensim_tool_log_ms": statistics.median(tool_logged), "opensim_tool_run_ms": statistics.median(tool_cpu),
        "loop_vs_tool_nm": loop_vs_tool,
        "detail": (f"OpenSim 4.6 InverseDynamicsSolver loop as InverseDynamicsTool runs it (quintic GCV splines of "
                   f"the coordinates, no filter), warm; OpenSim CPU ms/frame {[round(x, 4) for x in o_cpu]}, wall "
                   f"{[round(x, 4) for x in o_wall]}; openfdk/OpenSim per run {[round(x, 2) for x in ratios]}; "
                   f"InverseDynamicsTool.run() CPU ms/frame {[round(x, 3) for x in tool_cpu]} (reads, fits, solves, "
                   f"writes), its logged solve {[round(x, 3) for x in tool_logged]} ms/frame (includes the one-off "
                   f"spline construction); the loop's forces equal the tool's .sto within {loop_vs_tool:.1e}")})
    worst, column, at, interior = differences(np.asarray(dyn.time, float), ours, tool_times, tool_columns)
    exact = theirs.exact(np.asarray(dyn.time, float))
    times = np.asarray(dyn.time, float)
    ours_exact = differences(times, ours, times, exact)
    theirs_exact = differences(np.asarray(tool_times, float), tool_columns, times, exact)
    records.append({
        "name": "full_body_id_max_diff_nm", "value": worst, "unit": "N m", "largest_in": column, "at_s": at,
        "interior_nm": interior, "openfdk_vs_exact_nm": ours_exact[0], "openfdk_vs_exact_interior_nm": ours_exact[3],
        "opensim_vs_exact_nm": theirs_exact[0], "opensim_vs_exact_interior_nm": theirs_exact[3],
        "detail": (f"openfdk's generalized_forces vs OpenSim's InverseDynamicsTool .sto at the {len(times)} common "
                   f"frames, both unfiltered (N m; N for pelvis_t*); largest in {column} at t = {at:g} s; "
                   f"{interior:.3g} over the frames {END_FRAMES} or more from either end. Against the exact "
                   f"inverse dynamics of the analytic motion: openfdk (cubic not-a-knot spline) {ours_exact[0]:.3g} "
                   f"(interior {ours_exact[3]:.3g}), OpenSim (quintic GCV spline) {theirs_exact[0]:.3g} "
                   f"(interior {theirs_exact[3]:.3g})")})
    return records


def _child(directory, flags, env):
    """The records printed by ``python -m openfdk.bench.full_body_id directory *flags``."""
    from .full_body import child_records

    return child_records("openfdk.bench.full_body_id", directory, flags, env, "full-body inverse dynamics benchmark")


def run(quick=False):
    """The records (module docstring), measured in a child process with one BLAS
    thread."""
    with tempfile.TemporaryDirectory() as d:
        write_inputs(d, quick)
        records = _child(d, ["--quick"] if quick else [], {**os.environ, **SINGLE_THREAD})
    for note in sorted({r["note"] for r in records if r.get("note")}):  # the text output shows only name, value, unit
        print(f"full_body_id: {note}", file=sys.stderr, flush=True)
    return records


if __name__ == "__main__":  # the child process of run()
    _records = measure(sys.argv[1], quick="--quick" in sys.argv[2:])
    print(json.dumps(_records), flush=True)
