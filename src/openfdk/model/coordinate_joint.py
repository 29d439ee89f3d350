"""OpenSim's joints in openfdk's maximal coordinates: a SpatialTransform as constraint
rows, its coordinates as measures.

An OpenSim joint places its child frame M in its parent frame F by a SpatialTransform
of six axes (OpenSim's CustomJoint; Pin, Slider, Universal, Gimbal, Ball, Free and
Planar joints are fixed choices of it):

    R_FM = Rot(a1, f1(q)) Rot(a2, f2(q)) Rot(a3, f3(q))      (intrinsic: each axis in the
                                                              frame the previous rotations left)
    p_FM = g1(q) t1 + g2(q) t2 + g3(q) t3                     (in F)

with unit axes a_i, t_i and functions f_i, g_i of the joint's coordinates q (constant,
linear, splines, …). openfdk keeps the bodies' poses as its unknowns (docs/design.md §1) and
turns this into measures and rows:

1. Constant rotations are moved to the end: Rot(a, θ) after a constant C equals
   C·Rot(a, θ) = Rot(C a, θ)·C, so R_FM = Rot(a'_1, θ_1) … Rot(a'_k, θ_k)·C with the
   k ≤ 3 moving axes a' = C a. In a basis E of F in which the moving axes are coordinate
   axes, Eᵀ R_FM Cᵀ E is an intrinsic Cardan (or Euler) sequence, so the angles θ are a
   :class:`~openfdk.model.rotation_angles.RotationAngles` measure of the frames F·E and
   M·Cᵀ·E — exact, with its analytic Jacobian and bias. Moving axes that are not
   orthogonal (a wrist's, a thumb's) are angles about those axes themselves
   (:class:`~openfdk.model.axis_angles.AxisAngles`, Davenport angles), two of them
   completed by a'_1 × a'_2; axes that do not span space are refused by name.
2. Translations: with the moving translation axes completed to a basis T, the
   components τ = T⁻¹ (p_FM − Σ_constant c_i t_i) are a linear measure of the vector
   F → M expressed in F.
3. Each coordinate is *measured* by one axis whose function is linear in it
   (q = (θ − intercept)/slope): the coordinate is that measure, named after it
   (``model.measures['knee_angle_r']``). Every other axis is a row
   θ_i − f_i(q) = 0 or τ_i − g_i(q) = 0 (:class:`~openfdk.model.function_measure.FunctionOf`,
   op-code OP_FUNCTION: value, Jacobian f'(q) M_q and bias f''(q) q̇² + f'(q) b_q), and
   every unused angle or translation is a row "= 0". A joint has 6 − (its coordinates)
   rows, with reactions.

A coordinate that no axis measures linearly (one that only enters through splines) is
refused with its name: openfdk cannot recover it from the bodies' poses exactly —
unless a CoordinateCouplerConstraint makes it a function of another joint's coordinate
(Rajagopal 2016's patella: ``knee_angle_r_beta = knee_angle_r``). Then it is that
function of that coordinate's measure, every axis it moves is a row (the patella is
placed on the femur by the knee's angle), and the coupler holds by construction.
The alternative considered, coordinates as extra unknowns beside the poses (mixed
coordinates), is discussed in docs/architecture.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .builder import _stack
from .constraints import JOINT, Constraint
from .function_measure import FunctionOf
from .joint_records import JointRecord, record_joint
from .measures import Linear
from .model import ModelError
from .axis_angles import MIN_TRIPLE_PRODUCT, AxisAngles
from .rotation_angles import RotationAngles
from .timefunctions import TimeFunction

#: orthogonality tolerance of moving rotation axes (|a_i · a_j|)
AXIS_TOLERANCE = 1e-9
COORDINATE_UNITS = {"rotational": "angle", "translational": "length", "coupled": "angle"}


@dataclass(frozen=True, eq=False)
class Coordinate:
    """A joint coordinate (OpenSim's Coordinate).

    name : str; joint : the joint whose axis measures it; motion : "rotational",
    "translational" or "coupled"; unit : "angle" (rad) or "length" (m); measure : its
    scalar Measure; default : value at the reference pose (SI); range : (2,) (SI);
    clamped, locked, prescribed : OpenSim's flags (a locked coordinate is held at
    ``default`` by a row ``{name}.locked``; a prescribed one follows its function of
    time, driver ``{name}.prescribed``); opensim_motion : OpenSim's motion type where it
    differs from ``motion`` (a CustomJoint coordinate moved through a spline: coupled),
    "" otherwise."""

    name: str
    joint: str
    motion: str
    unit: str
    measure: object
    default: float = 0.0
    range: tuple = (-np.inf, np.inf)
    clamped: bool = False
    locked: bool = False
    prescribed: bool = False
    opensim_motion: str = ""

    @property
    def opensim_rotational(self):
        """Whether OpenSim calls this coordinate rotational: it writes and reads its
        ``.mot`` column in degrees (``inDegrees=yes``) and names its generalised force
        ``_moment``; a coupled one's column is in rad and its force is ``_force``
        (:func:`openfdk.io.opensim.document.opensim_motion_type`)."""
        return (self.opensim_motion or self.motion) == "rotational"


@dataclass(frozen=True)
class Axis:
    """One axis of a SpatialTransform: ``axis`` (3,) unit, in F (translations) or in the
    intermediate frame (rotations); ``coordinate`` name or None (a constant axis);
    ``function``: PiecewisePolynomial of the coordinate (SI: rad or m of the coordinate ->
    rad or m of the axis), or the constant value (float) when ``coordinate`` is None."""

    name: str
    axis: np.ndarray
    coordinate: str | None
    function: object


def affine(function, rtol=1e-12):
    """(slope, intercept) if the PiecewisePolynomial ``function`` is one affine function
    on the whole real line, else None: OpenSim's LinearFunction, a MultiplierFunction of
    one, a degree-1 PolynomialFunction, and a spline through collinear points (a
    SimmSpline through two points, y = −x in the knee_l of jam-resources'
    full_body_healthy_knee.osim), whose pieces and end tangents are that line to
    ``rtol`` of its values and slope."""
    if not function.n_pieces:
        if not np.array_equal(function.left, function.right) or np.any(function.left[2:] != 0.0):
            return None
        return float(function.left[1]), float(function.left[0])
    b = function.breaks
    slope = float(function.coeffs[0, 1])
    intercept = float(function.coeffs[0, 0]) - slope * float(b[0])
    h = np.diff(b)
    # each piece and end as (value at its start, slope, the higher terms' size over the piece)
    ends = [(function.left, b[0], 0.0), (function.right, b[-1], 0.0)]
    pieces = [(c, x0, dx) for c, x0, dx in zip(function.coeffs, b[:-1], h)] + ends
    scale = max(np.max(np.abs(function.coeffs[:, 0])), abs(slope) * float(b[-1] - b[0]), 1e-300)
    for c, x0, dx in pieces:
        higher = np.abs(c[2:]) * np.maximum(dx, 1.0) ** np.arange(2, len(c))
        if (abs(c[0] - (intercept + slope * x0)) > rtol * scale or abs(c[1] - slope) > rtol * max(abs(slope), 1e-300)
                or np.any(higher > rtol * scale) or (dx == 0.0 and np.any(c[2:] != 0.0))):
            return None
    return slope, intercept


def _rotation(axis, angle):
    """Rodrigues: Rot(axis, angle) (3, 3) for a unit axis (3,)."""
    k = np.asarray(axis, float)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def _complete(a):
    """A right-handed orthonormal basis (3, 3) whose third column is the unit vector a."""
    helper = np.eye(3)[int(np.argmin(np.abs(a)))]
    u = np.cross(helper, a)
    u /= np.linalg.norm(u)
    return np.column_stack([u, np.cross(a, u), a])


def _rotation_basis(joint, moving):
    """(E (3, 3), sequence, signs (3,), slot of each angle (3,) or None) for the moving
    axes ``moving`` [(slot, a'_k)] (module docstring, step 1); E is None when the axes are
    not orthogonal: sequence is then the axes N (3, 3) of :class:`AxisAngles` (rows)."""
    if not moving:
        return np.eye(3), "xyz", (1.0, 1.0, 1.0), (None, None, None)
    if len(moving) == 1:
        (k, a), = moving
        return _complete(a), "zxy", (1.0, 1.0, 1.0), (k, None, None)
    (k1, a1), (k2, a2) = moving[:2]
    slots = (k1, k2, moving[2][0] if len(moving) == 3 else None)
    if abs(a1 @ a2) > AXIS_TOLERANCE:
        return None, _general_axes(joint, [a for _, a in moving]), (1.0, 1.0, 1.0), slots
    e3 = np.cross(a1, a2)
    E = np.column_stack([a1, a2, e3])
    if len(moving) == 2:
        return E, "xyz", (1.0, 1.0, 1.0), slots
    k3, a3 = moving[2]
    if abs(abs(a3 @ a1) - 1.0) < AXIS_TOLERANCE:
        return E, "xyx", (1.0, 1.0, float(np.sign(a3 @ a1))), slots
    if abs(abs(a3 @ e3) - 1.0) < AXIS_TOLERANCE:
        return E, "xyz", (1.0, 1.0, float(np.sign(a3 @ e3))), slots
    return None, _general_axes(joint, [a for _, a in moving]), (1.0, 1.0, 1.0), slots


def _general_axes(joint, axes):
    """N (3, 3), rows n1, n2, n3 of :class:`AxisAngles`: the moving axes, completed by
    n1 × n2 when there are two (its angle is then a row = 0). ModelError unless they span
    space (a third axis along the first of two non-orthogonal ones has no angles)."""
    if len(axes) == 2:
        n3 = np.cross(axes[0], axes[1])
        axes = axes + [n3 / max(float(np.linalg.norm(n3)), 1e-300)]
    N = np.array(axes, dtype=float)
    if not abs(np.linalg.det(N)) >= MIN_TRIPLE_PRODUCT:  # (parallel axes: NaN or 0)
        raise ModelError(f"joint {joint!r}: its moving rotation axes {N.round(6).tolist()} do not span space: no "
                         "three angles describe its rotations")
    return N


def _translation_basis(joint, moving):
    """T (3, 3): the moving translation axes [(slot, t)] completed to a basis; slots (3,)."""
    if not moving:
        return np.eye(3), (None, None, None)
    axes = [t for _, t in moving]
    A = np.column_stack(axes)
    if np.linalg.matrix_rank(A, tol=1e-9) < len(axes):
        raise ModelError(f"joint {joint!r}: its moving translation axes {[t.round(6).tolist() for t in axes]} are "
                         "not independent")
    # complete with the orthogonal complement of the moving axes
    U, _, _ = np.linalg.svd(A, full_matrices=True)
    extra = [U[:, r] for r in range(len(axes), 3)]
    T = np.column_stack(axes + extra)
    slots = tuple(k for k, _ in moving) + (None,) * (3 - len(moving))
    return T, slots


def add_coordinate_joint(b, name, parent, child, rotations, translations, coordinates, joint_type="custom",
                         coupled=None):
    """Add an OpenSim joint to the builder ``b``: its rows (one Constraint ``name``,
    kind joint, with reactions) and its coordinates' measures (named measures).

    parent, child : qualified frames "body.frame" (OpenSim's parent frame F and child
    frame M); rotations, translations : 3 :class:`Axis` each (OpenSim's rotation1-3,
    translation1-3); coordinates : {name: unit} of the coordinates this joint defines
    ("angle" or "length"); coupled : {name: scalar Measure} for coordinates that no axis
    measures linearly but a CoordinateCouplerConstraint defines as a function of another
    coordinate (Rajagopal's patella: knee_angle_r_beta = knee_angle_r): that measure is
    the coordinate, and every axis moved by it is a row. Returns {coordinate name: scalar
    Measure}.
    """
    coupled = coupled or {}
    fa, fb = b.frame(parent), b.frame(child)
    ia, ib = b._body_index(fa.body), b._body_index(fb.body)
    if ia == ib:
        raise ModelError(f"joint {name!r}: parent and child are on the same body {fa.body!r}")
    # 1. rotations: constants moved to the end, moving axes in a basis E
    C = np.eye(3)
    moving = []
    for k, ax in enumerate(rotations):
        if ax.coordinate is None:
            C = C @ _rotation(ax.axis, float(ax.function))
        else:
            moving.append((k, C @ ax.axis))
    E, sequence, signs, angle_slot = _rotation_basis(name, moving)
    if E is None:  # non-orthogonal moving axes (the wrist's, the thumb's): angles about them
        angles = AxisAngles(ia, fa.R_BF, ib, fb.R_BF @ C.T, sequence, name=f"{name}.angles")
    else:
        angles = RotationAngles(ia, fa.R_BF @ E, ib, fb.R_BF @ C.T @ E, sequence, signs, name=f"{name}.angles")
    slot_measure = {}
    free_rows = []  # (label, scalar measure that must be 0)
    for r in range(3):
        m = Linear([(np.eye(3)[[r]], angles)])
        if angle_slot[r] is None:
            free_rows.append((f"r{r + 1}", m))
        else:
            slot_measure[("rotation", angle_slot[r])] = m
    # 2. translations: components along the moving axes, constants removed
    p_const = sum((float(ax.function) * ax.axis for ax in translations if ax.coordinate is None), np.zeros(3))
    T, trans_slot = _translation_basis(name, [(k, ax.axis) for k, ax in enumerate(translations)
                                              if ax.coordinate is not None])
    Tinv = np.linalg.inv(T)
    p_FM = b.vector(parent, child, expressed_in=parent)
    tau = Linear([(Tinv, p_FM)], offset=-Tinv @ p_const, units=("length",) * 3, name=f"{name}.translation")
    for r in range(3):
        m = Linear([(np.eye(3)[[r]], tau)])
        if trans_slot[r] is None:
            free_rows.append((f"t{r + 1}", m))
        else:
            slot_measure[("translation", trans_slot[r])] = m
    # 3. each coordinate measured by an axis linear in it
    axes = [("rotation", k, ax) for k, ax in enumerate(rotations)] + \
           [("translation", k, ax) for k, ax in enumerate(translations)]
    defined, measuring = {}, set()
    for cname, unit in coordinates.items():
        for kind, k, ax in axes:
            line = affine(ax.function) if ax.coordinate == cname else None
            if line is not None and line[0] != 0.0:
                slope, intercept = line
                defined[cname] = Linear([(np.array([[1.0 / slope]]), slot_measure[(kind, k)])],
                                        offset=np.array([-intercept / slope]), units=(unit,), name=cname)
                measuring.add((kind, k))
                break
        else:
            if cname in coupled:
                defined[cname] = coupled[cname]
                continue
            raise ModelError(f"joint {name!r}: coordinate {cname!r} moves no axis through a linear function, so "
                             "openfdk cannot measure it from the bodies' poses (it enters only through splines or "
                             "other non-linear functions), and no CoordinateCouplerConstraint makes it a function "
                             "of another coordinate")
    rows = []
    for kind, k, ax in axes:
        if ax.coordinate is None or (kind, k) in measuring:
            continue
        if ax.coordinate not in defined:
            raise ModelError(f"joint {name!r}: axis {ax.name} is a function of {ax.coordinate!r}, which is not one "
                             "of the joint's coordinates")
        unit = "angle" if kind == "rotation" else "length"
        fq = FunctionOf(ax.function, defined[ax.coordinate], unit)
        rows.append((ax.name, Linear([(np.ones((1, 1)), slot_measure[(kind, k)]), (-np.ones((1, 1)), fq)])))
    rows += free_rows
    record_joint(b, JointRecord(name, "custom", fa.name, fb.name, rotations=tuple(rotations),  # qualified frames
                                translations=tuple(translations)))
    for cname, m in defined.items():
        b.add_measure(cname, m)
    if rows:
        measure = _stack([(np.ones((1, 1)), m) for _, m in rows])
        b._add_constraint(Constraint(name, measure, JOINT, np.zeros(measure.size), None, True,
                                     tuple(f"{name}.{label}" for label, _ in rows), joint_type))
    return defined


def add_coupler(b, name, independent, dependent, function, by_construction=False):
    """OpenSim's CoordinateCouplerConstraint: the row q_dep − f(q_indep) = 0 (kind joint,
    with its reaction); ``function``: PiecewisePolynomial (SI units of the two
    coordinates). ``by_construction``: q_dep's measure is f(q_indep) itself (its joint
    has no axis linear in it, module docstring), so the coupler holds without a row and
    is only recorded."""
    if not by_construction:
        q_i, q_d = b.measure(independent), b.measure(dependent)
        fq = FunctionOf(function, q_i, q_d.units[0])
        measure = Linear([(np.ones((1, 1)), q_d), (-np.ones((1, 1)), fq)])
        b._add_constraint(Constraint(name, measure, JOINT, np.zeros(1), None, True, (name,), "coupler"))
    record_joint(b, JointRecord(name, "coupler", independent=independent, dependent=dependent, function=function))


class CoordinateTimeFunction(TimeFunction):
    """A prescribed coordinate's function of time: f(t) from a PiecewisePolynomial of t
    (s -> rad or m), with its first and second derivative."""

    size = 1

    def __init__(self, function):
        self.function = function

    def derivatives(self, t):
        f, df, d2f = self.function.evaluate(float(t))
        return np.array([f]), np.array([df]), np.array([d2f])
