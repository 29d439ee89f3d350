"""Long trials in parallel: split the analysed frames into K contiguous segments, solve
each independently, drop the warm-up frames and stitch.

Every frame's solution depends only on the measured markers at that frame and its two
neighbours (Eq. 7: δ̇, δ̈ by central differences over t ± Δt; FDK solves positions at
t − Δt, t, t + Δt with the frame's own α), and each frame is solved to a tolerance
(marker tracking to its Gauss–Newton tolerance, FDK to max |f^FDK| < tolerance). So a
segment solved on its own gives the serial result to tolerance provided each kept
frame sees its real neighbours. Segment k keeps frames [a_k, b_k) and solves

    [max(0, a_k − overlap − 1), min(n, b_k + 1))

— ``overlap`` warm-up frames (default 5) in which FDK's α extrapolation and the
recruitment warm start settle, one more frame so the first kept frame has its left
neighbour, and one frame after the end for the right neighbour — then drops everything
outside [a_k, b_k). Markers are filtered over the whole trial in every segment (the
zero-lag Butterworth filter is not local), exactly as in the serial run.
"""

from __future__ import annotations

import itertools
import time as _time
from dataclasses import dataclass, field, fields, replace

import numpy as np

from .defaults import DEFAULT_OVERLAP


@dataclass(frozen=True)
class Segment:
    """Frames of one chunk: keep [keep_start, keep_stop), solve [solve_start, solve_stop)
    (indices into the analysed times)."""

    index: int
    keep_start: int
    keep_stop: int
    solve_start: int
    solve_stop: int


#: a cut's cold start is good enough when its preference is at least this fraction of
#: the trial's largest (plan_segments)
DEEP_ENOUGH = 0.5


def plan_segments(n_frames: int, chunks: int, overlap: int = DEFAULT_OVERLAP, preference=None) -> list:
    """K contiguous segments covering n_frames frames (module docstring for the solved
    ranges): of near-equal length, or with ``preference`` (n_frames,) — how good a cold
    start each frame is (:func:`openfdk.study.boundaries.cut_preference`: how deep in a
    stance) — each cut moved to the cut nearest the equal split, within half a chunk's
    length, whose segment's cold start (``overlap`` + 1 frames before the cut) has a
    preference of at least :data:`DEEP_ENOUGH` × the largest (the equal split when no
    cut in reach has). Raises ValueError for chunks < 1 or > n_frames."""
    if not isinstance(chunks, (int, np.integer)) or chunks < 1:
        raise ValueError(f"chunks must be a whole number >= 1, got {chunks!r}")
    if chunks > n_frames:
        raise ValueError(f"cannot split {n_frames} frames into {chunks} chunks (at most one chunk per frame)")
    if overlap < 0:
        raise ValueError(f"overlap must be >= 0 frames, got {overlap}")
    edges = np.linspace(0, n_frames, chunks + 1).round().astype(int)
    if preference is not None and chunks > 1:
        edges = _preferred_edges(edges, np.asarray(preference, dtype=float), overlap)
    return [Segment(k, int(a), int(b), max(0, int(a) - overlap - 1), min(n_frames, int(b) + 1))
            for k, (a, b) in enumerate(itertools.pairwise(edges))]


