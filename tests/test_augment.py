"""Geometry augmentation (retarget.augment): variants of a synthetic demonstration, retargeted by the real IK."""

import numpy as np
import pytest

from ingest.synthetic import default_clips
from pipeline.clip import ObjectTrack
from pipeline.distance.field import ObjectField
from pipeline.errors import InputError
from pipeline.geometry import Chair, Primitive, variant_label
from pipeline.robot import HAND_BODIES
from pipeline.terms.link_motion import link_motion
from retarget.augment import (
    Variant,
    VariantMap,
    lifted_weight,
    not_applicable,
    parse_variants,
    variant_geometry,
    variant_mass,
)
from retarget.clip import retarget_clip
from retarget.grip import SQUEEZE
from retarget.objects import object_bottom

BOX = Primitive("box", (0.20, 0.15, 0.15))


@pytest.fixture(scope="module")
def pickup():
    return next(c for c in default_clips() if c.task == "PickUp")


@pytest.fixture(scope="module")
def retargeted(pickup):
    """The PickUp demonstration retargeted as it is, at 0.6x and as a 1.4x cylinder: (clip, metrics) per label."""
    return {v.label: retarget_clip(pickup, variant=v)[:2] for v in (Variant(), Variant((0.6,) * 3))} | {
        "x1.4-cylinder": retarget_clip(pickup, variant=Variant((1.4,) * 3, "cylinder"))[:2]
    }


def test_parse_variants_is_scales_times_shapes():
    labels = [v.label for v in parse_variants("0.6, 1,1.4:1:0.8", "box,cylinder")]
    assert labels == ["x0.6", "x0.6-cylinder", "x1", "x1-cylinder", "x1.4,1,0.8", "x1.4,1,0.8-cylinder"]
    assert Variant().identity and not Variant((1.0,) * 3, "cylinder").identity
    assert variant_label((0.5, 0.5, 0.5), "cylinder") == "x0.5-cylinder"


@pytest.mark.parametrize(
    "scales, shapes, field, match",
    [
        ("0,1", "box", "--augment-scales", "one or three positive"),
        ("-0.5", "box", "--augment-scales", "one or three positive"),
        ("big", "box", "--augment-scales", "not a number"),
        ("0.6:1", "box", "--augment-scales", "one or three"),
        ("5", "box", "--augment-scales", "outside 0.2-3"),
        ("0.6,0.6", "box", "--augment-scales", "listed twice"),
        ("0.6", "sphere", "--augment-shapes", "unknown shape 'sphere'"),
        ("0.6", "", "--augment-shapes", "empty"),
    ],
)
def test_bad_augmentation_specs_are_one_line_errors(scales, shapes, field, match):
    with pytest.raises(InputError, match=match) as info:
        parse_variants(scales, shapes)
    assert info.value.field == field and "\n" not in str(info.value)


def test_variants_that_do_not_apply_say_why():
    cylinder = Variant((1.0,) * 3, "cylinder")
    assert not_applicable(BOX, cylinder) is None
    assert "only a primitive box" in not_applicable(Chair(), cylinder)
    assert "this clip has none" in not_applicable(None, Variant((0.6,) * 3))
    assert not_applicable(None, Variant()) is None  # the clip as it is needs no object


def test_mass_is_constant_density_capped_at_the_demonstrated_mass():
    track = ObjectTrack("object", BOX, np.tile([1.0, 0, 0.15, 1, 0, 0, 0], (2, 1)), mass=1.5)
    small = variant_mass(track, variant_geometry(BOX, Variant((0.5,) * 3)))
    assert small["mass"] == pytest.approx(1.5 / 8) and not small["mass_capped"]
    big = variant_mass(track, variant_geometry(BOX, Variant((1.4, 1.0, 1.0))))
    assert big["mass"] == 1.5 and big["density_mass"] == pytest.approx(2.1) and big["mass_capped"]
    cylinder = variant_geometry(BOX, Variant((1.0,) * 3, "cylinder"))
    assert cylinder == Primitive("cylinder", (0.175, 0.15))
    assert variant_mass(track, cylinder)["mass"] == pytest.approx(1.5 * np.pi * 0.175**2 * 0.3 / (0.4 * 0.3 * 0.3))


