"""Approach: a frame that failed from every nearby start is solved again after marching
to it through frames the trial does not report (part of the setting ``restart``).

Measured on the DM knee in gait (docs/tutorial-knee-gait.md): the frames that fail are
heel strikes. The ground reaction rises from zero to about a body weight in 20–30 ms,
so between two 120 Hz frames the knee's load changes by hundreds of newtons; the warm
start extrapolated from the frame before then lies where f^FDK(α) has kinks (muscles
entering the recruitment's active set, contact vertices entering the patch) and Newton
stalls. The window's first frame is worse: it starts from the DOFs' initial values.
Continuation in time is the remedy: the same frame is reached through intermediate
frames, each close to the one before.

* **The transient solver, then sub-steps** — when frame k − 1 converged: pseudo-transient
  continuation (:mod:`.transient`) from α_{k−1} with the ordinary iteration limit; when
  that fails, :data:`SUBSTEPS` − 1 frames at t_{k−1} + j (t_k − t_{k−1}) / SUBSTEPS,
  j = 1 … SUBSTEPS − 1, from frame k − 1's solution. On DM's six overground stances
  (1 464 frames, every one converged either way) the frames whose warm starts failed
  took the six 9 463 evaluations with sub-steps alone, 8 987 with the transient solver
  after them, 8 048 with it before them (23 of 23 such solves converged, 19 evaluations
  each on average).
* **The transient start** — at the window's first frame (marker tracking), before any
  other start: pseudo-transient continuation from the DOFs' initial values, with the
  cold iteration limit. Newton's method from there stops at stationary points of its
  merit that are not roots (the patella's nearly free tilt and medio-lateral
  translation); the relaxation along −f^FDK passes them. When it converges, no lead-in
  is marched. The next frame then has no velocity to extrapolate (from α_0 alone DM og1
  2.508 s starts at 720 N and Newton stalls near 70 N) and goes to the transient solver
  at once (:meth:`Approach.without_velocity`). Measured on DM's 15 cold starts (og1,
  og3, og4, og5 and og9 at three times each, each from the initial values as given and
  moved by 1e-12 of themselves; the first frame and the two after it, 90 frames): the
  first frames took 750 evaluations (median 20) instead of 5 098 (median 92), all 90
  frames 1 371 instead of 5 589, every frame converged either way; frame 1 took 6–20
  evaluations by the transient solver, 7–120 through sub-steps. When the transient start
  fails, the lead-ins follow.
* **Lead-in** — at the window's first frame, when the transient start failed: up to
  :data:`LEAD_IN_FRAMES` frames before it at the trial's rate, from the DOFs' initial
  values, as far back as the markers and the measured loads have data (at the window's
  spacing, or the trial's sample interval when the window is one frame); when the frame
  fails after it, again from :data:`LEAD_IN_LENGTHS` frames further back (DM og3 from
  3.47 s, late swing: 5 of 16 frames converged after a 12-frame lead-in, 16 of 16
  with the longer ones; the chunks of ``openfdk run --chunks`` start this way). A
  lead-in that converged up to the frame before the window's first, whose first then
  fails, is followed by sub-steps from its last frame before the next length (a heel
  strike between the two: DM og1 from 2.406 s, the tutorial's gait cycle, 2 156 → 1 133
  evaluations); so is one whose last frame failed, from the frame before it, over the
  two frame intervals (og1 from 2.408 s: the lead-in's 2.400 s fails at the heel
  strike; 457 → 168 evaluations, stop 56). When the frame still fails, a last lead-in of :data:`LAST_LEAD_IN_FRAMES` frames lets its
  marched frames restart when they fail (from the previous marched frame's α and from
  the initial values, without the scan around α_{k−1}). DM og1 from 2.5 s with its
  ground reactions filtered at 6 Hz (docs/tutorial-knee-gait.md, "Filtered ground
  reactions"): the plain lead-ins (12, 24, 48 frames at the time) stall at
  2.483 and 2.492 s, where the patella engages as the quadriceps switch on, and the first
  5 of 31 frames failed (1 590 evaluations for frame 0, 127 for each failed frame after
  it); with the last lead-in all 31 converge (2 086 for frame 0). (Measured on
  DM og4 from 3.083 s: the first frame from the initial values took 100 iterations and
  failed, about 500 evaluations, before the lead-in solved it; the lead-in alone took
  about 350.)

**Where the lead-in starts** (:func:`seated_length`). A lead-in's cold frame costs what
the distance from the DOFs' initial values to its root costs, and the initial values are
a seated joint in its reference pose: DM's knee extended. In swing, with the knee flexed
45° and more, the cold frame starts at 10 kN (og1 from 3.183 s: the 6-frame lead-in's
cold frame at 3.133 s, 10.5 kN along ``knee_tx_r``; its root 6 mm and 0.22 rad of
patellar flexion away), its 25 iterations and those of the marched frames after it
end far from their roots, and the 24-frame lead-in walks on for 20 frames: 515
evaluations and 11 s for the window's first frame. Started at 2.942 s instead (knee
9°), the same frames converge on the way, 177 evaluations to 3.183 s. So before the
first lead-in the merit ‖W f^FDK‖₂ at the initial values is evaluated at its cold frame
(6 frames back) and at that of the 24-frame lead-in; when the near one's is more than
:data:`SEATED_FACTOR` times the far one's, also at 12 and 18 frames back, and the
lead-in starts at the nearest of them within SEATED_FACTOR of the smallest (og1 from
3.183 s: 17.6, 8.4, 2.8 and 1.8 J: 18 frames back, 193 evaluations for the first frame
instead of 389). These two to four evaluations count towards frame k's. Over DM's 15
cold starts (og1, og3, og4, og5 and og9 at three times each, the first frame with its
lead-in and the two frames after it): 1 938 evaluations for the first frames instead of
2 115, every frame converged either way; where the near start is as good (the bench
window, og1 from 2.5 s: 2.2 against 1.3 J) nothing changes but the two evaluations.

The marched frames are solved as the trial's frames are (warm starts, Broyden-carried
Jacobian) but without restarts, with the ordinary iteration limit even when cold (a
stalled one hands its best iterate on: the lead-in's cold frames in terminal swing creep
and stall near 0.2–0.8 N; at the six DM whole-stance starts the windows' first frames
took 1 422 evaluations instead of 1 779), and only
to :data:`MARCH_TOLERANCE` times the tolerance: a marched frame is a stepping stone,
and 0.1 N off its root moves the next start by micrometres (the knee's stiffness is
1e5 N/m and more). Measured on DM's bench window (og1 from 2.5 s, `dm_pt.yaml`): the
lead-in's first two frames, cold, stalled near 0.05–0.07 N and spent their 100
iterations each; solved to 0.1 N the lead-in takes 236 evaluations and 121 Jacobians
instead of 353 and 247, and the window's first frame converges from it as before (5
evaluations instead of 6). Frame k is then solved from the extrapolation of the last
two with their poses, recruitment and Jacobian. After a lead-in it gets the cold
iteration limit (the window's first frame is typically a heel strike), and the lead-in's
converged frames join the step's history as the window's frames −m … −1 (the same
spacing; their rates, like frame 0's, are central: the trial's samples outside the
window are the edge frames' neighbours, :func:`~openfdk.fdk.residual.window_measurements`),
so that frame 1 is extrapolated from them and frame 0 instead of starting at α_0 (DM og1
from 2.5 s: 720 N there, 67 evaluations and the sub-steps; now 20 N and 4). The marched
frames' iterations, evaluations and Jacobians count towards frame k's; nothing else of
them is reported. The lead-in needs marker tracking (the markers reach before the
window; a determinate model's drivers need not).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..kinematics.tracking import window_spacing
from .newton import FrameSolution, solve_frame
from .residual import FrameWorkspace
from .transient import solve_transient
from .trust_region import work

#: intermediate steps between a converged frame and the failed frame after it
SUBSTEPS = 4
#: frames before the window's first frame, at the trial's rate. Measured on 15 cold
#: starts of DM (og1, og3, og4, og5 and og9 at three times each, the window's first frame
#: with its lead-in and the two frames after it; stop 49): the first frames' median 188
#: evaluations with 12 frames, 160 with 8, 129 with 6, 321 with 4; in all 4 607, 4 527,
#: 4 433 and 7 119, every frame converged each time. A lead-in's cold first frame costs
#: as much wherever it starts; the frames marched after it cost 3–40 evaluations each
LEAD_IN_FRAMES = 6
#: the lead-in's lengths, tried in turn while the window's first frame fails after the
#: shorter one (and the trial's data reach further back)
LEAD_IN_LENGTHS = (LEAD_IN_FRAMES, 24, 48)
#: the last lead-in's length, whose marched frames restart when they fail
LAST_LEAD_IN_FRAMES = 12
#: a lead-in's cold frame moves further back when there the DOFs' initial values are this
#: many times nearer equilibrium (:func:`seated_length`)
SEATED_FACTOR = 2.0
#: the marched frames are stepping stones, not results: each is solved to this many
#: times the tolerance (0.1 N, N m at the default 1e-3), frame k itself to the tolerance
MARCH_TOLERANCE = 100.0


def sub_step_times(t_previous, t_k, frames=1):
    """(SUBSTEPS · frames − 1,) s: the intermediate times t_prev + j (t_k − t_prev) / n,
    n = SUBSTEPS · frames, j = 1 … n − 1, between a converged frame at ``t_previous`` and
    frame k at ``t_k`` (s), ``frames`` frame intervals apart."""
    n = SUBSTEPS * int(frames)
    return t_previous + (t_k - t_previous) * np.arange(1, n) / n


def approach_times(times, k, previous_converged, first_time, lead_in=LEAD_IN_FRAMES, sample_interval=None):
    """Times (m,) s of the frames that lead to frame k, or an empty array.

    times (nf,) s: the window's uniform frame times; previous_converged: whether frame
    k − 1 converged; first_time: the earliest time with data (markers and loads), s;
    lead_in: the lead-in's length in frames (k = 0); sample_interval: s, the trial's
    sample interval, the lead-in's spacing when the window has one frame (else the
    window's spacing; None: no lead-in for a one-frame window)."""
    times = np.asarray(times, dtype=float)
    if k > 0 and previous_converged:
        return sub_step_times(times[k - 1], times[k])
    dt = times[1] - times[0] if len(times) > 1 else sample_interval
    if k == 0 and dt is not None and dt > 0:
        lead = times[0] - dt * np.arange(int(lead_in), 0, -1)
        return lead[lead >= first_time - 1e-9 * max(1.0, abs(first_time))]
    return np.empty(0)


