"""Assembly of the hard constraints Φ(q, t) = 0 (paper Eq. 1) with FDK rows Φ^FDK − α.

``ConstraintSystem.evaluate`` returns, in the paper's conventions,
``Φ`` (m,), ``Φ_q̂`` (m, 6 n_moving), ``ν`` (m,) with Φ_q̂ v = ν = −Φ_t (Eq. 2) and
``γ`` (m,) with Φ_q̂ v̇ = γ = f̈ − b (Eq. 3).
"""

from __future__ import annotations

import weakref

import numpy as np

from ..model.compiled import CompiledMeasures
from ..model.model import Model
from .block_triangular import block_triangular_form, dense_form


class KinematicsError(ValueError):
    """The kinematic problem is ill-posed (redundant, inconsistent or too few constraints)."""


class ConstraintSystem:
    """All constraint rows of a model: joints and drivers, then FDK DOF rows.

    include_fdk : append one row per FDK DOF, Φ^FDK(q) − α = 0 (α given at evaluation).

    The measures of all rows are one compiled program (``program``,
    :class:`~openfdk.model.compiled.CompiledMeasures`): one kernel call evaluates every
    row's m, M and b. :meth:`evaluate_reference` evaluates measure by measure in Python
    (the reference, for tests).
    """

    def __init__(self, model: Model, include_fdk=True):
        self.model = model
        self.blocks = list(model.constraints)
        self.fdk = list(model.fdk_dofs) if include_fdk else []
        self.n_coords = model.n_coords
        self.program, self._shared = _program(
            model, include_fdk, [c.measure for c in self.blocks] + [d.measure for d in self.fdk],
            [range(c.size) for c in self.blocks] + [[0]] * len(self.fdk))
        rows = self._shared.get("rows")  # derived from the model alone: once per model (never modified)
        if rows is None:
            rows = self._shared["rows"] = self._rows()
        self.row_names, self.angle_rows, self._f_const, self._n_joint_rows, self._spline_groups, self._drivers = rows
        self.row_names = list(self.row_names)
        self.n_rows = len(self.row_names)
        self.has_angles = bool(self.angle_rows.any())
        self._targets_key = None
        self._targets = None
        self._block_form = None

    def _rows(self):
        """(row names, angle rows (m,) bool, constant targets (m,), number of joint and
        driver rows, spline-driver groups, other drivers [(row, Constraint)])."""
        names = tuple(self.model.constraint_row_names() + [f"fdk.{d.name}" for d in self.fdk])
        units = [u for c in self.blocks for u in c.measure.units] + [d.measure.units[0] for d in self.fdk]
        # angle rows are compared modulo 2π: a driver may prescribe θ beyond ±π while
        # the Cardan-angle measure returns values in (−π, π]
        angle_rows = np.array([u == "angle" for u in units], dtype=bool)
        angle_rows.setflags(write=False)
        # constant targets (joints, generic constraints); driver rows are filled per t
        f_const = np.zeros(len(names))
        drivers, r = [], 0
        for c in self.blocks:
            if c.function is None:
                f_const[r : r + c.size] = c.target
            else:
                drivers.append((r, c))
            r += c.size
        f_const.setflags(write=False)
        groups, drivers = _spline_groups(drivers)
        return names, angle_rows, f_const, r, tuple(groups), tuple(drivers)

    def jacobian_pattern(self):
        """(m, 6 n_moving) bool: the entries of Φ_q̂ that can be non-zero, the 6 columns
        of every moving body a row's measure names (``Measure.bodies``)."""
        column = self.model.initial_state().column
        P = np.zeros((self.n_rows, self.n_coords), dtype=bool)
        r = 0
        for measure, size in [(c.measure, c.size) for c in self.blocks] + [(d.measure, 1) for d in self.fdk]:
            for body in measure.bodies():
                c = column[body]
                if c >= 0:
                    P[r : r + size, c : c + 6] = True
            r += size
        return P

    def checked_pattern(self):
        """:meth:`jacobian_pattern` once it is checked against Φ_q̂ at a random pose, or
        None (an entry outside the pattern, or a pose where the rows cannot be
        evaluated): the pattern the block solves rely on. Computed once."""
        if "pattern" not in self._shared:  # once per model (and include_fdk)
            try:
                pattern = self.jacobian_pattern()
                ok = not np.any((self._random_jacobian() != 0.0) & ~pattern)
            except (NotImplementedError, FloatingPointError, ValueError):
                ok = False
            self._shared["pattern"] = pattern if ok else None
        return self._shared["pattern"]

    @property
    def block_form(self):
        """The :class:`~.block_triangular.BlockForm` of a square Φ_q̂ (determinate
        kinematics), found once from :meth:`checked_pattern`: one 6×6 block per body of
        a tree of joints and drivers (without a checked pattern: one block, a plain LU)."""
        if self._block_form is None:
            n = self.n_coords
            pattern = self.checked_pattern() if self.n_rows == n and n > 6 else None
            self._block_form = dense_form(n) if pattern is None else block_triangular_form(pattern)
        return self._block_form

    def _random_jacobian(self):
        """Φ_q̂ at the initial pose displaced by a random step (fixed seed), for
        :attr:`block_form`'s check."""
        from ..model.kernels import displace_poses

        state = self.model.initial_state()
        dq = np.random.default_rng(12345).uniform(-0.3, 0.3, self.n_coords)
        displace_poses(state.p_WB, state.quat_WB, state.R_WB, state.moving, state.column, dq)
        return self.program.evaluate(state, 1)[1]

    @property
    def block_args(self):
        """:attr:`block_form` as the kernels take it: (rows, cols, starts, ptr, earlier)."""
        f = self.block_form
        return (f.rows, f.cols, f.starts, f.ptr, f.earlier)

    def targets(self, t, alpha=None):
        """(f, ḟ, f̈) each (n_rows,) at time t (s): the rows' targets, Φ = m − f (Eq. 1);
        FDK rows have f = α, ḟ = f̈ = 0. The last call's result is reused at the same t, α."""
        alpha = np.zeros(len(self.fdk)) if alpha is None else np.asarray(alpha, dtype=float)
        key = (float(t), alpha.tobytes())
        if key == self._targets_key:
            return self._targets
        f = self._f_const.copy()
        df = np.zeros(self.n_rows)
        ddf = np.zeros(self.n_rows)
        for r, c in self._drivers:
            f[r : r + c.size], df[r : r + c.size], ddf[r : r + c.size] = c.function.derivatives(t)
        for rows, check, spline in self._spline_groups:  # spline drivers on one knot grid: one evaluation
            check.derivatives_range_check(t)
            spline.derivatives_into(t, rows, f, df, ddf)
        f[self._n_joint_rows :] = alpha
        self._targets_key, self._targets = key, (f, df, ddf)
        return self._targets

    def targets_over(self, times, alpha=None):
        """(F, Ḟ, F̈) each (nf, n_rows): :meth:`targets` at every time of ``times`` (nf,)
        s, the spline drivers of a group evaluated for all times at once (the same piece
        and arithmetic as one time at a time). Raises ValueError like :meth:`targets` for
        a time outside a spline's data."""
        times = np.asarray(times, dtype=float).reshape(-1)
        nf = len(times)
        F = np.tile(self._f_const, (nf, 1))
        dF, ddF = np.zeros((nf, self.n_rows)), np.zeros((nf, self.n_rows))
        for k, t in enumerate(times):
            for r, c in self._drivers:
                F[k, r : r + c.size], dF[k, r : r + c.size], ddF[k, r : r + c.size] = c.function.derivatives(t)
        for rows, check, spline in self._spline_groups:
            if nf:
                check.derivatives_range_check(times.min())
                check.derivatives_range_check(times.max())
            F[:, rows], dF[:, rows], ddF[:, rows] = spline.derivatives_over(times)
        F[:, self._n_joint_rows :] = 0.0 if alpha is None else np.asarray(alpha, dtype=float)
        return F, dF, ddF

    def wrap_angles(self, Phi):
        """Φ with its angle rows wrapped into [−π, π) (in place; returns Φ)."""
        if self.has_angles:
            a = self.angle_rows
            Phi[a] = (Phi[a] + np.pi) % (2.0 * np.pi) - np.pi
        return Phi

    def evaluate(self, state, t, alpha=None, order=1):
        """Φ, Φ_q̂, ν, γ at time t (s) for FDK inputs α (n_fdk,) in m or rad.

        Φ (m,) m or rad; Φ_q̂ (m, 6 n_moving); ν = ḟ (m,) (Eq. 2: Φ_t = −ḟ; α̇ = 0);
        γ = f̈ − b (m,) (Eq. 3; α̈ = 0). order 0: (Φ, None, None, None); order 1 adds
        Φ_q̂ and ν; order 2 adds γ (needs the state's velocities).
        """
        val, M, b = self.program.evaluate(state, order)
        return self._assemble(val, M, b, t, alpha, order)

    def bias(self, state, t, alpha=None):
        """γ (m,) alone, Φ_q̂ v̇ = γ (Eq. 3), at a pose whose Φ_q̂ is already known (the
        velocity stage; needs the state's velocities). Φ_q̂ is not assembled again (the
        compiled program still returns its rows with the bias)."""
        _, _, b = self.program.evaluate(state, 2)
        _, _, ddf = self.targets(t, alpha)
        return ddf - b  # Eq. 3

    def jacobian(self, state):
        """Φ_q̂ (m, 6 n_moving) alone (no targets: for the equilibrium, Eq. 12)."""
        return self.program.evaluate(state, 1)[1]

    def evaluate_reference(self, state, t, alpha=None, order=1):
        """As :meth:`evaluate`, measure by measure in Python (the reference for tests)."""
        parts = [c.measure.evaluate(state, order) for c in self.blocks]
        parts += [tuple(None if x is None else x[:1] for x in d.measure.evaluate(state, order)) for d in self.fdk]
        val = np.concatenate([p[0] for p in parts]) if parts else np.zeros(0)
        M = (np.vstack([p[1] for p in parts]) if parts else np.zeros((0, self.n_coords))) if order >= 1 else None
        b = (np.concatenate([p[2] for p in parts]) if parts else np.zeros(0)) if order >= 2 else None
        return self._assemble(val, M, b, t, alpha, order)

    def _assemble(self, val, M, b, t, alpha, order):
        f, df, ddf = self.targets(t, alpha)
        Phi = self.wrap_angles(val - f)  # Eq. 1
        if order == 0:
            return Phi, None, None, None
        nu = df.copy()  # Eq. 2: Φ_t = −ḟ
        gamma = ddf - b if order >= 2 else None  # Eq. 3
        return Phi, M, nu, gamma


