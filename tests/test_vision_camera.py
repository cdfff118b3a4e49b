"""The depth camera (train.vision.camera) on a real G1 scene: a wall facing the camera at a known distance reads it
to the millimetre at the centre and in the corner (z-depth, not ray length), the camera follows the torso, and bad
settings are one-line errors."""

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from pipeline.errors import InputError
from pipeline.geometry import Primitive
from pipeline.robot import actuator_profile
from pipeline.scene import SceneObject, build_scene
from train.vision.camera import DepthCamera

CAMERA = DepthCamera(width=33, height=21, geom_groups=(0,))  # odd sizes: a pixel on the axis; the robot unseen


def _scene(wall_pose=(0.0, 0.0, -5.0, 1.0, 0.0, 0.0, 0.0)):
    wall = SceneObject("wall", Primitive("box", (0.005, 3.0, 3.0)), pose=wall_pose, fixed=True)
    scene = build_scene([wall], actuator_profile("mjlab"))
    d = mujoco.MjData(scene.model)
    d.qpos[2] += 3.0  # the robot high above the floor: the wall alone in view
    mujoco.mj_forward(scene.model, d)
    return scene.model, d


def test_a_wall_facing_the_camera_reads_its_distance_at_the_centre_and_the_corner():
    m, d = _scene()
    origin, C = CAMERA.frame(m, d)
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, C.reshape(-1))
    distance = 1.0
    centre = origin + (distance + 0.005) * C[:, 0]  # the wall's near face at 1 m along the optical axis
    m, d = _scene((*centre, *q))
    depth = CAMERA.render(m, d)
    assert depth.shape == (21, 33) and depth.dtype == np.float32
    assert abs(depth[10, 16] - distance) < 1e-3  # the centre pixel's ray is the optical axis
    assert abs(depth[0, 0] - distance) < 1e-3 and abs(depth[-1, -1] - distance) < 1e-3  # z-depth, not range
    far = CAMERA.render(*_scene())  # nothing in view: the far plane
    assert np.all(far == CAMERA.far)


def test_the_camera_follows_the_torso():
    m, d = _scene()
    origin, C = CAMERA.frame(m, d)
    root = d.qpos[:3].copy()
    d.qpos[3:7] = [np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)]  # the robot turned 90 degrees left
    mujoco.mj_forward(m, d)
    turned_origin, turned = CAMERA.frame(m, d)
    yaw = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(turned, yaw @ C, atol=1e-9)
    np.testing.assert_allclose(turned_origin - root, yaw @ (origin - root), atol=1e-9)
    assert C[2, 0] < -0.6  # pitched down ~48 degrees: the optical axis points at the floor ahead
    seen = DepthCamera().render(m, d)  # the default groups see the robot's own collision primitives
    assert seen.shape == (40, 64) and seen.min() < DepthCamera().far


@pytest.mark.parametrize(
    "change, field",
    [
        ({"fov_x_deg": 180.0}, "fov_x_deg"),
        ({"fov_y_deg": 0.0}, "fov_y_deg"),
        ({"width": 4}, "width"),
        ({"height": 300}, "height"),
        ({"near": 3.0, "far": 1.0}, "near"),
        ({"geom_groups": (0, 9)}, "geom_groups"),
    ],
)
def test_bad_settings_are_one_line_errors(change, field):
    with pytest.raises(InputError) as e:
        replace(DepthCamera(), **change)
    assert e.value.field == field and "\n" not in str(e.value)


def test_a_camera_on_a_body_the_g1_lacks():
    m, d = _scene()
    with pytest.raises(InputError, match="body: 'd435_link' is not a body"):
        DepthCamera(body="d435_link").render(m, d)
