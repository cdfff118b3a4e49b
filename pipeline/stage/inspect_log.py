"""Per-clip inspection logs: MCAP files with Foxglove schemas, viewable without writing code.

Why MCAP + Foxglove and not a Rerun ``.rrd``: MCAP is an open, versioned container format
that Foxglove Studio opens directly, that our own ``mcap`` reader (and rosbag2 tooling, whose
default storage it is) reads back, and whose Foxglove schemas (protobuf, embedded in the file)
are stable across SDK versions. ``.rrd`` files are tied to the rerun-sdk version that wrote them.

Topics (log time = ``frame / fps`` in nanoseconds, also the messages' own timestamps):

* ``/tf`` (``foxglove.FrameTransforms``, one per frame): ``world -> <body>`` for every G1 body
  (MuJoCo forward kinematics of ``qpos``; frame ids are the ``g1.xml`` body names, e.g.
  ``pelvis``) or ``world -> <joint>`` for every human joint (global position; global
  orientation when the clip has one, identity otherwise), plus ``world -> object/<name>``.
* ``/scene`` (``foxglove.SceneUpdate``, once at t=0): frame-locked shapes that follow ``/tf``:
  the robot's collision geoms (spheres; capsules drawn as a cylinder and two spheres) and the
  objects (boxes, spheres, cylinders; a chair's boxes; a mesh as a triangle list, vertex-clustered
  down to at most :data:`MAX_MESH_FACES` faces for display -- the physics uses the full mesh).
* ``/skeleton`` (human, ``foxglove.SceneUpdate`` per frame): parent->child line segments and a
  sphere per joint, red while that joint is in contact.
* ``/contact_markers`` (robot, ``foxglove.SceneUpdate`` per frame): a red sphere on each link
  in contact.
* ``/contacts`` (JSON, schema ``lessmimic.Contacts``, per frame): ``{"frame": k, "contacts":
  {link-or-joint: bool}, "objects": {object: bool}}`` -- plot it in a Plot or State panel.

To view: Foxglove Studio -> "Open local file" -> pick the ``.mcap``; add a 3D panel, set its
display frame to ``world``, and enable the topics above. Every write is atomic (a temporary
file in the same folder, then ``os.replace``), so an interrupted run leaves no half file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable
from functools import lru_cache
from pathlib import Path

import foxglove
import mujoco
import numpy as np
from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from pipeline.clip import HumanClip, ObjectTrack, RobotClip
from pipeline.collision_mesh import load_mesh
from pipeline.geometry import Chair, MeshGeometry, Primitive
from pipeline.scene import Scene, build_scene

WORLD = "world"
MAX_MESH_FACES = 20_000
_ROBOT_RGBA = Color(r=0.6, g=0.65, b=0.75, a=0.9)
_OBJECT_RGBA = Color(r=0.8, g=0.5, b=0.2, a=0.9)
_BONE_RGBA = Color(r=0.2, g=0.6, b=1.0, a=1.0)
_JOINT_RGBA = Color(r=0.9, g=0.9, b=0.9, a=1.0)
_CONTACT_RGBA = Color(r=1.0, g=0.1, b=0.1, a=1.0)
_CONTACT_SCHEMA = foxglove.Schema(
    name="lessmimic.Contacts",
    encoding="jsonschema",
    data=json.dumps(
        {
            "type": "object",
            "properties": {
                "frame": {"type": "integer"},
                "contacts": {"type": "object", "additionalProperties": {"type": "boolean"}},
                "objects": {"type": "object", "additionalProperties": {"type": "boolean"}},
            },
        }
    ).encode(),
)


def object_frame(name: str) -> str:
    """The ``/tf`` frame id of object ``name``."""
    return f"object/{name}"


def _vec(v) -> Vector3:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quat(q_wxyz) -> Quaternion:
    return Quaternion(w=float(q_wxyz[0]), x=float(q_wxyz[1]), y=float(q_wxyz[2]), z=float(q_wxyz[3]))


def _pose(p=(0.0, 0.0, 0.0), q_wxyz=(1.0, 0.0, 0.0, 0.0)) -> Pose:
    return Pose(position=_vec(p), orientation=_quat(q_wxyz))


def _stamp(ns: int) -> Timestamp:
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _tf(ns: int, child: str, p, q_wxyz) -> FrameTransform:
    return FrameTransform(
        timestamp=_stamp(ns), parent_frame_id=WORLD, child_frame_id=child, translation=_vec(p), rotation=_quat(q_wxyz)
    )


def _capsule(pose_p: np.ndarray, pose_q: np.ndarray, r: np.ndarray, h: float, color: Color) -> dict[str, list]:
    """A capsule along the local z of (pose_p, pose_q), radius ``r`` (per axis), half-length ``h``."""
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, pose_q)
    axis = rot.reshape(3, 3)[:, 2] * h
    return {
        "cylinders": [
            CylinderPrimitive(
                pose=_pose(pose_p, pose_q),
                size=_vec([2 * r[0], 2 * r[1], 2 * h]),
                bottom_scale=1,
                top_scale=1,
                color=color,
            )
        ],
        "spheres": [
            SpherePrimitive(pose=_pose(pose_p + s * axis, pose_q), size=_vec(2 * r), color=color) for s in (-1, 1)
        ],
    }


def _decimate(v: np.ndarray, f: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering on a shrinking grid until at most ``max_faces`` faces remain (display only)."""
    cells = max(2, int(np.sqrt(max_faces)))
    lo, extent = v.min(0), float(np.ptp(v, axis=0).max()) or 1.0
    while len(f) > max_faces and cells >= 2:
        _, inv, counts = np.unique(
            np.floor((v - lo) / (extent / cells)).astype(np.int64), axis=0, return_inverse=True, return_counts=True
        )
        inv = inv.reshape(-1)
        nf = inv[f]
        nf = nf[(nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])]
        nf = np.unique(nf, axis=0)
        nv = np.zeros((len(counts), 3))
        np.add.at(nv, inv, v)
        v, f, cells = nv / counts[:, None], nf, int(cells * 0.7)
    return v, f


