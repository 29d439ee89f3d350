"""Brace registration: where the brace markers sit on the skull and on the mandible.

The models and the marker-only "measured" kinematics need each brace marker's position
in its bone's frame: skull markers in the skull frame S, mandible markers in the
mandible frame M (which coincides with S at the reference/CT pose). Two methods:

* **From the subject's braces** (:func:`register_from_braces`, the paper's method:
  Andersen et al. 2017 laser-scanned the braces and registered the scans to the CT).
  The subject folder's ``braces`` *are* the registered positions; a static trial, if
  given, only checks them: each brace's nominal geometry is fitted rigidly to its mean
  measured markers and the RMS residual of each fit is reported (a warning above
  1 mm). The fits also give the mandible's pose in the static trial (e.g. a few degrees
  open when the braces hold the teeth apart), reported, never assumed.
* **From a static trial** (:func:`register_from_static_trial`), for subjects without
  scanned braces: the skull brace's nominal geometry is fitted to the mean measured
  skull markers, which maps every measured marker into S; the mandible markers are then
  carried into M through the mandible's **static pose** in S. That pose is an input
  (:class:`StaticPose`): occlusion (identity) by default — an assumption stated in the
  result, not made silently — or a known pose such as the opening set by the brace
  thickness between the teeth (:meth:`StaticPose.from_opening`,
  :meth:`StaticPose.from_incisal_gap`).

Both return a :class:`Registration` that records the method, the positions, the fit RMS
per brace, the static pose and the assumption; the study writes it to
``registration.yaml`` and ``summary.json``.

**Plausibility of the measured static pose** (:func:`check_static_pose`). A rigid fit
cannot see brace coordinates given in the wrong frame (e.g. the brace scan's frame
instead of the subject frame): both braces fit the static trial as well as before, but
the static pose they measure, T P T⁻¹ instead of P, is the true pose seen from the
wrong frame. So the pose the braces measure is checked against the anatomy: each
condyle must still sit in its fossa (the bone-to-bone joint space, the smallest signed
distance from the condyle mesh to the fossa mesh, within ``PLAUSIBLE_JOINT_SPACE_CHANGE_M``
= 2 mm of its value in the reference pose), and the incisors may be apart by at most
what the braces between the teeth allow (the incisal point at most ``max_incisal_gap``,
default 12 mm, below its reference position and not more than 1 mm above it, where
the teeth would overlap). A failed check is a :class:`RegistrationWarning` with the
numbers; the numbers are in ``registration.yaml`` either way (``static_pose_check``).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ..io.c3d import MarkerTrial
from ..io.trials import read_trial
from .experiment import rigid_fit

__all__ = ["DEFAULT_MAX_INCISAL_GAP_M", "PLAUSIBLE_JOINT_SPACE_CHANGE_M", "PoseCheck", "Registration",
           "RegistrationError", "RegistrationWarning", "StaticPose", "WARN_RMS_M", "check_static_pose",
           "register", "register_braces", "register_from_braces", "register_from_static_trial"]

#: RMS residual of a brace fit above which the registration warns, m
WARN_RMS_M = 1e-3
#: change of a condyle's joint space (static pose vs reference pose) above which the
#: measured static pose is implausible, m ("condyles more than about 2 mm from the fossa")
PLAUSIBLE_JOINT_SPACE_CHANGE_M = 2e-3
#: default largest drop of the incisal point in a static trial (braces between the
#: teeth), m; ``registration.max_incisal_gap`` of subject.yaml sets it per subject
DEFAULT_MAX_INCISAL_GAP_M = 12e-3
#: the incisal point may rise at most this far above its reference position, m (the
#: lower incisor would pass into the upper one)
INCISAL_OVERLAP_M = 1e-3
OCCLUSION_ASSUMPTION = ("the static trial is in occlusion: the mandible is at its reference (CT) pose "
                        "relative to the skull")


class RegistrationError(ValueError):
    """The static trial cannot register or check the braces; the message says why."""


class RegistrationWarning(UserWarning):
    """A brace fit's RMS residual is above 1 mm, or the static pose the brace fits
    measure is anatomically implausible: the braces or the static trial are off."""


@dataclass(frozen=True)
class StaticPose:
    """Pose of the mandible frame M in the skull frame S during a static trial:
    ``R_SM`` (3, 3), ``p_SM`` (3,) m (x_S = R_SM x_M + p_SM); ``description`` says where
    it comes from."""

    R_SM: np.ndarray
    p_SM: np.ndarray
    description: str = "given"

    @classmethod
    def occlusion(cls) -> "StaticPose":
        """The reference pose (identity): teeth in occlusion."""
        return cls(np.eye(3), np.zeros(3), OCCLUSION_ASSUMPTION)

    @classmethod
    def from_opening(cls, subject, opening_deg: float, translation=(0.0, 0.0, 0.0)) -> "StaticPose":
        """The mandible rotated open by ``opening_deg`` (deg, incisor down for > 0) about
        the intercondylar axis (y, through the midpoint of the condyle tops), then
        translated by ``translation`` (3,) m."""
        c = 0.5 * (subject.condyle_top("r") + subject.condyle_top("l"))
        a = np.deg2rad(opening_deg)
        R = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
        p = c - R @ c + np.asarray(translation, dtype=float)
        t_mm = ", ".join(f"{1e3 * v:.3g}" for v in np.asarray(translation, dtype=float))
        return cls(R, p, f"mandible {opening_deg:.3g}° open about the intercondylar axis, translated "
                         f"[{t_mm}] mm")

    @classmethod
    def from_incisal_gap(cls, subject, gap_m: float) -> "StaticPose":
        """The opening about the intercondylar axis that moves the incisal point ``gap_m``
        (m, e.g. the brace thickness between the teeth) down."""
        c = 0.5 * (subject.condyle_top("r") + subject.condyle_top("l"))
        x, _, z = subject.landmarks["incisal_point"] - c
        # drop(a) = z − (−x sin a + z cos a) = gap  →  x sin a − z cos a = r sin(a − ψ) = gap − z,
        # r = √(x² + z²), ψ = atan2(z, x) (the incisor's angle about the axis)
        r, psi = np.hypot(x, z), np.arctan2(z, x)
        if not abs(gap_m - z) <= r:
            raise RegistrationError(f"an incisal gap of {1e3 * gap_m:.3g} mm cannot be reached by "
                                    "opening about the intercondylar axis")
        a = psi + np.arcsin((gap_m - z) / r)
        pose = cls.from_opening(subject, np.rad2deg(a))
        return cls(pose.R_SM, pose.p_SM, f"incisal gap {1e3 * gap_m:.3g} mm ({pose.description})")

    def opening_deg(self) -> float:
        """Rotation angle of R_SM (deg)."""
        return float(np.rad2deg(np.arccos(np.clip(0.5 * (np.trace(self.R_SM) - 1.0), -1.0, 1.0))))


@dataclass(frozen=True)
class PoseCheck:
    """Plausibility of a static pose (:func:`check_static_pose`).

    ``joint_space_m``: side 'r'/'l' → (reference, static) bone-to-bone joint space, m
    (smallest signed distance from the condyle mesh to the fossa mesh; None when no
    condyle vertex lies over the fossa); ``condyle_shift_m``: side → (3,) m
    displacement of the condyle top; ``incisal_gap_m``: drop of the incisal point below
    its reference position, m (positive = teeth apart); ``incisal_shift_m`` (3,) m;
    ``max_incisal_gap_m``: the allowance used; ``problems``: one phrase per failed
    check (empty: plausible)."""

    joint_space_m: dict
    condyle_shift_m: dict
    incisal_gap_m: float
    incisal_shift_m: np.ndarray
    max_incisal_gap_m: float
    problems: tuple

    @property
    def plausible(self) -> bool:
        return not self.problems

    def to_dict(self) -> dict:
        """mm, for registration.yaml."""
        def mm(v):
            return None if v is None else round(1e3 * float(v), 3)

        return {"plausible": self.plausible,
                "joint_space_mm": {side: {"reference": mm(ref), "static": mm(now),
                                          "change": None if now is None else mm(now - ref)}
                                   for side, (ref, now) in self.joint_space_m.items()},
                "condyle_shift_mm": {side: np.round(1e3 * v, 3).tolist() for side, v in self.condyle_shift_m.items()},
                "incisal_gap_mm": mm(self.incisal_gap_m),
                "incisal_shift_mm": np.round(1e3 * self.incisal_shift_m, 3).tolist(),
                "max_incisal_gap_mm": mm(self.max_incisal_gap_m),
                "problems": list(self.problems)}


def _joint_space(subject, side, R, p):
    """Smallest signed distance (m) from the condyle mesh of ``side``, moved by (R, p),
    to the fossa mesh (positive: in front of the fossa, i.e. apart); None when no
    condyle vertex lies over the fossa (every closest point on the fossa's rim)."""
    from ..contact.mesh import surface_mesh
    from ..contact.signed_distance import OpenSurfaceDistance

    fossa = subject.surfaces[f"fossa_{side}"]
    condyle = subject.surfaces[f"condyle_{side}"]
    distance = OpenSurfaceDistance(surface_mesh(fossa.vertices, fossa.faces, fossa.name, repair=False))
    phi, _, valid, _ = distance.query(condyle.vertices @ R.T + p)
    return float(phi[valid].min()) if np.any(valid) else None


def check_static_pose(subject, pose: "StaticPose", max_incisal_gap: float | None = None) -> PoseCheck:
    """Is the mandible's static pose anatomically plausible? (module docstring)

    Args: subject (its condyle and fossa meshes, condyle tops and incisal point);
    pose: the static pose (R_SM, p_SM); max_incisal_gap: largest drop (m) of the
    incisal point the braces allow (default :data:`DEFAULT_MAX_INCISAL_GAP_M`).
    Returns a :class:`PoseCheck`; its ``problems`` name each failed check with numbers."""
    limit = DEFAULT_MAX_INCISAL_GAP_M if max_incisal_gap is None else float(max_incisal_gap)
    R, p = np.asarray(pose.R_SM, float), np.asarray(pose.p_SM, float)
    problems, spaces, shifts = [], {}, {}
    for side, name in (("r", "right"), ("l", "left")):
        reference = _joint_space(subject, side, np.eye(3), np.zeros(3))
        static = _joint_space(subject, side, R, p)
        spaces[side] = (reference, static)
        top = subject.condyle_top(side)
        shifts[side] = R @ top + p - top
        shift = ", ".join(f"{1e3 * v:+.1f}" for v in shifts[side])
        if static is None:
            problems.append(f"the {name} condyle is off its fossa (no condyle vertex lies over the fossa mesh; "
                            f"condyle top moved [{shift}] mm)")
        elif reference is not None and abs(static - reference) > PLAUSIBLE_JOINT_SPACE_CHANGE_M:
            problems.append(f"the {name} condyle is {abs(1e3 * (static - reference)):.1f} mm "
                            f"{'farther from' if static > reference else 'deeper into'} its fossa than in the "
                            f"reference pose (joint space {1e3 * static:.1f} mm, reference {1e3 * reference:.1f} mm; "
                            f"limit {1e3 * PLAUSIBLE_JOINT_SPACE_CHANGE_M:.0f} mm; condyle top moved [{shift}] mm)")
    incisor = subject.landmarks["incisal_point"]
    incisal_shift = R @ incisor + p - incisor
    gap = -float(incisal_shift[2])
    if gap > limit:
        problems.append(f"the incisors are {1e3 * gap:.1f} mm apart, more than the braces allow "
                        f"({1e3 * limit:.0f} mm; registration.max_incisal_gap)")
    elif gap < -INCISAL_OVERLAP_M:
        problems.append(f"the lower incisor is {-1e3 * gap:.1f} mm above its occlusal position "
                        "(the teeth would overlap)")
    return PoseCheck(spaces, shifts, gap, incisal_shift, limit, tuple(problems))


@dataclass(frozen=True)
class Registration:
    """Registered brace markers and how they were obtained.

    ``method``: "braces" or "static_trial"; ``skull`` / ``mandible``: (labels tuple,
    positions (k, 3) m) in the skull frame S / mandible frame M (= S at the reference
    pose); ``rms_m``: body → RMS residual (m) of the brace fit to the static trial (None
    without a static trial); ``static_pose``: the mandible's pose in the static trial
    (measured for "braces", assumed or given for "static_trial"; None without a static
    trial); ``assumption``: what was assumed; ``static_trial``: its file; ``warnings``:
    the messages issued. ``reg["skull"]``, ``reg["mandible"]`` and ``reg["rms_m"]`` (the
    skull fit) work as for a mapping.
    """

    method: str
    skull: tuple
    mandible: tuple
    rms_m: dict
    static_pose: StaticPose | None = None
    assumption: str = ""
    static_trial: str | None = None
    warnings: tuple = field(default_factory=tuple)
    pose_check: PoseCheck | None = None

    def __getitem__(self, key):
        if key in ("skull", "mandible"):
            return getattr(self, key)
        if key == "rms_m":
            return self.rms_m.get("skull")
        raise KeyError(key)

    def to_dict(self) -> dict:
        """A plain mapping for YAML/JSON outputs (mm and deg)."""
        pose = None
        if self.static_pose is not None:
            pose = {"description": self.static_pose.description,
                    "rotation_deg": round(self.static_pose.opening_deg(), 4),
                    "R_SM": np.round(self.static_pose.R_SM, 9).tolist(),
                    "p_SM_mm": np.round(1e3 * self.static_pose.p_SM, 6).tolist()}
        return {
            "method": self.method,
            "static_trial": self.static_trial,
            "assumption": self.assumption,
            "rms_mm": {k: (None if v is None else round(1e3 * v, 6)) for k, v in self.rms_m.items()},
            "static_pose": pose,
            "static_pose_check": None if self.pose_check is None else self.pose_check.to_dict(),
            "markers_mm": {body: {lab: np.round(1e3 * p, 6).tolist() for lab, p in zip(*getattr(self, body))}
                           for body in ("skull", "mandible")},
            "warnings": list(self.warnings),
        }


def _static_markers(subject, trial, min_frames):
    """Measured brace markers per frame, body → (n, k, 3) m (lab frame, NaN = missing)."""
    trial = trial if isinstance(trial, MarkerTrial) else read_trial(trial)
    out = {}
    for body in ("skull", "mandible"):
        labels = subject.braces[body].labels
        x = trial.select(labels).positions  # (n, k, 3)
        counts = np.sum(np.all(np.isfinite(x), axis=2), axis=0)
        if np.any(counts < min_frames):
            bad = [lab for lab, c in zip(labels, counts) if c < min_frames]
            raise RegistrationError(
                f"{trial.source}: markers {bad} are visible in fewer than {min_frames} frames of the "
                f"static trial; cannot register the {body} brace")
        out[body] = x
    return trial, out


def _fit(nominal, measured, source, body):
    """Per-frame rigid fits of nominal (k, 3) to measured (n, k, 3): R (n, 3, 3),
    p (n, 3) m, and the RMS residual over every visible marker sample (m)."""
    R, p = rigid_fit(nominal, measured)
    if not np.any(np.isfinite(R[:, 0, 0])):
        raise RegistrationError(f"{source}: the {body} brace markers do not define a pose in any frame")
    residual = np.einsum("nij,kj->nki", R, nominal) + p[:, None, :] - measured
    rms = float(np.sqrt(np.nanmean(np.sum(residual ** 2, axis=2))))
    return R, p, rms


def _mean_rotation(R):
    """The rotation (3, 3) closest to the mean of the finite matrices R (n, 3, 3)."""
    U, _, Vt = np.linalg.svd(np.nanmean(R, axis=0))
    return U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt


def _warn(messages, body, rms, source, warn_rms):
    if rms > warn_rms:
        msg = (f"{source}: the {body} brace fits the static trial with an RMS of {1e3 * rms:.2f} mm "
               f"(> {1e3 * warn_rms:.2g} mm): check the brace positions in subject.yaml and the static trial")
        warnings.warn(msg, RegistrationWarning, stacklevel=3)
        messages.append(msg)


def register_from_braces(subject, static_trial=None, *, warn_rms=WARN_RMS_M, min_frames=10,
                         max_incisal_gap=None) -> Registration:
    """Registration from the subject's scanned braces (``subject.braces``, the paper's method).

    Args:
        subject : Subject; its braces are the marker positions (m) in the skull and
            mandible frames.
        static_trial : optional MarkerTrial or C3D path of a static trial, used only to
            check the braces: each brace is fitted to its mean measured markers; the RMS
            of each fit is reported and a :class:`RegistrationWarning` is issued above
            ``warn_rms`` (m). The mandible's static pose is measured from the two fits
            and checked (:func:`check_static_pose`, ``max_incisal_gap`` m); an
            implausible pose is a :class:`RegistrationWarning` with the numbers.
    Returns: :class:`Registration` (method "braces").
    """
    skull = (subject.braces["skull"].labels, np.array(subject.braces["skull"].positions))
    mandible = (subject.braces["mandible"].labels, np.array(subject.braces["mandible"].positions))
    if static_trial is None:
        return Registration("braces", skull, mandible, {"skull": None, "mandible": None},
                            assumption="none: the braces of subject.yaml are used unchecked (no static trial)")
    trial, x = _static_markers(subject, static_trial, min_frames)
    R_LS, p_LS, rms_s = _fit(skull[1], x["skull"], trial.source, "skull")
    R_LM, p_LM, rms_m = _fit(mandible[1], x["mandible"], trial.source, "mandible")
    messages = []
    _warn(messages, "skull", rms_s, trial.source, warn_rms)
    _warn(messages, "mandible", rms_m, trial.source, warn_rms)
    # static pose of M in S per frame, R_SM = R_LSᵀ R_LM, p_SM = R_LSᵀ (p_LM − p_LS); mean
    R_SM = np.einsum("nji,njk->nik", R_LS, R_LM)
    p_SM = np.einsum("nji,nj->ni", R_LS, p_LM - p_LS)
    pose = StaticPose(_mean_rotation(R_SM), np.nanmean(p_SM, axis=0), "measured by the brace fits")
    check = check_static_pose(subject, pose, max_incisal_gap)
    if check.problems:
        msg = (f"{trial.source}: the static pose measured by the brace fits is implausible: "
               + "; ".join(check.problems)
               + f" (pose: {pose.opening_deg():.2f}° rotation, translation "
               + "[" + ", ".join(f"{1e3 * v:.1f}" for v in pose.p_SM) + "] mm). The brace fits alone cannot "
               "see this: check that both braces in subject.yaml are in the subject frame, not the brace "
               "scan's frame (docs/subject-folder.md, 'braces')")
        warnings.warn(msg, RegistrationWarning, stacklevel=2)
        messages.append(msg)
    return Registration("braces", skull, mandible, {"skull": rms_s, "mandible": rms_m}, pose,
                        "none: the braces of subject.yaml are the registered positions; the static trial "
                        "only checks them", str(trial.source), tuple(messages), check)


def register_from_static_trial(subject, static_trial, static_pose: StaticPose | None = None, *,
                               warn_rms=WARN_RMS_M, min_frames=10) -> Registration:
    """Registration from a static trial, for subjects without scanned braces.

    The skull brace's nominal geometry (subject folder) is fitted rigidly to the mean
    measured skull markers (pose R_LS, p_LS); every measured marker is expressed in S,
    x_S = R_LSᵀ (x_L − p_LS); the mandible markers are carried into M through the static
    pose, x_M = R_SMᵀ (x_S − p_SM).

    Args:
        subject : Subject (skull brace geometry; the mandible brace only for its labels).
        static_trial : MarkerTrial or C3D path.
        static_pose : the mandible's pose in the static trial; None assumes occlusion
            and says so in the result's ``assumption``.
    Returns: :class:`Registration` (method "static_trial"); ``rms_m["skull"]`` is the
    skull-brace fit, ``rms_m["mandible"]`` how far the registered mandible markers lie
    from the subject's nominal mandible brace after a rigid fit (m).
    """
    pose = static_pose if static_pose is not None else StaticPose.occlusion()
    assumption = pose.description if static_pose is None else f"static pose given: {pose.description}"
    trial, x = _static_markers(subject, static_trial, min_frames)
    R_LS, p_LS, rms_s = _fit(subject.braces["skull"].positions, x["skull"], trial.source, "skull")
    # every marker in S per frame, x_S = R_LSᵀ (x_L − p_LS), then the mean over frames
    x_S = {body: np.nanmean(np.einsum("nji,nkj->nki", R_LS, x[body] - p_LS[:, None, :]), axis=0)
           for body in ("skull", "mandible")}
    x_M = (x_S["mandible"] - pose.p_SM) @ pose.R_SM                              # R_SMᵀ (x_S − p_SM)
    _, _, rms_m = _fit(subject.braces["mandible"].positions, x_M[None], trial.source, "mandible")
    messages = []
    _warn(messages, "skull", rms_s, trial.source, warn_rms)
    return Registration("static_trial", (subject.braces["skull"].labels, x_S["skull"]),
                        (subject.braces["mandible"].labels, x_M), {"skull": rms_s, "mandible": rms_m},
                        pose, assumption, str(trial.source), tuple(messages))


def register(subject, static_trial=None, method: str = "braces", static_pose: StaticPose | None = None,
             **kw) -> Registration:
    """Dispatch: ``method`` "braces" (:func:`register_from_braces`) or "static_trial"
    (:func:`register_from_static_trial`, which needs ``static_trial``)."""
    if method == "braces":
        if static_pose is not None:
            raise RegistrationError("a static pose is only used by the static_trial registration")
        return register_from_braces(subject, static_trial, **kw)
    if method == "static_trial":
        if static_trial is None:
            raise RegistrationError("the static_trial registration needs a static trial")
        kw.pop("max_incisal_gap", None)             # the static pose is an input there, not measured
        return register_from_static_trial(subject, static_trial, static_pose, **kw)
    raise RegistrationError(f"unknown registration method {method!r}; expected 'braces' or 'static_trial'")


def register_braces(subject, reference_trial, min_frames=10) -> Registration:
    """Static-trial registration assuming occlusion (the method before the ``braces``
    default; kept for scripts): :func:`register_from_static_trial` with no static pose."""
    return register_from_static_trial(subject, reference_trial, None, min_frames=min_frames)
