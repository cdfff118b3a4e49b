"""Long-horizon chains (train.evaluation.chains) on the default corpus: real datasets, a BC policy trained briefly,
real MuJoCo."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from train.actors import PolicyActor
from train.envs.cpu.env import InteractionEnv
from train.evaluation.chains import ENDINGS, ChainConfig, evaluate_chains, markdown, relocated, run_chains
from train.evaluation.chains import _yaw as heading_yaw
from train.policy import load_policy


@pytest.fixture(scope="module")
def corpus(bc_corpus):
    return bc_corpus


def _yaw(wxyz) -> float:
    return float(Rotation.from_quat(np.asarray(wxyz)[[1, 2, 3, 0]]).as_euler("ZYX")[0])


def test_a_relocated_episode_starts_where_asked_and_keeps_its_object_where_it_was_relative_to_the_robot(corpus):
    episodes, _ = corpus
    e = next(x for x in episodes if x.task == "PickUp")
    r = relocated(e, 1.5, -2.0, 1.0)
    q, q0 = r.simulated.robot.qpos, e.simulated.robot.qpos
    np.testing.assert_allclose(q[0, :2], [1.5, -2.0], atol=1e-9)
    assert heading_yaw(q[0]) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(np.diff([_yaw(x) for x in q[:, 3:7]]), np.diff([_yaw(x) for x in q0[:, 3:7]]), atol=1e-9)
    np.testing.assert_array_equal(q[:, 2], q0[:, 2])
    np.testing.assert_array_equal(q[:, 7:], q0[:, 7:])  # joint angles unchanged
    for new, old in ((r.simulated.robot.objects[0].pose, e.simulated.robot.objects[0].pose),):
        d_new = np.linalg.norm(new[:, :2] - q[:, :2], axis=1)
        d_old = np.linalg.norm(old[:, :2] - q0[:, :2], axis=1)
        np.testing.assert_allclose(d_new, d_old, atol=1e-9)  # a rigid motion of the whole scene
    speed = np.linalg.norm(r.simulated.qvel[:, :3], axis=1)
    np.testing.assert_allclose(speed, np.linalg.norm(e.simulated.qvel[:, :3], axis=1), atol=1e-9)
    gap = np.linalg.norm(r.reference.qpos[:, :2] - q[:, :2], axis=1)  # the reference moved with it
    np.testing.assert_allclose(gap, np.linalg.norm(e.reference.qpos[:, :2] - q0[:, :2], axis=1), atol=1e-9)


def test_r_acc_measures_against_the_relocated_reference(corpus):
    """In a chain the commanded trajectory is the relocated episode's: at its recorded state the root is on it, 10 m
    from where the original episode's root was."""
    episodes, _ = corpus
    e = next(x for x in episodes if x.task == "PickUp")
    r = relocated(
        e, e.simulated.robot.qpos[0, 0] + 10.0, e.simulated.robot.qpos[0, 1], heading_yaw(e.simulated.robot.qpos[0])
    )
    env = InteractionEnv()
    env.reset([(r, 1.0)])
    slot, t = env.slots[0], 5
    slot.set_state(r.simulated.robot.qpos[t], r.simulated.qvel[t])
    assert slot.facts(t).root_dev_m == pytest.approx(0.0, abs=1e-9)
    assert np.linalg.norm(slot.data.qpos[:2] - e.simulated.robot.qpos[t, :2]) > 9.0


def test_a_chain_goes_on_from_the_robots_state_into_the_next_task(corpus):
    """Switching to the next task keeps the robot's state and places the next episode where the robot stands."""
    from train.evaluation.chains import _switch

    episodes, policy = corpus
    pick, sit = (next(x for x in episodes if x.task == t) for t in ("PickUp", "SitStand"))
    env = InteractionEnv()
    env.reset([(pick, 1.0)])
    actor = PolicyActor(load_policy(policy))
    actor.reset(env)
    for _ in range(5):
        actor.observe(env.step(actor.act(env))[0])
    q = env.slots[0].data.qpos[:36].copy()
    _switch(env, actor, 0, sit)
    slot = env.slots[0]
    assert slot.episode.task == "SitStand" and slot.t == 0
    np.testing.assert_array_equal(slot.data.qpos[:36], q)
    np.testing.assert_allclose(slot.episode.simulated.robot.qpos[0, :2], q[:2], atol=1e-9)
    np.testing.assert_allclose(actor.history.terms["proprio"][0, -1], env.observe().proprio[0])


