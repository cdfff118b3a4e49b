"""Rejection before tracking: whether pressing hands (and the floor) can give the force a held object needs,
on hand-made references of a 2 kg box in a real MuJoCo scene."""

import numpy as np
import pytest

from physicalize.feasibility import (
    REJECT_MIN_S,
    hold_feasibility,
    producible,
    reach_figures,
    rejection,
    rejection_reason,
)
from physicalize.grasp_force import cone_edges
from physicalize.reference import build_reference, place_on_floor
from physicalize.static_torque import static_torque_figures
from pipeline.geometry import ObjectPhysics, Primitive
from pipeline.robot import EFFORT_LIMIT, HAND_BODIES, actuator_profile, default_qpos
from pipeline.scene import SceneObject, build_scene
from pipeline.take import LIFT, SLIDE, SMALL_MOVE, take_kind

FPS = 50.0
T = 50
HALF = 0.15
MU = 0.8


@pytest.fixture(scope="module")
def scene():
    box = SceneObject(
        "box", Primitive("box", (HALF, HALF, HALF)), ObjectPhysics(mass=2.0), pose=(0.6, 0, HALF, 1, 0, 0, 0)
    )
    return build_scene([box])


def _track(start, velocity) -> np.ndarray:
    """(T, 7) box pose: from ``start`` at constant ``velocity`` (m/s), upright."""
    t = np.arange(T)[:, None] / FPS
    return np.column_stack([np.asarray(start) + t * np.asarray(velocity), np.tile([1.0, 0, 0, 0], (T, 1))])


def _figures(scene, track, normals) -> dict:
    """Figures of the box held along ``track`` by the hands whose inward normals are ``normals`` (None: that hand
    does not hold)."""
    body = scene.model.body("box").id
    grasped = np.array([[n is not None for n in normals]] * T)
    normal = np.array([[n if n is not None else (0, 0, 0) for n in normals]] * T, dtype=float)
    return hold_feasibility(scene.model, grasped, np.where(grasped, body, -1), normal, MU, track, FPS)


def test_cone_edges_lie_on_the_friction_cone():
    n = np.array([0.0, 0.6, 0.8])
    edges = cone_edges(n, MU)
    tangential = np.linalg.norm(edges - np.outer(edges @ n, n), axis=1)
    np.testing.assert_allclose(tangential / (edges @ n), MU)
    assert producible(30 * n, edges) and not producible(-30 * n, edges)


def test_a_two_handed_squeeze_lifts_the_box(scene):
    lift = _track((0.6, 0, 0.4), (0, 0, 0.2))  # in the air, rising
    f = _figures(scene, lift, [(1.0, 0, 0), (-1.0, 0, 0)])  # hands on opposite faces, normals into the box
    assert f["reference_hold_frames"] == T and f["reference_hold_infeasible_frac"] == 0.0 and rejection(f) is None


def test_one_hand_on_a_side_cannot_hold_the_box_up(scene):
    f = _figures(scene, _track((0.6, 0, 0.4), (0, 0, 0)), [(1.0, 0, 0), None])
    assert f["reference_hold_infeasible_frac"] == 1.0 and f["reference_hold_infeasible_from_s"] == 0.0
    assert rejection(f) == "needs a grip"


def test_pulling_along_the_floor_is_outside_the_cone_but_a_slide_is_never_rejected(scene):
    slide = _track((0.6, 0, HALF), (0.3, 0, 0))  # resting on the floor, sliding +x
    pulled = _figures(scene, slide, [(-1.0, 0, 0), None])  # a hand on the +x face, towards which it moves
    pushed = _figures(scene, slide, [(1.0, 0, 0), None])  # a hand on the -x face, behind it
    assert pulled["reference_hold_infeasible_frac"] > 0.9 and pushed["reference_hold_infeasible_frac"] == 0.0
    assert rejection(pulled) == "needs a grip" and rejection(pushed) is None  # a take of no known kind
    kind = take_kind(slide)
    assert kind.kind == SLIDE
    for kind_name in (SLIDE, SMALL_MOVE):  # the floor carries it: tracked, whatever the hands or motors
        assert rejection({**pulled, "take_kind": kind_name, "reference_static_torque_over_s": 5.0}) is None


