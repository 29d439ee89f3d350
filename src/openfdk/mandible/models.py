"""The paper's two TMJ models, written as ordinary model files from a subject folder.

Both models have a skull (tracked by its brace, `equilibrium: false`: its loads come
from the neck and are not analysed), a mandible (mass, inertia, centre of mass from the
subject), 24 Hill-type muscles (origin on the skull, insertion on the mandible, straight
lines) and cubic recruitment. The brace markers are the registered positions
(:mod:`.registration`).

* **POP** (point-on-plane): the most superior point of each condyle stays on its TMJ
  plane (30° down-anteriorly, 5° medial cant; subject ``tmj_planes``) and the mandible
  origin cannot move medio-laterally relative to the skull. The plane reactions are
  compressive only: 20 kN push-only elements recruited like muscles; the medio-lateral
  reaction is free and is assigned to the right or left TMJ by its sign (a force toward
  +y, i.e. medial on the right condyle, to the right TMJ; toward −y to the left).
* **FDK**: the same three directions (each condyle's distance from its plane, the
  medio-lateral shift) are FDK DOFs; the joint is held by elastic-foundation contact of
  the condyle (offset by the subject's cartilage layer, 1 mm) against the fossa/eminence
  (10 GN/m³), three Blankevoort ligament elements per side (the paper's whole-ligament
  stiffness k split equally over the elements, reference strain ε_r at the reference
  pose), and a weak spring (0.1 N/m) on each FDK DOF.

Muscle calibration (as AnyBody's 3-element muscles, e.g. in the de Zee et al. 2007
mandible model, are calibrated): each tendon slack length is set so that the fibres are
at their optimal length in a calibration pose — the mandible opened by
``calibration_opening_deg`` (default 22.5°) about the intercondylar axis and translated
10 mm forward and 5.5 mm down (the subject's ``muscle_calibration``). The supra-hyoid
muscles' lower ends sit on a ``hyoid`` body that follows half of the mandible's motion
(the subject's ``hyoid``; :func:`_add_hyoid`). With the earlier 5° calibration and
skull-fixed supra-hyoid ends, a 45 mm opening was infeasible on a third of the frames:
the openers' moment arms vanish and the stretched elevators pull it shut
(docs/mandible-study.md, "Muscle calibration and the hyoid"). The parallel-elastic strain
at F0 is Thelen's (2003) 0.6 (see :data:`PASSIVE_STRAIN_AT_MAX_FORCE`; the subject's
``muscle_calibration.passive_strain`` sets it): the passive tension of the stretched
muscles is what loads the TMJ in unloaded movements, and with 0.6 the virtual study's
TMJ forces and Table 2 are in the paper's range (docs/mandible-study.md, "TMJ forces").
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml

from ..numerics.spatial import quat_from_rotvec, rotation_matrix
from . import protocol as _protocol

PARAMETER_STUDY_STIFFNESS = (136.2, 272.4, 544.8)  # N/m, whole TMJ ligament (paper)
PARAMETER_STUDY_STRAIN = (-0.04, -0.02, 0.0, 0.02, 0.04)
DEFAULT_STIFFNESS, DEFAULT_STRAIN = 272.4, 0.0  # the paper's comparison model
#: the default muscle calibration pose: opening (deg) and condyle translation (m),
#: forward and down along the eminence (docs/mandible-study.md)
CALIBRATION_OPENING_DEG = _protocol.CALIBRATION_OPENING_DEG
CALIBRATION_TRANSLATION = tuple(1e-3 * float(v) for v in _protocol.CALIBRATION_TRANSLATION_MM)
#: parallel-elastic strain at F0 of the jaw muscles: Thelen (2003, J Biomech Eng
#: 125:70, Eq. 3) ε0_M = 0.6 for young adults (the reference table gives none; openfdk's
#: Hill default, docs/muscles.md). It sets the passive tension of the stretched muscles,
#: which is most of the TMJ load in unloaded movements; with the earlier 1.0 the TMJ
#: carried a few newtons. With 0.6 the calibration pose moved from 20° to 22.5° open
#: (the smallest tested opening at which POP stays feasible up to a 45 mm incisal
#: opening); measurements in docs/mandible-study.md, "TMJ forces". Per subject:
#: ``muscle_calibration.passive_strain``.
PASSIVE_STRAIN_AT_MAX_FORCE = 0.6
#: fraction λ of the mandible's motion (at the hyoid's rest position) that the hyoid
#: follows (0 = supra-hyoid lower ends fixed to the skull)
HYOID_FOLLOW = _protocol.HYOID_FOLLOW
#: marker low-pass cut-off of the models' marker tracking (and of the measured
#: kinematics of the study), Hz
MARKER_CUTOFF_HZ = 6.0
SIDES = (("r", "right"), ("l", "left"))


def _mm(v):
    return [round(float(x) * 1e3, 6) for x in np.asarray(v).ravel()]


def _plane_frame(normal):
    """Rotation (3, 3) whose z axis is the plane normal and x axis points anteriorly."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    x = np.array([1.0, 0.0, 0.0]) - n[0] * n
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(n, x), n])


