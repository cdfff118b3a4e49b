"""The depth camera on mjlab (train.envs.mjlab.camera) against the CPU one (train.vision.camera): the MuJoCo camera
has our mount and intrinsics, the depth read is mapped like ours, and one state of the G1 (arms forward, turned)
with a box in front gives the same image pixel for pixel through MuJoCo Warp's renderer (run on the CPU here)."""

import math
from dataclasses import replace
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest
import torch

from pipeline.errors import InputError
from pipeline.geometry import Primitive
from pipeline.robot import G1_JOINT_NAMES, actuator_profile, default_qpos
from pipeline.scene import SceneObject, build_spec, object_spec
from train.vision.camera import DepthCamera

pytest.importorskip("mjlab")
from mjlab.entity import EntityCfg  # noqa: E402
from mjlab.scene import Scene, SceneCfg  # noqa: E402

from train.envs.mjlab.camera import depth_sensor_cfg, read_depth  # noqa: E402

CAMERA = DepthCamera()
YAW = math.radians(30.0)
BOX = SceneObject(
    "box",
    Primitive("box", (0.25, 0.3, 0.25)),
    pose=(0.3 + 0.9 * math.cos(YAW), -0.2 + 0.9 * math.sin(YAW), 0.25, math.cos(0.2), 0.0, 0.0, math.sin(0.2)),
)


def _qpos() -> np.ndarray:
    """The G1 standing at (0.3, -0.2) turned 30 degrees left, arms forward into the view; the box 0.9 m ahead."""
    q = default_qpos(actuator_profile("mjlab"))
    q[:2], q[3:7] = (0.3, -0.2), (math.cos(YAW / 2), 0.0, 0.0, math.sin(YAW / 2))
    for side in ("left", "right"):
        q[7 + G1_JOINT_NAMES.index(f"{side}_shoulder_pitch_joint")] = -0.6
        q[7 + G1_JOINT_NAMES.index(f"{side}_elbow_joint")] = 0.3
    return np.concatenate([q, BOX.pose])


def _robot_spec() -> mujoco.MjSpec:
    """The G1 of :func:`pipeline.scene.build_spec` with MuJoCo's default options (mjlab keeps the scene's and warns
    about an entity's, as :mod:`train.envs.mjlab.env` does)."""
    spec, default = build_spec((), actuator_profile("mjlab")), mujoco.MjSpec().option
    for name in ("timestep", "integrator", "cone", "impratio"):
        setattr(spec.option, name, getattr(default, name))
    return spec


def _scene(num_envs: int = 1) -> Scene:
    entities = {
        "robot": EntityCfg(spec_fn=_robot_spec),
        "object": EntityCfg(spec_fn=lambda: object_spec(BOX)),
    }
    return Scene(SceneCfg(num_envs=num_envs, entities=entities, sensors=(depth_sensor_cfg(CAMERA),)), device="cpu")


def test_the_mujoco_camera_has_our_mount_and_intrinsics():
    """The camera mjlab adds, compiled by MuJoCo: at :meth:`DepthCamera.frame`'s pose (looking along -z, x right,
    y up), focal lengths ``DepthCamera.focal`` in pixels, ``fovy`` and the horizontal field of view ours."""
    m = _scene().spec.compile()
    d = mujoco.MjData(m)
    d.qpos[:] = _qpos()
    mujoco.mj_forward(m, d)
    origin, C = replace(CAMERA, body="robot/torso_link").frame(m, d)
    cam = m.camera("depth_camera").id
    R = d.cam("depth_camera").xmat.reshape(3, 3)
    np.testing.assert_allclose(d.cam("depth_camera").xpos, origin, atol=1e-9)
    np.testing.assert_allclose(R[:, 2], -C[:, 0], atol=1e-9)  # the optical axis
    np.testing.assert_allclose(R[:, 0], -C[:, 1], atol=1e-9)  # image right
    np.testing.assert_allclose(R[:, 1], C[:, 2], atol=1e-9)  # image up
    assert tuple(m.cam_resolution[cam]) == (CAMERA.width, CAMERA.height)
    fx, fy, cx, cy = m.cam_intrinsic[cam]
    sw, sh = m.cam_sensorsize[cam]
    np.testing.assert_allclose([fx / sw * CAMERA.width, fy / sh * CAMERA.height], CAMERA.focal, rtol=1e-6)
    assert (cx, cy) == (0.0, 0.0)
    assert abs(m.cam_fovy[cam] - CAMERA.fov_y_deg) < 1e-5
    assert abs(2 * math.degrees(math.atan(sw / 2 / fx)) - CAMERA.fov_x_deg) < 1e-5


