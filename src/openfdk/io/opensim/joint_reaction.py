"""OpenSim's ``JointReaction`` options for an ``.osim`` run: the overlay's
``joint_reaction`` section in OpenSim's names, or the ``<JointReaction>`` of an OpenSim
setup file (an AnalyzeTool setup, ``joint_reaction: setup_JointReaction.xml``).

OpenSim expresses a load in a body's own frame, whose origin openfdk moves to the body's
centre of mass (:mod:`.to_model`), and a body welded to another is merged into it.
:func:`resolved` therefore gives each ``express_in_frame`` entry as that OpenSim body's
frame in its openfdk body, ``{name, body, position, orientation}``, and each
``apply_on_bodies`` entry with the OpenSim body's name
(:mod:`openfdk.dynamics.joint_reaction_settings`), so that the forces, moments and
points are OpenSim's numbers with OpenSim's labels. The welds a section names are kept
apart by the import (:func:`requested_joints`).
"""

from __future__ import annotations

import difflib
from pathlib import Path

import numpy as np

from ...model.model import ModelError
from .document import parse_xml
from .errors import where

#: OpenSim's JointReaction properties: the keys of the model file's ``joint_reaction``
#: section (:mod:`openfdk.dynamics.joint_reaction_settings`) and what a setup gives
KEYS = ("joint_names", "apply_on_bodies", "express_in_frame")



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
    for tag in KEYS:  # the others (forces_file, start_time, …) are the AnalyzeTool's, whose inputs the run has
        e = found.find(tag)
        words = (e.text or "").split() if e is not None else []
        if words:
            out[tag] = words if len(words) > 1 else words[0]
    out["from_file"] = source
    return out


def requested_joints(spec, base_dir="."):
    """The joints a ``joint_reaction`` spec (a mapping, or a setup file's path relative to
    ``base_dir``) asks for: a tuple of names, True for all, () when it cannot tell (its
    reader then names the mistake). The import keeps the WeldJoints among them apart
    (:class:`~.tree.Tree`), so that their loads can be reported."""
    if isinstance(spec, str):
        try:
            spec = read_setup(Path(base_dir) / spec)
        except (ModelError, OSError):
            return ()
    if not isinstance(spec, dict):
        return ()
    names = spec.get("joint_names", "all")
    if isinstance(names, str):
        return True if names.lower() == "all" else (names,)
    return tuple(n for n in names if isinstance(n, str)) if isinstance(names, list) else ()


def section_label(spec):
    """``joint_reaction``, with the setup file the entries came from: the start of the
    section's error paths."""
    origin = spec.get("from_file") if isinstance(spec, dict) else None
    return f"joint_reaction (from {origin})" if isinstance(origin, str) and origin else "joint_reaction"


def resolved(spec, data, info, source):
    """The ``joint_reaction`` mapping ``spec`` (OpenSim names) with every
    ``apply_on_bodies`` entry naming its OpenSim body (``{side, name}``: a body merged
    into another keeps its name in the columns, as in OpenSim's) and every
    ``express_in_frame`` entry given as the OpenSim body's frame (module docstring);
    ModelError naming ``source`` and the entry for a frame the model has not. The welds
    it names are not merged (:func:`requested_joints`): they are joints here."""
    if not isinstance(spec, dict):
        return spec
    body_frames = info.get("body_frames", {})
    if not body_frames:
        return spec
    frames = {**info.get("offset_frames", {}), **body_frames}  # the JointSet's frames by path: "knee_r/tibia_r_offset"
    joints = data.get("joints", {}) if isinstance(data.get("joints"), dict) else {}
    ends = info.get("joint_bodies", {})  # {joint: [OpenSim parent body, OpenSim child body]}
    chosen = spec.get("joint_names", "all")
    if isinstance(chosen, str) and chosen.lower() == "all":  # in OpenSim's order, the JointSet's
        chosen = [n for n in ends if isinstance(joints.get(n), dict)] or \
            [n for n, j in joints.items() if isinstance(j, dict) and j.get("child")]
    chosen = chosen if isinstance(chosen, list) else [chosen]
    if not all(isinstance(name, str) for name in chosen):
        return spec  # the section's reader names the entry that is no name
    out = dict(spec, joint_names=chosen)
    for key, default, each in (("apply_on_bodies", "child", _osim_side), ("express_in_frame", "ground", _osim_frame)):
        given = spec.get(key, default)
        many = isinstance(given, list) and len(given) > 1
        if many and len(given) != len(chosen):
            return spec  # the section's reader names the lengths
        entries = given if many else [given[0] if isinstance(given, list) and given else given] * len(chosen)
        done = [each(entry, ends.get(joint) if joint in joints else None, frames, source,
                     f"{section_label(spec)}.{key}" + (f"[{k}]" if many else ""))
                for k, (joint, entry) in enumerate(zip(chosen, entries))]
        # an entry left as given is a mistake the section's reader names, in the form the file gives
        out[key] = done if all(isinstance(d, dict) or d == "ground" for d in done) else given
    return out


def _osim_side(side, ends, body_frames, source, path):
    """One ``apply_on_bodies`` entry with the OpenSim body it names, ``{side, name}`` (or as
    given, which the section's reader checks)."""
    if not isinstance(side, str) or side.lower() not in ("child", "parent") or ends is None:
        return side
    return {"side": side.lower(), "name": ends[1] if side.lower() == "child" else ends[0]}


def _osim_frame(frame, ends, body_frames, source, path):
    """One ``express_in_frame`` entry as an OpenSim body's frame, or another OpenSim frame
    by its path in the JointSet (``walker_knee_r/tibia_r_offset``), as OpenSim's
    JointReaction finds it (or as given: ground, a mapping, a joint the model has not,
    which the section's reader names); ``ends`` the joint's OpenSim [parent, child]
    bodies; ``body_frames`` {OpenSim frame: (openfdk body, p (3,) m, R (3, 3))}."""
    if not isinstance(frame, str) or frame.lower() == "ground" or ends is None:
        return frame
    if frame.lower() in ("child", "parent"):
        frame = ends[1] if frame.lower() == "child" else ends[0]
        if frame == "ground":
            return "ground"
    if frame not in body_frames:
        hint = difflib.get_close_matches(frame, list(body_frames), n=1)
        extra = f"; did you mean {hint[0]!r}?" if hint else ""
        raise ModelError(f"{source}: {path}: {frame!r}: expected ground, child, parent, a body of the OpenSim "
                         f"model or a joint's frame (joint/frame){extra}")
    body, p, R = body_frames[frame]
    if body == "ground":
        return "ground"
    # labelled by the frame's name, as OpenSim's columns are (a joint's frame without its joint's path)
    return {"name": frame.rsplit("/", 1)[-1], "body": body, "position": np.asarray(p, float).tolist(),
            "orientation": {"matrix": np.asarray(R, float).tolist()}}


__all__ = ["KEYS", "read_setup", "requested_joints", "resolved", "section_label"]
