"""The robot-alone mode and the balance trace every physicalized clip carries (physicalize/balance.py), on a standing
G1 in real MuJoCo: held, and pushed over."""

import numpy as np
import pytest
from bench_scripts import load
from mocap_paths import SHARED_MOCAP, needs_shared
from standing import standing_qpos

from physicalize.balance import _zmp_outside, balance_figures, reference_balance_figures
from physicalize.clip import physicalize_clip, robot_alone
from physicalize.reference import build_reference, place_on_floor
from pipeline.clip import ObjectTrack, RobotClip
from pipeline.geometry import Primitive
from pipeline.robot import actuator_profile, default_qpos
from pipeline.scene import build_scene

TRACE_KEYS = (
    "pelvis_drift_pre_fall_m",
    "com_drift_pre_fall_m",
    "drift_onset_s",
    "drift_onset_support",
    "step_adjustments",
    "step_adjust_max_m",
    "support_mismatch_frac",
    "reference_single_support_max_s",
    "plan_zmp_outside_max_m",
    "reference_foot_gap_min_m",
)


def _stand(frames: int = 100) -> RobotClip:
    stand = standing_qpos(frames)
    box = np.tile([0.8, 0.0, 0.15, 1.0, 0.0, 0.0, 0.0], (frames, 1))
    contacts = np.zeros((frames, 1), bool)
    contacts[60:, 0] = True
    return RobotClip(
        stand,
        50,
        "hand-made:stand",
        objects=(ObjectTrack("box", Primitive("box", (0.15, 0.15, 0.15)), box, None, 1.0, "hand-made"),),
        contact_links=("left_wrist_yaw_link",),
        contacts=contacts,
        task="stand",
    )


def test_robot_alone_drops_the_object_and_its_contacts_only():
    clip = _stand()
    alone = robot_alone(clip)
    assert alone.objects == () and alone.contact_links == () and alone.contacts is None
    assert alone.provenance["robot_alone"] and np.array_equal(alone.qpos, clip.qpos) and alone.fps == clip.fps
    robot, roll, figures, _ = physicalize_clip(alone)
    assert figures["valid"] and "object_pos_err_m" not in figures and figures["reference_first_contact_s"] is None
    assert robot.objects == () and roll.frames == clip.frames


def test_a_held_stand_has_a_quiet_trace():
    _, roll, figures, _ = physicalize_clip(robot_alone(_stand()))
    assert set(TRACE_KEYS) <= set(figures)
    assert figures["drift_onset_s"] is None and figures["drift_onset_support"] is None
    assert figures["pelvis_drift_pre_fall_m"] < 0.01 and figures["com_drift_pre_fall_m"] < 0.01
    assert figures["step_adjustments"] == 0 and figures["support_mismatch_frac"] == 0.0
    assert figures["reference_single_support_max_s"] == 0.0 and figures["plan_zmp_outside_max_m"] == 0.0
    assert roll.support.shape == (roll.frames, 2) and roll.support.all()
    assert roll.landing_shift.shape == (roll.frames, 2, 2)


def test_a_push_that_topples_the_robot_is_traced_to_its_drift():
    """A 250 N shove on the pelvis from 0.6 s: the pelvis drifts off its reference in double support before the fall,
    and the trace says when, on which support, and how far 0.2 s before the fall."""
    clip = robot_alone(_stand(150))

    def shove(t, d):
        d.xfrc_applied[1, 0] = 250.0 if t >= 30 else 0.0

    _, roll, figures, _ = physicalize_clip(clip, perturb=shove, gains=None)
    assert figures["fell"] and roll.fell_at is not None
    onset, fell = figures["drift_onset_s"], figures["fell_at_s"]
    assert onset is not None and 0.6 <= onset < fell and figures["drift_onset_support"] == "double"
    assert figures["pelvis_drift_pre_fall_m"] > 0.05 and figures["com_drift_pre_fall_m"] > 0.05


def test_a_planned_zmp_off_the_feet_is_measured():
    model = build_scene().model
    q = place_on_floor(model, np.repeat(default_qpos(actuator_profile("mjlab"))[None], 10, 0))
    ref = build_reference(model, q, 50.0)
    centre = ref.corners[:, :, :, :2].reshape(10, -1, 2).mean(axis=1)
    assert _zmp_outside(ref, centre) == 0.0
    assert _zmp_outside(ref, centre + [1.0, 0.0]) > 0.8
    assert _zmp_outside(ref, None) == 0.0


def test_balance_figures_need_no_plan():
    """A reference without a CoM plan (the raw reference) is traced against its kinematic CoM."""
    _, roll, _, _ = physicalize_clip(robot_alone(_stand(20)), reference="raw")
    model = build_scene().model
    ref = build_reference(model, _stand(20).qpos, 50.0)
    figures = balance_figures(model, ref, roll, 20.0)
    assert figures["com_drift_pre_fall_m"] < 0.02
    assert reference_balance_figures(ref, None)["plan_zmp_outside_max_m"] == 0.0


@needs_shared
def test_the_bench_runs_a_take_robot_alone():
    bench = load("bench_physicalize_real")
    row = bench.run_clip(SHARED_MOCAP / "interact" / "sub2_woodchair_003.pt", robot_only=True)
    assert row["kind"] == "small move" and "object_pos_err_m" not in row
    assert row["verdict"] == "valid" or row["verdict"].startswith("failed: fell")
    line = bench.trace_line(row)
    assert line.startswith("fell ") and "drift@" in line and "zmp" in line


@pytest.mark.parametrize("flags", [["--robot-only", "--sensitivity"]])
def test_the_bench_refuses_robot_alone_with_the_physics_ranges(flags, monkeypatch, capsys):
    bench = load("bench_physicalize_real")
    monkeypatch.setattr("sys.argv", ["bench_physicalize_real.py", *flags])
    with pytest.raises(SystemExit) as exit_:
        bench.main()
    assert exit_.value.code == 2 and "--robot-only and --sensitivity" in capsys.readouterr().err
