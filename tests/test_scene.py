"""Scenes: robot actuators and collision set, objects of every geometry kind, physics properties."""

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from pipeline.errors import InputError
from pipeline.geometry import Chair, MeshGeometry, ObjectPhysics, Primitive
from pipeline.robot import G1_JOINT_NAMES, actuator_profile
from pipeline.scene import Scene, SceneObject, build_scene, build_spec, restitution_damping_ratio


def _settle(scene: Scene, seconds: float = 1.0) -> mujoco.MjData:
    d = mujoco.MjData(scene.model)
    for o in scene.objects:
        if not o.fixed:
            a = scene.object_qpos_adr[o.name]
            d.qpos[a : a + 7] = o.pose
    d.qpos[:3] = (-5, 0, 0.8)  # robot far away
    for _ in range(int(seconds / scene.model.opt.timestep)):
        mujoco.mj_step(scene.model, d)
    return d


def test_robot_actuators_follow_profile():
    for name in ("mjlab", "lessmimic_demo"):
        s = build_scene(profile=name)
        prof = actuator_profile(name)
        m = s.model
        assert m.nu == 29 and m.opt.timestep == 0.005
        for i, j in enumerate(G1_JOINT_NAMES):
            a = m.actuator(j.removesuffix("_joint"))
            assert m.actuator_trnid[a.id, 0] == m.joint(j).id
            assert m.actuator_gainprm[a.id, 0] == pytest.approx(prof.kp[i])
            assert m.actuator_biasprm[a.id, 2] == pytest.approx(-prof.kd[i])
            assert m.actuator_forcerange[a.id, 1] == pytest.approx(prof.effort_limit[i])
            assert m.dof_armature[m.jnt_dofadr[m.joint(j).id]] == pytest.approx(prof.armature[i])


def test_robot_collision_set_is_mjlab_full_collision():
    m = build_scene().model
    for g in range(m.ngeom):
        name = m.geom(g).name
        if name.endswith("_collision"):
            assert m.geom_contype[g] == 1 and m.geom_conaffinity[g] == 1
            assert m.geom_condim[g] == (3 if "_foot" in name else 1)
        elif m.geom_bodyid[g] != 0:
            assert m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0, name


def test_pd_hold_torque_equals_profile():
    s = build_scene()
    d = mujoco.MjData(s.model)
    d.qpos[:7] = (0, 0, 2.0, 1, 0, 0, 0)
    d.ctrl[:] = 0.1
    mujoco.mj_forward(s.model, d)
    prof = actuator_profile("mjlab")
    np.testing.assert_allclose(d.actuator_force, prof.torque(np.full(29, 0.1), d.qpos[7:], d.qvel[6:]))


@pytest.mark.parametrize(
    "geometry, rest_height",
    [
        (Primitive("box", (0.2, 0.15, 0.1), scale=(1.0, 1.0, 2.0)), 0.2),
        (Primitive("sphere", (0.1,), scale=(1.0, 1.0, 1.5)), 0.15),  # ellipsoid
        (Primitive("cylinder", (0.1, 0.2)), 0.2),
        (Primitive("cylinder", (0.1, 0.2), scale=(2.0, 1.0, 0.5)), 0.1),  # elliptic: convex mesh
        (Primitive("capsule", (0.05, 0.1), scale=(1.0, 1.0, 1.0)), 0.15),
    ],
)
def test_primitive_rests_on_floor_at_its_scaled_half_height(geometry, rest_height):
    obj = SceneObject("obj", geometry, ObjectPhysics(mass=3.0), pose=(0, 0, rest_height + 0.05, 1, 0, 0, 0))
    s = build_scene([obj])
    d = _settle(s)
    assert s.model.body_mass[s.object_body_id["obj"]] == pytest.approx(3.0)
    assert d.xpos[s.object_body_id["obj"], 2] == pytest.approx(rest_height, abs=3e-3)


def test_chair_seat_top_at_seat_height():
    chair = Chair(seat_height=0.52)
    s = build_scene([SceneObject("chair", chair, fixed=True)])
    m = s.model
    seat = m.geom("chair_seat")
    top = m.geom_pos[seat.id, 2] + m.geom_size[seat.id, 2]
    assert top == pytest.approx(0.52)
    names = {m.geom(g).name for g in range(m.ngeom) if m.geom_bodyid[g] == s.object_body_id["chair"]}
    assert names == {"chair_seat", "chair_back", "chair_leg0", "chair_leg1", "chair_leg2", "chair_leg3"}


