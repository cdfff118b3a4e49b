"""The vision student (train.vision.student, train.vision.actor) and its distillation (train.vision.distill): it
cannot see the MoCap DF, its head starts as the teacher's, its checkpoint round-trips, one distillation iteration
runs, resumes and repeats for a seed, and bad inputs are one-line errors that leave nothing behind. One module: the
corpus fixture is built once."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch
from mocap_paths import expect_input_error

from lessmimic.cli import build_parser, main
from lessmimic.train_commands import _cmd_distill
from pipeline.errors import InputError
from train.envs.cpu.env import InteractionEnv
from train.evaluation.table2 import EvalConfig, scale_line, scale_note
from train.export.metadata import VISION_INPUTS
from train.export.onnx_policy import export_onnx
from train.export.parity import parity, recorded_windows
from train.export.runtime import OnnxPolicy, read_metadata
from train.policy import load_policy, save_policy
from train.vision.actor import VisionActor
from train.vision.camera import DepthCamera
from train.vision.distill import DistillConfig, distill, read_log
from train.vision.noise import DepthNoise
from train.vision.student import (
    DepthEncoder,
    EncoderConfig,
    is_vision_checkpoint,
    load_vision_policy,
    save_vision_policy,
    vision_student,
)


@pytest.fixture(scope="module")
def student_in_env(bc_corpus):
    """``(teacher, student, actor, env)``: a fresh student of the tiny BC policy, its actor reset in two environments
    of the corpus's PickUp and Push episodes, clean depth."""
    episodes, checkpoint = bc_corpus
    teacher = load_policy(checkpoint)
    torch.manual_seed(0)
    student = vision_student(teacher, DepthCamera(), source={"path": str(checkpoint)})
    actor = VisionActor(student, DepthNoise.off())
    env = InteractionEnv(actor.env_config())
    env.reset([(e, 1.0) for e in episodes if e.task in ("PickUp", "Push")])
    actor.reset(env)
    return teacher, student, actor, env


def _windows(actor) -> dict[str, torch.Tensor]:
    return {k: torch.as_tensor(v, dtype=torch.float32) for k, v in actor.history.terms.items()}


def test_the_student_cannot_see_the_mocap_df(student_in_env):
    """Called with the full observation the environment gives the MoCap policy (DF included), plus depth: perturbing
    the DF leaves the action unchanged to the bit, perturbing the depth changes it."""
    _, student, actor, _ = student_in_env
    terms = _windows(actor)
    assert set(terms) >= {"proprio", "root_command", "df", "depth"} and terms["df"].abs().sum() > 0
    base = student.act_observation(terms)
    df = {**terms, "df": terms["df"] + torch.randn_like(terms["df"])}
    assert torch.equal(student.act_observation(df), base)
    depth = {**terms, "depth": (terms["depth"] * 0.5).clamp(min=0.1)}
    assert (student.act_observation(depth) - base).abs().max() > 1e-4


def test_the_head_starts_as_the_teachers(student_in_env):
    """The student's head is a copy of pi_full's: fed pi_full's own latents it acts as pi_full."""
    teacher, student, actor, _ = student_in_env
    for a, b in zip(teacher.backbone.state_dict().values(), student.control.backbone.state_dict().values()):
        assert torch.equal(a, b)
    t = _windows(actor)
    with torch.no_grad():
        z = teacher.latents(t["df"])
        head = student.control.backbone(student.control.tokens_from_latents(t["proprio"], t["root_command"], z))
    want = teacher(t["proprio"], t["root_command"], t["df"])
    torch.testing.assert_close(head, want, rtol=0, atol=1e-6)
    assert not any(p.requires_grad for p in student.control.vae.parameters())
    names = {id(p) for p in student.trainable_parameters()}
    assert all(id(p) not in names for p in student.control.vae.parameters())
    assert all(id(p) in names for p in student.encoder.parameters())


def test_the_actor_reads_depth_of_every_environment(student_in_env):
    _, student, actor, env = student_in_env
    depth = actor.history.terms["depth"]
    cam = student.camera
    assert depth.shape == (env.num_envs, student.config.history, cam.height, cam.width)
    assert np.all((depth >= cam.near) & (depth <= cam.far)) and np.ptp(depth[0, -1]) > 0.1  # floor and object


