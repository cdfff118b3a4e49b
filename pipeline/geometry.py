"""Object geometry references shared by scenes, clips and (later) distance fields.

An object is one of:

* :class:`Primitive` -- box, cylinder, sphere or capsule, with MuJoCo's size
  convention (box: half-extents ``(hx, hy, hz)``; sphere: ``(r,)``; cylinder and
  capsule: ``(r, half_length)`` along local z) and a per-axis ``scale`` applied in
  the object frame, ``x_scaled = diag(scale) @ x``;
* :class:`MeshGeometry` -- a triangle mesh file read by trimesh, with per-axis scale;
* :class:`Chair` -- a composite of boxes (seat, back, four legs) parameterised by
  seat height. Its frame sits on the floor under the seat centre, +x facing forward
  (away from the back), z up.

Geometry is pure data; :mod:`pipeline.scene` turns it into MuJoCo geoms.
"""

from __future__ import annotations

from dataclasses import astuple, dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from pipeline.xp import namespace

PrimitiveKind = Literal["box", "cylinder", "sphere", "capsule"]
_SIZE_LEN = {"box": 3, "sphere": 1, "cylinder": 2, "capsule": 2}


def _scale3(scale) -> tuple[float, float, float]:
    s = tuple(float(v) for v in np.broadcast_to(np.asarray(scale, dtype=float), (3,)))
    if not all(np.isfinite(s)) or min(s) <= 0:
        raise ValueError(f"scale must be three positive finite numbers, got {scale!r}")
    return s  # type: ignore[return-value]


@dataclass(frozen=True)
class Primitive:
    kind: PrimitiveKind
    size: tuple[float, ...]
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)

    def __post_init__(self):
        if self.kind not in _SIZE_LEN:
            raise ValueError(f"primitive kind must be one of {sorted(_SIZE_LEN)}, got {self.kind!r}")
        size = tuple(float(v) for v in self.size)
        if len(size) != _SIZE_LEN[self.kind] or not all(np.isfinite(size)) or min(size) <= 0:
            raise ValueError(f"{self.kind} size must be {_SIZE_LEN[self.kind]} positive numbers, got {self.size!r}")
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "scale", _scale3(self.scale))

    @property
    def half_extents(self) -> np.ndarray:
        """Half-extents of the scaled object's axis-aligned bounding box in its own frame."""
        s = self.size
        if self.kind == "box":
            base = s
        elif self.kind == "sphere":
            base = (s[0],) * 3
        else:  # cylinder / capsule: radius, half-length (the capsule's caps add a radius)
            base = (s[0], s[0], s[1] + (s[0] if self.kind == "capsule" else 0.0))
        return np.asarray(base) * np.asarray(self.scale)

    def scaled(self, factor) -> Primitive:
        return Primitive(self.kind, self.size, tuple(np.asarray(self.scale) * np.broadcast_to(factor, (3,))))

    def as_cylinder(self) -> Primitive:
        """A box drawn as a circular cylinder along z: radius the mean of the box's x and y half-extents, the same
        half-height (both at the box's scale). Circular so that it is MuJoCo's cylinder primitive on every backend:
        a cylinder scaled per axis would be a collision mesh (:mod:`train.envs.mjlab.object`)."""
        if self.kind != "box":
            raise ValueError(f"only a box has a cylinder form, this primitive is a {self.kind}")
        hx, hy, hz = (float(h) for h in self.half_extents)
        return Primitive("cylinder", ((hx + hy) / 2, hz))

    @property
    def volume(self) -> float:
        """The scaled primitive's volume [m^3]."""
        hx, hy, hz = (float(h) for h in self.half_extents)
        r = self.size[0]
        if self.kind == "box":
            return 8 * hx * hy * hz
        if self.kind == "sphere":
            return 4 / 3 * np.pi * hx * hy * hz
        ends = 4 / 3 * np.pi * r**3 if self.kind == "capsule" else 0.0  # the capsule's two half-sphere caps
        return float(np.prod(self.scale)) * (np.pi * r**2 * 2 * self.size[1] + ends)


@dataclass(frozen=True)
class MeshGeometry:
    """A mesh file. ``collision`` says how the physics sees it: ``"hull"`` (one convex
    hull, exact for convex objects such as OMOMO's boxes) or ``"decomposition"``
    (approximate convex decomposition, for concave objects such as tables and chairs)."""

    path: str
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    collision: Literal["hull", "decomposition"] = "hull"

    def __post_init__(self):
        object.__setattr__(self, "path", str(Path(self.path)))
        object.__setattr__(self, "scale", _scale3(self.scale))
        if self.collision not in ("hull", "decomposition"):
            raise ValueError(f"mesh collision must be 'hull' or 'decomposition', got {self.collision!r}")

    def scaled(self, factor) -> MeshGeometry:
        return MeshGeometry(self.path, tuple(np.asarray(self.scale) * np.broadcast_to(factor, (3,))), self.collision)


