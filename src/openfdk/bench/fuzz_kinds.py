"""The fuzz kinds of issue 30 (items 7 and 8): the OpenSim ExternalLoads reader with its
GRF data file, OpenSim storage files, force-plate parameters of a C3D, result folders,
checkpoint parts and study locks. :mod:`openfdk.bench.fuzz_inputs` dispatches to this
module for these kinds; each has

* a valid base written into the fuzz folder by openfdk itself (:func:`build`),
* a mutator (:func:`mutate`: writes one mutated input over the base files),
* the loader a user reaches (:func:`load`: what the command line calls), and
* its documented error (:func:`documented_error`), a ``ValueError`` naming the file.

Kinds:

- ``external_loads``: an ExternalLoads ``.xml`` (two forces, one in the ground frame with
  point and torque columns, one in the body frame) applied to the fuzz ``.osim``
  (``--external-loads``), XML mutations -> ``ModelError``;
- ``grf_mot``: the ``.mot`` GRF data file that ExternalLoads names, read through the
  6 Hz low-pass (``--external-loads-cutoff``), text mutations ->
  ``ModelError`` (the ``external_loads`` entry and the file named);
- ``sto``: a coordinate ``.sto`` driving the ``.osim`` (``--motion``), text mutations ->
  ``ModelError``;
- ``overlay``: an overlay file run as the model (``opensim: leg.osim``) with a motion
  file, an FDK DOF, a frame, a measure and a constraint that determines a coordinate the
  motion would drive (the two-stage pipeline), YAML mutations -> ``ModelError``;
- ``force_plates``: a C3D with four plates of types 1–4 (26 analog channels) read by
  :func:`openfdk.io.force_plates.read_force_plates`; byte mutations and mutations of the
  FORCE_PLATFORM, ANALOG and POINT:UNITS parameter records themselves (a value set to an
  edge value, the type or a dimension byte changed, values swapped, a name misspelt) ->
  ``C3DError``;
- ``results``: the result folder of a small ``openfdk run`` read by the ``plot``,
  ``export-opensim`` and ``view`` readers, with a ``coordinates.csv`` of its frames (the
  table an OpenSim model's run adds; the plot reader groups its columns for the
  kinematics figure); JSON mutations of ``summary.json`` and text mutations of
  ``kinematics.csv`` / ``forces.csv`` / ``coordinates.csv`` -> ``ValueError`` naming
  the file;
- ``checkpoint``: the checkpoint parts of that run, resumed as ``--resume`` resumes them
  (:func:`openfdk.analysis.jobs.run_job`); JSON mutations of a sidecar, of the structure inside a
  part or of its arrays, byte mutations of a part (with the sidecar's SHA-256 rewritten,
  as an attacker would, or not) -> ``CheckpointError``;
- ``checkpoint_fdk``: the same for the checkpoint parts of a small FDK run (the
  synthetic TMJ jaw with its meshes), whose solver state carries the last solved frame's
  poses and KKT factors; the arrays' mutations also keep an array's shape and type and
  move one entry to an edge value (an index past the matrix, a negative one, NaN)
  -> ``CheckpointError``;
- ``study_lock``: a ``.study.lock`` written by the study runner (held by this process;
  for 30 % of the inputs first made stale: the pid of a finished process), JSON and text
  mutations -> ``StudyError`` (or the stale lock taken over);
- ``validation_map``, ``validation_reference``: the map (YAML) and the measured reference
  (``.sto``, time in %) of ``openfdk validate-kinematics`` against a run folder in the
  format ``openfdk run`` writes; YAML and text mutations -> ``ValidationError``;
- ``joint_reaction``: OpenSim's JointReaction setup (an AnalyzeTool setup with its
  joints, bodies and frames) named by an overlay's ``joint_reaction`` on the fuzz
  ``.osim``; XML mutations -> ``ModelError``.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import subprocess
import sys

import numpy as np

NEW_KINDS = ("external_loads", "grf_mot", "sto", "force_plates", "results", "checkpoint", "checkpoint_fdk",
             "study_lock", "validation_map", "validation_reference", "joint_reaction", "overlay", "cycles")
#: the kinds whose inputs are checkpoint parts, resumed
CHECKPOINT_KINDS = ("checkpoint", "checkpoint_fdk")
#: the FDK run's model file (in its run folder)
FDK_MODEL = "tmj.yaml"
#: the validation kinds' gait cycle (s) and toe-off (s), and their map file
VALIDATION_CYCLE, VALIDATION_TOE_OFF = (1.0, 2.0), 1.6
VALIDATION_MAP_TEXT = """knee_sup_r: {coordinate: knee_ty_r, unit: m, label: superior translation}
knee_rot_r: {coordinate: knee_flex_r, unit: rad, scale: -1}
knee_add_r: {coordinate: 'angles[1]', unit: deg}
"""
#: the fingerprint of the fuzz run's checkpoints
FINGERPRINT = "openfdk-fuzz"
#: the result folder's name (errors name it)
RESULTS_DIR = "fuzzres"
#: the end of the fuzz run (s): a few frames keep a resume and the readers fast
END_S = 0.05

EXTERNAL_LOADS_TEXT = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
 <ExternalLoads name="grf_loads">
  <objects>
   <ExternalForce name="right">
    <isDisabled>false</isDisabled>
    <applied_to_body>shank</applied_to_body>
    <force_expressed_in_body>ground</force_expressed_in_body>
    <point_expressed_in_body>ground</point_expressed_in_body>
    <force_identifier>ground_force_v</force_identifier>
    <point_identifier>ground_force_p</point_identifier>
    <torque_identifier>ground_torque_</torque_identifier>
    <data_source_name>grf.mot</data_source_name>
   </ExternalForce>
   <ExternalForce name="push">
    <applied_to_body>/bodyset/thigh</applied_to_body>
    <force_expressed_in_body>thigh</force_expressed_in_body>
    <point_expressed_in_body>thigh</point_expressed_in_body>
    <force_identifier>push_v</force_identifier>
    <point_identifier>push_p</point_identifier>
    <torque_identifier></torque_identifier>
    <data_source_name>Unassigned</data_source_name>
   </ExternalForce>
  </objects>
  <datafile>grf.mot</datafile>
 </ExternalLoads>
</OpenSimDocument>
"""

