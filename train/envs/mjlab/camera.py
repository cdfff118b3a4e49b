"""The depth camera of :class:`train.vision.camera.DepthCamera` as an mjlab camera sensor (MuJoCo Warp's ray-cast
renderer, every world at once on a GPU): the same mount, intrinsics, geoms and depth, so that a student trained on
the CPU images sees the same pixels here.

**Pose.** :func:`depth_sensor_cfg` adds a MuJoCo camera to ``<entity>/<camera.body>`` at the nominal pose
:meth:`DepthCamera.frame` gives in that body's frame (read through ``frame`` itself, on a one-body model). A
per-world pose offset would be written into MuJoCo Warp's per-world ``cam_pos`` / ``cam_quat`` (mjlab's
``expand_model_fields``); not done here. Our camera frame ``C`` has columns (optical axis, left, up); a MuJoCo camera
looks along its ``-z`` with ``x`` right and ``y`` up, so its axes are ``M = C K`` with
``K = [[0, 0, -1], [-1, 0, 0], [0, 1, 0]]`` (``M_x = -C_y``, ``M_y = C_z``, ``M_z = -C_x``), stored as a quaternion
(w, x, y, z).

**Intrinsics.** MuJoCo's ``fovy`` alone gives square pixels, so the horizontal field of view would be
``2 atan(W/H tan(fov_y/2))`` (83.1 degrees for the default 64 x 40 at 58, not 87). The camera therefore also gets a
sensor of ``W x H`` pixels of :data:`PIXEL_PITCH` and focal lengths ``(f_x, f_y)`` = :attr:`DepthCamera.focal` in
pixels, principal point at the centre; MuJoCo derives ``fovy`` = ``fov_y`` from them, and MuJoCo Warp's ray of pixel
``(r, c)`` is then ``normalise((c + 1/2 - W/2) / f_x, -(r + 1/2 - H/2) / f_y, -1)`` in the camera frame: our ray,
pixel for pixel (with a sensor size set, MuJoCo Warp reads the intrinsics, not ``fovy``).

**Depth.** MuJoCo Warp writes planar depth (the hit's distance times the cosine to the optical axis: the z-depth we
read) and 0 where a ray hits nothing, with no range limit. :func:`read_depth` maps it to :meth:`DepthCamera.render`'s
values: no hit reads ``far``, the rest is clipped to ``[near, far]``. One difference is left: ``mj_multiRay``'s
cutoff ``far`` skips the geoms wholly farther than ``far`` from the camera (a plane by its distance from the camera),
so a geom beyond ``far`` along the ray but nearer than ``far`` in depth -- only in the image's corners, ``far`` to
``far / cos`` away (3 to 4.4 m by default) -- reads ``far`` on the CPU and its depth here.

**Geoms.** The sensor renders the groups of ``camera.geom_groups`` (mjlab's ``enabled_geom_groups``). mjlab renders
all its cameras with one geom set, and with a ray-cast sensor in the scene the union of both sets: keep those equal.
One difference from ``mj_multiRay`` remains: MuJoCo Warp drops a hit on a primitive seen from inside (back-face
culling), where MuJoCo's ray reports the exit point; the D435 mount is outside the G1's collision primitives (1 mm
in front of the head's).

Measured (tests/test_vision_mjlab_camera.py, the G1 with its arms forward and a box, 64 x 40): the same image as
:meth:`DepthCamera.render` to 2.5 um on every pixel. On a CPU (warp's CPU backend, 1 world) a render takes ~25-32 ms
(``mj_multiRay``: ~1 ms), after ~45 s of kernel compiling the first time: a check of the code, not a CPU renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import torch
from mjlab.sensor.camera_sensor import CameraSensor, CameraSensorCfg

from pipeline.errors import InputError
from train.vision.camera import DepthCamera

PIXEL_PITCH = 3e-6
"""[m] the nominal pixel size of the MuJoCo camera's sensor (the D435's depth imager); only ratios of lengths reach
the image."""

MUJOCO_FROM_OURS = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
"""``K``: a MuJoCo camera's axes (x right, y up, z backward) in our camera frame's (optical axis, left, up)."""


@dataclass
class PinholeCameraSensorCfg(CameraSensorCfg):
    """mjlab's ``CameraSensorCfg`` with per-axis focal lengths: ``focal_pixel`` ``(f_x, f_y)`` in pixels sets the
    camera's sensor (``width x height`` pixels of :data:`PIXEL_PITCH`) and intrinsics, principal point at the
    centre; ``None`` leaves mjlab's ``fovy`` camera (square pixels)."""

    focal_pixel: tuple[float, float] | None = None

    def build(self) -> PinholeCameraSensor:
        return PinholeCameraSensor(self)


