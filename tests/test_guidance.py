"""Object guidance (physicalize.guidance): the virtual wrench toward an object's reference track, on a real MuJoCo
scene, and the stage's refusal of a negative scale."""

import mujoco
import numpy as np
import pytest

from physicalize.clip import physicalize_clip
from physicalize.guidance import ObjectGuidance
from pipeline.geometry import ObjectPhysics, Primitive
from pipeline.rotations import yaw_quat
from pipeline.scene import SceneObject, build_scene

MASS, FPS = 2.0, 50.0


def _box_scene():
    box = SceneObject("box", Primitive("box", (0.15, 0.1, 0.08)), ObjectPhysics(mass=MASS))
    return build_scene([box])


def _still_track(T: int, x: float, yaw: float = 0.0) -> np.ndarray:
    track = np.zeros((T, 7))
    track[:, 0], track[:, 1], track[:, 2] = x, 1.0, 0.5
    track[:, 3:] = yaw_quat(yaw)
    return track


def _place(scene, d, x: float, yaw: float) -> None:
    adr = scene.object_qpos_adr["box"]
    d.qpos[adr : adr + 3] = (x, 1.0, 0.5)
    d.qpos[adr + 3 : adr + 7] = yaw_quat(yaw)
    mujoco.mj_forward(scene.model, d)


def test_guidance_pulls_the_object_back_onto_its_track_at_its_scale():
    """f = s m kp (p_ref - p) at rest; a heading behind its reference's gets a torque about +z; scale doubles both."""
    scene = _box_scene()
    d = mujoco.MjData(scene.model)
    body = scene.object_body_id["box"]
    _place(scene, d, x=0.95, yaw=-0.1)
    for scale in (0.5, 1.0):
        guide = ObjectGuidance.of(scene, {"box": _still_track(20, x=1.0)}, FPS, scale)
        guide(0, d)
        f, tau = d.xfrc_applied[body, :3], d.xfrc_applied[body, 3:]
        np.testing.assert_allclose(f, [scale * MASS * 100.0 * 0.05, 0.0, 0.0], atol=1e-6)
        assert tau[2] > 0 and abs(tau[0]) < 1e-9 and abs(tau[1]) < 1e-9
        assert guide.peak_n == pytest.approx(np.linalg.norm(f))
    _place(scene, d, x=1.0, yaw=0.0)
    ObjectGuidance.of(scene, {"box": _still_track(20, x=1.0)}, FPS, 1.0)(0, d)
    np.testing.assert_allclose(d.xfrc_applied[body], 0.0, atol=1e-9)  # on its track, at rest: no wrench


def test_guidance_refuses_a_scale_that_is_not_positive():
    scene = _box_scene()
    with pytest.raises(ValueError, match="object guidance scale must be > 0, got 0"):
        ObjectGuidance.of(scene, {"box": _still_track(5, x=1.0)}, FPS, 0.0)
    with pytest.raises(ValueError, match="object guidance scale must be >= 0, got -1"):
        physicalize_clip(None, guide=-1.0)  # refused before the clip is read
