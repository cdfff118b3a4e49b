"""An augmented corpus end to end (slow): retarget with variants, physicalize (the yield per task and variant),
features, LeRobot's loader on the per-variant geometry, the training subset and the two evaluation protocols."""

import json

import numpy as np
import pytest
from mocap_paths import expect_input_error

from features.stage import run_stage as features_stage
from lessmimic.chain import retarget as retarget_stage
from physicalize.stage import run_stage as physicalize_stage
from pipeline.dataset.clips import episodes_to_physicalized_clips, episodes_to_robot_clips
from pipeline.dataset.subset import corpus_variants, read_subset, subset_corpus
from pipeline.geometry import Primitive
from pipeline.stage.paths import logs_dir, stage_dir
from retarget.augment import parse_variants
from train.actors import TeacherActor
from train.episodes import episode_variant, load_episodes
from train.evaluation.cells import cell_episodes, rule_window
from train.evaluation.table2 import EvalConfig, evaluate, markdown, scale_line, scale_note
from train.mdp.tasks import Rules

pytestmark = pytest.mark.slow
VARIANTS = "x0.6", "x0.6-cylinder", "x1", "x1-cylinder"


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """PickUp and SitStand of seed 0 at 0.6x and 1x, as boxes and cylinders (a chair has no cylinder form), through
    the three stages in a temporary datasets root."""
    root = tmp_path_factory.mktemp("datasets")
    mp = pytest.MonkeyPatch()
    mp.setenv("LESSMIMIC_DATASETS", str(root))
    retarget_stage("synthetic:0:PickUp,SitStand", "aug", variants=parse_variants("0.6,1", "box,cylinder"))
    physicalize_stage("aug")
    features_stage("aug")
    yield root
    mp.undo()


def test_every_variant_is_an_episode_with_its_geometry_or_a_reason(root):
    report = json.loads((logs_dir(stage_dir("aug", "retargeted")) / "report.json").read_text())
    assert sorted((c["task"], c["variant"]) for c in report["clips"]) == sorted(
        [("PickUp", v) for v in VARIANTS] + [("SitStand", "x0.6"), ("SitStand", "x1")]
    )
    assert [(n["source"], n["variant"]) for n in report["not_applicable"]] == [
        ("synthetic:SitStand:seed0", "x0.6-cylinder"),
        ("synthetic:SitStand:seed0", "x1-cylinder"),
    ]
    assert set(report["variants"]) == set(VARIANTS) and report["variants"]["x0.6"]["clips"] == 2
    assert corpus_variants("aug") == list(VARIANTS)


def test_per_variant_geometry_round_trips_through_lerobots_loader(root):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    src = stage_dir("aug", "retargeted")
    clips = {c.source: c for c in episodes_to_robot_clips(src)}
    small = clips["synthetic:PickUp:seed0@x0.6-cylinder"]
    assert small.objects[0].geometry == Primitive("box", (0.20, 0.15, 0.15)).scaled(0.6).as_cylinder()
    assert small.provenance["augment"]["mass"] == pytest.approx(small.objects[0].mass)
    ds = LeRobotDataset("lessmimic/aug-retargeted", root=src)
    assert ds.num_episodes == len(clips)
    k = list(clips).index(small.source)
    start = int(ds.meta.episodes["dataset_from_index"][k])
    np.testing.assert_allclose(ds[start]["object.pose"].numpy(), small.objects[0].pose[0], atol=1e-6)


def test_the_physicalize_report_counts_the_yield_per_task_and_variant(root):
    report = json.loads((logs_dir(stage_dir("aug", "physicalized")) / "report.json").read_text())
    assert set(report["yield"]) == {f"PickUp {v}" for v in VARIANTS} | {"SitStand x0.6", "SitStand x1"}
    for key, row in report["yield"].items():
        runs = [c for c in report["clips"] if f"{c['task']} {c['variant']}" == key]
        assert row["clips"] == len(runs) == 1 and row["valid"] == sum(c["valid"] for c in runs)
        assert row["valid"] + sum(row["rejected"].values()) + sum(row["failed"].values()) == row["clips"]
        assert row["payload_capped"] == sum(c["valid"] and "payload_capped" in c for c in runs)
    kept = episodes_to_physicalized_clips(stage_dir("aug", "physicalized"))
    assert {c.robot.source.split("@")[-1] for c in kept} <= {
        "synthetic:PickUp:seed0",
        "synthetic:SitStand:seed0",
        *VARIANTS,
    }


def test_a_subset_holds_out_the_other_variants(root):
    summary = subset_corpus("aug", "aug-box", ["x0.6", "x1"])
    assert summary["held_out"] == ["x0.6-cylinder", "x1-cylinder"] and read_subset("aug-box") == summary
    kept = load_episodes("aug-box", valid_only=False)
    assert {episode_variant(e) for e in kept} <= {"x0.6", "x1"} and kept
    assert summary["episodes"]["features"] == len(kept)
    folder = root
    expect_input_error(lambda: subset_corpus("aug", "other", list(VARIANTS)), folder, file="aug", field="variants")
    expect_input_error(
        lambda: subset_corpus("aug", "other", ["x2"]), folder, file=stage_dir("aug", "retargeted"), field="variants"
    )
    expect_input_error(lambda: subset_corpus("aug", "aug-box", ["x1"]), folder, file=root / "aug-box", field="out")


def test_the_two_protocols_draw_their_own_episodes(root):
    episodes = load_episodes("aug")
    scaled, at = cell_episodes(episodes, "PickUp", 0.6, "scaled", "box")
    assert at == 0.6 and {episode_variant(e) for e in scaled} == {"x1"}
    matched, at = cell_episodes(episodes, "PickUp", 0.6, "matched", "box")
    assert at == 1.0 and all(episode_variant(e) == "x0.6" for e in matched)
    cylinders, _ = cell_episodes(episodes, "PickUp", 1.0, "matched", "cylinder")
    assert all(episode_variant(e) == "x1-cylinder" for e in cylinders)
    cfg = EvalConfig(seeds=(0,), episodes=1, tasks=("PickUp",), scales=(0.4, 0.6, 1.0), protocol="matched")
    result = evaluate(TeacherActor(), episodes, cfg, "scale-matched teacher", corpus="aug")
    ran = {f"PickUp@{s:g}" for s in (0.6, 1.0) if cell_episodes(episodes, "PickUp", s, "matched", "box")[0]}
    assert set(result["cells"]) == ran
    missing = {m["cell"]: m["reason"] for m in result["missing"]}
    assert missing["PickUp@0.4"] == "the corpus has no valid episode of the variant"  # never made: no yield
    assert "| no clip |" in markdown([result])
    assert "Protocol `matched`" in scale_line(scale_note("aug", cfg))


def test_a_cell_the_success_rule_rules_out_is_not_run(root):
    """SitStand's rule wants the root at 0.3-0.6 m while seated: raised 0.6 m, every reference sits above it."""
    episodes = [e for e in load_episodes("aug") if e.task == "SitStand"]
    assert rule_window("SitStand", episodes, Rules(seat_height_m=(0.0, 0.1))).startswith("the references sit")
    assert rule_window("SitStand", episodes, Rules()) is None and rule_window("PickUp", episodes, Rules()) is None
