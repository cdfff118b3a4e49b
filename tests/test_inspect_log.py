"""Inspection logs: MCAP files with Foxglove schemas, read back with the ``mcap`` reader.

Foxglove messages are protobuf; each MCAP schema record embeds a ``FileDescriptorSet``, so the
tests decode them with ``google.protobuf`` alone (no ``mcap-protobuf-support`` needed).
"""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import trimesh
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

import pipeline.stage.inspect_log as inspect_log
from pipeline.clip import HumanClip, ObjectTrack, RobotClip, Skeleton
from pipeline.errors import InputError
from pipeline.geometry import Chair, MeshGeometry, Primitive
from pipeline.robot import G1_JOINT_NAMES
from pipeline.stage.inspect_log import object_frame, write_human_log, write_robot_log

FPS = 30.0
T = 20


def _read(path: Path) -> tuple[dict[str, str], dict[str, list[tuple[int, object]]]]:
    """({topic: schema name}, {topic: [(log_time, decoded message)]}) of an MCAP file."""
    classes: dict[int, type] = {}

    def decode(schema, data: bytes):
        if schema.encoding == "jsonschema":
            return json.loads(data)
        assert schema.encoding == "protobuf"
        if schema.id not in classes:
            pool = descriptor_pool.DescriptorPool()
            for f in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
                pool.Add(f)
            classes[schema.id] = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
        return classes[schema.id].FromString(data)

    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        msgs: dict[str, list] = defaultdict(list)
        for schema, channel, msg in reader.iter_messages(log_time_order=True):
            msgs[channel.topic].append((msg.log_time, decode(schema, msg.data)))
    return schemas, msgs


def _box_track(frames: int = T) -> ObjectTrack:
    pose = np.zeros((frames, 7))
    pose[:, 0] = np.linspace(0.5, 1.0, frames)
    pose[:, 2], pose[:, 3] = 0.2, 1.0
    return ObjectTrack("box", Primitive("box", (0.2, 0.15, 0.1)), pose, contact=np.arange(frames) % 2 == 0)


def _robot_clip(objects=None) -> RobotClip:
    qpos = np.zeros((T, 36))
    qpos[:, 0] = np.linspace(0.0, 0.3, T)
    qpos[:, 2], qpos[:, 3] = 0.79, 1.0
    qpos[:, 7 + G1_JOINT_NAMES.index("left_elbow_joint")] = 0.5 * np.sin(np.arange(T) / 3)
    contacts = (np.arange(T) >= 10)[:, None]
    return RobotClip(
        qpos,
        FPS,
        "test",
        objects=(_box_track(),) if objects is None else objects,
        contact_links=("left_wrist_yaw_link",),
        contacts=contacts,
    )


def _check_times(msgs: list[tuple[int, object]]) -> None:
    times = np.array([t for t, _ in msgs])
    assert np.allclose(times, np.arange(T) * 1e9 / FPS, atol=1)
    assert (np.diff(times) > 0).all()


def _transforms(msg) -> dict[str, object]:
    return {t.child_frame_id: t for t in msg.transforms}


def test_robot_log_topics_times_and_poses(tmp_path):
    clip = _robot_clip()
    path = write_robot_log(clip, tmp_path / "sub" / "robot.mcap")
    assert path == tmp_path / "sub" / "robot.mcap" and path.is_file()
    schemas, msgs = _read(path)
    assert schemas == {
        "/tf": "foxglove.FrameTransforms",
        "/scene": "foxglove.SceneUpdate",
        "/contact_markers": "foxglove.SceneUpdate",
        "/contacts": "lessmimic.Contacts",
    }
    assert len(msgs["/scene"]) == 1 and all(len(msgs[t]) == T for t in ("/tf", "/contacts", "/contact_markers"))
    _check_times(msgs["/tf"])
    elbow_rot = []
    for k, (_, m) in enumerate(msgs["/tf"]):
        tfs = _transforms(m)
        assert all(t.parent_frame_id == "world" for t in tfs.values())
        assert len(tfs) == 30 + 1  # 30 G1 bodies + the box
        p = tfs["pelvis"].translation
        assert [p.x, p.y, p.z] == pytest.approx(clip.qpos[k, :3])
        b = tfs[object_frame("box")].translation
        assert [b.x, b.y, b.z] == pytest.approx(clip.objects[0].pose[k, :3])
        assert tfs["pelvis"].timestamp.seconds * 10**9 + tfs["pelvis"].timestamp.nanos == msgs["/tf"][k][0]
        r = tfs["left_elbow_link"].rotation
        elbow_rot.append([r.w, r.x, r.y, r.z])
    assert np.ptp(np.asarray(elbow_rot), axis=0).max() > 0.1  # the sinusoid on the elbow shows
    scene = {e.id: e for e in msgs["/scene"][0][1].entities}
    assert "robot/pelvis" in scene and scene["robot/pelvis"].frame_locked
    assert scene["object/box"].frame_id == object_frame("box")
    size = scene["object/box"].cubes[0].size
    assert [size.x, size.y, size.z] == pytest.approx([0.4, 0.3, 0.2])
    assert sum(len(e.spheres) + len(e.cylinders) for e in scene.values() if e.id.startswith("robot/")) >= 31
    contacts = [m for _, m in msgs["/contacts"]]
    assert [c["contacts"]["left_wrist_yaw_link"] for c in contacts] == list(np.arange(T) >= 10)
    assert [c["objects"]["box"] for c in contacts] == list(np.arange(T) % 2 == 0)
    assert [len(m.entities) for _, m in msgs["/contact_markers"]] == [int(k >= 10) for k in range(T)]


