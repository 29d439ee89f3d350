"""The approach of a failed frame through intermediate frames (openfdk.fdk.approach):
the frame times in closed form, and a load step that Newton cannot follow in one frame
but follows in sub-steps."""

from types import SimpleNamespace

import numpy as np
import pytest

import openfdk.fdk.approach as approach_module
from openfdk.fdk.analysis import FDKStep, fdk_context, run_fdk
from openfdk.fdk.approach import LEAD_IN_FRAMES, MARCH_TOLERANCE, SUBSTEPS, approach_times
from openfdk.fdk.settings import fdk_settings
from openfdk.forces.elements import add_external_load, add_spring
from openfdk.model.builder import ModelBuilder
from openfdk.model.timefunctions import TimeFunction
from openfdk.trial import drive

G = 9.81
M, K = 2.0, 500.0  # kg, N/m
T_STEP, DT = 0.3, 0.1  # s: the load ramps over the frame interval [T_STEP, T_STEP + DT]
F_STEP = 4.0  # N: the root moves by F_STEP / K = 8 mm within that interval


class _Ramp(TimeFunction):
    """Vertical force (3,) N: 0 before T_STEP, F_STEP after T_STEP + DT, linear between."""

    size = 3

    def derivatives(self, t):
        s = min(max((t - T_STEP) / DT, 0.0), 1.0)
        ds = 1.0 / DT if T_STEP < t < T_STEP + DT else 0.0
        return np.array([0.0, 0.0, F_STEP * s]), np.array([0.0, 0.0, F_STEP * ds]), np.zeros(3)


def _slider():
    """A block on a vertical rail on a linear spring, pushed up by the ramp: the root is
    α*(t) = (F(t) − m g) / k (the block's inertia is zero: α̇ = α̈ = 0)."""
    b = ModelBuilder("ramp", gravity=(0, 0, -G))
    b.add_body("block", M, [1e-3] * 3)
    b.add_joint("rail", "prismatic", parent="ground.origin", child="block.origin")
    b.add_measure("z", b._select(b.vector("ground.origin", "block.origin"), [2]))
    b.add_fdk_dof("height", "z", initial=-M * G / K, max_step=1e-3)
    add_spring(b, "spring", "z", K)
    add_external_load(b, "push", "block.origin", force=_Ramp())
    return b.build()


def test_approach_times_in_closed_form():
    """Sub-steps: SUBSTEPS − 1 equally spaced times strictly between frames k − 1 and k;
    lead-in: LEAD_IN_FRAMES frames before the first at the frame spacing, cut at the
    first time with data; nothing for a frame after a failed one."""
    times = 2.0 + np.arange(5) / 120.0
    sub = approach_times(times, 3, True, -np.inf)
    np.testing.assert_allclose(sub, times[2] + np.arange(1, SUBSTEPS) / (120.0 * SUBSTEPS), rtol=0, atol=1e-15)
    lead = approach_times(times, 0, False, -np.inf)
    np.testing.assert_allclose(lead, 2.0 - np.arange(LEAD_IN_FRAMES, 0, -1) / 120.0, rtol=0, atol=1e-15)
    cut = approach_times(times, 0, False, 2.0 - 3.5 / 120.0)
    np.testing.assert_allclose(cut, 2.0 - np.arange(3, 0, -1) / 120.0, rtol=0, atol=1e-15)
    assert approach_times(times, 3, False, -np.inf).size == 0
    assert approach_times(times, 0, False, np.inf).size == 0
    # a one-frame window (``--start`` = ``--end``): the lead-in at the trial's sample
    # interval; without one, no lead-in
    one = approach_times(times[:1], 0, False, 2.0 - 5.5 / 100.0, sample_interval=1 / 100.0)
    np.testing.assert_allclose(one, 2.0 - np.arange(5, 0, -1) / 100.0, rtol=0, atol=1e-15)
    assert approach_times(times[:1], 0, False, -np.inf).size == 0


def test_a_load_step_newton_cannot_follow_in_one_frame_converges_in_sub_steps():
    """Frames 0.1 s apart, max_step 1 mm, 3 Newton iterations per frame: the root moves
    8 mm between t = 0.3 and 0.4 s, so frame 0.4 s fails from its warm start, from the
    previous α, from the initial value and from every scan start (at most 4 mm nearer).
    Through SUBSTEPS − 1 intermediate frames (2 mm apart, the last two extrapolated
    exactly on the linear ramp) it converges; every frame equals the closed form
    α* = (F − m g) / k, and frame 0.4 s counts the marched frames' evaluations. (The
    transient solver, tried first from α_{k−1}, cannot reach 8 mm in 3 steps of at most
    1 mm. Frame 0.5 s, extrapolated 8 mm past its root, which is 0.4 s's, is solved by it
    from 0.4 s.)
    Without the approach (and without the sweep back) the same frame fails."""
    model = _slider()
    times = np.arange(6) * DT
    alpha_star = (np.array([_Ramp().derivatives(t)[0][2] for t in times]) - M * G) / K
    res = run_fdk(model, None, times, max_iterations=3)
    assert res.converged.all(), res.messages
    np.testing.assert_allclose(res.alpha[:, 0], alpha_star, rtol=0, atol=1e-3 / K)
    k = int(np.flatnonzero(np.isclose(times, T_STEP + DT))[0])
    assert alpha_star[k] - alpha_star[k - 1] == pytest.approx(F_STEP / K)
    assert res.restarts[k] >= 1 and np.all(res.restarts[:k] == 0)
    assert res.evaluations[k] > res.evaluations[:k].max() + SUBSTEPS - 1

    settings = fdk_settings(model, None, max_iterations=3)
    ctx = fdk_context(model, None, times)
    step = FDKStep(model, ctx, settings, approach=None, sweep_back=False)
    values = drive(step, len(times), lambda rec: rec.objects("fdk.report"))
    assert [r.converged for r in values] == [i != k for i in range(len(times))]