def _object_entity(obj: ObjectTrack) -> SceneEntity:
    """The object's shape in its own frame (``object/<name>``), frame-locked."""
    geo, prims = obj.geometry, {"cubes": [], "spheres": [], "cylinders": [], "triangles": []}
    if isinstance(geo, Primitive):
        s, sc = np.asarray(geo.size), np.asarray(geo.scale)
        if geo.kind == "box":
            prims["cubes"].append(CubePrimitive(pose=_pose(), size=_vec(2 * s * sc), color=_OBJECT_RGBA))
        elif geo.kind == "sphere":
            prims["spheres"].append(SpherePrimitive(pose=_pose(), size=_vec(2 * s[0] * sc), color=_OBJECT_RGBA))
        elif geo.kind == "cylinder":
            prims["cylinders"].append(
                CylinderPrimitive(
                    pose=_pose(), size=_vec(2 * s[[0, 0, 1]] * sc), bottom_scale=1, top_scale=1, color=_OBJECT_RGBA
                )
            )
        else:
            for k, v in _capsule(np.zeros(3), np.array([1.0, 0, 0, 0]), s[0] * sc, s[1] * sc[2], _OBJECT_RGBA).items():
                prims[k] += v
    elif isinstance(geo, Chair):
        for _, box, centre in geo.parts():
            prims["cubes"].append(
                CubePrimitive(pose=_pose(centre), size=_vec(2 * np.asarray(box.size)), color=_OBJECT_RGBA)
            )
    elif isinstance(geo, MeshGeometry):
        mesh = load_mesh(geo.path)  # InputError if missing or unreadable
        v, f = _decimate(np.asarray(mesh.vertices) * np.asarray(geo.scale), np.asarray(mesh.faces), MAX_MESH_FACES)
        prims["triangles"].append(
            TriangleListPrimitive(
                pose=_pose(),
                points=[Point3(x=a, y=b, z=c) for a, b, c in v.tolist()],
                color=_OBJECT_RGBA,
                indices=f.reshape(-1).tolist(),
            )
        )
    else:
        raise TypeError(f"object {obj.name}: unsupported geometry {type(geo).__name__}")
    return SceneEntity(
        timestamp=_stamp(0), frame_id=object_frame(obj.name), id=f"object/{obj.name}", frame_locked=True, **prims
    )