_PROGRAMS = weakref.WeakKeyDictionary()  # model -> {include_fdk: (measure ids, CompiledMeasures, shared dict)}


def _program(model, include_fdk, measures, rows):
    """(CompiledMeasures of the rows, a dict for data derived from it) built once per
    model: a run builds several ConstraintSystems of one model (the model check, the
    kinematics, the dynamics) and a program is never modified once built. Built again
    when the model's measures are not those it was built from."""
    ids = tuple(id(m) for m in measures)
    per_model = _PROGRAMS.get(model)
    if per_model is None:
        per_model = _PROGRAMS[model] = {}
    entry = per_model.get(include_fdk)
    if entry is None or entry[0] != ids:
        entry = per_model[include_fdk] = (ids, CompiledMeasures(measures, rows), {})
    return entry[1], entry[2]


def _spline_groups(drivers):
    """(groups, other drivers): drivers whose functions are splines through data of one
    kind on the same knots (a --motion file drives every coordinate so) evaluated as one
    spline of all their columns — one knot search per time instead of one per driver.
    Each group is (rows (k,) int, the first driver's function (its time-range check), the
    spline of the group's columns: a NotAKnotSpline or SplineColumns)."""
    from ..model.timefunctions import SplineThroughData

    by_knots, rest = {}, []
    for r, c in drivers:
        fn = c.function
        if type(fn) is SplineThroughData:
            key = (type(fn._s), fn._s.coef.shape[1], fn._s.x.tobytes(), fn.extrapolate)
            by_knots.setdefault(key, []).append((r, c))
        else:
            rest.append((r, c))
    groups = []
    for members in by_knots.values():
        if len(members) == 1:
            rest += members
            continue
        first = members[0][1].function
        spline = type(first._s).__new__(type(first._s))
        spline.x, spline._knots = first._s.x, first._s._knots
        spline.coef = np.ascontiguousarray(np.concatenate([c.function._s.coef for _, c in members], axis=2))
        rows = np.concatenate([np.arange(r, r + c.size) for r, c in members])
        groups.append((rows, first, spline))
    return groups, rest