def test_a_failed_frame_is_solved_again_backward_from_the_next_converged_frame():
    """The slider's load step without the approach: frame 0.4 s fails from every start
    (3 Newton iterations of at most 1 mm, its root 8 mm away). Frame 0.5 s, after it,
    converges cold from that frame's best iterate; the ramp has ended, so its root is
    frame 0.4 s's, and the sweep back from it solves frame 0.4 s from there. Both equal
    the closed form α* = (F − m g) / k; frame 0.4 s is recorded once more (the driver
    keeps the later record), flagged ``fdk.backward``, its counts the failed solve's plus
    the sweep's; no other frame is solved again, and the restarts count the sweep."""
    model = _slider()
    times = np.arange(6) * DT
    alpha_star = (np.array([_Ramp().derivatives(t)[0][2] for t in times]) - M * G) / K
    k = int(np.flatnonzero(np.isclose(times, T_STEP + DT))[0])
    settings = fdk_settings(model, None, max_iterations=3)
    recorded = []
    step = FDKStep(model, fdk_context(model, None, times), settings, approach=None)
    original = step.step

    def logged(j):
        out = original(j)
        recorded.append([(i, v["fdk.evaluations"], v["fdk.report"].converged) for i, v in out])
        return out

    step.step = logged
    rec = drive(step, len(times), lambda rec: rec)
    assert all(r.converged for r in rec.objects("fdk.report"))
    np.testing.assert_allclose(rec.array("fdk.alpha")[:, 0], alpha_star, rtol=0, atol=1e-3 / K)
    assert alpha_star[k + 1] == pytest.approx(alpha_star[k], abs=1e-12)  # the ramp's end
    assert rec.array("fdk.backward").tolist() == [int(i == k) for i in range(len(times))]
    # frame k failed first, then frame k + 1 gave it again, converged, with more evaluations
    (failed_k,), (now, again) = recorded[k], recorded[k + 1]
    assert failed_k[0] == k and not failed_k[2]
    assert now[0] == k + 1 and now[2] and again[0] == k and again[2]
    assert again[1] > failed_k[1] and rec.array("fdk.evaluations")[k] == again[1]
    assert rec.array("fdk.restarts")[k] >= 1
    assert all(len(r) == 1 for j, r in enumerate(recorded) if j != k + 1)


def test_the_marched_frames_are_solved_to_march_tolerance_and_the_frame_to_the_tolerance(monkeypatch):
    """The marched frames are stepping stones: each Newton solve of one is asked for
    MARCH_TOLERANCE × the tolerance; frame k's own solve for the tolerance, and its α
    still equals the closed form to tolerance / k."""
    import openfdk.fdk.analysis as analysis

    asked = []
    solve = analysis.solve_frame

    def recording(ctx, k, alpha0, ws, settings, *args, **kwargs):
        asked.append((len(ctx.times), settings.tolerance))
        return solve(ctx, k, alpha0, ws, settings, *args, **kwargs)

    monkeypatch.setattr(analysis, "solve_frame", recording)
    # (the transient solver, tried first, solves frame 0.5 s from 0.4 s's α: the ramp
    # has ended; made to fail here so that both frames are marched to)
    monkeypatch.setattr(approach_module, "solve_transient", _transient_stand_in(False))
    model = _slider()
    times = np.arange(6) * DT
    res = run_fdk(model, None, times, max_iterations=3)
    assert res.converged.all()
    marched = [tol for n, tol in asked if n == SUBSTEPS - 1]
    trial = [tol for n, tol in asked if n == len(times)]
    # (frames 0.4 and 0.5 s each fail from their warm starts and are approached)
    assert len(marched) == 2 * (SUBSTEPS - 1) and set(marched) == {MARCH_TOLERANCE * 1e-3}
    assert len(trial) >= len(times) and set(trial) == {1e-3}
    alpha_star = (np.array([_Ramp().derivatives(t)[0][2] for t in times]) - M * G) / K
    np.testing.assert_allclose(res.alpha[:, 0], alpha_star, rtol=0, atol=1e-3 / K)


def _lead_in_stand_in(tried, record, converged, march=None, reaches_end=True):
    """An ``Approach._solve_after`` stand-in: appends ``record(times, previous, restart,
    source)`` to ``tried``; frame k converges iff ``converged(times, previous, restart)``,
    with counts 10, 100 and 1 per marched frame (iterations, evaluations, Jacobians); the
    march's history reaches its last frame iff ``reaches_end`` (an int: it stops that
    many frames short of it); the march is ``march``."""
    from openfdk.fdk.newton import FrameSolution

    def solve_after(self, step, k, times, previous, restart=False, source=None):
        tried.append(record(np.array(times), previous, restart, source))
        ok = bool(converged(times, previous, restart))
        sol = FrameSolution(None, ok, 10 * len(times), 100 * len(times), "", "converged" if ok else "x",
                            jacobians=len(times))
        short = 0 if reaches_end is True else 1 if reaches_end is False else int(reaches_end)
        reached = len(times) - short
        return sol, [(j, np.array([float(j)])) for j in range(reached)], march

    return solve_after