def test_carry_keeps_a_point_on_its_face_at_its_gap():
    """A point 2 cm off the +y face goes to the scaled +y face, 2 cm off it, at the scaled place along the face; on a
    cylinder it lands 2 cm off the side."""
    u = np.array([[-0.08, 0.17, 0.12]])
    flat = ObjectField.from_geometry(BOX)
    scaled = VariantMap(np.full(3, 0.6), flat, ObjectField.from_geometry(BOX.scaled(0.6)), np.zeros(3), 0.0, *_idle())
    np.testing.assert_allclose(scaled.carry(u), [[-0.048, 0.09 + 0.02, 0.072]], atol=1e-9)
    cylinder = BOX.as_cylinder()
    vmap = VariantMap(np.ones(3), flat, ObjectField.from_geometry(cylinder), np.zeros(3), 0.0, *_idle())
    v = vmap.carry(u)[0]
    assert np.hypot(v[0], v[1]) == pytest.approx(cylinder.size[0] + 0.02, abs=1e-6) and v[2] == pytest.approx(0.12)


def _idle():
    return np.zeros(1), np.zeros(3)


def test_the_demonstration_variant_is_the_clip_itself(pickup, retargeted):
    plain = retarget_clip(pickup)[0]
    same = retargeted["x1"][0]
    np.testing.assert_array_equal(same.qpos, plain.qpos)
    assert same.source == plain.source and same.provenance["augment"]["label"] == "x1"


def test_a_variant_keeps_the_hands_on_the_faces_the_human_holds(retargeted):
    """The 0.6x box and the 1.4x cylinder: the box rests on the floor where the demonstration's did; while the human
    holds it, the G1's hands stay on opposite sides of it (the human's squeeze: n_l . n_r near -1 on the box, below
    retarget.grip.SQUEEZE on the cylinder, whose sides turn away from the grip's place) within a few cm of
    its surface as on the demonstration (the wrist link's origin: a hand's width off it); the variant carries its own
    geometry and mass rule."""
    gaps = {}
    for label, (robot, metrics) in retargeted.items():
        o = robot.objects[0]
        assert object_bottom(o.geometry, o.pose[:1])[0] == pytest.approx(0.0, abs=2e-3), label
        held = robot.contacts[:, robot.contact_links.index("left_wrist_yaw_link")]
        hands = link_motion(robot.qpos[held], np.zeros((held.sum(), 35)), HAND_BODIES, robot.source).pos
        sample = ObjectField.from_geometry(o.geometry).query_links(hands, o.pose[held])
        normals = np.asarray(sample.grad)
        opposition = np.mean(np.einsum("ti,ti->t", normals[:, 0], normals[:, 1]))
        assert opposition < (SQUEEZE if "cylinder" in label else -0.9), label  # round: the grip is off its axis
        gaps[label] = np.median(np.asarray(sample.phi))
        assert metrics["contact_preservation_frac"] > 0.9, label
    assert all(abs(gap - gaps["x1"]) < 0.02 for gap in gaps.values()), gaps
    small = retargeted["x0.6"][0]
    assert small.source.endswith("@x0.6") and small.objects[0].geometry == BOX.scaled(0.6)
    assert small.provenance["augment"]["mass"] == pytest.approx(1.5 * 0.6**3)
    assert retargeted["x1.4-cylinder"][0].objects[0].geometry.kind == "cylinder"


def test_a_lifted_object_is_held_once_it_rises(pickup):
    w = lifted_weight(pickup.resampled(50).objects[0])
    assert w[0] == 0 and w[-1] == 1 and np.all(np.diff(w[: np.argmax(w)]) >= 0)
