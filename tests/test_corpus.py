"""The synthetic training corpus input ``synthetic:<seeds>[:<tasks>]``: parsing, the clips, the retarget fingerprint."""

import numpy as np
import pytest

from ingest.stage import is_synthetic_spec, load_input, parse_synthetic_spec, source_fingerprint, synthetic_corpus
from pipeline.errors import InputError
from retarget.stage import input_fingerprint

TASKS = ("PickUp", "SitStand", "Push", "Carry")


@pytest.mark.parametrize(
    "spec, seeds, tasks",
    [
        ("synthetic:0-24", tuple(range(25)), TASKS),
        ("synthetic:3", (3,), TASKS),
        ("synthetic:7-7", (7,), TASKS),
        ("synthetic:0,5,7", (0, 5, 7), TASKS),
        ("synthetic:9, 2-3", (9, 2, 3), TASKS),
        ("synthetic:0-24:PickUp,Push", tuple(range(25)), ("PickUp", "Push")),
        ("synthetic:1:Carry,SitStand", (1,), ("SitStand", "Carry")),  # the generator's order
    ],
)
def test_spec_grammar(spec, seeds, tasks):
    assert is_synthetic_spec(spec)
    assert parse_synthetic_spec(spec) == (seeds, tasks)


def test_only_the_prefix_names_a_corpus():
    assert not is_synthetic_spec(None) and not is_synthetic_spec("mocap/synthetic") and not is_synthetic_spec("x.bvh")


@pytest.mark.parametrize(
    "spec, field, words",
    [
        ("synthetic:5-2", "seeds", "range 5-2 is empty"),
        ("synthetic:1.5", "seeds", "'1.5' is not an integer"),
        ("synthetic:a-3", "seeds", "'a' is not an integer"),
        ("synthetic:x", "seeds", "'x' is not an integer"),
        ("synthetic:-3", "seeds", "seed -3 is negative"),
        ("synthetic:2--1", "seeds", "seed -1 is negative"),
        ("synthetic:", "seeds", "empty"),
        ("synthetic:0,,1", "seeds", "empty"),
        ("synthetic:0-2,1", "seeds", "seed 1 is listed twice"),
        ("synthetic:0:Jump", "tasks", "unknown task 'Jump' (known: PickUp, SitStand, Push, Carry)"),
        ("synthetic:0:", "tasks", "unknown task ''"),
        ("synthetic:0:Push,Push", "tasks", "listed twice"),
        ("synthetic:0:Push:x", "spec", "expected synthetic:<seeds>"),
    ],
)
def test_bad_spec_is_one_line_input_error_naming_the_field(spec, field, words):
    with pytest.raises(InputError) as err:
        parse_synthetic_spec(spec)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{spec}: {field}: ") and words in msg, msg
    assert err.value.field == field
    with pytest.raises(InputError):  # the same line from the loader and the retarget stage, before any work
        load_input(spec)
    with pytest.raises(InputError):
        source_fingerprint(spec)


def test_load_two_seeds_gives_eight_unique_synthetic_clips_with_moved_objects():
    clips = load_input("synthetic:0-1")
    assert len(clips) == 8
    assert [c.source for c in clips] == [f"synthetic:{t}:seed{s}" for s in (0, 1) for t in TASKS]
    assert all(c.synthetic for c in clips)
    assert all(o.source == c.source for c in clips for o in c.objects)
    assert [c.task for c in clips] == list(TASKS) * 2
    for a, b in zip(clips[:4], clips[4:]):  # the seed moves the objects by a few cm
        moved = np.linalg.norm(a.objects[0].pose[0, :3] - b.objects[0].pose[0, :3])
        assert 1e-3 < moved < 0.3, (a.task, moved)


def test_tasks_filter_and_seed_clips_equal_the_generators():
    from ingest.default_input import default_clips

    clips = synthetic_corpus("synthetic:3:Push,PickUp")
    assert [c.source for c in clips] == ["synthetic:PickUp:seed3", "synthetic:Push:seed3"]
    ref = {c.task: c for c in default_clips(seed=3)}
    for c in clips:
        np.testing.assert_array_equal(c.joint_pos, ref[c.task].joint_pos)
        np.testing.assert_array_equal(c.objects[0].pose, ref[c.task].objects[0].pose)


def test_default_input_is_unchanged():
    clips = load_input(None)
    assert [c.source for c in clips] == [f"synthetic:{t}" for t in TASKS]
    assert all(c.synthetic for c in clips)
    seed0 = synthetic_corpus("synthetic:0")
    for a, b in zip(clips, seed0):  # the same motion; only the source differs
        np.testing.assert_array_equal(a.joint_pos, b.joint_pos)


def fingerprint(spec, **options):
    return input_fingerprint(source_fingerprint(spec), **options)


def test_retarget_fingerprint_names_the_spec():
    fp = fingerprint("synthetic:0-24")
    assert fp == fingerprint("synthetic:0-24")  # a rerun is up to date
    assert fp == fingerprint("synthetic:0-24:PickUp,SitStand,Push,Carry")  # the same seeds and tasks
    others = {
        fingerprint(s)
        for s in ["synthetic:0-23", "synthetic:0-24:PickUp", "synthetic:1-25", "synthetic:0", "synthetic:0,1"]
    }
    assert fp not in others and len(others) == 5
    assert fingerprint(None) not in others | {fp}  # the embedded default is its own input
    assert fingerprint("synthetic:0-24", height_override=1.5) != fp