def _preferred_edges(edges, preference, overlap):
    """The equal split's ``edges`` (K + 1,) with each interior cut moved (plan_segments)."""
    out = edges.copy()
    half = max(1, int((edges[1] - edges[0]) // 2))
    threshold = DEEP_ENOUGH * float(np.max(preference)) if len(preference) else 0.0
    for k in range(1, len(edges) - 1):
        lo, hi = max(out[k - 1] + 1, edges[k] - half), min(edges[k + 1] - 1, edges[k] + half)
        cuts = np.arange(lo, hi + 1)
        starts = np.clip(cuts - overlap - 1, 0, len(preference) - 1)
        good = cuts[preference[starts] >= max(threshold, 1e-300)]
        if len(good):
            out[k] = good[np.argmin(np.abs(good - edges[k]))]
    return out


def analysis_inputs(model, trial_path=None, cutoff_hz=None, start=None, end=None, settings=None):
    """(trajectories or None, times (nf,) s, info) exactly as :func:`openfdk.analysis.jobs.run_job`
    chooses them (:func:`openfdk.analysis.jobs.analysis_inputs`; settings : the model file's
    AnalysisSettings)."""
    from ..analysis.jobs import analysis_inputs as inputs

    return inputs(model, trial_path, cutoff_hz, start, end, settings)


@dataclass(frozen=True)
class SegmentResult:
    """segment; kinematics : KinematicsResult; forces : InverseDynamicsResult; fdk :
    FDKResult or None (no FDK DOFs); wall_time : s; info : input description (model,
    trial, rate, markers) for the summary."""

    segment: Segment
    kinematics: object
    forces: object
    fdk: object
    wall_time: float
    info: dict = field(default_factory=dict)


def analyse(model, trajectories, times, settings=None):
    """Kinematics, inverse dynamics and (when the model has FDK DOFs) FDK over ``times``
    (nf,) s with ``settings`` (AnalysisSettings), as :func:`openfdk.analysis.jobs.run_job` does
    (one pass of the trial driver). Returns (kin, dyn, fdk or None)."""
    from ..analysis.run import run_trial

    return run_trial(model, trajectories, times, settings=settings)


def solve_segment(model, trajectories, times, segment: Segment, info=None, settings=None) -> SegmentResult:
    """Analyse the solved range of one segment (times: all analysed times (nf,) s)
    with ``settings`` (AnalysisSettings)."""
    t0 = _time.perf_counter()
    kin, dyn, fdk = analyse(model, trajectories, times[segment.solve_start:segment.solve_stop], settings)
    return SegmentResult(segment, kin, dyn, fdk, _time.perf_counter() - t0, dict(info or {}))


# -- stitching -----------------------------------------------------------------------

#: per-frame fields of each result kind. Messages are not among them: they are made from
#: the structured reports with the trial's frame numbers (openfdk.trial.status).
_PER_FRAME = {
    "KinematicsResult": ("time", "q", "v", "vdot", "marker_residual", "constraint_violation", "iterations",
                         "converged", "reports"),
    "InverseDynamicsResult": ("time", "forces", "muscle_length", "muscle_speed", "muscle_strength", "muscle_passive",
                              "ligament_length", "ligament_strain", "ligament_force", "spring_force", "converged",
                              "status", "reports", "iterations"),
    "FDKResult": ("alpha", "f_fdk", "converged", "iterations", "evaluations", "jacobians", "restarts", "backward",
                  "reports"),
}


def _join(parts):
    if isinstance(parts[0], np.ndarray):
        out = np.concatenate(parts, axis=0)
        out.setflags(write=False)  # results are immutable, stitched ones too
        return out
    return tuple(x for p in parts for x in p)


def _stitch_object(objects, segments, wall_time, extra_columns=None):
    """One result object from per-segment ones: per-frame fields are the kept slices
    concatenated, the others are taken from the first segment."""
    kind = type(objects[0]).__name__
    per_frame = _PER_FRAME[kind]
    changes = {}
    for name in per_frame:
        parts = []
        for obj, seg in zip(objects, segments):
            lo, hi = seg.keep_start - seg.solve_start, seg.keep_stop - seg.solve_start
            parts.append(getattr(obj, name)[lo:hi])
        changes[name] = _join(parts)
    if "wall_time" in {f.name for f in fields(objects[0])}:
        changes["wall_time"] = wall_time
    if extra_columns is not None:
        changes["extra"] = {**objects[0].extra, "columns": extra_columns}
    return replace(objects[0], **changes)


def _stitch_columns(forces, segments):
    """forces.extra["columns"] (name -> per-frame values) stitched; a column missing in a
    segment is NaN (numbers) or '' (text) there."""
    names = []
    for f in forces:
        names += [k for k in f.extra.get("columns", {}) if k not in names]
    out = {}
    for name in names:
        parts = []
        sample = next(f.extra["columns"][name] for f in forces if name in f.extra.get("columns", {}))
        textual = not isinstance(sample, np.ndarray)
        for f, seg in zip(forces, segments):
            lo, hi = seg.keep_start - seg.solve_start, seg.keep_stop - seg.solve_start
            col = f.extra.get("columns", {}).get(name)
            if col is None:
                parts.append([""] * (hi - lo) if textual else np.full(hi - lo, np.nan))
            else:
                parts.append(list(col[lo:hi]) if textual else np.asarray(col)[lo:hi])
        out[name] = [x for p in parts for x in p] if textual else np.concatenate(parts)
    return out


def stitch(results, wall_time=None):
    """(kin, dyn, fdk or None) of the whole trial from the SegmentResults of every
    segment (any order). wall_time (s) is stored in the results (default: the sum of
    the segments' wall times)."""
    results = sorted(results, key=lambda r: r.segment.index)
    segs = [r.segment for r in results]
    for a, b in itertools.pairwise(segs):
        if a.keep_stop != b.keep_start:
            raise ValueError(f"segments {a.index} and {b.index} do not join (frames {a.keep_stop} and {b.keep_start})")
    if segs[0].keep_start != 0:
        raise ValueError("the first segment does not start at frame 0: a segment result is missing")
    wall = float(sum(r.wall_time for r in results)) if wall_time is None else float(wall_time)
    kin = _stitch_object([r.kinematics for r in results], segs, wall)
    dyn = _stitch_object([r.forces for r in results], segs, wall, _stitch_columns([r.forces for r in results], segs))
    fdk = None
    if results[0].fdk is not None:
        fdk = _stitch_object([r.fdk for r in results], segs, wall)
        fdk = replace(fdk, kinematics=kin, forces=dyn)
        # kinematics.alpha holds the first frame's α (as run_fdk stores it)
        kin = replace(kin, alpha=fdk.alpha[0].copy())
        fdk = replace(fdk, kinematics=kin)
    return kin, dyn, fdk


def chunk_info(results, overlap):
    """Summary entries of a chunked run (a later segment's ``cold_start_in_stance`` when
    the trial has a stance of the FDK limb, :func:`openfdk.study.case.cold_start_info`)."""
    results = sorted(results, key=lambda r: r.segment.index)
    return {
        "chunks": len(results),
        "overlap_frames": int(overlap),
        "segments": [{"keep": [r.segment.keep_start, r.segment.keep_stop],
                      "solved": [r.segment.solve_start, r.segment.solve_stop],
                      # the first kept frame's time, and where the segment started cold
                      "keep_from_s": float(r.kinematics.time[r.segment.keep_start - r.segment.solve_start]),
                      "cold_start_s": float(r.kinematics.time[0]),
                      **({"cold_start_in_stance": r.info["cold_start_in_stance"]}
                         if "cold_start_in_stance" in (r.info or {}) else {}),
                      "wall_time_s": r.wall_time} for r in results],
    }