def seated_length(merit, base=LEAD_IN_FRAMES):
    """(The lead-in's first length in frames, the merits evaluated): where its cold frame
    starts (module docstring, "Where the lead-in starts").

    merit : m → the merit ‖W f^FDK‖₂ (J) at the DOFs' initial values at the cold frame of
    an m-frame lead-in, None where the trial's data do not reach that far, inf where it
    cannot be evaluated. The base length stands unless its merit is more than
    :data:`SEATED_FACTOR` times that of 4 × base; then the shortest of base, 2, 3 and
    4 × base whose merit is within SEATED_FACTOR of the smallest. The merits evaluated
    are those not None."""
    values = {}

    def value(m):
        if m not in values:
            values[m] = merit(m)
        return values[m]

    near, far = value(base), value(4 * base)
    if near is None or far is None or near <= SEATED_FACTOR * far:
        return base, sum(v is not None for v in values.values())
    for m in (2 * base, 3 * base):
        value(m)
    known = {m: v for m, v in values.items() if v is not None}
    best = min(known.values())
    return min(m for m, v in known.items() if v <= SEATED_FACTOR * best), len(known)


class Approach:
    """The approach of an :class:`~openfdk.fdk.analysis.FDKStep` (module docstring).

    trajectories : the trial's markers (``evaluate(t)``, ``time``), or None for
    determinate kinematics (sub-steps only: the drivers need not reach before the
    window); first_time : s, the earliest time the measured loads have data (−inf when
    none is sampled)."""

    def __init__(self, trajectories=None, first_time=-np.inf):
        self.trajectories = trajectories
        self.sample_interval = None  # the lead-in's spacing for a one-frame window
        self.transient_frame = None  # the frame the transient start solved, without a lead-in
        #: (k, (t_a, t_b) s): where the last sub-step march towards frame k lost the
        #: equilibrium followed from frame k − 1 (:func:`lost_between`), or None
        self.lost = None
        if trajectories is None:
            self.first_time = np.inf  # no lead-in
        else:
            t = np.asarray(trajectories.time, dtype=float)
            self.first_time = max(float(t[0]), float(first_time))
            self.sample_interval = window_spacing(t[:1], trajectories)  # the trial's median interval

    def __call__(self, step, k) -> FrameSolution:
        """Frame k of ``step`` solved after the march: a FrameSolution (converged or not)
        whose counts include the marched frames', or None when no frame leads to k. A
        lead-in after which frame k fails is tried again from further back
        (:data:`LEAD_IN_LENGTHS`), while the trial's data reach there."""
        ctx = step.ctx
        history = step.history
        previous = bool(history) and history[-1][0] == k - 1
        lengths = (LEAD_IN_FRAMES,) if previous else LEAD_IN_LENGTHS
        self.lost = None
        spent = np.zeros(3, dtype=int)  # the earlier, failed attempts' counts
        transient = None  # the transient start's failed solution
        if previous:
            # after a converged frame: by the transient solver from its α first (module
            # docstring, "The transient start"), then through sub-steps
            sol = self._transient(step, k, history[-1][1], step.settings)
            if sol.converged:
                return sol
            spent += (sol.iterations, sol.evaluations, sol.jacobians)
        if not previous and self.trajectories is not None and ctx.tracker is not None:
            # first by pseudo-transient continuation from the initial values (module
            # docstring, "The transient start"); the lead-ins when that fails
            sol = self._transient(step, k, step.a_init, step.settings.cold())
            if sol.converged:
                self.transient_frame = k
                return sol
            spent += (sol.iterations, sol.evaluations, sol.jacobians)
            transient = sol
            # the lead-in's cold frame where the initial values are nearer equilibrium
            # (module docstring); its merits are residual evaluations of frame k
            first, merits = seated_length(lambda m: self._initial_merit(step, k, m))
            spent[1] += merits
            lengths = (first,) + tuple(n for n in LEAD_IN_LENGTHS if n > first)
        sol, marched = None, 0
        for length in lengths:
            times = approach_times(ctx.times, k, previous, self.first_time, length, self.sample_interval)
            if len(times) <= marched:
                break  # no data further back
            if sol is not None:
                spent += (sol.iterations, sol.evaluations, sol.jacobians)
            sol, h, march = self._solve_after(step, k, times, previous)
            marched = len(times)
            if sol.converged:
                break
            if previous:
                self.lost = (k, lost_between(ctx.times[k - 1], times, ctx.times[k], h))
            gap = len(times) - h[-1][0] if h else 0  # frame intervals from its last converged frame to k
            if not previous and gap in (1, 2):
                # the lead-in reached the frame before the window's first (or the one
                # before that, its last failing), and the first fails from it: sub-steps
                # from the lead-in's last converged frame, as after any converged frame,
                # before a longer lead-in (a heel strike between the two: DM og1 from
                # 2.406 s, the tutorial's gait cycle, whose first frame stalled at 0.3 N
                # after the 6-frame lead-in and converged in sub-steps after the 24-frame
                # one, the cycle's evaluations 2 156 → 1 133; og1 from 2.408 s, whose
                # lead-in's last frame 2.400 s failed at the heel strike, converges in 7
                # sub-steps from 2.392 s: 457 → 168 evaluations, stop 56)
                spent += (sol.iterations, sol.evaluations, sol.jacobians)
                sol, _, _ = self._solve_after(step, k, sub_step_times(times[-gap], ctx.times[k], gap), True,
                                              source=march)
                if sol.converged:
                    break
        if sol is not None and not sol.converged and not previous:
            # the last lead-in: its marched frames restart when they fail (module docstring)
            times = approach_times(ctx.times, k, previous, self.first_time, LAST_LEAD_IN_FRAMES,
                                   self.sample_interval)
            spent += (sol.iterations, sol.evaluations, sol.jacobians)
            sol, h, _ = self._solve_after(step, k, times, previous, restart=True)
            marched = len(times)
        if sol is None:
            # no frame leads to k: the failed transient start, if any, with its counts
            return None if transient is None else replace(
                transient, iterations=int(spent[0]), evaluations=int(spent[1]), jacobians=int(spent[2]))
        if not previous and sol.converged:
            # the lead-in's frames are the window's frames −m … −1 (the same spacing): in the
            # step's history frame 1 is extrapolated from them and frame 0, not taken from
            # frame 0 alone (DM og1 from 2.5 s: 720 N at α_0, Newton stalled near 120 N,
            # 67 evaluations and the sub-steps for frame 1)
            step.history[:0] = [(j - marched, alpha) for j, alpha in h]
        return replace(sol, iterations=sol.iterations + int(spent[0]), evaluations=sol.evaluations + int(spent[1]),
                       jacobians=sol.jacobians + int(spent[2]))

    def transient_start(self, step, k):
        """Frame k of ``step`` by the transient start (module docstring) from the DOFs'
        initial values with the cold iteration limit: for determinate kinematics after the
        first cold start failed (no lead-in: the drivers need not reach before the window;
        a DM gait cycle driven by a tracking pass's ``coordinates.mot`` stalls at 0.45 N at
        its heel strike, 2.408 s, and converges so)."""
        sol = self._transient(step, k, step.a_init, step.settings.cold())
        if sol.converged:
            self.transient_frame = k
        return sol

    def _transient(self, step, k, alpha0, settings):
        """Frame k of ``step`` by pseudo-transient continuation (:func:`~.transient.solve_transient`)
        from alpha0 (n_fdk,) with ``settings``, the poses from the step's last state."""
        ws = FrameWorkspace({j: step.last_state for j in step.ctx.frames_needed(k)})
        return solve_transient(step.ctx, k, np.array(alpha0, dtype=float), ws, settings, step.warm)

    def without_velocity(self, step, k):
        """Whether frame k's warm start has no velocity to extrapolate: frame k − 1 is the
        one the transient start solved, and the only frame in ``step``'s history. Such a
        frame is solved by the transient solver too before its sub-steps (module
        docstring)."""
        return self.transient_frame == k - 1 and len(step.history) == 1 and step.history[0][0] == k - 1

    def _initial_merit(self, step, k, m):
        """The merit ‖W f^FDK‖₂ (J, W = diag(max_step)) at the DOFs' initial values at the
        cold frame of an m-frame lead-in to frame k, its pose tracked from scratch; None
        where the trial's data do not reach, inf where it cannot be evaluated."""
        ctx = step.ctx
        times = approach_times(ctx.times, k, False, self.first_time, m, self.sample_interval)
        if len(times) < m:
            return None
        cold = ctx.at_times(times[:1], self.trajectories)
        state = step.model.initial_state()
        cold.tracker.initial_guess(state, cold.meas[0][0], cold.meas[0][3])
        ev = cold.evaluate(0, step.a_init, FrameWorkspace({j: state for j in cold.frames_needed(0)}))
        return float(np.linalg.norm(work(ev.f_fdk, np.asarray(step.settings.max_step)))) if ev.ok else np.inf

    def _solve_after(self, step, k, times, previous, restart=False, source=None):
        """(frame k solved after marching through the frames at ``times`` (m,) s, its
        counts including the march's; the march's converged history [(j, α)]; the march,
        an FDKStep). With ``restart`` a marched frame that fails is solved again from the
        previous marched frame's α and from the initial values (no scan). ``previous``:
        the march starts from a converged frame, ``source``'s last (an FDKStep: its
        history, poses, recruitment and Jacobian; default ``step``)."""
        ctx, settings = step.ctx, step.settings
        # the same kind of step (FDKStep) on the marched frames, without restarts
        march = type(step)(step.model, ctx.at_times(times, self.trajectories),
                           replace(settings, restart=restart, tolerance=settings.tolerance * MARCH_TOLERANCE,
                                   cold_max_iterations=settings.max_iterations), scan=False, sweep_back=False)
        if previous:
            src = step if source is None else source
            march.history = [(-1, src.history[-1][1].copy())]
            march.last_state, march.warm, march.J_carry = src.last_state, src.warm, src.J_carry
            march.dq_dalpha = src.dq_dalpha
            march.ctx.tracking_curvature = src.ctx.tracking_curvature
        totals = np.zeros(3, dtype=int)
        for j in range(len(times)):
            (_, values), = march.step(j)
            totals += (values["fdk.iterations"], values["fdk.evaluations"], values["fdk.jacobians"])
        h = march.history
        if len(h) >= 2 and h[-1][0] == len(times) - 1 and h[-2][0] == len(times) - 2:
            a0 = 2 * h[-1][1] - h[-2][1]
        elif h and h[-1][0] == len(times) - 1:
            a0 = h[-1][1].copy()
        elif march.last_failed is not None:
            a0 = march.last_failed[1].copy()
        else:
            a0 = step.a_init.copy()
        warm_end = bool(h) and h[-1][0] == len(times) - 1
        ws = FrameWorkspace({j: march.last_state for j in ctx.frames_needed(k)})
        # the cold iteration limit unless a sub-step march ended converged: a lead-in ends
        # at the window's first frame, typically a heel strike (DM og9 from 3.214 s
        # failed at the 25-iteration limit from the lead-in's extrapolation)
        first = settings if warm_end and previous else settings.cold()
        sol = solve_frame(ctx, k, a0, ws, first, march.warm if warm_end else step.warm,
                          march.J_carry if warm_end else None, not warm_end)
        return replace(sol, iterations=sol.iterations + int(totals[0]), evaluations=sol.evaluations + int(totals[1]),
                       jacobians=sol.jacobians + int(totals[2])), h, march