def _bare_approach():
    """An Approach without trajectories or a data bound (its _solve_after stood in for)."""
    from openfdk.fdk.approach import Approach

    approach = Approach.__new__(Approach)
    approach.trajectories, approach.first_time, approach.sample_interval = None, -np.inf, None
    approach.transient_frame = None
    return approach


def test_a_lead_in_after_which_the_first_frame_fails_is_tried_again_from_further_back(monkeypatch):
    """The window's first frame fails after the short lead-in (LEAD_IN_FRAMES) and
    converges after the 24-frame one (DM og3 from 3.47 s, late swing: 5 of 16 frames
    converged after a 12-frame lead-in alone, 16 of 16 with the longer ones). The lengths
    are tried in order, the failed attempt's counts are added to the frame's, and the
    successful march's frames join the history as frames −24 … −1. With data only 20
    frames back, the lead-in stops at those 20 frames, and the last lead-in (whose
    marched frames restart) has LAST_LEAD_IN_FRAMES."""
    from types import SimpleNamespace

    from openfdk.fdk.approach import LAST_LEAD_IN_FRAMES, LEAD_IN_LENGTHS, Approach

    assert LEAD_IN_LENGTHS == (LEAD_IN_FRAMES, 24, 48) and LEAD_IN_FRAMES < 20 < 24
    dt = 1 / 120
    window = 3.0 + dt * np.arange(5)
    tried = []

    monkeypatch.setattr(Approach, "_solve_after", _lead_in_stand_in(
        tried, lambda times, *_: len(times), lambda times, *_: len(times) >= 24))
    step = SimpleNamespace(ctx=SimpleNamespace(times=window), history=[])
    approach = _bare_approach()
    sol = approach(step, 0)
    n = LEAD_IN_FRAMES + (SUBSTEPS - 1) + 24  # (the sub-steps after the first lead-in: below)
    assert tried == [LEAD_IN_FRAMES, SUBSTEPS - 1, 24] and sol.converged
    assert (sol.iterations, sol.evaluations, sol.jacobians) == (10 * n, 100 * n, n)
    assert [j for j, _ in step.history] == list(range(-24, 0))

    # the trial's data begin 20 frames before the window: the short lead-in, then 20
    # frames, then no further
    tried.clear()
    step = SimpleNamespace(ctx=SimpleNamespace(times=window), history=[])
    approach.first_time = window[0] - 20 * dt
    sol = approach(step, 0)
    # (and the last lead-in, whose marched frames restart)
    assert tried == [LEAD_IN_FRAMES, SUBSTEPS - 1, 20, SUBSTEPS - 1, LAST_LEAD_IN_FRAMES] and not sol.converged
    assert sol.evaluations == 100 * (LEAD_IN_FRAMES + 20 + 2 * (SUBSTEPS - 1) + LAST_LEAD_IN_FRAMES)
    assert step.history == []


def test_a_first_frame_that_fails_after_a_converged_lead_in_is_approached_in_sub_steps_from_it(monkeypatch):
    """DM og1 from 2.406 s (the tutorial's gait cycle): the 6-frame lead-in converged up to
    the frame before the window's first, a heel strike fell between the two, and the
    first stalled at 0.3 N; the longer lead-ins then failed through late swing (1 498 of
    the cycle's 2 156 evaluations; 1 133 in all with sub-steps after each lead-in: they
    converged after the 24-frame one). After a lead-in whose march reached its last frame,
    the sub-steps from that frame come first: at t_last + j (t_0 − t_last) / SUBSTEPS, from
    that march's own state (``source``); when they converge, no longer lead-in runs, the
    counts are the two attempts' sum, and the lead-in's frames join the history as
    −LEAD_IN_FRAMES … −1. A lead-in whose last frame failed (og1 from 2.408 s: 2.400 s, at
    the heel strike) gets 2 SUBSTEPS − 1 sub-steps from the frame before (its last
    converged one); one whose last two failed, none."""
    from types import SimpleNamespace

    from openfdk.fdk.approach import Approach

    dt = 1 / 120
    window = 3.0 + dt * np.arange(5)
    tried, lead_in_march = [], object()

    # the lead-in's first frame fails, the sub-steps (previous: True) converge
    record = lambda times, previous, restart, source: (times, previous, source)  # noqa: E731
    monkeypatch.setattr(Approach, "_solve_after", _lead_in_stand_in(
        tried, record, lambda times, previous, restart: previous, march=lead_in_march))
    approach = _bare_approach()
    step = SimpleNamespace(ctx=SimpleNamespace(times=window), history=[])
    sol = approach(step, 0)
    assert [(len(t), p) for t, p, _ in tried] == [(LEAD_IN_FRAMES, False), (SUBSTEPS - 1, True)]
    lead_in, sub = tried[0][0], tried[1][0]
    np.testing.assert_allclose(lead_in, window[0] - dt * np.arange(LEAD_IN_FRAMES, 0, -1))
    np.testing.assert_allclose(sub, window[0] - dt + dt * np.arange(1, SUBSTEPS) / SUBSTEPS)
    assert lead_in[-1] < sub[0] and sub[-1] < window[0] and tried[1][2] is lead_in_march
    n = LEAD_IN_FRAMES + SUBSTEPS - 1
    assert sol.converged and (sol.iterations, sol.evaluations, sol.jacobians) == (10 * n, 100 * n, n)
    assert [j for j, _ in step.history] == list(range(-LEAD_IN_FRAMES, 0))

    # the lead-in's own last frame failed: sub-steps over the two frame intervals from the
    # frame before it, then (they fail here) the longer lead-in
    monkeypatch.setattr(Approach, "_solve_after", _lead_in_stand_in(
        tried, record, lambda times, *_: len(times) >= 24, reaches_end=False, march=lead_in_march))
    tried.clear()
    step = SimpleNamespace(ctx=SimpleNamespace(times=window), history=[])
    assert approach(step, 0).converged
    assert [(len(t), p) for t, p, _ in tried] == [(LEAD_IN_FRAMES, False), (2 * SUBSTEPS - 1, True), (24, False)]
    np.testing.assert_allclose(tried[1][0], window[0] - 2 * dt + 2 * dt * np.arange(1, 2 * SUBSTEPS) / (2 * SUBSTEPS))
    assert tried[1][2] is lead_in_march

    # its last two frames failed: on to the longer lead-in, no sub-steps
    monkeypatch.setattr(Approach, "_solve_after", _lead_in_stand_in(
        tried, record, lambda times, *_: len(times) >= 24, reaches_end=2))
    tried.clear()
    step = SimpleNamespace(ctx=SimpleNamespace(times=window), history=[])
    assert approach(step, 0).converged and [len(t) for t, _, _ in tried] == [LEAD_IN_FRAMES, 24]


