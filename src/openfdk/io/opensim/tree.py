"""The kinematic tree of an OpenSim document: frames resolved to bodies, welded bodies
merged, and forward kinematics (body poses from coordinate values).

Forward kinematics follows OpenSim's SpatialTransform (:mod:`openfdk.model.coordinate_joint`):
X_WB(child) = X_WB(parent) · X_PF · X_FM(q) · X_CM⁻¹ with
R_FM = Rot(a1, f1) Rot(a2, f2) Rot(a3, f3) and p_FM = Σ g_i t_i. It is the closed form
the reader uses for the reference pose (coordinates at their defaults) and the tests
use against OpenSim; analyses never call it (they solve the joint rows).

Welded bodies (WeldJoint) are merged into the body they are welded to, with their mass,
centre of mass and inertia combined exactly (parallel-axis theorem); their frames,
markers and geometry move with them. A body welded to the ground becomes part of it.
"""

from __future__ import annotations

import numpy as np

from .document import OsimDocument, OsimFrame
from .errors import OsimError


def _rotation(axis, angle):
    k = np.asarray(axis, float)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


class Tree:
    """Topology and poses of an OsimDocument.

    ``ground``: the ground's name; ``order``: the non-weld joints, parents before
    children; ``root[b]``: the body (or ground) that body b is merged into and
    ``X_root[b] = (p (3,) m, R (3, 3))``, body b's OpenSim frame in its root's frame;
    ``functions[joint][slot]``: PiecewisePolynomial of each TransformAxis (SI). A weld kept
    (``keep_welds``) is a joint of ``order`` with six constant axes."""

    def __init__(self, doc: OsimDocument, keep_welds=()):
        """``keep_welds``: the WeldJoints whose child stays a body of its own (joined by the
        weld's six rows, so that the weld's load is known), by name, or True for all."""
        from ...model.coordinate_functions import function_from_spec

        self.doc = doc
        self.ground = "ground"
        joints_by_child = {}
        for j in doc.joints:
            child_body = self.frame_body(j.child)[0]
            if child_body == self.ground:
                raise OsimError(f"{doc.source}: line {j.line}: {j.type} {j.name!r}: its child frame {j.child!r} is "
                                "the ground or fixed to it; a joint's child must be a body")
            if child_body in joints_by_child:
                raise OsimError(f"{doc.source}: line {j.line}: {j.type} {j.name!r}: body {child_body!r} is already the "
                                f"child of joint {joints_by_child[child_body].name!r}; closed loops need a constraint")
            joints_by_child[child_body] = j
        self.joint_of = joints_by_child
        for b in doc.bodies:
            if b not in joints_by_child:
                raise OsimError(f"{doc.source}: line {doc.bodies[b].line}: Body {b!r}: no joint connects it to the "
                                "model")

        def error(path, msg):
            return OsimError(f"{doc.source}: {path}: {msg}")

        self.functions = {}
        for j in doc.joints:
            self.functions[j.name] = [function_from_spec(ax.function, f"line {ax.line}: TransformAxis {ax.name!r} of "
                                                                      f"{j.type} {j.name!r}", error)
                                      for ax in j.rotations + j.translations]
        # order: parents first (depth of each body)
        depth = {}

        def body_depth(b, seen=()):
            if b == self.ground:
                return 0
            if b in depth:
                return depth[b]
            if b in seen:
                j = joints_by_child[b]
                raise OsimError(f"{doc.source}: line {j.line}: {j.type} {j.name!r}: the joints form a loop")
            parent = self.frame_body(joints_by_child[b].parent)[0]
            depth[b] = body_depth(parent, seen + (b,)) + 1
            return depth[b]

        for b in doc.bodies:
            body_depth(b)
        ordered = sorted(doc.bodies, key=lambda b: depth[b])
        self.root, self.X_root = {self.ground: self.ground}, {self.ground: (np.zeros(3), np.eye(3))}
        self.order = []
        for b in ordered:
            j = joints_by_child[b]
            parent, p_PF, R_PF = self.frame_body(j.parent)
            _, p_CM, R_CM = self.frame_body(j.child)
            if j.type == "WeldJoint" and not (keep_welds is True or j.name in keep_welds):
                # X_PC = X_PF · X_CM⁻¹, then into the parent's root
                R_PC = R_PF @ R_CM.T
                p_PC = p_PF - R_PC @ p_CM
                p_rP, R_rP = self.X_root[parent]
                self.root[b] = self.root[parent]
                self.X_root[b] = (p_rP + R_rP @ p_PC, R_rP @ R_PC)
            else:
                self.root[b] = b
                self.X_root[b] = (np.zeros(3), np.eye(3))
                self.order.append(j)

    def frame_body(self, name):
        """(body, p_BF (3,), R_BF (3, 3)) of a frame, through chains of offset frames."""
        frames = self.doc.frames
        p, R = np.zeros(3), np.eye(3)
        seen = set()
        while True:
            if name == self.ground or (name not in frames and name in ("ground",)):
                return self.ground, p, R
            if name not in frames:
                raise OsimError(f"{self.doc.source}: unknown frame or body {name!r}")
            f: OsimFrame = frames[name]
            if f.body == name:  # a body's own frame
                return name, p, R
            if name in seen:
                raise OsimError(f"{self.doc.source}: line {f.line}: frame {name!r} is attached to itself")
            seen.add(name)
            # X_{parent}F · (what we have so far)
            p, R = f.p_BF + f.R_BF @ p, f.R_BF @ R
            name = f.body

    def frame_in_root(self, name):
        """(root body, p (3,), R (3, 3)) of a frame in its root body's OpenSim frame."""
        body, p_BF, R_BF = self.frame_body(name)
        p_rB, R_rB = self.X_root[body]
        return self.root[body], p_rB + R_rB @ p_BF, R_rB @ R_BF

    def joint_transform(self, joint, q):
        """X_FM (p (3,) m, R (3, 3)) of a joint at coordinate values ``q`` {name: SI}."""
        fns = self.functions[joint.name]
        R = np.eye(3)
        for k, ax in enumerate(joint.rotations):
            x = q[ax.coordinates[0]] if ax.coordinates else 0.0
            R = R @ _rotation(ax.axis, fns[k].evaluate(x)[0])
        p = np.zeros(3)
        for k, ax in enumerate(joint.translations):
            x = q[ax.coordinates[0]] if ax.coordinates else 0.0
            p = p + fns[3 + k].evaluate(x)[0] * ax.axis
        return p, R

    def poses(self, q=None):
        """{root body: (p_WB (3,) m, R_WB (3, 3))} of the OpenSim body frames at
        coordinate values ``q`` {name: SI} (default: the coordinates' defaults)."""
        values = {c.name: c.default for c in self.doc.coordinates.values()}
        values.update(q or {})
        X = {self.ground: (np.zeros(3), np.eye(3))}
        for j in self.order:
            parent, p_PF, R_PF = self.frame_in_root(j.parent)
            child, p_CM, R_CM = self.frame_in_root(j.child)
            p_WP, R_WP = X[parent]
            p_FM, R_FM = self.joint_transform(j, values)
            R_WM = R_WP @ R_PF @ R_FM
            p_WM = p_WP + R_WP @ (p_PF + R_PF @ p_FM)
            R_WC = R_WM @ R_CM.T
            X[child] = (p_WM - R_WC @ p_CM, R_WC)
        return X

    def body_pose(self, body, X):
        """(p_WB, R_WB) of any OpenSim body (merged ones included) from :meth:`poses`."""
        p_WR, R_WR = X[self.root[body]]
        p_RB, R_RB = self.X_root[body]
        return p_WR + R_WR @ p_RB, R_WR @ R_RB

    def mass_properties(self, root):
        """(mass kg, centre of mass (3,) m and inertia about it (3, 3) kg m², both in the
        root's OpenSim frame) of a root body with every body welded to it. Without mass
        (massless bodies, as OpenSim allows) the centre of mass is the root's
        ``mass_center`` and the inertia zero: OpenSim resets a massless body's inertia."""
        parts = [b for b, r in self.root.items() if r == root and b in self.doc.bodies]
        m = sum(self.doc.bodies[b].mass for b in parts)
        if m > 0.0:
            c = sum(self.doc.bodies[b].mass * (self.X_root[b][0] + self.X_root[b][1] @ self.doc.bodies[b].mass_center)
                    for b in parts) / m
        else:  # massless (OpenSim allows it): any point is the centre of mass; the root's own
            c = self.X_root[root][0] + self.X_root[root][1] @ self.doc.bodies[root].mass_center
            return 0.0, c, np.zeros((3, 3))
        inertia = np.zeros((3, 3))
        for b in parts:
            body = self.doc.bodies[b]
            p, R = self.X_root[b]
            d = p + R @ body.mass_center - c
            inertia += R @ opensim_inertia(body)[0] @ R.T + body.mass * ((d @ d) * np.eye(3) - np.outer(d, d))
        return m, c, inertia

    def inertia_resets(self):
        """[(OpenSim body name, what OpenSim does)] of the bodies whose inertia OpenSim
        replaces (:func:`opensim_inertia`), for one warning."""
        return [(b, note) for b, body in self.doc.bodies.items() for note in [opensim_inertia(body)[1]] if note]


#: SimTK::SignificantReal (ε^⅞ for doubles): below it OpenSim calls a mass zero
SIGNIFICANT_REAL = float(np.finfo(float).eps) ** 0.875


def opensim_inertia(body):
    """(inertia (3, 3) kg m² about the centre of mass, '' or what was replaced) of an
    OsimBody as OpenSim's Body takes it (Body::getInertia): a massless body's inertia is
    zero, with a warning in OpenSim. (Simbody's check of the triangle inequality is
    compiled out of OpenSim's release builds, which take any other inertia as given;
    openfdk uses one that no rigid body has as given too, with a warning: the body's
    ``inertia_as_given``, model/plausibility.py.)"""
    if abs(body.mass) > SIGNIFICANT_REAL:
        return body.inertia, ""
    I = body.inertia
    if np.linalg.norm([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]]) > SIGNIFICANT_REAL:
        return np.zeros((3, 3)), "massless with inertia: inertia taken as zero"
    return np.zeros((3, 3)), ""
