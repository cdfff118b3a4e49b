"""The learned residual teacher: its vectorised environment, smoke-scale PPO training (real MuJoCo,
real rsl-rl), its checkpoint in the closed loop, and the stage with ``--teacher base+residual:<ckpt>``."""

import json
from dataclasses import replace

import numpy as np
import pytest
import torch
from standing import standing_qpos

from lessmimic.cli import main
from physicalize.clip import parse_teacher, physicalize_clip
from physicalize.problem import tracking_problem
from physicalize.residual import ResidualConfig, ResidualEnv, ResidualPolicy, observe, train_residual
from physicalize.rollout import initial_state, replay, simulate
from physicalize.wbc import WholeBodyController
from pipeline.clip import RobotClip
from pipeline.errors import InputError

SMOKE = ResidualConfig(num_steps_per_env=8, hidden_dims=(32, 32), num_mini_batches=2, num_learning_epochs=2)


def _standing_clip(frames: int = 60) -> RobotClip:
    q = standing_qpos(frames)
    return RobotClip(q, 50, "hand-made:stand", task="stand")


@pytest.fixture(scope="module")
def problem():
    return tracking_problem(_standing_clip())


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return train_residual(_standing_clip(), 2, 4, 0, tmp_path_factory.mktemp("residual") / "stand.pt", config=SMOKE)


def test_env_shapes_and_rsl_rl_contract(problem):
    scene, ref, objects, _ = problem
    env = ResidualEnv(scene, ref, objects, 3, 0, SMOKE)
    obs = env.get_observations()
    assert (
        tuple(obs.batch_size) == (3,)
        and obs["policy"].shape == (3, env.obs_dim)
        and obs["policy"].dtype == torch.float32
    )
    assert (
        env.obs_dim == 94 + (1 + len(SMOKE.lookahead)) * 38 + 10 + 3
    )  # state, look-ahead, object slot, phase + stance
    o, r, done, extras = env.step(torch.zeros(3, 29))
    assert (
        o["policy"].shape == (3, env.obs_dim)
        and r.shape == (3,)
        and done.shape == (3,)
        and extras["time_outs"].shape == (3,)
    )
    assert r.dtype == torch.float32 and done.dtype == torch.bool
    assert torch.all(r > SMOKE.w_alive) and not done.any()  # standing on the reference: every kernel near 1, no fall
    assert torch.equal(env.episode_length_buf, torch.ones(3, dtype=torch.long))


def test_env_is_deterministic_for_a_seed_and_the_residual_moves_the_targets(problem):
    scene, ref, objects, _ = problem
    runs = []
    for seed in (0, 0, 1):
        env = ResidualEnv(scene, ref, objects, 2, seed, SMOKE)
        gen = torch.Generator().manual_seed(5)
        first = env.get_observations()["policy"].clone()
        for _ in range(5):
            o, r, _, _ = env.step(torch.randn(2, 29, generator=gen))
        runs.append((env.start.copy(), first, o["policy"].clone(), r.clone(), env.datas[0].qpos.copy()))
    (
        (s0, f0, o0, r0, q0),
        (s1, f1, o1, r1, q1),
        (s2, *_),
    ) = runs
    assert (
        np.array_equal(s0, s1)
        and torch.equal(f0, f1)
        and torch.equal(o0, o1)
        and torch.equal(r0, r1)
        and np.array_equal(q0, q1)
    )
    assert not np.array_equal(s0, s2)  # another seed, other start frames
    # the applied targets are the controller's plus scale * clip(a): a unit residual on one joint moves it
    env = ResidualEnv(scene, ref, objects, 1, 0, SMOKE)
    base, a = env.base[0].copy(), torch.zeros(1, 29)
    a[0, 3] = 5.0  # clipped to 1
    env.step(a)
    assert np.allclose(env.datas[0].ctrl - base, np.eye(29)[3] * SMOKE.scale)


def test_smoke_training_writes_a_checkpoint_that_runs_in_simulate(checkpoint, problem):
    ck = torch.load(checkpoint, weights_only=True)
    assert ck["training"]["env_steps"] == 2 * 4 * SMOKE.num_steps_per_env and len(ck["training"]["history"]) == 2
    policy = ResidualPolicy.load(checkpoint)
    assert policy.cfg == SMOKE and policy.obs_dim == ck["obs_dim"]
    scene, ref, objects, _ = problem
    q0, v0 = initial_state(scene, ref, objects)
    base = simulate(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0)
    roll = simulate(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0, residual=policy)
    assert roll.fell_at is None and roll.frames == ref.frames
    diff = np.abs(roll.action - base.action).max()
    assert 0 < diff  # the residual acts ...
    qs, _ = replay(scene.model, q0, v0, roll.action)  # ... and the recorded actions are the applied ones
    assert np.abs(qs[:-1] - roll.qpos).max() <= 1e-6 and np.abs(qs[-1] - roll.final_qpos).max() <= 1e-6
    # deterministic: the mean action, the same for the same state
    import mujoco

    d = mujoco.MjData(scene.model)
    d.qpos[:], d.qvel[:] = q0, v0
    mujoco.mj_forward(scene.model, d)
    u = WholeBodyController(scene.model, scene.profile).solve(d, ref.target(0)).action
    a1, a2 = policy(d, ref, 0, u), policy(d, ref, 0, u)
    assert np.array_equal(a1, a2) and np.abs(a1 - u).max() <= SMOKE.scale + 1e-12
    assert observe(d, ref, 0, u, SMOKE).shape == (policy.obs_dim,)