def calibrated_tendon_slack(subject, muscle, opening_deg, translation=(0.0, 0.0, 0.0)):
    """Tendon slack length (m) with optimal fibres in the calibration posture: the
    insertion rotated by ``opening_deg`` about the intercondylar (y) axis through the
    condyle tops, then translated by ``translation`` (3,) m (forward–down along the
    eminence); l_T = l_MT − Lf0 cos α0, at least 1 mm."""
    axis_point = 0.5 * (subject.condyle_top("r") + subject.condyle_top("l"))
    R = rotation_matrix(quat_from_rotvec([0.0, np.deg2rad(opening_deg), 0.0]))
    insertion = axis_point + R @ (muscle.insertion - axis_point) + np.asarray(translation, dtype=float)
    l_mt = float(np.linalg.norm(insertion - muscle.origin))
    return max(l_mt - muscle.optimal_fibre_length * np.cos(muscle.pennation_angle_at_optimal), 1e-3)


def model_dict(subject, registration, kind, ligament_stiffness=DEFAULT_STIFFNESS,
               reference_strain=DEFAULT_STRAIN, calibration_opening_deg=None,
               calibration_translation=None, mesh_dir=None,
               passive_strain_at_max_force=None,
               pressure_modulus=1.0e10, spring_stiffness=0.1, hyoid_follow=None, contact_max_depth=None):
    """The POP (``kind="pop"``) or FDK (``kind="fdk"``) model of a subject as a model-file
    mapping (mm, deg). ``mesh_dir``: path written for the STL files (relative to where
    the model file will be written; default the subject folder, absolute).
    ``calibration_opening_deg`` (deg), ``calibration_translation`` ((3,) m) and
    ``hyoid_follow`` (fraction) and ``passive_strain_at_max_force`` default to the
    subject's ``muscle_calibration`` and ``hyoid`` sections, else to the module defaults. ``contact_max_depth`` (m): the
    contacts' ``max_depth`` (default the subject's ``contact.max_depth``, else the
    model file's default, 3 mm)."""
    if kind not in ("pop", "fdk"):
        raise ValueError(f"model kind must be 'pop' or 'fdk', got {kind!r}")
    protocol = getattr(subject, "protocol", None)
    if calibration_opening_deg is None:
        calibration_opening_deg = (np.rad2deg(protocol.calibration_opening) if protocol is not None
                                   else CALIBRATION_OPENING_DEG)
    if calibration_translation is None:
        calibration_translation = (protocol.calibration_translation if protocol is not None
                                   else CALIBRATION_TRANSLATION)
    if hyoid_follow is None:
        hyoid_follow = protocol.hyoid_follow if protocol is not None else HYOID_FOLLOW
    if passive_strain_at_max_force is None:
        passive_strain_at_max_force = getattr(protocol, "passive_strain", None) or PASSIVE_STRAIN_AT_MAX_FORCE
    if contact_max_depth is None and protocol is not None:
        contact_max_depth = protocol.contact_max_depth
    com = subject.mandible.center_of_mass
    skull_frames = {"incisal_point_skull": _mm(subject.landmarks["incisal_point"])}
    jaw_frames = {"ml_point": _mm(-com), "incisal_point": _mm(subject.landmarks["incisal_point"] - com)}
    for tag, _ in SIDES:
        plane = subject.tmj_planes[tag]
        skull_frames[f"plane_{tag}"] = {"position": _mm(plane.point),
                                        "orientation": {"matrix": _plane_frame(plane.normal).round(12).tolist()}}
        jaw_frames[f"condyle_{tag}"] = _mm(subject.condyle_top(tag) - com)
    muscles = {}
    hyoid_muscles = set(suprahyoid_muscles(subject)) if hyoid_follow > 0 else set()
    hyoid_rest = (np.mean([m.origin for m in subject.muscles if m.name in hyoid_muscles], axis=0)
                  if hyoid_muscles else None)
    hyoid_frames = {}
    for m in subject.muscles:
        if m.name in hyoid_muscles:
            hyoid_frames[f"{m.name}_origin"] = _mm(m.origin - hyoid_rest)
            origin = f"hyoid.{m.name}_origin"
        else:
            skull_frames[f"{m.name}_origin"] = _mm(m.origin)
            origin = f"skull.{m.name}_origin"
        jaw_frames[f"{m.name}_insertion"] = _mm(m.insertion - com)
        muscles[m.name] = {
            "path": [origin, f"mandible.{m.name}_insertion"],
            "max_isometric_force": float(m.max_isometric_force),
            "optimal_fibre_length": float(m.optimal_fibre_length * 1e3),
            "tendon_slack_length": float(round(calibrated_tendon_slack(
                subject, m, calibration_opening_deg, calibration_translation) * 1e3, 6)),
            "tendon_strain_at_max_force": float(m.tendon_strain_at_max_force),
            "pennation_angle_at_optimal": float(np.rad2deg(m.pennation_angle_at_optimal)),
            "fast_fibre_fraction": float(m.fast_fibre_fraction),
            "passive_shape_factor": float(m.passive_shape_factor),
            "passive_strain_at_max_force": float(passive_strain_at_max_force),
        }
    labels_s, pos_s = registration["skull"]
    labels_m, pos_m = registration["mandible"]
    data = {
        "openfdk": 1,
        "name": f"{subject.name} {kind.upper()} TMJ model",
        "description": (f"written by openfdk.mandible.models from {subject.directory}; tendon slack lengths "
                        f"calibrated {float(calibration_opening_deg):g} deg open, condyles translated "
                        f"{[round(1e3 * float(v), 3) for v in calibration_translation]} mm, parallel-elastic "
                        f"strain at F0 {float(passive_strain_at_max_force):g}; "
                        f"hyoid follows {float(hyoid_follow):g} of the mandible's motion"),
        "units": {"length": "mm", "angle": "deg"},
        "gravity": [0.0, 0.0, -9.81],
        "bodies": {
            "skull": {"mass": 4.0, "inertia": [0.02, 0.02, 0.02], "equilibrium": False, "frames": skull_frames,
                      "markers": {lab: _mm(p) for lab, p in zip(labels_s, pos_s)}},
            "mandible": {"mass": float(subject.mandible.mass), "inertia": np.asarray(subject.mandible.inertia).tolist(),
                         "position": _mm(com), "frames": jaw_frames,
                         "markers": {lab: _mm(p - com) for lab, p in zip(labels_m, pos_m)}},
        },
        "measures": {
            "ml": {"type": "vector", "from": "skull.origin", "to": "mandible.ml_point", "expressed_in": "skull"},
            "gap_r": {"type": "plane_distance", "plane": "skull.plane_r", "point": "mandible.condyle_r"},
            "gap_l": {"type": "plane_distance", "plane": "skull.plane_l", "point": "mandible.condyle_l"},
        },
        "muscles": muscles,
        "recruitment": {"criterion": "polynomial", "power": 3},
        "analysis": {"marker_cutoff_hz": MARKER_CUTOFF_HZ},
    }
    if hyoid_muscles:
        _add_hyoid(data, hyoid_rest, com, hyoid_frames, hyoid_follow)
    _add_bone_meshes(data, subject, com, mesh_dir)
    if kind == "pop":
        data["joints"] = {f"tmj_{t}": {"type": "point_on_plane", "parent": f"skull.plane_{t}", "child": f"mandible.condyle_{t}"}
                          for t, _ in SIDES}
        data.setdefault("constraints", {})["tmj_ml"] = {"measure": "ml", "components": [1]}
        # plane normals point up into the skull: the fossa pushes the condyle along −n
        data["reactions"] = {f"tmj_{t}_compression": {"joint": f"tmj_{t}", "direction": "pull", "strength": 20000}
                             for t, _ in SIDES}
        return data
    mesh_dir = Path(mesh_dir) if mesh_dir is not None else Path(subject.directory).resolve()
    contacts, ligaments = {}, {}
    per_element = ligament_stiffness / 3.0
    for tag, _ in SIDES:
        condyle, fossa = subject.surfaces[f"condyle_{tag}"], subject.surfaces[f"fossa_{tag}"]
        contacts[f"tmj_{tag}"] = {
            "vertices": {"body": "mandible", "mesh": str(mesh_dir / condyle.path.name), "units": subject.length_unit,
                         "placement": {"position": _mm(-com)}, "offset": float(round(subject.cartilage_offset * 1e3, 6))},
            "surface": {"body": "skull", "mesh": str(mesh_dir / fossa.path.name), "units": subject.length_unit},
            "pressure_modulus": float(pressure_modulus),
        }
        if contact_max_depth is not None:
            contacts[f"tmj_{tag}"]["max_depth"] = float(round(contact_max_depth * 1e3, 6))
    for lig in subject.ligaments:
        skull_frames[f"{lig.name}_origin"] = _mm(lig.origin)
        jaw_frames[f"{lig.name}_insertion"] = _mm(lig.insertion - com)
        ligaments[lig.name] = {
            "path": [f"skull.{lig.name}_origin", f"mandible.{lig.name}_insertion"],
            "stiffness": float(round(per_element, 9)),
            "reference_length": float(round(lig.reference_length * 1e3, 6)),
            "reference_strain": float(reference_strain),
        }
    data["contacts"] = contacts
    data["ligaments"] = ligaments
    data["fdk_dofs"] = {
        "tmj_r_normal": {"measure": "gap_r", "initial": 0.0, "max_step": 0.5},
        "tmj_l_normal": {"measure": "gap_l", "initial": 0.0, "max_step": 0.5},
        "tmj_ml": {"measure": "ml", "component": 1, "initial": 0.0, "max_step": 0.5},
    }
    # FDK continues from the previous frame's α (no linear extrapolation of the two
    # previous ones): where the medio-lateral DOF's root moves fast, the extrapolated
    # start passes over the branch the frames follow (issue 28; docs/mandible-study.md,
    # "FDK's medio-lateral DOF")
    data["fdk"] = {"extrapolate": False}
    data["springs"] = {
        "fdk_spring_r": {"measure": "gap_r", "stiffness": spring_stiffness},
        "fdk_spring_l": {"measure": "gap_l", "stiffness": spring_stiffness},
        "fdk_spring_ml": {"measure": "ml", "component": 1, "stiffness": spring_stiffness},
    }
    return data


