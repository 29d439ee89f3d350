"""Kinematic measures: value m(q), Jacobian M = ∂m/∂q̂ and acceleration bias b.

docs/design.md §1: every geometric quantity is a *measure* with ṁ = M v and m̈ = M v̇ + b,
where v = [ṙ_i; ω'_i] per moving body and q̂ = [δr_i; δπ'_i] (body-frame rotation).
Joints, drivers, marker residuals, muscle and ligament lengths and FDK DOFs are built from
these. ``evaluate(state, order)`` returns ``(value, M, b)``:

* order 0: ``(value (m,), None, None)``
* order 1: ``(value, M (m, 6 n_moving), None)``
* order 2: ``(value, M, b (m,))`` — needs the velocities in ``state``.

Each measure also declares ``units``: a tuple of "length" or "angle" or "1" per
component, used for unit conversion of drivers and reports.
"""

from __future__ import annotations

import numpy as np

from ..numerics.spatial import xyz_angles_from_matrix
from .kernels import relative_vector

__all__ = [
    "Measure",
    "PointPosition",
    "RelativeVector",
    "Distance",
    "AxisDot",
    "RelativeAngles",
    "Linear",
]


def _cross(a, b):
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


class Measure:
    """Base class. Subclasses set ``size`` and ``units`` and implement ``evaluate``."""

    size: int = 0
    units: tuple = ()
    name: str = ""

    def evaluate(self, state, order=1):  # pragma: no cover - interface
        raise NotImplementedError

    def bodies(self):
        """Indices of the bodies this measure depends on."""
        raise NotImplementedError

    def __repr__(self):
        return f"{type(self).__name__}({self.name!r})"


class PointPosition(Measure):
    """World position of a point fixed in a body: p_WP = r_WB + R_WB p_BP.

    ∂p/∂δr = I, ∂p/∂δπ' = −R_WB p̃_BP, b = R_WB ω̃' ω̃' p_BP  (docs/design.md §1).
    body : int body index; p_BP : (3,) m.
    """

    size = 3
    units = ("length",) * 3

    def __init__(self, body, p_BP, name=""):
        self.body = int(body)
        self.p_BP = np.asarray(p_BP, dtype=float)
        self._skew_p = _skew(self.p_BP)
        self.name = name

    def bodies(self):
        return (self.body,)

    def evaluate(self, state, order=1):
        i = self.body
        R = state.R_WB[i]
        value = state.p_WB[i] + R @ self.p_BP
        if order == 0:
            return value, None, None
        M = np.zeros((3, state.n_coords))
        c = state.column[i]
        if c >= 0:
            M[0, c] = M[1, c + 1] = M[2, c + 2] = 1.0
            M[:, c + 3 : c + 6] = -(R @ self._skew_p)
        if order == 1:
            return value, M, None
        w = state.w_BB[i]
        b = R @ _cross(w, _cross(w, self.p_BP))
        return value, M, b

    def velocity(self, state):
        """ṗ_WP (3,) m/s from the state's velocities."""
        i = self.body
        return state.v_WB[i] + state.R_WB[i] @ _cross(state.w_BB[i], self.p_BP)


class RelativeVector(Measure):
    """Vector from point A to point B expressed in the frame of body k (world if None).

    w = R_Wkᵀ (p_WB − p_WA). M = R_Wkᵀ (M_B − M_A) plus w̃ in body k's rotation columns;
    b = R_Wkᵀ b_u − 2 ω̃'_k R_Wkᵀ u̇ + ω̃'_k ω̃'_k w  (u = p_WB − p_WA).
    """

    size = 3
    units = ("length",) * 3

    def __init__(self, point_a: PointPosition, point_b: PointPosition, expressed_in=None, name=""):
        self.point_a = point_a
        self.point_b = point_b
        self.frame = None if expressed_in is None else int(expressed_in)
        self.name = name

    def bodies(self):
        extra = () if self.frame is None else (self.frame,)
        return tuple(sorted(set(self.point_a.bodies() + self.point_b.bodies() + extra)))

    def evaluate(self, state, order=1):
        value, M, b, _ = self._kernel(state, order)
        return value, (M if order >= 1 else None), (b if order >= 2 else None)

    def _kernel(self, state, order):
        """(w, M, b, ẇ) from the numba kernel :func:`openfdk.model.kernels.relative_vector`."""
        return relative_vector(
            state.p_WB, state.R_WB, state.w_BB, state.v_WB, state.column,
            self.point_a.body, self.point_a.p_BP, self.point_b.body, self.point_b.p_BP,
            -1 if self.frame is None else self.frame, state.n_coords, order,
        )


