"""Compiled measures: a model's measure trees as flat instruction arrays, evaluated by one
numba kernel (value, Jacobian ∂m/∂q̂ and acceleration bias b for every row at once).

Why: a measure tree evaluated in Python costs a call chain and NumPy dispatches per node
(≈ 10–20 µs each) for a few hundred flops. :class:`CompiledMeasures` compiles a list of
measures once per model into a *program* and evaluates all of its rows in one kernel
call, with no Python per measure and per frame. The Python ``Measure.evaluate`` stays as
the reference (tests compare the two, and both with finite differences on the manifold).

Program (built once, never modified)
------------------------------------
Every distinct measure object of the trees is a *node*; nodes are stored in topological
order (children before parents: a post-order walk, shared sub-measures compiled once).
Per node: ``op`` (op-code), ``node_row``/``node_size`` (its rows in the node buffers),
``i_start`` into the integer table ``iparams`` and ``f_start`` into the float table
``fparams``. The kernel :func:`evaluate_program` runs the nodes in order; a node reads
its children's rows of the buffers ``val (R,)``, ``M (R, n)``, ``b (R,)`` and writes its
own. ``out_rows`` picks the output rows (the requested rows of the root measures).

=============  =======================================  =============================
op-code        iparams                                  fparams
=============  =======================================  =============================
OP_POINT       body                                     p_BP (3)
OP_VECTOR      node_a, node_b, frame body k (−1: world) —
OP_DISTANCE    node_u (a 3-row vector node)             —
OP_AXIS_DOT    body_a, body_b                           n_a (3), n_b (3)
OP_ANGLES      body_a, body_b                           R_aFa (9), R_bFb (9) row-major
OP_LINEAR      n_terms, child_1 … child_n               offset (size), C_1 … C_n row-major
OP_ROTATION_   body_a, body_b, axes i, j, k             R_aFa (9), R_bFb (9), sign (3)
ANGLES         (any Euler/Cardan sequence, JCS angles)
OP_FUNCTION    node_u (a 1-row node)                    f as PiecewisePolynomial.to_params()
OP_AXIS_ANGLES body_a, body_b                           R_aFa (9), R_bFb (9), axes n1, n2, n3 (9) row-major
               (m = f(u): OpenSim's coupled joint rows and coordinate couplers)
=============  =======================================  =============================

The maths of each op is the one of the measure class of the same name in
:mod:`openfdk.model.measures` (docs/design.md §1: ṁ = M v, m̈ = M v̇ + b). Rates of children
that a parent's bias needs (ẇ of a vector for a distance) are ṁ = M v, formed in the
kernel from the node's Jacobian rows.

Adding a measure type (muscle wrapping paths, joint-coordinate-system angles,
force-dependent joint rows, …)
------------------------------------------------------------------------------------
1. a ``Measure`` subclass with its Python ``evaluate`` (the reference);
2. a new op-code constant and one ``elif`` branch in :func:`evaluate_program` that fills
   the node's value, Jacobian rows and bias from its parameters and children's rows, and
   its body set in the node mask at the top of the loop (its Jacobian loops run over
   those bodies' columns only);
3. a compiler function ``f(measure, compile_child) -> (op, iparams, fparams)``
   registered with :func:`register`;
4. an entry in the compiled-vs-Python and finite-difference test of tests/test_compiled.py.
5. touch :mod:`openfdk.kinematics.frame_kernels` and :mod:`openfdk.analysis.tree_trial`
   (and this file when a kernel it calls
   changes, e.g. :func:`~openfdk.model.rotation_angles.rotation_angles`): numba's
   on-disk cache (``cache=True``) checks only the source file of the cached function,
   so kernels in other files would keep a stale copy of :func:`evaluate_program`.
Solvers never change: the constraint system, tracking, equilibrium and FDK Jacobian
consume ``(value, M, b)`` rows of a program whatever its ops.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .measures import AxisDot, Distance, Linear, PointPosition, RelativeAngles, RelativeVector
from .coordinate_functions import pp_evaluate
from .function_measure import FunctionOf
from .axis_angles import AxisAngles, axis_angle_blocks
from .rotation_angles import RotationAngles, inverse3_into, rotation_angle_blocks

__all__ = ["CompiledMeasures", "MeasureCompileError", "register", "evaluate_program"]

OP_POINT, OP_VECTOR, OP_DISTANCE, OP_AXIS_DOT, OP_ANGLES, OP_LINEAR, OP_ROTATION_ANGLES, OP_FUNCTION, OP_AXIS_ANGLES = \
    range(9)

#: error codes returned by the kernel (with the failing node)
ERR_NONE, ERR_COINCIDENT, ERR_GIMBAL = 0, 1, 2


class MeasureCompileError(TypeError):
    """A measure type has no compiled op-code (register one, see the module docstring)."""


_COMPILERS = {}


def register(measure_type, compiler):
    """Register ``compiler(measure, compile_child) -> (op, iparams list, fparams list)``
    for ``measure_type``; ``compile_child(m)`` returns the node index of a sub-measure."""
    _COMPILERS[measure_type] = compiler


register(PointPosition, lambda m, child: (OP_POINT, [m.body], list(m.p_BP)))
register(RelativeVector, lambda m, child: (
    OP_VECTOR, [child(m.point_a), child(m.point_b), -1 if m.frame is None else m.frame], []))
register(Distance, lambda m, child: (OP_DISTANCE, [child(m.vector)], []))
register(AxisDot, lambda m, child: (OP_AXIS_DOT, [m.body_a, m.body_b], list(m.n_a) + list(m.n_b)))
register(RelativeAngles, lambda m, child: (
    OP_ANGLES, [m.body_a, m.body_b], list(np.ravel(m.R_aFa)) + list(np.ravel(m.R_bFb))))
register(RotationAngles, lambda m, child: (
    OP_ROTATION_ANGLES, [m.body_a, m.body_b] + [int(x) for x in m.seq],
    list(np.ravel(m.R_aFa)) + list(np.ravel(m.R_bFb)) + list(m.sign)))
register(FunctionOf, lambda m, child: (OP_FUNCTION, [child(m.measure)], list(m.function.to_params())))
register(AxisAngles, lambda m, child: (
    OP_AXIS_ANGLES, [m.body_a, m.body_b], list(np.ravel(m.R_aFa)) + list(np.ravel(m.R_bFb)) + list(np.ravel(m.axes))))


def linear_terms(m):
    """(offset (size,), [(C (size, size_k), measure_k)]) of a Linear measure with every
    Linear sub-measure expanded: m = Σ_j C_j m_j + o with m_j = Σ_k D_jk n_k + o_j is
    Σ_j Σ_k (C_j D_jk) n_k + o + Σ_j C_j o_j; terms on the same measure are summed. An
    imported joint's coordinate is a selector of a selector of an angle; expanded, it is
    one node of the program instead of a chain (the Jacobian rows copied once)."""
    offset = np.array(m.offset, dtype=float)
    terms = {}  # id(measure) -> [C, measure], in order of appearance

    def add(C, sub):
        if id(sub) in terms:
            terms[id(sub)][0] = terms[id(sub)][0] + C
        else:
            terms[id(sub)] = [C, sub]

    for C, sub in m.terms:
        if type(sub) is Linear:
            o, inner = linear_terms(sub)
            offset = offset + C @ o
            for D, n in inner:
                add(C @ D, n)
        else:
            add(C, sub)
    return offset, [(C, sub) for C, sub in terms.values()]


def _compile_linear(m, child):
    offset, terms = linear_terms(m)
    return (OP_LINEAR, [len(terms)] + [child(sub) for _, sub in terms],
            list(offset) + [x for C, _ in terms for x in np.ravel(C)])


register(Linear, _compile_linear)


class CompiledMeasures:
    """The rows of a list of measures as one compiled program.

    measures : sequence of Measure; rows : None (all rows of each) or a sequence with, per
    measure, the list of its row indices to output (e.g. ``[0]`` for an FDK DOF).
    ``evaluate(state, order)`` has the contract of ``Measure.evaluate`` for the stacked
    output rows: value (n_rows,), M (n_rows, n_coords) for order ≥ 1, b (n_rows,) for
    order 2, in the measures' units (m, rad, 1).
    """

    def __init__(self, measures, rows=None):
        self.measures = list(measures)
        ops, node_row, node_size, i_start, f_start = [], [], [], [], []
        iparams, fparams, nodes_of = [], [], {}
        self._node_measure = []

        def compile_node(m):
            key = id(m)
            if key in nodes_of:
                return nodes_of[key]
            compiler = _COMPILERS.get(type(m))
            if compiler is None:
                raise MeasureCompileError(
                    f"measure {m.name!r} of type {type(m).__name__} has no compiled op-code; "
                    f"register one with openfdk.model.compiled.register")
            op, ip, fp = compiler(m, compile_node)
            k = len(ops)
            ops.append(op)
            node_row.append(sum(node_size))
            node_size.append(m.size)
            i_start.append(len(iparams))
            f_start.append(len(fparams))
            iparams.extend(int(x) for x in ip)
            fparams.extend(float(x) for x in fp)
            nodes_of[key] = k
            self._node_measure.append(m)
            return k

        out = []
        for j, m in enumerate(self.measures):
            k = compile_node(m)
            picked = range(m.size) if rows is None else rows[j]
            out += [node_row[k] + r for r in picked]
        self.op = np.array(ops, np.int64)
        self.node_row = np.array(node_row, np.int64)
        self.node_size = np.array(node_size, np.int64)
        self.i_start = np.array(i_start, np.int64)
        self.f_start = np.array(f_start, np.int64)
        self.iparams = np.array(iparams + [0], np.int64)
        self.fparams = np.array(fparams + [0.0], float)
        self.out_rows = np.array(out, np.int64)
        self.n_node_rows = int(sum(node_size))
        self.n_rows = len(out)

    @property
    def program(self):
        """The arrays passed to :func:`evaluate_program` (for kernels that call it)."""
        return (self.op, self.node_row, self.node_size, self.i_start, self.iparams,
                self.f_start, self.fparams, self.out_rows)

    def raise_error(self, err_node, err_kind, state=None):
        """Raise the Python reference's FloatingPointError for a kernel error code
        (``state``: the pose, for messages that quote values)."""
        m = self._node_measure[err_node]
        if state is not None and isinstance(m, (RotationAngles, RelativeAngles)):
            m.evaluate(state, 1)  # raises the reference's message (the middle angle and its value)
        if err_kind == ERR_COINCIDENT:
            raise FloatingPointError(f"distance measure {m.name!r}: the two points coincide")
        raise FloatingPointError(f"relative angles {m.name!r} (x-y'-z''): gimbal lock, the middle angle "
                                 "(about y') is ±90 deg")

    def evaluate(self, state, order=1):
        """value (n_rows,), M (n_rows, n_coords) or None, b (n_rows,) or None."""
        n = state.n_coords
        value = np.empty(self.n_rows)
        M = np.empty((self.n_rows, n)) if order >= 1 else np.empty((0, n))
        b = np.empty(self.n_rows)
        err_node, err_kind = evaluate_into(*self.program, self.n_node_rows, state.p_WB, state.R_WB,
                                           state.w_BB, state.v_WB, state.column, n, order, value, M, b)
        if err_node >= 0:
            self.raise_error(err_node, err_kind, state)
        return value, (M if order >= 1 else None), (b if order >= 2 else None)


@njit(cache=True)
def _cross(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True)
def _add_axis_dot_columns(M, row, c, R, other, n0, n1, n2):
    """M[row, c+3:c+6] += n × (Rᵀ other): ∂(R n · other)/∂δπ' of the body at column c."""
    t0 = R[0, 0] * other[0] + R[1, 0] * other[1] + R[2, 0] * other[2]
    t1 = R[0, 1] * other[0] + R[1, 1] * other[1] + R[2, 1] * other[2]
    t2 = R[0, 2] * other[0] + R[1, 2] * other[1] + R[2, 2] * other[2]
    x0, x1, x2 = _cross(n0, n1, n2, t0, t1, t2)
    M[row, c + 3] += x0
    M[row, c + 4] += x1
    M[row, c + 5] += x2