def test_restitution_bounce_height():
    """A ball dropped from 0.5 m rebounds to about e^2 * 0.5 m."""
    heights = {}
    for e in (0.0, 0.6, 0.8):
        obj = SceneObject(
            "ball", Primitive("sphere", (0.05,)), ObjectPhysics(mass=0.5, restitution=e), pose=(0, 0, 0.55, 1, 0, 0, 0)
        )
        s = build_scene([obj])
        d = mujoco.MjData(s.model)
        d.qpos[:3] = (-5, 0, 0.8)
        a = s.object_qpos_adr["ball"]
        d.qpos[a : a + 7] = obj.pose
        rising, peak = False, 0.0
        for _ in range(300):  # 1.5 s: the first rebound only
            mujoco.mj_step(s.model, d)
            v = d.qvel[s.model.jnt_dofadr[s.model.joint("ball_free").id] + 2]
            rising |= v > 0
            if rising:
                peak = max(peak, d.qpos[a + 2] - 0.05)
            if rising and v < 0:
                break
        heights[e] = peak
    assert heights[0.0] < 0.01
    assert heights[0.6] == pytest.approx(0.36 * 0.5, rel=0.1)
    assert heights[0.8] == pytest.approx(0.64 * 0.5, rel=0.1)
    assert restitution_damping_ratio(0.0) == 1.0
    assert restitution_damping_ratio(math.exp(-math.pi)) == pytest.approx(1 / math.sqrt(2))


def test_duplicate_object_names():
    box = Primitive("box", (0.1, 0.1, 0.1))
    with pytest.raises(ValueError, match="unique"):
        build_scene([SceneObject("a", box), SceneObject("a", box)])


def test_missing_and_empty_mesh(tmp_path: Path):
    with pytest.raises(InputError, match=r"nope\.obj: mesh: object mesh file not found"):
        build_scene([SceneObject("m", MeshGeometry(str(tmp_path / "nope.obj")))])
    empty = tmp_path / "empty.obj"
    empty.write_text("# no vertices\n")
    with pytest.raises(InputError, match=r"empty\.obj: mesh: .*(empty|cannot be read)"):
        build_scene([SceneObject("m", MeshGeometry(str(empty)))])
    triangle = tmp_path / "triangle.obj"
    triangle.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=r"triangle\.obj: mesh: has 3 vertices: too few to enclose a volume"):
        build_scene([SceneObject("m", MeshGeometry(str(triangle)))])
    with pytest.raises(InputError, match=r": mesh: is a folder; give the object's mesh file"):
        build_scene([SceneObject("m", MeshGeometry(str(tmp_path)))])


@needs_shared
def test_omomo_box_mesh_collides_through_its_hull():
    """The OMOMO box scan is not watertight; its hull rests on the floor (its lowest vertex at z = 0)."""
    import trimesh

    from pipeline.rotations import rotation_from_wxyz

    path = SHARED_MOCAP / "omomo" / "largebox.obj"
    mesh = trimesh.load(path, force="mesh")
    assert not mesh.is_watertight
    obj = SceneObject(
        "box", MeshGeometry(str(path)), ObjectPhysics(mass=4.0), pose=(0, 0, -mesh.bounds[0, 2] + 0.02, 1, 0, 0, 0)
    )
    s = build_scene([obj])
    d = _settle(s)
    a = s.object_qpos_adr["box"]
    world = rotation_from_wxyz(d.qpos[a + 3 : a + 7]).apply(mesh.convex_hull.vertices) + d.qpos[a : a + 3]
    assert world[:, 2].min() == pytest.approx(0.0, abs=3e-3)
    assert s.model.body_mass[s.object_body_id["box"]] == pytest.approx(4.0)


def test_link_contact_surfaces():
    from pipeline.scene import link_collision_geoms

    m = build_scene().model
    names = lambda body: sorted(m.geom(g).name for g in link_collision_geoms(m, body))  # noqa: E731
    assert names("pelvis") == [
        "left_hip_collision",
        "pelvis_collision",
        "right_hip_collision",
    ]  # the G1 sits on its hips
    assert names("left_hip_pitch_link") == ["left_hip_collision"]  # no geoms of its own: the child's capsule
    assert len(names("left_ankle_roll_link")) == 7
    with pytest.raises(ValueError, match="'nose' is not a body"):
        link_collision_geoms(m, "nose")