class Distance(Measure):
    """Distance between two points, l = |u|, u = p_WB − p_WA (m).

    M = eᵀ (M_B − M_A); b = eᵀ b_u + (u̇·u̇ − (e·u̇)²)/l with e = u/l.
    """

    size = 1
    units = ("length",)

    def __init__(self, point_a: PointPosition, point_b: PointPosition, name=""):
        self.vector = RelativeVector(point_a, point_b, None)
        self.name = name

    def bodies(self):
        return self.vector.bodies()

    def evaluate(self, state, order=1):
        u, Mu, bu, du = self.vector._kernel(state, order)
        length = float(np.sqrt(u @ u))
        value = np.array([length])
        if order == 0:
            return value, None, None
        if length == 0.0:
            raise FloatingPointError(f"distance measure {self.name!r}: the two points coincide")
        e = u / length
        M = (e @ Mu)[None, :]
        if order == 1:
            return value, M, None
        b = np.array([e @ bu + (du @ du - (e @ du) ** 2) / length])
        return value, M, b


class AxisDot(Measure):
    """Dot product of two body-fixed unit axes: c = (R_Wa n_a)·(R_Wb n_b) (dimensionless).

    ∂c/∂δπ'_a = n_a × (R_Waᵀ R_Wb n_b), ∂c/∂δπ'_b = n_b × (R_Wbᵀ R_Wa n_a);
    b = (R_Wa ω̃'_a ω̃'_a n_a)·b + a·(R_Wb ω̃'_b ω̃'_b n_b) + 2 ȧ·ḃ.
    Used for the orientation rows of weld, revolute and prismatic joints.
    """

    size = 1
    units = ("1",)

    def __init__(self, body_a, n_a, body_b, n_b, name=""):
        self.body_a, self.body_b = int(body_a), int(body_b)
        self.n_a = np.asarray(n_a, dtype=float)
        self.n_b = np.asarray(n_b, dtype=float)
        self.name = name

    def bodies(self):
        return tuple(sorted({self.body_a, self.body_b}))

    def evaluate(self, state, order=1):
        Ra, Rb = state.R_WB[self.body_a], state.R_WB[self.body_b]
        a, bvec = Ra @ self.n_a, Rb @ self.n_b
        value = np.array([a @ bvec])
        if order == 0:
            return value, None, None
        M = np.zeros((1, state.n_coords))
        ca, cb = state.column[self.body_a], state.column[self.body_b]
        if ca >= 0:
            M[0, ca + 3 : ca + 6] += _cross(self.n_a, Ra.T @ bvec)
        if cb >= 0:
            M[0, cb + 3 : cb + 6] += _cross(self.n_b, Rb.T @ a)
        if order == 1:
            return value, M, None
        wa, wb = state.w_BB[self.body_a], state.w_BB[self.body_b]
        da = Ra @ _cross(wa, self.n_a)
        db = Rb @ _cross(wb, self.n_b)
        ba = Ra @ _cross(wa, _cross(wa, self.n_a))
        bb = Rb @ _cross(wb, _cross(wb, self.n_b))
        return value, M, np.array([ba @ bvec + a @ bb + 2.0 * da @ db])