@dataclass(frozen=True)
class Chair:
    """Seat (a box whose top is at ``seat_height``), a back behind it, four legs."""

    seat_height: float = 0.45
    seat_width: float = 0.45
    seat_depth: float = 0.42
    seat_thickness: float = 0.04
    back_height: float = 0.40
    back_thickness: float = 0.04
    leg_width: float = 0.04

    def __post_init__(self):
        for name, v in self.__dict__.items():
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"chair {name} must be positive, got {v!r}")
        if self.seat_height <= self.seat_thickness:
            raise ValueError(f"chair seat_height {self.seat_height} must exceed seat_thickness {self.seat_thickness}")

    def scaled(self, factor) -> Chair:
        """The chair scaled per axis in its frame (:func:`chair_scaled`)."""
        scale = np.broadcast_to(np.asarray(factor, dtype=float), (3,))[None]
        return Chair(*(float(v) for v in chair_scaled(np.array([astuple(self)]), scale)[0]))

    def parts(self) -> list[tuple[str, Primitive, np.ndarray]]:
        """(name, box, centre in the chair frame) for each part (:func:`chair_boxes`)."""
        half, centre = chair_boxes(np.array([astuple(self)]))
        return [(name, Primitive("box", tuple(half[0, k])), centre[0, k]) for k, name in enumerate(CHAIR_PARTS)]


CHAIR_PARTS = ("seat", "back", "leg0", "leg1", "leg2", "leg3")


def chair_scaled(params, scale):
    """(N, 7) chairs (:class:`Chair`'s fields in order) scaled per axis ``scale`` (N, 3) in their frame: x the
    depths, y the width, z the heights; the legs' width with the smaller of x and y. numpy or torch alike (a restart
    of the mjlab backend scales a batch of chairs)."""
    xp = namespace(params)
    sx, sy, sz = scale[:, 0], scale[:, 1], scale[:, 2]
    return params * xp.stack([sz, sy, sx, sz, sz, sx, xp.minimum(sx, sy)], 1)


def chair_boxes(params):
    """``(half-extents, centres)``, each (N, 6, 3), of N chairs' parts (:data:`CHAIR_PARTS`) in the chair frame:
    the seat (its top at ``seat_height``), the back behind it, a leg under each corner of the seat; ``params``
    (N, 7) :class:`Chair`'s fields in order. numpy or torch alike."""
    xp = namespace(params)
    height, width, depth, thick, back_h, back_t, leg_w = (params[:, i] for i in range(7))
    hw, hd, lw, zero = width / 2, depth / 2, leg_w / 2, 0 * height
    leg_h = height - thick

    def v(x, y, z):
        return xp.stack([x, y, z], 1)

    legs = [(sx, sy) for sx, sy in [(1, 1), (1, -1), (-1, 1), (-1, -1)]]
    half = [v(hd, hw, thick / 2), v(back_t / 2, hw, back_h / 2)] + [v(lw, lw, leg_h / 2)] * 4
    centre = [v(zero, zero, height - thick / 2), v(-hd + back_t / 2, zero, height + back_h / 2)]
    centre += [v(sx * (hd - lw), sy * (hw - lw), leg_h / 2) for sx, sy in legs]
    return xp.stack(half, 1), xp.stack(centre, 1)


ObjectGeometry = Primitive | MeshGeometry | Chair


def variant_label(scale, shape: str = "box") -> str:
    """The name of an object variant (``retarget.augment``): ``x0.6`` (one scale for every axis), ``x0.6,1,1.4`` (per
    axis), with ``-cylinder`` appended for a box drawn as a cylinder; ``x1`` is the object as it is."""
    s = [float(v) for v in np.broadcast_to(np.asarray(scale, dtype=float), (3,))]
    size = f"x{s[0]:g}" if s[0] == s[1] == s[2] else "x" + ",".join(f"{v:g}" for v in s)
    return size + ("-cylinder" if shape == "cylinder" else "")


def provenance_variant(provenance: dict | None) -> str | None:
    """The variant label a clip's provenance records (``provenance["augment"]["label"]``, written by
    ``retarget.augment``); None when the clip's corpus was not augmented."""
    augment = (provenance or {}).get("augment")
    return augment.get("label") if isinstance(augment, dict) else None


def geometry_to_dict(g: ObjectGeometry) -> dict:
    """Plain-JSON description (for dataset cards and episode metadata)."""
    kind = {Primitive: "primitive", MeshGeometry: "mesh", Chair: "chair"}[type(g)]
    return {"type": kind, **{k: (list(v) if isinstance(v, tuple) else v) for k, v in g.__dict__.items()}}


def geometry_from_dict(d: dict) -> ObjectGeometry:
    d = dict(d)
    cls = {"primitive": Primitive, "mesh": MeshGeometry, "chair": Chair}[d.pop("type")]
    return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})


@dataclass(frozen=True)
class ObjectPhysics:
    """Physical properties an object gets in a scene (later stages randomise them): ``mass`` [kg], ``friction``
    (sliding, of the object's contacts with the robot and other objects), ``floor_friction`` (sliding, of its
    contacts with the floor: :func:`pipeline.scene.build_spec` gives them an explicit contact pair;
    :mod:`pipeline.materials` says why the two differ) and ``restitution`` (0: inelastic)."""

    mass: float = 2.0
    friction: float = 0.8
    floor_friction: float = 0.8
    restitution: float = 0.0

    def __post_init__(self):
        for key in ("mass", "friction", "floor_friction"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"object {key} must be a positive number, got {v!r}")
        if not 0 <= self.restitution < 1:
            raise ValueError(f"object restitution must be in [0, 1), got {self.restitution!r}")