def _add_bone_meshes(data, subject, com, mesh_dir):
    """``visual`` entries of the skull and mandible display meshes (skull.stl,
    mandible.stl: subject frame, reference pose) when the subject folder has them (a
    virtual subject does, :mod:`.bone_meshes`); the mandible's is placed at −r_com."""
    from .generator import MANDIBLE_MESH, SKULL_MESH

    folder = Path(subject.directory)
    mesh_dir = Path(mesh_dir) if mesh_dir is not None else folder.resolve()
    for body, file, placement, color in (("skull", SKULL_MESH, [0.0, 0.0, 0.0], "#e8dcc8"),
                                          ("mandible", MANDIBLE_MESH, _mm(-com), "#d9cbb0")):
        if (folder / file).is_file():
            data["bodies"][body]["visual"] = {"mesh": str(mesh_dir / file), "units": "mm",
                                              "placement": {"position": placement}, "color": color}


def suprahyoid_muscles(subject) -> tuple:
    """Names of the muscles whose skull-side end is on the hyoid: ``subject.hyoid_muscles``
    when the subject folder lists them, else those named like a supra-hyoid muscle
    (digastric, geniohyoid, mylohyoid)."""
    listed = getattr(subject, "hyoid_muscles", None)
    if listed is not None:
        return tuple(listed)
    return tuple(m.name for m in subject.muscles
                 if any(k in m.name.lower() for k in ("digastric", "geniohyoid", "mylohyoid")))


