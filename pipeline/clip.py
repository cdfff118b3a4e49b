"""The typed clip schema every stage exchanges: :class:`HumanClip`, :class:`ObjectTrack`, :class:`RobotClip`,
:class:`PhysicalizedClip`.

Conventions (all clips, all stages):

* world frame z-up, metres, seconds;
* quaternions scalar-first ``wxyz`` (MuJoCo);
* a pose is ``(x, y, z, qw, qx, qy, qz)``;
* robot ``qpos`` is MuJoCo's free-floating layout for the G1: root position (3),
  root quaternion (4), then the 29 joints in :data:`pipeline.robot.G1_JOINT_NAMES` order.

Every clip validates itself on construction and raises :class:`~pipeline.errors.InputError`
naming the source file, the first bad frame and the field.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from pipeline.errors import InputError, first_bad_frame
from pipeline.geometry import ObjectGeometry, ObjectPhysics
from pipeline.robot import JOINTS_QPOS, NQ_ROBOT, NUM_JOINTS, NV_ROBOT, ROOT_POSE
from pipeline.rotations import slerp_wxyz


def _check_fps(fps: float, source: str) -> float:
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(source, "fps", f"must be a positive finite number, got {fps!r}")
    return float(fps)


def check_array(a, shape: tuple, name: str, source: str, frames: int | None = None) -> np.ndarray:
    """Float64 array of ``shape`` (``None`` = any length), finite, with ``frames`` rows if given;
    otherwise :class:`InputError` naming ``source``, the field ``name`` and the first bad frame."""
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("T" if s is None else str(s) for s in shape) + ")"
        raise InputError(source, name, f"shape {a.shape} does not match {want}")
    if a.shape[0] == 0:
        raise InputError(source, name, "has zero frames")
    if frames is not None and a.shape[0] != frames:
        raise InputError(source, name, f"has {a.shape[0]} frames, expected {frames}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise InputError(source, name, "is NaN or infinite", frame=first_bad_frame(bad))
    return a


def _normalise_quats(q: np.ndarray, name: str, source: str) -> np.ndarray:
    """Unit-normalise ``(..., 4)`` quaternions; a norm below 1e-6 is an error."""
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    bad = n[..., 0] < 1e-6
    if bad.any():
        raise InputError(source, name, "quaternion has zero norm", frame=first_bad_frame(bad))
    return q / n


def _resample_times(frames: int, fps: float, new_fps: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(frames) / fps
    n = int(np.floor(t[-1] * new_fps + 1e-9)) + 1
    return t, np.arange(n) / new_fps


def _lerp(t: np.ndarray, x: np.ndarray, nt: np.ndarray) -> np.ndarray:
    flat = x.reshape(x.shape[0], -1)
    out = np.stack([np.interp(nt, t, flat[:, k]) for k in range(flat.shape[1])], axis=1)
    return out.reshape((len(nt),) + x.shape[1:])


def _nearest(t: np.ndarray, x: np.ndarray, nt: np.ndarray) -> np.ndarray:
    idx = (
        np.clip(np.rint(nt * (len(t) - 1) / max(t[-1], 1e-12)).astype(int), 0, len(t) - 1)
        if len(t) > 1
        else np.zeros(len(nt), int)
    )
    return x[idx]


def _resample_pose(t: np.ndarray, pose: np.ndarray, nt: np.ndarray) -> np.ndarray:
    if len(t) == 1:
        return np.repeat(pose, len(nt), axis=0)
    return np.concatenate([_lerp(t, pose[:, :3], nt), slerp_wxyz(t, pose[:, 3:7], nt)], axis=1)


@dataclass(frozen=True)
class Skeleton:
    """Joint names and parent indices (``-1`` for the root); parents precede children."""

    joint_names: tuple[str, ...]
    parents: tuple[int, ...]

    def __post_init__(self):
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        object.__setattr__(self, "parents", tuple(int(p) for p in self.parents))
        if len(self.joint_names) != len(self.parents) or not self.joint_names:
            raise ValueError(f"skeleton has {len(self.joint_names)} names and {len(self.parents)} parents")
        if len(set(self.joint_names)) != len(self.joint_names):
            raise ValueError("skeleton joint names are not unique")
        for i, p in enumerate(self.parents):
            if not -1 <= p < i:
                raise ValueError(
                    f"skeleton joint {self.joint_names[i]!r} has parent {p}; parents must precede children"
                )

    def index(self, name: str) -> int:
        return self.joint_names.index(name)


@dataclass(frozen=True)
class ObjectTrack:
    """One rigid object over a clip: its geometry, a ``(T,7)`` world pose, optional ``(T,)`` contact flags,
    and optional physical properties (``None``: :class:`~pipeline.geometry.ObjectPhysics`'s defaults)."""

    name: str
    geometry: ObjectGeometry
    pose: np.ndarray
    contact: np.ndarray | None = None
    mass: float | None = None
    source: str = ""
    # sliding friction against the robot and other objects, and against the floor (ObjectPhysics)
    friction: float | None = None
    floor_friction: float | None = None
    # where mass and frictions come from (pipeline.materials: the object kind's material, or "default")
    material: str = ""

    def __post_init__(self):
        pose = check_array(self.pose, (None, 7), f"object {self.name} pose", self.source)
        pose[:, 3:] = _normalise_quats(pose[:, 3:], f"object {self.name} quaternion", self.source)
        object.__setattr__(self, "pose", pose)
        if self.contact is not None:
            c = np.asarray(self.contact).astype(bool).reshape(-1)
            if c.shape[0] != pose.shape[0]:
                raise InputError(
                    self.source, f"object {self.name} contact", f"has {c.shape[0]} frames, pose has {pose.shape[0]}"
                )
            object.__setattr__(self, "contact", c)
        for key in ("mass", "friction", "floor_friction"):
            v = getattr(self, key)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise InputError(self.source, f"object {self.name} {key}", f"must be a positive number, got {v!r}")

    @property
    def frames(self) -> int:
        return self.pose.shape[0]

    def physics(self) -> ObjectPhysics:
        """The scene properties of this object: its own mass and frictions where known, else the defaults."""
        default = ObjectPhysics()
        return ObjectPhysics(
            mass=self.mass or default.mass,
            friction=self.friction or default.friction,
            floor_friction=self.floor_friction or default.floor_friction,
        )

    def resampled(self, fps: float, new_fps: float) -> ObjectTrack:
        t, nt = _resample_times(self.frames, fps, new_fps)
        contact = None if self.contact is None else _nearest(t, self.contact, nt)
        return replace(self, pose=_resample_pose(t, self.pose, nt), contact=contact)


@dataclass(frozen=True)
class HumanClip:
    """Human (and object) motion: global joint positions ``(T,J,3)`` in metres, z-up.

    ``joint_quat`` (optional) are global joint orientations ``(T,J,4)`` wxyz.
    ``contacts`` (optional) are per-joint human-object/ground contact flags ``(T,J)``.
    ``subject_height`` is the standing height in metres when known.
    """

    skeleton: Skeleton
    joint_pos: np.ndarray
    fps: float
    source: str
    subject_height: float | None = None
    joint_quat: np.ndarray | None = None
    contacts: np.ndarray | None = None
    objects: tuple[ObjectTrack, ...] = ()
    task: str = ""
    synthetic: bool = False

    def __post_init__(self):
        src = self.source
        object.__setattr__(self, "fps", _check_fps(self.fps, src))
        J = len(self.skeleton.joint_names)
        pos = check_array(self.joint_pos, (None, J, 3), "joint_pos", src)
        object.__setattr__(self, "joint_pos", pos)
        T = pos.shape[0]
        if self.joint_quat is not None:
            q = check_array(self.joint_quat, (T, J, 4), "joint_quat", src, frames=T)
            object.__setattr__(self, "joint_quat", _normalise_quats(q, "joint_quat", src))
        if self.contacts is not None:
            c = np.asarray(self.contacts).astype(bool)
            if c.shape != (T, J):
                raise InputError(src, "contacts", f"shape {c.shape} does not match ({T}, {J})")
            object.__setattr__(self, "contacts", c)
        if self.subject_height is not None and not (0.3 < self.subject_height < 3.0):
            raise InputError(src, "subject_height", f"{self.subject_height!r} m is not a human height")
        object.__setattr__(self, "objects", tuple(self.objects))
        for o in self.objects:
            if o.frames != T:
                raise InputError(src, f"object {o.name} pose", f"has {o.frames} frames, joint_pos has {T}")

    @property
    def frames(self) -> int:
        return self.joint_pos.shape[0]

    @property
    def duration(self) -> float:
        return (self.frames - 1) / self.fps

    def resampled(self, new_fps: float) -> HumanClip:
        """The clip at ``new_fps``: positions linearly interpolated, orientations slerped, flags nearest."""
        new_fps = _check_fps(new_fps, self.source)
        t, nt = _resample_times(self.frames, self.fps, new_fps)
        quat = None
        if self.joint_quat is not None:
            quat = (
                np.stack([slerp_wxyz(t, self.joint_quat[:, j], nt) for j in range(self.joint_quat.shape[1])], axis=1)
                if len(t) > 1
                else np.repeat(self.joint_quat, len(nt), 0)
            )
        pos = _lerp(t, self.joint_pos, nt) if len(t) > 1 else np.repeat(self.joint_pos, len(nt), 0)
        contacts = None if self.contacts is None else _nearest(t, self.contacts, nt)
        objects = tuple(o.resampled(self.fps, new_fps) for o in self.objects)
        return replace(self, joint_pos=pos, joint_quat=quat, contacts=contacts, objects=objects, fps=new_fps)


START_PREFIX_KEY = "start_prefix_frames"
"""``RobotClip.provenance`` key: the frames of a synthetic start prefix before the clip's own (physicalize.start)."""


@dataclass(frozen=True)
class RobotClip:
    """G1 motion: ``qpos (T,36)`` in MuJoCo convention, objects, per-frame contact labels, provenance.

    ``contacts`` is ``(T, len(contact_links))`` booleans: link ``k`` touches an object at frame ``t``.
    """

    qpos: np.ndarray
    fps: float
    source: str
    objects: tuple[ObjectTrack, ...] = ()
    contact_links: tuple[str, ...] = ()
    contacts: np.ndarray | None = None
    method: str = ""
    provenance: dict = field(default_factory=dict)
    task: str = ""

    def __post_init__(self):
        src = self.source
        object.__setattr__(self, "fps", _check_fps(self.fps, src))
        qpos = check_array(self.qpos, (None, NQ_ROBOT), "qpos", src)
        qpos[:, 3:7] = _normalise_quats(qpos[:, 3:7], "qpos root quaternion", src)
        object.__setattr__(self, "qpos", qpos)
        T = qpos.shape[0]
        object.__setattr__(self, "objects", tuple(self.objects))
        object.__setattr__(self, "contact_links", tuple(self.contact_links))
        for o in self.objects:
            if o.frames != T:
                raise InputError(src, f"object {o.name} pose", f"has {o.frames} frames, qpos has {T}")
        if self.contacts is not None:
            c = np.asarray(self.contacts).astype(bool)
            if c.shape != (T, len(self.contact_links)):
                raise InputError(src, "contacts", f"shape {c.shape} does not match ({T}, {len(self.contact_links)})")
            object.__setattr__(self, "contacts", c)

    @property
    def frames(self) -> int:
        return self.qpos.shape[0]

    def resampled(self, new_fps: float) -> RobotClip:
        """Root position and joints linearly interpolated, root orientation slerped, labels nearest."""
        new_fps = _check_fps(new_fps, self.source)
        t, nt = _resample_times(self.frames, self.fps, new_fps)
        if len(t) == 1:
            qpos = np.repeat(self.qpos, len(nt), 0)
        else:
            qpos = np.concatenate(
                [_resample_pose(t, self.qpos[:, ROOT_POSE], nt), _lerp(t, self.qpos[:, JOINTS_QPOS], nt)], axis=1
            )
        contacts = None if self.contacts is None else _nearest(t, self.contacts, nt)
        objects = tuple(o.resampled(self.fps, new_fps) for o in self.objects)
        return replace(self, qpos=qpos, contacts=contacts, objects=objects, fps=new_fps)


@dataclass(frozen=True)
class PhysicalizedClip:
    """A G1 clip simulated in MuJoCo (the physicalize stage's output, the features stage's input).

    ``robot`` holds the simulated motion: ``qpos`` and the objects' simulated poses, with the
    per-link robot-object contact flags measured in the simulation. Per frame ``t`` (50 Hz) also:

    * ``qvel (T, 35)`` -- the robot's MuJoCo ``qvel``: root linear velocity (world), root angular
      velocity (root body frame), joint velocities;
    * ``object_vel`` -- per object ``(T, 6)``: linear velocity of its origin (world), angular
      velocity (object body frame), MuJoCo free-joint convention;
    * ``action (T, 29)`` -- joint position targets held from ``t`` to ``t + 1``;
    * ``torque (T, 29)`` -- applied actuator torques, mean over the hold;
    * ``foot_force (T, 2)`` -- vertical floor force on the left and right foot [N];
    * ``reference_qpos (T, 36)`` -- the retargeted ``qpos`` tracked at ``t``;
    * ``validation`` -- the clip's validation figures (``valid``, ``reason``, errors).
    """

    robot: RobotClip
    qvel: np.ndarray
    object_vel: tuple[np.ndarray, ...]
    action: np.ndarray
    torque: np.ndarray
    foot_force: np.ndarray
    reference_qpos: np.ndarray
    validation: dict = field(default_factory=dict)

    def __post_init__(self):
        src, T = self.robot.source, self.robot.frames
        for name, dim in (
            ("qvel", NV_ROBOT),
            ("action", NUM_JOINTS),
            ("torque", NUM_JOINTS),
            ("foot_force", 2),
            ("reference_qpos", NQ_ROBOT),
        ):
            object.__setattr__(self, name, check_array(getattr(self, name), (None, dim), name, src, frames=T))
        vel = tuple(self.object_vel)
        if len(vel) != len(self.robot.objects):
            raise InputError(src, "object_vel", f"{len(vel)} velocity tracks for {len(self.robot.objects)} objects")
        object.__setattr__(
            self,
            "object_vel",
            tuple(
                check_array(v, (None, 6), f"object {o.name} vel", src, frames=T)
                for v, o in zip(vel, self.robot.objects)
            ),
        )

    @property
    def frames(self) -> int:
        return self.robot.frames
