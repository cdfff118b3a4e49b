"""MCAP reader: real files written with foxglove-sdk, mcap and mcap_ros2 writers, read back."""

import json

import foxglove
import numpy as np
import pytest
from foxglove.channels import FrameTransformChannel, FrameTransformsChannel
from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, Timestamp, Vector3
from mcap.writer import Writer
from mcap_ros2.writer import Writer as Ros2Writer
from mocap_paths import expect_input_error
from scipy.spatial.transform import Rotation

from pipeline.readers.mcap_reader import read_mcap
from pipeline.rotations import rotation_from_wxyz

SEP = "=" * 80 + "\n"
TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
VEC = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
QUAT = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
TF_MSG = SEP.join(
    [
        "geometry_msgs/TransformStamped[] transforms\n",
        "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\nTransform transform\n",
        "MSG: geometry_msgs/Transform\nVector3 translation\nQuaternion rotation\n",
        VEC,
        QUAT,
        HEADER,
        TIME,
    ]
)
# mocap4r2_msgs as released (Marker: int8 id_type with USE_NAME/USE_INDEX/USE_BOTH constants).
RIGID_BODIES = SEP.join(
    [
        "std_msgs/Header header\nuint32 frame_number\nmocap4r2_msgs/RigidBody[] rigidbodies\n",
        "MSG: mocap4r2_msgs/RigidBody\nstring rigid_body_name\nmocap4r2_msgs/Marker[] markers\ngeometry_msgs/Pose "
        "pose\n",
        "MSG: mocap4r2_msgs/Marker\nint8 USE_NAME=0\nint8 USE_INDEX=1\nint8 USE_BOTH=2\nint8 id_type\nint32 "
        "marker_index\nstring marker_name\ngeometry_msgs/Point translation\n",
        "MSG: geometry_msgs/Pose\nPoint position\nQuaternion orientation\n",
        POINT,
        QUAT,
        HEADER,
        TIME,
    ]
)


def _stamp(t):
    return dict(sec=int(t), nanosec=int(round((t % 1) * 1e9)))


def _yaw(t):
    return Rotation.from_euler("z", 2.0 * t)


def _tf(parent, child, t, xyz, rot):
    x, y, z, w = rot.as_quat()
    return dict(
        header=dict(stamp=_stamp(t), frame_id=parent),
        child_frame_id=child,
        transform=dict(translation=dict(zip("xyz", xyz)), rotation=dict(x=x, y=y, z=z, w=w)),
    )


def test_ros2_tf_chain_composes_to_world(tmp_path):
    """pelvis (moving, yawing, 100 Hz) -> hand (fixed 0.5 m along the pelvis x axis)."""
    p = tmp_path / "tf.mcap"
    with open(p, "wb") as f:
        w = Ros2Writer(f)
        schema = w.register_msgdef("tf2_msgs/msg/TFMessage", TF_MSG)
        for i in range(50):
            t = 10 + i / 100
            msg = dict(
                transforms=[
                    _tf("world", "pelvis", t, [i / 100, 0, 1.0], _yaw(i / 100)),
                    _tf("pelvis", "hand", t, [0.5, 0, 0], Rotation.identity()),
                ]
            )
            w.write_message("/tf", schema, msg, log_time=int(t * 1e9))
        w.finish()
    c = read_mcap(p)
    assert (
        c.fps == 100.0
        and c.frames == 50
        and c.skeleton.joint_names == ("pelvis", "hand")
        and c.skeleton.parents == (-1, 0)
    )
    s = 0.49
    np.testing.assert_allclose(c.joint_pos[-1, 1], [s + 0.5 * np.cos(2 * s), 0.5 * np.sin(2 * s), 1.0], atol=1e-9)
    assert (rotation_from_wxyz(c.joint_quat[-1, 1])[0].inv() * _yaw(s)).magnitude() < 1e-9


