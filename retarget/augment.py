"""Geometry augmentation: one demonstration -> variants of it at other object sizes and shapes, each solved anew so
that the robot's contacts keep their place on the object's surface (OmniRetarget's interaction-preserving
augmentation, here before physicalize: every variant is then simulated and validated like any clip).

A :class:`Variant` is a per-axis scale ``S = diag(s)`` of the clip's object (object 0: the one the hands, the seat
or the pelvis touch) in its own frame, and a shape: ``box`` (the object's own shape) or ``cylinder`` (a primitive
box drawn as a circular cylinder, :meth:`pipeline.geometry.Primitive.as_cylinder`, the shape post-training draws).

**Contacts carried** (:meth:`VariantMap.carry`). A contact link's target ``p`` at frame ``t`` (object pose ``c_t,
R_t``) sits in the object's frame at ``u = R_t^T (p - c_t)``, its nearest surface point ``x = u - phi(u) grad(u)``
and its offset from the surface ``e = u - x``. On the variant it goes to ``u' = S x + e``, then along the variant's
field gradient to the same distance from its surface, ``u'' = u' - grad'(u') (phi'(u') - phi(u))`` (two steps):
for a box scaled per axis the faces keep their normals and ``u'`` is already there; a cylinder moves it onto its
side. The contact's place scales with the object: hands halfway up a box's sides stay halfway up, a pelvis on a
seat stays on the seat, at the seat's new height.

**Placement.** The object is scaled about its contact anchor ``a`` (the mean surface point ``x`` over the contact
frames and links, object frame): the variant's origin is ``c'_t = c_t + R_t (a - S a)_xy + dz e_z``, so the
anchor keeps its horizontal place and the robot walks where it walked; ``dz`` keeps the object's lowest point at
frame 0 where it was (a box resting on the floor still rests on it). A larger object would then reach into the body
parts that never touch it (a 1.4x box's near face into the squatting knees, the box into the torso once lifted, a
deeper seat into the shins): the shift grows horizontally, away from the body, until those parts are as far from
the variant as they were from the object, up to :data:`CLEARANCE_M` (:func:`_cleared`), with one shift while the
object rests where it started (it must not move untouched) and another, blended in as the hands lift it
(:func:`lifted_weight`), while it is held.

**Targets.** Each contact link's target moves by ``d_t = c'_t + R_t u''_t - p_t``, weighted by ``w_t``: 1 on its
contact frames, falling to 0 over :data:`RAMP_S` before and after them (minimum jerk), so the reach into the
grasp and out of it bends smoothly. The rest of the body follows the contacts' mean vertical move ``dz_t`` by a
fraction per body part (:data:`FOLLOW`): reaching a lower grip bends the trunk and the knees, sitting on a lower
seat lowers the whole upper body; the feet stay where they were. The IK then solves the clip as usual (its contact
task closes the remaining gap); where the G1 cannot reach, its contact residual says so in the metrics.

**Mass** (:func:`variant_mass`): constant density, capped at the clip's own mass, ``m' = m min(1, V'/V)``: a
smaller object is lighter by its volume; a larger one is as heavy as the demonstrated one (the mass this motion is
known to move: the synthetic PickUp's 1.5 kg is the most the G1 lifts that way, ``ingest.synthetic.tasks``), and
the cap is reported per variant (``mass_capped``, ``density_mass``), never hidden.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import distance_transform_edt

from pipeline.clip import ObjectTrack
from pipeline.collision_mesh import load_mesh
from pipeline.distance.field import ObjectField
from pipeline.errors import InputError
from pipeline.geometry import Chair, ObjectGeometry, Primitive, variant_label
from pipeline.rotations import from_pose_frame, pose_rotations, to_pose_frame
from pipeline.take import geometry_field
from retarget.mapping import G1_ROLES
from retarget.objects import object_bottom
from retarget.targets import IKTargets

SHAPES = ("box", "cylinder")
SCALE_RANGE = (0.2, 3.0)  # a variant's per-axis scale: beyond this the G1's reach is not the question any more
CLEAR_KINDS = ("pelvis", "torso", "thigh", "shank", "foot")  # body parts a variant must not reach into
CLEARANCE_M = 0.15  # the clearance kept between the variant and those parts where the object was that far or more
LIFTED_M = 0.1  # an object this far above where it started is held up: the hands carry it
CLEARANCE_STEPS = 3  # pushes of the variant clear of the body (each can only add to the last: a few suffice)
RAMP_S = 0.8  # s over which a contact's move fades in before the contact and out after it
# The fraction of the contacts' mean vertical move each non-contact body part follows, by what leads: the hands
# (a grip lower or higher on the object: the trunk bends, the knees give) or the pelvis (a lower or higher seat:
# the upper body rides with the pelvis). Feet never move.
FOLLOW = {
    "hand": {"pelvis": 0.5, "thigh": 0.5, "shank": 0.25, "torso": 0.75, "upper_arm": 0.75, "forearm": 0.9, "hand": 1.0},
    "pelvis": {"pelvis": 1.0, "thigh": 1.0, "shank": 0.5, "torso": 1.0, "upper_arm": 1.0, "forearm": 1.0, "hand": 1.0},
}


@dataclass(frozen=True)
class Variant:
    """One augmentation: the object scaled per axis by ``scale`` in its frame, in ``shape`` (module docstring)."""

    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    shape: str = "box"

    def __post_init__(self):
        object.__setattr__(self, "scale", _checked(self.scale, self.shape, None))

    @property
    def identity(self) -> bool:
        """The demonstration as it is (scale 1, own shape): retargeted exactly as without augmentation."""
        return self.shape == "box" and self.scale == (1.0, 1.0, 1.0)

    @property
    def label(self) -> str:
        """:func:`pipeline.geometry.variant_label`: ``x0.6``, ``x0.6,1,1.4`` per axis, ``-cylinder`` appended."""
        return variant_label(self.scale, self.shape)

    def to_dict(self) -> dict:
        return {"label": self.label, "scale": list(self.scale), "shape": self.shape}


def _checked(scale, shape: str, source: str | None) -> tuple[float, float, float]:
    """The per-axis ``scale`` as three floats in :data:`SCALE_RANGE`, ``shape`` one of :data:`SHAPES`; otherwise a
    one-line :class:`InputError` naming ``source`` and the command-line field."""
    s = tuple(float(v) for v in np.broadcast_to(np.asarray(scale, dtype=float), (3,)))
    lo, hi = SCALE_RANGE
    if not all(np.isfinite(s)) or not all(lo <= v <= hi for v in s):
        raise InputError(source, "--augment-scales", f"{scale!r} is outside {lo}-{hi} (per axis)")
    if shape not in SHAPES:
        raise InputError(source, "--augment-shapes", f"unknown shape {shape!r} (known: {', '.join(SHAPES)})")
    return s  # type: ignore[return-value]


def parse_variants(scales: str, shapes: str = "box") -> tuple[Variant, ...]:
    """The variants of ``scales`` (comma list; a per-axis scale is ``sx:sy:sz``) times ``shapes`` (comma list of
    :data:`SHAPES`), in that order; a bad item is one :class:`InputError` line naming the field."""
    out = []
    shape_list = [s.strip() for s in shapes.split(",") if s.strip()]
    if not shape_list:
        raise InputError(shapes, "--augment-shapes", "empty (expected e.g. box or box,cylinder)")
    scale_list = [s.strip() for s in scales.split(",") if s.strip()]
    if not scale_list:
        raise InputError(scales, "--augment-scales", "empty (expected e.g. 0.6,1,1.4 or 0.6:1:1.4)")
    for text in scale_list:
        try:
            value = [float(v) for v in text.split(":")]
        except ValueError:
            raise InputError(scales, "--augment-scales", f"{text!r} is not a number or sx:sy:sz") from None
        if len(value) not in (1, 3) or min(value) <= 0:
            raise InputError(scales, "--augment-scales", f"{text!r}: a scale is one or three positive numbers")
        for shape in shape_list:
            v = Variant(_checked(value, shape, scales if shape in SHAPES else shapes), shape)
            if v.label in {o.label for o in out}:
                raise InputError(scales, "--augment-scales", f"variant {v.label} is listed twice")
            out.append(v)
    return tuple(out)


def not_applicable(geometry: ObjectGeometry | None, variant: Variant) -> str | None:
    """Why ``variant`` cannot be made of a clip whose object is ``geometry`` (None: no object), or None."""
    if variant.identity:
        return None
    if geometry is None:
        return f"variant {variant.label} varies the object; this clip has none"
    if variant.shape == "cylinder" and not (isinstance(geometry, Primitive) and geometry.kind == "box"):
        return f"variant {variant.label}: only a primitive box has a cylinder form, this object is {_kind(geometry)}"
    return None


def _kind(g: ObjectGeometry) -> str:
    return f"a {g.kind}" if isinstance(g, Primitive) else ("a chair" if isinstance(g, Chair) else "a mesh")


def variant_geometry(geometry: ObjectGeometry, variant: Variant) -> ObjectGeometry:
    """The object's geometry in ``variant``: scaled in its frame, then drawn as a cylinder if asked."""
    g = geometry.scaled(variant.scale)
    return g.as_cylinder() if variant.shape == "cylinder" else g


