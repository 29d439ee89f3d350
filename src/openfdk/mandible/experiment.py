"""The virtual experiment: true jaw motion on the true joint, recorded as C3D files.

:func:`record_experiment` plays the paper's protocol (Andersen et al. 2017, "Motion
capture data") on a virtual subject folder: a static closed-mouth reference trial and
three tasks (unloaded chewing, protrusion to incisor-to-incisor, half open–close), five
cycles each at 100 Hz, with both braces tracked. Each task prescribes its "intended"
DOFs of the mandible relative to the skull (AP/ML translation of the condyle-top
midpoint, yaw, opening rotation); the remaining two (vertical translation, roll) are
solved per frame so that both condyles touch the TRUE fossa through the TRUE disc layer
(:func:`openfdk.mandible.truth.solve_contact`). The model's view (the subject folder)
differs from this truth as set by :class:`~openfdk.mandible.truth.TruthOptions`.

Motion targets (shared/reference/mandible-reference-data.md, "Jaw motion"):
* open–close: incisal opening 20–25 mm; condyles 5–8 mm forward, 4–7 mm down; rotation
  first (translation ∝ q², so at half the opening angle a quarter of the translation) —
  about 75 % of the opening is rotation at the start (Ferrario; Mapelli).
* protrusion (0.5 Hz): incisor 8–10 mm forward and a few mm down; condyles 8–10 mm
  forward, 5–8 mm down.
* chewing (1.0–1.6 Hz; here 1.2 Hz; Po et al. 2011: natural chewing 1.57 Hz): incisor
  15–20 mm vertical, 5–14 mm lateral; working-side condyle moves little, balancing-side
  condyle forward–down–medially.

Output (docs/virtual-experiment.md): ``trials/<task>.c3d`` (mm, 8 brace markers) and
``truth/<task>.csv`` (SI), ``truth/truth.yaml``, ``truth/README.md``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ..io.c3d import MarkerTrial, write_c3d
from ..io.trials import read_trial
from ..numerics.spatial import rotation_matrix_xyz
from .generator import load_anatomy
from .subject import Subject, load_subject
from .truth import SIDES, TrueJoint, TruthOptions, solve_contact

__all__ = [
    "TASKS",
    "TaskTruth",
    "load_true_joint",
    "load_truth",
    "measured_condyle_kinematics",
    "record_experiment",
    "rigid_fit",
    "simulate_task",
    "true_marker_positions",
]

_MM, _DEG = 1e-3, np.pi / 180.0
#: default cycle frequency (Hz) of each task; "reference" is a static 1 s trial
TASKS = {"chewing": 1.2, "protrusion": 0.5, "open_close": 0.8}
REST_S = 0.5              # closed-mouth rest before the first and after the last cycle, s
REFERENCE_S = 1.0         # length of the static reference trial, s
#: lab pose of the skull frame: position (m) and x-y-z angles (deg) — arbitrary, placed
#: like a seated subject in a lab; all lab coordinates stay below 2 m (float32 C3D
#: resolution ≤ 1.2e-4 mm)
SKULL_LAB_POSITION = np.array([0.30, 0.20, 1.15])
SKULL_LAB_ANGLES_DEG = np.array([0.0, 5.0, 30.0])
HEAD_SWAY = {"translation_mm": 2.0, "rotation_deg": 1.0, "frequency_hz": (0.1, 0.4)}


# --------------------------------------------------------------------------------------
# Task profiles
# --------------------------------------------------------------------------------------

def _bump(s, start, rise_end, fall_start, end):
    """0 → 1 → 0 over a cycle phase s (…) in [0, 1): raised-cosine rise on
    [start, rise_end], plateau, raised-cosine fall on [fall_start, end]; C¹."""
    s = np.asarray(s, dtype=float)
    out = np.zeros_like(s)
    rise = (s >= start) & (s < rise_end)
    out[rise] = 0.5 * (1 - np.cos(np.pi * (s[rise] - start) / (rise_end - start)))
    out[(s >= rise_end) & (s < fall_start)] = 1.0
    fall = (s >= fall_start) & (s < end)
    out[fall] = 0.5 * (1 + np.cos(np.pi * (s[fall] - fall_start) / (end - fall_start)))
    return out


#: movement amplitudes of each task (lengths mm, angles deg): open–close opening and
#: condyle translation; protrusion condyle translation; chewing opening and balancing-side
#: lateral translation (the docstring's targets). :data:`WIDE_AMPLITUDES`: the realistic
#: recordings' wide movements (incisal opening ≈ 45 mm, protrusion ≈ 10 mm, lateral
#: incisor excursion ≈ 12 mm).
AMPLITUDES = {"open_close": {"opening_deg": 12.5, "translation_mm": 7.0},
              "protrusion": {"translation_mm": 8.6, "opening_deg": -1.0},
              "chewing": {"opening_deg": 10.5, "lateral_mm": 4.0, "bennett_mm": 1.2, "working_mm": 0.8}}
WIDE_AMPLITUDES = {"open_close": {"opening_deg": 30.0, "translation_mm": 14.0},
                   "protrusion": {"translation_mm": 9.0, "opening_deg": -1.0},
                   "chewing": {"opening_deg": 12.0, "lateral_mm": 11.0, "bennett_mm": 1.2, "working_mm": 4.0}}


def _prescribe(task: str, s, amplitude, working_side: str, intercondylar: float, amplitudes=None):
    """Prescribed DOFs (x, y, yaw, opening) for phase s (n,) and per-frame amplitude
    factors ``amplitude`` (n, 3); lengths m, angles rad. ``task`` is a task kind;
    ``amplitudes``: a task's entry of :data:`AMPLITUDES` (default). See the module
    docstring."""
    zero = np.zeros_like(s)
    a0, a1, a2 = amplitude.T
    A = amplitudes if amplitudes is not None else AMPLITUDES.get(task, {})
    if task == "open_close":
        q = _bump(s, 0.0, 0.40, 0.50, 0.90)
        # rotation first: translation ∝ q², 25 % of it at half the opening angle
        return A["translation_mm"] * _MM * a1 * q ** 2, zero, zero, A["opening_deg"] * _DEG * a0 * q
    if task == "protrusion":
        q = _bump(s, 0.0, 0.35, 0.50, 0.85)
        # slight closing rotation keeps the incisor path "forward and a few mm down"
        return A["translation_mm"] * _MM * a1 * q, zero, zero, A["opening_deg"] * _DEG * a0 * q
    if task == "chewing":
        q_open = _bump(s, 0.0, 0.35, 0.35, 0.80)
        q_side = _bump(s, 0.10, 0.50, 0.50, 0.90)            # lateral excursion lags opening
        x_working = A["working_mm"] * _MM * a1 * q_open
        x_balancing = 2.5 * _MM * a1 * q_open + A["lateral_mm"] * _MM * a2 * q_side
        toward_working = 1.0 if working_side == "l" else -1.0      # +y is left
        y = toward_working * A["bennett_mm"] * _MM * a2 * q_side   # Bennett shift
        x_r, x_l = (x_balancing, x_working) if working_side == "l" else (x_working, x_balancing)
        # Rz(yaw) moves the right condyle top (0, −W/2, 0) forward by (W/2) sin(yaw)
        yaw = np.arcsin((x_r - x_l) / intercondylar)
        return 0.5 * (x_r + x_l), y, yaw, A["opening_deg"] * _DEG * a0 * q_open
    raise ValueError(f"unknown task {task!r}; known: {sorted(TASKS)}")


def _cycle_phase(rng, cycles: int, frequency: float, rate: float):
    """Time (n,) s, cycle index (n,) (−1 at rest) and phase (n,) with ±5 % period
    variation per cycle and REST_S of rest before and after."""
    periods = (1.0 / frequency) * (1.0 + np.clip(rng.normal(0.0, 0.025, cycles), -0.05, 0.05))
    edges = REST_S + np.concatenate([[0.0], np.cumsum(periods)])
    n = int(np.floor((edges[-1] + REST_S) * rate)) + 1
    t = np.arange(n) / rate
    k = np.searchsorted(edges, t, side="right") - 1
    inside = (k >= 0) & (k < cycles)
    phase = np.zeros(n)
    phase[inside] = (t[inside] - edges[k[inside]]) / periods[k[inside]]
    return t, np.where(inside, k, -1), phase


def _rotvec_matrices(phi) -> np.ndarray:
    """Exp of rotation vectors (n, 3) rad → (n, 3, 3) (Rodrigues)."""
    angle = np.linalg.norm(phi, axis=1)
    axis = phi / np.maximum(angle, 1e-300)[:, None]
    K = np.zeros((len(phi), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K -= np.transpose(K, (0, 2, 1))
    s, c = np.sin(angle)[:, None, None], (1 - np.cos(angle))[:, None, None]
    return np.eye(3) + s * K + c * K @ K


def _head_pose(rng, t, head_motion: bool):
    """Skull pose in the lab: R_LS (n, 3, 3), p_LS (n, 3) m; slow sway if head_motion."""
    R0 = rotation_matrix_xyz(SKULL_LAB_ANGLES_DEG * _DEG)
    n = len(t)
    if not head_motion:
        return np.broadcast_to(R0, (n, 3, 3)).copy(), np.tile(SKULL_LAB_POSITION, (n, 1))

    def sway(amplitude):
        f = rng.uniform(*HEAD_SWAY["frequency_hz"], size=3)
        phase = rng.uniform(0, 2 * np.pi, size=3)
        return amplitude * np.sin(2 * np.pi * f * t[:, None] + phase)

    p = SKULL_LAB_POSITION + sway(HEAD_SWAY["translation_mm"] * _MM)
    R = R0 @ _rotvec_matrices(sway(HEAD_SWAY["rotation_deg"] * _DEG))    # R_LS = R0 Exp(ω_S)
    return R, p


def true_marker_positions(subject: Subject, options: TruthOptions, rng) -> dict:
    """True brace marker positions (k, 3) m per body: the registered (subject-folder)
    positions moved by the registration difference (rotation about the marker
    centroid by ``registration_rotation`` about a random axis, then a translation of
    ``registration_translation`` in a random direction)."""
    true = {}
    for body in ("skull", "mandible"):
        p = subject.braces[body].positions
        axis, direction = rng.normal(size=3), rng.normal(size=3)
        R = _rotvec_matrices((options.registration_rotation * _DEG * axis / np.linalg.norm(axis))[None])[0]
        shift = options.registration_translation * _MM * direction / np.linalg.norm(direction)
        centroid = p.mean(axis=0)
        # p + (R − I)(p − c) + t: exactly p when both differences are zero
        true[body] = p + (p - centroid) @ (R - np.eye(3)).T + shift
    return true


# --------------------------------------------------------------------------------------
# One trial
# --------------------------------------------------------------------------------------

@dataclass(frozen=True)
class TaskTruth:
    """Ground truth of one trial (SI; S = skull frame, M = mandible anatomical frame, L = lab).

    ``time`` (n,) s; ``cycle`` (n,) int (−1 at rest); ``R_LS``/``p_LS`` and ``R_LM``/``p_LM``
    skull and mandible poses in the lab ((n, 3, 3), (n, 3) m); ``R_SM``/``p_SM`` the
    mandible in the skull frame; ``yaw``/``opening``/``roll`` (n,) rad; ``condyle_S``
    (n, 2, 3) m condyle-top landmarks (right, left) in S; ``incisor_S`` (n, 3) m incisal
    point in S; ``contact_S`` (n, 2, 3) m contact points on the true fossae; ``gap``
    (n, 2) m residual of the contact solve; ``markers_L`` (n, 8, 3) m noise-free
    marker positions in the lab.
    """

    task: str
    time: np.ndarray
    cycle: np.ndarray
    R_LS: np.ndarray
    p_LS: np.ndarray
    R_LM: np.ndarray
    p_LM: np.ndarray
    R_SM: np.ndarray
    p_SM: np.ndarray
    yaw: np.ndarray
    opening: np.ndarray
    roll: np.ndarray
    condyle_S: np.ndarray
    incisor_S: np.ndarray
    contact_S: np.ndarray
    gap: np.ndarray
    markers_L: np.ndarray


def simulate_task(subject: Subject, joint: TrueJoint, markers_true: dict, task: str, *,
                  cycles: int = 5, rate: float = 100.0, head_motion: bool = True,
                  rng=None, frequency: float | None = None, working_side: str = "l",
                  amplitudes: dict | None = None, static_opening_deg: float = 0.0,
                  rest_opening_deg: float = 0.0) -> TaskTruth:
    """True motion of one trial ("reference" or a key of :data:`TASKS`).

    Args: ``markers_true`` body → (4, 3) m true brace markers (mandible/skull frames);
    ``rate`` Hz; ``working_side`` 'r'/'l' for chewing; ``amplitudes``: the task's
    movement amplitudes (an entry of :data:`AMPLITUDES`, the default);
    ``static_opening_deg``: the reference trial's opening (deg; 0 = occlusion; the
    condyles stay on the true fossae); ``rest_opening_deg``: a movement task's rest
    opening (deg, added to the task's opening; e.g. braces between the teeth hold the
    mouth a few degrees open, so the rest is not the CT's occlusion). Returns a
    :class:`TaskTruth`.
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    if task == "reference":
        t = np.arange(round(REFERENCE_S * rate) + 1) / rate
        cycle, phase, amplitude = -np.ones(len(t), dtype=int), np.zeros(len(t)), np.ones((len(t), 3))
    else:
        if task not in TASKS:
            raise ValueError(f"unknown task {task!r}; known: {sorted(TASKS)} (and 'reference')")
        t, cycle, phase = _cycle_phase(rng, cycles, frequency or TASKS[task], rate)
        # per-cycle amplitude factors (opening, translation, lateral): ±3 % at most
        factors = 1.0 + np.clip(rng.normal(0.0, 0.015, (cycles, 3)), -0.03, 0.03)
        amplitude = np.where(cycle[:, None] >= 0, factors[np.maximum(cycle, 0)], 1.0)
    top_r, top_l = subject.condyle_top("r"), subject.condyle_top("l")
    intercondylar = float(np.linalg.norm(top_l - top_r))
    if task == "reference":
        x = y = yaw = np.zeros(len(t))
        opening = np.full(len(t), static_opening_deg * _DEG)
    else:
        x, y, yaw, opening = _prescribe(task, phase, amplitude, working_side, intercondylar, amplitudes)
        opening = opening + rest_opening_deg * _DEG
    solution = solve_contact(joint, x, y, yaw, opening)
    R_SM, p_SM = solution.R_SM, solution.p_SM
    R_LS, p_LS = _head_pose(rng, t, head_motion)
    R_LM = R_LS @ R_SM                                        # R_LM = R_LS R_SM
    p_LM = p_LS + np.einsum("nij,nj->ni", R_LS, p_SM)         # p_LM = p_LS + R_LS p_SM
    condyle_S = p_SM[:, None, :] + np.einsum("nij,kj->nki", R_SM, np.stack([top_r, top_l]))
    incisor_S = p_SM + R_SM @ subject.landmarks["incisal_point"]
    markers_L = np.concatenate([
        p_LS[:, None, :] + np.einsum("nij,kj->nki", R_LS, markers_true["skull"]),
        p_LM[:, None, :] + np.einsum("nij,kj->nki", R_LM, markers_true["mandible"])], axis=1)
    return TaskTruth(task, t, cycle, R_LS, p_LS, R_LM, p_LM, R_SM, p_SM, yaw, opening,
                     solution.roll, condyle_S, incisor_S, solution.contact_S, solution.gap, markers_L)


# --------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------

def _quaternions(R) -> np.ndarray:
    from ..numerics.spatial import quat_from_matrix

    return np.array([quat_from_matrix(r) for r in R])


def _truth_columns(truth: TaskTruth) -> dict:
    cols = {"time_s": truth.time, "cycle": truth.cycle.astype(float)}
    for name, R, p in (("skull", truth.R_LS, truth.p_LS), ("mandible", truth.R_LM, truth.p_LM),
                       ("mandible_in_skull", truth.R_SM, truth.p_SM)):
        for i, a in enumerate("xyz"):
            cols[f"{name}_p{a}_m"] = p[:, i]
        for i, q in enumerate(_quaternions(R).T):
            cols[f"{name}_q{i}"] = q
    cols.update({"yaw_rad": truth.yaw, "opening_rad": truth.opening, "roll_rad": truth.roll})
    for k, side in enumerate(SIDES):
        for i, a in enumerate("xyz"):
            cols[f"condyle_{side}_{a}_m"] = truth.condyle_S[:, k, i]
    for i, a in enumerate("xyz"):
        cols[f"incisor_{a}_m"] = truth.incisor_S[:, i]
    for k, side in enumerate(SIDES):
        for i, a in enumerate("xyz"):
            cols[f"contact_{side}_{a}_m"] = truth.contact_S[:, k, i]
        cols[f"gap_{side}_m"] = truth.gap[:, k]
    return cols


def write_truth_csv(directory, task: str, truth: TaskTruth) -> Path:
    """Write ``truth/<task>.csv`` (columns of docs/virtual-experiment.md); returns its path."""
    columns = _truth_columns(truth)
    path = Path(directory) / "truth" / f"{task}.csv"
    np.savetxt(path, np.column_stack(list(columns.values())), delimiter=",",
               header=",".join(columns), comments="", fmt="%.12g")
    return path


def truth_geometry(subject: Subject, joint: TrueJoint, markers_true: dict) -> dict:
    """The truth.yaml entries :func:`load_true_joint` reads back: cartilage offset, true
    brace markers (m, body frames) and the segmentation-error fields."""
    return {"cartilage_offset_m": float(subject.cartilage_offset),
            "true_markers_m": {body: dict(zip(subject.braces[body].labels, markers_true[body].tolist()))
                               for body in ("skull", "mandible")},
            "segmentation_fields": {f"condyle_{s}": joint.condyle_errors[s].to_dict() for s in SIDES}
            | {f"fossa_{s}": joint.fossa_errors[s].to_dict() for s in SIDES}}


def load_truth(directory: str | os.PathLike, task: str) -> dict:
    """Columns of ``truth/<task>.csv`` as arrays (n,), names as in docs/virtual-experiment.md."""
    path = Path(directory) / "truth" / f"{task}.csv"
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {name: np.asarray(data[name]) for name in data.dtype.names}


def load_true_joint(directory: str | os.PathLike) -> tuple[TrueJoint, dict]:
    """The true joint and true brace markers of a recorded virtual experiment.

    Rebuilt from ``truth/anatomy.yaml`` and ``truth/truth.yaml``. Returns the
    :class:`TrueJoint` and body → (k, 3) m true marker positions (body frames).
    """
    from .geometry import SmoothField

    directory = Path(directory)
    anatomy = load_anatomy(directory)
    info = yaml.safe_load((directory / "truth" / "truth.yaml").read_text(encoding="utf-8"))
    options = info["truth_options"]
    fields = {k: SmoothField(*(np.asarray(v[key], dtype=float).reshape(-1, 3) if key == "wave_vectors"
                               else np.asarray(v[key], dtype=float) for key in ("wave_vectors", "amplitudes", "phases")))
              for k, v in info["segmentation_fields"].items()}
    joint = TrueJoint(anatomy.condyles, anatomy.fossae, float(info["cartilage_offset_m"]),
                      _MM * np.array([options["disc_excess_anterior"], options["disc_excess_superior"],
                                      options["disc_excess_posterior"]]),
                      {s: fields[f"condyle_{s}"] for s in SIDES}, {s: fields[f"fossa_{s}"] for s in SIDES})
    markers = {body: np.array(list(m.values())) for body, m in info["true_markers_m"].items()}
    return joint, markers


_README = """\
# Ground truth of the virtual experiment

Written by `openfdk.mandible.record_experiment` (see docs/virtual-experiment.md).
SI units. Frames: L = lab (the C3D frame), S = skull anatomical frame (the subject
frame: origin midway between the condyle tops, x anterior, y left, z up), M = mandible
anatomical frame (coincides with S at the reference/CT pose of the subject folder).

`<task>.csv`, one row per C3D frame:
- `time_s`, `cycle` (0-based cycle index, -1 during rest)
- `skull_p{x,y,z}_m`, `skull_q{0..3}`: pose of S in L (origin, unit quaternion scalar first)
- `mandible_p*_m`, `mandible_q*`: pose of M in L
- `mandible_in_skull_p*_m`, `mandible_in_skull_q*`: pose of M in S;
  R_SM = Rz(yaw) Ry(opening) Rx(roll) with `yaw_rad`, `opening_rad`, `roll_rad`
- `condyle_{r,l}_{x,y,z}_m`: the condyle-top landmarks (mandible-fixed) in S
- `incisor_{x,y,z}_m`: the incisal point in S
- `contact_{r,l}_{x,y,z}_m`: contact point on the true fossa, in S
- `gap_{r,l}_m`: residual of the contact condition (|gap| < 1e-10 m)

`truth.yaml`: the TruthOptions used, the seed, the true brace marker positions (m, body
frames) and the random fields of the segmentation difference.
"""


def record_experiment(directory: str | os.PathLike, *,
                      tasks=("chewing", "protrusion", "open_close"), cycles: int = 5,
                      rate: float = 100.0, noise_mm: float = 0.15, head_motion: bool = True,
                      seed: int = 0, truth: TruthOptions | None = None,
                      working_side: str = "l", frequencies: dict | None = None) -> dict:
    """Record the virtual experiment for a generated subject folder.

    Args:
        directory: a folder written by :func:`openfdk.mandible.create_subject`.
        tasks: any of "chewing", "protrusion", "open_close"; the static "reference"
            trial is always recorded.
        cycles: cycles per task (≥ 1; the study uses 5).
        rate: marker sample rate, Hz.
        noise_mm: standard deviation of the Gaussian marker noise per coordinate, mm.
        head_motion: the skull sways slowly (±2 mm, ±1°, 0.1–0.4 Hz) when True.
        seed: seeds everything random (cycle variation, noise, head motion, truth
            differences).
        truth: :class:`TruthOptions` (default ``TruthOptions()``; ``TruthOptions.exact()``
            makes the truth equal the subject folder).
        working_side: chewing side, "l" or "r".
        frequencies: task → cycle frequency (Hz), overriding :data:`TASKS`.
    Returns: dict "trials/<name>.c3d" / "truth/<name>.csv" / "truth/truth.yaml" /
    "truth/README.md" → Path of each written file.
    """
    directory = Path(directory)
    truth = TruthOptions() if truth is None else truth
    if cycles < 1:
        raise ValueError(f"cycles must be ≥ 1, got {cycles}")
    if working_side not in SIDES:
        raise ValueError(f"working_side must be 'r' or 'l', got {working_side!r}")
    unknown = [t for t in tasks if t not in TASKS]
    if unknown:
        raise ValueError(f"unknown task(s) {unknown}; known: {sorted(TASKS)}")
    subject = load_subject(directory)
    anatomy = load_anatomy(directory)
    root = np.random.SeedSequence(seed)
    truth_rng, marker_rng, *task_seeds = (np.random.default_rng(s) for s in root.spawn(2 + 1 + len(tasks)))
    joint = TrueJoint.build(anatomy.condyles, anatomy.fossae, subject.cartilage_offset, truth, truth_rng)
    markers_true = true_marker_positions(subject, truth, truth_rng)
    labels = subject.marker_labels
    (directory / "trials").mkdir(exist_ok=True)
    (directory / "truth").mkdir(exist_ok=True)
    written = {}
    for task, rng in zip(("reference", *tasks), task_seeds):
        result = simulate_task(subject, joint, markers_true, task, cycles=cycles, rate=rate,
                               head_motion=head_motion, rng=rng, working_side=working_side,
                               frequency=(frequencies or {}).get(task))
        noisy = result.markers_L + marker_rng.normal(0.0, noise_mm * _MM, result.markers_L.shape)
        c3d_path = directory / "trials" / f"{task}.c3d"
        write_c3d(c3d_path, labels, noisy, rate, units="mm")
        written[f"trials/{task}.c3d"] = c3d_path
        written[f"truth/{task}.csv"] = write_truth_csv(directory, task, result)
    info = {"truth_options": truth.to_dict(), "seed": int(seed), "noise_mm": float(noise_mm),
            "head_motion": bool(head_motion), "rate_hz": float(rate), "cycles": int(cycles),
            "working_side": working_side, **truth_geometry(subject, joint, markers_true)}
    (directory / "truth" / "truth.yaml").write_text(yaml.safe_dump(info, sort_keys=False), encoding="utf-8")
    (directory / "truth" / "README.md").write_text(_README, encoding="utf-8")
    written["truth/truth.yaml"] = directory / "truth" / "truth.yaml"
    written["truth/README.md"] = directory / "truth" / "README.md"
    return written


# --------------------------------------------------------------------------------------
# What the brace measures
# --------------------------------------------------------------------------------------

def rigid_fit(model_points, measured):
    """Least-squares rigid fit (Kabsch/Horn) per frame, ignoring NaN markers.

    Args: model_points (k, 3) m in the body frame; measured (n, k, 3) m, NaN = missing.
    Returns: R (n, 3, 3), p (n, 3) m minimising Σ |R a_i + p − b_i|² (NaN where fewer
    than 3 markers are visible).
    """
    a = np.asarray(model_points, dtype=float)
    b = np.asarray(measured, dtype=float)
    valid = np.all(np.isfinite(b), axis=2)                             # (n, k)
    w = valid.astype(float)
    count = w.sum(axis=1)
    b0 = np.where(valid[..., None], b, 0.0)
    a_mean = (w @ a) / np.maximum(count, 1)[:, None]                   # (n, 3)
    b_mean = b0.sum(axis=1) / np.maximum(count, 1)[:, None]
    A = (a[None] - a_mean[:, None]) * w[..., None]
    B = (b0 - b_mean[:, None]) * w[..., None]
    H = np.einsum("nki,nkj->nij", A, B)                                # Σ a bᵀ
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.einsum("nji,nkj->nik", Vt, U)))       # det(V Uᵀ)
    D = np.zeros_like(H)
    D[:, 0, 0], D[:, 1, 1], D[:, 2, 2] = 1.0, 1.0, d
    R = np.einsum("nji,njk,nlk->nil", Vt, D, U)                        # V D Uᵀ
    p = b_mean - np.einsum("nij,nj->ni", R, a_mean)
    bad = count < 3
    R[bad], p[bad] = np.nan, np.nan
    return R, p


