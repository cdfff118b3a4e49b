"""The search's children in worker processes (physicalize/search/children.py): a tracker restored from another
tracker's snapshot continues as that one does, and a search gives the same segments, rollout and budget with two
workers as in one process (real MuJoCo, the real QP teacher)."""

import numpy as np
import pytest
from standing import stand_problem

from physicalize.rollout import Tracker, simulate
from physicalize.search.beam import SearchConfig, search
from physicalize.search.children import Children
from physicalize.stage import search_workers
from physicalize.wbc import WholeBodyController


def _shove(t, d):
    d.xfrc_applied[1, :3] = [400.0, 0.0, 0.0] if 40 <= t < 50 else 0.0


def test_a_tracker_restored_from_another_trackers_snapshot_continues_as_that_one():
    """A fresh tracker restored to another's frame 30 records frames 30-60 exactly as the other does; the frames
    before the restore it never recorded are None (nothing it reads after the restore)."""
    scene, ref, (q0, v0) = stand_problem(60)
    first = Tracker(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0)
    first.run(30)
    snap = first.snapshot()
    first.run(60)
    second = Tracker(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0)
    second.restore(snap)
    assert second.t == 30 and len(second.rec["qpos"]) == 30 and second.rec["qpos"][0] is None
    second.run(60)
    for key in ("qpos", "action", "torque", "support"):
        np.testing.assert_array_equal(np.asarray(second.rec[key][30:]), np.asarray(first.rec[key][30:]), err_msg=key)


def test_the_search_is_the_same_in_worker_processes_as_here():
    """From a shoved nominal rollout's drift onset, the search with its children in two forked workers picks the
    same segments, re-simulates the same rollout and spends the same frames as in one process; the workers'
    CPU-seconds are counted."""
    scene, ref, (q0, v0) = stand_problem(120)
    nominal = simulate(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0, perturb=_shove)
    assert nominal.fell_at is not None

    def make():
        return WholeBodyController(scene.model, scene.profile)

    config = SearchConfig(children=4, beam=2, start_before_s=0.2, children_per_s=20.0)
    here = search(scene, ref, make, q0, v0, nominal, config)
    there = search(scene, ref, make, q0, v0, nominal, config, workers=2)
    assert here.children > 0 and here.worker_cpu_s == 0.0 and there.worker_cpu_s > 0.0
    assert there.segments == here.segments and (there.children, there.frames) == (here.children, here.frames)
    np.testing.assert_array_equal(there.rollout.qpos, here.rollout.qpos)


def test_workers_follow_the_idle_jobs_and_bad_counts_are_one_line_errors():
    assert [search_workers(8, n) for n in (1, 3, 8, 20)] == [8, 2, 1, 1]
    assert search_workers(8, 1, "ray") == 1
    scene, ref, (q0, v0) = stand_problem(10)
    tracker = Tracker(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0)
    with pytest.raises(ValueError, match=r"search workers: must be >= 1, got 0"):
        Children(tracker, None, 5, 25, workers=0)