def volume(g: ObjectGeometry) -> float:
    """The object's volume [m^3] (a mesh: its convex hull's, scaled; a chair: its parts')."""
    if isinstance(g, Primitive):
        return g.volume
    if isinstance(g, Chair):
        return float(sum(p.volume for _, p, _ in g.parts()))
    return float(load_mesh(g.path).convex_hull.volume * np.prod(g.scale))


def variant_mass(track: ObjectTrack, geometry: ObjectGeometry) -> dict:
    """The variant's mass (module docstring): ``mass``, ``density_mass`` (constant density) and ``mass_capped``."""
    m = track.physics().mass
    density = m * volume(geometry) / volume(track.geometry)
    return {"mass": min(m, density), "density_mass": density, "mass_capped": bool(density > m)}


@dataclass(frozen=True)
class VariantMap:
    """The object-frame map of one object to its variant (module docstring): ``scale`` (3,), the two fields, the
    variant's origin shift ``shift`` (3,: object frame, horizontal), plus ``held_shift`` weighted per frame by
    ``held`` (T,: 0 while the object rests where it started, 1 once it is lifted :data:`LIFTED_M` off it), and the
    world lift ``dz``."""

    scale: np.ndarray
    field: ObjectField
    variant_field: ObjectField
    shift: np.ndarray
    dz: float
    held: np.ndarray
    held_shift: np.ndarray

    def carry(self, u: np.ndarray) -> np.ndarray:
        """(N, 3) points ``u`` of the object's frame -> their places on the variant, in the variant's frame (module
        docstring)."""
        phi, grad = _local(self.field, u)
        x = u - phi[:, None] * grad
        v = self.scale * x + (u - x)
        for _ in range(2):  # to the same distance from the variant's surface along its gradient
            phi2, grad2 = _local(self.variant_field, v)
            v = v - grad2 * (phi2 - phi)[:, None]
        return v

    def pose(self, pose: np.ndarray) -> np.ndarray:
        """The object's (T, 7) track -> the variant's: ``c + R (shift + held held_shift) + dz e_z``, the same
        orientation."""
        out = pose.copy()
        shift = self.shift + self.held[: len(pose), None] * self.held_shift
        out[:, :3] += np.einsum("tij,tj->ti", pose_rotations(pose), shift)
        out[:, 2] += self.dz
        return out