@njit(cache=True)
def _rate(M, v, row, cols, ncol):
    """ṁ of node row ``row``: M[row] · v over the node's column blocks ``cols[:ncol]``
    (M is zero elsewhere)."""
    s = 0.0
    for q in range(ncol):
        for c in range(cols[q], cols[q] + 6):
            s += M[row, c] * v[c]
    return s


@njit(cache=True)
def _bit(body):
    """The bit of a body in a node's body set (none past 62: such models are dense)."""
    return np.int64(1) << np.int64(body) if 0 <= body < 63 else np.int64(0)


@njit(cache=True)
def _node_columns(mask, column, cols):
    """cols[:k] ← the first q̂ column of each moving body in the bit set ``mask`` (bit i:
    body i; every moving body when the model has more than 63 bodies). Returns k."""
    k = 0
    dense = column.shape[0] > 63
    for i in range(column.shape[0]):
        if column[i] >= 0 and (dense or (mask >> np.int64(i)) & np.int64(1)):
            cols[k] = column[i]
            k += 1
    return k


@njit(cache=True)
def _angle_node_into(ia, ib, column, row, order, theta, Ma, Mb, br, val, M, b):
    """An angle node's three rows from its kernel's outputs: val[row:row + 3] ← θ, its
    Jacobian blocks M_a, M_b added into body a's and b's rotation columns of M, b ← bias."""
    ca, cb = column[ia], column[ib]
    for r in range(3):
        val[row + r] = theta[r]
        if order >= 1:
            for c in range(3):
                if ca >= 0:
                    M[row + r, ca + 3 + c] += Ma[r, c]
                if cb >= 0:
                    M[row + r, cb + 3 + c] += Mb[r, c]
        if order >= 2:
            b[row + r] = br[r]


