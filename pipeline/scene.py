"""MuJoCo scenes built with ``MjSpec``: the G1, its actuators, a floor and any objects.

One scene builder serves every stage, so the retarget stage's penetration checks and
the physics stage's contacts see the same collision model:

* robot collision geoms are mjlab's ``FULL_COLLISION`` set: every ``*_collision`` geom
  collides (self-collision included); foot capsules have ``condim 3``, ``priority 1``,
  friction 0.6; the others ``condim 1``; visual meshes never collide;
* objects are free bodies (or fixed ones) with ``priority 2``, so their own friction and
  restitution govern their contacts with the robot; their contacts with the floor are explicit
  contact pairs (the object's geoms against ``floor``, the world-object body pair excluded from
  MuJoCo's own collision search) with the object's ``floor_friction`` and the same restitution
  (:func:`add_floor_pairs`; :mod:`pipeline.materials` says why the two frictions differ);
* restitution ``e`` (0 = MuJoCo's default inelastic contact) becomes a contact spring in
  MuJoCo's direct form, ``solref = (-w^2, -2 zeta w)`` with ``w = 60 rad/s`` and
  ``solimp = (0.99, 0.99, 0.001)``, where ``zeta`` comes from the damped-oscillator relation
  ``e = exp(-zeta pi / sqrt(1 - zeta^2))``, i.e. ``zeta = -ln e / sqrt(pi^2 + ln^2 e)``.
  (The default time-constant form with a low damping ratio gains energy at 200 Hz: a ball
  with e = 0.6 bounced higher each time; the direct form rebounds to ``e^2`` of the drop
  height within a few per cent for e >= 0.6.);
* mesh objects collide through :func:`pipeline.collision_mesh.collision_parts` (convex hull or
  CoACD decomposition) and are drawn with the original mesh; a primitive with a
  non-uniform scale becomes the exact shape MuJoCo has (box half-extents, an ellipsoid)
  or, for cylinders and capsules, a convex mesh of the scaled shape;
* the object's mass is spread over its collision pieces in proportion to their volume.

Physics runs at 200 Hz (``timestep 0.005``) with the ``implicitfast`` integrator, elliptic friction
cones and ``impratio`` 10 (friction constraints 10x harder than normal ones: a 1.5 kg box squeezed
between the two hand capsules crept down 2-3 cm/s with MuJoCo's default pyramidal cones and
``impratio`` 1, and < 0.5 cm/s with these; tests/test_grasp.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np
import trimesh

from pipeline.collision_mesh import collision_parts, load_mesh
from pipeline.geometry import Chair, MeshGeometry, ObjectGeometry, ObjectPhysics, Primitive
from pipeline.robot import G1_JOINT_NAMES, HAND_BODIES, ActuatorProfile, actuator_profile, g1_spec
from pipeline.terms.layout import PHYSICS_TIMESTEP
from pipeline.xp import namespace

IMPRATIO = 10.0
OBJECT_PRIORITY = 2
_FOOT_PREFIXES = tuple(f"{s}_foot" for s in ("left", "right"))


@dataclass(frozen=True)
class SceneObject:
    """An object placed in a scene: geometry, physical properties, initial pose (x y z qw qx qy qz)."""

    name: str
    geometry: ObjectGeometry
    physics: ObjectPhysics = ObjectPhysics()
    pose: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)
    fixed: bool = False


@dataclass
class Scene:
    """A compiled scene: the model plus where the robot and each object live in ``qpos``."""

    model: mujoco.MjModel
    spec: mujoco.MjSpec
    profile: ActuatorProfile
    objects: tuple[SceneObject, ...]
    object_qpos_adr: dict[str, int] = field(default_factory=dict)
    object_body_id: dict[str, int] = field(default_factory=dict)

    @property
    def robot_geom_ids(self) -> np.ndarray:
        """Ids of the robot's collision geoms."""
        m = self.model
        return np.array(
            [g for g in range(m.ngeom) if m.geom_contype[g] and m.body_rootid[m.geom_bodyid[g]] == m.body("pelvis").id]
        )


RESTITUTION_CONTACT_FREQ = 60.0


RESTITUTION_SOLIMP = (0.99, 0.99, 0.001, 0.5, 2.0)


def restitution_damping_ratio(e: float) -> float:
    """Contact damping ratio ``zeta`` giving a coefficient of restitution ``e`` in [0, 1)."""
    if not 0.0 <= e < 1.0:
        raise ValueError(f"restitution must be in [0, 1), got {e}")
    return float(_damping_ratio(np.float64(e))) if e > 0 else 1.0