def test_human_log_topics_times_and_skeleton(tmp_path):
    skel = Skeleton(("pelvis", "spine", "head"), (-1, 0, 1))
    pos = np.zeros((T, 3, 3))
    pos[:, :, 2] = [0.9, 1.2, 1.6]
    pos[:, :, 0] = np.linspace(0, 1, T)[:, None]
    contacts = np.zeros((T, 3), bool)
    contacts[5:, 2] = True
    clip = HumanClip(skel, pos, FPS, "test", contacts=contacts, objects=(_box_track(),))
    schemas, msgs = _read(write_human_log(clip, tmp_path / "human.mcap"))
    assert schemas["/tf"] == "foxglove.FrameTransforms" and schemas["/skeleton"] == "foxglove.SceneUpdate"
    assert schemas["/scene"] == "foxglove.SceneUpdate" and len(msgs["/tf"]) == len(msgs["/skeleton"]) == T
    _check_times(msgs["/tf"])
    _check_times(msgs["/skeleton"])
    for k, (_, m) in enumerate(msgs["/tf"]):
        tfs = _transforms(m)
        assert set(tfs) == {"pelvis", "spine", "head", object_frame("box")}
        h = tfs["head"]
        assert [h.translation.x, h.translation.y, h.translation.z] == pytest.approx(pos[k, 2])
        assert [h.rotation.w, h.rotation.x, h.rotation.y, h.rotation.z] == pytest.approx([1, 0, 0, 0])
    entity = msgs["/skeleton"][7][1].entities[0]
    assert len(entity.lines[0].points) == 4  # two bones, parent -> child
    assert entity.lines[0].points[3].z == pytest.approx(1.6)
    assert [s.color.r > 0.95 and s.color.g < 0.2 for s in entity.spheres] == [False, False, True]
    assert msgs["/contacts"][7][1]["contacts"] == {"pelvis": False, "spine": False, "head": True}


def test_chair_and_mesh_objects_are_drawn(tmp_path):
    mesh_file = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=5).export(mesh_file)  # 20480 faces
    pose = np.tile([0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0], (T, 1))
    objects = (
        ObjectTrack("chair", Chair(), pose),
        ObjectTrack("ball", MeshGeometry(str(mesh_file), scale=(0.2, 0.2, 0.2)), pose),
    )
    _, msgs = _read(write_robot_log(_robot_clip(objects), tmp_path / "objects.mcap"))
    scene = {e.id: e for e in msgs["/scene"][0][1].entities}
    assert len(scene["object/chair"].cubes) == 6
    tri = scene["object/ball"].triangles[0]
    assert 0 < len(tri.indices) // 3 <= inspect_log.MAX_MESH_FACES
    radii = np.linalg.norm([[p.x, p.y, p.z] for p in tri.points], axis=1)
    assert radii == pytest.approx(0.2, abs=0.01)


def test_failed_write_leaves_no_file(tmp_path, monkeypatch):
    pose = np.tile([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], (T, 1))
    missing = ObjectTrack("ghost", MeshGeometry(str(tmp_path / "missing.obj")), pose)
    with pytest.raises(InputError, match="missing.obj"):
        write_robot_log(_robot_clip((missing,)), tmp_path / "bad.mcap")
    assert list(tmp_path.iterdir()) == []

    # A failure mid-way (after some frames were logged) leaves an older file untouched.
    old = tmp_path / "robot.mcap"
    old.write_bytes(b"previous")
    calls = {"n": 0}
    real_tf = inspect_log._tf

    def flaky(*args):
        calls["n"] += 1
        if calls["n"] > 200:
            raise RuntimeError("interrupted")
        return real_tf(*args)

    monkeypatch.setattr(inspect_log, "_tf", flaky)
    with pytest.raises(RuntimeError, match="interrupted"):
        write_robot_log(_robot_clip(), old)
    assert calls["n"] > 200 and old.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["robot.mcap"]
