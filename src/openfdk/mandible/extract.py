"""TMJ kinematics and forces from analysis results, in the skull frame S (AP = x,
ML = y, SI = z), as the paper reports them.

* kinematics: the most superior condyle point (mandible-fixed landmark) expressed in the
  skull frame, p_S = R_WSᵀ (r_M + R_WM c_M − r_S);
* POP forces: the compressive plane reactions along −n (the fossa pushes the condyle)
  plus the medio-lateral reaction, assigned to the right TMJ when it pushes the mandible
  toward +y (medially on the right condyle) and to the left TMJ otherwise;
* FDK forces: the elastic-foundation contact force on each condyle.
All forces are the forces on the mandible, in N, in skull-frame components.
"""

from __future__ import annotations

import numpy as np

from ..numerics.spatial import rotation_matrix

SIDE_TAGS = {"right": "r", "left": "l"}


def compared_condyle_point(subject, tag):
    """The condyle point (3,) m whose kinematics the study compares, side tag 'r'/'l':
    the subject's ``condyle_point`` landmark (default the condyle top)."""
    return getattr(subject, "condyle_point", subject.condyle_top)(tag)


def _rotations(q):
    """(nf, 3, 3) rotation matrices of (nf, 4) unit quaternions (NaN rows stay NaN)."""
    R = np.full((len(q), 3, 3), np.nan)
    ok = np.all(np.isfinite(q), axis=1)
    for k in np.flatnonzero(ok):
        R[k] = rotation_matrix(q[k])
    return R


def _body_poses(kin, name):
    i = kin.body_names.index(name)
    return kin.q[:, 7 * i : 7 * i + 7]


def skull_frame_points(q_S, q_M, subject):
    """dict side -> (nf, 3) m: the compared condyle points (default the condyle tops;
    :func:`compared_condyle_point`) in the skull frame, from the skull and
    mandible poses q_S, q_M (nf, 7) = (position m, unit quaternion) per frame."""
    R_S, R_M = _rotations(q_S[:, 3:7]), _rotations(q_M[:, 3:7])
    com = subject.mandible.center_of_mass
    out = {}
    for side, tag in SIDE_TAGS.items():
        c = compared_condyle_point(subject, tag) - com
        p_W = q_M[:, :3] + np.einsum("nij,j->ni", R_M, c)
        out[side] = np.einsum("nji,nj->ni", R_S, p_W - q_S[:, :3])
    return out


def condyle_kinematics(kin, subject):
    """dict side -> (nf, 3) m: compared condyle points in the skull frame (NaN for failed
    frames)."""
    return skull_frame_points(_body_poses(kin, "skull"), _body_poses(kin, "mandible"), subject)


def pop_forces(dyn, kin, subject):
    """dict side -> (nf, 3) N: POP TMJ reaction forces on the mandible in S."""
    cols = dyn.column_names
    ml = dyn.forces[:, cols.index("tmj_ml")]
    out = {}
    for side, tag in SIDE_TAGS.items():
        n = subject.tmj_planes[tag].normal
        f = dyn.forces[:, cols.index(f"tmj_{tag}_compression")]
        F = -f[:, None] * n[None, :]
        mine = ml > 0 if side == "right" else ml < 0
        F[:, 1] += np.where(mine, ml, 0.0)
        out[side] = F
    return out


def skull_frame_forces(columns, q_S):
    """dict side -> (nf, 3) N: the contact forces ``tmj_<r|l>.F{x,y,z}_N`` of ``columns``
    (forces.csv columns, world frame) in the skull frame of poses q_S (nf, 7)."""
    R_S = _rotations(q_S[:, 3:7])
    out = {}
    for side, tag in SIDE_TAGS.items():
        F_W = np.stack([columns.get(f"tmj_{tag}.F{c}_N", np.full(len(q_S), np.nan)) for c in "xyz"], axis=1)
        out[side] = np.einsum("nji,nj->ni", R_S, F_W)
    return out


def fdk_forces(dyn, kin, subject):
    """dict side -> (nf, 3) N: FDK contact forces on the mandible in S."""
    return skull_frame_forces(dyn.extra["columns"], _body_poses(kin, "skull"))