def test_a_first_frame_that_fails_after_every_lead_in_gets_one_whose_marched_frames_restart(monkeypatch):
    """DM og1 from 2.5 s with filtered ground reactions: the plain lead-ins (12, 24, 48
    frames at the time) stall where the patella engages and the window's first 5 frames
    failed. The last lead-in (LAST_LEAD_IN_FRAMES, 12) lets its marched frames restart;
    its counts add to the frame's and its frames join the history as −12 … −1."""
    from types import SimpleNamespace

    from openfdk.fdk.approach import LAST_LEAD_IN_FRAMES, LEAD_IN_LENGTHS, Approach

    dt = 1 / 120
    window = 3.0 + dt * np.arange(5)
    tried = []

    monkeypatch.setattr(Approach, "_solve_after", _lead_in_stand_in(
        tried, lambda times, previous, restart, source: (len(times), restart), lambda times, previous, restart: restart))
    approach = _bare_approach()
    step = SimpleNamespace(ctx=SimpleNamespace(times=window), history=[])
    sol = approach(step, 0)
    # (each plain lead-in's march reached its last frame: sub-steps from it after each)
    assert tried == [p for n in LEAD_IN_LENGTHS for p in ((n, False), (SUBSTEPS - 1, False))] + \
        [(LAST_LEAD_IN_FRAMES, True)]
    total = sum(LEAD_IN_LENGTHS) + len(LEAD_IN_LENGTHS) * (SUBSTEPS - 1) + LAST_LEAD_IN_FRAMES
    assert sol.converged and (sol.iterations, sol.evaluations, sol.jacobians) == (10 * total, 100 * total, total)
    assert [j for j, _ in step.history] == list(range(-LAST_LEAD_IN_FRAMES, 0))
    # a sub-step approach (frame k − 1 converged; the transient solver from its α failed
    # first) gets no such last attempt
    tried.clear()
    monkeypatch.setattr(approach_module, "solve_transient", _transient_stand_in(False))
    step = _first_frame_step(window)
    step.history = [(0, np.zeros(1))]
    sol = approach(step, 1)
    assert not sol.converged and tried == [(SUBSTEPS - 1, False)]
    assert (sol.iterations, sol.evaluations, sol.jacobians) == (3 + 10 * (SUBSTEPS - 1), 7 + 100 * (SUBSTEPS - 1),
                                                                2 + SUBSTEPS - 1)


def test_a_marched_frame_with_restarts_is_solved_again_and_never_scanned(monkeypatch):
    """The last lead-in's marched steps restart (restart=True) but do not scan around
    α_{k−1} (FDKStep(scan=False)): a failed frame there costs at most three starts. The
    slider at 0.3 s (no load: the root is the initial α) and 0.4 s (the load's 4 N move the
    root 8 max_steps up), one Newton iteration per start: frame 1 fails from every start."""
    import openfdk.fdk.analysis as analysis
    from openfdk.fdk.analysis import SCAN_STEPS

    model = _slider()
    times = np.array([T_STEP, T_STEP + DT])
    settings = fdk_settings(model, None, max_iterations=1, cold_max_iterations=1, line_search=False)
    calls = []
    original = analysis.solve_restarts

    def recording(ctx, k, starts, *args, **kwargs):
        calls.append(len(list(starts)))
        return original(ctx, k, starts, *args, **kwargs)

    monkeypatch.setattr(analysis, "solve_restarts", recording)
    for scan, expected in ((False, [2]), (True, [2, 2 * len(SCAN_STEPS) * 1])):
        calls.clear()
        step = FDKStep(model, fdk_context(model, None, times), settings, scan=scan)
        (_, first), = step.step(0)
        (_, second), = step.step(1)
        assert first["fdk.report"].converged and not second["fdk.report"].converged
        assert calls == expected, (scan, calls)


