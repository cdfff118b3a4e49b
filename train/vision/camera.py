"""An egocentric depth camera on the G1, rendered on the CPU by ray casting (``mujoco.mj_multiRay``).

**Pose.** The camera sits on ``body`` at ``pos`` in that body's frame, pitched down by ``pitch`` about the body's
y axis: by default the G1's RealSense D435 mount (Unitree's G1 URDF, ``d435_joint`` on ``torso_link``: xyz
(0.0576, 0.0175, 0.4199) m, rpy (0, 0.8308, 0) rad), so the camera follows the torso. In the camera frame ``C``
(:meth:`DepthCamera.frame`) the optical axis is ``C[:, 0]`` (the body's x after the pitch), image right is
``-C[:, 1]`` and image down ``-C[:, 2]`` (ROS's body-frame convention: x forward, y left, z up).

**Offset.** An optional :class:`CameraOffset` moves the camera off its nominal mount, for per-episode extrinsics
and per-step jitter (:mod:`train.vision.noise`): ``pos`` is added to ``pos`` in the body's frame, and ``rot =
(roll, pitch, yaw)`` turns the camera frame about its own axes after the mount's pitch,
``C' = C R_x(roll) R_y(pitch) R_z(yaw)`` (roll about the optical axis; a positive pitch tips it further down, as the
mount's does). No offset, or an all-zero one, gives the nominal pose bit for bit.

**Pinhole.** ``width x height`` pixels over ``fov_x x fov_y`` degrees (the D435's depth stream: ~87 x 58); pixel
``(r, c)``'s centre is at ``u = (c + 1/2 - W/2) / f_x``, ``v = (r + 1/2 - H/2) / f_y`` with
``f = (size / 2) / tan(fov / 2)``, its ray ``d = normalise(x + u (-y) + v (-z))`` in the world.

**Depth.** The z-depth ``z = t (d . x)`` of the first hit at range ``t`` among the geoms of ``geom_groups``, clipped to
``[near, far]``; no hit reads ``far``. ``mj_multiRay``'s cutoff ``far`` skips the geoms lying wholly farther than
``far`` from the camera, not each ray at range ``far``: a hit on another geom up to ``far / cos(angle off axis)`` away
still reads its z-depth, so in the image's corners (3 to 4.4 m away by default) a surface beyond ``far`` along its ray
reads either (mjlab's camera: its depth, :mod:`train.envs.mjlab.camera`). The default groups {0, 3} are the world,
the objects and the G1's collision primitives (its visual meshes are in group 2): the paper's student sees the scene
the physics has. Measured (FIELD-NOTES, a 64 x 64 image of the G1 and a box): ~0.5 ms through these groups, 6.8-11 ms
through every geom.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from pipeline.errors import InputError


def _rotation_xyz(rot: tuple[float, float, float]) -> np.ndarray:
    """``R_x(roll) R_y(pitch) R_z(yaw)``: turns about the frame's own x, then y, then z (intrinsic)."""
    (cx, cy, cz), (sx, sy, sz) = map(math.cos, rot), map(math.sin, rot)
    return np.array(  # the product written out
        [
            [cy * cz, -cy * sz, sy],
            [sx * sy * cz + cx * sz, -sx * sy * sz + cx * cz, -sx * cy],
            [-cx * sy * cz + sx * sz, cx * sy * sz + sx * cz, cx * cy],
        ]
    )


@dataclass(frozen=True)
class CameraOffset:
    """A camera pose offset (module docstring): ``pos`` (m, in the mount body's frame), ``rot`` (roll, pitch, yaw; rad,
    about the camera frame's own axes after the mount's pitch).

    ``a + b`` adds the positions (exact: both are body-frame translations) and the angles (a first-order composition:
    the error is of the order of the product of the two angles, ~1e-4 rad for the 0.01-rad offsets of
    :mod:`train.vision.noise`)."""

    pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rot: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        for name in ("pos", "rot"):  # plain Python: built every control step, a few microseconds
            value = getattr(self, name)
            try:
                v = tuple(float(x) for x in value)
            except (TypeError, ValueError):
                v = ()
            if len(v) != 3 or not all(map(math.isfinite, v)):
                raise InputError("camera", f"offset.{name}", f"{value!r} is not 3 finite numbers")
            object.__setattr__(self, name, v)

    def __add__(self, other: CameraOffset) -> CameraOffset:
        if not isinstance(other, CameraOffset):
            return NotImplemented
        return CameraOffset(
            tuple(a + b for a, b in zip(self.pos, other.pos)), tuple(a + b for a, b in zip(self.rot, other.rot))
        )

    @property
    def is_zero(self) -> bool:
        return not any(self.pos) and not any(self.rot)


