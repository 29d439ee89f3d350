"""Brace registration from a reference trial (as in the paper).

The subject sits still with the teeth in occlusion, so the mandible is in its reference
pose relative to the skull (the subject frame S, where skull and mandible frames
coincide). The skull brace's nominal geometry (subject folder, from the brace scan) is
fitted rigidly to the mean measured skull-brace markers; that pose maps every measured
marker, skull and mandible brace alike, into S. Those registered positions are what the
models and the marker-only "measured" kinematics use.
"""

from __future__ import annotations

import numpy as np

from ..io.c3d import MarkerTrial
from ..io.trials import read_trial
from .experiment import rigid_fit


class RegistrationError(ValueError):
    """The reference trial cannot register the braces; the message says why."""


def register_braces(subject, reference_trial, min_frames=10):
    """Registered brace marker positions in the subject frame S.

    subject : Subject; reference_trial : MarkerTrial or C3D path (static, occluded).
    Returns dict body -> (labels tuple, positions (k, 3) m in S) for "skull" and
    "mandible", and the RMS fit residual of the skull brace (m) under key "rms_m".
    """
    trial = reference_trial if isinstance(reference_trial, MarkerTrial) else read_trial(reference_trial)
    out = {}
    mean = {}
    for body in ("skull", "mandible"):
        labels = subject.braces[body].labels
        x = trial.select(labels).positions  # (n, k, 3)
        counts = np.sum(np.all(np.isfinite(x), axis=2), axis=0)
        if np.any(counts < min_frames):
            bad = [lab for lab, c in zip(labels, counts) if c < min_frames]
            raise RegistrationError(
                f"{trial.source}: markers {bad} are visible in fewer than {min_frames} frames of the "
                f"reference trial; cannot register the {body} brace"
            )
        mean[body] = np.nanmean(x, axis=0)
    R, p = rigid_fit(subject.braces["skull"].positions, mean["skull"][None])
    R, p = R[0], p[0]
    if not np.all(np.isfinite(R)):
        raise RegistrationError(f"{trial.source}: the skull brace markers do not define a pose")
    for body in ("skull", "mandible"):
        out[body] = (subject.braces[body].labels, (mean[body] - p) @ R)  # R_LSᵀ (x − p_LS)
    fit = out["skull"][1] - subject.braces["skull"].positions
    out["rms_m"] = float(np.sqrt(np.mean(np.sum(fit**2, axis=1))))
    return out