def test_a_squeeze_is_never_rejected_needs_a_grip(scene):
    one_side = _figures(scene, _track((0.6, 0, 0.4), (0, 0, 0)), [(1.0, 0, 0), None])
    assert rejection({**one_side, "take_kind": LIFT}) == "needs a grip"
    # the human's wrists on opposite faces: the retargeted hands lost the squeeze, not the take
    assert rejection({**one_side, "take_kind": LIFT, "human_hand_opposition": -0.9}) is None
    # a G1 motion with no human: the reference grasp's own opposition decides
    assert rejection({**one_side, "human_hand_opposition": None, "reference_hand_opposition": -0.8}) is None
    assert rejection({**one_side, "human_hand_opposition": 0.9, "reference_hand_opposition": -0.8}) == "needs a grip"


def test_pressing_on_top_of_a_resting_box_is_carried_by_the_floor(scene):
    f = _figures(scene, _track((0.6, 0, HALF), (0, 0, 0)), [(0, 0, -1.0), (0, 0, -1.0)])
    assert f["reference_hold_infeasible_frac"] == 0.0


def test_a_brief_infeasible_touch_is_not_rejected():
    brief = {"reference_hold_infeasible_frac": 1.0, "reference_hold_infeasible_s": REJECT_MIN_S / 2}
    assert rejection(brief) is None
    assert rejection({**brief, "reference_hold_infeasible_s": REJECT_MIN_S}) == "needs a grip"


def _standing(scene, frames: int = T) -> np.ndarray:
    q = place_on_floor(scene.model, default_qpos(actuator_profile("mjlab"))[None])[0]
    return np.repeat(q[None], frames, 0)


def test_a_box_overhead_is_out_of_reach(scene):
    """Both hands labelled on a box 2.2 m up, the G1 standing: every labelled hand-frame is far from it."""
    qpos = _standing(scene)
    ref = build_reference(scene.model, qpos, FPS)
    labels = np.ones((T, 2), bool)
    high = reach_figures(scene, ref, HAND_BODIES, labels, {"box": _track((0.3, 0, 2.2), (0, 0, 0))})
    assert high["reference_hand_unreached_frac"] == 1.0 and high["reference_hand_unreached_s"] == T / FPS
    assert high["reference_hand_gap_m"] > 0.5
    f = {**high, "take_kind": "overhead"}
    assert rejection(f) == "out of reach" and "m (median) from the object" in rejection_reason(f, "out of reach")
    unlabelled = reach_figures(
        scene, ref, HAND_BODIES, np.zeros((T, 2), bool), {"box": _track((0.3, 0, 2.2), (0, 0, 0))}
    )
    assert unlabelled["reference_hand_unreached_frac"] == 0.0 and rejection({**unlabelled, "take_kind": LIFT}) is None


def test_a_hold_beyond_the_motors_is_over_torque(scene):
    """The standing G1 pushing 100 N forward with each hanging hand: its shoulders would need more than they give."""
    qpos = _standing(scene, 30)
    light = static_torque_figures(qpos, (np.zeros((2, 3)), np.zeros((30, 2, 3))), EFFORT_LIMIT, FPS)
    heavy = static_torque_figures(qpos, (np.zeros((2, 3)), np.tile([100.0, 0, 0], (30, 2, 1))), EFFORT_LIMIT, FPS)
    assert light["reference_static_torque_over_s"] == 0.0 and rejection({**light, "take_kind": LIFT}) is None
    assert heavy["reference_static_torque_ratio_max"] > 1.0 and heavy["reference_static_torque_over_s"] == 30 / FPS
    f = {**heavy, "take_kind": LIFT}
    assert rejection(f) == "over torque" and heavy["reference_static_torque_joint"] in rejection_reason(
        f, "over torque"
    )