@dataclass(frozen=True)
class DepthCamera:
    """A depth camera's mount, intrinsics and range (module docstring); checked on construction."""

    body: str = "torso_link"
    pos: tuple[float, float, float] = (0.0576235, 0.01753, 0.41987)
    pitch: float = 0.8307767  # rad, down
    width: int = 64
    height: int = 40
    fov_x_deg: float = 87.0
    fov_y_deg: float = 58.0
    near: float = 0.1  # m
    far: float = 3.0  # m
    geom_groups: tuple[int, ...] = (0, 3)

    def __post_init__(self):
        for name in ("fov_x_deg", "fov_y_deg"):
            if not 0.0 < getattr(self, name) < 180.0:
                raise InputError("camera", name, f"{getattr(self, name)!r} is outside (0, 180) degrees")
        for name in ("width", "height"):
            if not 8 <= getattr(self, name) <= 256:
                raise InputError("camera", name, f"{getattr(self, name)!r} pixels is outside [8, 256]")
        if not 0.0 <= self.near < self.far:
            raise InputError("camera", "near", f"near {self.near!r} must be >= 0 and below far {self.far!r}")
        if any(not 0 <= g < mujoco.mjNGROUP for g in self.geom_groups):
            raise InputError("camera", "geom_groups", f"{self.geom_groups!r}: groups are 0..{mujoco.mjNGROUP - 1}")

    @classmethod
    def from_dict(cls, d) -> DepthCamera:
        """The camera of ``asdict(camera)`` read back from JSON (its tuples come back as lists)."""
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})

    @property
    def focal(self) -> tuple[float, float]:
        """``(f_x, f_y)`` in pixels."""
        fx = self.width / 2 / np.tan(np.radians(self.fov_x_deg) / 2)
        return float(fx), float(self.height / 2 / np.tan(np.radians(self.fov_y_deg) / 2))

    def body_id(self, m: mujoco.MjModel) -> int:
        bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, self.body)
        if bid < 0:
            raise InputError("camera", "body", f"{self.body!r} is not a body of this model")
        return bid

    def frame(
        self, m: mujoco.MjModel, d: mujoco.MjData, offset: CameraOffset | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(position (3,), C (3, 3))``: the camera's world position and axes (columns: optical axis, left, up),
        moved by ``offset`` if one is given (module docstring)."""
        b = self.body_id(m)
        R = d.xmat[b].reshape(3, 3)
        c, s = np.cos(self.pitch), np.sin(self.pitch)
        pitch = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])  # about y: x tips down for pitch > 0
        if offset is None or offset.is_zero:
            return d.xpos[b] + R @ np.asarray(self.pos), R @ pitch
        pos = np.asarray(self.pos) + np.asarray(offset.pos)
        return d.xpos[b] + R @ pos, R @ pitch @ _rotation_xyz(offset.rot)

    def rays(self) -> np.ndarray:
        """(H, W, 3) unit ray directions in the camera frame ``(x, y, z)`` (module docstring)."""
        fx, fy = self.focal
        u = (np.arange(self.width) + 0.5 - self.width / 2) / fx
        v = (np.arange(self.height) + 0.5 - self.height / 2) / fy
        uu, vv = np.meshgrid(u, v)
        d = np.stack([np.ones_like(uu), -uu, -vv], axis=-1)
        return d / np.linalg.norm(d, axis=-1, keepdims=True)

    def render(self, m: mujoco.MjModel, d: mujoco.MjData, offset: CameraOffset | None = None) -> np.ndarray:
        """(H, W) float32 z-depth in metres of ``d`` (after ``mj_kinematics``), clipped to ``[near, far]``, from the
        camera moved by ``offset`` if one is given."""
        origin, C = self.frame(m, d, offset)
        local = self.rays().reshape(-1, 3)
        world = local @ C.T
        n = len(world)
        dist, geomid = np.zeros(n), np.zeros(n, dtype=np.int32)
        groups = np.zeros(mujoco.mjNGROUP, dtype=np.uint8)
        groups[list(self.geom_groups)] = 1
        mujoco.mj_multiRay(m, d, origin, world.reshape(-1), groups, 1, -1, geomid, dist, None, n, self.far)
        z = np.where(dist < 0, self.far, dist * local[:, 0])
        return np.clip(z, self.near, self.far).reshape(self.height, self.width).astype(np.float32)