def test_a_frame_stalled_near_its_root_is_scanned_around_its_best_iterate(monkeypatch):
    """After every start failed, a frame whose best iterate came within NEAR_SCAN_RANGE
    tolerances of the root is solved again from that iterate moved along each DOF by
    ±NEAR_SCAN_STEP max_step (analysis.near_starts); one whose best stayed farther is
    not. The slider of the test above, one Newton iteration per start, each a max_step
    (1 mm) long towards the root 8 max_steps above α_{k−1}: the best start is the scan's
    α_{k−1} + 4 max_steps, which ends 3 max_steps short (|f| = 3 mm × k = 1.5 N). With a
    tolerance of 0.05 N (range 5 N) the two near starts follow the scan, with 0.01 N
    (range 1 N) they do not."""
    import openfdk.fdk.analysis as analysis
    from openfdk.fdk.analysis import NEAR_SCAN_RANGE, NEAR_SCAN_STEP, SCAN_STEPS, near_starts

    starts = np.array(near_starts(np.array([1.0, 2.0]), np.array([0.5, 4.0])))
    np.testing.assert_allclose(starts, [[1.0 - 0.05, 2.0], [1.05, 2.0], [1.0, 2.0 - 0.4], [1.0, 2.4]])
    model = _slider()
    times = np.array([T_STEP, T_STEP + DT])
    calls = []
    original = analysis.solve_restarts

    def recording(ctx, k, starts, *args, **kwargs):
        starts = list(starts)
        calls.append([float(a[0]) for a in starts])
        return original(ctx, k, starts, *args, **kwargs)

    monkeypatch.setattr(analysis, "solve_restarts", recording)
    for tolerance, near in ((0.05, True), (0.01, False)):
        assert (3 * 1e-3 * K < NEAR_SCAN_RANGE * tolerance) == near
        settings = fdk_settings(model, None, max_iterations=1, cold_max_iterations=1, line_search=False,
                                tolerance=tolerance)
        calls.clear()
        step = FDKStep(model, fdk_context(model, None, times), settings)
        (_, first), = step.step(0)
        (_, second), = step.step(1)
        assert first["fdk.report"].converged and not second["fdk.report"].converged
        assert [len(c) for c in calls] == [2, 2 * len(SCAN_STEPS)] + ([2] if near else [])
        if near:  # around the best iterate of the earlier starts, 3 max_steps short of the root
            stall = first["fdk.alpha"][0] + 5e-3
            np.testing.assert_allclose(calls[-1], [stall - NEAR_SCAN_STEP * 1e-3, stall + NEAR_SCAN_STEP * 1e-3],
                                       rtol=0, atol=1e-12)
            # the frame reports the best of all: the upper near start's step, 1.9 mm short
            assert second["fdk.alpha"][0] == pytest.approx(stall + 1.1e-3, abs=1e-12)
            assert abs(second["fdk.f_fdk"][0]) == pytest.approx(1.9e-3 * K, rel=1e-9)


def test_a_frame_whose_warm_start_fails_after_a_converged_frame_is_approached_before_any_other_start(monkeypatch):
    """After a converged frame, a frame that fails from its warm start goes through the
    sub-steps first, and the restarts from α_{k−1} and the initial values are tried only
    if the sub-steps fail (a heel strike's load moves the root further than Newton
    reaches from any of those starts; on DM's six gait trials 12 of 45 restarted frames
    had converged only after the approach, at 129 evaluations each). The slider's
    ramp: frames 0.4 s (root 8 mm up) and 0.5 s (extrapolated 8 mm past its root) fail
    from their warm starts with 3 iterations; each is approached, converges there, and
    is never restarted from another α; every α is the closed form (F − m g) / k."""
    import openfdk.fdk.analysis as analysis
    from openfdk.fdk.approach import Approach

    model = _slider()
    times = np.arange(6) * DT
    alpha_star = (np.array([_Ramp().derivatives(t)[0][2] for t in times]) - M * G) / K
    approached, restarted = [], []
    call, restarts = Approach.__call__, analysis.solve_restarts

    def approach(self, step, k):
        approached.append(k)
        return call(self, step, k)

    def solve_restarts(ctx, k, *args, **kwargs):
        restarted.append(k)
        return restarts(ctx, k, *args, **kwargs)

    monkeypatch.setattr(Approach, "__call__", approach)
    monkeypatch.setattr(analysis, "solve_restarts", solve_restarts)
    res = run_fdk(model, None, times, max_iterations=3)
    assert res.converged.all(), res.messages
    np.testing.assert_allclose(res.alpha[:, 0], alpha_star, rtol=0, atol=1e-3 / K)
    k = int(np.flatnonzero(np.isclose(times, T_STEP + DT))[0])
    assert approached == [0, k, k + 1]  # (frame 0: its lead-in, none here without markers)
    assert restarted == []
    assert list(res.restarts) == [0] * k + [1, 1]


