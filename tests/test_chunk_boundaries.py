"""Where a trial is cut into chunks (openfdk.study.boundaries): the limb beyond the FDK
DOFs, its stance from the measured loads, and the cuts moved into stance."""

import numpy as np

from openfdk.study.boundaries import LOADED, cut_preference, limb_bodies, stance_depth
from openfdk.study.chunks import DEEP_ENOUGH, plan_segments


def test_stance_depth_counts_frames_to_the_nearest_unloaded_frame():
    """Frames 2–7 loaded (≥ LOADED × the 10 N peak; 1.5 N is below it): their distance
    to the nearest unloaded frame, by hand; the trial's end counts as a release."""
    assert LOADED == 0.2
    load = np.array([0.0, 1.5, 5.0, 10.0, 10.0, 10.0, 10.0, 5.0, 0.0, 0.0, 3.0, 3.0])
    np.testing.assert_array_equal(stance_depth(load), [0, 0, 1, 2, 3, 3, 2, 1, 0, 0, 1, 1])
    np.testing.assert_array_equal(stance_depth(np.zeros(4)), [0, 0, 0, 0])


def test_a_cut_whose_cold_start_falls_in_swing_moves_into_stance():
    """100 frames in 2 chunks, overlap 5: the equal cut at 50 would start its chunk cold
    at frame 44, in a swing (frames 35–64 unloaded). Stances: frames 0–34 and 65–99,
    each at most 18 frames deep, so a cold start must be ≥ DEEP_ENOUGH × 18 = 9 deep.
    The cut may move within half a chunk (25–75), its cold start (cut − 6) within 19–69:
    frames 19–26 of the first stance qualify (26 is 9 frames before the release at 35),
    none of the second (73 is its first 9 deep). The nearest to the equal split: cut 32.
    Without a preference, or with none positive in reach, the equal split stands."""
    assert DEEP_ENOUGH == 0.5
    load = np.ones(100)
    load[35:65] = 0.0
    pref = stance_depth(load)
    assert pref.max() == 18 and pref[26] == 9 and pref[27] == 8 and pref[73] == 9
    segs = plan_segments(100, 2, 5, pref)
    assert [(s.keep_start, s.keep_stop) for s in segs] == [(0, 32), (32, 100)]
    assert segs[1].solve_start == 26
    equal = [(s.keep_start, s.keep_stop) for s in plan_segments(100, 2, 5)]
    assert equal == [(0, 50), (50, 100)]
    none = np.zeros(100, dtype=int)
    assert [(s.keep_start, s.keep_stop) for s in plan_segments(100, 2, 5, none)] == equal


def test_four_chunks_of_a_gait_like_load_by_hand():
    """240 frames, 4 chunks, overlap 5, loaded 60 of every 100 frames (stances 0–59,
    100–159, 200–239; the deepest frames 30 deep, so a cold start must be ≥ 15 deep).
    Equal cuts 60, 120, 180, each free to move 30 frames. Cut 1: cold starts 24–84,
    qualifying 24–45 (cuts 30–51): 51. Cut 2: cold starts 84–144 (cuts 90–150), the
    second stance qualifies from 114: cut 120 stays, its cold start 15 deep. Cut 3: cold
    starts 144–204; 144 and 145 qualify (the third stance only from 214): 151. The
    segments join and cover every frame once."""
    t = np.arange(240)
    pref = stance_depth(((t % 100) < 60).astype(float))
    segs = plan_segments(240, 4, 5, pref)
    assert [s.keep_start for s in segs] == [0, 51, 120, 151] and segs[-1].keep_stop == 240
    assert all(a.keep_stop == b.keep_start for a, b in zip(segs, segs[1:]))
    assert [int(pref[s.solve_start]) for s in segs[1:]] == [15, 15, 15]


def test_the_limb_of_the_bench_knee_is_the_tibia_the_patella_and_the_foot(tmp_path):
    """The bench's knee (openfdk.fixtures.tka_knee: pelvis welded to the ground, the hip,
    knee and ankle driven, the knee's and the patella's secondary coordinates FDK DOFs):
    cutting the knee's and the patellofemoral joint's rows leaves the femur held to the
    ground by the hip, and the tibia, patella and foot beyond."""
    import warnings

    from openfdk.analysis.jobs import model_and_settings
    from openfdk.fixtures.tka_knee import write_tka_knee

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model, _, _ = model_and_settings(str(write_tka_knee(tmp_path)))
    assert sorted(model.bodies[i].name for i in limb_bodies(model)) == ["calcn_r", "patella_r", "tibia_r"]


def test_without_fdk_dofs_or_limb_loads_there_is_no_preference():
    """A model without FDK DOFs has no limb, and no preference: the equal split."""
    from openfdk.model.builder import ModelBuilder

    b = ModelBuilder("block")
    b.add_body("block", 1.0, [1e-3] * 3)
    model = b.build()
    assert len(limb_bodies(model)) == 0
    assert cut_preference(model, np.linspace(0, 1, 11)) is None


def test_a_later_segment_that_starts_cold_in_swing_is_flagged():
    """The 4-chunk plan of 240 frames with stances 0–59, 100–159, 200–239 and the cuts
    forced to the equal split (no preference): segment 2 starts cold at frame 54 (stance),
    segment 3 at 114 (stance), segment 4 at 174 (swing). cold_start_info flags the last;
    the first segment (the window's own start) and a trial without a stance get nothing;
    chunk_info carries the flag into summary.json's segments."""
    from types import SimpleNamespace

    from openfdk.study.case import cold_start_info
    from openfdk.study.chunks import chunk_info

    t = np.arange(240)
    pref = stance_depth(((t % 100) < 60).astype(float))
    segs = plan_segments(240, 4, 5)
    assert [s.solve_start for s in segs] == [0, 54, 114, 174]
    assert [cold_start_info(pref, s) for s in segs] == [
        {}, {"cold_start_in_stance": True}, {"cold_start_in_stance": True}, {"cold_start_in_stance": False}]
    assert all(cold_start_info(None, s) == {} for s in segs)
    times = t / 100.0
    results = [SimpleNamespace(segment=s, wall_time=1.0, info=cold_start_info(pref, s),
                               kinematics=SimpleNamespace(time=times[s.solve_start:s.solve_stop])) for s in segs]
    info = chunk_info(results, 5)
    assert [seg.get("cold_start_in_stance") for seg in info["segments"]] == [None, True, True, False]
    assert [seg["cold_start_s"] for seg in info["segments"]] == [0.0, 0.54, 1.14, 1.74]