class PinholeCameraSensor(CameraSensor):
    """mjlab's camera sensor whose camera takes :attr:`PinholeCameraSensorCfg.focal_pixel`."""

    cfg: PinholeCameraSensorCfg

    def edit_spec(self, scene_spec: mujoco.MjSpec, entities: dict) -> None:
        super().edit_spec(scene_spec, entities)
        if self.cfg.focal_pixel is None:
            return
        cam = scene_spec.camera(self.camera_name)
        cam.resolution = [self.cfg.width, self.cfg.height]
        cam.sensor_size = [self.cfg.width * PIXEL_PITCH, self.cfg.height * PIXEL_PITCH]
        cam.focal_pixel = list(self.cfg.focal_pixel)
        cam.principal_pixel = [0.0, 0.0]


def mount(camera: DepthCamera) -> tuple[np.ndarray, np.ndarray]:
    """``(pos (3,), quat (4,))``: the MuJoCo camera's position and orientation (w, x, y, z) in ``camera.body``'s
    frame, from :meth:`DepthCamera.frame` with the body at the world's origin (module docstring)."""
    spec = mujoco.MjSpec()
    spec.worldbody.add_body(name=camera.body)
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    pos, C = camera.frame(m, d)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, (C @ MUJOCO_FROM_OURS).reshape(-1))
    return np.asarray(pos, dtype=float), quat


def depth_sensor_cfg(camera: DepthCamera, name: str = "depth_camera", entity: str = "robot") -> PinholeCameraSensorCfg:
    """mjlab's depth camera sensor ``name`` for ``camera`` on entity ``entity`` (``SceneCfg.sensors``): its pose on
    ``<entity>/<camera.body>``, its ``W x H`` pixels over ``fov_x x fov_y``, its geom groups; depth only, no
    textures or shadows (module docstring). Read it with :func:`read_depth`."""
    pos, quat = mount(camera)
    return PinholeCameraSensorCfg(
        name=name,
        parent_body=f"{entity}/{camera.body}",
        pos=tuple(float(x) for x in pos),
        quat=tuple(float(x) for x in quat),
        fovy=camera.fov_y_deg,
        width=camera.width,
        height=camera.height,
        data_types=("depth",),
        use_textures=False,
        use_shadows=False,
        enabled_geom_groups=tuple(camera.geom_groups),
        focal_pixel=camera.focal,
    )


def read_depth(sensor: CameraSensor, camera: DepthCamera) -> torch.Tensor:
    """(num_envs, H, W) float32 z-depth in metres of mjlab's camera ``sensor`` (``env.scene[name]``, after
    ``sim.sense()``), as :meth:`DepthCamera.render` gives it: no hit reads ``far``, the rest is clipped to
    ``[near, far]``."""
    cfg = sensor.cfg
    if (cfg.width, cfg.height) != (camera.width, camera.height):
        why = f"sensor {cfg.name!r} is {cfg.width} x {cfg.height} pixels, the camera {camera.width} x {camera.height}"
        raise InputError("camera", "width", why)
    depth = sensor.data.depth
    if depth is None:
        raise InputError("camera", "data_types", f"sensor {cfg.name!r} renders no depth ({cfg.data_types!r})")
    z = depth[..., 0]
    return torch.where(z > 0.0, z, camera.far).clamp(camera.near, camera.far)
