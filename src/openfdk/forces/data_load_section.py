"""The model-file section ``external_loads``: measured loads (ground reactions) from a
sampled file, applied as OpenSim's ExternalForce applies them (:mod:`.data_loads`).

::

    external_loads:
      right_grf:
        body: calcn_r                  # the body the load is applied to
        frame: calcn_r.osim_frame      # the frame of "body" components (default: the body's frame)
        force_frame: world             # world (ground) or body: the force's and torque's components
        point_frame: world             # world or body: the point's components
        file: walk_grf.mot             # an OpenSim .mot/.sto (relative to the model file)
        force: [ground_force_vx, ground_force_vy, ground_force_vz]       # N
        point: [ground_force_px, ground_force_py, ground_force_pz]       # m (default: the frame's origin)
        torque: [ground_torque_x, ground_torque_y, ground_torque_z]      # N m (default: 0)
        cutoff_hz: 6                   # zero-lag low-pass of the samples, Hz (default: none)

The columns are interpolated as OpenSim's ExternalForce interpolates them: by the
natural cubic spline through the samples (its GCVSpline of degree 3, exact at the sample
times), or straight lines between 2 or 3 samples; a frame outside the file's time range
fails with a message naming the load. ``cutoff_hz`` > 0 low-pass filters them first, as the markers are (a ground
reaction as a wrench, on its loaded runs; :mod:`.load_filter`). Without it, a ground
reaction whose samples look unfiltered (their second differences as large as their
first, :func:`~.load_filter.noise_ratio`) is named in a warning.
``openfdk run MODEL.osim TRIAL --external-loads LOADS.xml`` writes this section from
OpenSim's ExternalLoads file (:mod:`openfdk.io.opensim.external_loads`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model.plausibility import RawGroundReactionWarning, warn_plausibility
from ..model.timefunctions import Constant, SplineThroughData
from .data_loads import DataLoad
from .load_filter import NOISY_RATIO, filter_load, noise_ratio

KEYS = ["body", "frame", "force_frame", "point_frame", "file", "force", "point", "torque", "cutoff_hz"]


def _columns(ctx, spec, key, path, columns, required):
    names = spec.get(key)
    if names is None:
        if required:
            raise ctx.error(path, f"missing required key {key!r} (three column names)")
        return None
    if not (isinstance(names, list) and len(names) == 3 and all(isinstance(x, str) for x in names)):
        raise ctx.error(f"{path}.{key}", f"expected three column names, got {names!r}")
    missing = [x for x in names if x not in columns]
    if missing:
        raise ctx.error(f"{path}.{key}", f"{columns.absent(missing[0])} in {spec['file']}")   # StorageColumns
    return np.column_stack([columns[x] for x in names])


#: the largest magnitude of a measured force (N), torque (N·m) and point coordinate (m),
#: and of the force's moment |p| |F| about the origin (N·m), beyond which a sample is no
#: measurement. Force plates saturate at ~40 kN (the largest Kistler/AMTI ranges); real
#: data stay far inside: walking and running ~0.7–3 kN, 0.1 kN·m free moments; a raw
#: OpenSim example GRF (Rajagopal 2016's walk) puts the unloaded point 526 m away (0 N).
#: The bounds also keep every product of the solver's equations far from overflow.
MAX_FORCE_N = 1e6
MAX_TORQUE_N_M = 1e6
MAX_POINT_M = 1e5
MAX_MOMENT_N_M = 1e6
_LIMITS = {"force": (MAX_FORCE_N, "N", "force"), "torque": (MAX_TORQUE_N_M, "N m", "torque"),
           "point": (MAX_POINT_M, "m", "point")}


def _impossible(values, names, label, file, times):
    """The message for the first sample of ``values`` (n, 3) (columns ``names`` of
    ``file``, times ``times`` (n,) s) beyond its physical limit (``_LIMITS[label]``), or ''."""
    limit, unit, what = _LIMITS[label]
    bad = np.abs(values) > limit
    if not bad.any():
        return ""
    k, j = np.argwhere(bad)[0]
    return (f"{names[j]} = {values[k, j]:.4g} {unit} in {file} at t = {times[k]:g} s: beyond {limit:.0e} {unit}, "
            f"not a measured {what}")


def _impossible_moment(F, P, force_names, point_names, file, times):
    """The message for the first sample whose force F (n, 3) N at the point P (n, 3) m
    has a moment about the origin, bounded by |P| |F|, above MAX_MOMENT_N_M, or ''.
    A point far away is possible only while the force is (nearly) zero: at a centre of
    pressure |P| |F| is about the moment the plate measured (a few hundred N m) plus the
    plate's offset from the origin times the force."""
    moment = np.linalg.norm(P, axis=1) * np.linalg.norm(F, axis=1)
    bad = np.flatnonzero(moment > MAX_MOMENT_N_M)
    if not bad.size:
        return ""
    k = int(bad[0])
    j, i = int(np.argmax(np.abs(P[k]))), int(np.argmax(np.abs(F[k])))
    return (f"{point_names[j]} = {P[k, j]:.4g} m with {force_names[i]} = {F[k, i]:.4g} N in {file} at "
            f"t = {times[k]:g} s: a moment of {moment[k]:.3g} N m about the origin, beyond {MAX_MOMENT_N_M:.0e} N m, "
            f"not a measured point of application")


