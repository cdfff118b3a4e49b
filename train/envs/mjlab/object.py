"""The object of each mjlab world (:mod:`train.envs.mjlab.env`): a free body made of box parts -- one box, or a chair's
six (:func:`pipeline.geometry.chair_boxes`) -- and, where boxes may be drawn as cylinders
(:func:`train.mdp.randomize.vary_shape`), one cylinder slot; each world holds its own copy of the sizes, positions,
mass,
inertia, friction (with the robot; with the floor: explicit contact pairs, :func:`add_object_floor_pairs`) and
restitution, written at every restart from the episode and its draw.

MuJoCo Warp fixes the number and types of geoms at start-up, the same in every world, so every world's object has
the most box parts any episode needs, plus the cylinder slot. The slots a world does not use shrink to
:data:`PAD_HALF` inside the part it does use (a box's or a cylinder's centre, a chair's seat), where nothing reaches
them: the robot's links and the floor touch the used part's faces, and outside it the field's nearest part is the
used part, the pads being inside it.

The mass of a part is the object's mass times its share of the parts' volume (as :func:`pipeline.scene.build_spec`
builds it); what MuJoCo derives at compile time from the parts is written directly (:func:`rigid_body`), not by
MuJoCo Warp's ``set_const`` (~1400 kernel launches per call; measured in :mod:`train.envs.mjlab.env`)."""

from __future__ import annotations

from dataclasses import astuple
from typing import NamedTuple

import mujoco
import numpy as np
import torch

from pipeline.geometry import Chair, Primitive, chair_boxes, chair_scaled
from pipeline.scene import RESTITUTION_SOLIMP, SceneObject, add_floor_pairs, object_spec, restitution_solref
from train.episodes import Episode

PAD_HALF = 1e-4
"""[m] half-extent of a box world's unused parts (MuJoCo needs positive sizes)."""

MODEL_FIELDS = ("geom_size", "geom_pos", "geom_rbound", "geom_aabb", "geom_friction", "geom_solref", "geom_solimp",
                "pair_friction", "pair_solref", "pair_solimp", "body_mass", "body_ipos", "body_iquat", "body_inertia",
                "body_subtreemass", "body_invweight0", "dof_invweight0")  # fmt: skip
"""The model fields each world holds its own copy of (mjlab's ``requires_model_fields``)."""


def is_box(e: Episode) -> bool:
    objects = e.simulated.robot.objects
    return len(objects) == 1 and isinstance(objects[0].geometry, Primitive) and objects[0].geometry.kind == "box"


def is_chair(e: Episode) -> bool:
    objects = e.simulated.robot.objects
    return len(objects) == 1 and isinstance(objects[0].geometry, Chair)


class Parts(NamedTuple):
    """n worlds' object slots (:meth:`Shapes.at`): the box parts' half-extents and centres (n, P, 3) and which are
    used (n, P); whether the cylinder slot is, and its radius and half-length (n,)."""

    half: torch.Tensor
    centre: torch.Tensor
    real: torch.Tensor
    cylinder: torch.Tensor
    radius: torch.Tensor
    length: torch.Tensor