class RelativeAngles(Measure):
    """Cardan angles (x-y-z, body-fixed) of frame F_b relative to frame F_a, rad.

    R_FaFb = Rx(θ0) Ry(θ1) Rz(θ2). The relative angular velocity in F_a is
    ω_rel = R_FaFb ω_Fb − ω_Fa = B(θ) θ̇ with B = [e_x, Rx e_y, Rx Ry e_z], so
    M = B⁻¹ [−R_aFaᵀ in a's rotation columns, R_FaFb R_bFbᵀ in b's] and
    b = B⁻¹ (−ω_Fa × (R_FaFb ω_Fb) − Ḃ θ̇). Singular at θ1 = ±90° (gimbal lock).
    """

    size = 3
    units = ("angle",) * 3

    def __init__(self, body_a, R_aFa, body_b, R_bFb, name=""):
        self.body_a, self.body_b = int(body_a), int(body_b)
        self.R_aFa = np.asarray(R_aFa, dtype=float)
        self.R_bFb = np.asarray(R_bFb, dtype=float)
        self.name = name

    def bodies(self):
        return tuple(sorted({self.body_a, self.body_b}))

    def evaluate(self, state, order=1):
        R_WFa = state.R_WB[self.body_a] @ self.R_aFa
        R_WFb = state.R_WB[self.body_b] @ self.R_bFb
        R_FaFb = R_WFa.T @ R_WFb
        theta = xyz_angles_from_matrix(R_FaFb)
        if order == 0:
            return theta, None, None
        s0, c0 = np.sin(theta[0]), np.cos(theta[0])
        s1, c1 = np.sin(theta[1]), np.cos(theta[1])
        B = np.array([[1.0, 0.0, s1], [0.0, c0, -s0 * c1], [0.0, s0, c0 * c1]])
        if abs(c1) < 1e-9:
            raise FloatingPointError(f"relative angles {self.name!r} (x-y'-z''): gimbal lock, the middle angle "
                                     f"(about y') is {np.degrees(theta[1]):.1f} deg")
        Binv = np.linalg.inv(B)
        M = np.zeros((3, state.n_coords))
        ca, cb = state.column[self.body_a], state.column[self.body_b]
        G_b = R_FaFb @ self.R_bFb.T
        if ca >= 0:
            M[:, ca + 3 : ca + 6] -= Binv @ self.R_aFa.T
        if cb >= 0:
            M[:, cb + 3 : cb + 6] += Binv @ G_b
        if order == 1:
            return theta, M, None
        w_Fa = self.R_aFa.T @ state.w_BB[self.body_a]
        w_Fb = self.R_bFb.T @ state.w_BB[self.body_b]
        w_rel = R_FaFb @ w_Fb - w_Fa
        dtheta = Binv @ w_rel
        d0, d1 = dtheta[0], dtheta[1]
        dB = np.array(
            [
                [0.0, 0.0, c1 * d1],
                [0.0, -s0 * d0, -c0 * c1 * d0 + s0 * s1 * d1],
                [0.0, c0 * d0, -s0 * c1 * d0 - c0 * s1 * d1],
            ]
        )
        b = Binv @ (-_cross(w_Fa, R_FaFb @ w_Fb) - dB @ dtheta)
        return theta, M, b


class Linear(Measure):
    """Linear combination of measures: m = Σ_j C_j m_j + offset.

    terms : list of (C_j (size, size_j), measure_j); offset (size,). Covers components
    (a selector row), projections on a fixed axis (an axis row) and sums/differences.
    """

    def __init__(self, terms, offset=None, units=None, name=""):
        self.terms = [(np.atleast_2d(np.asarray(C, dtype=float)), m) for C, m in terms]
        sizes = {C.shape[0] for C, _ in self.terms}
        if len(sizes) != 1:
            raise ValueError(f"linear measure {name!r}: terms have different row counts {sizes}")
        for C, m in self.terms:
            if C.shape[1] != m.size:
                raise ValueError(
                    f"linear measure {name!r}: coefficient matrix {C.shape} does not match "
                    f"measure {m.name!r} of size {m.size}"
                )
        self.size = sizes.pop()
        self.offset = np.zeros(self.size) if offset is None else np.asarray(offset, dtype=float)
        if units is None:
            # a row inherits the unit of the components it combines, if they agree
            units = []
            for r in range(self.size):
                kinds = {
                    m.units[j] for C, m in self.terms for j in range(m.size) if C[r, j] != 0.0
                }
                units.append(kinds.pop() if len(kinds) == 1 else "1")
        self.units = tuple(units)
        self.name = name

    def bodies(self):
        out = set()
        for _, m in self.terms:
            out.update(m.bodies())
        return tuple(sorted(out))

    def evaluate(self, state, order=1):
        if len(self.terms) == 1:
            C, m = self.terms[0]
            mv, mM, mb = m.evaluate(state, order)
            return (C @ mv + self.offset, None if order == 0 else C @ mM, None if order < 2 else C @ mb)
        value = self.offset.copy()
        M = None if order == 0 else np.zeros((self.size, state.n_coords))
        b = None if order < 2 else np.zeros(self.size)
        for C, m in self.terms:
            mv, mM, mb = m.evaluate(state, order)
            value += C @ mv
            if order >= 1:
                M += C @ mM
            if order >= 2:
                b += C @ mb
        return value, M, b