def lifted_weight(track: ObjectTrack) -> np.ndarray:
    """(T,) 0 while the object's lowest point is within 1 cm of where it started, rising to 1 (minimum jerk) as it
    gets :data:`LIFTED_M` above it."""
    rise = object_bottom(track.geometry, track.pose) - object_bottom(track.geometry, track.pose[:1])[0]
    return _minjerk((rise - 0.01) / (LIFTED_M - 0.01))


def _local(field: ObjectField, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    s = field.query(u, np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]))
    return np.asarray(s.phi), np.asarray(s.grad)


def _ramp(flags: np.ndarray, frames: int) -> np.ndarray:
    """(T,) weight: 1 on flagged frames, falling to 0 over ``frames`` frames on either side (minimum jerk)."""
    if not flags.any():
        return np.zeros(len(flags))
    return _minjerk(1.0 - distance_transform_edt(~flags) / (frames + 1))


def _minjerk(x: np.ndarray) -> np.ndarray:
    """The minimum-jerk blend ``10 x^3 - 15 x^4 + 6 x^5`` of ``x`` clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10 - 15 * x + 6 * x**2)


def variant_map(track: ObjectTrack, geometry: ObjectGeometry, targets: IKTargets, variant: Variant) -> VariantMap:
    """The map of ``track``'s object to ``geometry`` (its variant), anchored on the contacts of ``targets`` and
    pushed clear of the body (module docstring)."""
    field, variant_field = geometry_field(track.geometry), geometry_field(geometry)
    scale = np.asarray(variant.scale)
    surface = []
    for k in _contact_bodies(targets):
        frames = np.flatnonzero(targets.object_contact[:, k])
        u = to_pose_frame(track.pose[frames], targets.pos[frames, targets.body_names.index(targets.contact_links[k])])
        phi, grad = _local(field, u)
        surface.append(u - phi[:, None] * grad)
    anchor = np.concatenate(surface).mean(axis=0) if surface else np.zeros(3)
    shift = np.array([*(anchor - scale * anchor)[:2], 0.0])
    vmap = _lifted(
        VariantMap(scale, field, variant_field, shift, 0.0, lifted_weight(track), np.zeros(3)), track, geometry
    )
    for _ in range(CLEARANCE_STEPS):
        vmap = _lifted(_cleared(vmap, track, targets, carried_targets(targets, track, vmap)), track, geometry)
    return vmap


def _contact_bodies(targets: IKTargets) -> list[int]:
    """Indices into ``contact_links`` of the links that are IK target bodies and touch the object somewhere."""
    if targets.object_contact is None:
        return []
    return [
        k
        for k, link in enumerate(targets.contact_links)
        if link in targets.body_names and targets.object_contact[:, k].any()
    ]


def _lifted(vmap: VariantMap, track: ObjectTrack, geometry: ObjectGeometry) -> VariantMap:
    """``vmap`` with ``dz`` keeping the object's lowest point at frame 0 where it was."""
    flat = replace(vmap, dz=0.0).pose(track.pose)[:1]
    dz = float(object_bottom(track.geometry, track.pose[:1])[0] - object_bottom(geometry, flat)[0])
    return replace(vmap, dz=dz)