@njit(cache=True)
def evaluate_program(op, node_row, node_size, i_start, iparams, f_start, fparams,
                     p_WB, R_WB, w_BB, v_WB, column, n_coords, order, val, M, b):
    """Run the program's nodes in order, filling the node buffers val (R,), M (R, n) and
    b (R,) (M is zeroed here when order ≥ 1; b is only filled for order 2).

    p_WB (nb, 3) m, R_WB (nb, 3, 3), w_BB (nb, 3) rad/s (body frame), v_WB (nb, 3) m/s,
    column (nb,) first q̂ column of each body (−1: fixed). Returns (failing node or −1,
    error code ERR_*).

    Sparsity: a node's rows depend on the bodies its sub-tree names (a point's body, an
    angle's two bodies, the union of a vector's or a combination's children), so its
    Jacobian rows are zero outside those bodies' 6 columns each. The node's body set is
    a bit mask (``mask``), and every loop over Jacobian columns runs over its blocks
    only: a joint's rows touch 12 of the 6 n_moving columns, whatever the model's size."""
    n = n_coords
    if order >= 1:
        M[:, :] = 0.0
    v = np.zeros(n)
    if order >= 2:
        for i in range(column.shape[0]):
            c = column[i]
            if c >= 0:
                for r in range(3):
                    v[c + r] = v_WB[i, r]
                    v[c + 3 + r] = w_BB[i, r]
    u = np.zeros(3)
    tmp = np.zeros(3)
    B = np.zeros((3, 3))
    R_FaFb = np.zeros((3, 3))
    R_WFa = np.zeros((3, 3))
    R_WFb = np.zeros((3, 3))
    Binv = np.zeros((3, 3))
    # the rotation-angle nodes' frames, scratch and outputs (allocated once per call)
    R_aFa, R_bFb, rot_work, N = np.empty((3, 3)), np.empty((3, 3)), np.empty((9, 3, 3)), np.empty((3, 3))
    theta, Ma, Mb, br = np.empty(3), np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    mask = np.zeros(op.shape[0], np.int64)
    cols = np.empty(column.shape[0], np.int64)
    for k in range(op.shape[0]):
        o = op[k]
        row = node_row[k]
        ip = i_start[k]
        fp = f_start[k]
        if o == OP_POINT:
            mk = _bit(iparams[ip])
        elif o == OP_VECTOR:
            mk = mask[iparams[ip]] | mask[iparams[ip + 1]] | _bit(iparams[ip + 2])
        elif o == OP_DISTANCE or o == OP_FUNCTION:
            mk = mask[iparams[ip]]
        elif o == OP_LINEAR:
            mk = np.int64(0)
            for t in range(iparams[ip]):
                mk |= mask[iparams[ip + 1 + t]]
        else:  # the two bodies of OP_AXIS_DOT, OP_ANGLES, OP_ROTATION_ANGLES, OP_AXIS_ANGLES
            mk = _bit(iparams[ip]) | _bit(iparams[ip + 1])
        mask[k] = mk
        ncol = _node_columns(mk, column, cols) if order >= 1 else 0
        if o == OP_POINT:
            # p = r + R s', ∂p/∂δr = I, ∂p/∂δπ' = −R s̃', b = R ω̃' ω̃' s' (docs/design.md §1)
            i = iparams[ip]
            s0, s1, s2 = fparams[fp], fparams[fp + 1], fparams[fp + 2]
            R = R_WB[i]
            for r in range(3):
                val[row + r] = p_WB[i, r] + R[r, 0] * s0 + R[r, 1] * s1 + R[r, 2] * s2
            c = column[i]
            if order >= 1 and c >= 0:
                for r in range(3):
                    M[row + r, c + r] = 1.0
                    M[row + r, c + 3] = R[r, 2] * s1 - R[r, 1] * s2
                    M[row + r, c + 4] = R[r, 0] * s2 - R[r, 2] * s0
                    M[row + r, c + 5] = R[r, 1] * s0 - R[r, 0] * s1
            if order >= 2:
                a0, a1, a2 = _cross(w_BB[i, 0], w_BB[i, 1], w_BB[i, 2], s0, s1, s2)
                c0, c1, c2 = _cross(w_BB[i, 0], w_BB[i, 1], w_BB[i, 2], a0, a1, a2)
                for r in range(3):
                    b[row + r] = R[r, 0] * c0 + R[r, 1] * c1 + R[r, 2] * c2
        elif o == OP_VECTOR:
            # w = R_kᵀ (p_b − p_a); M = R_kᵀ (M_b − M_a) + w̃ in k's rotation columns;
            # b = R_kᵀ b_u − 2 ω'_k × (R_kᵀ u̇) + ω'_k × (ω'_k × w)
            ra = node_row[iparams[ip]]
            rb = node_row[iparams[ip + 1]]
            kb = iparams[ip + 2]
            for r in range(3):
                u[r] = val[rb + r] - val[ra + r]
            if kb < 0:
                for r in range(3):
                    val[row + r] = u[r]
                if order >= 1:
                    for r in range(3):
                        for q in range(ncol):
                            for c in range(cols[q], cols[q] + 6):
                                M[row + r, c] = M[rb + r, c] - M[ra + r, c]
                if order >= 2:
                    for r in range(3):
                        b[row + r] = b[rb + r] - b[ra + r]
            else:
                Rk = R_WB[kb]
                for r in range(3):
                    val[row + r] = Rk[0, r] * u[0] + Rk[1, r] * u[1] + Rk[2, r] * u[2]
                if order >= 1:
                    for r in range(3):
                        for q in range(ncol):
                            for c in range(cols[q], cols[q] + 6):
                                M[row + r, c] = (Rk[0, r] * (M[rb, c] - M[ra, c])
                                                 + Rk[1, r] * (M[rb + 1, c] - M[ra + 1, c])
                                                 + Rk[2, r] * (M[rb + 2, c] - M[ra + 2, c]))
                    ck = column[kb]
                    if ck >= 0:
                        w0, w1, w2 = val[row], val[row + 1], val[row + 2]
                        M[row, ck + 4] -= w2
                        M[row, ck + 5] += w1
                        M[row + 1, ck + 3] += w2
                        M[row + 1, ck + 5] -= w0
                        M[row + 2, ck + 3] -= w1
                        M[row + 2, ck + 4] += w0
                if order >= 2:
                    # u̇ = (M_b − M_a) v in world, then expressed in k
                    for r in range(3):
                        tmp[r] = _rate(M, v, rb + r, cols, ncol) - _rate(M, v, ra + r, cols, ncol)
                    d0 = Rk[0, 0] * tmp[0] + Rk[1, 0] * tmp[1] + Rk[2, 0] * tmp[2]
                    d1 = Rk[0, 1] * tmp[0] + Rk[1, 1] * tmp[1] + Rk[2, 1] * tmp[2]
                    d2 = Rk[0, 2] * tmp[0] + Rk[1, 2] * tmp[1] + Rk[2, 2] * tmp[2]
                    wk0, wk1, wk2 = w_BB[kb, 0], w_BB[kb, 1], w_BB[kb, 2]
                    x0, x1, x2 = _cross(wk0, wk1, wk2, d0, d1, d2)
                    y0, y1, y2 = _cross(wk0, wk1, wk2, val[row], val[row + 1], val[row + 2])
                    z0, z1, z2 = _cross(wk0, wk1, wk2, y0, y1, y2)
                    for r in range(3):
                        tmp[r] = b[rb + r] - b[ra + r]
                    for r in range(3):
                        b[row + r] = Rk[0, r] * tmp[0] + Rk[1, r] * tmp[1] + Rk[2, r] * tmp[2]
                    b[row] += -2.0 * x0 + z0
                    b[row + 1] += -2.0 * x1 + z1
                    b[row + 2] += -2.0 * x2 + z2
        elif o == OP_DISTANCE:
            # l = |u|, M = eᵀ M_u, b = eᵀ b_u + (u̇·u̇ − (e·u̇)²)/l
            ru = node_row[iparams[ip]]
            length = np.sqrt(val[ru] ** 2 + val[ru + 1] ** 2 + val[ru + 2] ** 2)
            val[row] = length
            if order >= 1:
                if length == 0.0:
                    return k, ERR_COINCIDENT
                e0, e1, e2 = val[ru] / length, val[ru + 1] / length, val[ru + 2] / length
                for q in range(ncol):
                    for c in range(cols[q], cols[q] + 6):
                        M[row, c] = e0 * M[ru, c] + e1 * M[ru + 1, c] + e2 * M[ru + 2, c]
                if order >= 2:
                    du0 = _rate(M, v, ru, cols, ncol)
                    du1 = _rate(M, v, ru + 1, cols, ncol)
                    du2 = _rate(M, v, ru + 2, cols, ncol)
                    edu = e0 * du0 + e1 * du1 + e2 * du2
                    b[row] = (e0 * b[ru] + e1 * b[ru + 1] + e2 * b[ru + 2]
                              + (du0 * du0 + du1 * du1 + du2 * du2 - edu * edu) / length)
        elif o == OP_AXIS_DOT:
            # c = (R_a n_a)·(R_b n_b); ∂c/∂δπ'_a = n_a × (R_aᵀ b), ∂c/∂δπ'_b = n_b × (R_bᵀ a)
            ia, ib = iparams[ip], iparams[ip + 1]
            na0, na1, na2 = fparams[fp], fparams[fp + 1], fparams[fp + 2]
            nb0, nb1, nb2 = fparams[fp + 3], fparams[fp + 4], fparams[fp + 5]
            Ra, Rb = R_WB[ia], R_WB[ib]
            a = np.empty(3)
            bv = np.empty(3)
            for r in range(3):
                a[r] = Ra[r, 0] * na0 + Ra[r, 1] * na1 + Ra[r, 2] * na2
                bv[r] = Rb[r, 0] * nb0 + Rb[r, 1] * nb1 + Rb[r, 2] * nb2
            val[row] = a[0] * bv[0] + a[1] * bv[1] + a[2] * bv[2]
            if order >= 1:
                ca, cb = column[ia], column[ib]
                if ca >= 0:
                    _add_axis_dot_columns(M, row, ca, Ra, bv, na0, na1, na2)
                if cb >= 0:
                    _add_axis_dot_columns(M, row, cb, Rb, a, nb0, nb1, nb2)
            if order >= 2:
                # b = (R_a ω̃ ω̃ n_a)·b + a·(R_b ω̃ ω̃ n_b) + 2 ȧ·ḃ
                wa0, wa1, wa2 = w_BB[ia, 0], w_BB[ia, 1], w_BB[ia, 2]
                wb0, wb1, wb2 = w_BB[ib, 0], w_BB[ib, 1], w_BB[ib, 2]
                pa0, pa1, pa2 = _cross(wa0, wa1, wa2, na0, na1, na2)
                qa0, qa1, qa2 = _cross(wa0, wa1, wa2, pa0, pa1, pa2)
                pb0, pb1, pb2 = _cross(wb0, wb1, wb2, nb0, nb1, nb2)
                qb0, qb1, qb2 = _cross(wb0, wb1, wb2, pb0, pb1, pb2)
                acc = 0.0
                for r in range(3):
                    da = Ra[r, 0] * pa0 + Ra[r, 1] * pa1 + Ra[r, 2] * pa2
                    db = Rb[r, 0] * pb0 + Rb[r, 1] * pb1 + Rb[r, 2] * pb2
                    ba = Ra[r, 0] * qa0 + Ra[r, 1] * qa1 + Ra[r, 2] * qa2
                    bb = Rb[r, 0] * qb0 + Rb[r, 1] * qb1 + Rb[r, 2] * qb2
                    acc += ba * bv[r] + a[r] * bb + 2.0 * da * db
                b[row] = acc
        elif o == OP_ANGLES:
            # θ: x-y-z Cardan angles of R_FaFb = (R_a R_aFa)ᵀ (R_b R_bFb); ω_rel = B(θ) θ̇
            ia, ib = iparams[ip], iparams[ip + 1]
            Ra, Rb = R_WB[ia], R_WB[ib]
            for r in range(3):
                for c in range(3):
                    sa = 0.0
                    sb = 0.0
                    for j in range(3):
                        sa += Ra[r, j] * fparams[fp + 3 * j + c]
                        sb += Rb[r, j] * fparams[fp + 9 + 3 * j + c]
                    R_WFa[r, c] = sa
                    R_WFb[r, c] = sb
            for r in range(3):
                for c in range(3):
                    R_FaFb[r, c] = R_WFa[0, r] * R_WFb[0, c] + R_WFa[1, r] * R_WFb[1, c] + R_WFa[2, r] * R_WFb[2, c]
            th0 = np.arctan2(-R_FaFb[1, 2], R_FaFb[2, 2])
            th1 = np.arcsin(min(1.0, max(-1.0, R_FaFb[0, 2])))
            th2 = np.arctan2(-R_FaFb[0, 1], R_FaFb[0, 0])
            val[row], val[row + 1], val[row + 2] = th0, th1, th2
            if order >= 1:
                s0, c0 = np.sin(th0), np.cos(th0)
                s1, c1 = np.sin(th1), np.cos(th1)
                if abs(c1) < 1e-9:
                    return k, ERR_GIMBAL
                B[0, 0], B[0, 1], B[0, 2] = 1.0, 0.0, s1
                B[1, 0], B[1, 1], B[1, 2] = 0.0, c0, -s0 * c1
                B[2, 0], B[2, 1], B[2, 2] = 0.0, s0, c0 * c1
                inverse3_into(B, Binv)
                ca, cb = column[ia], column[ib]
                for r in range(3):
                    for c in range(3):
                        if ca >= 0:
                            # −B⁻¹ R_aFaᵀ
                            acc = 0.0
                            for j in range(3):
                                acc += Binv[r, j] * fparams[fp + 3 * c + j]
                            M[row + r, ca + 3 + c] -= acc
                        if cb >= 0:
                            # +B⁻¹ R_FaFb R_bFbᵀ
                            acc = 0.0
                            for j in range(3):
                                g = 0.0
                                for l in range(3):
                                    g += R_FaFb[j, l] * fparams[fp + 9 + 3 * c + l]
                                acc += Binv[r, j] * g
                            M[row + r, cb + 3 + c] += acc
                if order >= 2:
                    wa0 = fparams[fp] * w_BB[ia, 0] + fparams[fp + 3] * w_BB[ia, 1] + fparams[fp + 6] * w_BB[ia, 2]
                    wa1 = fparams[fp + 1] * w_BB[ia, 0] + fparams[fp + 4] * w_BB[ia, 1] + fparams[fp + 7] * w_BB[ia, 2]
                    wa2 = fparams[fp + 2] * w_BB[ia, 0] + fparams[fp + 5] * w_BB[ia, 1] + fparams[fp + 8] * w_BB[ia, 2]
                    f9 = fp + 9
                    wb0 = fparams[f9] * w_BB[ib, 0] + fparams[f9 + 3] * w_BB[ib, 1] + fparams[f9 + 6] * w_BB[ib, 2]
                    wb1 = fparams[f9 + 1] * w_BB[ib, 0] + fparams[f9 + 4] * w_BB[ib, 1] + fparams[f9 + 7] * w_BB[ib, 2]
                    wb2 = fparams[f9 + 2] * w_BB[ib, 0] + fparams[f9 + 5] * w_BB[ib, 1] + fparams[f9 + 8] * w_BB[ib, 2]
                    # R_FaFb ω_Fb
                    g0 = R_FaFb[0, 0] * wb0 + R_FaFb[0, 1] * wb1 + R_FaFb[0, 2] * wb2
                    g1 = R_FaFb[1, 0] * wb0 + R_FaFb[1, 1] * wb1 + R_FaFb[1, 2] * wb2
                    g2 = R_FaFb[2, 0] * wb0 + R_FaFb[2, 1] * wb1 + R_FaFb[2, 2] * wb2
                    wr0, wr1, wr2 = g0 - wa0, g1 - wa1, g2 - wa2
                    d0 = Binv[0, 0] * wr0 + Binv[0, 1] * wr1 + Binv[0, 2] * wr2
                    d1 = Binv[1, 0] * wr0 + Binv[1, 1] * wr1 + Binv[1, 2] * wr2
                    d2 = Binv[2, 0] * wr0 + Binv[2, 1] * wr1 + Binv[2, 2] * wr2
                    # Ḃ θ̇ (Ḃ's first column is zero)
                    e0 = c1 * d1 * d2
                    e1 = -s0 * d0 * d1 + (-c0 * c1 * d0 + s0 * s1 * d1) * d2
                    e2 = c0 * d0 * d1 + (-s0 * c1 * d0 - c0 * s1 * d1) * d2
                    x0, x1, x2 = _cross(wa0, wa1, wa2, g0, g1, g2)
                    r0, r1, r2 = -x0 - e0, -x1 - e1, -x2 - e2
                    for r in range(3):
                        b[row + r] = Binv[r, 0] * r0 + Binv[r, 1] * r1 + Binv[r, 2] * r2
        elif o == OP_ROTATION_ANGLES:
            # any intrinsic sequence (JCS angles): the kernel of openfdk.model.rotation_angles
            ia, ib = iparams[ip], iparams[ip + 1]
            for r in range(3):
                for c in range(3):
                    R_aFa[r, c] = fparams[fp + 3 * r + c]
                    R_bFb[r, c] = fparams[fp + 9 + 3 * r + c]
            ok = rotation_angle_blocks(R_WB[ia], R_aFa, w_BB[ia], R_WB[ib], R_bFb, w_BB[ib],
                                       iparams[ip + 2 : ip + 5], fparams[fp + 18 : fp + 21], order, rot_work,
                                       theta, Ma, Mb, br)
            if not ok:
                return k, ERR_GIMBAL
            _angle_node_into(ia, ib, column, row, order, theta, Ma, Mb, br, val, M, b)
        elif o == OP_AXIS_ANGLES:
            # angles about any three axes (a joint's non-orthogonal axes): openfdk.model.axis_angles
            ia, ib = iparams[ip], iparams[ip + 1]
            for r in range(3):
                for c in range(3):
                    R_aFa[r, c] = fparams[fp + 3 * r + c]
                    R_bFb[r, c] = fparams[fp + 9 + 3 * r + c]
                    N[r, c] = fparams[fp + 18 + 3 * r + c]
            ok = axis_angle_blocks(R_WB[ia], R_aFa, w_BB[ia], R_WB[ib], R_bFb, w_BB[ib], N, order, rot_work,
                                   theta, Ma, Mb, br)
            if not ok:
                return k, ERR_GIMBAL
            _angle_node_into(ia, ib, column, row, order, theta, Ma, Mb, br, val, M, b)
        elif o == OP_FUNCTION:
            # m = f(u): M = f'(u) M_u, b = f''(u) u̇² + f'(u) b_u (openfdk.model.function_measure)
            ru = node_row[iparams[ip]]
            f, df, d2f = pp_evaluate(fparams, fp, val[ru])
            val[row] = f
            if order >= 1:
                for q in range(ncol):
                    for c in range(cols[q], cols[q] + 6):
                        M[row, c] = df * M[ru, c]
                if order >= 2:
                    du = _rate(M, v, ru, cols, ncol)
                    b[row] = d2f * du * du + df * b[ru]
        else:  # OP_LINEAR: m = Σ_j C_j m_j + offset
            size = node_size[k]
            n_terms = iparams[ip]
            for r in range(size):
                val[row + r] = fparams[fp + r]
                if order >= 2:
                    b[row + r] = 0.0
            cp = fp + size
            for t in range(n_terms):
                child = iparams[ip + 1 + t]
                rc = node_row[child]
                sc = node_size[child]
                for r in range(size):
                    for j in range(sc):
                        C = fparams[cp + r * sc + j]
                        if C == 0.0:
                            continue
                        val[row + r] += C * val[rc + j]
                        if order >= 1:
                            for q in range(ncol):
                                for c in range(cols[q], cols[q] + 6):
                                    M[row + r, c] += C * M[rc + j, c]
                        if order >= 2:
                            b[row + r] += C * b[rc + j]
                cp += size * sc
    return -1, ERR_NONE


@njit(cache=True)
def evaluate_into(op, node_row, node_size, i_start, iparams, f_start, fparams, out_rows,
                  n_node_rows, p_WB, R_WB, w_BB, v_WB, column, n_coords, order, value, M, b):
    """Evaluate the program and gather its output rows into value (n_out,), M (n_out, n)
    (order ≥ 1) and b (n_out,) (order 2). Returns (failing node or −1, error code)."""
    val = np.empty(n_node_rows)
    Mn = np.empty((n_node_rows if order >= 1 else 0, n_coords))
    bn = np.empty(n_node_rows)
    err_node, err_kind = evaluate_program(op, node_row, node_size, i_start, iparams, f_start, fparams,
                                          p_WB, R_WB, w_BB, v_WB, column, n_coords, order, val, Mn, bn)
    for r in range(out_rows.shape[0]):
        src = out_rows[r]
        value[r] = val[src]
        if order >= 1:
            for c in range(n_coords):
                M[r, c] = Mn[src, c]
        if order >= 2:
            b[r] = bn[src]
        else:
            b[r] = 0.0
    return err_node, err_kind
