"""The search with the object guidance annealed to none (physicalize/search/anneal.py), on a real MuJoCo scene with the
real QP teacher: a G1 shoved at its start beside a free box, searched level by level (1.0, 0.3, then none)."""

import numpy as np
import pytest
from bench_scripts import load
from standing import standing_qpos

from physicalize.problem import tracking_problem
from physicalize.rollout import initial_state, simulate
from physicalize.search import anneal, beam
from physicalize.search.beam import SearchConfig
from physicalize.wbc import WholeBodyController
from pipeline.clip import ObjectTrack, RobotClip
from pipeline.geometry import Primitive

# a smoke-scale budget (one beam step per level), annealed at the measured levels
SMALL = SearchConfig(children=4, beam=2, children_per_s=20.0, guidance=anneal.LEVELS)


def _shoved_beside_a_box(frames: int = 100):
    """``(scene, ref, objects, qpos0, qvel0, make_controller)``: the G1 standing, a free box still 0.8 m ahead on its
    track, the robot shoved sideways at 0.6 m/s at frame 0 (the teacher falls at 0.92 s)."""
    box = np.zeros((frames, 7))
    box[:, 0], box[:, 2], box[:, 3] = 0.8, 0.15, 1.0
    track = ObjectTrack("box", Primitive("box", (0.15, 0.15, 0.15)), box, None, 1.0, "hand-made")
    clip = RobotClip(standing_qpos(frames), 50, "hand-made:stand", objects=(track,), task="stand")
    scene, ref, objects, _ = tracking_problem(clip)
    q0, v0 = initial_state(scene, ref, objects)
    v0 = v0.copy()
    v0[1] = 0.6
    return scene, ref, objects, q0, v0, lambda: WholeBodyController(scene.model, scene.profile)


def test_every_level_searches_on_the_levels_before_and_only_the_unguided_one_makes_the_rollout():
    scene, ref, objects, q0, v0, make = _shoved_beside_a_box()
    nominal = simulate(scene, ref, make(), q0, v0)
    assert nominal.fell_at is not None
    found, levels = anneal.search(scene, ref, make, q0, v0, nominal, SMALL, objects=objects)
    assert [level.scale for level in levels] == [1.0, 0.3, 0.0]
    assert all(level.segments > 0 and level.frames > 0 for level in levels)
    assert len(found.segments) == sum(level.segments for level in levels)
    assert found.frames == sum(level.frames for level in levels)
    assert found.rollout.external_force.max() == 0.0  # the data pass: no wrench on anything
    line = load("bench_physicalize_real").level_line([level.as_dict() for level in levels])
    assert line.startswith("1: fell 0.92 s -> ") and ", 0.3: " in line and ", 0: " in line
    # the first level's segments are under every later one: its search starts from them
    first, _ = anneal.search(
        scene, ref, make, q0, v0, nominal, SearchConfig(**{**SMALL.__dict__, "guidance": (1.0,)}), objects=objects
    )
    assert found.segments[: levels[0].segments] == first.segments[: levels[0].segments]
    again, _ = anneal.search(scene, ref, make, q0, v0, nominal, SMALL, objects=objects)
    assert again.segments == found.segments
    np.testing.assert_array_equal(again.rollout.qpos, found.rollout.qpos)


def test_without_levels_it_is_the_plain_search():
    """No guidance (the stage's default), or a clip with no free object: the beam search as it is, no level."""
    scene, ref, objects, q0, v0, make = _shoved_beside_a_box(60)
    nominal = simulate(scene, ref, make(), q0, v0)
    for config, objs in ((SearchConfig(**{**SMALL.__dict__, "guidance": ()}), objects), (SMALL, {})):
        found, levels = anneal.search(scene, ref, make, q0, v0, nominal, config, objects=objs)
        plain = beam.search(scene, ref, make, q0, v0, nominal, config, objects=objs)
        assert levels == [] and found.segments == plain.segments


def test_bad_guidance_levels_are_one_line_errors():
    with pytest.raises(ValueError, match=r"SearchConfig.guidance: scales > 0 .* got \(1.0, 0.0\)"):
        SearchConfig(guidance=(1.0, 0.0))
    with pytest.raises(ValueError, match=r"leave the unguided level some budget, got \(1.0, 0.5, 0.3\)"):
        SearchConfig(guidance=(1.0, 0.5, 0.3), guided_share=0.4)
    assert SearchConfig().guidance == () and anneal.LEVELS == (1.0, 0.3)
