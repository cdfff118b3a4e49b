"""The paper's success rules (App. "Evaluation Metrics") on hand-made step sequences: each rule passes at its
threshold and fails just short of it; R_acc on a hand-made trajectory."""

import numpy as np
import pytest

from train.mdp.tasks import Rules, StepFacts, TaskMeter

FPS = 50.0


def facts(**kw) -> StepFacts:
    base = dict(
        object_low=0.0,
        object_pos=np.zeros(3),
        object_ref=np.zeros(3),
        root_z=0.75,
        root_dev_m=0.0,
        pelvis_on_object=False,
        hand_on_object=False,
        body_on_object=False,
        reference_pushing=False,
    )
    return StepFacts(**{**base, **kw})


def run(task: str, steps: list[StepFacts], track_end=(0.0, 0.0, 0.0)) -> TaskMeter:
    meter = TaskMeter(task, FPS, track_end=np.array(track_end))
    for f in steps:
        meter.update(f)
    return meter


@pytest.mark.parametrize(("seconds", "low", "expected"), [(3.0, 0.31, True), (2.98, 0.31, False), (3.0, 0.29, False)])
def test_pickup_needs_the_box_above_0_3_m_for_3_s(seconds, low, expected):
    held = [facts(object_low=low)] * int(round(seconds * FPS))
    assert run("PickUp", [facts()] * 10 + held + [facts()] * 5).success is expected


def test_pickup_hold_must_be_unbroken():
    half = [facts(object_low=0.5)] * int(2 * FPS)
    assert not run("PickUp", half + [facts(object_low=0.1)] + half).success


@pytest.mark.parametrize(("root_z", "expected"), [(0.55, True), (0.3, True), (0.6, True), (0.62, False), (0.25, False)])
def test_sitstand_needs_pelvis_contact_with_the_root_in_0_3_0_6_m(root_z, expected):
    seated = [facts(pelvis_on_object=True, root_z=root_z)] * int(Rules().sit_s * FPS)
    meter = run("SitStand", [facts()] * 20 + seated + [facts()] * 20)
    assert meter.success is expected
    summary = meter.summary()
    assert summary["seated_s"] == pytest.approx(Rules().sit_s) and summary["seated_root_z_m"] == pytest.approx(root_z)


def test_sitstand_contact_must_last():
    short = [facts(pelvis_on_object=True, root_z=0.5)] * (int(Rules().sit_s * FPS) - 1)
    meter = run("SitStand", short)
    assert not meter.success and run("SitStand", [facts()]).summary()["seated_root_z_m"] is None


def _carry(max_dev: float, end_low: float, picked: bool = True) -> list[StepFacts]:
    ref = np.zeros(3)
    lift = [facts(object_low=0.4 if picked else 0.0, object_pos=np.array([max_dev, 0, 0]), object_ref=ref)]
    return [facts()] * 5 + lift * 20 + [facts(object_low=end_low, object_pos=np.array([0.1, 0, 0]), object_ref=ref)]


@pytest.mark.parametrize(
    ("steps", "expected"),
    [
        (_carry(0.5, 0.0), True),
        (_carry(0.61, 0.0), False),  # strayed more than 0.6 m from the track once
        (_carry(0.5, 0.2), False),  # not put down
        (_carry(0.5, 0.0, picked=False), False),  # never picked up
    ],
)
def test_carry_picks_follows_within_0_6_m_and_places(steps, expected):
    assert run("Carry", steps).success is expected


def test_carry_placed_means_at_the_track_end_not_where_a_fall_dropped_it():
    dropped = _carry(0.5, 0.0)  # on the floor, on the track at the last step, but the track goes on to x = 2 m
    assert not run("Carry", dropped, track_end=(2.0, 0.0, 0.0)).success
    assert run("Carry", dropped, track_end=(0.5, 0.0, 0.0)).success
    with pytest.raises(ValueError, match="track_end"):
        TaskMeter("Carry", FPS)


def test_push_rate_counts_hand_contact_while_the_reference_pushes_and_body_contact_fails():
    pushing = [facts(reference_pushing=True, hand_on_object=True)] * 30 + [facts(reference_pushing=True)] * 10
    meter = run("Push", [facts(hand_on_object=True)] * 50 + pushing)  # contact outside the push does not count
    assert meter.contact_rate == pytest.approx(0.75) and meter.success
    leaning = [facts(reference_pushing=True, hand_on_object=True, body_on_object=True)] * 10
    leaning += [facts(reference_pushing=True, body_on_object=True)] * 11
    assert run("Push", leaning).contact_rate == 0.0


def test_push_rate_counts_the_pushing_frames_after_a_fall_as_without_contact():
    meter = TaskMeter("Push", FPS, push_total=40)  # the reference pushes 40 frames; the episode ends after 20
    for f in [facts(reference_pushing=True, hand_on_object=True)] * 20:
        meter.update(f)
    assert meter.contact_rate == pytest.approx(0.5)


def test_unknown_task_is_refused():
    with pytest.raises(ValueError, match="unknown task"):
        TaskMeter("Dance", FPS)


def test_r_acc_on_a_hand_made_trajectory():
    """The commanded root walks along x at 1 m/s; the root follows it but drifts sideways 1 cm per step (and crouches,
    which the horizontal distance ignores): on the track (<= 0.6 m) for steps 1..60 of 100, so R_acc = 0.6."""
    t = np.arange(1, 101)
    command = np.column_stack([t / FPS, np.zeros(100), np.full(100, 0.75)])
    root = np.column_stack([t / FPS, 0.01 * t, np.linspace(0.75, 0.45, 100)])
    steps = [facts(root_z=r[2], root_dev_m=float(np.linalg.norm(r[:2] - c[:2]))) for r, c in zip(root, command)]
    meter = TaskMeter("PickUp", FPS, root_total=100)
    for f in steps:
        meter.update(f)
    assert meter.root_within == 60 and meter.summary()["root_accuracy"] == pytest.approx(0.6)
    assert Rules().root_tolerance_m == 0.6


def test_r_acc_counts_the_steps_a_fall_cut_off_as_off_the_track():
    """A policy on the track until it falls at step 10 of a 100-step episode scores 10%, not 100%."""
    meter = TaskMeter("Push", FPS, root_total=100)
    for f in [facts(root_dev_m=0.1)] * 10:
        meter.update(f)
    assert meter.root_accuracy == pytest.approx(0.1)
    unbounded = TaskMeter("Push", FPS)  # without the episode's length: the steps run
    for f in [facts(root_dev_m=0.6)] * 3 + [facts(root_dev_m=0.61)]:
        unbounded.update(f)
    assert unbounded.root_accuracy == pytest.approx(0.75) and TaskMeter("Push", FPS).root_accuracy == 0.0
