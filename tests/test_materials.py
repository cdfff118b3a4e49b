"""Object physics of real takes (:mod:`pipeline.materials`): one table per object kind, each value with its range,
applied by the OMOMO reader and built into the scene's contacts."""

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from pipeline.geometry import ObjectPhysics
from pipeline.materials import ENDS, OBJECT_KINDS, Range, object_physics_for
from pipeline.scene import SceneObject, build_scene


def test_every_kind_has_ranges_in_physical_bounds():
    for name, kind in OBJECT_KINDS.items():
        assert 0.1 <= kind.mass.low <= kind.mass.high <= 20.0, name
        for r in (kind.hand_friction, kind.floor_friction):
            assert 0.05 <= r.low <= r.nominal <= r.high <= 1.2, name
        assert kind.floor_friction.nominal < kind.hand_friction.nominal, name  # objects slide; rubber grips


def test_a_range_knows_its_ends_and_refuses_disorder():
    r = Range(0.2, 0.3, 0.5)
    assert [r.at(e) for e in ENDS] == [0.2, 0.3, 0.5]
    with pytest.raises(ValueError, match="low <= nominal <= high"):
        Range(0.5, 0.3, 0.6)
    with pytest.raises(ValueError, match="range end must be one of"):
        r.at("middle")


def test_a_kind_at_each_end_and_an_unknown_kind():
    for end in ENDS:
        physics, material = object_physics_for("largebox", end)
        kind = OBJECT_KINDS["largebox"]
        assert (physics.mass, physics.friction, physics.floor_friction) == (
            kind.mass.at(end),
            kind.hand_friction.at(end),
            kind.floor_friction.at(end),
        )
        assert material == kind.material
    assert object_physics_for("spaceship") == (ObjectPhysics(), "default")


@needs_shared
def test_an_omomo_take_carries_its_kind_s_physics_into_the_scene():
    from pipeline.readers import read_clips

    clip = read_clips(SHARED_MOCAP / "interact" / "sub8_plasticbox_000.pt")[0]
    o = clip.objects[0]
    physics, material = object_physics_for("plasticbox")
    assert (o.mass, o.friction, o.floor_friction, o.material) == (
        physics.mass,
        physics.friction,
        physics.floor_friction,
        material,
    )
    scene = build_scene([SceneObject(o.name, o.geometry, o.physics(), pose=tuple(o.pose[0]))])
    m = scene.model
    body = m.body(o.name).id
    geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] == body and m.geom_contype[g]]
    assert np.allclose(m.geom_friction[geoms, 0], physics.friction)  # with the robot
    assert m.npair == len(geoms) and np.allclose(m.pair_friction[:, :2], physics.floor_friction)  # with the floor
    assert m.body_subtreemass[body] == pytest.approx(physics.mass)