def _damping_ratio(e):
    """``zeta = -ln e / sqrt(pi^2 + ln^2 e)`` for ``e`` in (0, 1), the damped-oscillator relation; numpy or torch."""
    xp = namespace(e)
    le = xp.log(e)
    return -le / xp.sqrt(math.pi**2 + le**2)


def contact_spring(zeta):
    """(..., 2) MuJoCo's direct ``solref = (-w^2, -2 zeta w)`` of the contact spring of damping ratio ``zeta``."""
    w = RESTITUTION_CONTACT_FREQ
    return namespace(zeta).stack([0.0 * zeta - w * w, -2.0 * zeta * w], -1)


def restitution_solref(e):
    """(..., 2) :func:`contact_spring` for restitution ``e`` (...) in (0, 1); numpy or torch alike (the mjlab backend
    draws ``e`` per world)."""
    return contact_spring(_damping_ratio(e))


def _apply_robot_collisions(spec: mujoco.MjSpec) -> None:
    for g in spec.geoms:
        if not g.name.endswith("_collision"):
            continue
        g.contype, g.conaffinity = 1, 1
        if g.name.startswith(_FOOT_PREFIXES):
            g.condim, g.priority, g.friction = 3, 1, [0.6, 0.005, 0.0001]
        else:
            g.condim, g.priority = 1, 0


def _add_actuators(spec: mujoco.MjSpec, profile: ActuatorProfile) -> None:
    for i, name in enumerate(G1_JOINT_NAMES):
        spec.joint(name).armature = float(profile.armature[i])
        act = spec.add_actuator(name=name.removesuffix("_joint"), target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=float(profile.kp[i]), kv=float(profile.kd[i]))
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-float(profile.effort_limit[i]), float(profile.effort_limit[i])]


def _primitive_pieces(p: Primitive) -> list[tuple[str, object]]:
    """[(mujoco geom type name, size or trimesh)] for a scaled primitive."""
    s = np.asarray(p.scale)
    uniform = np.allclose(s, s[0])
    if p.kind == "box":
        return [("box", np.asarray(p.size) * s)]
    if p.kind == "sphere":
        return [("sphere", [p.size[0] * s[0]])] if uniform else [("ellipsoid", p.size[0] * s)]
    if uniform or (p.kind == "cylinder" and s[0] == s[1]):
        r, h = p.size[0] * s[0], p.size[1] * s[2]
        return [(p.kind, [r, h])]
    base = (
        trimesh.creation.cylinder(p.size[0], 2 * p.size[1], sections=48)
        if p.kind == "cylinder"
        else trimesh.creation.capsule(2 * p.size[1], p.size[0], count=[24, 24])
    )
    base.apply_scale(s)
    return [("mesh", base)]


def _add_mesh_geom(spec, body, name: str, mesh: trimesh.Trimesh, *, collide: bool, scale=(1.0, 1.0, 1.0)):
    m = spec.add_mesh(name=name)
    m.uservert = np.asarray(mesh.vertices, dtype=np.float32).ravel().tolist()
    m.userface = np.asarray(mesh.faces, dtype=np.int32).ravel().tolist()
    m.scale = list(scale)
    if not collide:
        m.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL
    return body.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name)


