"""Angles and orientations as model files give them (``orientation:`` of bodies, frames
and visual meshes): Cardan x-y-z angles in the file's angle unit, or a quaternion, a
rotation matrix or a rotation vector (docs/model-file.md). Kept apart from
:mod:`.modelfile` so that the sections it loads (visual meshes) can read orientations
without importing it back."""

from __future__ import annotations

import numpy as np

from ..numerics.spatial import quat_from_rotvec, rotation_matrix_xyz


def _angles(ctx, value, path):
    """Three angles in the file's angle unit -> rad (3,). Warns when the file's angles are
    in rad but a value exceeds a full turn (2π): such numbers are almost always degrees."""
    v = ctx.vector(value, path, n=3)
    if ctx.angle == 1.0 and np.any(np.abs(v) > 2 * np.pi):
        from .plausibility import warn_plausibility

        big = float(v[np.argmax(np.abs(v))])
        warn_plausibility(f"{ctx.source}: {path}: {big:g} rad is more than a full turn; the file's angles are in rad "
                          "(the default): are these degrees? (set units: {angle: deg})")
    return v * ctx.angle


def _orientation(value, path, ctx):
    """Cardan x-y-z angles (file angle unit), or {quaternion: [...]}, {matrix: [[...]]},
    {rotation_vector: [...]} -> rotation matrix (3, 3)."""
    if value is None:
        return np.eye(3)
    if isinstance(value, dict):
        ctx.keys(value, path, ["xyz", "quaternion", "matrix", "rotation_vector"])
        if len(value) != 1:
            raise ctx.error(path, "give exactly one of xyz, quaternion, matrix, rotation_vector")
        kind, v = next(iter(value.items()))
        if kind == "xyz":
            return rotation_matrix_xyz(_angles(ctx, v, f"{path}.xyz"))
        if kind == "rotation_vector":
            from ..numerics.spatial import rotation_matrix

            return rotation_matrix(quat_from_rotvec(_angles(ctx, v, f"{path}.{kind}")))
        if kind == "quaternion":
            from ..numerics.spatial import normalize_quat, rotation_matrix

            return rotation_matrix(normalize_quat(ctx.vector(v, f"{path}.quaternion", n=4)))
        M = ctx.vector(v, f"{path}.matrix", shape=(3, 3))
        if not np.allclose(M @ M.T, np.eye(3), atol=1e-6) or np.linalg.det(M) <= 0:
            raise ctx.error(f"{path}.matrix", "is not a rotation matrix")
        return M
    return rotation_matrix_xyz(_angles(ctx, value, path))