def measured_condyle_kinematics(subject: Subject, trial, braces=None) -> tuple:
    """Condyle-top positions as the brace measures them (paper: marker-only estimate).

    Fits the skull and mandible braces rigidly (:func:`rigid_fit`) to the trial's
    markers in each frame, then expresses the mandible's condyle-top landmarks in the
    skull frame: p_S = R_LSᵀ (p_LM + R_LM p_M − p_LS).

    Args: subject (its brace marker positions and landmarks); trial: a
    :class:`~openfdk.io.c3d.MarkerTrial` or a C3D path; braces: optional registered
    brace geometry, body -> (labels, positions (k, 3) m in the subject frame), e.g. from
    :func:`openfdk.mandible.registration.register_braces` (default: the subject's
    nominal brace positions).
    Returns: time (n,) s, p_right (n, 3) m, p_left (n, 3) m in the skull/subject frame.
    """
    time, p = mandible_points_in_skull(subject, trial, [subject.condyle_top(side) for side in SIDES], braces)
    return time, p[:, 0], p[:, 1]


def mandible_points_in_skull(subject: Subject, trial, points_S, braces=None) -> tuple:
    """Mandible-fixed points (given in the subject frame at the reference pose) in the
    skull frame over a trial, from rigid fits of the two braces (marker-only estimate).

    points_S : (k, 3) m; braces: as in :func:`measured_condyle_kinematics`.
    Returns time (n,) s and p (n, k, 3) m (NaN where a brace has < 3 markers).
    """
    if not isinstance(trial, MarkerTrial):
        trial = read_trial(trial)
    if braces is None:
        braces = {b: (subject.braces[b].labels, subject.braces[b].positions) for b in ("skull", "mandible")}
    R_LS, p_LS = rigid_fit(braces["skull"][1], trial.select(braces["skull"][0]).positions)
    R_LM, p_LM = rigid_fit(braces["mandible"][1], trial.select(braces["mandible"][0]).positions)
    points_S = np.asarray(points_S, dtype=float).reshape(-1, 3)
    p_L = p_LM[:, None, :] + np.einsum("nij,kj->nki", R_LM, points_S)
    return trial.time, np.einsum("nji,nkj->nki", R_LS, p_L - p_LS[:, None, :])