def _robot_entities(m: mujoco.MjModel, bodies: list[int]) -> list[SceneEntity]:
    """The robot's collision geoms (spheres and capsules) in their bodies' frames, frame-locked."""
    out = []
    for b in bodies:
        prims: dict[str, list] = {"spheres": [], "cylinders": []}
        for g in range(m.ngeom):
            if m.geom_bodyid[g] != b or not m.geom_contype[g]:
                continue
            p, q, size = m.geom_pos[g], m.geom_quat[g], m.geom_size[g]
            if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE:
                prims["spheres"].append(
                    SpherePrimitive(pose=_pose(p, q), size=_vec([2 * size[0]] * 3), color=_ROBOT_RGBA)
                )
            elif m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE:
                for k, v in _capsule(p, q, np.full(3, size[0]), float(size[1]), _ROBOT_RGBA).items():
                    prims[k] += v
        if prims["spheres"] or prims["cylinders"]:
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
            out.append(SceneEntity(timestamp=_stamp(0), frame_id=name, id=f"robot/{name}", frame_locked=True, **prims))
    return out


@lru_cache(maxsize=1)
def _default_scene() -> Scene:
    return build_scene()


def _atomic_mcap(path: Path, body: Callable[[foxglove.Context], None]) -> Path:
    """Run ``body`` against a private logging context recorded to a temp file, then move it in place."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        ctx = foxglove.Context()
        with foxglove.open_mcap(tmp, allow_overwrite=True, context=ctx):
            body(ctx)
        os.replace(tmp, path)
    except OSError as exc:  # the MCAP writer's errors name no file: the one line names the one asked for
        tmp.unlink(missing_ok=True)
        if exc.filename is not None:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _times(frames: int, fps: float) -> list[int]:
    return [int(round(k * 1e9 / fps)) for k in range(frames)]


def _log_static(ctx: foxglove.Context, entities: Iterable[SceneEntity]) -> None:
    SceneUpdateChannel("/scene", context=ctx).log(SceneUpdate(entities=list(entities)), log_time=0)


def _contacts_msg(k: int, names: Iterable[str], flags, objects: tuple[ObjectTrack, ...]) -> dict:
    return {
        "frame": k,
        "contacts": {n: bool(c) for n, c in zip(names, flags)},
        "objects": {o.name: bool(o.contact[k]) for o in objects if o.contact is not None},
    }


def _delete_all(ns: int) -> SceneEntityDeletion:
    return SceneEntityDeletion(timestamp=_stamp(ns), type=SceneEntityDeletionType.All)


def write_robot_log(clip: RobotClip, path: Path, *, scene: Scene | None = None) -> Path:
    """Write ``clip`` as an MCAP inspection log at ``path`` (see the module docstring); returns ``path``."""
    scene = _default_scene() if scene is None else scene
    m = scene.model
    pelvis = m.body("pelvis").id
    bodies = [b for b in range(m.nbody) if m.body_rootid[b] == pelvis]
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in bodies]
    body_of = {n: b for n, b in zip(names, bodies)}
    static = _robot_entities(m, bodies) + [_object_entity(o) for o in clip.objects]
    d = mujoco.MjData(m)

    def body(ctx: foxglove.Context) -> None:
        _log_static(ctx, static)
        tf, markers = FrameTransformsChannel("/tf", context=ctx), SceneUpdateChannel("/contact_markers", context=ctx)
        contacts = foxglove.Channel("/contacts", schema=_CONTACT_SCHEMA, message_encoding="json", context=ctx)
        for k, ns in enumerate(_times(clip.frames, clip.fps)):
            d.qpos[: clip.qpos.shape[1]] = clip.qpos[k]
            mujoco.mj_kinematics(m, d)
            tfs = [_tf(ns, n, d.xpos[b], d.xquat[b]) for n, b in zip(names, bodies)]
            tfs += [_tf(ns, object_frame(o.name), o.pose[k, :3], o.pose[k, 3:]) for o in clip.objects]
            tf.log(FrameTransforms(transforms=tfs), log_time=ns)
            flags = clip.contacts[k] if clip.contacts is not None else np.zeros(len(clip.contact_links), bool)
            spheres = [
                SceneEntity(
                    timestamp=_stamp(ns),
                    frame_id=n,
                    id=f"contact/{n}",
                    frame_locked=True,
                    spheres=[SpherePrimitive(pose=_pose(), size=_vec([0.08] * 3), color=_CONTACT_RGBA)],
                )
                for n, c in zip(clip.contact_links, flags)
                if c and n in body_of
            ]
            markers.log(SceneUpdate(deletions=[_delete_all(ns)], entities=spheres), log_time=ns)
            contacts.log(_contacts_msg(k, clip.contact_links, flags, clip.objects), log_time=ns)

    return _atomic_mcap(path, body)


def write_human_log(clip: HumanClip, path: Path) -> Path:
    """Write ``clip`` as an MCAP inspection log at ``path`` (see the module docstring); returns ``path``."""
    joints, parents = clip.skeleton.joint_names, clip.skeleton.parents
    bone_idx = np.asarray([(p, j) for j, p in enumerate(parents) if p >= 0], dtype=int).reshape(
        -1
    )  # parent, child, ...
    static = [_object_entity(o) for o in clip.objects]
    identity = np.array([1.0, 0.0, 0.0, 0.0])

    def body(ctx: foxglove.Context) -> None:
        _log_static(ctx, static)
        tf, skel = FrameTransformsChannel("/tf", context=ctx), SceneUpdateChannel("/skeleton", context=ctx)
        contacts = foxglove.Channel("/contacts", schema=_CONTACT_SCHEMA, message_encoding="json", context=ctx)
        for k, ns in enumerate(_times(clip.frames, clip.fps)):
            pos = clip.joint_pos[k]
            quat = clip.joint_quat[k] if clip.joint_quat is not None else [identity] * len(joints)
            tfs = [_tf(ns, n, pos[j], quat[j]) for j, n in enumerate(joints)]
            tfs += [_tf(ns, object_frame(o.name), o.pose[k, :3], o.pose[k, 3:]) for o in clip.objects]
            tf.log(FrameTransforms(transforms=tfs), log_time=ns)
            flags = clip.contacts[k] if clip.contacts is not None else np.zeros(len(joints), bool)
            pts = [Point3(x=x, y=y, z=z) for x, y, z in pos[bone_idx].tolist()]
            entity = SceneEntity(
                timestamp=_stamp(ns),
                frame_id=WORLD,
                id="skeleton",
                lines=[
                    LinePrimitive(
                        type=LinePrimitiveLineType.LineList, pose=_pose(), thickness=0.02, points=pts, color=_BONE_RGBA
                    )
                ]
                if pts
                else [],
                spheres=[
                    SpherePrimitive(
                        pose=_pose(pos[j]), size=_vec([0.05] * 3), color=_CONTACT_RGBA if flags[j] else _JOINT_RGBA
                    )
                    for j in range(len(joints))
                ],
            )
            skel.log(SceneUpdate(entities=[entity]), log_time=ns)
            contacts.log(_contacts_msg(k, joints, flags, clip.objects), log_time=ns)

    return _atomic_mcap(path, body)
