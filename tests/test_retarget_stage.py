"""End-to-end retargeting of real and synthetic clips against the issue's quality bars."""

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from pipeline.errors import InputError
from pipeline.stage.run import StageRun
from retarget.clip import retarget_clip
from retarget.stage import _clip_key, retarget_one

BARS = {
    "object_penetration_frac_1cm": (0.0, 0.0),
    "ground_penetration_frac_1cm": (0.0, 0.0),
    "float_frac_2cm": (0.0, 0.02),
    "foot_slide_frac_1cm_per_frame": (0.0, 0.05),
    "contact_preservation_frac": (0.9, 1.0),
    "joint_limit_violation_frac": (0.0, 0.0),
}


def _meets_bars(m: dict) -> list[str]:
    return [f"{k}={m[k]:.4f}" for k, (lo, hi) in BARS.items() if not lo <= m[k] <= hi]


@needs_shared
@pytest.mark.slow
def test_omomo_box_clip_meets_the_quality_bars():
    from pipeline.readers import read_clips

    clip = read_clips(SHARED_MOCAP / "omomo" / "sub3_largebox_003.pt")[0]
    robot, metrics, scale = retarget_clip(clip)
    assert robot.fps == 50 and robot.qpos.shape[1] == 36 and np.isfinite(robot.qpos).all()
    assert robot.objects and robot.objects[0].geometry.path.endswith("largebox.obj")
    assert _meets_bars(metrics) == []
    assert scale["subject_height_m"] == pytest.approx(1.941, abs=1e-3)
    assert 0.5 < scale["scale_leg"] < 0.9


@needs_shared
@pytest.mark.slow
def test_intermimic_table_clip_meets_the_quality_bars():
    from pipeline.readers import read_clips

    clip = read_clips(SHARED_MOCAP / "intermimic" / "sub2_largetable_000.pt")[0]
    robot, metrics, _ = retarget_clip(clip)
    assert robot.objects and _meets_bars(metrics) == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "task",
    [
        "PickUp",
        "Push",
        "SitStand",
        "Carry",
    ],
)
def test_default_clips_meet_the_quality_bars(task):
    from ingest.default_input import default_clips

    clip = next(c for c in default_clips() if c.task == task)
    _, metrics, _ = retarget_clip(clip)
    assert _meets_bars(metrics) == []


def test_short_clip_is_reported_and_others_go_on(tmp_path):
    from ingest.default_input import default_clips

    good = default_clips()[2]
    short = type(good)(good.skeleton, good.joint_pos[:1], good.fps, "short.bvh")
    with pytest.raises(InputError, match=r"short\.bvh: frames: a clip needs at least 2 frames"):
        retarget_clip(short)
    run = StageRun(tmp_path / "retargeted", "fp")
    run.begin(overwrite=False)
    results = run.map(retarget_one, [(0, short, None), (1, good, None)], key=_clip_key)
    assert results[0].robot is None and "at least 2 frames" in results[0].error
    assert results[1].robot is not None
    # resume: the finished clip is read back from the cache, identical
    assert len(list(run.clips.glob("*.pkl"))) == 2
    again = run.map(retarget_one, [(0, short, None), (1, good, None)], key=_clip_key)
    np.testing.assert_array_equal(again[1].robot.qpos, results[1].robot.qpos)


@pytest.mark.parametrize(
    "name, content",
    [("truncated.bvh", "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0"), ("notes.txt", "not mocap"), ("empty", None)],
)
def test_a_refused_input_leaves_no_dataset_folder_behind(name, content, tmp_path, monkeypatch):
    """The chain reads and validates the input before the retarget stage records its run: a refused input is one
    line and writes nothing (no ``datasets/<NAME>/.work/retargeted/run.json`` of a run that never started)."""
    from lessmimic.chain import retarget

    root = tmp_path / "datasets"
    root.mkdir()
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(root))
    src = tmp_path / name
    if content is None:
        src.mkdir()
    else:
        src.write_text(content)
    with pytest.raises(InputError) as err:
        retarget(str(src), "bad")
    assert "\n" not in str(err.value) and str(src) in str(err.value)
    assert not any(root.iterdir()), sorted(p.relative_to(root) for p in root.rglob("*"))