def dependent_rows(A, row_names, tol=1e-9):
    """Names of constraint rows that take part in a linear dependency of A (m, n).

    Uses the left null space of A (SVD): a row is reported when it has a significant
    weight in a left-null vector. Returns (rank, list of row names).
    """
    if A.shape[0] == 0:
        return 0, []
    # the left null space needs all of U only when A has more rows than columns; a full
    # SVD of a tall matrix costs 100x more (and starts BLAS threads)
    U, s, _ = np.linalg.svd(A, full_matrices=A.shape[0] > A.shape[1])
    scale = s[0] if s.size and s[0] > 0 else 1.0
    rank = int(np.sum(s > tol * scale))
    left_null = U[:, rank:]
    if left_null.shape[1] == 0:
        return rank, []
    weight = np.sqrt(np.sum(left_null**2, axis=1))
    return rank, [row_names[i] for i in np.flatnonzero(weight > 1e-6)]


def null_space(A, tol=1e-9):
    """(n, k) orthonormal basis of the right null space of A (m, n): the directions of
    q̂ that A leaves free (singular values below ``tol`` times the largest are zero)."""
    if A.shape[0] == 0:
        return np.eye(A.shape[1])
    # the right null space needs all of Vt only when A has fewer rows than columns
    _, s, Vt = np.linalg.svd(A, full_matrices=A.shape[0] < A.shape[1])
    scale = s[0] if s.size and s[0] > 0 else 1.0
    rank = int(np.sum(s > tol * scale))
    return Vt[rank:].T


def undetermined_coordinates(A, coord_names, tol=1e-9):
    """Names of q̂ components that A (m, n) leaves free (right null space)."""
    null = null_space(A, tol)
    if null.shape[1] == 0:
        return []
    weight = np.sqrt(np.sum(null**2, axis=1))
    return [coord_names[i] for i in np.flatnonzero(weight > 1e-6)]