def _cleared(vmap: VariantMap, track: ObjectTrack, targets: IKTargets, carried: IKTargets) -> VariantMap:
    """``vmap`` with its shifts grown horizontally until the body parts that do not touch the object (the trunk and
    the legs: :data:`CLEAR_KINDS`) of ``carried`` (the targets on the variant) are as far from the variant as those
    of ``targets`` from the object, up to :data:`CLEARANCE_M`: a larger box lifted at the same grip would sweep
    through the knees and end in the torso, a deeper seat would reach into the knees. ``shift`` clears the frames
    where the object rests (one shift: a resting object does not move), ``held_shift`` the frames it is lifted
    (the hands carry it there, and their targets move with it)."""
    touching = {targets.contact_links[k] for k in _contact_bodies(targets)}
    bodies = [
        b
        for b, name in enumerate(targets.body_names)
        if name not in touching and name in G1_ROLES and G1_ROLES[name].kind in CLEAR_KINDS
    ]
    if not bodies:
        return vmap
    B = len(bodies)
    before = _local(vmap.field, to_pose_frame(np.repeat(track.pose, B, 0), targets.pos[:, bodies].reshape(-1, 3)))[0]
    moved = np.repeat(vmap.pose(track.pose), B, 0)
    after, grad = _local(vmap.variant_field, to_pose_frame(moved, carried.pos[:, bodies].reshape(-1, 3)))
    need = np.minimum(before, CLEARANCE_M) - after
    lifted = np.repeat(vmap.held, B) >= 0.5
    for part, rows in (("shift", ~lifted), ("held_shift", lifted)):
        if not rows.any():
            continue
        i = np.flatnonzero(rows)[int(np.argmax(need[rows]))]
        away = -grad[i, :2]  # the object moves away from the body point: against the field's gradient there
        if need[i] > 1e-4 and np.linalg.norm(away) >= 0.3:
            push = np.array([*(need[i] * away / np.linalg.norm(away)), 0.0])
            vmap = replace(vmap, **{part: getattr(vmap, part) + push})
    return vmap