def test_a_run_interrupted_after_a_failed_frame_resumes_and_sweeps_it_as_the_whole_run_does(tmp_path):
    """The slider's load step without the approach, checkpointed after every frame and
    interrupted just after the failed frame 0.4 s: the checkpoint carries the frames not
    yet swept, so the resumed run solves frame 0.5 s and then 0.4 s backward, and every
    frame's record equals the uninterrupted run's (α, counts, the backward flag)."""
    from openfdk.trial import TrialInterrupted
    from openfdk.trial.checkpoint import Checkpoints

    model = _slider()
    times = np.arange(6) * DT
    k = int(np.flatnonzero(np.isclose(times, T_STEP + DT))[0])
    settings = fdk_settings(model, None, max_iterations=3)

    def fresh():
        return FDKStep(model, fdk_context(model, None, times), settings, approach=None)

    def records(rec):
        return (rec.array("fdk.alpha").copy(), rec.array("fdk.evaluations").copy(), rec.array("fdk.backward").copy(),
                [r.converged for r in rec.objects("fdk.report")])

    whole = drive(fresh(), len(times), records)
    assert whole[2].tolist() == [int(i == k) for i in range(len(times))] and all(whole[3])
    step = fresh()
    solve = step.step

    def stopping(j):
        if j == k + 1:
            raise KeyboardInterrupt  # (the driver's Ctrl-C) before frame k + 1
        return solve(j)

    step.step = stopping
    checkpoints = Checkpoints(tmp_path / "ck", "slider", every_frames=1)
    with pytest.raises(TrialInterrupted) as stopped:
        drive(step, len(times), records, checkpoints=checkpoints)
    assert stopped.value.partial[3] == [True] * k + [False]  # frame k failed, not yet swept
    resumed = drive(fresh(), len(times), records, checkpoints=Checkpoints(tmp_path / "ck", "slider", every_frames=1),
                    resume=True)
    for got, expected in zip(resumed[:3], whole[:3]):
        np.testing.assert_array_equal(got, expected)
    assert resumed[3] == whole[3]


def test_the_convergence_figure_marks_the_frames_solved_backward():
    """The slider's load step without the approach: in the run's convergence figure the
    FDK panel marks frame 0.4 s, and only it, at its evaluation count (the failed solve's
    and the sweep's), and the caption says what the mark means."""
    from openfdk.fdk.analysis import fdk_result
    from openfdk.plots.run import make_figures
    from openfdk.results.run import RunResults

    model = _slider()
    times = np.arange(6) * DT
    k = int(np.flatnonzero(np.isclose(times, T_STEP + DT))[0])
    settings = fdk_settings(model, None, max_iterations=3)
    ctx = fdk_context(model, None, times)
    res = drive(FDKStep(model, ctx, settings, approach=None), len(times),
                lambda rec: fdk_result(rec, model, ctx, settings, times, 1.0))
    assert res.backward.tolist() == [int(i == k) for i in range(len(times))]
    fig = make_figures(RunResults.from_analysis(res.kinematics, res.forces, {"fdk": res.summary()}, model))["convergence"]
    marks = [(ax, line) for ax in fig.axes for line in ax.get_lines() if line.get_label() == "solved backward"]
    assert len(marks) == 1
    ax, line = marks[0]
    assert ax.get_ylabel().startswith("FDK iterations")
    np.testing.assert_allclose(line.get_xdata(), [times[k]])
    np.testing.assert_allclose(line.get_ydata(), [res.evaluations[k]])
    assert "solved again backward" in fig.texts[-1].get_text()


def test_the_lead_in_starts_where_the_initial_values_are_nearer_equilibrium():
    """seated_length: the 6-frame lead-in stands unless its cold frame's merit at the
    initial values is more than SEATED_FACTOR times the 24-frame one's; then the nearest
    of 6, 12, 18 and 24 frames within SEATED_FACTOR of the smallest merit (DM og1 from
    3.183 s: 17.6, 8.4, 2.8, 1.8 J → 18 frames)."""
    from openfdk.fdk.approach import LEAD_IN_FRAMES, SEATED_FACTOR, seated_length

    assert LEAD_IN_FRAMES == 6 and SEATED_FACTOR == 2.0
    asked = []

    def merits(table):
        def merit(m):
            asked.append(m)
            return table.get(m)
        return merit

    # og1 from 3.183 s (swing): further back
    assert seated_length(merits({6: 17.6, 12: 8.4, 18: 2.8, 24: 1.8})) == (18, 4)
    assert sorted(asked) == [6, 12, 18, 24]
    # the bench window (og1 from 2.5 s): 2.2 ≤ 2 × 1.3, the near one stands; two merits asked
    asked.clear()
    assert seated_length(merits({6: 2.2, 12: 2.4, 18: 13.0, 24: 1.3})) == (6, 2) and asked == [6, 24]
    # the smallest merit itself when none nearer is within the factor
    assert seated_length(merits({6: 50.0, 12: 30.0, 18: 20.0, 24: 4.0})) == (24, 4)
    # exactly at the factor: the near one (≤)
    assert seated_length(merits({6: 2.0, 24: 1.0})) == (6, 2)
    # data that do not reach 24 frames back (not an evaluation), or a near frame that
    # cannot be evaluated (an evaluation that failed)
    assert seated_length(merits({6: 9.0, 12: 1.0})) == (6, 1)
    assert seated_length(merits({})) == (6, 0)
    assert seated_length(merits({6: np.inf, 12: 1.5, 18: 5.0, 24: 1.0})) == (12, 4)
    assert seated_length(merits({6: np.inf, 12: 3.0, 18: 5.0, 24: 1.0})) == (24, 4)
    assert seated_length(merits({6: np.inf, 12: np.inf, 18: np.inf, 24: np.inf})) == (6, 2)


