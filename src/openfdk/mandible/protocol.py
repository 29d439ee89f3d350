"""The study protocol of a subject folder: the optional sections of ``subject.yaml`` that
say how the mandible study uses the subject (docs/subject-folder.md, "Study sections").

* ``trials``: task → C3D file, kind, optional time window and cycle count. Without the
  section the defaults are ``trials/reference.c3d`` (the static trial) and
  ``trials/{chewing,protrusion,open_close}.c3d``.
* ``registration``: ``method`` "braces" (default: the braces of subject.yaml are the
  registered markers; the static trial only checks them) or "static_trial" (with an
  optional known ``static_pose``); see :mod:`.registration`.
* ``condyle_point``: the landmark per side whose kinematics Table 1 compares (default
  the condyle tops).
* ``muscle_calibration``: the pose in which the fibres are at their optimal length
  (tendon slack lengths, :func:`.models.calibrated_tendon_slack`), and the muscles'
  parallel-elastic strain at F0 (``passive_strain``).
* ``hyoid``: the muscles whose lower end is on the hyoid and the fraction of the
  mandible's motion the hyoid follows (:mod:`.models`).
* ``contact``: ``max_depth`` of the FDK model's condyle–fossa contacts (vertices
  deeper than it are ignored; default 3 mm, the model file's default).

:func:`parse_protocol` reads them (positions and lengths converted to SI, angles to
rad); every problem names the file and the entry.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

__all__ = ["DEFAULT_TRIALS", "PROTOCOL_KEYS", "StudyProtocol", "TASK_KINDS", "TrialSpec",
           "parse_protocol"]

#: kinds of movement task; "static" is a static (registration) trial
TASK_KINDS = ("chewing", "protrusion", "open_close")
STATIC = "static"
#: trials of a subject folder without a ``trials`` section: task → (file, kind)
DEFAULT_TRIALS = {"reference": ("trials/reference.c3d", STATIC),
                  **{k: (f"trials/{k}.c3d", k) for k in TASK_KINDS}}
#: top-level keys of subject.yaml read here
PROTOCOL_KEYS = ("trials", "registration", "condyle_point", "muscle_calibration", "hyoid", "contact")
#: defaults of the muscle calibration pose (deg, mm) and of the hyoid's following fraction
CALIBRATION_OPENING_DEG = 22.5
CALIBRATION_TRANSLATION_MM = (10.0, 0.0, -5.5)
HYOID_FOLLOW = 0.5
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


@dataclass(frozen=True)
class TrialSpec:
    """One trial of the study: ``task`` name, ``kind`` (a :data:`TASK_KINDS` entry or
    "static"), ``file`` (absolute Path), ``relative`` (as written, relative to the
    subject folder), ``window`` (start, end) s or None (whole record), ``cycles`` int,
    "all" or None (the study's default), ``declared`` (from a ``trials`` section)."""

    task: str
    kind: str
    file: Path
    relative: str
    window: tuple | None = None
    cycles: int | str | None = None
    declared: bool = False


@dataclass(frozen=True)
class StudyProtocol:
    """The study sections of subject.yaml (SI: m, rad).

    ``trials``: task → :class:`TrialSpec` in file order; ``registration_method``:
    "braces" or "static_trial"; ``static_trial``: task name of the static trial used
    (None: none); ``static_pose``: None, ``{"opening": rad, "translation": (3,) m}``,
    ``{"rotation": (3, 3), "translation": (3,) m}`` or ``{"incisal_gap": m}``;
    ``max_incisal_gap``: m or None (the registration check's default); ``condyle_points``: 'r'/'l' → landmark name;
    ``calibration_opening`` rad and ``calibration_translation`` (3,) m;
    ``hyoid_muscles``: tuple of names or None (named like supra-hyoid muscles);
    ``hyoid_follow``: fraction in [0, 1]; ``contact_max_depth``: m or None (the model
    file's default, 3 mm); ``passive_strain``: the muscles' parallel-elastic strain at
    F0 or None (the models' default); ``file``: subject.yaml path (for messages).
    """

    trials: MappingProxyType
    registration_method: str = "braces"
    static_trial: str | None = None
    static_pose: dict | None = None
    max_incisal_gap: float | None = None
    condyle_points: MappingProxyType = field(
        default_factory=lambda: MappingProxyType({"r": "condyle_top_r", "l": "condyle_top_l"}))
    calibration_opening: float = float(np.deg2rad(CALIBRATION_OPENING_DEG))
    calibration_translation: tuple = tuple(1e-3 * float(v) for v in CALIBRATION_TRANSLATION_MM)
    hyoid_muscles: tuple | None = None
    hyoid_follow: float = HYOID_FOLLOW
    file: Path | None = None
    contact_max_depth: float | None = None
    passive_strain: float | None = None

    @property
    def tasks(self) -> tuple:
        """Movement task names (every trial that is not static), in file order."""
        return tuple(t for t, spec in self.trials.items() if spec.kind != STATIC)

    def trial(self, task: str) -> TrialSpec:
        """The :class:`TrialSpec` of ``task``; KeyError naming the known tasks."""
        if task not in self.trials:
            raise KeyError(f"{self.file}: no trial {task!r}; the subject's trials are {list(self.trials)}")
        return self.trials[task]

    def missing_files(self, tasks=None) -> list[str]:
        """One message per trial of ``tasks`` (default all, the static trial included)
        whose C3D file does not exist, naming the task and the file."""
        wanted = list(self.trials) if tasks is None else [t for t in self.trials if t in tasks or t == self.static_trial]
        out = []
        for task in wanted:
            spec = self.trials[task]
            if spec.file.is_file():
                continue
            if spec.declared:
                out.append(f"{self.file}: trials.{task}: file {spec.relative!r} not found in {spec.file.parent}")
            else:
                out.append(f"{self.file.parent}: task {task!r}: trial file {spec.relative} is missing "
                           "(name the recordings in a trials: section of subject.yaml, docs/subject-folder.md)")
        return out


def _trials(ctx, data, directory: Path) -> dict:
    if data is None:
        return {task: TrialSpec(task, kind, directory / rel, rel) for task, (rel, kind) in DEFAULT_TRIALS.items()}
    data = ctx.mapping(data, "trials")
    if not data:
        raise ctx.error("trials", "no trials listed")
    out = {}
    for task, entry in data.items():
        where = f"trials.{task}"
        task = str(task)
        if not _NAME.match(task):
            raise ctx.error(where, "a task name may hold letters, digits, '_', '-' and '.' only (it names a folder)")
        if isinstance(entry, str):
            entry = {"file": entry}
        entry = ctx.mapping(entry, where, allowed={"file", "kind", "window", "cycles"}, required=("file",))
        rel = entry["file"]
        if not isinstance(rel, str) or not rel:
            raise ctx.error(f"{where}.file", f"expected a C3D file name (relative to the subject folder), got {rel!r}")
        default_kind = task if task in TASK_KINDS else STATIC if task == "reference" else None
        kind = entry.get("kind", default_kind)
        if kind is None:
            raise ctx.error(where, f"missing 'kind' (one of {list(TASK_KINDS) + [STATIC]}) for the user-named task")
        if kind not in TASK_KINDS + (STATIC,):
            raise ctx.error(f"{where}.kind", f"unknown kind {kind!r}; expected one of {list(TASK_KINDS) + [STATIC]}")
        window = None
        if "window" in entry:
            w = ctx.vector(entry["window"], f"{where}.window", n=2)
            if not 0 <= w[0] < w[1]:
                raise ctx.error(f"{where}.window", f"expected [start, end] in s with 0 ≤ start < end, got {list(w)}")
            window = (float(w[0]), float(w[1]))
        cycles = entry.get("cycles")
        if cycles is not None and cycles != "all" and (isinstance(cycles, bool) or not isinstance(cycles, int)
                                                       or cycles < 1):
            raise ctx.error(f"{where}.cycles", f"expected a whole number ≥ 1 or 'all', got {cycles!r}")
        if kind == STATIC and (window is not None or cycles is not None):
            raise ctx.error(where, "a static trial takes no window or cycles")
        out[task] = TrialSpec(task, kind, directory / rel, rel, window, cycles, True)
    return out


#: keys of a static pose given as registration.yaml reports it (``R_SM``, ``p_SM_mm``;
#: ``description`` and ``rotation_deg`` are accepted so that the block can be pasted)
_REPORTED_POSE = {"R_SM", "p_SM_mm", "description", "rotation_deg"}


def _rotation(ctx, value, where) -> np.ndarray:
    """A proper rotation matrix (3, 3) from a list of 3 rows, orthonormal to 1e-3 (rounded
    digits), made exactly orthonormal (the closest rotation, SVD)."""
    from ..io.yamlfile import YamlContext

    R = YamlContext.vector(ctx, value, where, None, (3, 3))
    if np.max(np.abs(R @ R.T - np.eye(3))) > 1e-3 or np.linalg.det(R) <= 0:
        raise ctx.error(where, "expected a rotation matrix (3 orthonormal rows, determinant +1)")
    U, _, Vt = np.linalg.svd(R)                 # remove the round-off of the printed digits
    return U @ Vt


def _static_pose(ctx, data, where):
    """``{incisal_gap}``, ``{opening, translation}``, ``{rotation, translation}`` (a 3 × 3
    matrix and the file's length unit) or registration.yaml's ``{R_SM, p_SM_mm}``."""
    data = ctx.mapping(data, where, allowed={"opening", "rotation", "translation", "incisal_gap"} | _REPORTED_POSE)
    given = set(data)
    if "incisal_gap" in given:
        if given != {"incisal_gap"}:
            raise ctx.error(where, "give either incisal_gap or opening/translation, not both")
        return {"incisal_gap": ctx.length * ctx.number(data["incisal_gap"], f"{where}.incisal_gap", low=0.0)}
    if given & _REPORTED_POSE:
        if not {"R_SM", "p_SM_mm"} <= given or given - _REPORTED_POSE:
            raise ctx.error(where, "the form registration.yaml reports needs R_SM (3 rows) and p_SM_mm (mm), "
                                   "without opening/rotation/translation")
        return {"rotation": _rotation(ctx, data["R_SM"], f"{where}.R_SM"),
                "translation": tuple(1e-3 * ctx.vector(data["p_SM_mm"], f"{where}.p_SM_mm"))}
    translation = tuple(ctx.length * ctx.vector(data.get("translation", [0, 0, 0]), f"{where}.translation"))
    if "rotation" in given:
        if "opening" in given:
            raise ctx.error(where, "give either opening or rotation, not both")
        return {"rotation": _rotation(ctx, data["rotation"], f"{where}.rotation"), "translation": translation}
    return {"opening": ctx.angle * ctx.number(data.get("opening", 0.0), f"{where}.opening"),
            "translation": translation}


def parse_protocol(ctx, data: dict, directory: Path, landmarks: dict, muscle_names) -> StudyProtocol:
    """The study sections of a subject.yaml mapping ``data`` (see the module docstring).

    ``ctx``: the subject reader's context (file, units, error messages); ``landmarks``
    name → (3,) m; ``muscle_names``: the subject's muscles. Raises SubjectError."""
    trials = _trials(ctx, data.get("trials"), Path(directory))
    statics = [t for t, spec in trials.items() if spec.kind == STATIC]
    reg = ctx.mapping(data.get("registration") or {}, "registration",
                      allowed={"method", "static_trial", "static_pose", "max_incisal_gap"})
    method = reg.get("method", "braces")
    if method not in ("braces", "static_trial"):
        raise ctx.error("registration.method", f"expected 'braces' or 'static_trial', got {method!r}")
    static = reg.get("static_trial", "reference" if "reference" in statics else statics[0] if len(statics) == 1 else None)
    if "static_trial" in reg and static not in statics:
        raise ctx.error("registration.static_trial", f"{static!r} is not a static trial of trials: ({statics or 'none'})")
    if method == "static_trial" and static is None:
        raise ctx.error("registration", "method static_trial needs a static trial (kind: static) in trials:")
    pose = None
    if "static_pose" in reg:
        if method != "static_trial":
            raise ctx.error("registration.static_pose", "only used with method: static_trial (the braces "
                            "method measures the static pose)")
        pose = _static_pose(ctx, reg["static_pose"], "registration.static_pose")
    max_gap = None
    if "max_incisal_gap" in reg:
        max_gap = ctx.length * ctx.number(reg["max_incisal_gap"], "registration.max_incisal_gap", positive=True)
    points = ctx.mapping(data.get("condyle_point") or {}, "condyle_point", allowed={"r", "l"})
    condyle_points = {side: str(points.get(side, f"condyle_top_{side}")) for side in ("r", "l")}
    for side, name in condyle_points.items():
        if name not in landmarks:
            raise ctx.error(f"condyle_point.{side}", f"unknown landmark {name!r}; landmarks: {sorted(landmarks)}")
    cal = ctx.mapping(data.get("muscle_calibration") or {}, "muscle_calibration",
                      allowed={"opening", "translation", "passive_strain"})
    passive_strain = (ctx.number(cal["passive_strain"], "muscle_calibration.passive_strain", positive=True)
                      if "passive_strain" in cal else None)
    opening = ctx.angle * ctx.number(cal.get("opening", CALIBRATION_OPENING_DEG * np.pi / 180.0 / ctx.angle),
                                     "muscle_calibration.opening")
    translation = (ctx.vector(cal["translation"], "muscle_calibration.translation") * ctx.length
                   if "translation" in cal else 1e-3 * np.array(CALIBRATION_TRANSLATION_MM))
    hyoid = ctx.mapping(data.get("hyoid") or {}, "hyoid", allowed={"muscles", "follow"})
    hyoid_muscles = None
    if "muscles" in hyoid:
        names = hyoid["muscles"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise ctx.error("hyoid.muscles", f"expected a list of muscle names, got {names!r}")
        unknown = [n for n in names if n not in muscle_names]
        if unknown:
            raise ctx.error("hyoid.muscles", f"unknown muscle(s) {unknown}")
        hyoid_muscles = tuple(names)
    follow = ctx.number(hyoid.get("follow", HYOID_FOLLOW), "hyoid.follow", low=0.0, high=1.0)
    contact = ctx.mapping(data.get("contact") or {}, "contact", allowed={"max_depth"})
    max_depth = (ctx.length * ctx.number(contact["max_depth"], "contact.max_depth", positive=True)
                 if "max_depth" in contact else None)
    return StudyProtocol(MappingProxyType(trials), method, static, pose, max_gap, MappingProxyType(condyle_points),
                         float(opening), tuple(float(v) for v in translation), hyoid_muscles, float(follow),
                         ctx.file, max_depth, passive_strain)
