"""The full-body model with its 92 muscles: path evaluation, recruitment against OpenSim
4.6's StaticOptimization on the same file and motion in the same process, and the HTML
viewer of a 60 s run (issues 25 and 29).

Inputs (written by openfdk, :mod:`openfdk.fixtures.full_body_osim` with ``muscles=True``
and :mod:`openfdk.fixtures.full_body_muscles`): the 12-body, 23-coordinate model with 92
Thelen2003Muscles (conditional points on the hamstrings, sartorius, gracilis and vasti;
the quadriceps over a moving patella point; psoas, iliacus and both gastrocnemii over
four WrapCylinders), a reserve CoordinateActuator (10 N m) on each joint coordinate and
residual ones on the six pelvis coordinates (300 N m, 1000 N); the walking-like motion of
:mod:`openfdk.bench.full_body_id` as a coordinate file (``motion.mot``, degrees, 100 Hz,
100 frames; ``--quick``: 30). No ground reactions: the pelvis residuals hold the body up.

Records:

* ``full_body_paths_us``: the 92 path lengths and their Jacobians at one pose of the walk
  (:class:`openfdk.forces.pathset.PathSet` ``evaluate``: 64 straight paths, 8 wrapped
  over cylinders, 20 with conditional or moving points) and the 92 × 23 moment arms
  about the coordinates (−L V, V the body velocities per unit coordinate rate, computed
  once), µs per evaluation, warm, median of 7 batches of 200.
* ``full_body_recruitment_ms``: openfdk's ``run`` of the model with ``--motion
  motion.mot`` and the overlay ``recruitment: {power: 2, static_optimization: opensim}``
  (OpenSim's choices: Σ a², rigid-tendon strengths with Thelen's force–velocity, no
  passive force, activations in [0.01, 1]; docs/recruitment.md), CPU ms per frame of
  :func:`openfdk.analysis.jobs.run_job` on the loaded model — the determinate kinematics from the
  coordinate splines, then per frame the paths, strengths, equilibrium and recruitment
  (92 muscles + 23 actuators as 46 one-sided columns, 49 free joint reactions, 72 rows).
  Median of 5 runs (``--quick``: 2).
* ``full_body_joint_loads_ms``: the joint loads of that run (``joint_loads.csv``: the 12
  joints' reactions, the actuators on their coordinates and the quadriceps' moving
  patella points; :mod:`openfdk.dynamics.joint_loads`), CPU ms per frame, median of as
  many runs.
* ``full_body_so_vs_opensim``: that time divided by OpenSim's per frame (below),
  alternated run by run in the same process; median of the per-pair ratios. Target
  ≤ 0.1. The record's ``max_muscle_diff_n`` (and its ``detail``) gives the largest
  difference of a muscle force between the two over every frame, and over the frames 10
  or more from either end (``interior_muscle_diff_n``; ``interior_muscle_diff_opensim_1e-8_n``
  the same against an untimed OpenSim run with its optimizer's convergence criterion
  1e-8 instead of 1e-4, not in ``--quick``).
* ``view_full_body_60s_build_s``: ``openfdk view`` (:func:`openfdk.viewer.write_view`)
  of the result folder of a real ``openfdk run`` of 60 s of the walk at 100 Hz (6000
  frames; ``--quick``: 5 s) on the model with a capsule mesh per body (binary STL,
  ≈ 2 300 vertices each, written here), CPU seconds of the build (single-threaded:
  the one-core time, meaningful on a shared machine; wall seconds in the detail), median
  of 3 (``--quick``: 1); ``file_mb`` is the page's size. Targets ≤ 5 s and ≤ 30 MB. The run
  itself is not timed.

How OpenSim is timed. ``AnalyzeTool.run()`` with a ``StaticOptimization`` loads the
model, reads the coordinate file and builds the states (``loadStatesFromFile``: the
coordinates in radians, their speeds from GCV splines), then for each time sets the
state, ``assemble``\\s, realises velocities and calls the analysis: ``begin`` (a working
copy of the model, ``initSystem``, quintic GCV splines of the states for the
accelerations, then the first frame's solve) at the first time, ``step`` (one frame's
solve: the working state set, the accelerations from the splines, IPOPT on Σ aᵖ subject
to the equations of motion with the actuators overridden) at the next ones; then it
writes the files. The timed loop is the tool's own loop over the frames after the first
(:func:`opensim_so_loop`), run from Python as ``AnalyzeTool::run`` runs it
(``setStateVariableValues``, ``assemble``, ``realizeVelocity``, ``step``), every set-up
step done before it as the tool does them (the same model with the analysis added,
``initSystem``, the tool's ``loadStatesFromFile``, ``begin``); CPU time of the loop per
frame. The Python calls cost a few µs per frame against OpenSim's ≈ 0.1 s. The loop's
forces are OpenSim's (its ``getForceStorage``); they are checked once against the
``_StaticOptimization_force.sto`` of ``AnalyzeTool.run()`` on the same files
(``loop_vs_tool_n``).

openfdk's timed run does more than OpenSim's loop: it solves the kinematics from the
coordinate splines (Newton), and the joint reactions come out of its recruitment.

Why the forces differ. Both interpolate the same samples with OpenSim's quintic spline
(since stop 64, :mod:`openfdk.bench.full_body_id`), so q and q̇ are the same at every
frame; q̈ nearly so: OpenSim's static optimisation differentiates a second quintic spline
through the samples of the first one's q̇, openfdk the first one twice. That matters at
the two ends (≈ 11 N in the erector spinae at the last frame; ≈ 25 N with openfdk's
earlier cubic spline). In the interior the difference (≈ 5 N) is OpenSim's IPOPT stopping
at its ``optimizer_convergence_criterion`` (1e-4) where openfdk's dual Newton method
reaches 1e-10: with the criterion 1e-8 it falls to ≈ 0.5 N (measured, December 2026;
OpenSim then takes ≈ 10 % longer).

Threads. The measurements run in a child process with one BLAS thread: with the default
threads on this 2-core machine (shared), OpenBLAS's threads make the recruitment's small
LAPACK calls (the 72 × 49 SVD of the free columns) 10–100× slower and erratic.

When ``opensim`` cannot be imported the OpenSim figures are NaN with a ``note``.
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ..contact.stl import write_stl

from .full_body import SINGLE_THREAD, SKIP_NOTE, opensim_available
from .full_body_id import TimedRun

RATE_HZ = 100.0
END_FRAMES = 10
MODEL, MOTION, OVERLAY = "full_body.osim", "motion.mot", "so.yaml"
VIEW_MODEL, VIEW_MOTION = "full_body_meshes.osim", "motion_60s.mot"
OVERLAY_TEXT = "recruitment: {power: 2, static_optimization: opensim}\n"
PATHS_POSE_S = 0.3  # the walk's time of the pose of full_body_paths_us

#: body: (capsule end A, end B (m, body frame, right side), radius m) of the viewer's meshes
_CAPSULES = {
    "pelvis": ((-0.10, 0.0, -0.07), (-0.10, 0.0, 0.07), 0.07),
    "femur": ((0.0, -0.03, 0.02), (-0.004, -0.38, 0.0), 0.028),
    "tibia": ((0.0, -0.03, 0.0), (0.0, -0.40, 0.0), 0.025),
    "talus": ((-0.01, -0.01, 0.0), (0.02, -0.02, 0.0), 0.018),
    "calcn": ((-0.01, 0.02, 0.0), (0.16, 0.0, 0.0), 0.025),
    "toes": ((0.0, 0.0, 0.0), (0.045, 0.0, 0.0), 0.012),
    "torso": ((-0.03, 0.05, 0.0), (-0.03, 0.45, 0.0), 0.11),
}


def write_inputs(directory, quick=False):
    """Write the model, the coordinate file (100 Hz) and the overlay into ``directory``;
    returns (model, motion, overlay)."""
    from ..fixtures.full_body_osim import write_full_body_motion, write_full_body_osim

    directory = Path(directory)
    model = write_full_body_osim(directory / MODEL, muscles=True)
    motion = write_full_body_motion(directory, np.arange(30 if quick else 100) / RATE_HZ, name=MOTION)
    overlay = directory / OVERLAY
    overlay.write_text(OVERLAY_TEXT, encoding="utf-8")
    return model, motion, overlay


# -- meshes -------------------------------------------------------------------------
def capsule(a, b, radius, segments=48, rings=24):
    """(vertices (n, 3) m, faces (m, 3) int) of a closed capsule around the segment a–b:
    a cylinder of ``segments`` sides and two hemispheres of ``rings`` rings each."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = b - a
    length = float(np.linalg.norm(axis))
    e3 = axis / length
    e1 = np.cross(e3, [1.0, 0.0, 0.0] if abs(e3[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(e3, e1)
    # rings of latitude φ from −π/2 (below a) to +π/2 (above b), then the two poles
    phis = np.concatenate([np.linspace(-np.pi / 2, 0.0, rings + 1)[1:], np.linspace(0.0, np.pi / 2, rings + 1)[:-1]])
    centres = [a] * rings + [b] * rings
    th = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    verts = []
    for phi, c in zip(phis, centres):
        r, h = radius * np.cos(phi), radius * np.sin(phi)
        verts.append(c + h * e3 + r * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2))
    verts = np.vstack(verts + [(a - radius * e3)[None], (b + radius * e3)[None]])
    n_rings = len(phis)
    south, north = len(verts) - 2, len(verts) - 1
    faces = []
    for i in range(n_rings - 1):
        for j in range(segments):
            p, q = i * segments + j, i * segments + (j + 1) % segments
            faces += [(p, q, q + segments), (p, q + segments, p + segments)]
    top = (n_rings - 1) * segments
    for j in range(segments):  # counter-clockwise seen from outside: outward normals
        faces.append((south, j, (j + 1) % segments))
        faces.append((north, top + (j + 1) % segments, top + j))
    return verts, np.array(faces, dtype=np.int64)


def write_view_inputs(directory, seconds):
    """A capsule STL per body in ``directory/Geometry``, the model with them as display
    meshes, the walk's coordinate file of ``seconds`` s at 100 Hz and the overlay;
    returns (model, motion, overlay)."""
    from ..fixtures.full_body_osim import BODIES, write_full_body_motion, write_full_body_osim

    directory = Path(directory)
    (directory / "Geometry").mkdir(parents=True, exist_ok=True)
    meshes = {}
    for body in BODIES:
        a, b, r = _CAPSULES[body.split("_")[0]]
        if body.endswith("_l"):
            a, b = (a[0], a[1], -a[2]), (b[0], b[1], -b[2])
        write_stl(directory / "Geometry" / f"{body}.stl", *capsule(a, b, r))
        meshes[body] = f"{body}.stl"
    model = write_full_body_osim(directory / VIEW_MODEL, muscles=True, meshes=meshes)
    motion = write_full_body_motion(directory, np.arange(int(round(seconds * RATE_HZ))) / RATE_HZ, name=VIEW_MOTION)
    overlay = directory / OVERLAY
    overlay.write_text(OVERLAY_TEXT, encoding="utf-8")
    return model, motion, overlay


# -- openfdk ------------------------------------------------------------------------
def _load(model_path, motion_path, overlay_path):
    from ..io.modelfile import load_model_and_settings
    from ..io.opensim.overlay import register

    register(model_path, motion=motion_path, overlay=overlay_path)
    return load_model_and_settings(model_path)


class OpenfdkRecruitment(TimedRun):
    """openfdk's run of the model with ``--motion`` and the overlay, loaded once;
    :meth:`run` times one run over the motion file's sample times."""

    def __init__(self, model_path, motion_path, overlay_path):
        super().__init__(*_load(model_path, motion_path, overlay_path), motion_path, "recruitment")


def muscle_forces(dyn):
    """{muscle: (nf,) N} of an InverseDynamicsResult."""
    index = {name: k for k, name in enumerate(dyn.column_names)}
    return {m: np.asarray(dyn.forces[:, index[m]], float) for m in dyn.muscle_names}


def paths_timing(model_path, batches=7, calls=200):
    """(µs per evaluation of the 92 paths and their 92 × 23 moment arms: list of batch
    medians, the moment arms (92, 23) m at the pose)."""
    from ..fixtures.full_body_osim import full_body_coordinates
    from ..forces.pathset import PathSet
    from ..io.modelfile import load_model
    from ..kinematics.coordinate_pose import pose_from_coordinates

    model = load_model(model_path)
    q = {n: float(v[0]) for n, v in full_body_coordinates(np.array([PATHS_POSE_S])).items()}
    state, _ = pose_from_coordinates(model, q)
    V = np.empty((state.n_coords, len(q)))
    for j, name in enumerate(q):
        st, _ = pose_from_coordinates(model, q, qdot={name: 1.0})
        V[:, j] = st.get_v()
    paths = PathSet(model.muscles)
    paths.evaluate(state)  # warm-up
    per_call = []
    for _ in range(batches):
        t0 = time.perf_counter()
        for _ in range(calls):
            _, L = paths.evaluate(state)
            arms = -(L @ V)
        per_call.append(1e6 * (time.perf_counter() - t0) / calls)
    return per_call, arms


# -- OpenSim ------------------------------------------------------------------------
class OpensimStaticOptimization:
    """OpenSim's StaticOptimization loop, set up as ``AnalyzeTool.run()`` sets it up
    (module docstring); :meth:`run` times the loop over the frames after the first."""

    def __init__(self, model_path, motion_path, exponent=2.0, convergence=None):
        import opensim as osim

        from ..io.storage import read_storage

        self.osim, self.model_path, self.exponent, self.convergence = osim, str(model_path), exponent, convergence
        self.motion_path = str(motion_path)
        self.times = np.asarray(read_storage(motion_path)[0], float)

    def _set_up(self):
        osim = self.osim
        model = osim.Model(self.model_path)
        so = osim.StaticOptimization()
        so.setName("so")
        so.setActivationExponent(self.exponent)
        if self.convergence is not None:  # optimizer_convergence_criterion (OpenSim's default 1e-4)
            so.setConvergenceCriterion(self.convergence)
        so.setStartTime(float(self.times[0]))
        so.setEndTime(float(self.times[-1]))
        model.addAnalysis(so)
        state = model.initSystem()
        tool = osim.AnalyzeTool()
        tool.setModel(model)
        tool.setCoordinatesFileName(self.motion_path)
        tool.setLowpassCutoffFrequency(-1)
        tool.loadStatesFromFile(state)
        store = tool.getStatesStorage()
        so.setStatesStore(store)
        # the tool's mapping of the storage's columns to the model's state variables
        labels = store.getColumnLabels()
        names = model.getStateVariableNames()
        model_names = [names.get(j) for j in range(names.getSize())]
        defaults = [model.getStateVariableValue(state, n) for n in model_names]
        column = {labels.get(k): k - 1 for k in range(1, labels.getSize())}
        rows = []
        for i in range(store.getSize()):
            data = store.getStateVector(i).getData()
            values = osim.Vector(len(model_names), 0.0)
            for j, n in enumerate(model_names):
                values.set(j, data.get(column[n]) if n in column else defaults[j])
            rows.append((store.getStateVector(i).getTime(), values))
        return model, so, state, tool, store, rows

    def run(self):
        """(CPU ms per frame of the loop, wall ms per frame, times (nf,), {actuator: (nf,) N})."""
        model, so, state, tool, store, rows = self._set_up()

        def set_row(i):
            t, values = rows[i]
            state.setTime(t)
            model.setStateVariableValues(state, values)
            model.assemble(state)
            model.realizeVelocity(state)

        set_row(0)
        so.begin(state)  # set-up and the first frame (untimed)
        c0, w0 = time.process_time(), time.perf_counter()
        for i in range(1, len(rows)):
            set_row(i)
            so.step(state, i)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        n = len(rows) - 1
        return 1e3 * cpu / n, 1e3 * wall / n, *_storage_columns(so.getForceStorage())

    def tool_forces(self, results_dir):
        """(times, {actuator: (nf,)}) of ``AnalyzeTool.run()``'s force file on the same files."""
        from ..io.storage import read_storage

        osim = self.osim
        results_dir = Path(results_dir)
        results_dir.mkdir(parents=True, exist_ok=True)
        tool = osim.AnalyzeTool()
        tool.setModelFilename(self.model_path)
        tool.setName("so")
        tool.setCoordinatesFileName(self.motion_path)
        tool.setLowpassCutoffFrequency(-1)
        tool.setInitialTime(float(self.times[0]))
        tool.setFinalTime(float(self.times[-1]))
        tool.setResultsDir(str(results_dir))
        so = osim.StaticOptimization()
        so.setStartTime(float(self.times[0]))
        so.setEndTime(float(self.times[-1]))
        so.setActivationExponent(self.exponent)
        tool.getAnalysisSet().cloneAndAppend(so)
        tool.printToXML(str(results_dir / "so_setup.xml"))
        if not osim.AnalyzeTool(str(results_dir / "so_setup.xml")).run():
            raise RuntimeError("OpenSim's AnalyzeTool (StaticOptimization) failed")
        t, columns, _ = read_storage(Path(results_dir) / "so_StaticOptimization_force.sto")
        return np.asarray(t, float), columns


def _storage_columns(storage):
    """(times (nf,), {label: (nf,)}) of an OpenSim Storage."""
    labels = storage.getColumnLabels()
    names = [labels.get(k) for k in range(1, labels.getSize())]
    times, rows = [], []
    for i in range(storage.getSize()):
        sv = storage.getStateVector(i)
        data = sv.getData()
        times.append(sv.getTime())
        rows.append([data.get(k) for k in range(len(names))])
    rows = np.array(rows, float).reshape(len(times), len(names))
    return np.array(times), {n: rows[:, k] for k, n in enumerate(names)}


def force_differences(times, ours, their_times, theirs):
    """(largest |Δf| N, its muscle, its time, largest over the frames END_FRAMES or more
    from either end) of the muscles' forces at the common times."""
    their_times = np.asarray(their_times, float)
    idx = np.clip(np.searchsorted(their_times, times - 1e-9), 0, len(their_times) - 1)
    common = np.abs(their_times[idx] - times) <= 1e-9
    k = np.arange(len(times))
    inner = common & (k >= END_FRAMES) & (k < len(times) - END_FRAMES)
    worst, which, at, interior = -1.0, "", float("nan"), 0.0
    for name, f in ours.items():
        diff = np.where(common, np.abs(f - np.asarray(theirs[name], float)[idx]), 0.0)
        j = int(np.argmax(diff))
        if diff[j] > worst:
            worst, which, at = float(diff[j]), name, float(times[j])
        if inner.any():
            interior = max(interior, float(diff[inner].max()))
    return worst, which, at, interior


# -- the viewer ---------------------------------------------------------------------
def view_timing(directory, seconds, repeats):
    """(CPU s of each build of the viewer, wall s of each, page size MB, frames) of a
    real ``openfdk run`` of ``seconds`` s of the walk on the model with meshes (the run
    not timed)."""
    from ..cli.commands import main
    from ..viewer import write_view

    directory = Path(directory) / "view"
    model, motion, overlay = write_view_inputs(directory, seconds)
    out = directory / "run"
    code = main(["run", str(model), "--motion", str(motion), "--with", str(overlay), "--out", str(out), "--no-plots",
                 "-q"])
    if code != 0:
        raise RuntimeError(f"openfdk run of the {seconds:g} s viewer input failed (exit {code})")
    builds, walls = [], []
    page = None
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        page = write_view(out, out=out / "view.html")
        builds.append(time.process_time() - c0)
        walls.append(time.perf_counter() - w0)
    return builds, walls, page.stat().st_size / 1e6, int(round(seconds * RATE_HZ))


def joint_loads_record(model, kin, dyn, repeats):
    """``full_body_joint_loads_ms``: CPU ms per frame of the joint loads
    (:func:`openfdk.io.joint_load_outputs.joint_load_columns`: the 12 joints' reactions,
    the 23 actuators on their coordinates, the quadriceps' moving patella points) of the
    recruitment's run, the median of ``repeats`` runs."""
    from ..io.joint_load_outputs import joint_load_columns

    cpu = []
    for _ in range(repeats):
        c0 = time.process_time()
        columns = joint_load_columns(model, kin, dyn)
        cpu.append(1e3 * (time.process_time() - c0) / len(dyn.time))
    knee = np.linalg.norm(np.column_stack([columns[f"knee_r_on_tibia_r_in_ground_f{c}"] for c in "xyz"]), axis=1)
    return {"name": "full_body_joint_loads_ms", "value": statistics.median(cpu), "unit": "ms/frame", "runs": repeats,
            "detail": (f"{len(dyn.time)} frames, {len(columns) // 9} joints; CPU ms/frame "
                       f"{[round(x, 3) for x in cpu]}; the right knee's force peaks at {np.nanmax(knee):.0f} N")}


# -- the measurement (child process) ------------------------------------------------
def measure(directory, quick=False):
    """Every figure, measured in this process on the inputs in ``directory`` (written by
    :func:`write_inputs`). Returns the records."""
    directory = Path(directory)
    model_path, motion, overlay = directory / MODEL, directory / MOTION, directory / OVERLAY
    batches, arms = paths_timing(model_path, batches=3 if quick else 7)
    records = [{"name": "full_body_paths_us", "value": statistics.median(batches), "unit": "us",
                "runs": len(batches),
                "detail": (f"92 path lengths, Jacobians and the 92 x 23 moment arms at the walk's pose at "
                           f"t = {PATHS_POSE_S} s (64 straight, 8 wrapped over cylinders, 20 with conditional or "
                           f"moving points), warm; us per evaluation, medians of batches of 200: "
                           f"{[round(x, 1) for x in batches]}; largest |moment arm| {np.abs(arms).max():.3f} m")}]
    repeats = 2 if quick else 5
    fdk = OpenfdkRecruitment(model_path, motion, overlay)
    have_opensim = opensim_available()
    theirs = None
    if have_opensim:
        import opensim as osim

        osim.Logger.setLevelString("warn")
        theirs = OpensimStaticOptimization(model_path, motion)
    ours_cpu, ours_wall, o_cpu, o_wall, ratios = [], [], [], [], []
    dyn = kin = their_run = None
    for _ in range(repeats):
        cpu, wall, kin, dyn = fdk.run()
        ours_cpu.append(cpu)
        ours_wall.append(wall)
        if have_opensim:
            their_run = theirs.run()
            o_cpu.append(their_run[0])
            o_wall.append(their_run[1])
            ratios.append(cpu / their_run[0])
    n = len(fdk.times)
    records.append({
        "name": "full_body_recruitment_ms", "value": statistics.median(ours_cpu), "unit": "ms/frame", "runs": repeats,
        "detail": (f"{n} frames at {RATE_HZ:g} Hz, 23 coordinates driven by OpenSim's quintic splines of {MOTION}, recruitment "
                   f"{OVERLAY_TEXT.strip()}: 92 muscles, 23 actuators, {np.mean(dyn.iterations):.1f} iterations per "
                   f"frame; CPU ms/frame of {repeats} runs {[round(x, 2) for x in ours_cpu]}, wall "
                   f"{[round(x, 2) for x in ours_wall]}; one BLAS thread")})
    records.append(joint_loads_record(fdk.model, kin, dyn, repeats))
    if not have_opensim:
        records.append({"name": "full_body_so_vs_opensim", "value": float("nan"), "unit": "ratio", "target": 0.1,
                        "note": SKIP_NOTE})
    else:
        ours = muscle_forces(dyn)
        times = np.asarray(dyn.time, float)
        worst, which, at, interior = force_differences(times, ours, their_run[2], their_run[3])
        tool_t, tool_columns = theirs.tool_forces(directory / "opensim")
        tight = None
        if not quick:  # OpenSim's optimizer to 1e-8 (untimed): what is left is the splines'
            tight_run = OpensimStaticOptimization(model_path, motion, convergence=1e-8).run()
            tight = force_differences(times, ours, tight_run[2], tight_run[3])
        loop_vs_tool = force_differences(their_run[2], {m: their_run[3][m] for m in ours}, tool_t, tool_columns)[0]
        records.append({
            "name": "full_body_so_vs_opensim", "value": statistics.median(ratios), "unit": "ratio", "target": 0.1,
            "runs": repeats, "opensim_ms": statistics.median(o_cpu), "max_muscle_diff_n": worst,
            "largest_in": which, "at_s": at, "interior_muscle_diff_n": interior, "loop_vs_tool_n": loop_vs_tool,
            "interior_muscle_diff_opensim_1e-8_n": float("nan") if tight is None else tight[3],
            "detail": (f"OpenSim 4.6 StaticOptimization (activation exponent 2, the model's actuators, unfiltered "
                       f"coordinates) timed over the AnalyzeTool's loop of frames 2..{n}, warm; OpenSim CPU ms/frame "
                       f"{[round(x, 1) for x in o_cpu]}, wall {[round(x, 1) for x in o_wall]}; openfdk/OpenSim per run "
                       f"{[round(x, 4) for x in ratios]}. Largest muscle-force difference {worst:.3g} N ({which} at "
                       f"t = {at:g} s), {interior:.3g} N over the frames {END_FRAMES} or more from either end"
                       + ("" if tight is None else f" ({tight[3]:.3g} N with OpenSim's optimizer_convergence_criterion "
                                                   f"1e-8 instead of its default 1e-4)")
                       + f"; the timed loop's forces equal AnalyzeTool.run()'s .sto within {loop_vs_tool:.1e} N")})
    seconds = 5.0 if quick else 60.0
    builds, walls, size_mb, frames = view_timing(directory, seconds, 1 if quick else 3)
    records.append({
        "name": "view_full_body_60s_build_s", "value": statistics.median(builds), "unit": "s", "target": 5.0,
        "file_mb": size_mb, "file_target_mb": 30.0, "frames": frames, "runs": len(builds),
        "detail": (f"openfdk view of a run of {seconds:g} s at {RATE_HZ:g} Hz ({frames} frames), 12 bodies with a "
                   f"capsule STL each, 92 muscles (8 wrapped), 40 markers; CPU s per build "
                   f"{[round(x, 2) for x in builds]}, wall {[round(x, 2) for x in walls]}; page {size_mb:.1f} MB")})
    return records


def run(quick=False):
    """The records (module docstring), measured in a child process with one BLAS thread."""
    from .full_body import child_records

    with tempfile.TemporaryDirectory() as d:
        write_inputs(d, quick)
        records = child_records("openfdk.bench.full_body_muscles", d, ["--quick"] if quick else [],
                                {**os.environ, **SINGLE_THREAD}, "full-body muscle benchmark")
    for note in sorted({r["note"] for r in records if r.get("note")}):
        print(f"full_body_muscles: {note}", file=sys.stderr, flush=True)
    return records


if __name__ == "__main__":  # the child process of run()
    _records = measure(sys.argv[1], quick="--quick" in sys.argv[2:])
    print(json.dumps(_records), flush=True)