def test_the_lead_in_s_first_length_and_its_merits_count_towards_the_frame(monkeypatch):
    """Approach: the first lead-in has seated_length's length (the longer ones follow),
    and its merit evaluations are added to the frame's evaluations."""
    from types import SimpleNamespace

    from openfdk.fdk.approach import Approach

    dt = 1 / 120
    window = 3.0 + dt * np.arange(5)
    tried = []
    table = {6: 17.6, 12: 8.4, 18: 2.8, 24: 1.8}
    monkeypatch.setattr(Approach, "_initial_merit", lambda self, step, k, m: table.get(m))
    monkeypatch.setattr(Approach, "_solve_after", _lead_in_stand_in(
        tried, lambda times, *_: len(times), lambda times, *_: len(times) >= 24))
    monkeypatch.setattr(approach_module, "solve_transient", _transient_stand_in(False))
    approach = _bare_approach()
    approach.trajectories = object()  # (markers: the lead-in's start is chosen)
    step = _first_frame_step(window)
    sol = approach(step, 0)
    n = 18 + (SUBSTEPS - 1) + 24  # 18 frames (failed), the sub-steps from its last, then 24
    assert tried == [18, SUBSTEPS - 1, 24] and sol.converged
    # the failed transient start's counts (3, 7, 2) and the 4 merits add to the lead-ins'
    assert (sol.iterations, sol.evaluations, sol.jacobians) == (10 * n + 3, 100 * n + 4 + 7, n + 2)
    assert approach.transient_frame is None


def _transient_stand_in(converged, calls=None):
    """A ``solve_transient`` stand-in: 3 iterations, 7 evaluations, 2 Jacobians, frame k
    converged iff ``converged(k)`` (or ``converged`` itself, a bool), α = 0.5; appends
    (k, alpha0, max_iterations) to ``calls``."""
    from openfdk.fdk.newton import FrameSolution

    def solve(ctx, k, alpha0, ws, settings, warm=None):
        ok = converged(k) if callable(converged) else converged
        if calls is not None:
            calls.append((k, np.array(alpha0), settings.max_iterations))
        best = SimpleNamespace(alpha=np.array([0.5]), norm=0.0 if ok else 5.0)
        return FrameSolution(best, ok, 3, 7, "", "converged" if ok else "iteration_limit", jacobians=2)

    return solve


def _first_frame_step(window):
    """The stand-in of an FDKStep at the window's first frame, with marker tracking."""
    from openfdk.fdk.settings import FDKSettings

    ctx = SimpleNamespace(times=window, tracker=object(), frames_needed=lambda k: [k])
    return SimpleNamespace(ctx=ctx, history=[], settings=FDKSettings(), last_state=np.zeros(1), a_init=np.zeros(1),
                           warm=None)


def test_the_transient_start_solves_the_first_frame_before_any_lead_in(monkeypatch):
    """The window's first frame is solved by pseudo-transient continuation from the
    initial values first (fdk/transient.py), with the cold iteration limit; when that
    converges no lead-in is marched. The next frame, which has no velocity to
    extrapolate, is solved by it too, from frame 0's α with the ordinary limit, and
    through sub-steps when that fails (their counts added)."""
    from openfdk.fdk.approach import Approach

    dt = 1 / 120
    window = 3.0 + dt * np.arange(5)
    tried, calls = [], []
    monkeypatch.setattr(Approach, "_initial_merit", lambda self, step, k, m: pytest.fail("no lead-in"))
    monkeypatch.setattr(Approach, "_solve_after", _lead_in_stand_in(
        tried, lambda times, previous, restart, source: (len(times), previous), lambda *_: True))
    monkeypatch.setattr(approach_module, "solve_transient", _transient_stand_in(lambda k: k == 0, calls))
    approach = _bare_approach()
    approach.trajectories = object()
    step = _first_frame_step(window)
    sol = approach(step, 0)
    assert sol.converged and (sol.iterations, sol.evaluations, sol.jacobians) == (3, 7, 2)
    assert tried == [] and step.history == [] and approach.transient_frame == 0
    assert len(calls) == 1 and calls[0][0] == 0 and np.array_equal(calls[0][1], step.a_init)
    assert calls[0][2] == step.settings.cold_max_iterations
    step.history = [(0, np.array([0.5]))]
    assert approach.without_velocity(step, 1) and not approach.without_velocity(step, 2)
    sol = approach(step, 1)  # the transient solver fails at frame 1: sub-steps
    assert calls[1][0] == 1 and calls[1][1] == pytest.approx([0.5]) and calls[1][2] == step.settings.max_iterations
    assert sol.converged and tried == [(SUBSTEPS - 1, True)]
    assert (sol.iterations, sol.evaluations, sol.jacobians) == (3 + 10 * (SUBSTEPS - 1), 7 + 100 * (SUBSTEPS - 1),
                                                                2 + SUBSTEPS - 1)
    # with frames before it in the history (a lead-in's, or frame 1 solved) it has a velocity
    step.history = [(-1, np.zeros(1)), (0, np.ones(1))]
    assert not approach.without_velocity(step, 1)
    step.history = [(0, np.zeros(1)), (1, np.ones(1))]
    assert not approach.without_velocity(step, 2)


R_PIN = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # the pin's z axis along world +y
L_ARM = 0.5  # m: the bob's centre of mass below the pivot
T_TIP = 0.3375  # s: the moment reaches m g L here (between the sub-steps at 0.325 and 0.35 s)


class _Twist(TimeFunction):
    """A moment (3,) N m about world y rising at m g L / T_TIP per second."""

    size = 3

    def derivatives(self, t):
        rate = M * G * L_ARM / T_TIP
        return np.array([0.0, rate * t, 0.0]), np.array([0.0, rate, 0.0]), np.zeros(3)


