"""Clips <-> dataset episodes, shared by every stage that writes or reads a dataset.

Robot datasets (:func:`robot_clips_to_episodes`, :func:`episodes_to_robot_clips`):

* ``observation.state`` -- MuJoCo ``qpos`` (36): root position (m, world), root quaternion
  (wxyz, world), 29 joint angles (rad) in :data:`pipeline.robot.G1_JOINT_NAMES` order;
* ``observation.qvel`` -- MuJoCo ``qvel`` (35) from finite differences of ``qpos``
  (:func:`pipeline.kinematics.qvel_from_qpos`): root linear velocity in the world frame (m/s),
  root angular velocity in the body (pelvis) frame (rad/s), joint velocities (rad/s);
* ``contact`` -- per contact link, ``True`` when the link touches an object (if the clips name links);
* ``object.pose`` -- the clip's object's pose (x, y, z, qw, qx, qy, qz) in the world frame, and
  ``object.contact`` (1 bool) when any clip has contact flags for it (further objects: ``object_2.*``, ...;
  columns by role, the object's identity in the episode meta: :mod:`pipeline.dataset.objects`)
  (:mod:`pipeline.dataset.objects`);
* ``source_frame`` -- frame index in the source motion: ``t + provenance["source_frame_start"]``
  (0 when absent); -1 over a physicalized clip's synthetic start prefix (``provenance["start_prefix_frames"]``).

Physicalized datasets (:func:`physicalized_clips_to_episodes`, :func:`episodes_to_physicalized_clips`):
the robot features with ``observation.qvel`` from the simulation, plus ``action`` (29 joint position
targets), ``observation.torque`` (29), ``observation.foot_force`` (left, right), ``reference.state``
(the retargeted ``qpos`` tracked) and ``object.vel`` (linear world, angular body); the
validation figures go into the episode metadata.

Human datasets (:func:`human_clips_to_episodes`, :func:`episodes_to_human_clips`):
``observation.joint_pos`` (J*3, names ``<joint>.x``), ``observation.joint_quat`` (J*4, names
``<joint>.qw`` ..., when the clips have orientations), ``contact`` (J), the object features and
``source_frame``; the skeleton lives in the per-episode sidecar metadata.

All clips of one dataset must share the fps (an integer: LeRobot stores integer fps), the number of
objects (not which: columns are by role), the contact links and (human) the skeleton, because a dataset
has one feature spec.
Object geometry, masses, sources, provenance and per-clip presence flags go into the per-episode
``meta`` (``meta/lessmimic_episodes.jsonl``); reading back restores the clips exactly up to float32.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from pipeline.clip import START_PREFIX_KEY, HumanClip, PhysicalizedClip, RobotClip, Skeleton
from pipeline.dataset.objects import (
    episode_column,
    object_column,
    object_data,
    object_features,
    objects_from_episode,
)
from pipeline.dataset.read import iter_episodes, read_info
from pipeline.dataset.schema import Episode, Feature
from pipeline.errors import InputError
from pipeline.kinematics import qvel_from_qpos
from pipeline.robot import G1_JOINT_NAMES, QPOS_NAMES
from pipeline.terms.layout import ACTION

QVEL_NAMES: tuple[str, ...] = ("root_vx", "root_vy", "root_vz", "root_wx", "root_wy", "root_wz") + G1_JOINT_NAMES
DEFAULT_TASK = "humanoid whole-body motion"


# --- shared helpers ------------------------------------------------------------------------------


def clips_fps(clips: Sequence[RobotClip | HumanClip]) -> int:
    """The clips' common integer fps, or an InputError naming the first clip that differs."""
    if not clips:
        raise InputError(None, "clips", "no clips to convert")
    fps = clips[0].fps
    for c in clips:
        if abs(c.fps - fps) > 1e-9:
            raise InputError(c.source, "fps", f"{c.fps} differs from {clips[0].source} ({fps}); resample first")
    if abs(fps - round(fps)) > 1e-6:
        raise InputError(
            clips[0].source, "fps", f"{fps} is not an integer; LeRobot needs an integer fps: resample first"
        )
    return int(round(fps))


