"""Rejection before tracking: whether pressing hands (and the floor) can give the force a held object needs,
on hand-made references of a 2 kg box in a real MuJoCo scene."""

import numpy as np
import pytest

from physicalize.feasibility import REJECT_MIN_S, cone_edges, hold_feasibility, producible, rejection
from pipeline.geometry import ObjectPhysics, Primitive
from pipeline.scene import SceneObject, build_scene

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


def test_pulling_along_the_floor_needs_a_grip_pushing_does_not(scene):
    slide = _track((0.6, 0, HALF), (0.3, 0, 0))  # resting on the floor, sliding +x
    pulled = _figures(scene, slide, [(-1.0, 0, 0), None])  # a hand on the +x face, towards which it moves
    pushed = _figures(scene, slide, [(1.0, 0, 0), None])  # a hand on the -x face, behind it
    assert rejection(pulled) == "needs a grip" and pulled["reference_hold_infeasible_frac"] > 0.9
    assert rejection(pushed) is None and pushed["reference_hold_infeasible_frac"] == 0.0


def test_pressing_on_top_of_a_resting_box_is_carried_by_the_floor(scene):
    f = _figures(scene, _track((0.6, 0, HALF), (0, 0, 0)), [(0, 0, -1.0), (0, 0, -1.0)])
    assert f["reference_hold_infeasible_frac"] == 0.0


def test_a_brief_infeasible_touch_is_not_rejected():
    brief = {"reference_hold_infeasible_frac": 1.0, "reference_hold_infeasible_s": REJECT_MIN_S / 2}
    assert rejection(brief) is None
    assert rejection({**brief, "reference_hold_infeasible_s": REJECT_MIN_S}) == "needs a grip"