class Shapes:
    """The episodes' objects at scale 1 on the device: a box's half-extents or a chair's fields, mass and friction;
    :attr:`parts` box parts per world (6 when any episode holds a chair, else 1), and :attr:`cylinders`, whether
    there is a cylinder slot (boxes are drawn as cylinders with ``cylinder_prob`` > 0)."""

    def __init__(self, episodes: list[Episode], device: torch.device, cylinder_prob: float):
        objects = [e.simulated.robot.objects[0] for e in episodes]
        physics = [o.physics() for o in objects]

        def tensor(values) -> torch.Tensor:
            return torch.as_tensor(np.array(values, dtype=float), dtype=torch.float32, device=device)

        self.chair = torch.as_tensor([is_chair(e) for e in episodes], device=device)
        self.parts = 6 if bool(self.chair.any()) else 1
        self.cylinders = cylinder_prob > 0 and not bool(self.chair.all())
        self.half = tensor([np.ones(3) if c else o.geometry.half_extents for o, c in zip(objects, self.chair)])
        self.chair_fields = tensor([astuple(o.geometry if c else Chair()) for o, c in zip(objects, self.chair)])
        self.mass = tensor([p.mass for p in physics])
        self.friction = tensor([p.friction for p in physics])
        self.floor_friction = tensor([p.floor_friction for p in physics])

    def at(self, episode: torch.Tensor, scale: torch.Tensor, cylinder: torch.Tensor) -> Parts:
        """The slots of episodes ``episode`` at the per-axis ``scale`` (n, 3), a box drawn as a cylinder where
        ``cylinder`` (:func:`train.mdp.randomize.vary_shape`): the box scaled, or
        :meth:`pipeline.geometry.Chair.scaled`'s
        parts."""
        box = self.half[episode] * scale
        n, dev = len(episode), box.device
        cylinder = cylinder.bool() & ~self.chair[episode] & self.cylinders
        radius, length = (box[:, 0] + box[:, 1]) / 2, box[:, 2]
        half, centre, real = (
            box[:, None],
            torch.zeros_like(box)[:, None],
            torch.ones(n, 1, dtype=torch.bool, device=dev),
        )
        if self.parts > 1:
            chair = self.chair[episode]
            parts, at = chair_boxes(chair_scaled(self.chair_fields[episode], scale))
            pads = torch.full((n, self.parts - 1, 3), PAD_HALF, device=dev)
            half = torch.where(chair[:, None, None], parts, torch.cat([box[:, None], pads], 1))
            centre = torch.where(chair[:, None, None], at, torch.zeros_like(at))
            real = chair[:, None] | (torch.arange(self.parts, device=dev) == 0)
        half = torch.where(cylinder[:, None, None], PAD_HALF, half)
        return Parts(half, centre, real & ~cylinder[:, None], cylinder, radius, length)

    def floor_shift(self, episode: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
        """(n,) how far the object's frame rises at ``scale`` so that what rested on the floor still does: a box's
        (or its cylinder's) centre with its half-height; a chair's frame is on the floor
        (:func:`train.episodes.scaled_objects`)."""
        return torch.where(self.chair[episode], 0.0, self.half[episode, 2] * (scale[:, 2] - 1))


def slots(p: Parts, cylinders: bool) -> dict:
    """Every geom slot of the object (the box parts, then the cylinder slot if any): MuJoCo's ``size`` and ``pos``,
    its bounding sphere's radius ``rbound`` and box's half-sizes ``aabb``, and each slot's ``volume`` and ``unit``
    inertia (its principal moments per unit mass about its centre), 0 for the slots a world does not use."""
    box_volume = 8 * p.half.prod(-1) * p.real
    box_unit = (p.half.square().sum(-1, keepdim=True) - p.half.square()) / 3
    out = {"size": p.half, "pos": p.centre, "aabb": p.half, "rbound": p.half.norm(dim=-1), "volume": box_volume,
           "unit": box_unit}  # fmt: skip
    if not cylinders:
        return out
    r = torch.where(p.cylinder, p.radius, PAD_HALF)
    h = torch.where(p.cylinder, p.length, PAD_HALF)
    at = torch.where(p.cylinder[:, None], 0.0, p.centre[:, 0])  # a pad sits in the used part (a chair's seat)
    side = (3 * r.square() + 4 * h.square()) / 12
    cyl = {
        "size": torch.stack([r, h, 0 * r], 1),
        "pos": at,
        "aabb": torch.stack([r, r, h], 1),
        "rbound": torch.hypot(r, h),
        "volume": 2 * torch.pi * r.square() * h * p.cylinder,
        "unit": torch.stack([side, side, r.square() / 2], 1),
    }
    return {k: torch.cat([v, cyl[k][:, None]], 1) for k, v in out.items()}


def rigid_body(mass: torch.Tensor, volume: torch.Tensor, unit: torch.Tensor, centre: torch.Tensor) -> dict:
    """What MuJoCo's compiler and ``mj_setConst`` derive for a free body of S parts (n worlds), its ``mass`` (n,)
    spread by ``volume`` (n, S), each part's principal moments per unit mass ``unit`` (n, S, 3) about its ``centre``
    (n, S, 3), its axes the body's: ``ipos`` (n, 3) the centre of mass; ``inertia`` (n, 3) the principal moments,
    about the axes ``iquat`` (n, 4) turns the body frame to; ``invweight`` (n, 2) the body's mean inverse weight over
    translation and rotation at its centre of mass (1/m, tr(I^-1)/3), and ``dof_invweight`` (n, 6) the free joint's,
    ``M^-1``'s diagonal blocks at the body's origin: translation ``1/m + (|c|^2 tr A - c'Ac) / 3`` (``A = I^-1``,
    ``c`` the centre of mass), rotation ``tr A / 3``.

    The objects are symmetric about their xz-plane (a box, a cylinder, a chair): y is a principal axis and the other
    two are turned about y by ``theta = atan2(-2 I_xz s, |I_xx - I_zz|) / 2``, ``s`` the sign of ``I_xx - I_zz``,
    which keeps a box's axes its own (theta = 0)."""
    m = mass[:, None] * volume / volume.sum(1, keepdim=True)  # (n, S)
    com = (m[..., None] * centre).sum(1) / mass[:, None]
    d = centre - com[:, None]
    eye = torch.eye(3, device=mass.device, dtype=mass.dtype)
    shift = d.square().sum(-1)[..., None, None] * eye - d[..., :, None] * d[..., None, :]
    tensor = (m[..., None, None] * (torch.diag_embed(unit) + shift)).sum(1)  # about the centre of mass, body axes
    ixx, iyy, izz, ixz = tensor[:, 0, 0], tensor[:, 1, 1], tensor[:, 2, 2], tensor[:, 0, 2]
    sign = torch.where(ixx >= izz, 1.0, -1.0)
    r = torch.hypot(ixx - izz, 2 * ixz)
    theta = torch.atan2(-2 * ixz * sign, (ixx - izz).abs()) / 2
    mean = (ixx + izz) / 2
    inertia = torch.stack([mean + sign * r / 2, iyy, mean - sign * r / 2], 1)
    zero = torch.zeros_like(theta)
    iquat = torch.stack([torch.cos(theta / 2), zero, torch.sin(theta / 2), zero], 1)
    inverse = torch.linalg.inv(tensor)
    trace = inverse.diagonal(dim1=1, dim2=2).sum(1)
    c_ac = (com[:, None] @ inverse @ com[:, :, None]).reshape(-1)
    translation = 1 / mass + (com.square().sum(1) * trace - c_ac) / 3
    return {
        "ipos": com,
        "inertia": inertia,
        "iquat": iquat,
        "invweight": torch.stack([1 / mass, trace / 3], 1),
        "dof_invweight": torch.stack([translation] * 3 + [trace / 3] * 3, 1),
    }


def entity_spec(shapes: Shapes, obj: SceneObject) -> mujoco.MjSpec:
    """The object entity: ``obj`` (an episode's, with the most box parts) as :func:`pipeline.scene.object_spec` builds
    it, and the cylinder slot if any, with the first part's contact settings."""
    spec = object_spec(obj)
    if shapes.cylinders:
        body = spec.body(obj.name)
        first = body.first_geom()
        g = body.add_geom(name=f"{obj.name}_cylinder", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[PAD_HALF] * 3)
        for name in ("contype", "conaffinity", "condim", "priority", "friction", "solref", "solimp", "rgba"):
            setattr(g, name, getattr(first, name))
        g.mass = 0.0
    return spec


def add_object_floor_pairs(spec: mujoco.MjSpec, obj: SceneObject) -> None:
    """On mjlab's scene ``spec`` (the entities attached as ``robot/`` and ``object/``), the object's floor contacts
    as :func:`pipeline.scene.build_spec` makes them (:func:`pipeline.scene.add_floor_pairs`): one pair per collision
    geom of the object entity, the cylinder slot included."""
    geoms = [g.name for g in spec.geoms if g.name.startswith("object/") and g.contype]
    add_floor_pairs(spec, "robot/floor", f"object/{obj.name}", geoms, obj.physics)


def write_object(env, ids: torch.Tensor, shapes: Shapes, parts: Parts, draws: dict, episode: torch.Tensor) -> None:
    """Worlds ``ids`` take the object ``parts`` of their episodes under ``draws``
    (:func:`train.mdp.randomize.draw_batch`'s,
    as tensors): slot sizes and positions, mass (:func:`train.mdp.randomize.object_physics`), inertia, friction,
    restitution (:func:`pipeline.scene.restitution_solref`: a contact spring where it is drawn above 0) and the
    derived constants (:func:`rigid_body`)."""
    m, obj = env.sim.model, env.scene["object"]
    g, b = obj.indexing.geom_ids, obj.indexing.body_ids[0]
    geoms = slots(parts, shapes.cylinders)
    mass = shapes.mass[episode] * draws["mass_factor"]
    rows, cols = ids[:, None], g[None]
    m.geom_size[rows, cols], m.geom_pos[rows, cols] = geoms["size"], geoms["pos"]
    m.geom_rbound[rows, cols] = geoms["rbound"]
    m.geom_aabb[rows, cols] = torch.stack([torch.zeros_like(geoms["aabb"]), geoms["aabb"]], 2)  # (centre, half)
    m.geom_friction[rows, cols, 0] = (shapes.friction[episode] * draws["friction_factor"])[:, None]
    m.pair_friction[ids, :, :2] = (shapes.floor_friction[episode] * draws["friction_factor"])[:, None, None]
    e_rest = draws["restitution"]
    bouncy = (e_rest > 0)[:, None, None]
    solref = restitution_solref(e_rest.clamp(min=1e-6))[:, None]
    solimp = torch.as_tensor(RESTITUTION_SOLIMP, device=mass.device, dtype=mass.dtype)
    default = env.sim.get_default_field
    m.geom_solref[rows, cols] = torch.where(bouncy, solref, default("geom_solref")[g])
    m.geom_solimp[rows, cols] = torch.where(bouncy, solimp, default("geom_solimp")[g])
    m.pair_solref[ids] = torch.where(bouncy, solref, default("pair_solref"))  # every pair is the object's
    m.pair_solimp[ids] = torch.where(bouncy, solimp, default("pair_solimp"))
    body = rigid_body(mass, geoms["volume"], geoms["unit"], geoms["pos"])
    world_mass = env.sim.get_default_field("body_subtreemass")[0] - env.sim.get_default_field("body_mass")[b]
    m.body_mass[ids, b], m.body_ipos[ids, b], m.body_iquat[ids, b] = mass, body["ipos"], body["iquat"]
    m.body_inertia[ids, b] = body["inertia"]
    m.body_subtreemass[ids, b], m.body_subtreemass[ids, 0] = mass, world_mass + mass
    m.body_invweight0[ids, b] = body["invweight"]
    m.dof_invweight0[ids[:, None], obj.indexing.free_joint_v_adr] = body["dof_invweight"]