def test_chain_results_per_length_say_how_each_chain_ended(corpus):
    episodes, policy = corpus
    cfg = ChainConfig(lengths=(1, 2), seeds=(0, 1), chains=2, envs=2)
    result = evaluate_chains(PolicyActor(load_policy(policy)), episodes, cfg, "smoke")
    for n in ("1", "2"):
        c = result["lengths"][n]
        assert sum(c["ended"].values()) == 4 and set(c["ended"]) == set(ENDINGS)
        assert 0 <= c["mean"] <= 1 and 0 <= c["mean_tasks_completed"] <= int(n) and len(c["per_seed"]) == 2
        assert 0 <= c["root_accuracy"] <= 1
    assert result["tasks"] == sorted({e.task for e in episodes}) and "not_applicable" not in result
    assert "| smoke |" in markdown(result) and "N = 2" in markdown(result) and ", R_acc " in markdown(result)
    outcome = run_chains(PolicyActor(load_policy(policy)), [[episodes[0]]], cfg)
    assert outcome[0]["tasks_completed"] == int(outcome[0]["success"])
    assert outcome[0]["ended"] != "strayed" or outcome[0]["root_accuracy"] < 1.0


class _NoSitting(PolicyActor):
    excluded_tasks = ("SitStand",)
    excluded_reason = "the seat is behind the robot"


def test_a_vision_policys_chains_leave_out_the_tasks_it_excludes(corpus, tmp_path):
    from train.evaluation.chains import write

    episodes, policy = corpus
    cfg = ChainConfig(lengths=(2,), seeds=(0,), chains=2, envs=2)
    result = evaluate_chains(_NoSitting(load_policy(policy)), episodes, cfg, "vision")
    assert result["tasks"] == sorted({e.task for e in episodes} - {"SitStand"})
    assert result["not_applicable"] == [{"task": "SitStand", "reason": "the seat is behind the robot"}]
    write(result, tmp_path, {})
    head = (tmp_path / "chains.md").read_text().splitlines()[0]
    assert f"tasks drawn from {', '.join(result['tasks'])}." in head and "SitStand not applicable" in head
    old = {"label": "old", "lengths": {"5": {"mean": 0.5, "std": 0.0, "ci95": [0.2, 0.8], "mean_tasks_completed": 3.0}}}
    assert markdown(old).splitlines()[2] == "| old | 50.0 (20-80), 3.0 tasks |"  # written before R_acc
    with pytest.raises(ValueError, match="no episode of a task the actor attempts"):
        evaluate_chains(_NoSitting(load_policy(policy)), [e for e in episodes if e.task == "SitStand"], cfg)


def test_the_eval_command_adds_the_chains_table(corpus, tmp_path):
    import json

    from lessmimic.cli import main

    _, policy = corpus
    args = ["eval", "--name", "train", "--policy", str(policy), "--seeds", "0", "--episodes", "1", "--envs", "4"]
    assert main([*args, "--chains", "1,2", "--chains-per-seed", "2", "--out", str(tmp_path)]) == 0
    saved = json.loads((tmp_path / "chains.json").read_text())
    assert list(saved["result"]["lengths"]) == ["1", "2"] and saved["scale"]["policy"]["checkpoint"] == str(policy)
    assert "Chains: 2 per length and seed, seeds 0" in (tmp_path / "chains.md").read_text()


def test_the_qp_teachers_chains_track_each_tasks_own_reference(corpus, tmp_path):
    """``eval --teacher --chains``: the QP teacher's chains (its ceiling) in ``qp_teacher/``; at each switch the
    teacher is rebound to the next task's relocated reference, so it completes the first task of every chain."""
    import json

    from lessmimic.cli import main

    args = ["eval", "--name", "train", "--teacher", "--seeds", "0", "--episodes", "1", "--envs", "2", "--scales", "1.0"]
    assert main([*args, "--chains", "2", "--chains-per-seed", "2", "--out", str(tmp_path)]) == 0
    saved = json.loads((tmp_path / "qp_teacher" / "chains.json").read_text())["result"]
    assert saved["label"] == "QP teacher, each task's reference"
    assert saved["lengths"]["2"]["mean_tasks_completed"] >= 1.0