def load_external_loads(b, data, ctx):
    """The ``external_loads`` section into ``b.elements["external_loads"]``."""
    from ..io.storage import read_storage, sample_times_problem

    files = {}
    out = []
    noisy = {}  # file: names of its unfiltered ground reactions that look raw
    for name, spec in ctx.mapping(data or {}, "external_loads").items():
        p = f"external_loads.{name}"
        ctx.keys(spec, p, KEYS, required=("body", "file", "force"))
        body = ctx.string(spec["body"], f"{p}.body")
        try:
            index = b._body_index(body, f"{p}.body")
        except ValueError as exc:
            raise ctx.error(f"{p}.body", str(exc)) from None
        if index == 0:
            raise ctx.error(f"{p}.body", "a load on the ground does nothing; name the body it acts on")
        frame = b.frame(spec.get("frame", body)) if isinstance(spec.get("frame", body), str) else None
        if frame is None or frame.body != body:
            raise ctx.error(f"{p}.frame", f"expected a frame of body {body!r}, got {spec.get('frame')!r}")
        frames = {}
        for key in ("force_frame", "point_frame"):
            frames[key] = ctx.choice(spec.get(key, "world"), f"{p}.{key}", ("world", "body"), "frame")
        file = spec["file"]
        if not isinstance(file, str) or not file:
            raise ctx.error(f"{p}.file", f"expected a file name, got {file!r}")
        path = Path(file) if Path(file).is_absolute() else ctx.base_dir / file
        if path not in files:
            try:
                files[path] = read_storage(path)
            except ValueError as exc:
                raise ctx.error(f"{p}.file", str(exc)) from None
        times, columns, _ = files[path]
        if len(times) < 2:
            raise ctx.error(f"{p}.file", f"{file} has fewer than 2 samples")
        if problem := sample_times_problem(times, file, printed=False):
            raise ctx.error(f"{p}.file", problem)
        F = _columns(ctx, spec, "force", p, columns, True)
        P = _columns(ctx, spec, "point", p, columns, False)
        T = _columns(ctx, spec, "torque", p, columns, False)
        for label, arr in (("force", F), ("point", P), ("torque", T)):
            if arr is not None and not np.all(np.isfinite(arr)):
                k = int(np.flatnonzero(~np.all(np.isfinite(arr), axis=1))[0])
                raise ctx.error(f"{p}.{label}", f"non-finite value in {file} at t = {times[k]:g} s")
            if arr is not None and (problem := _impossible(arr, spec[label], label, file, times)):
                raise ctx.error(f"{p}.{label}", problem)
        if P is not None and (problem := _impossible_moment(F, P, spec["force"], spec["point"], file, times)):
            raise ctx.error(f"{p}.point", problem)
        if P is None and frames["point_frame"] == "world":
            raise ctx.error(f"{p}.point", "a load without a point acts at the frame's origin: set point_frame: body")
        ground_reaction = P is not None and frames["force_frame"] == frames["point_frame"] == "world"
        t = times
        cutoff = ctx.number(spec["cutoff_hz"], f"{p}.cutoff_hz", "Hz", nonnegative=True) if "cutoff_hz" in spec else 0.0
        if cutoff > 0:
            try:
                t, F, P, T = filter_load(times, F, P, T, ground_reaction, cutoff)
            except ValueError as exc:
                raise ctx.error(f"{p}.cutoff_hz", f"{file}: {exc}") from None
        elif ground_reaction and (ratio := noise_ratio(F)) > NOISY_RATIO:
            noisy.setdefault(file, []).append((name, ratio))
        natural = 3 if len(t) >= 4 else 1  # OpenSim's ExternalForce: GCVSpline of degree 3, linear below 4
        out.append(DataLoad(
            name, index, SplineThroughData(t, F, natural=natural),
            Constant(np.zeros(3)) if P is None else SplineThroughData(t, P, natural=natural),
            Constant(np.zeros(3)) if T is None else SplineThroughData(t, T, natural=natural),
            frames["force_frame"], frames["point_frame"], np.asarray(frame.p_BF, float), np.asarray(frame.R_BF, float)))
    for file, loads in noisy.items():
        names = ", ".join(f"{name!r} ({ratio:.2f})" for name, ratio in loads)
        warn_plausibility(
            f"{Path(file).name}: the ground reaction(s) {names} look unfiltered (the RMS of their samples' second "
            f"differences over that of their first, in brackets: smooth data give far less than 1, white noise "
            f"1.7) while the markers are low-pass filtered: filter them alike with cutoff_hz (an overlay's "
            f"external_loads_cutoff_hz, or --external-loads-cutoff), e.g. the markers' 6 Hz", RawGroundReactionWarning)
    b.elements["external_loads"] = out