def _tipping(moment=None):
    """A bob on a pin (the swing angle θ its FDK DOF) twisted by a rising moment M(t):
    its equilibrium is M = m g L sin θ, which exists only while M ≤ m g L, i.e. until
    t = T_TIP (a fold at θ = 90°, then no root at all)."""
    b = ModelBuilder("tipping", gravity=(0, 0, -G))
    b.add_body("bob", M, [1e-3] * 3, position=[0, 0, -L_ARM])
    b.add_frame("ground", "pin", [0, 0, 0], orientation=R_PIN)
    b.add_frame("bob", "pin", [0, 0, L_ARM], orientation=R_PIN)
    b.add_joint("pin", "revolute", parent="ground.pin", child="bob.pin")
    b.add_fdk_dof("swing", b.angles("ground.pin", "bob.pin"), component=2, initial=0.0, max_step=0.05)
    add_external_load(b, "twist", "bob.origin", moment=_Twist() if moment is None else moment)
    return b.build()


def test_a_frame_past_a_fold_says_where_its_sub_steps_lost_the_equilibrium():
    """Frames 0.1 s apart: the equilibrium sin θ = t / T_TIP exists at 0–0.3 s and at no
    α from 0.4 s on. Frame 0.4 s fails after the converged 0.3 s; its sub-steps (0.325,
    0.35, 0.375 s) follow the equilibrium to 0.325 s (sin θ = 0.963) and lose it at
    0.35 s, which brackets the fold at T_TIP. The message says so; the frames after it,
    whose previous frame failed, are not marched and say nothing of it."""
    from openfdk.fdk.approach import lost_between

    model = _tipping()
    times = np.arange(7) * DT
    res = run_fdk(model, None, times)
    converged = times < T_TIP
    assert res.converged.tolist() == converged.tolist(), res.messages
    np.testing.assert_allclose(np.abs(np.sin(res.alpha[converged, 0])), times[converged] / T_TIP, atol=1e-4)
    k = int(np.flatnonzero(~converged)[0])
    message = res.messages[k]
    assert "the equilibrium followed from the converged frame at 0.3000 s is found in sub-steps up to 0.3250 s " \
           "and not at 0.3500 s" in message, message
    assert 0.325 < T_TIP < 0.35
    assert all("sub-steps" not in res.messages[j] for j in range(k + 1, len(times)))
    # no root: the best iterate of each failed frame is the tipped bob (|sin θ| = 1), where
    # the residual moment is smallest, M(t) − m g L
    for j in np.flatnonzero(~converged):
        assert abs(res.f_fdk[j, 0]) == pytest.approx(M * G * L_ARM * (times[j] / T_TIP - 1.0), rel=1e-3)
    # lost_between: the unbroken run of converged sub-steps, whatever converged after it
    sub = np.array([0.1, 0.2, 0.3])
    assert lost_between(0.0, sub, 0.4, [(-1, 0), (0, 0), (2, 0)]) == (0.1, 0.2)
    assert lost_between(0.0, sub, 0.4, [(-1, 0)]) == (0.0, 0.1)
    assert lost_between(0.0, sub, 0.4, [(-1, 0), (0, 0), (1, 0), (2, 0)]) == (0.3, 0.4)


class _Tent(TimeFunction):
    """The moment of :class:`_Twist` rising until T_PEAK, then falling back as fast."""

    size = 3

    def derivatives(self, t):
        rate = M * G * L_ARM / T_TIP
        up = t <= T_PEAK
        value = rate * (t if up else 2.0 * T_PEAK - t)
        return np.array([0.0, value, 0.0]), np.array([0.0, rate if up else -rate, 0.0]), np.zeros(3)


T_PEAK = 0.45  # s: the tent's moment exceeds m g L from T_TIP to 2 T_PEAK − T_TIP = 0.5625 s


def test_a_failed_frame_the_sweep_back_cannot_solve_says_so():
    """The bob twisted by a moment that rises past m g L and falls back: no equilibrium
    at 0.4 and 0.5 s, one again at 0.6 s (sin θ = 0.889), which converges after the
    failed frames. The sweep back from it tries 0.5 s, which has no root, and stops
    there: frame 0.5 s is recorded again with its message ending in the sweep's
    account and its counts including the sweep's solve; frame 0.4 s keeps its sub-step
    account and is not tried backward."""
    model = _tipping(_Tent())
    times = np.arange(8) * DT
    moment = np.array([_Tent().derivatives(t)[0][1] for t in times])
    converged = moment <= M * G * L_ARM
    assert converged.tolist() == [True, True, True, True, False, False, True, True]
    recorded = []
    step = FDKStep(model, fdk_context(model, None, times), fdk_settings(model, None),
                   approach=approach_module.approach_for(model, None))
    original = step.step

    def logged(j):
        out = original(j)
        recorded.append([(i, v["fdk.evaluations"], v["fdk.report"]) for i, v in out])
        return out

    step.step = logged
    rec = drive(step, len(times), lambda rec: rec)
    reports = rec.objects("fdk.report")
    assert [r.converged for r in reports] == converged.tolist()
    np.testing.assert_allclose(np.abs(np.sin(rec.array("fdk.alpha")[converged, 0])), moment[converged] / (M * G * L_ARM),
                               atol=1e-4)
    assert "solved backward from the converged frame at 0.6000 s, not converged either" in reports[5].message
    assert "sub-steps up to" not in reports[5].message
    assert "sub-steps up to" in reports[4].message and "solved backward" not in reports[4].message
    # frame 0.6 s gave frame 0.5 s again, its counts the forward solve's and the sweep's
    (first_5,), (now_6, again_5) = recorded[5], recorded[6]
    assert now_6[0] == 6 and now_6[2].converged and again_5[0] == 5 and not again_5[2].converged
    assert again_5[1] > first_5[1] and rec.array("fdk.evaluations")[5] == again_5[1]
    assert rec.array("fdk.backward")[5] == 0  # not solved backward
