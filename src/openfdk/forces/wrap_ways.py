"""The way round an ellipsoid a wrapped path takes, held from one FDK frame to the next.

Where the straight line between a path's anchors crosses an ellipsoid whose ``side`` is
free (OpenSim's quadrant ``all``), the geodesic can go either way round. Evaluated alone,
the path takes the shorter way (:func:`~.wrap_kernels.ellipsoid_wrap_from`), and where
the two are equally long the path's direction, and the force it carries, jump. On DM's
lateral patellofemoral ligament (``lPFL5`` over ``lPFL_r``) the equilibrium of the
patella in tm_med1 at 2.708 s lies across such a jump: f^FDK(α) has no root there, and
Newton stalled at 1.7 N from every start (docs/knee-gait-solver-history.md, stop 73).
A taut strand over a bone does not jump to the other side; it stays on its way round
until the line stops crossing the bone. So FDK holds it: when a frame converges, each
path's way round (:func:`~.wrap_kernels.way_round`) is held, and the next frame's
evaluations take the geodesic on the held way (the nearer of the two), whatever pose
they are at. f^FDK is then one function of α within a frame, and its root is the
equilibrium of the strand on the side it was on. A path that stopped wrapping is
released: when its line crosses the ellipsoid again, the shorter way is taken, as
outside FDK (inverse dynamics, kinematics, OpenSim's own paths) always. When a frame
finds no equilibrium with the ways held (every restart failed), the ways are released
and the frame is solved again, each path taking the shorter way at each pose: the strand
slips over to the other side where it cannot stay (fdk/analysis.py).

Only the force elements' paths (ligaments, muscles) are held; a measure's path
(``measures:`` of type path) is evaluated alone.
"""

from __future__ import annotations

import numpy as np

from .wrap_kernels import ELLIPSOID, HELD, HOLD, OPENSIM_PLANE, WAY


def wrap_nodes(forces):
    """The WrapNodes (:class:`~.wrapping.WrapNodes`) of every path set of ``forces``
    (ForceElements): its sets' wrapped paths and those over coordinate surfaces."""
    out = []
    for fs in forces.sets:
        paths = getattr(fs, "paths", None)
        if paths is None:
            continue
        if paths.wrapped is not None:
            out.append(paths.wrapped)
        if getattr(paths, "mixed", None) is not None:
            out.append(paths.mixed.wrap)
    return out


def geodesic_rows(nodes):
    """Row indices (m,) of ``nodes``' geodesic ellipsoids (not OpenSim's planar rule,
    whose warm rows hold other data)."""
    flags = nodes.limits[:, 1].astype(np.int64)
    return np.flatnonzero((nodes.kinds == ELLIPSOID) & ((flags & OPENSIM_PLANE) == 0))


def hold_ways(forces):
    """Hold each geodesic's way round from its last solve; a node not wrapping is
    released."""
    for nodes in wrap_nodes(forces):
        rows = geodesic_rows(nodes)
        w = nodes.warm
        w[rows, HOLD:HOLD + 3] = w[rows, WAY:WAY + 3]
        w[rows, HELD] = (w[rows, 3] > 0.0).astype(float)


def any_held(forces):
    """Whether any path of ``forces`` has a held way round."""
    return any(np.any(nodes.warm[geodesic_rows(nodes), HELD] > 0.0) for nodes in wrap_nodes(forces))


def release_ways(forces):
    """Release every held way and drop the warm starts, so that the next solve of each
    geodesic is cold and takes the shorter way (a run's start)."""
    for nodes in wrap_nodes(forces):
        rows = geodesic_rows(nodes)
        nodes.warm[rows, HELD] = 0.0
        nodes.warm[rows, 3] = 0.0


def held_ways(forces):
    """The held ways, for a checkpoint: a list of (m_i, 4) arrays [way (3,), held] per
    WrapNodes of ``forces``."""
    return [nodes.warm[geodesic_rows(nodes), HOLD:HELD + 1].copy() for nodes in wrap_nodes(forces)]


def restore_ways(forces, saved):
    """Hold the ways of a checkpoint's :func:`held_ways` (untrusted: ValueError unless
    each array has its WrapNodes' shape and finite entries); the warm starts are dropped."""
    kernels = wrap_nodes(forces)
    if not isinstance(saved, (list, tuple)) or len(saved) != len(kernels):
        raise ValueError("held wrap ways: expected one array per wrapped path set")
    for nodes, ways in zip(kernels, saved):
        rows = geodesic_rows(nodes)
        ways = np.asarray(ways, dtype=float)
        if ways.shape != (len(rows), 4) or not np.all(np.isfinite(ways)):
            raise ValueError(f"held wrap ways: expected a finite ({len(rows)}, 4) array")
        nodes.warm[rows, HOLD:HELD + 1] = ways
        nodes.warm[rows, 3] = 0.0


__all__ = ["wrap_nodes", "geodesic_rows", "any_held", "hold_ways", "release_ways", "held_ways", "restore_ways"]
