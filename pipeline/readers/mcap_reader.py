"""MCAP transform / rigid-body streams -> :class:`HumanClip` (one joint per tracked frame).

Streams read (by schema name, any topic):

* ``foxglove.FrameTransform`` and ``foxglove.FrameTransforms``, protobuf (what foxglove-sdk
  writes; decoded from the FileDescriptorSet stored in the schema) or JSON encoding;
* ROS 2 ``tf2_msgs/msg/TFMessage`` (CDR, via ``mcap_ros2``'s decoder);
* mocap4r2 ``mocap4r2_msgs/msg/RigidBodies`` (and its older name ``mocap_msgs/msg/RigidBodies``):
  each rigid body's ``pose`` is relative to ``header.frame_id`` (``"world"`` when empty).

Every child frame / rigid body becomes a joint; its parent joint is the transform's parent
frame when that frame is itself tracked, else ``-1`` (the parent is a world/root frame, taken
as the z-up world; ROS REP-103 and Foxglove use metres, z up). Global poses compose the chain
``T_world_child = T_world_parent T_parent_child`` (``p = p_P + R_P t``, ``R = R_P R_t``).

Time: the samples' own stamps (``timestamp`` / ``header.stamp``) when every one is non-zero,
else the message log times. Every frame's local transform is sampled on one grid from the first to the
last sample at ``fps`` (given, else ``1 / median`` interval of the busiest frame's samples):
positions linearly, rotations by slerp; before its first / after its last sample a frame holds
its pose, and gaps are interpolated. A missing (all-zero) rotation means identity.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from pipeline.clip import HumanClip, Skeleton
from pipeline.errors import InputError
from pipeline.rotations import wxyz_from_rotation

TRANSFORM_SCHEMAS = ("foxglove.FrameTransform", "foxglove.FrameTransforms", "tf2_msgs/msg/TFMessage")
RIGID_BODY_SCHEMAS = ("mocap4r2_msgs/msg/RigidBodies", "mocap_msgs/msg/RigidBodies")
SUPPORTED = TRANSFORM_SCHEMAS + RIGID_BODY_SCHEMAS


def _get(obj, name: str, default=None):
    if isinstance(obj, dict):
        return obj.get(name, default)
    return getattr(obj, name, default)


def _stamp(ts) -> float:
    """Seconds from a Foxglove / protobuf / ROS 2 time (``sec``+``nsec`` / ``seconds``+``nanos`` /
    ``sec``+``nanosec``)."""
    if ts is None:
        return 0.0
    sec = _get(ts, "sec", None)
    sec = _get(ts, "seconds", 0) if sec is None else sec
    nsec = next((v for v in (_get(ts, k, None) for k in ("nsec", "nanosec", "nanos")) if v is not None), 0)
    return float(sec) + 1e-9 * float(nsec)


def _vec(v, keys=("x", "y", "z")) -> list[float]:
    return [float(_get(v, k, 0.0) or 0.0) for k in keys] if v is not None else [0.0] * len(keys)


@dataclass
class _Track:
    parent: str
    stamps: list[float] = field(default_factory=list)
    log_times: list[float] = field(default_factory=list)
    pose: list[list[float]] = field(default_factory=list)  # x y z qx qy qz qw
    times: list[float] = field(default_factory=list)  # the clock chosen by _choose_clock


def _protobuf_decoder(schema):
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool, pending = descriptor_pool.DescriptorPool(), list(fds.file)
    added: set[str] = set()
    while pending:  # add files after their dependencies
        ready = [f for f in pending if all(d in added for d in f.dependency)]
        if not ready:
            raise ValueError("protobuf schema has unresolved dependencies")
        for f in ready:
            pool.Add(f)
            added.add(f.name)
            pending.remove(f)
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return cls.FromString


def _decoder_factories():
    from mcap.decoder import DecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    class _Foxglove(DecoderFactory):
        def decoder_for(self, message_encoding, schema):
            if schema is None or schema.name not in SUPPORTED:
                return None
            if message_encoding == "protobuf":
                return _protobuf_decoder(schema)
            if message_encoding == "json":
                return json.loads
            return None

    return [Ros2DecoderFactory(), _Foxglove()]


def _transforms(schema_name: str, msg) -> list[tuple[float, str, str, list[float], list[float] | None]]:
    """``(stamp, parent, child, translation, rotation xyzw or None)`` entries of one message."""
    out = []
    if schema_name == "foxglove.FrameTransform":
        items = [msg]
    elif schema_name == "foxglove.FrameTransforms":
        items = list(_get(msg, "transforms", []) or [])
    elif schema_name == "tf2_msgs/msg/TFMessage":
        for tf in _get(msg, "transforms", []) or []:
            h, tr = _get(tf, "header"), _get(tf, "transform")
            out.append(
                (
                    _stamp(_get(h, "stamp")),
                    _get(h, "frame_id", ""),
                    _get(tf, "child_frame_id", ""),
                    _vec(_get(tr, "translation")),
                    _vec(_get(tr, "rotation"), ("x", "y", "z", "w")),
                )
            )
        return out
    else:  # RigidBodies
        h = _get(msg, "header")
        parent, stamp = _get(h, "frame_id", "") or "world", _stamp(_get(h, "stamp"))
        for rb in _get(msg, "rigidbodies", []) or []:
            pose = _get(rb, "pose")
            out.append(
                (
                    stamp,
                    parent,
                    _get(rb, "rigid_body_name", ""),
                    _vec(_get(pose, "position")),
                    _vec(_get(pose, "orientation"), ("x", "y", "z", "w")),
                )
            )
        return out
    for tf in items:
        rot = _get(tf, "rotation")
        out.append(
            (
                _stamp(_get(tf, "timestamp")),
                _get(tf, "parent_frame_id", ""),
                _get(tf, "child_frame_id", ""),
                _vec(_get(tf, "translation")),
                None if rot is None else _vec(rot, ("x", "y", "z", "w")),
            )
        )
    return out


def _collect(path: str | Path, topics: list[str] | None) -> dict[str, _Track]:
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        from google.protobuf.message import DecodeError
    except ImportError:  # protobuf is needed only for protobuf-encoded streams
        DecodeError = McapError

    src = str(path)
    tracks: dict[str, _Track] = {}
    try:
        with open(path, "rb") as f:
            reader = make_reader(f, decoder_factories=_decoder_factories())
            summary = reader.get_summary()
            if summary is None:
                raise InputError(
                    src, "summary", "the MCAP has no summary section (not finalised?); re-save it with `mcap recover`"
                )
            have = {
                c.topic: summary.schemas[c.schema_id].name if c.schema_id in summary.schemas else "(no schema)"
                for c in summary.channels.values()
            }
            use = [t for t, s in have.items() if s in SUPPORTED and (topics is None or t in topics)]
            if not use:
                listing = ", ".join(f"{t} ({s})" for t, s in sorted(have.items())) or "no topics"
                raise InputError(
                    src, "topics", f"no FrameTransform(s), TFMessage or RigidBodies stream; the file has: {listing}"
                )
            for k, (schema, channel, message, decoded) in enumerate(reader.iter_decoded_messages(topics=use)):
                for stamp, parent, child, t, q in _transforms(schema.name, decoded):
                    _add(tracks, src, channel.topic, k, (stamp, message.log_time * 1e-9), parent, child, t, q)
    except (McapError, OSError, ValueError, DecodeError, EOFError) as e:
        if isinstance(e, InputError):
            raise
        raise InputError(src, "file", f"not a readable MCAP ({type(e).__name__}: {e})") from None
    if not tracks:
        raise InputError(src, "messages", "the transform streams hold zero transforms")
    use_stamps = all(all(st > 0 for st in tr.stamps) for tr in tracks.values())
    for tr in tracks.values():
        tr.times = tr.stamps if use_stamps else tr.log_times
    return tracks


def _add(tracks, src, topic, k, times: tuple[float, float], parent, child, t, q) -> None:
    if not child:
        raise InputError(src, f"{topic} child_frame_id", "is empty", frame=k)
    q = [0.0, 0.0, 0.0, 1.0] if q is None or not any(q) else q
    if not np.all(np.isfinite(t + q)):
        raise InputError(src, f"{topic} {child}", "translation or rotation is NaN or infinite", frame=k)
    tr = tracks.setdefault(child, _Track(parent))
    if tr.parent != parent:
        raise InputError(src, f"{topic} {child}", f"parent changes from {tr.parent!r} to {parent!r}", frame=k)
    tr.stamps.append(times[0])
    tr.log_times.append(times[1])
    tr.pose.append(t + q)


def _order(tracks: dict[str, _Track], src: str) -> list[str]:
    """Child frames with every tracked parent before its children."""
    order: list[str] = []
    state: dict[str, int] = {}

    def visit(name: str) -> None:
        if state.get(name) == 2:
            return
        if state.get(name) == 1:
            raise InputError(src, f"frame {name}", "the transform tree has a cycle")
        state[name] = 1
        if tracks[name].parent in tracks:
            visit(tracks[name].parent)
        state[name] = 2
        order.append(name)

    for name in sorted(tracks):
        visit(name)
    return order


def _sample(tr: _Track, grid: np.ndarray) -> tuple[np.ndarray, Rotation]:
    """Local translation ``[N, 3]`` and rotation of one frame on ``grid`` (hold at the ends)."""
    t = np.asarray(tr.times)
    order = np.argsort(t, kind="stable")
    t, pose = t[order], np.asarray(tr.pose)[order]
    t, last = np.unique(t[::-1], return_index=True)  # keep the last sample of equal stamps
    pose = pose[::-1][last]
    if len(t) == 1:
        return np.repeat(pose[:, :3], len(grid), 0), Rotation.from_quat(np.repeat(pose[:, 3:], len(grid), 0))
    g = np.clip(grid, t[0], t[-1])
    pos = np.stack([np.interp(g, t, pose[:, k]) for k in range(3)], axis=1)
    return pos, Slerp(t, Rotation.from_quat(pose[:, 3:]))(g)


def _infer_fps(tracks: dict[str, _Track], src: str) -> float:
    busiest = max(tracks.values(), key=lambda tr: len(set(tr.times)))
    dt = np.diff(np.unique(busiest.times))
    if len(dt) == 0:
        raise InputError(src, "fps", "every frame has a single sample; pass --fps N")
    fps = 1.0 / float(np.median(dt))
    return float(round(fps)) if abs(fps - round(fps)) < 1e-3 * fps else fps


def read_mcap(path: str | Path, *, fps: float | None = None, topics: list[str] | None = None) -> HumanClip:
    """Transform / rigid-body streams of an MCAP as a :class:`HumanClip` sampled at ``fps``."""
    src = str(path)
    tracks = _collect(path, topics)
    fps = _infer_fps(tracks, src) if fps is None else float(fps)
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(src, "fps", f"must be positive, got {fps}")
    t0 = min(min(tr.times) for tr in tracks.values())
    t1 = max(max(tr.times) for tr in tracks.values())
    grid = t0 + np.arange(int(np.floor((t1 - t0) * fps + 1e-6)) + 1) / fps
    names = _order(tracks, src)
    index = {n: k for k, n in enumerate(names)}
    pos = np.zeros((len(grid), len(names), 3))
    rots: list[Rotation] = []
    for k, name in enumerate(names):
        t_local, r_local = _sample(tracks[name], grid)
        p = index.get(tracks[name].parent)
        if p is None:
            pos[:, k], r = t_local, r_local
        else:
            pos[:, k], r = pos[:, p] + rots[p].apply(t_local), rots[p] * r_local
        rots.append(r)
    quat = np.stack([wxyz_from_rotation(r) for r in rots], axis=1)
    parents = tuple(index.get(tracks[n].parent, -1) for n in names)
    return HumanClip(Skeleton(tuple(names), parents), pos, fps, src, joint_quat=quat)
