"""Object tracks <-> dataset features, shared by the robot and human clip conversions (:mod:`pipeline.dataset.clips`).

Columns are named by the object's role in the clip, not by its mesh, so that one dataset holds episodes of
different objects (a box, a chair, a table), as a training corpus must: the clip's first object is
``object``, further ones ``object_2``, ``object_3``, ... (:func:`object_column`). Per object: ``<column>.pose``
-- pose (x, y, z, qw, qx, qy, qz) in the world frame -- and ``<column>.contact`` (1 bool) when any clip has
contact flags for it. Which object it is (its name, geometry with mesh path and scale, mass, friction,
source) and whether the clip had contact flags go into the episode meta (``meta["objects"]``, with the
``column``); :func:`objects_note` summarises them for the dataset card. Datasets written before roles
(columns ``object.<name>.pose``, meta without ``column``) read back as they were.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.clip import ObjectTrack
from pipeline.dataset.schema import Episode, Feature
from pipeline.errors import InputError
from pipeline.geometry import geometry_from_dict, geometry_to_dict

POSE_NAMES = ("x", "y", "z", "qw", "qx", "qy", "qz")


def object_column(k: int) -> str:
    """The column prefix of a clip's ``k``-th object (0-based): ``object``, ``object_2``, ``object_3``, ..."""
    return "object" if k == 0 else f"object_{k + 1}"


def object_features(clips) -> tuple[list[Feature], tuple[str, ...], set[str]]:
    """The object features of ``clips`` (which must have the same number of objects), the column prefixes
    and the prefixes of the objects that some clip has contact flags for."""
    n = len(clips[0].objects)
    for c in clips:
        if len(c.objects) != n:
            raise InputError(
                c.source,
                "objects",
                f"{len(c.objects)} object(s) ({[o.name for o in c.objects]}), {clips[0].source} has {n}: the clips of "
                "one dataset hold the same number of objects",
            )
        for o in c.objects:
            if not o.name or "/" in o.name:
                raise InputError(c.source, "objects", f"object name {o.name!r} is empty or contains '/'")
    columns = tuple(object_column(k) for k in range(n))
    with_contact = {object_column(k) for c in clips for k, o in enumerate(c.objects) if o.contact is not None}
    feats = []
    for k, col in enumerate(columns):
        which = "the clip's object" if k == 0 else f"the clip's object {k + 1}"
        feats.append(Feature(f"{col}.pose", "float32", POSE_NAMES, f"pose of {which}: position, quaternion wxyz", "m"))
        if col in with_contact:
            feats.append(Feature(f"{col}.contact", "bool", ("contact",), f"{which} is in contact"))
    return feats, columns, with_contact


def object_data(clip, with_contact: set[str]) -> tuple[dict, list[dict]]:
    """One clip's object columns (contact flags all False for an object in ``with_contact`` that has
    none) and its per-object episode meta."""
    data, meta = {}, []
    for k, o in enumerate(clip.objects):
        col = object_column(k)
        data[f"{col}.pose"] = o.pose
        if col in with_contact:
            data[f"{col}.contact"] = np.zeros(o.frames, bool) if o.contact is None else o.contact
        meta.append(
            {
                "column": col,
                "name": o.name,
                "geometry": geometry_to_dict(o.geometry),
                "mass": o.mass,
                "friction": o.friction,
                "floor_friction": o.floor_friction,
                "material": o.material,
                "source": o.source,
                "has_contact": o.contact is not None,
            }
        )
    return data, meta


def objects_from_episode(ep: Episode, source: str) -> tuple[ObjectTrack, ...]:
    """The object tracks back from an episode written with :func:`object_data`."""
    out = []
    for m in ep.meta.get("objects", []):
        col = episode_column(m)
        c = ep.data.get(f"{col}.contact")
        contact = c[:, 0].astype(bool) if c is not None and m.get("has_contact") else None
        pose = ep.data[f"{col}.pose"].astype(np.float64)
        try:
            geometry = geometry_from_dict(m["geometry"])
        except (ValueError, KeyError, TypeError) as exc:  # e.g. a zero scale written by another tool
            raise InputError(source, f"object {m['name']} geometry", str(exc)) from None
        out.append(
            ObjectTrack(
                m["name"],
                geometry,
                pose,
                contact,
                m.get("mass"),
                m.get("source", source),
                m.get("friction"),
                m.get("floor_friction"),
                m.get("material", ""),
            )
        )
    return tuple(out)


def episode_column(meta: dict) -> str:
    """An object's column prefix from its episode meta (``object.<name>`` in datasets written before roles)."""
    return meta.get("column", f"object.{meta['name']}")


def objects_note(clips) -> str:
    """One dataset-card line: which objects the episodes hold, by column, with their geometry."""
    seen: dict[tuple[str, str], int] = {}
    for c in clips:
        for k, o in enumerate(c.objects):
            g = geometry_to_dict(o.geometry)
            what = Path(g["path"]).name if "path" in g else g.get("kind", g["type"])
            scale = g.get("scale")
            label = f"{o.name} ({what}" + (f", scale {scale}" if scale not in (None, [1.0, 1.0, 1.0]) else "") + ")"
            key = (object_column(k), label)
            seen[key] = seen.get(key, 0) + 1
    if not seen:
        return "No objects."
    parts = [f"`{col}`: {label} in {n} episode(s)" for (col, label), n in seen.items()]
    return (
        "Objects are columns by role (`object.*` the clip's object), not by mesh; which object an episode holds "
        "(name, geometry, mass, hand and floor friction, material) is in its metadata "
        "(`meta/lessmimic_episodes.jsonl`, `objects`). " + "; ".join(parts) + "."
    )