def test_the_checkpoint_round_trips(student_in_env, tmp_path):
    teacher, student, actor, _ = student_in_env
    path = save_vision_policy(student, tmp_path / "vision.pt")
    again = load_vision_policy(path)
    terms = _windows(actor)
    assert torch.equal(again.act_observation(terms), student.act_observation(terms))
    assert again.camera == student.camera and again.teacher == student.teacher
    assert is_vision_checkpoint(path) and not is_vision_checkpoint(tmp_path / "missing.pt")
    mocap = save_policy(teacher, tmp_path / "mocap.pt")
    assert not is_vision_checkpoint(mocap)
    expect_input_error(lambda: load_vision_policy(mocap), tmp_path, file=mocap, field="format")
    expect_input_error(lambda: load_policy(path), tmp_path, file=path, field="format")


def test_bad_frames_and_configs_are_refused():
    enc = DepthEncoder(DepthCamera(), 8)
    assert enc(torch.zeros(2, 3, 40, 64)).shape == (2, 3, 8)
    with pytest.raises(ValueError, match="expected"):
        enc(torch.zeros(2, 3, 64, 40))
    with pytest.raises(ValueError, match="no pixel"):
        DepthEncoder(DepthCamera(width=8, height=8), 8, EncoderConfig(convs=((4, 16, 16),)))


# --- distillation (train.vision.distill) ---------------------------------------------------------------------------

TINY = DistillConfig(iterations=2, episodes=2, probe=1, envs=2, fit_steps=4, batch=16)


def _figures(row: dict) -> dict:
    """A log row without its timings."""
    out = {k: v for k, v in row.items() if k != "seconds"}
    out["fit"] = {k: v for k, v in row["fit"].items() if k not in ("seconds", "windows_per_s")}
    return out


def test_one_distillation_resumes_and_repeats_for_a_seed(bc_corpus, tmp_path):
    """Two iterations straight, and one then a resumed second, give the same log and the same student; the windows
    are stored once per iteration, depth as uint16 millimetres; the report names the scale and the teacher."""
    episodes, checkpoint = bc_corpus
    teacher, source = load_policy(checkpoint), {"path": str(checkpoint), "sha256": "x", "corpus": "train"}
    straight = distill(teacher, source, episodes, tmp_path / "a", TINY)
    distill(teacher, source, episodes, tmp_path / "b", replace(TINY, iterations=1))
    resumed = distill(teacher, source, episodes, tmp_path / "b", TINY)
    rows_a, rows_b = read_log(tmp_path / "a"), read_log(tmp_path / "b")
    assert len(rows_a) == 2 and [_figures(r) for r in rows_a] == [_figures(r) for r in rows_b]
    for a, b in zip(straight.state_dict().values(), resumed.state_dict().values()):
        assert torch.equal(a, b)
    row = rows_a[0]
    assert row["beta"] == 1.0 and rows_a[1]["beta"] == 0.5 and set(row["tasks"]) <= {"PickUp", "Push", "Carry"}
    assert {"action_rmse", "episode_length", "falls", "success", "root_accuracy"} <= set(row["student"])
    assert 0.0 <= row["root_accuracy"] <= 1.0 and row["fit"]["action_loss"] > 0
    data = torch.load(tmp_path / "a" / "distill_data0.pt", weights_only=True)
    assert data["depth"].dtype == torch.uint16 and len(data["action"]) == row["windows"] + row["student"]["windows"]
    assert int(data["depth"].to(torch.int32).max()) <= 3000 and data["rows"].shape[1] == teacher.config.history
    report = json.loads((tmp_path / "a" / "report.json").read_text())
    assert report["teacher"] == source and report["scale"]["distill_iterations"] == 2
    assert report["scale"]["env_steps"] == sum(r["env_steps"] + r["student"]["env_steps"] for r in rows_a)
    assert is_vision_checkpoint(tmp_path / "a" / "policy.pt")
    first = scale_note("train", EvalConfig(), tmp_path / "a" / "policy_distill0.pt")["policy"]["training_scale"]
    assert first["distill_iterations"] == 1 and first["windows"] == rows_a[0]["aggregated_windows"]
    assert first["env_steps"] == row["env_steps"] + row["student"]["env_steps"]
    assert "2 DAgger iterations" in scale_line(scale_note("train", EvalConfig(), tmp_path / "a" / "policy.pt"))


def test_the_latent_alignment_switch_reports_its_cosine(bc_corpus, tmp_path):
    episodes, checkpoint = bc_corpus
    distill(load_policy(checkpoint), {"path": "t"}, episodes, tmp_path, replace(TINY, iterations=1, align=1.0))
    fit = read_log(tmp_path)[0]["fit"]
    assert {"latent_loss", "latent_cosine"} <= set(fit) and -1.0 <= fit["latent_cosine"] <= 1.0


