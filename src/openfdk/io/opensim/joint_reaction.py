"""OpenSim's ``JointReaction`` options for an ``.osim`` run: the overlay's
``joint_reaction`` section in OpenSim's names, or the ``<JointReaction>`` of an OpenSim
setup file (an AnalyzeTool setup, ``joint_reaction: setup_JointReaction.xml``).

OpenSim expresses a load in a body's own frame, whose origin openfdk moves to the body's
centre of mass (:mod:`.to_model`). :func:`resolved` therefore gives each
``express_in_frame`` entry as
that OpenSim body's frame in its openfdk body, ``{name, body, position, orientation}``
(:mod:`openfdk.dynamics.joint_reaction_settings`), so that the forces, moments and
points are OpenSim's numbers with OpenSim's labels.
"""

from __future__ import annotations

import difflib

import numpy as np

from ...model.model import ModelError
from .document import parse_xml
from .errors import where

#: the setup's properties openfdk reads (the others — forces_file, start_time, … — belong
#: to the AnalyzeTool, whose inputs the run gives with its own options)
_KEYS = ("joint_names", "apply_on_bodies", "express_in_frame")


def read_setup(path):
    """{joint_names, apply_on_bodies, express_in_frame, from_file} of the first
    ``<JointReaction>`` in the OpenSim setup file ``path`` (an AnalyzeTool setup or a bare
    JointReaction; from_file: its name, which the section's errors give); OsimError or
    ModelError naming the file and line."""
    source = path.name
    root = parse_xml(path, source)
    # an AnalyzeTool's <defaults> holds templates, not analyses
    found = next((e for e in root.iter("JointReaction") if not any(a.tag == "defaults" for a in e.iterancestors())),
                 None)
    if found is None:
        raise ModelError(f"{source}: no <JointReaction> (give OpenSim's JointReaction setup, or the joint_reaction "
                         "section's keys joint_names, apply_on_bodies, express_in_frame)")
    on = found.find("on")
    if on is not None and (on.text or "").strip().lower() == "false":
        raise ModelError(f"{where(source, found)}: <on> is false: this JointReaction is switched off")
    out = {}
    for tag in _KEYS:
        e = found.find(tag)
        words = (e.text or "").split() if e is not None else []
        if words:
            out[tag] = words if len(words) > 1 else words[0]
    out["from_file"] = source
    return out


def section_label(spec):
    """``joint_reaction``, with the setup file the entries came from: the start of the
    section's error paths."""
    origin = spec.get("from_file") if isinstance(spec, dict) else None
    return f"joint_reaction (from {origin})" if isinstance(origin, str) and origin else "joint_reaction"


def _opensim_bodies(body_frames):
    """{openfdk body: the OpenSim body whose frame it keeps the axes of} (merged bodies
    map to their root)."""
    from .to_model import safe_name

    return {v[0]: k for k, v in body_frames.items() if safe_name(k) == v[0]}


def resolved(spec, data, info, source):
    """The ``joint_reaction`` mapping ``spec`` (OpenSim names) with every ``express_in_frame`` entry
    given as the OpenSim body's frame (module docstring); ModelError naming ``source``
    and the entry for a frame the model has not."""
    if not isinstance(spec, dict):
        return spec
    body_frames = info.get("body_frames", {})
    if not body_frames:
        return spec
    names = _opensim_bodies(body_frames)
    joints = data.get("joints", {}) if isinstance(data.get("joints"), dict) else {}
    chosen = spec.get("joint_names", "all")
    if isinstance(chosen, str) and chosen.lower() == "all":
        chosen = [n for n, j in joints.items() if isinstance(j, dict) and j.get("child")]
    chosen = chosen if isinstance(chosen, list) else [chosen]
    frames = spec.get("express_in_frame", "ground")
    many = isinstance(frames, list) and len(frames) > 1
    entries = frames if many else [frames[0] if isinstance(frames, list) and frames else frames] * len(chosen)
    if many and len(frames) != len(chosen):
        return spec  # the section's reader names the lengths
    out = []
    for k, (joint, frame) in enumerate(zip(chosen, entries)):
        path = f"{section_label(spec)}.express_in_frame" + (f"[{k}]" if many else "")
        out.append(_osim_frame(frame, joints.get(joint), names, body_frames, source, path))
    return {**spec, "joint_names": chosen, "express_in_frame": out}


def _osim_frame(frame, joint, names, body_frames, source, path):
    """One ``express_in_frame`` entry as an OpenSim body's frame (or as given: ground, a mapping, a
    joint the model has not, which the section's reader names)."""
    if not isinstance(frame, str) or frame.lower() == "ground" or not isinstance(joint, dict):
        return frame
    side = frame.lower()
    if side in ("child", "parent"):
        end = joint.get(side) or "ground."
        body = str(end).split(".", 1)[0]
        if body == "ground":
            return "ground"
        frame = names.get(body, body)
    if frame not in body_frames:
        hint = difflib.get_close_matches(frame, list(body_frames), n=1)
        extra = f"; did you mean {hint[0]!r}?" if hint else ""
        raise ModelError(f"{source}: {path}: {frame!r}: expected ground, child, parent or a body of the OpenSim "
                         f"model{extra}")
    body, p, R = body_frames[frame]
    if body == "ground":
        return "ground"
    return {"name": frame, "body": body, "position": np.asarray(p, float).tolist(),
            "orientation": {"matrix": np.asarray(R, float).tolist()}}


__all__ = ["read_setup", "resolved", "section_label"]