def _common(clips, attr: str, what: str):
    ref = getattr(clips[0], attr)
    for c in clips[1:]:
        if getattr(c, attr) != ref:
            raise InputError(
                c.source,
                what,
                f"{getattr(c, attr)!r} differs from {clips[0].source} ({ref!r}); one dataset has one feature spec",
            )
    return ref


def _source_frames(T: int, start, ratio: float = 1.0, prefix: int = 0) -> np.ndarray:
    """Source frame of each of ``T`` frames, ``start + round((t - prefix) ratio)`` (``ratio``: source fps / clip fps,
    for a clip resampled from its source), -1 over a synthetic start prefix of ``prefix`` frames (no source frame:
    :mod:`physicalize.start`)."""
    t = np.arange(T) - int(prefix)
    return np.where(t < 0, -1, int(start or 0) + np.round(np.maximum(t, 0) * ratio).astype(np.int64))


_SOURCE_FRAME = Feature("source_frame", "int64", ("source_frame",), "frame index in the source motion")


# --- robot clips ---------------------------------------------------------------------------------


def robot_clips_to_episodes(
    clips: Sequence[RobotClip], *, default_task: str = DEFAULT_TASK
) -> tuple[list[Feature], list[Episode]]:
    """The feature spec and one episode per clip (write them with ``write_dataset(..., fps=clips_fps(clips))``)."""
    fps = clips_fps(clips)
    links = _common(clips, "contact_links", "contact_links")
    obj_feats, _, with_contact = object_features(clips)
    features = [
        Feature(
            "observation.state",
            "float32",
            QPOS_NAMES,
            "G1 qpos: root position, root quaternion wxyz (world), joint angles",
            "m, rad",
        ),
        Feature(
            "observation.qvel",
            "float32",
            QVEL_NAMES,
            "G1 qvel by finite differences: root linear velocity (world), root angular velocity (body), joint "
            "velocities",
            "m/s, rad/s",
        ),
    ]
    if links:
        features.append(Feature("contact", "bool", links, "link touches an object"))
    features += obj_feats + [_SOURCE_FRAME]
    episodes = []
    for c in clips:
        data = {"observation.state": c.qpos, "observation.qvel": qvel_from_qpos(c.qpos, fps)}
        if links:
            data["contact"] = np.zeros((c.frames, len(links)), bool) if c.contacts is None else c.contacts
        obj_data, obj_meta = object_data(c, with_contact)
        data.update(obj_data)
        ratio = float(c.provenance.get("source_fps", fps)) / fps
        data["source_frame"] = _source_frames(
            c.frames, c.provenance.get("source_frame_start"), ratio, c.provenance.get(START_PREFIX_KEY, 0)
        )
        meta = {
            "kind": "robot",
            "source": c.source,
            "fps": c.fps,
            "method": c.method,
            "clip_task": c.task,
            "synthetic": bool(c.provenance.get("synthetic", False)),
            "provenance": c.provenance,
            "contact_links": list(c.contact_links),
            "has_contacts": c.contacts is not None,
            "objects": obj_meta,
        }
        episodes.append(Episode(c.task or default_task, data, meta))
    return features, episodes


def _robot_clip(ep: Episode, root, e: int, fps: float) -> RobotClip:
    m = ep.meta
    if m.get("kind") != "robot":
        raise InputError(root, f"episode {e}", "was not written from a robot clip (sidecar meta kind is not 'robot')")
    links = tuple(m.get("contact_links", ()))
    contacts = ep.data["contact"].astype(bool) if links and m.get("has_contacts") else None
    return RobotClip(
        qpos=ep.data["observation.state"].astype(np.float64),
        fps=float(m.get("fps", fps)),
        source=m["source"],
        objects=objects_from_episode(ep, m["source"]),
        contact_links=links,
        contacts=contacts,
        method=m.get("method", ""),
        provenance=m.get("provenance", {}),
        task=m.get("clip_task", ep.task),
    )


