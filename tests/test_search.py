"""The search with the QP teacher in the loop (physicalize/search/): exact snapshots of a rollout, the guided
reference's offsets, a search that turns a falling real take into a standing one, determinism for a seed, and bad
settings as one-line errors (real MuJoCo, the real QP teacher)."""

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared
from standing import stand_problem

from physicalize.clip import physicalize_clip, robot_alone
from physicalize.rollout import Tracker, simulate
from physicalize.search.beam import Elite, Scorer, SearchConfig, _skip_ahead, drift_onset, frame_budget, search
from physicalize.search.guide import GuidedReference, Segment, fade
from physicalize.stage import search_config
from physicalize.wbc import WholeBodyController
from pipeline.errors import InputError


def _controller(scene):
    return WholeBodyController(scene.model, scene.profile)


def test_a_restored_tracker_continues_bit_for_bit():
    """Snapshot at frame 30, another continuation (a guided reference) to 60, restore: the run to 60 equals a run
    that never branched, in every recorded array, and the controller's state is back too."""
    scene, ref, (q0, v0) = stand_problem()
    straight = simulate(scene, ref, _controller(scene), q0, v0)
    tracker = Tracker(scene, ref, _controller(scene), q0, v0)
    tracker.run(30)
    snap = tracker.snapshot()
    tracker.ref = GuidedReference(ref, (Segment(30, 60, (0.05, -0.03), (0.02, 0.0)),), 5)
    tracker.run(60)
    assert not np.array_equal(np.asarray(tracker.rec["qpos"][40]), straight.qpos[40])  # it did go elsewhere
    tracker.restore(snap)
    tracker.ref = ref
    tracker.run(ref.frames)
    branched = tracker.rollout()
    for key in ("qpos", "qvel", "action", "torque", "foot_force", "penetration", "support", "landing_shift"):
        np.testing.assert_array_equal(getattr(branched, key), getattr(straight, key), err_msg=key)
    np.testing.assert_array_equal(branched.final_qpos, straight.final_qpos)


def test_the_guided_reference_fades_its_offsets_in_and_out():
    w, dw = fade(40, 10, 20, 4)
    assert w[:10].max() == 0.0 and np.allclose(w[14:20], 1.0) and w[24:].max() == 0.0
    assert 0.0 < w[12] < 1.0 and dw[12] > 0 and dw[22] < 0
    _, ref, _ = stand_problem(40)
    guided = GuidedReference(ref, (Segment(10, 20, (0.1, 0.0), (0.0, 0.05)),), 4)
    assert guided.frames == ref.frames and guided.qpos is ref.qpos  # everything else is the reference's
    a, b = ref.target(16), guided.target(16)
    np.testing.assert_allclose(b.com - a.com, [0.1, 0.0, 0.0])
    np.testing.assert_array_equal(b.foot_pos, a.foot_pos)  # both feet in stance: no swing to move
    np.testing.assert_array_equal(guided.target(30).com, ref.target(30).com)


def test_nothing_is_searched_where_nothing_fell():
    scene, ref, (q0, v0) = stand_problem(40)
    nominal = simulate(scene, ref, _controller(scene), q0, v0)
    assert nominal.fell_at is None and drift_onset(ref, nominal.qpos, nominal.fell_at) == nominal.frames
    assert search(scene, ref, lambda: _controller(scene), q0, v0, nominal) is None


def test_the_search_skips_what_the_teacher_walks_unaided():
    """A beam whose best stands clean: with a continuation that stands to the end the search is done; with one that a
    shove at frame 100 topples, it resumes ``start_before`` frames before that continuation's drift onset, from the
    best elite advanced there alone (the shove is a test's ``perturb``: the search itself never pushes)."""
    scene, ref, (q0, v0) = stand_problem(160)
    scorer = Scorer.of(scene, ref)
    for shove, done in ((0.0, True), (400.0, False)):

        def perturb(t, d, shove=shove):
            d.xfrc_applied[1, :3] = [shove, 0.0, 0.0] if 100 <= t < 110 else 0.0

        tracker = Tracker(scene, ref, _controller(scene), q0, v0, perturb=perturb)
        tracker.run(40)
        best = Elite(tracker.snapshot(), (), 0.0)
        beam, s, next_check = _skip_ahead(tracker, ref, [best], scorer, 5, 25, ref.frames)
        if done:
            assert (s, next_check) == (ref.frames, ref.frames) and beam == [best]
            continue
        shoved = simulate(scene, ref, _controller(scene), q0, v0, perturb=perturb)
        onset = drift_onset(ref, shoved.qpos[40:], shoved.fell_at, since=40)
        assert shoved.fell_at is not None and 100 <= onset < shoved.fell_at
        assert (s, next_check) == (onset - 25, onset) and beam[0].snapshot.t == s and beam[0].segments == ()
    assert frame_budget(SearchConfig(children_per_s=10.0), 100, 50) == 20 * 50  # 2 s: 20 children of 25 + 25 frames


def test_bad_search_settings_are_one_line_errors():
    with pytest.raises(ValueError, match=r"SearchConfig.children: must be >= 1, got 0"):
        SearchConfig(children=0)
    with pytest.raises(ValueError, match=r"SearchConfig.segment_s: must be > 0"):
        SearchConfig(segment_s=0.0)
    with pytest.raises(InputError, match=r"--search-budget: must be >= 0 children per second of motion"):
        search_config(-1.0)
    with pytest.raises(InputError, match=r"--search-budget"):
        search_config(float("nan"))
    assert search_config(0.0) is None and search_config(None) == SearchConfig()
    assert search_config(50.0).children_per_s == 50.0


@needs_shared
def test_a_search_turns_a_falling_take_into_a_standing_one_the_same_for_a_seed():
    """``interact/sub8_largebox_000``'s walk, the robot alone: the teacher falls at 3.44 s under every gain set; the
    search from its drift onset makes it valid (the pelvis within its bar to the end), and the same seed gives the
    same segments and the same rollout."""
    from pipeline.readers import read_clips
    from retarget.clip import retarget_clip

    clip = robot_alone(retarget_clip(read_clips(SHARED_MOCAP / "interact" / "sub8_largebox_000.pt")[0])[0])
    _, unsearched, before, _ = physicalize_clip(clip, search=None)
    assert before["failure"] == "fell before contact" and unsearched.fell_at is not None
    _, roll, figures, _ = physicalize_clip(clip)
    assert figures["valid"] and roll.fell_at is None and roll.frames > unsearched.frames
    found = figures["search"]
    assert found["failure_before"] == "fell before contact" and found["failure_after"] is None
    assert found["segments"] and found["children"] > 0 and found["cpu_s"] > 0
    assert found["start_s"] < before["fell_at_s"]
    _, again, figures_again, _ = physicalize_clip(clip)
    np.testing.assert_array_equal(again.qpos, roll.qpos)
    assert figures_again["search"]["segments"] == found["segments"]
