"""The model file's ``joint_reaction`` section: which joint loads are reported, on which
body and in which frame, with the options of OpenSim's ``JointReaction`` analysis.

.. code-block:: yaml

    joint_reaction:
      joint_names: [knee_r, hip_r]   # or all (the default)
      apply_on_bodies: child         # or parent; one entry, or one per joint
      express_in_frame: child        # ground (the default), child, parent or a body's name

The keys are OpenSim's JointReaction properties, and the section may instead name
OpenSim's setup file (``joint_reaction: setup_JointReaction.xml``); its entries then
carry ``from_file``, the setup's name, which errors give. ``apply_on_bodies:
child`` reports the load the joint transmits to its child body, about the origin of the
joint's child frame; ``parent`` the opposite load on the parent body, about the origin
of the joint's parent frame. ``express_in_frame`` names the frame the force, the moment
and the point are expressed in: the ground, the body on either side of the joint, or any
body. As in OpenSim, each holds one entry for every joint or one per joint named, in
order.

A body's frame is the model's body frame. For an OpenSim model, whose bodies openfdk
places at their centres of mass, the overlay reader gives each ``express_in_frame``
entry as the OpenSim body's frame, ``{name, body, position, orientation}`` (name: the
OpenSim body; body: the openfdk body it lies on; position (3,) m and orientation of its
frame in that body), and each ``apply_on_bodies`` entry as ``{side, name}`` with the
OpenSim body's name (a body merged into another by a weld keeps its own), so that the
numbers and the labels are OpenSim's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..io.opensim.joint_reaction import KEYS, read_setup, section_label
from ..model.orientation_entry import _orientation

SIDES = ("child", "parent")


@dataclass(frozen=True, eq=False)
class JointReport:
    """One joint's reported load. joint : the joint's name; on : "child" or "parent";
    on_body : the name of the body the load acts on (the column label's); label : the
    frame's name in the column label; frame_body : the model body the frame is fixed on
    ("ground" for the ground); p_BF (3,) m, R_BF (3, 3) : the frame in that body."""

    joint: str
    on: str
    on_body: str
    label: str
    frame_body: str
    p_BF: np.ndarray
    R_BF: np.ndarray

    @property
    def base(self):
        """The columns' common label, OpenSim's: ``{joint}_on_{body}_in_{frame}``."""
        return f"{self.joint}_on_{self.on_body}_in_{self.label}"


def _per_joint(ctx, value, path, n):
    """``value`` (one entry or a list) as n entries, OpenSim's rule; ``path`` the key's
    place in the file, for messages."""
    items = value if isinstance(value, list) else [value]
    if len(items) == 1:
        return [(items[0], path) for _ in range(n)]
    if len(items) != n:
        raise ctx.error(path, f"give one entry or one per joint ({n}), got {len(items)}")
    return [(item, f"{path}[{k}]") for k, item in enumerate(items)]


def load_joint_reaction(b, data, ctx):
    """The ``joint_reaction`` section (module docstring) read against the builder's joints
    and bodies: its JointReports, kept with the analysis settings. ``data`` may also name
    an OpenSim setup file with a ``<JointReaction>`` (relative to the model file)."""
    if isinstance(data, str):
        xml = ctx.base_dir / data
        if not xml.is_file():
            raise ctx.error("joint_reaction", f"{str(xml)!r} does not exist")
        data = read_setup(xml)
    ctx.keys(data, "joint_reaction", KEYS + ("from_file",))
    label = section_label(data)
    records = {j.name: j for j in b.elements.get("joints", ()) if j.child}
    bodies = {r["name"] for r in b._bodies}
    names = data.get("joint_names", "all")
    if isinstance(names, str):
        names = list(records) if names.lower() == "all" else [names]
    if not isinstance(names, list) or not names:
        raise ctx.error(f"{label}.joint_names", f"expected all or a list of joint names, got {names!r}")
    for k, name in enumerate(names):
        name = ctx.string(name, f"{label}.joint_names[{k}]")  # a mapping or a list is no name (and no key)
        if name not in records:
            from ..io.yamlfile import did_you_mean

            raise ctx.error(f"{label}.joint_names[{k}]", f"no joint {name!r} with a child body in the model"
                            f"{did_you_mean(str(name), list(records))}")
    sides = _per_joint(ctx, data.get("apply_on_bodies", "child"), f"{label}.apply_on_bodies", len(names))
    frames = _per_joint(ctx, data.get("express_in_frame", "ground"), f"{label}.express_in_frame", len(names))
    reports = []
    for name, (side, sp), (frame, fp) in zip(names, sides, frames):
        j = records[name]
        ends = {"child": j.child.split(".", 1)[0], "parent": j.parent.split(".", 1)[0] if j.parent else "ground"}
        side, on_body = _side(ctx, side, sp, ends)
        label, body, p, R = _frame(ctx, frame, fp, ends, bodies)
        reports.append(JointReport(name, side, on_body, label, body, p, R))
    b.elements["joint_reaction"] = tuple(reports)


def _side(ctx, side, path, ends):
    """(side, the name of the body on it) of one ``apply_on_bodies`` entry: child or
    parent, or ``{side, name}`` (an OpenSim body's name, :mod:`openfdk.io.opensim.joint_reaction`)."""
    name = None
    if isinstance(side, dict):
        ctx.keys(side, path, ["side", "name"], required=("side", "name"))
        side, name = side["side"], ctx.string(side["name"], f"{path}.name")
        path = f"{path}.side"
    side = ctx.choice(side.lower() if isinstance(side, str) else side, path, SIDES, "body side")
    return side, name or ends[side]


def _frame(ctx, frame, path, ends, bodies):
    """(label, body, p_BF (3,) m, R_BF (3, 3)) of one ``express_in_frame`` entry."""
    if isinstance(frame, dict):
        ctx.keys(frame, path, ["name", "body", "position", "orientation"], required=("name", "body"))
        body = ctx.string(frame["body"], f"{path}.body")
        if body not in bodies and body != "ground":
            raise ctx.error(f"{path}.body", f"no body {body!r} in the model")
        return (ctx.string(frame["name"], f"{path}.name"), body,
                ctx.position(frame.get("position", [0.0, 0.0, 0.0]), f"{path}.position"),
                _orientation(frame.get("orientation"), f"{path}.orientation", ctx))
    name = ctx.string(frame, path)
    body = ends.get(name.lower(), "ground" if name.lower() == "ground" else name)
    if body != "ground" and body not in bodies:
        from ..io.yamlfile import did_you_mean

        raise ctx.error(path, f"expected ground, child, parent or a body's name, got {name!r}"
                        f"{did_you_mean(name, sorted(bodies))}")
    return body, body, np.zeros(3), np.eye(3)


def default_reports(model):
    """OpenSim's defaults: every joint with a moving child body, on the child, in the
    ground."""
    out = []
    for j in model.joints:
        if j.type == "coupler" or not j.child:
            continue
        child = model.frame(j.child).body
        out.append(JointReport(j.name, "child", child, "ground", "ground", np.zeros(3), np.eye(3)))
    return out


__all__ = ["JointReport", "load_joint_reaction", "default_reports", "KEYS", "SIDES"]
