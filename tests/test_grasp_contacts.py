"""Object contacts other than a two-hand lift (physicalize.grasp + the whole-body QP), real MuJoCo physics.

The G1 stands in double support next to a free box resting on a fixed pedestal:

* **hands kept off**: the reference moves the left hand 1 cm *into* the box's side while the clip
  labels no hand contact (a retargeted wrist brushing a chair). The schedule keeps that hand
  ``clearance`` off the box: the box stays put; tracked without the schedule it is shoved away.
* **a two-hand push**: both hands behind the box (inward normals +x, the same direction: no squeeze)
  push it 12 cm along the pedestal. The planned force is the box's sliding friction plus ``m a``;
  the hand targets move with the box's reference track.
* **a grip on one line**: reference hands at different heights on opposite sides get targets on one
  line along the grip normal, over the box's centre of mass (no squeeze couple turns the box).
"""

import mujoco
import numpy as np
import pytest
from test_grasp import _arm_ik, _smooth, _track_box

from physicalize.grasp import GraspConfig, grasp_schedule
from physicalize.hand_reach import hand_offsets
from physicalize.reference import build_reference, place_on_floor
from pipeline.geometry import ObjectPhysics, Primitive
from pipeline.robot import HAND_BODIES, default_qpos
from pipeline.scene import SceneObject, build_scene

HALF = (0.08, 0.12, 0.08)
POS = np.array([0.32, 0.0, 0.66])
LINKS = ("pelvis",) + HAND_BODIES
PUSH = 0.12
MU = 0.3
END = 200


def _scene(mass: float = 1.0):
    top = POS[2] - HALF[2]
    pedestal = SceneObject(
        "pedestal",
        Primitive("box", (0.25, 0.25, top / 2)),
        ObjectPhysics(friction=MU),
        pose=(POS[0] + 0.1, 0.0, top / 2, 1, 0, 0, 0),
        fixed=True,
    )
    physics = ObjectPhysics(mass=mass, friction=MU, floor_friction=MU)  # the planner takes its support as the floor
    box = SceneObject("box", Primitive("box", HALF), physics, pose=(*POS, 1, 0, 0, 0))
    return build_scene([box, pedestal])


@pytest.fixture(scope="module")
def scene():
    return _scene()


def _brush_clip(scene):
    """The left hand from 6 cm beside the box's +y side to 1 cm into it (frames 10-60), held; the right hand away."""
    m = scene.model
    q0 = place_on_floor(m, default_qpos(scene.profile)[None])[0]
    side = HALF[1] + 0.035
    right = POS + [0, -side - 0.15, 0]
    far = _arm_ik(m, q0, np.array([POS + [0, side + 0.06, 0], right]))
    into = _arm_ik(m, q0, np.array([POS + [0, side - 0.01, 0], right]))
    t = np.arange(END)
    s1, s2 = _smooth(t, 10, 40), _smooth(t, 40, 60)
    qpos = q0 + s1[:, None] * (far - q0) + s2[:, None] * (into - far)
    return qpos, np.tile(np.r_[POS, 1.0, 0, 0, 0], (END, 1)), np.zeros((END, 3), bool)


def test_an_unlabelled_hand_is_kept_off_the_box(scene):
    qpos, box, contacts = _brush_clip(scene)
    cfg = GraspConfig()
    roll, sim, g = _track_box(scene, qpos, box, contacts, cfg)
    assert roll.fell_at is None and not g.grasped.any() and g.clear[70:, 0].all()
    assert np.abs(sim[:, :3] - POS).max() < 0.005  # the box stays where it rests
    assert not roll.contact[:, 1].any()  # the left hand never touches it
    roll0, sim0, _ = _track_box(scene, qpos, box, contacts, None)
    assert roll0.fell_at is None and np.abs(sim0[-1, 1] - POS[1]) > 0.01  # tracked as is, the hand shoves the box


