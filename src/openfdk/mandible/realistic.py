"""The realistic virtual experiment: recordings that behave like real ones.

:func:`record_realistic` plays the virtual experiment (:mod:`.experiment`, same true
joint and true motion model) with what real recordings of the paper's protocol do and
the default virtual experiment does not (docs/virtual-experiment.md, "Realistic
recordings"):

* a static trial with the braces holding the mouth open (``STATIC_OPENING_DEG`` = 4.6°,
  within 3–6°), so a registration that assumes occlusion is wrong;
* slow tasks: protrusion period 2.75 s (2.5–3 s), open–close 2 s;
* only 3 open–close cycles (fewer than the study's default 5);
* wide movements (:data:`.experiment.WIDE_AMPLITUDES`): incisal opening ≈ 45 mm,
  protrusion ≈ 10 mm, lateral incisor excursion ≈ 12 mm in chewing;
* non-standard trial file names, declared in a ``trials:`` section that is written into
  ``subject.yaml`` (chewing with a time window, protrusion with its own cycle count:
  3, quick 2);
* extra markers (9 skin markers: 17 in all, as the paper's recordings);
* occasional short marker gaps (0.05–0.25 s, one marker at a time).

The study runs on the folder unchanged: ``openfdk subject study DIR``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from ..io.c3d import write_c3d
from .experiment import (WIDE_AMPLITUDES, load_anatomy, simulate_task, true_marker_positions, truth_geometry,
                         write_truth_csv)
from .subject import SUBJECT_FILE, load_subject
from .truth import TrueJoint, TruthOptions

__all__ = ["EXTRA_MARKERS", "REALISTIC_TRIALS", "STATIC_OPENING_DEG", "record_realistic"]

_MM = 1e-3
STATIC_OPENING_DEG = 4.6
#: task -> (file name, kind, frequency Hz, cycles recorded, cycles recorded when quick)
REALISTIC_TRIALS = {
    "reference": ("S01_static_braces.c3d", "static", None, 0, 0),
    "chewing": ("S01_chew_gum_01.c3d", "chewing", 1.2, 8, 5),
    "protrusion": ("S01_protrusion_slow.c3d", "protrusion", 1.0 / 2.75, 6, 3),
    "open_close": ("S01_open_close_max.c3d", "open_close", 0.5, 3, 3),
}
#: extra (skin) markers: body -> label -> position (mm) in the subject frame at the
#: reference pose; forehead, nose, cheeks and ears on the skull, chin and jaw on the
#: mandible — the study ignores them
EXTRA_MARKERS = {
    "skull": {"Forehead": [95.0, 0.0, 60.0], "Nasion": [100.0, 0.0, 25.0], "Nose_tip": [125.0, 0.0, -15.0],
              "Cheek_R": [75.0, -55.0, -20.0], "Cheek_L": [75.0, 55.0, -20.0],
              "Tragus_R": [5.0, -72.0, 0.0], "Tragus_L": [5.0, 72.0, 0.0]},
    "mandible": {"Chin": [95.0, 0.0, -75.0], "Jaw_R": [40.0, -50.0, -60.0]},
}
GAPS_PER_TRIAL = 4
GAP_S = (0.05, 0.25)


def _trials_section(quick: bool) -> str:
    """The ``trials:`` (and ``registration:``) text appended to subject.yaml."""
    lines = ["", "# realistic virtual recordings (openfdk subject record --realistic)", "trials:"]
    for task, (name, kind, _, _, _) in REALISTIC_TRIALS.items():
        extra = ""
        if task == "chewing":       # a window: quick, all 5 cycles; else it cuts the 7th cycle
            extra = f", window: [0.2, {round(0.5 + 5 / 1.2 + 0.3, 2) if quick else 6.0}]"
        if task == "protrusion":    # this task's own cycle count
            extra = f", cycles: {2 if quick else 3}"
        lines.append(f"  {task}: {{file: trials/{name}, kind: {kind}{extra}}}")
    lines += ["registration: {method: braces, static_trial: reference}", ""]
    return "\n".join(lines)


def _strip_sections(text: str, keys=("trials", "registration")) -> str:
    """subject.yaml text without the top-level blocks ``keys`` (and their comment)."""
    out, skip = [], False
    for line in text.splitlines():
        top = line[:1] not in (" ", "\t", "") and not line.startswith("#")
        if top:
            skip = line.split(":", 1)[0].strip() in keys
        if line.startswith("# realistic virtual recordings"):
            continue
        if not skip:
            out.append(line)
    return "\n".join(out).rstrip() + "\n"


def _gaps(rng, n_frames, n_markers, rate):
    """Mask (n_frames, n_markers) True inside the gaps: GAPS_PER_TRIAL gaps of 0.05–0.25 s,
    one marker at a time, none in the first or last second."""
    mask = np.zeros((n_frames, n_markers), dtype=bool)
    if n_frames < 3 * rate:
        return mask
    for _ in range(GAPS_PER_TRIAL):
        length = int(rng.uniform(*GAP_S) * rate)
        start = int(rng.integers(int(rate), n_frames - int(rate) - length))
        if mask[start : start + length].any():
            continue
        mask[start : start + length, int(rng.integers(n_markers))] = True
    return mask


def record_realistic(directory: str | os.PathLike, *, quick: bool = False, rate: float = 100.0,
                     noise_mm: float = 0.15, head_motion: bool = True, seed: int = 0,
                     truth: TruthOptions | None = None, working_side: str = "l") -> dict:
    """Record the realistic virtual experiment for a generated subject folder.

    Args: directory: a folder written by :func:`openfdk.mandible.create_subject`;
    quick: fewer chewing and protrusion cycles (5 and 3, for tests); rate Hz; noise_mm
    σ per coordinate, mm; head_motion, seed, truth, working_side: as in
    :func:`.experiment.record_experiment`.
    Returns: dict "trials/<file>" / "truth/<task>.csv" / "truth/truth.yaml" /
    "subject.yaml" → Path. ``subject.yaml`` gets a ``trials:`` and a ``registration:``
    section (replacing earlier ones)."""
    directory = Path(directory)
    truth = TruthOptions() if truth is None else truth
    subject_file = directory / SUBJECT_FILE
    subject_file.write_text(_strip_sections(subject_file.read_text(encoding="utf-8")), encoding="utf-8")
    subject = load_subject(directory)
    anatomy = load_anatomy(directory)
    root = np.random.SeedSequence(seed)
    truth_rng, marker_rng, gap_rng, *task_seeds = (np.random.default_rng(s)
                                                   for s in root.spawn(3 + len(REALISTIC_TRIALS)))
    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, subject.cartilage_offset, truth, truth_rng)
    markers_true = true_marker_positions(subject, truth, truth_rng)
    extra = {body: _MM * np.array(list(EXTRA_MARKERS[body].values())) for body in ("skull", "mandible")}
    labels = (subject.marker_labels + tuple(EXTRA_MARKERS["skull"]) + tuple(EXTRA_MARKERS["mandible"]))
    (directory / "trials").mkdir(exist_ok=True)
    (directory / "truth").mkdir(exist_ok=True)
    written = {}
    for (task, (name, kind, frequency, cycles, cycles_quick)), rng in zip(REALISTIC_TRIALS.items(), task_seeds):
        motion = "reference" if kind == "static" else kind
        result = simulate_task(subject, joint, markers_true, motion, cycles=max(1, cycles_quick if quick else cycles),
                               rate=rate, head_motion=head_motion, rng=rng, frequency=frequency,
                               working_side=working_side, amplitudes=WIDE_AMPLITUDES.get(kind),
                               static_opening_deg=STATIC_OPENING_DEG if kind == "static" else 0.0)
        # extra markers ride on the true skull / mandible poses
        skin = np.concatenate([
            result.p_LS[:, None, :] + np.einsum("nij,kj->nki", result.R_LS, extra["skull"]),
            result.p_LM[:, None, :] + np.einsum("nij,kj->nki", result.R_LM, extra["mandible"])], axis=1)
        positions = np.concatenate([result.markers_L, skin], axis=1)
        positions = positions + marker_rng.normal(0.0, noise_mm * _MM, positions.shape)
        if kind != "static":
            positions[_gaps(gap_rng, len(result.time), positions.shape[1], rate)] = np.nan
        path = directory / "trials" / name
        write_c3d(path, labels, positions, rate, units="mm")
        written[f"trials/{name}"] = path
        written[f"truth/{task}.csv"] = write_truth_csv(directory, task, result)
    info = {"realistic": True, "quick": bool(quick), "truth_options": truth.to_dict(), "seed": int(seed),
            "noise_mm": float(noise_mm), "head_motion": bool(head_motion), "rate_hz": float(rate),
            "static_opening_deg": STATIC_OPENING_DEG, "working_side": working_side,
            "trials": {task: {"file": f"trials/{v[0]}", "kind": v[1], "frequency_hz": v[2],
                              "cycles": v[4] if quick else v[3]} for task, v in REALISTIC_TRIALS.items()},
            "amplitudes": WIDE_AMPLITUDES, **truth_geometry(subject, joint, markers_true)}
    (directory / "truth" / "truth.yaml").write_text(yaml.safe_dump(info, sort_keys=False), encoding="utf-8")
    written["truth/truth.yaml"] = directory / "truth" / "truth.yaml"
    with open(subject_file, "a", encoding="utf-8") as fh:
        fh.write(_trials_section(quick))
    load_subject(directory)                      # the written sections must load
    written["subject.yaml"] = subject_file
    return written