#: the ``overlay`` kind's base: the fuzz ``.osim`` driven by a motion file, its knee an FDK
#: DOF, with a constraint that leaves the motion's hip column out (docs/gait.md, two stages)
OVERLAY_TEXT = """opensim: leg.osim
motion: overlay_motion.sto
fdk: [knee]
frames:
  ground: {a: [0.3, 0.2, 0.0]}
  shank: {b: [0.03, -0.05, 0.0]}
measures:
  reach: {type: distance, from: ground.a, to: shank.b}
constraints:
  reach_held: {measure: reach, value: 0.3}
analysis: {start: 0.05, end: 0.15}
"""

JOINT_REACTION_TEXT = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
 <AnalyzeTool name="leg">
  <model_file>leg.osim</model_file>
  <AnalysisSet name="Analyses">
   <objects>
    <JointReaction name="JointReaction">
     <on>true</on>
     <forces_file>forces.sto</forces_file>
     <joint_names>hip knee_j pat_j</joint_names>
     <apply_on_bodies>parent child child</apply_on_bodies>
     <express_in_frame>child shank ground</express_in_frame>
    </JointReaction>
   </objects>
  </AnalysisSet>
 </AnalyzeTool>
</OpenSimDocument>
"""
_JR_VALUES = ("hip", "knee_j", "pat_j", "all", "All", "child", "parent", "ground", "shank", "thigh", "patella",
              "/bodyset/shank", "hip knee_j", "child parent", "child child child child", "true", "false", "", " ",
              "NaN", "1", "..", "/etc/passwd")
_JR_TAGS = ("JointReaction", "joint_names", "apply_on_bodies", "express_in_frame", "on", "objects",
            "AnalysisSet", "Foo")

_EL_VALUES = ("shank", "thigh", "patella", "ground", "/bodyset/shank", "/ground", "hip", "unassigned", "grf.mot",
              "motion.sto", "../grf.mot", "/etc/passwd", "ground_force_v", "ground_force_p", "push_v", "true",
              "false", "True", "", " ", "NaN", "1", "a/b", "..")
_EL_TAGS = ("ExternalForce", "PrescribedForce", "ExternalLoads", "objects", "datafile", "applied_to_body",
            "force_identifier", "point_identifier", "torque_identifier", "isDisabled", "appliesForce", "Foo")


# -- base files -----------------------------------------------------------------------

def _write_grf(path, n=21, rate=100.0):
    """The GRF data file of :data:`EXTERNAL_LOADS_TEXT` (OpenSim's column names)."""
    from ..io.storage import write_storage

    t = np.arange(n) / rate
    s = np.sin(np.pi * t / t[-1])
    cols = {"ground_force_vx": 50 * s, "ground_force_vy": 700 * s, "ground_force_vz": 10 * s,
            "ground_force_px": 0.1 + 0.2 * t, "ground_force_py": 0 * t, "ground_force_pz": 0.05 + 0 * t,
            "ground_torque_x": 0 * t, "ground_torque_y": 3 * s, "ground_torque_z": 0 * t,
            "push_vx": 5 + 0 * t, "push_vy": 0 * t, "push_vz": -2 * s,
            "push_px": 0 * t, "push_py": -0.2 + 0 * t, "push_pz": 0 * t}
    write_storage(path, t, cols, name="grf")


def _write_motion(path, n=21, rate=100.0):
    """A coordinate file (degrees) for every free coordinate of the fuzz ``.osim``."""
    from ..io.storage import write_storage

    t = np.arange(n) / rate
    write_storage(path, t, {"hip_q": 10 * np.sin(2 * t), "knee": -30 + 5 * t}, name="motion", in_degrees=True)


def _write_plates(path, n_frames=40, rate=100.0, ratio=5, seed=3):
    """A C3D (ezc3d) with four markers and four force plates, types 1, 2, 3 and 4, loaded
    by a half-sine stance each, sampled at ``ratio`` × ``rate``."""
    import ezc3d

    rng = np.random.default_rng(seed)
    n = n_frames * ratio
    t = np.arange(n) / (rate * ratio)
    load = np.clip(np.sin(np.pi * (t - 0.05) / 0.25), 0, None) * (t > 0.05)
    per_type = {1: [30 * load, 10 * load, 600 * load, 20 * load, -10 * load, 500 * load],
                2: [30 * load, 10 * load, 600 * load, 2000 * load, -3000 * load, 500 * load],
                3: [10 * load, 10 * load, 5 * load, 5 * load] + [150 * load] * 4,
                4: [0.1 * load, 0.05 * load, 2 * load, 0.2 * load, -0.3 * load, 0.01 * load]}
    kinds = (1, 2, 3, 4)
    values, channel, first = [], np.zeros((8, 4), dtype=int), 1
    for k, kind in enumerate(kinds):
        block = np.array(per_type[kind]) + rng.normal(0, 0.5, (len(per_type[kind]), n))
        channel[:len(block), k] = np.arange(first, first + len(block))
        first += len(block)
        values.append(block)
    values = np.vstack(values)
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["M1", "M2", "M3", "M4"]
    c3d["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c3d["data"]["points"] = np.concatenate((rng.normal(500, 100, (3, 4, n_frames)), np.ones((1, 4, n_frames))))
    analog = c3d["parameters"]["ANALOG"]
    analog["RATE"]["value"] = [rate * ratio]
    analog["LABELS"]["value"] = [f"A{i + 1}" for i in range(len(values))]
    analog["UNITS"]["value"] = ["N"] * 3 + ["mm"] * 2 + ["Nmm"] + ["N"] * 3 + ["Nmm"] * 3 + ["N"] * 8 + ["V"] * 6
    c3d["data"]["analogs"] = values[None]
    fp = c3d["parameters"]["FORCE_PLATFORM"]
    fp["USED"]["value"] = [len(kinds)]
    fp["TYPE"]["value"] = list(kinds)
    fp["ZERO"]["value"] = [1, 4]
    fp["CHANNEL"]["value"] = channel
    fp["CORNERS"]["value"] = np.stack([np.array([[x + 300, 0, 0], [x - 300, 0, 0], [x - 300, 500, 0],
                                                 [x + 300, 500, 0]]).T for x in (0, 700, 1400, 2100)], axis=2)
    fp["ORIGIN"]["value"] = np.array([[0, 0, 0], [1.5, -2.0, -40.0], [120.0, 200.0, -45.0], [1.0, 2.0, -35.0]]).T
    fp["CAL_MATRIX"]["value"] = np.stack([np.eye(6) * (100 if kind == 4 else 1) for kind in kinds], axis=2)
    c3d.write(str(path))


def _write_run(run_dir, model_text):
    """A small ``openfdk run`` in ``run_dir`` (model.yaml, trial.c3d, its result folder),
    and its checkpoint parts kept from a second run that saved a part every 2 frames
    (frames 0 … END_S, 100 Hz)."""
    from ..cli.commands import main
    from ..fixtures.synthetic import synthetic_markers
    from ..io.c3d import write_c3d
    from ..analysis.jobs import run_job
    from ..study.runner import _acquire_lock
    from ..trial.checkpoint import CHECKPOINT_DIR, Checkpoints

    run_dir.mkdir()
    model = run_dir / "model.yaml"
    model.write_text(model_text)
    _, labels, x, _ = synthetic_markers(60, rate=100.0, noise=1e-4)
    write_c3d(run_dir / "trial.c3d", labels, x, 100.0, units="mm")
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        code = main(["run", str(model), str(run_dir / "trial.c3d"), "--out", str(run_dir / RESULTS_DIR),
                     "--no-progress", "--no-plots", "--max-failed", "1", "--end", str(END_S)])
        if code != 0:
            raise RuntimeError(f"the fuzz run exited with {code}")
        ckpt = Checkpoints(run_dir / "ckpt" / CHECKPOINT_DIR, FINGERPRINT, every_frames=2)
        run_job(model, run_dir / "trial.c3d", progress=False, end=END_S, checkpoints=ckpt)
    (run_dir / "lock").mkdir()
    _acquire_lock(run_dir / "lock")


def _write_coordinates(res):
    """A coordinates.csv at the frames of the result folder ``res`` (an angle, a
    translation and a constant angle, SI), as an OpenSim model's run writes it."""
    from ..io.results import read_table, write_table

    t = np.asarray(read_table(res / "kinematics.csv")["time"], dtype=float)
    write_table(res / "coordinates.csv", {"time": t, "hinge_rad": 0.3 * np.sin(4 * t), "slide_m": 0.01 * t,
                                          "fixed_rad": np.full(t.size, 0.2)})


def _write_fdk_run(run_dir):
    """A small FDK run's checkpoint parts in ``run_dir/ckpt`` (a part every 2 frames,
    frames 0 … END_S at 100 Hz): the synthetic TMJ jaw (:data:`FDK_MODEL` and its meshes)
    and a marker trial (trial.c3d)."""
    import yaml

    from ..analysis.jobs import run_job
    from ..fixtures.synthetic_jaw import jaw_fdk_model_dict, jaw_markers, write_jaw_meshes
    from ..io.c3d import write_c3d
    from ..trial.checkpoint import CHECKPOINT_DIR, Checkpoints

    run_dir.mkdir()
    write_jaw_meshes(run_dir / "meshes")
    (run_dir / FDK_MODEL).write_text(yaml.safe_dump(jaw_fdk_model_dict("meshes"), sort_keys=False))
    _, labels, x, _ = jaw_markers(20, noise=1e-4, seed=3)
    write_c3d(run_dir / "trial.c3d", labels, x, 100.0)
    ckpt = Checkpoints(run_dir / "ckpt" / CHECKPOINT_DIR, FINGERPRINT, every_frames=2)
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        run_job(run_dir / FDK_MODEL, run_dir / "trial.c3d", progress=False, end=END_S, checkpoints=ckpt)


def _checkpoint_base(bases, kind, folder):
    """Register the checkpoint parts in ``folder`` as the base files of ``kind``."""
    parts = sorted(folder.glob("part-*.npz"))
    bases.paths[kind] = parts[0]
    bases.originals[kind] = {p: p.read_bytes() for part in parts for p in (part, part.with_suffix(".json"))}


def _write_validation_inputs(d):
    """A run folder ``d/kvrun`` as ``openfdk run`` writes it (kinematics.csv, forces.csv,
    coordinates.csv, measures.csv; one frame failed) and the validation map and
    reference (time in % of the cycle) in ``d/kvfiles``. Returns (map, reference)."""
    from ..io.results import write_table
    from ..io.storage import write_storage

    run, files = d / "kvrun", d / "kvfiles"
    run.mkdir()
    files.mkdir()
    t = np.linspace(0.9, 2.1, 61)
    ok = np.ones(t.size, bool)
    ok[30] = False
    w = 2 * np.pi * (t - VALIDATION_CYCLE[0]) / (VALIDATION_CYCLE[1] - VALIDATION_CYCLE[0])
    msg = ["" if c else "failed" for c in ok]
    write_table(run / "kinematics.csv", {"time": t, "converged": ok, "message": msg})
    write_table(run / "forces.csv", {"time": t, "converged": ok, "status": ["optimal"] * t.size, "message": msg})
    write_table(run / "coordinates.csv", {"time": t, "knee_ty_r_m": 0.012 + 0.002 * np.sin(w),
                                          "knee_flex_r_rad": 0.5 + 0.4 * np.sin(w)})
    write_table(run / "measures.csv", {"time": t, "angles[1]_rad": 0.02 * np.cos(w)})
    p = np.arange(1.0, 101.0)
    wp = 2 * np.pi * p / 100
    write_storage(files / "reference.sto", p, {"knee_sup_r": 0.042 + 0.002 * np.sin(wp),
                                               "knee_rot_r": -(0.5 + 0.3 * np.sin(wp)),
                                               "knee_add_r": np.degrees(0.02 * np.cos(wp))}, name="fluoroscopy")
    (files / "map.yaml").write_text(VALIDATION_MAP_TEXT)
    return files / "map.yaml", files / "reference.sto"


def build(bases, kinds):
    """Write the base files of the new ``kinds`` into ``bases.dir``; fills
    ``bases.paths[kind]`` (the file whose name an error must give) and
    ``bases.originals[kind]`` ({path: bytes} of every file a mutation may change)."""
    from ..fixtures.synthetic import two_body_model_dict
    from .fuzz_inputs import _dump

    d = bases.dir
    kinds = [k for k in kinds if k in NEW_KINDS]
    if {"external_loads", "grf_mot"} & set(kinds):
        (d / "loads.xml").write_text(EXTERNAL_LOADS_TEXT)
        _write_grf(d / "grf.mot")
        bases.paths["external_loads"], bases.paths["grf_mot"] = d / "loads.xml", d / "grf.mot"
    if "joint_reaction" in kinds:
        (d / "jr.xml").write_text(JOINT_REACTION_TEXT)
        (d / "jr.yaml").write_text("joint_reaction: jr.xml\n")
        bases.paths["joint_reaction"] = d / "jr.xml"
    if "sto" in kinds:
        _write_motion(d / "motion.sto")
        bases.paths["sto"] = d / "motion.sto"
    if "overlay" in kinds:
        _write_motion(d / "overlay_motion.sto")
        (d / "overlay.yaml").write_text(OVERLAY_TEXT)
        bases.paths["overlay"] = d / "overlay.yaml"
    if "force_plates" in kinds:
        _write_plates(d / "plates.c3d")
        bases.paths["force_plates"] = d / "plates.c3d"
    if {"results", "checkpoint", "study_lock"} & set(kinds):
        run = d / "run"
        _write_run(run, _dump(two_body_model_dict()))
        res = run / RESULTS_DIR
        _write_coordinates(res)
        bases.paths["results"] = res / "summary.json"
        bases.originals["results"] = {p: p.read_bytes() for p in (res / "summary.json", res / "kinematics.csv",
                                                                  res / "forces.csv", res / "coordinates.csv")}
        _checkpoint_base(bases, "checkpoint", run / "ckpt" / ".checkpoint")
        bases.paths["study_lock"] = run / "lock" / ".study.lock"
        child = subprocess.Popen([sys.executable, "-c", ""])
        child.wait()
        bases.dead_pid = child.pid  # the lock of a study killed on this host (stale, taken over)
    if "checkpoint_fdk" in kinds:
        _write_fdk_run(d / "fdkrun")
        _checkpoint_base(bases, "checkpoint_fdk", d / "fdkrun" / "ckpt" / ".checkpoint")
    if {"validation_map", "validation_reference"} & set(kinds):
        bases.paths["validation_map"], bases.paths["validation_reference"] = _write_validation_inputs(d)
    if "cycles" in kinds:  # a walk's result folder with measured loads (openfdk cycles)
        from ..fixtures.gait_cycles_run import write_cycles_run

        res = d / "cycrun"
        write_cycles_run(res)
        bases.paths["cycles"] = res / "summary.json"
        bases.originals["cycles"] = {p: p.read_bytes() for p in (res / "summary.json", res / "kinematics.csv",
                                                                 res / "forces.csv", res / "coordinates.csv")}
    for kind in kinds:
        if kind not in bases.originals:
            bases.originals[kind] = {bases.paths[kind]: bases.paths[kind].read_bytes()}


# -- mutations ------------------------------------------------------------------------

def mutate_json(text, rng, n_mutations=None):
    """A mutated copy of JSON ``text``: 1–3 mutations of the parsed tree (as for YAML:
    a value of another type, a key deleted, misspelt or added, a list changed; NaN and
    infinities written as JSON's extensions) or of the text."""
    from .fuzz_inputs import _text_mutation, _tree_mutation

    for _ in range(int(rng.integers(1, 4)) if n_mutations is None else n_mutations):
        if rng.random() < 0.75:
            try:
                data = json.loads(text)
            except (ValueError, RecursionError):
                data = None
            if isinstance(data, (dict, list)):
                text = json.dumps(_tree_mutation(data, rng))
                continue
        text = _text_mutation(text, rng)
    return text


def _parameter_records(data):
    """{"GROUP:NAME": (name_pos, name_len, type_pos, data_pos, n_values)} of the C3D
    parameter section of ``data`` (Intel byte order, as ezc3d writes)."""
    start = (data[0] - 1) * 512 if data and data[0] >= 1 else len(data)
    pos, groups, found = start + 4, {}, {}
    while pos + 4 <= len(data):
        n_name, gid = (v - 256 if v > 127 else v for v in data[pos:pos + 2])
        if n_name == 0:
            break
        name_pos, n = pos + 2, abs(n_name)
        off_pos = name_pos + n
        if off_pos + 4 > len(data):
            break
        name = bytes(data[name_pos:off_pos]).decode("latin-1")
        offset = int.from_bytes(data[off_pos:off_pos + 2], "little")
        if gid < 0:
            groups[-gid] = name
        else:
            kind, n_dims = data[off_pos + 2], data[off_pos + 3]
            dims = list(data[off_pos + 4:off_pos + 4 + n_dims])
            found[gid, name] = (name_pos, n, off_pos + 2, off_pos + 4 + n_dims, int(np.prod(dims)) if n_dims else 1,
                                kind - 256 if kind > 127 else kind)
        if offset == 0:
            break
        pos = off_pos + offset
    return {f"{groups.get(g, '?')}:{name}": record for (g, name), record in found.items()}


_PLATE_PARAMETERS = ("FORCE_PLATFORM:USED", "FORCE_PLATFORM:TYPE", "FORCE_PLATFORM:CORNERS",
                     "FORCE_PLATFORM:ORIGIN", "FORCE_PLATFORM:CHANNEL", "FORCE_PLATFORM:CAL_MATRIX",
                     "FORCE_PLATFORM:ZERO", "ANALOG:SCALE", "ANALOG:OFFSET", "ANALOG:UNITS", "ANALOG:USED",
                     "ANALOG:RATE", "ANALOG:GEN_SCALE", "POINT:UNITS", "POINT:RATE")
_PLATE_VALUES = (0.0, -1.0, 1.0, 2.0, 3.0, 4.0, 5.0, 7.0, 27.0, 255.0, 32767.0, -32768.0, 1e30, -1e30, np.nan, np.inf,
                 0.5, 1e-30)


def mutate_plate_parameters(data: bytes, rng, n_mutations=None) -> bytes:
    """A mutated copy of a C3D's bytes whose FORCE_PLATFORM, ANALOG and POINT:UNITS
    parameters are changed in place: a value set to an edge value (stored as the
    parameter's type: int16 or float32, characters replaced), values swapped, the data
    type or a dimension byte changed, or the name misspelt."""
    b = bytearray(data)
    records = _parameter_records(b)
    names = [k for k in _PLATE_PARAMETERS if k in records]
    for _ in range(int(rng.integers(1, 4)) if n_mutations is None else n_mutations):
        if not names:
            break
        name_pos, name_len, type_pos, data_pos, count, kind = records[names[int(rng.integers(len(names)))]]
        size = abs(kind) if kind in (-1, 1, 2, 4) else 1
        op = int(rng.integers(6))
        if op <= 2 and count:                             # a value set to an edge value
            i = data_pos + size * int(rng.integers(count))
            v = float(rng.choice(_PLATE_VALUES))
            if kind == 4:
                b[i:i + 4] = np.float32(v).tobytes()
            elif kind == 2:
                b[i:i + 2] = int(np.clip(v, -32768, 32767) if np.isfinite(v) else -1).to_bytes(2, "little", signed=True)
            elif kind == 1:
                b[i] = int(v) % 256 if np.isfinite(v) else 255
            else:
                b[i] = int(rng.choice(list(b" xNm\x00\xff")))
        elif op == 3 and count > 1:                       # two values swapped
            i, j = (data_pos + size * int(k) for k in rng.choice(count, 2, replace=False))
            b[i:i + size], b[j:j + size] = b[j:j + size], b[i:i + size]
        elif op == 4:                                     # the data type or a dimension byte changed
            k = type_pos + int(rng.integers(2 + max(0, data_pos - type_pos - 2)))
            b[k] = int(rng.choice([0, 1, 2, 3, 4, 6, 255, 254, 128]))
        else:                                             # the name misspelt
            b[name_pos + int(rng.integers(name_len))] = int(rng.choice(list(b"XZ_0 ")))
    return bytes(b)


def _mutate_csv(text, rng):
    """A result table mutated: a cell replaced (number, text, empty, NaN), rows cut
    (mid-row), dropped or repeated, a column name changed, or a character changed."""
    from .fuzz_inputs import _text_mutation, mutate_text

    if rng.random() < 0.5:
        return mutate_text(text, rng, sep=",")
    lines = text.splitlines(keepends=True)
    op = int(rng.integers(3))
    if op == 0 and len(lines) > 1:                       # cut after a row, or mid-row
        k = int(rng.integers(1, len(lines)))
        return "".join(lines[:k]) + lines[k][: int(rng.integers(len(lines[k]) + 1))]
    if op == 1 and lines:                                # a column renamed or removed from the header
        names = lines[0].rstrip("\n").split(",")
        i = int(rng.integers(len(names)))
        names[i] = str(rng.choice(["time", "converged", "message", "", "x", names[i] + "_", "jaw.x_m"]))
        return ",".join(names) + "\n" + "".join(lines[1:])
    return _text_mutation(text, rng)


def _savez(arrays):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


_EDGE_ARRAYS = (np.zeros(0), np.zeros((2, 0)), np.array([np.nan]), np.array(["x"]), np.array([1, 2], dtype=np.int8),
                np.zeros((3, 3, 3)), np.array(1e308), np.array(True), np.array([-1], dtype=np.int64))


def _mutate_part(data, rng):
    """Bytes of a checkpoint part with its JSON structure mutated or one of its arrays
    replaced by an array of another shape or type."""
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    op = rng.random()
    names = sorted(k for k in arrays if k != "structure" and arrays[k].size > 0)
    if op < 0.55 or not names:
        text = mutate_json(arrays["structure"].tobytes().decode("utf-8"), rng)
        arrays["structure"] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    elif op < 0.8:
        arrays[names[int(rng.integers(len(names)))]] = _EDGE_ARRAYS[int(rng.integers(len(_EDGE_ARRAYS)))]
    else:
        # the same shape and type, one entry at an edge value: an index past any matrix
        # or a negative one (pivots, envelope ends, body columns), NaN
        name = names[int(rng.integers(len(names)))]
        a = arrays[name].copy()
        if np.issubdtype(a.dtype, np.integer):
            info = np.iinfo(a.dtype)  # (each edge within the dtype: 10⁶, −1, −10⁶ or its limits)
            a.flat[int(rng.integers(a.size))] = (min(10 ** 6, info.max), max(-1, info.min),
                                                 max(-10 ** 6, info.min))[int(rng.integers(3))]
        elif np.issubdtype(a.dtype, np.floating):
            a.flat[int(rng.integers(a.size))] = (np.nan, np.inf, -1e300)[int(rng.integers(3))]
        arrays[name] = a
    return _savez(arrays)


def _write_part(part, data, rehash):
    """Write ``data`` as the checkpoint ``part``; with ``rehash`` its sidecar's SHA-256
    is made to match (what an attacker who knows the format would do)."""
    part.write_bytes(data)
    if rehash:
        side = part.with_suffix(".json")
        doc = json.loads(side.read_text())
        doc["sha256"] = hashlib.sha256(data).hexdigest()
        side.write_text(json.dumps(doc))


#: the result-folder readers (command names); each mutated result folder goes to one
RESULT_READERS = ("plot", "export-opensim", "view")


def mutate(kind, bases, rng):
    """Write one mutated input of ``kind`` over its base files (restored first). Returns
    the reader the input is for (``results``: one of :data:`RESULT_READERS`), else None."""
    from .fuzz_inputs import mutate_bytes, mutate_text, mutate_xml, mutate_yaml

    restore(kind, bases)
    originals = bases.originals[kind]
    path = bases.paths[kind]
    if kind == "external_loads":
        path.write_text(mutate_xml(EXTERNAL_LOADS_TEXT, rng, values=_EL_VALUES, tags=_EL_TAGS), encoding="utf-8")
    elif kind == "joint_reaction":
        path.write_text(mutate_xml(JOINT_REACTION_TEXT, rng, values=_JR_VALUES, tags=_JR_TAGS), encoding="utf-8")
    elif kind in ("grf_mot", "sto", "validation_reference"):
        path.write_text(mutate_text(originals[path].decode(), rng), encoding="utf-8")
    elif kind in ("validation_map", "overlay"):
        path.write_text(mutate_yaml(originals[path].decode(), rng), encoding="utf-8")
    elif kind == "force_plates":
        data = originals[path]
        path.write_bytes(mutate_plate_parameters(data, rng) if rng.random() < 0.6 else mutate_bytes(data, rng))
    elif kind in ("results", "cycles"):
        files = list(originals)
        target = files[int(rng.choice(len(files), p=[0.4, 0.25, 0.2, 0.15]))]
        text = originals[target].decode()
        target.write_text(mutate_json(text, rng) if target.suffix == ".json" else _mutate_csv(text, rng),
                          encoding="utf-8")
        return RESULT_READERS[int(rng.integers(len(RESULT_READERS)))] if kind == "results" else None
    elif kind in CHECKPOINT_KINDS:
        parts = sorted(p for p in originals if p.suffix == ".npz")
        part = parts[int(rng.integers(len(parts)))]
        op = rng.random()
        if op < 0.3:
            side = part.with_suffix(".json")
            side.write_text(mutate_json(originals[side].decode(), rng))
        elif op < 0.75:
            _write_part(part, _mutate_part(originals[part], rng), rehash=True)
        else:
            _write_part(part, mutate_bytes(originals[part], rng), rehash=op < 0.95)
    elif kind == "study_lock":
        text = originals[path].decode()
        if rng.random() < 0.3:                         # a stale lock: its process is gone, maybe more changed
            text = json.dumps({**json.loads(text), "pid": bases.dead_pid})
            path.write_text(mutate_json(text, rng, int(rng.integers(3))), encoding="utf-8")
        else:
            path.write_text(mutate_json(text, rng), encoding="utf-8")
    else:
        raise ValueError(f"not a new fuzz kind: {kind!r}")
    return None


def restore(kind, bases):
    """Write the base files of ``kind`` back (and remove the parts a resumed run added)."""
    originals = bases.originals[kind]
    if kind in CHECKPOINT_KINDS:
        for p in bases.paths[kind].parent.iterdir():
            if p not in originals:
                p.unlink()
    for p, data in originals.items():
        if not p.exists() or p.read_bytes() != data:
            p.write_bytes(data)


def current_input(kind, bases):
    """{file name: bytes} of the files of ``kind`` that differ from the base (for
    :func:`openfdk.bench.fuzz_inputs.reproduce`)."""
    return {p.name: p.read_bytes() for p, data in bases.originals[kind].items()
            if not p.exists() or p.read_bytes() != data}


# -- loaders and their documented errors ----------------------------------------------

def documented_error(kind):
    """The exception class the loader of ``kind`` raises for bad input."""
    if kind in ("external_loads", "grf_mot", "sto", "joint_reaction", "overlay"):
        from ..model.errors import ModelError

        return ModelError
    if kind == "force_plates":
        from ..io.c3d import C3DError

        return C3DError
    if kind in CHECKPOINT_KINDS:
        from ..trial.checkpoint import CheckpointError

        return CheckpointError
    if kind == "study_lock":
        from ..study.spec import StudyError

        return StudyError
    if kind in ("validation_map", "validation_reference"):
        from ..analysis.kinematics_validation import ValidationError

        return ValidationError
    return ValueError  # results: the plot, export-opensim and view readers' ValueError (ViewError) naming the
    # file; cycles: the result folder's readers' ValueError, or CycleError (a ValueError)


def _results_readers(folder, readers=RESULT_READERS):
    """What the commands ``readers`` read of a result folder: ``plot`` the tables and
    summary, the run's model named in summary.json and the figures' inputs (name, failed
    frames, column groups; drawing is left out, it takes ~1 s); ``export-opensim`` the
    whole export (into a folder beside it); ``view`` the viewer's scene and frames."""
    from ..io.osim import export_opensim
    from ..plots.run import _failed, _name, coordinate_panels
    from ..results.run import read_results
    from ..viewer import view_data

    if "plot" in readers:
        results = read_results(folder)
        results.model()
        _name(results)
        _failed(results)
        results.failed_frames
        for group in (results.bodies, results.markers, results.muscles, results.ligaments, results.reactions,
                      results.fdk_dofs, results.measure_names):
            group()
        coordinate_panels(results)
    if "export-opensim" in readers:
        export_opensim(folder, folder.parent / "export")
    if "view" in readers:
        view_data(folder)


def load(kind, path, reader=None):
    """Load the mutated input of ``kind`` at ``path`` as the command line does
    (``reader``: the result-folder reader :func:`mutate` chose; None: all of them)."""
    if kind == "overlay":
        from ..io.modelfile import load_model_and_settings

        return load_model_and_settings(path)
    if kind in ("external_loads", "grf_mot", "sto", "joint_reaction"):
        from ..io.modelfile import load_model, load_model_and_settings
        from ..io.opensim.overlay import register

        model = path.parent / "leg.osim"
        if kind == "joint_reaction":
            register(model, overlay=path.parent / "jr.yaml")
            return load_model_and_settings(model)
        if kind == "sto":
            register(model, motion=path)
        else:
            # the data file's mutations through the low-pass as well (forces/load_filter.py);
            # the ExternalLoads XML's keep the loads as given
            register(model, external_loads=path.parent / "loads.xml",
                     external_loads_cutoff_hz=6.0 if kind == "grf_mot" else None)
        return load_model(model)
    if kind == "force_plates":
        from ..io.force_plates import read_force_plates

        return read_force_plates(path)
    if kind == "results":
        return _results_readers(path.parent, RESULT_READERS if reader is None else (reader,))
    if kind in CHECKPOINT_KINDS:
        from ..analysis.jobs import run_job
        from ..trial.checkpoint import Checkpoints

        run = path.parent.parent.parent
        ckpt = Checkpoints(path.parent, FINGERPRINT)
        return run_job(run / ("model.yaml" if kind == "checkpoint" else FDK_MODEL), run / "trial.c3d", progress=False,
                       end=END_S, checkpoints=ckpt, resume=True)
    if kind == "study_lock":
        from ..study.runner import _acquire_lock

        lock = _acquire_lock(path.parent)
        os.remove(lock)
        return lock
    if kind in ("validation_map", "validation_reference"):
        from ..analysis.kinematics_validation import csv_text, markdown_table, text_table, validate_kinematics

        files = path.parent
        result = validate_kinematics(files.parent / "kvrun", files / "reference.sto", files / "map.yaml",
                                     VALIDATION_CYCLE, VALIDATION_TOE_OFF)
        return csv_text(result), markdown_table(result), text_table(result)  # the figure is left out (~1 s)
    if kind == "cycles":
        from ..analysis.gait_cycles import csv_text, gait_cycles, strikes_text
        from ..results.run import read_results

        cycles = gait_cycles(read_results(path.parent), "calcn_r")
        return csv_text(cycles), strikes_text(cycles)  # the figure is left out (~1 s)
    raise ValueError(f"not a new fuzz kind: {kind!r}")