def episodes_to_robot_clips(root: str | Path) -> list[RobotClip]:
    """Robot clips back from a dataset written from :func:`robot_clips_to_episodes`."""
    fps = read_info(root)["fps"]
    return [_robot_clip(ep, root, e, fps) for e, ep in enumerate(iter_episodes(root))]


# --- physicalized clips --------------------------------------------------------------------------

_VEL_NAMES = ("vx", "vy", "vz", "wx", "wy", "wz")


def physicalized_clips_to_episodes(clips: Sequence[PhysicalizedClip]) -> tuple[list[Feature], list[Episode]]:
    """The feature spec and one episode per simulated clip (the robot features of :func:`robot_clips_to_episodes`
    with ``observation.qvel`` from the simulation, plus the simulation's actions, torques, forces and object
    velocities)."""
    features, episodes = robot_clips_to_episodes([c.robot for c in clips])
    sim_qvel = (
        "G1 qvel from the simulation: root linear velocity (world), root angular velocity (body), joint velocities"
    )
    features = [replace(f, description=sim_qvel) if f.name == "observation.qvel" else f for f in features]
    features += [
        Feature(ACTION, "float32", G1_JOINT_NAMES, "joint position targets held for the next 20 ms", "rad"),
        Feature(
            "observation.torque", "float32", G1_JOINT_NAMES, "applied actuator torques (mean over the hold)", "N m"
        ),
        Feature(
            "observation.foot_force", "float32", ("left", "right"), "vertical floor contact force on each foot", "N"
        ),
        Feature("reference.state", "float32", QPOS_NAMES, "retargeted qpos tracked at this frame", "m, rad"),
    ]
    columns = [object_column(k) for k in range(len(clips[0].robot.objects))]
    features += [
        Feature(f"{col}.vel", "float32", _VEL_NAMES, f"{col} velocity (linear world, angular body)", "m/s, rad/s")
        for col in columns
    ]
    for ep, c in zip(episodes, clips):
        ep.data.update(
            {
                "observation.qvel": c.qvel,
                ACTION: c.action,
                "observation.torque": c.torque,
                "observation.foot_force": c.foot_force,
                "reference.state": c.reference_qpos,
            }
        )
        ep.data.update({f"{col}.vel": v for col, v in zip(columns, c.object_vel)})
        ep.meta.update({"stage": "physicalized", "validation": c.validation})
    return features, episodes


def episodes_to_physicalized_clips(root: str | Path) -> list[PhysicalizedClip]:
    """Simulated clips back from a dataset written from :func:`physicalized_clips_to_episodes`; a
    dataset without the simulation's columns (e.g. a retargeted one) is an :class:`InputError`."""
    info = read_info(root)
    names = info["features"]
    missing = [k for k in (ACTION, "observation.torque", "observation.foot_force", "reference.state") if k not in names]
    if missing:
        raise InputError(
            root, "features", f"missing {missing}: not a physicalized dataset (run `lessmimic physicalize` first)"
        )
    clips = []
    for e, ep in enumerate(iter_episodes(root)):
        robot, d = _robot_clip(ep, root, e, info["fps"]), ep.data
        clips.append(
            PhysicalizedClip(
                robot=robot,
                qvel=d["observation.qvel"],
                object_vel=tuple(d[f"{episode_column(m)}.vel"] for m in ep.meta.get("objects", [])),
                action=d[ACTION],
                torque=d["observation.torque"],
                foot_force=d["observation.foot_force"],
                reference_qpos=d["reference.state"],
                validation=ep.meta.get("validation", {}),
            )
        )
    return clips


