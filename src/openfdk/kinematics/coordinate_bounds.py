"""Clamped coordinates held within their ranges in marker tracking (Eqs. 4–5 with bounds).

OpenSim's IK gives a clamped coordinate's range to its optimiser as bounds (Simbody's
Assembler restricts q), so its solution is the least-squares fit of the markers
*within* the ranges. openfdk's tracking solves the same bound-constrained problem

    min_q ½ Ψᵀ W Ψ   s.t.   Φ(q, t) = 0,   u_lo ≤ u_c(q) ≤ u_hi  (c clamped)

by an active set around the Gauss–Newton SQP of :mod:`.tracking`: a bound in the active
set is one more constraint row u_c(q) − u_bound = 0 (a row like a locked coordinate's,
no reaction), and the set changes until

* no clamped coordinate outside the active set leaves its range by more than
  :data:`TOLERANCE` (the one furthest out is added, one at a time: two coordinates that
  move together, as Rajagopal's knee angle and its coupled ``_beta``, never become two
  rows of one direction), and
* every active bound's multiplier pushes inward: at the optimum Ψ_q̂ᵀ W Ψ + Φ_q̂ᵀ λ = 0,
  so the fit's gradient along ∇u_c is −λ |∇u_c|², and an upper bound holds the fit back
  only where λ > 0, a lower one where λ < 0 (the KKT conditions of the inequality
  problem). A bound whose multiplier has the other sign is released (all such at once).

A frame starts from the previous frame's active set, so a coordinate resting on its bound
over a stretch of the trial costs no extra solve per frame. At an active bound the
velocity and acceleration solves (Eqs. 8–10) have the row too: u̇_c = ü_c = 0 there.

Each active set's rows are a :class:`~openfdk.kinematics.tracking.MarkerTracker` of the
model with the bound rows appended to its constraints (before the FDK rows), built once
per active set. Later stages (inverse dynamics' reactions) see the model's own rows:
:meth:`CoordinateBounds.model_rows` drops the bound rows from a frame's Φ, Φ_q̂ and ν.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..model.compiled import CompiledMeasures
from ..model.constraints import DRIVER, Constraint

#: a clamped coordinate outside its range by more than this (rad or m) is bounded
TOLERANCE = 1e-9
#: at most this many changes of the active set in one frame (each one position solve)
MAX_CHANGES = 20


class CoordinateBounds:
    """The clamped coordinates of a model and the trackers of their active bounds.

    model : Model; tracker : the model's own MarkerTracker (no bound rows), whose
    settings the bounded trackers share. ``names`` (k,), ``lo``, ``hi`` (k,) SI: the
    clamped coordinates with a finite bound that are not locked, prescribed or FDK DOFs
    (those are rows already). An active set is a tuple of (coordinate index, side),
    side −1 the lower bound and +1 the upper, in the order the bounds were added."""

    def __init__(self, model, tracker):
        fdk_measures = {id(d.measure) for d in model.fdk_dofs}
        clamped = [c for c in model.coordinates
                   if c.clamped and not c.locked and not c.prescribed and id(c.measure) not in fdk_measures
                   and (np.isfinite(c.range[0]) or np.isfinite(c.range[1]))]
        self.model, self.tracker = model, tracker
        self.coordinates = tuple(clamped)
        self.names = tuple(c.name for c in clamped)
        self.lo = np.array([c.range[0] for c in clamped], dtype=float)
        self.hi = np.array([c.range[1] for c in clamped], dtype=float)
        self.program = CompiledMeasures([c.measure for c in clamped]) if clamped else None
        self.n_model_rows = model.n_constraint_rows  # the bound rows follow these
        self._trackers = {(): tracker}

    def __bool__(self):
        return bool(self.coordinates)

    def values(self, state):
        """u_c (k,) of the clamped coordinates at ``state`` (rad or m)."""
        return self.program.evaluate(state, 0)[0]

    def check_active(self, active):
        """``active`` as a tuple of (index, ±1); ValueError unless every entry names a
        clamped coordinate once with a side of ±1 (a checkpoint's, untrusted)."""
        out = tuple((int(i), int(s)) for i, s in active)
        if any(not 0 <= i < len(self.names) or s not in (-1, 1) for i, s in out) or len({i for i, _ in out}) < len(out):
            raise ValueError(f"active coordinate bounds {list(active)[:4]} do not fit the model's "
                             f"{len(self.names)} clamped coordinates")
        return out

    def tracker_for(self, active):
        """The MarkerTracker with a row u_c − bound = 0 per entry of ``active`` (built once
        per active set)."""
        tracker = self._trackers.get(active)
        if tracker is None:
            from .system import ConstraintSystem
            from .tracking import MarkerTracker

            rows = tuple(Constraint(f"{self.names[i]}_{'upper' if s > 0 else 'lower'}_bound",
                                    self.coordinates[i].measure, kind=DRIVER,
                                    target=np.array([self.hi[i] if s > 0 else self.lo[i]]), reaction=False,
                                    row_names=(f"{self.names[i]}.{'upper' if s > 0 else 'lower'}_bound",))
                         for i, s in active)
            model = dataclasses.replace(self.model, constraints=tuple(self.model.constraints) + rows)
            tracker = self._trackers[active] = MarkerTracker(ConstraintSystem(model), self.tracker.settings)
        return tracker

    def change(self, values, active, lam):
        """The next active set after a solve that ended at coordinate values ``values``
        (k,) with multipliers ``lam`` (m,) of ``active``'s rows, or None when the solve is
        the bounded optimum (module docstring)."""
        on = {i for i, _ in active}
        out = np.maximum(self.lo - values, values - self.hi)
        out[list(on)] = -np.inf
        worst = int(np.argmax(out)) if len(out) else -1
        if worst >= 0 and out[worst] > TOLERANCE:
            return active + ((worst, -1 if values[worst] < self.lo[worst] else 1),)
        mult = lam[self.n_model_rows:self.n_model_rows + len(active)]
        keep = tuple(b for b, mu in zip(active, mult) if b[1] * mu >= 0.0)
        return keep if len(keep) < len(active) else None

    def model_rows(self, active, values):
        """Φ (m,), Φ_q̂ (m, n) or ν (m,) of a frame solved with ``active`` bounds, without
        the bound rows (the model's own rows, as the later stages expect)."""
        if not active:
            return values
        return np.delete(values, np.s_[self.n_model_rows:self.n_model_rows + len(active)], axis=0)


def solve_bounded(bounds, state, t, x_WM, visible, alpha, active, second_order=None):
    """Marker tracking of one frame within the clamped coordinates' ranges, from ``state``
    (modified in place) and the active set ``active`` (the previous frame's).

    Returns (FrameSolve, K, λ, active) of the last solve: its KKT matrix and multipliers
    are those of ``bounds.tracker_for(active)``. When a solve with a changed active set
    fails, the last converged solve is returned (a coordinate left outside its range is
    then reported by the coordinate outputs' warning); so is a frame whose set still
    changes after :data:`MAX_CHANGES` solves."""
    from .tracking import _restore

    out = bounds.tracker_for(active).solve_positions(state, t, x_WM, visible, alpha, second_order=second_order)
    if not out[0].converged and active:  # the previous frame's bounds do not serve here: none
        active = ()
        out = bounds.tracker.solve_positions(state, t, x_WM, visible, alpha, second_order=second_order)
    if not out[0].converged:
        return out + (active,)
    for _ in range(MAX_CHANGES):
        nxt = bounds.change(bounds.values(state), active, out[2])
        if nxt is None:
            break
        good = state.copy()
        trial = bounds.tracker_for(nxt).solve_positions(state, t, x_WM, visible, alpha, second_order=second_order)
        if not trial[0].converged:
            _restore(good, state)
            break
        out, active = trial, nxt
    return out + (active,)