def lost_between(t_previous, times, t_k, history):
    """Where a march through the sub-step ``times`` (m,) s from a converged frame at
    ``t_previous`` towards the frame at ``t_k`` lost the equilibrium it followed:
    (t_a, t_b) s, the last time of its unbroken run of converged frames (t_previous when
    the first sub-step failed) and the next time, a sub-step's or t_k. ``history``: the
    march's [(j, α)] of converged frames (j = −1 the frame it starts from)."""
    done = {j for j, _ in history}
    f = 0
    while f < len(times) and f in done:
        f += 1
    return (float(t_previous) if f == 0 else float(times[f - 1])), float(times[f] if f < len(times) else t_k)


def approach_for(model, trajectories):
    """The Approach of a trial of ``model`` (the measured loads' data bound the lead-in;
    ``trajectories`` None: determinate kinematics, sub-steps only)."""
    from ..forces.data_loads import data_time_range

    return Approach(trajectories, data_time_range(getattr(model, "external_loads", ()))[0])


__all__ = ["Approach", "approach_for", "approach_times", "lost_between", "sub_step_times", "seated_length", "SUBSTEPS", "LEAD_IN_FRAMES",
           "LEAD_IN_LENGTHS", "LAST_LEAD_IN_FRAMES", "SEATED_FACTOR",
           "MARCH_TOLERANCE"]