def test_bad_distillations_are_one_line_errors_that_leave_nothing(bc_corpus, tmp_path):
    episodes, checkpoint = bc_corpus
    teacher = load_policy(checkpoint)
    run = tmp_path / "run"
    call = lambda cfg: distill(teacher, {"path": "t"}, episodes, run, cfg)  # noqa: E731
    expect_input_error(lambda: call(replace(TINY, depth_memory_mb=0.01)), tmp_path, file=run, field="depth_memory_mb")
    run.mkdir()
    (run / "distill.json").write_text(json.dumps({"config": {"seed": 5}, "teacher": {"path": "t"}}))
    expect_input_error(lambda: call(TINY), tmp_path, file=run, field="distill.json")
    other = tmp_path / "other.pt"
    ckpt = torch.load(checkpoint, weights_only=True)
    ckpt["layout"]["actuator_profile"] = "lessmimic_demo"
    torch.save(ckpt, other)
    argv = ["distill", "--name", "train", "--teacher", str(other), "--run", str(tmp_path / "x"), "--iterations", "1"]
    with pytest.raises(InputError, match="actuator_profile"):
        _cmd_distill(build_parser().parse_args(argv))
    assert not (tmp_path / "x").exists()


# --- export and evaluation of a vision student -----------------------------------------------------------------------


def test_the_student_exports_to_onnx_with_its_camera(student_in_env, bc_corpus, tmp_path):
    """One ONNX graph from depth windows to joint targets, within 1e-5 rad of torch on windows recorded in the
    environment; its metadata carries the camera's intrinsics and extrinsics and the teacher; onnxruntime's file
    acts in the vision actor."""
    episodes, _ = bc_corpus
    _, student, _, _ = student_in_env
    checkpoint = save_vision_policy(student, tmp_path / "vision.pt")
    report = export_onnx(checkpoint)
    assert report.path == tmp_path / "vision.onnx" and report.check_max_abs <= 1e-5
    windows = recorded_windows(student, [e for e in episodes if e.task == "PickUp"], steps=30)
    assert windows[2].shape[1:] == (student.config.history, 40, 64)
    result = parity(student, report.path, windows)
    assert result["windows"] >= 30 and result["max_abs"] <= 1e-5, result
    meta = read_metadata(report.path)
    fx, fy = student.camera.focal
    assert meta["camera"]["intrinsics"]["fx"] == fx and meta["camera"]["intrinsics"]["fy"] == fy
    assert meta["camera"]["extrinsics"]["body"] == "torso_link" and meta["teacher"] == student.teacher
    assert set(meta["observation"]["inputs"]) == set(VISION_INPUTS)
    onnx_policy = OnnxPolicy(report.path)
    assert onnx_policy.camera == student.camera
    terms = {k: torch.from_numpy(w[:4]) for k, w in zip(VISION_INPUTS, windows)}
    torch.testing.assert_close(onnx_policy.act_observation(terms), student.act_observation(terms), rtol=0, atol=1e-5)


def test_eval_scores_a_vision_student_beside_its_teacher(student_in_env, bc_corpus, tmp_path):
    """``lessmimic eval --policy vision.pt``: the student's row shows SitStand not applicable, its MoCap teacher is
    scored in the same run, every row has R_acc."""
    _, checkpoint = bc_corpus
    _, student, _, _ = student_in_env
    path = save_vision_policy(student, tmp_path / "run" / "policy.pt")
    argv = ["eval", "--name", "train", "--policy", str(path), "--seeds", "0", "--episodes", "1", "--envs", "2"]
    assert main([*argv, "--scales", "1.0", "--out", str(tmp_path / "eval")]) == 0
    results = json.loads((tmp_path / "eval" / "eval.json").read_text())["results"]
    vision, teacher = results
    assert vision["label"] == "vision (run)" and teacher["label"].startswith("MoCap teacher")
    assert vision["not_applicable"][0]["task"] == "SitStand" and "SitStand@1" not in vision["cells"]
    assert "SitStand@1" in teacher["cells"] and "PickUp@0.4" not in teacher["cells"]
    assert all(0.0 <= c["root_accuracy"] <= 1.0 for r in results for c in r["cells"].values())
    table = (tmp_path / "eval" / "eval.md").read_text()
    assert "| vision (run): R_acc |" in table and "n/a" in table