def _add_object(spec: mujoco.MjSpec, obj: SceneObject) -> list[str]:
    body = spec.worldbody.add_body(name=obj.name, pos=list(obj.pose[:3]), quat=list(obj.pose[3:7]))
    if not obj.fixed:
        body.add_freejoint(name=f"{obj.name}_free")
    geo, phys = obj.geometry, obj.physics
    collide: list[tuple[mujoco.MjsGeom, float]] = []  # (geom, volume)
    if isinstance(geo, Primitive):
        for k, (kind, size) in enumerate(_primitive_pieces(geo)):
            if kind == "mesh":
                collide.append((_add_mesh_geom(spec, body, f"{obj.name}_col{k}", size, collide=True), size.volume))
            else:
                g = body.add_geom(
                    name=f"{obj.name}_col{k}",
                    type=getattr(mujoco.mjtGeom, f"mjGEOM_{kind.upper()}"),
                    size=list(size) + [0.0] * (3 - len(size)),
                )
                collide.append((g, _volume(kind, size)))
    elif isinstance(geo, Chair):
        for part, box, centre in geo.parts():
            g = body.add_geom(
                name=f"{obj.name}_{part}", type=mujoco.mjtGeom.mjGEOM_BOX, size=list(box.size), pos=centre.tolist()
            )
            collide.append((g, float(np.prod(box.size)) * 8))
    elif isinstance(geo, MeshGeometry):
        visual = _add_mesh_geom(spec, body, f"{obj.name}_visual", load_mesh(geo.path), collide=False, scale=geo.scale)
        visual.contype = visual.conaffinity = 0
        visual.group, visual.mass = 2, 0.0
        for k, piece in enumerate(collision_parts(geo)):
            g = _add_mesh_geom(spec, body, f"{obj.name}_col{k}", piece, collide=True, scale=geo.scale)
            g.group = 3
            collide.append((g, abs(piece.volume) * float(np.prod(geo.scale))))
    else:
        raise TypeError(f"object {obj.name}: unsupported geometry {type(geo).__name__}")
    total = sum(v for _, v in collide)
    zeta = restitution_damping_ratio(phys.restitution)
    for g, vol in collide:
        g.contype = g.conaffinity = 1
        g.condim, g.priority = 3, OBJECT_PRIORITY
        g.friction = [phys.friction, 0.005, 0.0001]
        if phys.restitution > 0:
            g.solref, g.solimp = contact_spring(np.float64(zeta)).tolist(), list(RESTITUTION_SOLIMP)
        g.mass = phys.mass * vol / total
        g.rgba = [0.8, 0.5, 0.2, 1.0]
    return [g.name for g, _ in collide]


def add_floor_pairs(
    spec: mujoco.MjSpec, floor: str, body: str, geoms: list[str], physics: ObjectPhysics, world: str = "world"
) -> None:
    """The contacts of ``body``'s ``geoms`` with the ``floor`` geom as explicit pairs of ``physics.floor_friction``
    (condim 3) and its restitution spring; MuJoCo's own collision search then skips the ``world``-``body`` pair
    (an exclusion touches only that search, never explicit pairs). The mjlab backend calls it on its scene, whose
    names carry the entities' prefixes."""
    mu = physics.floor_friction
    for name in geoms:
        pair = spec.add_pair(name=f"{name}_floor", geomname1=floor, geomname2=name)
        pair.condim, pair.friction = 3, [mu, mu, 0.005, 0.0001, 0.0001]
        if physics.restitution > 0:
            zeta = np.float64(restitution_damping_ratio(physics.restitution))
            pair.solref, pair.solimp = contact_spring(zeta).tolist(), list(RESTITUTION_SOLIMP)
    spec.add_exclude(bodyname1=world, bodyname2=body)


def object_spec(obj: SceneObject) -> mujoco.MjSpec:
    """One object alone as an ``MjSpec`` (its body, free joint and collision geoms as :func:`build_spec` adds
    them): an mjlab entity of :mod:`train.envs.mjlab.env`."""
    spec = mujoco.MjSpec()
    _add_object(spec, obj)
    return spec


def _volume(kind: str, size) -> float:
    if kind == "box":
        return 8.0 * float(np.prod(size))
    if kind == "sphere":
        return 4.0 / 3.0 * math.pi * size[0] ** 3
    if kind == "ellipsoid":
        return 4.0 / 3.0 * math.pi * float(np.prod(size))
    r, h = size[0], size[1]
    return math.pi * r * r * 2 * h + (4.0 / 3.0 * math.pi * r**3 if kind == "capsule" else 0.0)


def build_spec(
    objects: tuple[SceneObject, ...] | list[SceneObject] = (), profile: str | ActuatorProfile = "mjlab"
) -> mujoco.MjSpec:
    """G1 + actuators of ``profile`` + floor + ``objects``, as an editable ``MjSpec``."""
    profile = actuator_profile(profile) if isinstance(profile, str) else profile
    names = [o.name for o in objects]
    if len(set(names)) != len(names):
        raise ValueError(f"object names must be unique, got {names}")
    spec = g1_spec()
    spec.option.timestep = PHYSICS_TIMESTEP
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone, spec.option.impratio = mujoco.mjtCone.mjCONE_ELLIPTIC, IMPRATIO
    _apply_robot_collisions(spec)
    _add_actuators(spec, profile)
    floor = spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05])
    floor.contype = floor.conaffinity = 1
    floor.condim, floor.friction = 3, [1.0, 0.005, 0.0001]
    for obj in objects:
        geoms = _add_object(spec, obj)
        if not obj.fixed:
            add_floor_pairs(spec, "floor", obj.name, geoms, obj.physics)
    return spec


