"""A checkpoint's carry checked before a resumed run uses it.

What a step carries from one frame to the next (poses, a frame's KKT matrix, its marker
residuals, the FDK Jacobian, ...) is saved in the checkpoint's parts and restored on
``--resume`` (:mod:`.checkpoint`). It is untrusted input: anyone who knows the format
can rewrite a part and its sidecar. Its arrays go into compiled kernels that do not
check their bounds, so an array of another shape than the model gives it makes them
read or write outside its memory: a crash, not an error (the fuzz's ``checkpoint``
kind found one, a KKT matrix of shape (2, 0)). Each step's ``restore`` checks what it
takes back with these functions; their ValueError ends the resume in one line naming
the checkpoint folder (:func:`.driver.drive`).
"""

from __future__ import annotations

import numpy as np

#: dtype kinds accepted for each expected kind of array
_KINDS = {"f": "f", "i": "iu", "b": "b"}


def _shape_text(shape):
    return "(" + ", ".join("any" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def array(a, shape, what, kind="f", finite=True):
    """``a`` when it is a numpy array of ``shape`` (an int per axis, None: any length)
    whose dtype is of ``kind`` ("f" float, "i" integer, "b" bool), finite where
    ``finite`` (float arrays); ValueError naming ``what`` otherwise."""
    if not isinstance(a, np.ndarray):
        raise ValueError(f"{what}: expected an array of shape {_shape_text(shape)}, got {type(a).__name__}")
    if a.ndim != len(shape) or any(s is not None and n != s for n, s in zip(a.shape, shape)):
        raise ValueError(f"{what}: expected an array of shape {_shape_text(shape)}, got {a.shape}")
    if a.dtype.kind not in _KINDS[kind]:
        raise ValueError(f"{what}: expected an array of {dict(f='floats', i='integers', b='booleans')[kind]}, "
                         f"got {a.dtype}")
    if kind == "f" and finite and not np.isfinite(a).all():
        raise ValueError(f"{what}: non-finite values")
    return a


def optional(a, shape, what, kind="f", finite=True):
    """None, or ``a`` checked by :func:`array`."""
    return None if a is None else array(a, shape, what, kind, finite)


def number(x, what):
    """``x`` as a finite float; ValueError naming ``what`` otherwise."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (int, float, np.integer, np.floating)) \
            or not np.isfinite(x):
        raise ValueError(f"{what}: expected a finite number, got {str(x)[:40]}")
    return float(x)


def states(state, reference, what):
    """``state`` when it is a BodyStates like ``reference`` (the model's initial state):
    every array of the same shape and dtype, ``column``, ``moving`` and ``n_coords``
    equal to its (they index the kernels' arrays), poses and velocities finite."""
    from ..model.state import BodyStates

    if not isinstance(state, BodyStates):
        raise ValueError(f"{what}: expected the bodies' states, got {type(state).__name__}")
    for name in BodyStates.__slots__:
        a, r = getattr(state, name), getattr(reference, name)
        if name == "n_coords":
            if not isinstance(a, (int, np.integer)) or isinstance(a, bool) or a != r:
                raise ValueError(f"{what}: {a!r} coordinates, the model's {r}")
            continue
        if not isinstance(a, np.ndarray) or a.shape != r.shape or a.dtype != r.dtype:
            raise ValueError(f"{what}: {name} of shape {getattr(a, 'shape', type(a).__name__)}, the model's {r.shape}")
    if not (np.array_equal(state.column, reference.column) and np.array_equal(state.moving, reference.moving)):
        raise ValueError(f"{what}: the bodies' coordinate columns are not the model's")
    for name in ("p_WB", "quat_WB", "R_WB", "w_BB", "v_WB"):
        if not np.isfinite(getattr(state, name)).all():
            raise ValueError(f"{what}: {name} has non-finite values")
    return state


def frame_data_tracking(data, n, m, n_markers, n_fdk, what):
    """A tracked frame's FrameData as the velocity stage uses it: the KKT matrix
    (n + m, n + m), the marker Jacobian (3 n_markers, n), the markers' visibility
    (n_markers,), α (n_fdk,) or None and the time."""
    from ..model.framedata import FrameData

    if not isinstance(data, FrameData):
        raise ValueError(f"{what}: expected a frame's data, got {type(data).__name__}")
    number(data.t, f"{what}: t")
    array(data.kkt, (n + m, n + m), f"{what}: KKT matrix")
    array(data.J_M, (3 * n_markers, n), f"{what}: marker Jacobian")
    array(data.visible, (n_markers,), f"{what}: visible markers", kind="b")
    optional(data.alpha, (n_fdk,), f"{what}: alpha")
    return data
