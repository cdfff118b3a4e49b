"""The physical properties of the objects in real mocap takes: mass, hand-object friction and object-floor friction,
from one table per object kind, each value with the range it comes from.

Mocap files carry no masses or frictions. A take's object gets the nominal values of its kind
(:func:`object_physics_for`, by the OMOMO object name: ``largebox`` from ``sub8_largebox_001.pt``), never values
tuned per take; the bench (``make bench-physicalize-real --physics low|high``) runs every take at the low and the high
end of every range, so a reader sees how much of a result rests on the choice.

Why the two frictions are apart: in MuJoCo one geom friction governs every contact of the object (its geoms win the
mixing by priority). Under equal friction a box pushed from its top can never slide, and one pushed at height ``h``
over half-width ``b`` with ``h / b > 1 / mu`` tips before it slides (traced on ``interact/sub8_largebox_000`` with
0.8 everywhere: the floor pushed 154 N up on a 19.6 N box, which stopped by 1.0 s and tipped at ~1.6 s).
:func:`pipeline.scene.build_spec` gives the object-floor contacts their own friction (an explicit contact pair).

Sources of the ranges (estimates, not measurements of OMOMO's own objects, which are not published):

* **friction**, from engineering tables of static friction coefficients for dry contacts: rubber on cardboard,
  plastic or finished wood 0.5-0.9 (the G1's hands are rubber-coated); cardboard on a hard floor (laminate, vinyl,
  sealed wood) 0.3-0.5; polypropylene on a hard floor 0.2-0.4; wood on a hard floor 0.3-0.5. The mocap studio's floor
  is not given; a hard floor is assumed.
* **mass**, from catalogue weights of objects of the same kind and size (the mesh's bounding box): an empty
  corrugated moving box 0.47 x 0.46 x 0.41 m weighs 0.6-2 kg (InterMimic's G1-with-hands configuration gives it
  ~2 kg, density 25 kg/m^3 over its hulls: the upper end); a polypropylene storage box 0.56 x 0.28 x 0.39 m
  1-2.5 kg; a wooden side table 0.56 x 0.46 x 0.56 m 3-8 kg; a wooden dining chair 3-6 kg.

An object kind missing from the table gets :class:`~pipeline.geometry.ObjectPhysics`'s defaults and says so
(``material: "default"``).
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.geometry import ObjectPhysics


@dataclass(frozen=True)
class Range:
    """A physical value: its nominal value and the ``[low, high]`` range it comes from."""

    low: float
    nominal: float
    high: float

    def __post_init__(self):
        if not 0 < self.low <= self.nominal <= self.high:
            raise ValueError(f"a range needs 0 < low <= nominal <= high, got {self.low}, {self.nominal}, {self.high}")

    def at(self, end: str) -> float:
        """The value at ``end``: ``"low"``, ``"nominal"`` or ``"high"``."""
        if end not in ENDS:
            raise ValueError(f"range end must be one of {ENDS}, got {end!r}")
        return getattr(self, end)


ENDS = ("low", "nominal", "high")


@dataclass(frozen=True)
class ObjectKind:
    """An object kind's material and physical values: mass [kg], hand-object and object-floor sliding friction."""

    material: str
    mass: Range
    hand_friction: Range
    floor_friction: Range


_RUBBER_ON = Range(0.5, 0.7, 0.9)  # the G1's rubber-coated hands on cardboard, plastic or finished wood
OBJECT_KINDS: dict[str, ObjectKind] = {
    "largebox": ObjectKind("corrugated cardboard", Range(0.6, 1.2, 2.2), _RUBBER_ON, Range(0.3, 0.4, 0.5)),
    "smallbox": ObjectKind("corrugated cardboard", Range(0.3, 0.6, 1.2), _RUBBER_ON, Range(0.3, 0.4, 0.5)),
    "plasticbox": ObjectKind("polypropylene", Range(1.0, 1.5, 2.5), _RUBBER_ON, Range(0.2, 0.3, 0.4)),
    "largetable": ObjectKind("wood", Range(3.0, 5.0, 8.0), _RUBBER_ON, Range(0.3, 0.4, 0.5)),
    "smalltable": ObjectKind("wood", Range(2.0, 3.5, 6.0), _RUBBER_ON, Range(0.3, 0.4, 0.5)),
    "woodchair": ObjectKind("wood", Range(3.0, 4.5, 6.0), _RUBBER_ON, Range(0.3, 0.4, 0.5)),
    "whitechair": ObjectKind("polypropylene", Range(2.0, 3.0, 4.5), _RUBBER_ON, Range(0.2, 0.3, 0.4)),
    "trashcan": ObjectKind("polypropylene", Range(0.5, 1.0, 2.0), _RUBBER_ON, Range(0.2, 0.3, 0.4)),
}


def object_physics_for(name: str, end: str = "nominal") -> tuple[ObjectPhysics, str]:
    """``(physics, material)`` of an object kind at one ``end`` of its ranges (:data:`OBJECT_KINDS`); a kind not in
    the table: :class:`~pipeline.geometry.ObjectPhysics`'s defaults and ``"default"``."""
    kind = OBJECT_KINDS.get(name)
    if kind is None:
        return ObjectPhysics(), "default"
    return (
        ObjectPhysics(
            mass=kind.mass.at(end), friction=kind.hand_friction.at(end), floor_friction=kind.floor_friction.at(end)
        ),
        kind.material,
    )