def build_scene(
    objects: tuple[SceneObject, ...] | list[SceneObject] = (), profile: str | ActuatorProfile = "mjlab"
) -> Scene:
    """Compile :func:`build_spec` and record each object's ``qpos`` address and body id."""
    profile = actuator_profile(profile) if isinstance(profile, str) else profile
    spec = build_spec(objects, profile)
    model = spec.compile()
    scene = Scene(model=model, spec=spec, profile=profile, objects=tuple(objects))
    for o in objects:
        scene.object_body_id[o.name] = model.body(o.name).id
        if not o.fixed:
            scene.object_qpos_adr[o.name] = int(model.jnt_qposadr[model.joint(f"{o.name}_free").id])
    return scene


#: Contact surfaces that span more than one body: the G1 sits on its hip capsules (their bottom
#: is 3.6 cm below the pelvis sphere's, which cannot reach a seat), so a contact of the pelvis
#: means the pelvis sphere or either hip capsule.
CONTACT_SURFACE_EXTRA = {"pelvis": ("left_hip_collision", "right_hip_collision")}


def link_collision_geoms(model: mujoco.MjModel, body: str) -> list[int]:
    """Collision geoms (``contype`` != 0) making ``body``'s contact surface: its own (plus
    :data:`CONTACT_SURFACE_EXTRA`), else those of its nearest descendants that have some (the
    G1's ``*_hip_pitch_link`` has none: the hip capsule of ``*_hip_roll_link`` stands in;
    ``*_shoulder_pitch_link``: the upper-arm capsule)."""
    try:
        level = [model.body(body).id]
    except KeyError:
        raise ValueError(f"{body!r} is not a body of the model") from None
    extra = [
        model.geom(g).id
        for g in CONTACT_SURFACE_EXTRA.get(body, ())
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g) >= 0
    ]
    while level:
        geoms = [g for g in range(model.ngeom) if model.geom_contype[g] and model.geom_bodyid[g] in level]
        if geoms:
            return geoms + extra
        level = [b for b in range(model.nbody) if model.body_parentid[b] in level and b not in level]
    raise ValueError(f"body {body!r} has no collision geoms below it")


def hand_geoms(model: mujoco.MjModel) -> list[list[int]]:
    """Collision geoms of each hand (left, right): :func:`link_collision_geoms` of
    :data:`pipeline.robot.HAND_BODIES`."""
    return [link_collision_geoms(model, b) for b in HAND_BODIES]


def nearest_geom_pair(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    geoms_a: list[int],
    geoms_b: list[int],
    distmax: float,
    fromto: np.ndarray | None = None,
) -> tuple[float, int, int]:
    """``(d, a, b)``: the smallest signed distance (``mj_geomDistance``, < 0 when penetrating) between
    the geom sets and the pair that has it; ``(distmax, -1, -1)`` when every pair is farther.
    ``fromto`` (6,), when given, receives that pair's nearest points (on ``a``, then on ``b``)."""
    best, pair = distmax, (-1, -1)
    points = None if fromto is None else np.empty(6)
    for a in geoms_a:
        for b in geoms_b:
            dist = mujoco.mj_geomDistance(model, data, a, b, distmax, points)
            if dist < best:
                best, pair = dist, (a, b)
                if fromto is not None:
                    fromto[:] = points
    return best, *pair


def robot_collision_geoms(model: mujoco.MjModel) -> list[int]:
    """Collision geoms (``contype`` != 0) of the robot tree rooted at ``pelvis``."""
    root = model.body("pelvis").id
    return [g for g in range(model.ngeom) if model.geom_contype[g] and model.body_rootid[model.geom_bodyid[g]] == root]


def object_collision_geoms(model: mujoco.MjModel, scene: Scene) -> list[int]:
    """Collision geoms of every scene object (``<object>_col<k>``, chair parts, ...)."""
    ids = {model.body(o.name).id for o in scene.objects}
    return [g for g in range(model.ngeom) if model.geom_contype[g] and model.geom_bodyid[g] in ids]


def self_collision_groups(model: mujoco.MjModel) -> list[tuple[list[int], list[int]]]:
    """Robot geom groups checked against each other: every robot collision geom against every other.

    :class:`pipeline.ik_limits.SeparationLimit` then drops what MuJoCo's physics drops (``<exclude>``
    pairs, geoms of one weld, parent-child bodies), so the IK avoids exactly the self-contacts
    the physics stage would see.
    """
    geoms = robot_collision_geoms(model)
    return [(geoms, geoms)]