def test_depth_is_mapped_like_ours_and_a_mismatched_sensor_is_a_one_line_error():
    """MuJoCo Warp's 0 (no hit) reads far; depths are clipped to [near, far]; a sensor of another size, or one
    without depth, is a one-line error."""
    cfg = depth_sensor_cfg(CAMERA)
    raw = torch.full((2, CAMERA.height, CAMERA.width, 1), 1.5)
    raw[0, 0, 0], raw[0, 0, 1], raw[1, 5, 5] = 0.0, 0.05, 7.0
    got = read_depth(SimpleNamespace(cfg=cfg, data=SimpleNamespace(depth=raw)), CAMERA)
    assert got.shape == (2, CAMERA.height, CAMERA.width) and got.dtype == torch.float32
    assert got[0, 0, 0] == CAMERA.far and got[0, 0, 1] == CAMERA.near and got[1, 5, 5] == CAMERA.far
    assert got[0, 1, 1] == 1.5
    small = replace(cfg, width=32)
    with pytest.raises(InputError, match="width: sensor 'depth_camera' is 32 x 40 pixels") as e:
        read_depth(SimpleNamespace(cfg=small, data=SimpleNamespace(depth=raw)), CAMERA)
    assert "\n" not in str(e.value)
    with pytest.raises(InputError, match="data_types: sensor 'depth_camera' renders no depth"):
        read_depth(SimpleNamespace(cfg=cfg, data=SimpleNamespace(depth=None)), CAMERA)


def _kinds(m: mujoco.MjModel, d: mujoco.MjData, camera: DepthCamera) -> np.ndarray:
    """(H, W) what each pixel's ray hits first (``mj_multiRay`` through the camera's groups): 'floor', 'box',
    'robot', or 'background' (nothing, or something at ``far`` or beyond)."""
    origin, C = camera.frame(m, d)
    rays = (camera.rays().reshape(-1, 3) @ C.T).reshape(-1)
    n = camera.width * camera.height
    geom, dist = np.zeros(n, dtype=np.int32), np.zeros(n)
    groups = np.isin(np.arange(mujoco.mjNGROUP), camera.geom_groups).astype(np.uint8)
    mujoco.mj_multiRay(m, d, origin, rays, groups, 1, -1, geom, dist, None, n, camera.far)
    depth = dist * camera.rays().reshape(-1, 3)[:, 0]

    def kind(g: int, z: float) -> str:
        if g < 0 or z >= camera.far:
            return "background"
        name = m.geom(g).name
        return "floor" if name.endswith("floor") else "box" if name.startswith("object/") else "robot"

    kinds = [kind(g, z) for g, z in zip(geom, depth)]
    return np.array(kinds).reshape(camera.height, camera.width)


@pytest.mark.slow
def test_mjlab_renders_the_image_the_cpu_camera_renders():
    """1 world, 1 image of floor, box, the G1's arms and background: MuJoCo Warp's depth (read through
    :func:`read_depth`) and :meth:`DepthCamera.render`'s of the same model and state agree to a micrometre (the same
    rays). Asked: median |diff| < 5 mm, >= 95 % of pixels within 1 cm. Measured: max |diff| 2.5e-6 m, median
    1.2e-7 m; background 5 %, floor 61 %, box 14 %, arms 20 % of the pixels."""
    wp = pytest.importorskip("warp")
    from mjlab.sim import Simulation, SimulationCfg

    try:
        wp.init()
        wp.get_device("cpu")
    except Exception as e:  # warp cannot run here at all
        pytest.skip(f"warp cannot run on this machine's CPU: {e}")
    scene = _scene()
    sim = Simulation(num_envs=1, cfg=SimulationCfg(), spec=scene.spec, device="cpu")
    scene.initialize(mj_model=sim.mj_model, model=sim.model, data=sim.data)
    sim.set_sensor_context(scene.sensor_context)
    qpos = _qpos()
    sim.data.qpos[:] = torch.as_tensor(qpos, dtype=torch.float32)
    sim.forward()
    sim.sense()
    got = read_depth(scene["depth_camera"], CAMERA)
    assert got.shape == (1, CAMERA.height, CAMERA.width)

    m = sim.mj_model
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    ours = replace(CAMERA, body="robot/torso_link")
    want = ours.render(m, d)
    kinds = _kinds(m, d, ours)
    for kind in ("background", "floor", "box", "robot"):
        assert (kinds == kind).mean() > 0.02, kind  # each at least 2 % of the image
    diff = np.abs(got[0].numpy() - want)
    assert np.median(diff) < 5e-3 and (diff < 1e-2).mean() >= 0.95
    assert diff.max() < 1e-4  # in fact the same rays hit the same surfaces everywhere