def _add_hyoid(data, hyoid_rest, com, hyoid_frames, follow):
    """A hyoid body carrying the supra-hyoid muscles' lower ends: it keeps the skull's
    orientation and its origin H follows the mandible, p_SH = (1 − λ) p_SH0 + λ p_SF,
    with H0 the rest position (mean of those ends) and F the mandible point at H0 in the
    reference pose (λ = ``follow``). Both constraints carry no reaction: the hyoid is
    held by the (unmodelled) infra-hyoid muscles, so the mandible receives only the
    supra-hyoid muscle forces; the hyoid has no equilibrium rows."""
    data["bodies"]["skull"]["frames"]["hyoid_rest"] = _mm(hyoid_rest)
    data["bodies"]["mandible"]["frames"]["hyoid_follow"] = _mm(hyoid_rest - com)
    data["bodies"]["hyoid"] = {"mass": 0.02, "inertia": [2e-6, 2e-6, 2e-6], "position": _mm(hyoid_rest),
                               "equilibrium": False, "frames": hyoid_frames}
    eye = np.eye(3)
    # (p_SH − p_SH0) − λ (p_SF − p_SH0) = 0; the vectors inline, so any key order loads
    data["measures"]["hyoid_blend"] = {"type": "linear", "terms": [
        {"measure": {"type": "vector", "from": "skull.hyoid_rest", "to": "hyoid.origin", "expressed_in": "skull"},
         "coefficients": eye.tolist()},
        {"measure": {"type": "vector", "from": "skull.hyoid_rest", "to": "mandible.hyoid_follow",
                     "expressed_in": "skull"},
         "coefficients": (-float(follow) * eye).tolist()}]}
    data["measures"]["hyoid_orientation"] = {"type": "angles", "frame": "skull.origin", "of": "hyoid.origin"}
    data.setdefault("constraints", {})
    data["constraints"]["hyoid_follows_mandible"] = {"measure": "hyoid_blend", "reaction": False}
    data["constraints"]["hyoid_orientation"] = {"measure": "hyoid_orientation", "reaction": False}


def write_model(path, data):
    """Write a model mapping as a commented YAML model file; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = (f"# {data['name']}: written by openfdk (docs/mandible-study.md). An ordinary model file:\n"
              f"# edit it, or run it with `openfdk run {path.name} TRIAL.c3d --out DIR`.\n")
    path.write_text(header + yaml.safe_dump(data, sort_keys=False, width=120))
    return path


def write_models(subject, registration, out_dir, **kw):
    """Write pop.yaml and fdk.yaml into ``out_dir`` (mesh paths relative to it)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rel = Path(os.path.relpath(Path(subject.directory).resolve(), out_dir.resolve()))
    return {kind: write_model(out_dir / f"{kind}.yaml", model_dict(subject, registration, kind, mesh_dir=rel, **kw))
            for kind in ("pop", "fdk")}