def test_foxglove_protobuf_frame_transforms_with_gap(tmp_path):
    p = tmp_path / "fox.mcap"
    ctx = foxglove.Context()
    with foxglove.open_mcap(p, context=ctx):
        many, single = FrameTransformsChannel("/tfs", context=ctx), FrameTransformChannel("/tf_head", context=ctx)
        for i in range(30):
            stamp = Timestamp(sec=5, nsec=i * 20_000_000)  # 50 Hz
            if not 10 <= i < 15:  # the box is occluded for 5 samples
                box = FrameTransform(
                    timestamp=stamp,
                    parent_frame_id="world",
                    child_frame_id="box",
                    translation=Vector3(x=i * 0.01, y=0, z=0.2),
                )
                many.log(FrameTransforms(transforms=[box]), log_time=i)
            head = FrameTransform(
                timestamp=stamp,
                parent_frame_id="world",
                child_frame_id="head",
                translation=Vector3(x=0, y=0, z=1.7),
                rotation=Quaternion(x=0, y=0, z=np.sin(0.25), w=np.cos(0.25)),
            )
            single.log(head, log_time=i)
    c = read_mcap(p)
    assert c.fps == 50.0 and c.frames == 30 and set(c.skeleton.joint_names) == {"box", "head"}
    box = c.joint_pos[:, c.skeleton.index("box")]
    np.testing.assert_allclose(box[:, 0], np.arange(30) * 0.01, atol=1e-9)  # the gap is filled linearly
    np.testing.assert_allclose(
        c.joint_quat[:, c.skeleton.index("box")], [[1, 0, 0, 0]] * 30
    )  # absent rotation = identity
    np.testing.assert_allclose(
        c.joint_quat[0, c.skeleton.index("head")], [np.cos(0.25), 0, 0, np.sin(0.25)], atol=1e-12
    )
    assert read_mcap(p, fps=25).frames == 15


def _json_mcap(path, messages, schema_name="foxglove.FrameTransform", topic="/tf_json"):
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema(schema_name, "jsonschema", b"{}")
        cid = w.register_channel(topic, "json", sid)
        for i, m in enumerate(messages):
            w.add_message(cid, log_time=1_000 + i * 33_333_333, publish_time=0, data=json.dumps(m).encode())
        w.finish()
    return path


def test_foxglove_json_uses_log_time_without_stamps(tmp_path):
    msgs = [
        dict(
            parent_frame_id="world",
            child_frame_id="wrist",
            translation=dict(x=1, y=2, z=i * 0.1),
            rotation=dict(x=0, y=0, z=0, w=1),
        )
        for i in range(6)
    ]
    c = read_mcap(_json_mcap(tmp_path / "j.mcap", msgs))
    assert c.fps == 30.0 and c.frames == 6
    np.testing.assert_allclose(c.joint_pos[:, 0, 2], np.arange(6) * 0.1, atol=1e-9)


def test_mocap4r2_rigid_bodies(tmp_path):
    p = tmp_path / "rb.mcap"
    with open(p, "wb") as f:
        w = Ros2Writer(f)
        schema = w.register_msgdef("mocap4r2_msgs/msg/RigidBodies", RIGID_BODIES)
        for i in range(12):
            t = 3 + i / 120

            def body(name, x, i=i):
                return dict(
                    rigid_body_name=name,
                    markers=[dict(id_type=0, marker_index=i, marker_name="m1", translation=dict(x=x, y=0, z=0))],
                    pose=dict(position=dict(x=x, y=i * 0.01, z=1.0), orientation=dict(x=0, y=0, z=0, w=1)),
                )

            msg = dict(
                header=dict(stamp=_stamp(t), frame_id="map"),
                frame_number=i,
                rigidbodies=[body("pelvis", 0.0), body("left_hand", 0.3)],
            )
            w.write_message("/rigid_bodies", schema, msg, log_time=int(t * 1e9))
        w.finish()
    c = read_mcap(p)
    assert (
        c.fps == 120.0
        and c.frames == 12
        and c.skeleton.joint_names == ("left_hand", "pelvis")
        and c.skeleton.parents == (-1, -1)
    )
    np.testing.assert_allclose(c.joint_pos[-1, 0], [0.3, 0.11, 1.0], atol=1e-9)


def test_no_transform_stream_lists_topics(tmp_path):
    p = tmp_path / "chat.mcap"
    with open(p, "wb") as f:
        w = Ros2Writer(f)
        schema = w.register_msgdef("std_msgs/msg/String", "string data\n")
        w.write_message("/chatter", schema, dict(data="hi"), log_time=1)
        w.finish()
    expect_input_error(
        lambda: read_mcap(p), tmp_path, file=p, field="topics", match=r"the file has: /chatter \(std_msgs/msg/String\)"
    )


def test_nan_transform_names_topic_frame_and_message(tmp_path):
    msgs = [
        dict(
            parent_frame_id="world",
            child_frame_id="wrist",
            translation=dict(x=0, y=0, z=0),
            rotation=dict(x=0, y=0, z=0, w=1),
        )
    ] * 3
    msgs = msgs + [dict(msgs[0], translation=dict(x=float("nan"), y=0, z=0))]
    p = _json_mcap(tmp_path / "nan.mcap", msgs)
    expect_input_error(lambda: read_mcap(p), tmp_path, file=p, field="/tf_json wrist", frame=3, match="NaN")


@pytest.mark.parametrize("content", [b"", b"definitely not an mcap file"])
def test_not_an_mcap(tmp_path, content):
    p = tmp_path / "bad.mcap"
    p.write_bytes(content)
    expect_input_error(lambda: read_mcap(p), tmp_path, file=p, field="file", match="not a readable MCAP")