# --- human clips ---------------------------------------------------------------------------------


def human_clips_to_episodes(
    clips: Sequence[HumanClip], *, default_task: str = DEFAULT_TASK
) -> tuple[list[Feature], list[Episode]]:
    """The feature spec and one episode per human clip (all clips share one skeleton)."""
    clips_fps(clips)
    skel: Skeleton = _common(clips, "skeleton", "skeleton")
    quat = {c.joint_quat is not None for c in clips}
    if len(quat) > 1:
        bad = next(c for c in clips if (c.joint_quat is not None) != (clips[0].joint_quat is not None))
        raise InputError(bad.source, "joint_quat", f"present in some clips only (e.g. {clips[0].source} vs this one)")
    has_contacts = any(c.contacts is not None for c in clips)
    obj_feats, _, with_contact = object_features(clips)
    J = skel.joint_names
    features = [
        Feature(
            "observation.joint_pos",
            "float32",
            tuple(f"{j}.{a}" for j in J for a in "xyz"),
            "global joint positions (world, z-up)",
            "m",
        )
    ]
    if quat.pop():
        features.append(
            Feature(
                "observation.joint_quat",
                "float32",
                tuple(f"{j}.q{a}" for j in J for a in "wxyz"),
                "global joint orientations, quaternion wxyz (world)",
            )
        )
    if has_contacts:
        features.append(
            Feature("contact", "bool", J, "joint in contact with an object (foot-ground contact is derived downstream)")
        )
    features += obj_feats + [_SOURCE_FRAME]
    episodes = []
    for c in clips:
        T = c.frames
        data = {"observation.joint_pos": c.joint_pos.reshape(T, -1)}
        if c.joint_quat is not None:
            data["observation.joint_quat"] = c.joint_quat.reshape(T, -1)
        if has_contacts:
            data["contact"] = np.zeros((T, len(J)), bool) if c.contacts is None else c.contacts
        obj_data, obj_meta = object_data(c, with_contact)
        data.update(obj_data)
        data["source_frame"] = _source_frames(T, 0)
        meta = {
            "kind": "human",
            "source": c.source,
            "fps": c.fps,
            "clip_task": c.task,
            "synthetic": c.synthetic,
            "subject_height": c.subject_height,
            "skeleton": {"joint_names": list(J), "parents": list(skel.parents)},
            "has_contacts": c.contacts is not None,
            "objects": obj_meta,
        }
        episodes.append(Episode(c.task or default_task, data, meta))
    return features, episodes


def episodes_to_human_clips(root: str | Path) -> list[HumanClip]:
    """Human clips back from a dataset written from :func:`human_clips_to_episodes`."""
    fps = read_info(root)["fps"]
    clips = []
    for e, ep in enumerate(iter_episodes(root)):
        m = ep.meta
        if m.get("kind") != "human":
            raise InputError(
                root, f"episode {e}", "was not written from a human clip (sidecar meta kind is not 'human')"
            )
        skel = Skeleton(tuple(m["skeleton"]["joint_names"]), tuple(m["skeleton"]["parents"]))
        T, J = ep.data["observation.joint_pos"].shape[0], len(skel.joint_names)
        quat = ep.data.get("observation.joint_quat")
        contacts = ep.data["contact"].astype(bool) if m.get("has_contacts") else None
        clips.append(
            HumanClip(
                skeleton=skel,
                joint_pos=ep.data["observation.joint_pos"].astype(np.float64).reshape(T, J, 3),
                fps=float(m.get("fps", fps)),
                source=m["source"],
                subject_height=m.get("subject_height"),
                joint_quat=None if quat is None else quat.astype(np.float64).reshape(T, J, 4),
                contacts=contacts,
                objects=objects_from_episode(ep, m["source"]),
                task=m.get("clip_task", ep.task),
                synthetic=bool(m.get("synthetic", False)),
            )
        )
    return clips
