"""Object tracks <-> dataset features, shared by the robot and human clip conversions (:mod:`pipeline.dataset.clips`).

Per object ``<name>``: ``object.<name>.pose`` -- pose (x, y, z, qw, qx, qy, qz) in the world frame, and
``object.<name>.contact`` (1 bool) when any clip has contact flags for that object. Geometry, mass,
friction, source and whether the clip had contact flags go into the episode meta (``meta["objects"]``).
"""

from __future__ import annotations

import numpy as np

from pipeline.clip import ObjectTrack
from pipeline.dataset.schema import Episode, Feature
from pipeline.errors import InputError
from pipeline.geometry import geometry_from_dict, geometry_to_dict

POSE_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz")


def object_features(clips) -> tuple[list[Feature], tuple[str, ...], set[str]]:
    """The object features of ``clips`` (which must name the same objects), the object names and the
    names of the objects that some clip has contact flags for."""
    for c in clips:
        names = tuple(o.name for o in c.objects)
        if names != tuple(o.name for o in clips[0].objects):
            raise InputError(
                c.source, "objects", f"{list(names)} differ from {clips[0].source}; one dataset has one feature spec"
            )
        for n in names:
            if not n or "/" in n:
                raise InputError(c.source, "objects", f"object name {n!r} is empty or contains '/'")
    names = tuple(o.name for o in clips[0].objects)
    with_contact = {o.name for c in clips for o in c.objects if o.contact is not None}
    feats = []
    for n in names:
        feats.append(
            Feature(f"object.{n}.pose", "float32", POSE_NAMES, f"pose of object {n!r}: position, quaternion wxyz", "m")
        )
        if n in with_contact:
            feats.append(Feature(f"object.{n}.contact", "bool", ("contact",), f"object {n!r} is in contact"))
    return feats, names, with_contact


def object_data(clip, with_contact: set[str]) -> tuple[dict, list[dict]]:
    """One clip's object columns (contact flags all False for an object in ``with_contact`` that has
    none) and its per-object episode meta."""
    data, meta = {}, []
    for o in clip.objects:
        data[f"object.{o.name}.pose"] = o.pose
        if o.name in with_contact:
            data[f"object.{o.name}.contact"] = np.zeros(o.frames, bool) if o.contact is None else o.contact
        meta.append(
            {
                "name": o.name,
                "geometry": geometry_to_dict(o.geometry),
                "mass": o.mass,
                "friction": o.friction,
                "source": o.source,
                "has_contact": o.contact is not None,
            }
        )
    return data, meta


def objects_from_episode(ep: Episode, source: str) -> tuple[ObjectTrack, ...]:
    """The object tracks back from an episode written with :func:`object_data`."""
    out = []
    for m in ep.meta.get("objects", []):
        c = ep.data.get(f"object.{m['name']}.contact")
        contact = c[:, 0].astype(bool) if c is not None and m.get("has_contact") else None
        pose = ep.data[f"object.{m['name']}.pose"].astype(np.float64)
        try:
            geometry = geometry_from_dict(m["geometry"])
        except (ValueError, KeyError, TypeError) as exc:  # e.g. a zero scale written by another tool
            raise InputError(source, f"object {m['name']} geometry", str(exc)) from None
        out.append(
            ObjectTrack(m["name"], geometry, pose, contact, m.get("mass"), m.get("source", source), m.get("friction"))
        )
    return tuple(out)