def _push_clip(scene):
    """Both hands behind the box (-x side): reach (frames 10-50), close to 1 cm (50-70), push it +12 cm (90-150),
    hold."""
    m = scene.model
    q0 = place_on_floor(m, default_qpos(scene.profile)[None])[0]
    off = HALF[0] + 0.035 + 0.11  # the hand point sits 11 cm behind the hand's front (its offset), pointing forward
    key = {}
    for name, gap, dx in (("reach", 0.06, 0.0), ("close", 0.01, 0.0), ("push", 0.01, PUSH)):
        x = POS[0] - off - gap + dx
        key[name] = _arm_ik(m, q0, np.array([[x, 0.07, POS[2]], [x, -0.07, POS[2]]]))
    t = np.arange(END)
    s1, s2, s3 = _smooth(t, 10, 50), _smooth(t, 50, 70), _smooth(t, 90, 150)
    qpos = (
        q0
        + s1[:, None] * (key["reach"] - q0)
        + s2[:, None] * (key["close"] - key["reach"])
        + s3[:, None] * (key["push"] - key["close"])
    )
    box = np.tile(np.r_[POS, 1.0, 0, 0, 0], (END, 1))
    box[:, 0] += PUSH * s3
    contacts = np.zeros((END, 3), bool)
    contacts[65:, 1:] = True
    return qpos, box, contacts


def test_two_hands_push_a_box_along_its_support(scene):
    qpos, box, contacts = _push_clip(scene)
    ref = build_reference(scene.model, qpos, 50)
    g = grasp_schedule(scene, ref, LINKS, contacts, {"box": box})
    assert g.grasped[80:].all() and (g.normal[120, :, 0] > 0.9).all()  # both inward normals +x: a push, not a squeeze
    # while it slides (reference speed above slide_speed) the hands carry its sliding friction plus m a
    t = 120
    v = (box[t + 1, 0] - box[t - 1, 0]) * 25
    assert v > GraspConfig().slide_speed
    a = (box[t + 1, 0] - 2 * box[t, 0] + box[t - 1, 0]) * 2500
    assert g.force[t, :, 0].sum() == pytest.approx(MU * 1.0 * 9.81 + 1.0 * a, rel=0.02)
    roll, sim, _ = _track_box(scene, qpos, box, contacts)
    assert roll.fell_at is None and roll.external_force.max() == 0.0
    assert sim[-1, 0] - POS[0] > PUSH - 0.03  # pushed along
    assert np.linalg.norm(sim[:, :3] - box[:, :3], axis=1).max() < 0.04
    roll0, sim0, _ = _track_box(scene, qpos, box, contacts, None)
    assert sim0[-1, 0] - POS[0] < 0.5 * PUSH  # without the schedule the hands, 1 cm behind it, leave it behind


def test_a_two_hand_grip_lies_on_one_line_over_the_centre_of_mass(scene):
    m = scene.model
    q0 = place_on_floor(m, default_qpos(scene.profile)[None])[0]
    side = HALF[1] + 0.035 + 0.01
    grip = _arm_ik(m, q0, np.array([POS + [0.03, side, 0.04], POS + [-0.02, -side, -0.03]]))  # uneven hands
    qpos = np.repeat(grip[None], 40, 0)
    box = np.tile(np.r_[POS, 1.0, 0, 0, 0], (40, 1))
    cfg = GraspConfig()
    g = grasp_schedule(scene, build_reference(m, qpos, 50), LINKS, np.ones((40, 3), bool), {"box": box}, cfg)
    t = 30
    d = mujoco.MjData(m)
    d.qpos[:36] = qpos[t]
    mujoco.mj_kinematics(m, d)
    centre = np.array(
        [
            d.xpos[m.body(b).id] + d.xmat[m.body(b).id].reshape(3, 3) @ hand_offsets(m)[k]
            for k, b in enumerate(HAND_BODIES)
        ]
    )
    assert abs(centre[0, 2] - centre[1, 2]) > 0.04  # the reference hands are ~5 cm apart in height
    p = g.attached[t]
    n = g.normal[t, 0]
    axis = POS + [0, 0, cfg.grip_above]
    for k in range(2):  # each target on the line through the point grip_above over the centre of mass along the normal
        r = p[k] - axis
        assert np.linalg.norm(r - (r @ n) * n) < 1e-6
    assert g.friction_ok.all() and np.allclose(g.force[t].sum(axis=0), 0.0, atol=1e-6)  # resting: squeezes cancel