def test_training_is_deterministic_for_a_seed(checkpoint, tmp_path):
    again = torch.load(
        train_residual(_standing_clip(), 2, 4, 0, tmp_path / "again.pt", config=SMOKE), weights_only=True
    )
    first = torch.load(checkpoint, weights_only=True)
    assert first["actor_state_dict"].keys() == again["actor_state_dict"].keys()
    assert all(torch.equal(v, again["actor_state_dict"][k]) for k, v in first["actor_state_dict"].items())
    assert first["training"]["history"] == again["training"]["history"]


def test_the_checkpoint_and_the_config_round_trip(tmp_path):
    cfg = replace(SMOKE, lookahead=(1, 3), scale=0.02)
    assert ResidualConfig.from_dict({k: list(v) if isinstance(v, tuple) else v for k, v in cfg.__dict__.items()}) == cfg
    bad = tmp_path / "bad.pt"
    torch.save({"format": "something else"}, bad)
    with pytest.raises(ValueError, match="not a lessmimic-residual-v1 checkpoint"):
        ResidualPolicy.load(bad)


def test_teacher_parsing(tmp_path, checkpoint):
    assert parse_teacher("base").checkpoint is None
    spec = parse_teacher(f"base+residual:{checkpoint}")
    assert spec.checkpoint == checkpoint and len(spec.digest) == 64
    missing = tmp_path / "nope.pt"
    with pytest.raises(InputError, match="residual checkpoint not found") as err:
        parse_teacher(f"base+residual:{missing}")
    assert str(missing) in str(err.value) and "\n" not in str(err.value)
    for bad in ("residual", "base+residual:", "base+mpc"):
        with pytest.raises(InputError, match="unknown teacher"):
            parse_teacher(bad)


def test_stage_with_the_residual_teacher(tmp_path, monkeypatch, checkpoint, capsys):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from pipeline.dataset import write_dataset
    from pipeline.dataset.clips import robot_clips_to_episodes
    from pipeline.stage.paths import stage_dir

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    features, episodes = robot_clips_to_episodes([_standing_clip()])
    write_dataset(stage_dir("stand", "retargeted"), "lessmimic/stand-retargeted", 50, features, episodes)
    teacher = f"base+residual:{checkpoint}"
    assert main(["physicalize", "--name", "stand", "--teacher", str(tmp_path / "missing.pt")]) == 2
    assert main(["physicalize", "--name", "stand", "--teacher", f"base+residual:{tmp_path / 'missing.pt'}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "unknown teacher" in err[0] and "missing.pt" in err[1] and "not found" in err[1]
    assert main(["physicalize", "--name", "stand", "--teacher", teacher, "--profile", "lessmimic_demo"]) == 2
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    assert main(["physicalize", "--name", "stand", "--teacher", f"base+residual:{junk}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 2
        and "trained for actuator profile 'mjlab'" in err[0]
        and "unreadable residual checkpoint" in err[1]
    )
    assert not stage_dir("stand", "physicalized").exists()
    assert main(["physicalize", "--name", "stand", "--teacher", teacher]) == 0
    root = stage_dir("stand", "physicalized")
    report = json.loads((root / "report.json").read_text())
    clip = report["clips"][0]
    assert report["teacher"] == teacher and report["teacher_sha256"] == parse_teacher(teacher).digest
    assert clip["valid"] and clip["replay_err_max_m"] <= 1e-6
    assert LeRobotDataset("lessmimic/stand-physicalized", root=root).num_frames == 60
    assert teacher in (root / "README.md").read_text()
    # the same clip with the base teacher gives other actions (the cache key tells teachers apart)
    _, base_roll, _, _ = physicalize_clip(_standing_clip())
    _, res_roll, _, _ = physicalize_clip(_standing_clip(), teacher=teacher)
    assert not np.array_equal(base_roll.action, res_roll.action)


def test_train_on_a_retargeted_episode_from_the_cli(tmp_path, monkeypatch):
    from pipeline.dataset import write_dataset
    from pipeline.dataset.clips import robot_clips_to_episodes
    from pipeline.stage.paths import stage_dir

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    features, episodes = robot_clips_to_episodes([_standing_clip(30)])
    write_dataset(stage_dir("stand", "retargeted"), "lessmimic/stand-retargeted", 50, features, episodes)
    out = tmp_path / "r.pt"
    assert (
        main(
            [
                "physicalize-residual",
                "--name",
                "stand",
                "--episode",
                "3",
                "--iterations",
                "1",
                "--envs",
                "2",
                "--out",
                str(out),
            ]
        )
        == 2
    )
    assert (
        main(
            [
                "physicalize-residual",
                "--name",
                "stand",
                "--episode",
                "0",
                "--iterations",
                "1",
                "--envs",
                "2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    assert ResidualPolicy.load(out).training["source"] == "hand-made:stand"