def _push_box(hand_mu: float, floor_mu: float, height: float, force_share: float) -> tuple[float, float]:
    """``(travel [m], tilt [deg])`` after 1 s of a horizontal push of ``force_share`` x m g at ``height`` above the
    floor on a 0.4 x 0.4 x 0.8 m, 2 kg box (its own robot-contact friction ``hand_mu``, its floor pair's
    ``floor_mu``), far from the robot."""
    half = np.array([0.2, 0.2, 0.4])
    box = SceneObject(
        "box", Primitive("box", tuple(half)), ObjectPhysics(2.0, hand_mu, floor_mu), pose=(5, 0, half[2], 1, 0, 0, 0)
    )
    m = build_scene([box]).model
    d = mujoco.MjData(m)
    b = m.body("box").id
    f = np.array([force_share * 2.0 * 9.81, 0.0, 0.0])
    for _ in range(200):
        d.qfrc_applied[:] = 0
        point = d.xpos[b] + [-half[0], 0.0, height - d.xpos[b][2]]  # on the back face, ``height`` above the floor
        mujoco.mj_applyFT(m, d, f, np.zeros(3), point, b, d.qfrc_applied)
        mujoco.mj_step(m, d)
    up = d.xmat[b].reshape(3, 3)[:, 2]
    return float(d.qpos[-7] - 5.0), float(np.degrees(np.arccos(np.clip(up[2], -1, 1))))


def test_a_box_pushed_low_slides_at_its_floor_friction_not_its_hand_friction():
    """Pushed at h = 0.2 m over half-width b = 0.2 m (h / b = 1 < 1 / mu): it slides once the push exceeds
    mu_floor m g, and the hand friction (0.9, the object's geoms) plays no part (the floor pair decides)."""
    travel, tilt = _push_box(0.9, 0.3, 0.2, 0.4)
    assert travel == pytest.approx(0.5 * (0.4 - 0.3) * 9.81, rel=0.1) and tilt < 2.0  # (F / m - mu g) t^2 / 2
    travel, tilt = _push_box(0.9, 0.3, 0.2, 0.2)  # below mu m g: it stays
    assert abs(travel) < 0.01 and tilt < 2.0
    travel, tilt = _push_box(0.3, 0.9, 0.2, 0.4)  # the same push on a grippy floor: it stays
    assert abs(travel) < 0.01 and tilt < 2.0


def test_a_box_pushed_high_tips_before_it_slides():
    """Pushed at h = 0.6 m (h / b = 3 > 1 / mu = 1.25 at mu 0.8): it tips once the push exceeds m g b / h = 0.33 m g,
    long before it could slide (0.8 m g); at mu 0.25 (h / b < 4) the same push slides it upright."""
    travel, tilt = _push_box(0.8, 0.8, 0.6, 0.45)
    assert tilt > 45.0
    travel, tilt = _push_box(0.8, 0.25, 0.6, 0.3)
    assert travel == pytest.approx(0.5 * (0.3 - 0.25) * 9.81, rel=0.1) and tilt < 2.0


def _squeeze(mu: float, force_share: float, mass: float = 1.5) -> float:
    """How far [m] a box (0.3 m cube, ``mass``, hand-contact friction ``mu``) drops in 1 s, squeezed from rest
    between two capsules (radius 4 cm, the G1's hand size) pressed horizontally onto opposite faces, each with
    ``force_share`` x the normal force ``N = m g / (2 mu)`` at which friction just carries the weight. The scene's
    contact model (elliptic cones, impratio 10), the G1 far away."""
    spec = build_spec([SceneObject("box", Primitive("box", (0.15, 0.15, 0.15)), ObjectPhysics(mass, mu),
                                   pose=(5, 0, 1.0, 1, 0, 0, 0))])  # fmt: skip
    for side in (1, -1):
        body = spec.worldbody.add_body(name=f"pad{side}", pos=[5, side * 0.20, 1.0])
        body.add_joint(name=f"slide{side}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 1, 0])
        g = body.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.04, 0.05, 0], fromto=[-0.05, 0, 0, 0.05, 0, 0])
        g.mass = 0.5
        g.contype = g.conaffinity = 1
        body.gravcomp = 1.0
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    box = m.body("box").id
    z0 = d.xpos[box][2]
    push = force_share * mass * 9.81 / (2 * mu)
    for _ in range(200):
        for side in (1, -1):
            d.qfrc_applied[m.jnt_dofadr[m.joint(f"slide{side}").id]] = -side * push
        mujoco.mj_step(m, d)
    return float(z0 - d.xpos[box][2])


@pytest.mark.parametrize("mu", [0.5, 0.8])
def test_a_squeeze_holds_a_box_while_friction_carries_its_weight(mu):
    """Two hands of normal force N hold a box of mass m while 2 mu N >= m g, and it slips below: the physics the
    grasp planner's squeeze (physicalize.grasp_force.normal_force) counts on."""
    assert _squeeze(mu, 1.1) < 0.01  # 10% above: held (the soft contacts settle a few mm)
    assert _squeeze(mu, 0.9) > 0.2  # 10% short: it slips down between the hands to the floor
