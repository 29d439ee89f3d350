"""Where to cut one trial into chunks (``openfdk run --chunks K``): in the stance of the
limb the FDK DOFs hold, away from its load's onset and release.

Every chunk after the first starts cold (:mod:`openfdk.fdk.approach`: a lead-in from the
DOFs' initial values). What that costs depends on the phase of gait. Measured on the DM
knee (og9, ``dm_pt.yaml``, default settings), the residual evaluations of the first frame
of a window starting at

* 3.214 s, heel strike: 152 (the next two frames 102 and 132);
* 3.45 s, mid-stance: 91 (then 4 and 5);
* 3.70 s, push-off: 261;
* 3.95 s, early swing: 750;
* 4.197 s, mid-swing: 1 153.

In swing the unloaded knee is held by its ligaments alone, the patella floats, and a cold
Newton start creeps through soft, kinked directions (a cold start there is chaotic to
rounding, docs/fdk.md); loaded, the contact makes the root stiff and well defined. In
stance the cold starts above cost 3–7 s on this machine; in swing 23–58 s. Equal chunks
started og9's second chunk cold at 4.197 s, mid-swing: two chunks took 119 s against
92 s serially (stop 44, alternated runs).

So a cut is moved, within half a chunk's length of the equal split, to the nearest cut
whose segment's cold start (``overlap`` + 1 frames before it) lies at least half as deep
in a stance as the trial's deepest frame (:func:`openfdk.study.chunks.plan_segments`):
:func:`stance_depth` is, for each frame, the number of frames to the nearest frame at
which the measured loads on the limb the FDK DOFs hold (:func:`limb_bodies`) are below
:data:`LOADED` of their peak. The depth only separates stance from its edges: within a
stance the measured costs do not follow it. Without such loads (no FDK DOFs, no
measured loads on the limb, a model whose FDK joint is not a cut of its body graph), or
with no such cut in reach, the equal split stands.
"""

from __future__ import annotations

import numpy as np

#: a frame is in stance when the limb's measured load is at least this fraction of its peak
LOADED = 0.2


def limb_bodies(model):
    """Indices (into ``model.bodies``) of the moving bodies beyond the FDK DOFs: cut every
    constraint row that touches only bodies an FDK DOF row joins (the FDK joint's own
    rows, its drivers included), and take the bodies outside the trunk: the connected
    parts of the rest that a row holds to the ground, or, when none is (a free pelvis),
    the largest part. Empty when the model has no FDK DOFs or the cut leaves the bodies
    connected, or when its constraints cannot be evaluated at the reference pose (the DOFs'
    initial values), where this is decided."""
    from ..kinematics.system import ConstraintSystem

    if not model.fdk_dofs:
        return np.zeros(0, dtype=int)
    system = ConstraintSystem(model)
    alpha = np.array([d.initial for d in model.fdk_dofs], dtype=float)
    state = model.initial_state()
    try:
        _, A, _, _ = system.evaluate(state, 0.0, alpha, order=1)
    except (FloatingPointError, ValueError):  # not evaluable there: the run's frames say why
        return np.zeros(0, dtype=int)
    m, n = A.shape
    touched = (A != 0.0).reshape(m, n // 6, 6).any(axis=2)  # (m, n_moving)
    n_fdk = len(model.fdk_dofs)
    pairs = [frozenset(np.flatnonzero(row)) for row in touched[m - n_fdk:]]
    parent = list(range(n // 6))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    grounded = []  # bodies a row holds to the ground (a row touching one moving body)
    for row in touched[: m - n_fdk]:
        bodies = np.flatnonzero(row)
        if len(bodies) == 1:
            grounded.append(int(bodies[0]))
        if len(bodies) < 2 or any(set(bodies) <= pair for pair in pairs):
            continue
        for b in bodies[1:]:
            parent[root(int(b))] = root(int(bodies[0]))
    roots = np.array([root(i) for i in range(n // 6)])
    # the trunk: the part held to the ground, else (a free root such as a gait model's
    # pelvis) the largest part
    trunk = {int(roots[b]) for b in grounded} or {int(np.bincount(roots).argmax())}
    moving = np.flatnonzero(state.column >= 0)  # model body index of each moving body, by column
    moving = moving[np.argsort(state.column[moving])]
    return moving[~np.isin(roots, list(trunk))]


def limb_load(model, times):
    """(nf,) N: the summed magnitudes of the measured forces (``model.external_loads``)
    on the :func:`limb_bodies` at ``times`` (nf,) s, or None when no measured load acts
    there or a load has no data at some of the times."""
    from ..forces.data_loads import sample

    limb = set(int(b) for b in limb_bodies(model))
    loads = [ld for ld in getattr(model, "external_loads", ()) if ld.body in limb]
    if not loads:
        return None
    total = np.zeros(len(times))
    for load in loads:
        F = sample(load.force, times)
        if F is None:
            return None
        total += np.linalg.norm(F, axis=1)  # (in whichever frame it is given)
    return total


def stance_depth(load):
    """(nf,) int: for each frame with ``load`` (nf,) ≥ LOADED × its peak, the number of
    frames to the nearest frame below that (or to the trial's end); 0 elsewhere."""
    load = np.asarray(load, dtype=float)
    nf = len(load)
    loaded = load >= LOADED * load.max() if nf and load.max() > 0 else np.zeros(nf, dtype=bool)
    depth = np.zeros(nf, dtype=int)
    run = 0
    for k in range(nf):  # frames since the onset
        run = run + 1 if loaded[k] else 0
        depth[k] = run
    run = 0
    for k in range(nf - 1, -1, -1):  # frames to the release
        run = run + 1 if loaded[k] else 0
        depth[k] = min(depth[k], run)
    return depth


def cut_preference(model, times):
    """(nf,) int :func:`stance_depth` of the limb's load at ``times`` (nf,) s, for
    :func:`openfdk.study.chunks.plan_segments`, or None (the equal split stands)."""
    load = limb_load(model, np.asarray(times, dtype=float))
    if load is None or not np.any(load > 0):
        return None
    return stance_depth(load)


__all__ = ["LOADED", "limb_bodies", "limb_load", "stance_depth", "cut_preference"]
