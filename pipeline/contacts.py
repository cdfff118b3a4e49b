"""The robot's contacts in the simulation: which geoms are the robot's (:class:`ContactSets`) and the
contacts between them and everything else, with the force on the robot (:func:`robot_contacts`).

MuJoCo's contact ``i`` joins ``geom1`` and ``geom2``; its frame's first row is the normal, pointing from
``geom1`` to ``geom2``, and ``mj_contactForce`` gives the force ``f6[:3]`` in that frame on ``geom2``. The
world-frame force on the robot is therefore ``+frame^T f6[:3]`` when the robot is ``geom2`` and its negative
when it is ``geom1``. Contacts are visited in MuJoCo's order, so sums over them are the same in every user.

Shared robot-and-scene knowledge: the physicalize stage reads contact forces (the controller's measured external
forces, its seat contacts, the stepping logic's foot loads, the rollout's records), the training environments read
which of the robot's geoms touch the object (the tasks' success rules).
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from dataclasses import dataclass

import mujoco
import numpy as np

from pipeline.robot import FOOT_BODIES, sole_corners


@dataclass(frozen=True, eq=False)
class ContactSets:
    """The robot's contact sets in a compiled scene (the robot is the tree rooted at ``pelvis``):
    ``feet`` the foot body ids (left, right), ``floor`` the floor geom, ``bodies`` the robot's bodies,
    ``robot_geoms`` every geom on them, ``corners`` (2, 4, 3) each foot's sole corners in its body frame."""

    model: mujoco.MjModel
    feet: tuple[int, ...]
    floor: int
    bodies: tuple[int, ...]
    robot_geoms: frozenset[int]
    corners: np.ndarray

    @classmethod
    def of(cls, model: mujoco.MjModel) -> ContactSets:
        pelvis = model.body("pelvis").id
        bodies = tuple(b for b in range(1, model.nbody) if model.body_rootid[b] == pelvis)
        body_set = set(bodies)
        return cls(
            model,
            tuple(model.body(b).id for b in FOOT_BODIES),
            model.geom("floor").id,
            bodies,
            frozenset(g for g in range(model.ngeom) if model.geom_bodyid[g] in body_set),
            np.stack([sole_corners(model, b) for b in FOOT_BODIES]),
        )


@dataclass(frozen=True, slots=True)
class RobotContact:
    """Contact ``index`` of ``d`` between the robot's ``geom`` and an ``other`` geom (not the robot's);
    ``into_robot``: the robot is ``geom2``, so the contact normal points into it."""

    model: mujoco.MjModel
    data: mujoco.MjData
    index: int
    geom: int
    other: int
    into_robot: bool

    @property
    def pos(self) -> np.ndarray:
        """The contact point (world)."""
        return self.data.contact.pos[self.index]

    @property
    def normal(self) -> np.ndarray:
        """The contact normal pointing into the robot (world, unit)."""
        return self.data.contact.frame[self.index, :3] * (1.0 if self.into_robot else -1.0)

    def wrench(self) -> np.ndarray:
        """``f6``: ``mj_contactForce``'s force and torque on ``geom2`` in the contact frame (normal first)."""
        f6 = np.zeros(6)
        mujoco.mj_contactForce(self.model, self.data, self.index, f6)
        return f6

    def force(self) -> np.ndarray:
        """(3,) the contact force on the robot, world frame."""
        f = self.data.contact.frame[self.index].reshape(3, 3).T @ self.wrench()[:3]  # on geom2, world frame
        return f if self.into_robot else -f


def robot_contacts(model: mujoco.MjModel, data: mujoco.MjData, robot_geoms: Collection[int]) -> Iterator[RobotContact]:
    """The contacts of ``data`` between a geom of ``robot_geoms`` and a geom outside it, in MuJoCo's order
    (a contact's force is read only when asked for: :meth:`RobotContact.force`)."""
    n = data.ncon
    for i, (g1, g2) in enumerate(zip(data.contact.geom1[:n].tolist(), data.contact.geom2[:n].tolist())):
        r1, r2 = g1 in robot_geoms, g2 in robot_geoms
        if r1 != r2:
            yield RobotContact(model, data, i, g1 if r1 else g2, g2 if r1 else g1, r2)
