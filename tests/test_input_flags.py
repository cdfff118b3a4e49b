"""Issue 55, case 8 and part 4: the errors name the flags the command line has (``--fps``, ``--units``, ``--height``,
where they said ``fps=``, ``units=``, ``height_override``) and the flag fixes the case; what is only suspicious in an
input is read, printed once as a warning and listed in the stage's report (:mod:`pipeline.suspicious`)."""

import json
import re

import numpy as np
import pytest
from mocap_paths import needs_shared
from test_bad_inputs import _bvh, _keypoints_csv, _omomo_height

from lessmimic.cli import main


def test_the_flags_the_messages_name_exist_and_fix_the_case(tmp_path, monkeypatch, capsys):
    """Issue 55, case 8: the errors said ``pass fps=``, ``units=``, ``height_override``; each now names the flag, and
    the flag is what makes the file read: a keypoints CSV in centimetres, without a rate or a skeleton tree."""
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "datasets"))
    csv = _keypoints_csv(tmp_path)
    steps = [
        ([], 2, "fps: no time column; pass --fps N"),
        (["--fps", "30"], 2, "pelvis position: moves .* m/s .*: a jump or a wrong unit \\(--units\\)"),  # cm read as m
        (["--fps", "30", "--units", "cm"], 1, "subject_height: unknown .*; pass --height M"),  # no tree: no estimate
        (["--fps", "30", "--units", "cm", "--height", "1.7"], 0, None),
    ]
    for flags, status, error in steps:
        assert main(["retarget", "--input", str(csv), *flags]) == status, flags
        captured = capsys.readouterr()
        if error is not None:
            line = next(ln for ln in (captured.err + captured.out).splitlines() if ln.startswith("error: "))
            assert re.search(f"{re.escape(str(csv))}: (frame \\d+: )?{error}", line), line
    report = json.loads((tmp_path / "datasets" / "default" / "retargeted" / "report.json").read_text())
    assert report["clips"][0]["scale"]["height_source"] == "override" and report["warnings"] == []
    human = json.loads((tmp_path / "datasets" / "default" / "human" / "report.json").read_text())
    assert human["clips"][0]["fps"] == 30 and human["frames"] == 40
    assert main(["retarget", "--input", str(csv), "--fps", "30", "--units", "cm", "--height", "1.7"]) == 0
    assert "is up to date" in capsys.readouterr().out
    assert main(["retarget", "--input", str(csv), "--fps", "25", "--units", "cm", "--height", "1.7"]) == 2
    assert "--overwrite" in capsys.readouterr().err  # another rate is another input


def test_units_and_rate_reach_the_readers(tmp_path):
    from pipeline.errors import InputError
    from pipeline.readers import read_clips

    bvh = _bvh(tmp_path, [0, 0.01], sideways=True)
    with pytest.raises(InputError, match="pass --units m"):
        read_clips(bvh)
    assert np.allclose(read_clips(bvh, units="cm")[0].joint_pos, read_clips(bvh, units="m")[0].joint_pos * 0.01)
    assert read_clips(_keypoints_csv(tmp_path), fps=24, units="cm")[0].fps == 24


def test_what_is_only_suspicious_is_a_warning_line_and_in_the_reports(tmp_path, monkeypatch, capsys):
    """Issue 55, part 4: a root lurching 25 cm in one frame (~8 m/s: above a run, under the 15 m/s that is an error)
    is read, said once on stderr, and listed in the human and retargeted reports."""
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "datasets"))
    csv = _keypoints_csv(tmp_path, lurch_cm=25.0)
    assert main(["retarget", "--input", str(csv), "--fps", "30", "--units", "cm", "--height", "1.7"]) == 0
    captured = capsys.readouterr()
    warned = [ln for ln in captured.err.splitlines() if ln.startswith("warning: ")]
    said = f"{re.escape(str(csv))}: frame 20: pelvis position: moves [6-9]\\.\\d+ m/s since the frame before"
    assert len(warned) == 1 and re.fullmatch(f"warning: {said} \\(1 frame\\(s\\) above 5 m/s, a run\\); read as it is",
                                              warned[0]), warned  # fmt: skip
    assert "  1 warning(s) about the input, read as it is (listed in report.json)" in captured.out.splitlines()
    for stage in ("human", "retargeted"):
        report = json.loads((tmp_path / "datasets" / "default" / stage / "report.json").read_text())
        assert report["warnings"] == [warned[0].removeprefix("warning: ")]


def test_the_readers_say_what_is_suspicious(tmp_path):
    from pipeline.readers import read_clips
    from pipeline.suspicious import SuspiciousInput, collecting

    fast = _bvh(tmp_path, [0, 0.2, 0.4, 0.6], name="fast.bvh")  # 6 m/s in metres
    turned = _bvh(tmp_path, [0, 0.01, 0.02], rs=[10, 400, 10], name="turned.bvh")
    with collecting() as seen:
        for path in (fast, turned, fast):  # the same said once
            read_clips(path, units="m")
    assert seen == [
        f"{fast}: frame 1: Hips position: moves 6 m/s since the frame before (3 frame(s) above 5 m/s, a run); "
        "read as it is",
        f"{turned}: frame 1: Hips.Xrotation: 400 degrees is beyond +-360 (a full turn; 1 value(s)): read as is",
    ]
    with pytest.warns(SuspiciousInput, match="Hips.Xrotation: 400 degrees"):  # outside a stage: a Python warning
        read_clips(turned, units="m")


@needs_shared
def test_a_stated_height_far_from_the_joints_is_a_warning(tmp_path):
    """OMOMO's height_dict.pkl saying 1.2 m for a subject whose joints measure 1.84 m: read as stated, and said."""
    from pipeline.readers import read_clips
    from pipeline.suspicious import collecting

    take = _omomo_height(tmp_path, 1.2)
    with collecting() as seen:
        (clip,) = read_clips(take)
    assert clip.subject_height == 1.2
    assert len(seen) == 1 and re.fullmatch(
        f"{re.escape(str(take))}: subject_height: 1.2 m as the input states it, 1.84 m from its joints "
        "\\(head to ankle\\): 35% apart; read as stated \\(--height M overrides it\\)",
        seen[0],
    ), seen