def carried_targets(targets: IKTargets, track: ObjectTrack, vmap: VariantMap) -> IKTargets:
    """``targets`` on the variant of ``vmap``: each contact link carried onto it, ramped in and out, and the other
    body parts following the contacts' mean vertical move (module docstring)."""
    pos = targets.pos.copy()
    pose = vmap.pose(track.pose)
    ramp = max(int(round(RAMP_S * targets.fps)), 1)
    lead_dz, lead_w, lead = np.zeros(targets.frames), np.zeros(targets.frames), "hand"
    moved = set()
    for k in _contact_bodies(targets):
        link = targets.contact_links[k]
        b = targets.body_names.index(link)
        w = _ramp(targets.object_contact[:, k], ramp)
        t = np.flatnonzero(w > 0)
        u = to_pose_frame(track.pose[t], targets.pos[t, b])
        d = from_pose_frame(pose[t], vmap.carry(u)) - targets.pos[t, b]
        pos[t, b] += w[t, None] * d
        lead_dz[t] += w[t] * d[:, 2]
        lead_w[t] += w[t]
        moved.add(b)
        if link in G1_ROLES and G1_ROLES[link].kind == "pelvis":
            lead = "pelvis"
    dz = np.where(lead_w > 0, lead_dz / np.maximum(lead_w, 1e-9), 0.0) * np.minimum(lead_w, 1.0)
    for b, body in enumerate(targets.body_names):
        if b not in moved:
            pos[:, b, 2] += FOLLOW[lead].get(G1_ROLES[body].kind if body in G1_ROLES else "", 0.0) * dz
    return replace(targets, pos=pos)


def augment(
    targets: IKTargets, objects: tuple[ObjectTrack, ...], variant: Variant, source: str = ""
) -> tuple[IKTargets, tuple[ObjectTrack, ...], VariantMap, dict]:
    """``(targets, objects, map, figures)`` of ``variant`` (module docstring): object 0 varied, the contact links'
    targets carried onto it and the body following; ``figures`` the variant's :meth:`Variant.to_dict` with its mass
    figures, the object's shift (object frame, horizontal) and lift."""
    reason = not_applicable(objects[0].geometry if objects else None, variant)
    if reason is not None:
        raise InputError(source, "augment", reason)
    track = objects[0]
    geometry = variant_geometry(track.geometry, variant)
    vmap = variant_map(track, geometry, targets, variant)
    mass = variant_mass(track, geometry)
    varied = replace(track, geometry=geometry, pose=vmap.pose(track.pose), mass=mass["mass"])
    figures = {**variant.to_dict(), **mass, "shift_m": vmap.shift[:2].tolist()}
    figures |= {"held_shift_m": vmap.held_shift[:2].tolist(), "lift_m": vmap.dz}
    return carried_targets(targets, track, vmap), (varied, *objects[1:]), vmap, figures
