"""The held object inside the whole-body QP (physicalize.object_loop, physicalize.object_motion), real MuJoCo
physics: the reference motion's kinematics and contact modes, the block's Newton-Euler rows against the
simulation's own dynamics, and the loop closed on a lifted and on a shoved object."""

import mujoco
import numpy as np
import pytest
from qpsolvers import solve_qp

from ingest.synthetic import default_clips
from physicalize.object_loop import HeldObject, LoopGains, ObjectLoop
from physicalize.object_motion import LIFT, ObjectMotion
from physicalize.problem import tracking_problem
from physicalize.rollout import initial_state, simulate
from physicalize.start import clean_start
from physicalize.wbc import GRIP_LINKS, WholeBodyController
from physicalize.wbc_config import WBCConfig
from pipeline.geometry import ObjectPhysics, Primitive
from pipeline.rotations import quat_mat, yaw_quat
from pipeline.scene import SceneObject, build_scene, link_collision_geoms
from retarget.clip import retarget_clip

HALF = (0.15, 0.10, 0.08)
MASS = 2.0
FPS = 50.0


def _track(T: int, z: np.ndarray, x: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    pose = np.zeros((T, 7))
    pose[:, 0], pose[:, 1], pose[:, 2] = x, 0.5, z
    pose[:, 3:] = [yaw_quat(a) for a in yaw]
    return pose


def test_motion_turns_lifts_and_slides_as_its_track():
    T = 100
    t = np.arange(T) / FPS
    yaw = 0.8 * t  # 0.8 rad/s about the vertical
    z = np.where(t < 1.0, 0.08, 0.08 + 0.3 * (t - 1.0))  # rests 1 s, then rises at 0.3 m/s
    x = np.where(t < 0.5, 1.0, 1.0 + 0.2 * (t - 0.5))  # still 0.5 s, then slides at 0.2 m/s
    ipos = np.array([0.05, 0.0, 0.0])  # the centre of mass off the body origin
    mo = ObjectMotion.of(_track(T, z, x, yaw), ipos, FPS)
    assert np.allclose(mo.omega[1:-1], [0.0, 0.0, 0.8], atol=1e-6) and np.abs(mo.alpha[2:-2]).max() < 1e-6
    assert np.allclose(mo.com[10], _track(T, z, x, yaw)[10, :3] + quat_mat(yaw_quat(yaw[10])) @ ipos)
    lifted = mo.com[:, 2] - mo.com[:, 2].min() >= LIFT
    assert mo.rests[:49].all() and not mo.rests[lifted].any() and not mo.rests[55:].any()  # rising: carried
    still = ObjectMotion.of(_track(T, z, x, np.zeros(T)), ipos, FPS)  # (turning, that centre of mass moves too)
    assert not still.slides[:20].any() and still.slides[30:49].all()


def _box_scene():
    box = SceneObject("box", Primitive("box", HALF), ObjectPhysics(mass=MASS, friction=0.8, floor_friction=0.4))
    return build_scene([box])


def _held(scene, pose: np.ndarray, hands=(False, False)) -> HeldObject:
    T = len(pose)
    mo = ObjectMotion.of(pose, scene.model.body_ipos[scene.object_body_id["box"]], FPS)
    return HeldObject(scene.object_body_id["box"], np.array(hands), mo, T // 2, 0.8, 0.4)


def _loop(scene, qpos_box: np.ndarray, qvel_box: np.ndarray, pose: np.ndarray) -> tuple[ObjectLoop, mujoco.MjData]:
    m = scene.model
    d = mujoco.MjData(m)
    adr = scene.object_qpos_adr["box"]
    d.qpos[adr : adr + 7] = qpos_box
    d.qvel[m.jnt_dofadr[m.body_jntadr[scene.object_body_id["box"]]] :][:6] = qvel_box
    mujoco.mj_forward(m, d)
    grip = [{g for link in GRIP_LINKS for g in link_collision_geoms(m, f"{s}_{link}")} for s in ("left", "right")]
    return ObjectLoop.measure(m, d, _held(scene, pose), grip, m.geom("floor").id), d


def _solve_block(loop: ObjectLoop, g: LoopGains = LoopGains()) -> np.ndarray:
    """The block alone as a QP (its rows and tasks, the same regularization as the controller's)."""
    n = loop.nf
    A, b, G, h = loop.rows(0, n, g)
    P, q = 1e-5 * np.eye(n), np.zeros(n)
    for Ao, bo, wo in loop.tasks(0, n, g):
        P += Ao.T @ (wo[:, None] * Ao)
        q -= Ao.T @ (wo * bo)
    return solve_qp(P, q, G if len(G) else None, h if len(h) else None, A, b, solver="daqp")


def test_a_free_spinning_box_accelerates_as_the_simulation_says():
    """No contact: the rows leave one solution, ``c_dd = g`` and Euler's ``I w_dot = -w x I w``, which is what MuJoCo
    integrates for the same state (its free-body acceleration ``qacc``)."""
    scene = _box_scene()
    pose = _track(40, np.full(40, 1.0), np.ones(40), np.zeros(40))
    q = np.r_[1.0, 0.5, 1.0, yaw_quat(0.3)]
    w_body = np.array([3.0, -1.0, 2.0])  # a free joint's angular velocity is in the body frame
    loop, d = _loop(scene, q, np.r_[0.2, 0.0, 0.0, w_body], pose)
    assert not loop.grips and not loop.support and loop.nf == 6
    x = _solve_block(loop)
    mujoco.mj_forward(scene.model, d)
    R = quat_mat(q[3:])
    m = scene.model
    dof = m.jnt_dofadr[m.body_jntadr[scene.object_body_id["box"]]]
    assert np.allclose(x[:3], [0.0, 0.0, -9.81], atol=1e-6)
    assert np.allclose(x[3:], R @ d.qacc[dof + 3 : dof + 6], atol=1e-4)  # MuJoCo's body-frame angular acceleration


def test_a_resting_box_is_carried_by_its_support_and_slides_with_kinetic_friction():
    """Resting on the floor: the support points carry its weight (the QP's ``a_o`` is 0). Sliding at 0.3 m/s: the
    support's friction is ``mu_s m g`` against the motion, so holding the reference speed needs the hands, and
    without them the QP's object decelerates at ``mu_s g``."""
    scene = _box_scene()
    T = 40
    still = _track(T, np.full(T, HALF[2]), np.ones(T), np.zeros(T))
    loop, _ = _loop(scene, still[0], np.zeros(6), still)
    assert len(loop.support) >= 4 and loop.sliding is None
    x = _solve_block(loop)
    forces = x[: 3 * len(loop.support)].reshape(-1, 3)
    assert np.allclose(forces.sum(axis=0), [0.0, 0.0, MASS * 9.81], atol=1e-3) and np.abs(x[-6:]).max() < 1e-3
    slide = _track(T, np.full(T, HALF[2]), 1.0 + 0.3 * np.arange(T) / FPS, np.zeros(T))
    loop, _ = _loop(scene, slide[T // 2], np.r_[0.3, 0.0, 0.0, 0.0, 0.0, 0.0], slide)
    assert loop.sliding is not None and np.allclose(loop.sliding, [1.0, 0.0, 0.0])
    x = _solve_block(loop)
    assert x[-6] == pytest.approx(-0.4 * 9.81, rel=0.05)  # mu_s g of deceleration, whatever the task wants


@pytest.mark.slow
def test_a_shoved_pushed_box_keeps_the_loop_on_its_feet_where_the_open_loop_falls():
    """The default Push, its box shoved sideways (30 N for 0.3 s mid-push, a test's ``xfrc_applied``). The open
    loop keeps pressing with the force planned for a box where the reference has it and falls (measured: at 5.8 s
    of 8.3); the loop's forces come from the measured box, so the robot pushes on to the end with the box within
    0.1 m of its track (measured: 5 cm)."""
    human = next(c for c in default_clips() if c.task == "Push")
    robot = clean_start(retarget_clip(human)[0])
    scene, ref, objects, _ = tracking_problem(robot)
    box = robot.objects[0]
    body, adr = scene.object_body_id[box.name], scene.object_qpos_adr[box.name]

    def shove(t, d):
        d.xfrc_applied[body] = 0.0
        if 200 <= t < 215:
            d.xfrc_applied[body, 1] = 30.0

    out = {}
    for name, loop in (("open", None), ("loop", LoopGains())):
        ctrl = WholeBodyController(scene.model, scene.profile, WBCConfig(object_loop=loop))
        roll = simulate(scene, ref, ctrl, *initial_state(scene, ref, objects), perturb=shove)
        err = np.linalg.norm(roll.qpos[:, adr : adr + 3] - box.pose[: roll.frames, :3], axis=1)
        out[name] = roll, err
    assert out["open"][0].fell_at is not None
    roll, err = out["loop"]
    assert roll.fell_at is None and roll.frames == ref.frames and err.max() < 0.1
