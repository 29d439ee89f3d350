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

from ..spatial import rotation_matrix

SIDE_TAGS = {"right": "r", "left": "l"}


def _skull_rotations(kin, skull=0):
    q = kin.q[:, 7 * skull + 3 : 7 * skull + 7]
    R = np.full((len(q), 3, 3), np.nan)
    ok = np.all(np.isfinite(q), axis=1)
    for k in np.flatnonzero(ok):
        R[k] = rotation_matrix(q[k])
    return R


def condyle_kinematics(kin, subject):
    """dict side -> (nf, 3) m: condyle tops in the skull frame (NaN for failed frames)."""
    i_s, i_m = kin.body_names.index("skull"), kin.body_names.index("mandible")
    R_S = _skull_rotations(kin, i_s)
    R_M = _skull_rotations(kin, i_m)
    r_S, r_M = kin.q[:, 7 * i_s : 7 * i_s + 3], kin.q[:, 7 * i_m : 7 * i_m + 3]
    com = subject.mandible.center_of_mass
    out = {}
    for side, tag in SIDE_TAGS.items():
        c = subject.condyle_top(tag) - com
        p_W = r_M + np.einsum("nij,j->ni", R_M, c)
        out[side] = np.einsum("nji,nj->ni", R_S, p_W - r_S)
    return out


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


def fdk_forces(dyn, kin, subject):
    """dict side -> (nf, 3) N: FDK contact forces on the mandible in S."""
    cols = dyn.extra["columns"]
    R_S = _skull_rotations(kin, kin.body_names.index("skull"))
    out = {}
    for side, tag in SIDE_TAGS.items():
        F_W = np.stack([cols.get(f"tmj_{tag}.F{c}_N", np.full(len(kin.time), np.nan)) for c in "xyz"], axis=1)
        out[side] = np.einsum("nji,nj->ni", R_S, F_W)
    return out
