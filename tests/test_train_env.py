"""The interaction environment, the teacher service and the evaluation harness on the default corpus (real
retarget -> physicalize -> features datasets, real MuJoCo)."""

import json

import numpy as np
import pytest
import torch

from features.stage import run_stage as features_stage
from lessmimic.chain import retarget as retarget_stage
from physicalize.stage import run_stage as physicalize_stage
from pipeline.dataset.read import episode_ranges, read_columns
from pipeline.errors import InputError
from pipeline.stage.paths import stage_dir
from pipeline.terms.layout import DEMO_LINKS, TASK_CONDITION
from train.actors import TeacherActor
from train.bc import BCConfig, WindowTensors, train_bc
from train.envs.cpu.env import EnvConfig, InteractionEnv
from train.episodes import load_episodes, scaled_objects
from train.evaluation.table2 import EvalConfig, evaluate, interval95, markdown, scale_line, scale_note
from train.policy import PolicyConfig, dataset_layout
from train.teacher import Teacher
from train.vae import VAEConfig


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    """The default chain (4 synthetic clips) in a temporary datasets root; its episodes."""
    root = tmp_path_factory.mktemp("datasets")
    mp = pytest.MonkeyPatch()
    mp.setenv("LESSMIMIC_DATASETS", str(root))
    retarget_stage(None, "train")
    physicalize_stage("train")
    features_stage("train")
    yield load_episodes("train")
    mp.undo()


def _replayed(env: InteractionEnv, corpus, every: int):
    """``(episode index, frame, observation)`` of ``env`` put into every ``every``-th recorded state of each episode."""
    for e, episode in enumerate(corpus):
        env.reset([(episode, 1.0)])
        slot, sim = env.slots[0], episode.simulated
        for t in range(0, sim.frames, every):
            slot.t, slot.last_action = t, (sim.action[t - 1] if t else np.zeros(29))
            slot.set_state(sim.robot.qpos[t], sim.qvel[t], np.concatenate([o.pose[t] for o in sim.robot.objects]))
            yield e, t, env.observe()


def test_replayed_states_give_the_features_dataset_columns(corpus):
    """The environment's observation of each recorded state is the features dataset's row, to the last bit."""
    cols = read_columns(
        stage_dir("train", "features"), ["observation.proprio", "observation.root_command", "observation.df"]
    )
    starts, _, _ = episode_ranges(stage_dir("train", "features"))
    env = InteractionEnv()
    for e, t, obs in _replayed(env, corpus, every=7):
        for key, column in (
            ("proprio", "observation.proprio"),
            ("root_command", "observation.root_command"),
            ("df", "observation.df"),
        ):
            np.testing.assert_allclose(getattr(obs, key)[0], cols[column][starts[e] + t], rtol=0, atol=1e-6)
            assert np.array_equal(getattr(obs, key)[0].astype(np.float32), cols[column][starts[e] + t])


def test_the_demo_contracts_observation_is_the_features_datasets_too(corpus):
    """Under the released demo's contract the environment observes ``observation.df_demo`` and the dataset's root
    command with z zeroed and the task condition appended: what BC's windows of that contract hold."""
    features = stage_dir("train", "features")
    cols = read_columns(features, ["observation.root_command", "observation.df_demo"])
    starts, _, tasks = episode_ranges(features)
    layout = dataset_layout(features, 5, "lessmimic_demo")
    assert layout.links == DEMO_LINKS and layout.df_dim == 28 and layout.root_command_dim == 14
    windows = WindowTensors.from_dataset(features, 5, layout=layout)
    for e, t, obs in _replayed(InteractionEnv(EnvConfig.for_policy(layout)), corpus, every=29):
        row = starts[e] + t
        assert np.array_equal(obs.df[0].astype(np.float32), cols["observation.df_demo"][row])
        want = np.concatenate([cols["observation.root_command"][row], [TASK_CONDITION[tasks[e]]] * 2])
        want[[2, 11]] = 0.0
        np.testing.assert_allclose(obs.root_command[0], want, rtol=0, atol=1e-6)
        np.testing.assert_allclose(windows.root_command[row].numpy(), want, rtol=0, atol=1e-6)


def test_the_episodes_actuator_profile_drives_the_environment_and_binds_the_policy(corpus):
    """An episode physicalized under the demo's gains is simulated and taught with them (its actions are targets
    for those gains); a policy trained for another profile refuses it (the DAgger test below)."""
    from dataclasses import replace

    from pipeline.robot import actuator_profile

    assert {e.profile for e in corpus} == {"mjlab"}
    env = InteractionEnv()
    for name in ("mjlab", "lessmimic_demo"):
        env.reset([(replace(corpus[0], profile=name), 1.0)])
        np.testing.assert_allclose(env.slots[0].scene.model.actuator_gainprm[:29, 0], actuator_profile(name).kp)
        teacher = TeacherActor()
        teacher.reset(env)
        np.testing.assert_allclose(teacher.teachers[0].controller.profile.kp, actuator_profile(name).kp)


def test_stepping_is_deterministic_and_threads_change_nothing(corpus):
    rng = np.random.default_rng(0)
    actions = [corpus[0].simulated.action[t] + rng.normal(0, 0.05, 29) for t in range(30)]
    finals = []
    for threads in (1, 2):
        from train.envs.cpu.env import EnvConfig

        env = InteractionEnv(EnvConfig(threads=threads))
        env.reset([(corpus[0], 1.0), (corpus[2], 1.0)])
        for a in actions:
            obs, _ = env.step(np.stack([a, a]))
        finals.append((obs.proprio.copy(), obs.df.copy(), [s.data.qpos.copy() for s in env.slots]))
        env.close()
    assert np.array_equal(finals[0][0], finals[1][0]) and np.array_equal(finals[0][1], finals[1][1])
    assert all(np.array_equal(a, b) for a, b in zip(finals[0][2], finals[1][2]))


def test_the_teacher_answers_at_an_off_reference_state(corpus):
    """Shoved 10 cm sideways and 0.3 m/s, the teacher still returns finite targets within the joint ranges' reach,
    and tracking from the recorded first state completes the PickUp."""
    pickup = next(e for e in corpus if e.task == "PickUp")
    env = InteractionEnv()
    env.reset([(pickup, 1.0)])
    slot = env.slots[0]
    teacher = Teacher(pickup, slot.scene.model)
    q, v = slot.data.qpos.copy(), slot.data.qvel.copy()
    q[1] += 0.10
    v[1] += 0.3
    action = teacher.act_state(q, v, 40)
    assert action.shape == (29,) and np.isfinite(action).all()
    assert not np.allclose(action, teacher.act_state(slot.data.qpos.copy(), slot.data.qvel.copy(), 40))
    while not slot.done:
        env.step(teacher.act(slot.data, slot.t)[None])
    assert slot.meter.success and not slot.fell


def test_scaled_objects_rest_on_the_floor_and_the_command_does_not_change(corpus):
    box = next(e for e in corpus if e.task == "PickUp").simulated.robot.objects
    small, large = scaled_objects(box, 0.4), scaled_objects(box, 1.6)
    half = box[0].geometry.half_extents[2]
    assert np.isclose(small[0].pose[0, 2], 0.4 * half) and np.isclose(large[0].pose[0, 2], 1.6 * half)
    env = InteractionEnv()
    env.reset([(corpus[0], 0.4), (corpus[0], 1.6)])
    obs = env.observe()
    assert np.array_equal(obs.root_command[0], obs.root_command[1]) and not np.allclose(obs.df[0], obs.df[1])
    with pytest.raises(InputError, match="scale: .* outside the evaluated range 0.4-1.6"):
        env.reset_one(0, corpus[0], 2.0)


def test_the_root_deviation_is_horizontal_to_the_reference_at_the_same_frame(corpus):
    """R_acc's distance (StepFacts.root_dev_m): 0 at the recorded state even with the root 0.2 m lower (a sit on a
    scaled chair), the horizontal offset otherwise; the meter divides by the episode's full length."""
    episode = corpus[0]
    env = InteractionEnv()
    env.reset([(episode, 1.0)])
    slot, sim = env.slots[0], episode.simulated
    assert slot.meter.root_total == sim.frames - 1
    t = sim.frames // 2
    q = sim.robot.qpos[t].copy()
    q[2] -= 0.2
    slot.set_state(q, sim.qvel[t])
    assert slot.facts(t).root_dev_m == 0.0
    q[:2] += (0.3, 0.4)
    slot.set_state(q, sim.qvel[t])
    assert slot.facts(t).root_dev_m == pytest.approx(0.5)


class _NoSitting(TeacherActor):
    """The teacher standing in for a vision policy: it does not attempt SitStand."""

    excluded_tasks = ("SitStand",)
    excluded_reason = "the seat is behind the robot: not in the egocentric camera's view"


def test_an_actor_that_excludes_a_task_gets_n_a_cells_and_the_reason(corpus):
    cfg = EvalConfig(seeds=(0,), episodes=1, tasks=("PickUp", "SitStand"), scales=(1.0,))
    result = evaluate(_NoSitting(), corpus, cfg, "vision")
    assert set(result["cells"]) == {"PickUp@1"}
    assert result["not_applicable"] == [{"task": "SitStand", "reason": _NoSitting.excluded_reason}]
    success, accuracy = (line.split(" | ") for line in markdown([result]).splitlines()[2:4])
    assert success[1:4] == ["-", "-", "100.0 (21-100)"] and success[6:9] == ["n/a"] * 3 and success[9] == "-"
    assert accuracy[0] == "| vision: R_acc" and accuracy[6:9] == ["n/a"] * 3
    assert float(accuracy[3]) == pytest.approx(100 * result["cells"]["PickUp@1"]["root_accuracy"], abs=0.05)
    _NoSitting.excluded_tasks = ("Dance",)
    try:
        with pytest.raises(ValueError, match="unknown task"):
            evaluate(_NoSitting(), corpus, cfg)
    finally:
        _NoSitting.excluded_tasks = ("SitStand",)


def test_results_written_before_r_acc_still_read():
    cell = {"task": "PickUp", "scale": 1.0, "mean": 0.5, "std": 0.1, "ci95": [0.3, 0.7]}
    lines = markdown([{"label": "old", "cells": {"PickUp@1": cell}}]).splitlines()
    assert len(lines) == 3 and lines[2].split(" | ")[3] == "50.0 (30-70)"


def test_a_cells_interval_is_wilsons_for_successes_and_students_t_for_contact_rates():
    low, high = interval95([1.0] * 30 + [0.0] * 18, binary=True)  # 30 of 48
    assert np.isclose(low, 0.4836, atol=1e-4) and np.isclose(high, 0.7478, atol=1e-4)
    low, high = interval95([0.0] * 10, binary=True)  # none of 10: not the empty [0, 0] of the normal approximation
    assert low == 0.0 and 0.25 < high < 0.31
    rates = [0.9, 0.8, 0.85, 0.95, 0.7, 0.88]
    low, high = interval95(rates, binary=False)
    half = 2.5706 * np.std(rates, ddof=1) / np.sqrt(6)  # t(0.975, 5)
    assert np.isclose(low, np.mean(rates) - half, atol=1e-4) and np.isclose(high, np.mean(rates) + half, atol=1e-4)
    assert interval95([1.0, 1.0], binary=False) == (1.0, 1.0)


def test_the_evaluation_harness_scores_the_teacher(corpus, tmp_path):
    result = evaluate(TeacherActor(), corpus, EvalConfig(seeds=(0,), episodes=1, tasks=("PickUp", "Push")), "teacher")
    cells = result["cells"]
    assert set(cells) == {
        "PickUp@0.4",
        "PickUp@0.6",
        "PickUp@1",
        "PickUp@1.4",
        "PickUp@1.6",
        "Push@0.6",
        "Push@1",
        "Push@1.4",
    }
    assert cells["PickUp@1"]["mean"] == 1.0 and cells["Push@1"]["mean"] > 0.9
    assert cells["PickUp@1"]["root_accuracy"] > 0.9 and cells["Push@1"]["root_accuracy"] > 0.9  # tracks the root
    assert all(c["root_accuracy"] < 1.0 for c in cells.values() if c["falls"])  # a fall cuts the steps on the track
    table = markdown([result]).splitlines()
    row = table[2].split(" | ")
    assert row[0] == "| teacher" and row[3] == "100.0 (21-100)" and row[6:9] == ["-", "-", "-"]  # PickUp 1.0 (1 of 1)
    assert table[3].startswith("| teacher: R_acc | ") and "not_applicable" not in result
    assert cells["PickUp@1"]["episodes"] == 1 and cells["PickUp@1"]["ci95"][1] == 1.0
    note = scale_note("train", EvalConfig(seeds=(0,), episodes=1), tmp_path / "p.pt")  # no report.json beside it
    assert note["policy"]["training_scale"] == "unknown"
    assert "1 episodes per cell and seed" in scale_line(note) and "trained on unknown" in scale_line(note)
    (tmp_path / "report.json").write_text('{"scale": {"bc_steps": 7, "dagger_iterations": 3}}')
    assert scale_note("train", EvalConfig(), tmp_path / "p.pt")["policy"]["training_scale"]["dagger_iterations"] == 3
    scale = dict(corpus="train-syn", corpus_episodes=4, corpus_frames=9, bc_steps=7, bc_samples=70, dagger_iterations=3)
    scale |= dict(dagger_episodes_per_iteration=2, dagger_windows=5, device="cpu")
    (tmp_path / "q").mkdir()
    (tmp_path / "q" / "report.json").write_text(json.dumps({"scale": scale}))
    line = scale_line(scale_note("train", EvalConfig(), tmp_path / "q" / "policy.pt"))
    assert "trained on 4 corpus episodes of `train-syn` (9 frames)" in line  # the training corpus, e.g. -Syn's
    (tmp_path / "dagger_log.jsonl").write_text('{"iteration": 0, "aggregated_windows": 11}\n' * 3)
    early = scale_note("train", EvalConfig(), tmp_path / "policy_dagger0.pt")["policy"]["training_scale"]
    assert early["dagger_iterations"] == 1 and early["dagger_windows"] == 11 and early["bc_steps"] == 7
    bc = scale_note("train", EvalConfig(), tmp_path / "policy_bc.pt")["policy"]["training_scale"]
    assert bc["dagger_iterations"] == 0 and bc["dagger_windows"] == 0


def test_one_dagger_iteration_logs_labels_and_resumes(corpus, tmp_path):
    """BC on the corpus, then DAgger: the student's visited states labelled by the teacher, the refit logged; a rerun
    resumes after the finished iteration and a second iteration adds one row, with the optimiser's moments carried
    over: the resumed run's weights are those of two iterations in one go."""
    import json
    from dataclasses import replace

    from train.actors import PolicyActor
    from train.bc import BCConfig, WindowTensors, train_bc
    from train.dagger import DAggerConfig, dagger
    from train.policy import PolicyConfig, load_policy
    from train.vae import VAEConfig

    features = stage_dir("train", "features")
    train_bc(features, tmp_path, BCConfig(steps=30, log_every=10), PolicyConfig(), VAEConfig(), vae_steps=30)
    (tmp_path / "policy_bc.pt").write_bytes((tmp_path / "policy.pt").read_bytes())
    data = WindowTensors.from_dataset(features, 5)
    cfg = DAggerConfig(iterations=1, episodes=2, probe=1, envs=2, fit_steps=20)
    dagger(load_policy(tmp_path / "policy.pt"), data, corpus, tmp_path, cfg, BCConfig(log_every=10))
    (row,) = [json.loads(line) for line in (tmp_path / "dagger_log.jsonl").open()]
    student = row["student"]
    assert row["beta"] == 0.5 and row["windows"] > 20 and student["windows"] > 0
    assert row["aggregated_windows"] == row["windows"] + student["windows"]
    assert row["action_rmse"] > 0 and 0 <= row["success"] <= 1 and row["fit"]["step"] == 20 and row["seconds"] > 0
    assert set(row["task_weights"].values()) == {0.25} and sum(n for _, n in row["tasks"].values()) == 2
    dagger(load_policy(tmp_path / "policy.pt"), data, corpus, tmp_path, cfg, BCConfig(log_every=10))  # resumed: done
    assert len((tmp_path / "dagger_log.jsonl").read_text().splitlines()) == 1
    dagger(load_policy(tmp_path / "policy.pt"), data, corpus, tmp_path, replace(cfg, iterations=2), BCConfig())
    rows = [json.loads(line) for line in (tmp_path / "dagger_log.jsonl").open()]
    assert [r["iteration"] for r in rows] == [0, 1] and rows[1]["beta"] == pytest.approx(0.5 * cfg.beta_decay)
    new = rows[1]["windows"] + rows[1]["student"]["windows"]
    env = InteractionEnv()
    env.reset([(replace(corpus[0], profile="lessmimic_demo"), 1.0)])
    with pytest.raises(InputError, match="actuator_profile: episode physicalized under 'lessmimic_demo', the policy"):
        PolicyActor(load_policy(tmp_path / "policy.pt")).reset(env)
    assert rows[1]["aggregated_windows"] == rows[0]["aggregated_windows"] + new
    assert torch.load(tmp_path / "dagger_optimizer.pt", weights_only=True)["iteration"] == 1
    straight = tmp_path / "straight"
    straight.mkdir()
    dagger(load_policy(tmp_path / "policy_bc.pt"), data, corpus, straight, replace(cfg, iterations=2), BCConfig())
    resumed, whole = (torch.load(d / "policy_dagger1.pt", weights_only=True)["backbone"] for d in (tmp_path, straight))
    assert all(torch.equal(resumed[k], whole[k]) for k in whole)


def test_dagger_draws_more_of_the_tasks_the_student_fails(corpus):
    """The next iteration's task weights follow the last one's failures (mixture and probe together), never below
    the floor, until ``uniform_from``, then are equal (and the refits longer); the draw keeps to them and cycles through
    a task's episodes."""
    from train.dagger import DAggerConfig, draw_episodes, iteration_weights, refit_steps, task_weights

    tasks = ["Carry", "PickUp", "Push", "SitStand"]
    row = {"tasks": {"PickUp": [3, 4], "SitStand": [0, 3]}, "student": {"tasks": {"SitStand": [0, 1], "Push": [2, 2]}}}
    w = task_weights(tasks, row, floor=0.25)  # Carry not rolled out: 1; PickUp 1 - 3/4; Push floor; SitStand 1
    np.testing.assert_allclose(w, np.array([1.0, 0.25, 0.25, 1.0]) / 2.5)
    np.testing.assert_allclose(task_weights(tasks, None, 0.25), 0.25)
    config = DAggerConfig(uniform_from=3)
    np.testing.assert_array_equal(iteration_weights(tasks, row, 2, config), w)
    np.testing.assert_allclose(iteration_weights(tasks, row, 3, config), 0.25)
    assert [refit_steps(i, DAggerConfig(uniform_from=3, fit_steps=100)) for i in (2, 3, 9)] == [100, 200, 200]
    only_sit = draw_episodes(corpus, 3, np.array([0.0, 0.0, 0.0, 1.0]), tasks, np.random.default_rng(0))
    assert [e.task for e in only_sit] == ["SitStand"] * 3 and only_sit[0] is only_sit[1]  # one SitStand episode


def test_train_and_eval_commands_refuse_bad_input_with_one_line(corpus, tmp_path, capsys):
    from lessmimic.cli import main

    assert main(["train-bc", "--name", "missing", "--run", str(tmp_path / "r")]) == 2
    assert main(["eval", "--name", "train"]) == 2  # nothing to evaluate
    (tmp_path / "bad.pt").write_bytes(b"not a checkpoint")
    assert main(["eval", "--name", "train", "--policy", str(tmp_path / "bad.pt")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and "no features dataset here" in err[0] and "nothing to evaluate" in err[1]
    assert "bad.pt: format: not a torch checkpoint" in err[2]
    with pytest.raises(InputError, match="task: unknown task; known: PickUp"):
        load_episodes("train", ("Dance",))


def test_a_run_folder_takes_more_dagger_iterations_and_refuses_other_settings(tmp_path):
    from train.config import TrainConfig
    from train.run import _claim

    run = tmp_path / "run"
    _claim(run, TrainConfig(dagger_iterations=2), overwrite=False)
    _claim(run, TrainConfig(dagger_iterations=4), overwrite=False)  # a longer DAgger run continues this one
    assert '"dagger_iterations": 4' in (run / "config.json").read_text()
    for other in (TrainConfig(dagger_iterations=3), TrainConfig(dagger_iterations=4, bc_steps=1)):
        with pytest.raises(InputError, match="config: a run with other settings .* pass --overwrite"):
            _claim(run, other, overwrite=False)
    _claim(run, TrainConfig(bc_steps=1), overwrite=True)
    assert '"bc_steps": 1' in (run / "config.json").read_text()
    old = json.loads((run / "config.json").read_text())
    del old["select_episodes"]  # a run folder written before the setting existed: its default
    (run / "config.json").write_text(json.dumps(old))
    _claim(run, TrainConfig(bc_steps=1), overwrite=False)
    _claim(run, TrainConfig(bc_steps=1, select_episodes=4), overwrite=False)  # another choice, the same training


def _smoke(seed: int):
    from train.config import TrainConfig

    return TrainConfig(name="train", vae_steps=20, bc_steps=20, batch=32, dagger_iterations=2, dagger_episodes=2,
                       dagger_probe=1, dagger_fit_steps=10, envs=2, select_episodes=1, seed=seed)  # fmt: skip


@pytest.mark.slow
def test_the_same_seed_twice_gives_the_same_policy_and_the_same_choice(corpus, tmp_path):
    """Determinism at smoke scale (VAE, BC, two DAgger iterations, the checkpoint choice): one torch thread and one
    environment thread, the defaults, give identical weights for the same seed; another seed does not."""
    from train.run import train

    torch.set_num_threads(1)
    reports = [train(_smoke(seed), tmp_path / name) for seed, name in ((0, "a"), (0, "b"), (1, "c"))]
    a, b, c = (torch.load(tmp_path / n / "policy.pt", weights_only=True) for n in "abc")
    for key in ("backbone", "vae"):
        flat = [(k, v) for k, v in _tensors(a[key])]
        assert all(torch.equal(v, w) for (_, v), (_, w) in zip(flat, _tensors(b[key]))), key
    assert not all(torch.equal(v, w) for (_, v), (_, w) in zip(_tensors(a["backbone"]), _tensors(c["backbone"])))
    assert a["chosen_from"] == b["chosen_from"] == reports[0]["scale"]["chosen_checkpoint"]
    assert (tmp_path / "a" / "validation.jsonl").read_text() == (tmp_path / "b" / "validation.jsonl").read_text()


def _tensors(d, prefix=""):
    """(name, tensor) pairs of a nested checkpoint dict, in order."""
    for k, v in d.items():
        if isinstance(v, dict):
            yield from _tensors(v, f"{prefix}{k}.")
        elif isinstance(v, torch.Tensor):
            yield prefix + k, v


def test_the_policy_is_the_average_of_iterations_chosen_by_its_worst_task_relative_to_the_teacher(corpus, tmp_path):
    """Candidates average consecutive iterations' weights. Validation rows (here written beforehand, as a resumed
    choice finds them): the last candidate is best on average but lost SitStand, the middle one is best on its
    worst task; Carry, which the teacher rarely completes, does not decide alone. The choice is logged and policy.pt
    holds the mean of the chosen candidate's iterations."""
    from dataclasses import asdict

    from train.evaluation.select import SelectConfig, candidates, choose, validation_episodes
    from train.policy import load_policy, save_policy

    cfg = SelectConfig(episodes=1, average=2)
    features = stage_dir("train", "features")
    train_bc(features, tmp_path, BCConfig(steps=5, log_every=5), PolicyConfig(), VAEConfig(), vae_steps=5)
    base = load_policy(tmp_path / "policy.pt").backbone.state_dict()
    for i in range(3):  # iteration i: the BC weights + i
        policy = load_policy(tmp_path / "policy.pt")
        with torch.no_grad():
            for w in policy.backbone.parameters():
                w.add_(float(i))
        save_policy(policy, tmp_path / f"policy_dagger{i}.pt")
    labels = [label for label, _ in candidates(tmp_path, cfg.average)]
    assert labels == ["policy_dagger0.pt", "mean of policy_dagger0.pt..policy_dagger1.pt",
                      "mean of policy_dagger1.pt..policy_dagger2.pt"]  # fmt: skip
    teacher = {"PickUp": 1.0, "SitStand": 1.0, "Push": 1.0, "Carry": 0.25}
    scores = [
        {"PickUp": 0.2, "SitStand": 0.2, "Push": 0.5, "Carry": 0.0},
        {"PickUp": 0.6, "SitStand": 0.5, "Push": 0.7, "Carry": 0.125},  # worst: SitStand 0.5
        {"PickUp": 0.9, "SitStand": 0.1, "Push": 0.9, "Carry": 0.25},  # best mean, worst: SitStand 0.1
    ]
    rows = [{"checkpoint": "teacher", "scores": teacher, "config": asdict(cfg)}]
    for label, s in zip(labels, scores):
        ratio = [v / max(teacher[t], 0.05) for t, v in s.items()]
        rows.append({"checkpoint": label, "scores": s, "worst_ratio": min(ratio),
                     "mean_ratio": float(np.mean(ratio)), "config": asdict(cfg)})  # fmt: skip
    (tmp_path / "validation.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    choice = choose(tmp_path, corpus[:1], corpus[1:], cfg)
    assert choice["chosen"] == labels[1] and choice["last"] == labels[2]
    saved = torch.load(tmp_path / "policy.pt", weights_only=True)
    assert saved["chosen_from"] == labels[1]
    for k, w in saved["backbone"].items():  # the mean of iterations 0 and 1: the BC weights + 0.5
        torch.testing.assert_close(w, base[k] + 0.5 if w.is_floating_point() else base[k], rtol=0, atol=1e-5)
    assert json.loads((tmp_path / "selection.json").read_text())["chosen_scores"] == scores[1]
    last = choose(tmp_path, corpus[:1], corpus[1:], SelectConfig(episodes=0, average=2))  # the default: no rollouts
    assert last["chosen"] == labels[2] and "chosen_scores" not in last
    assert torch.load(tmp_path / "policy.pt", weights_only=True)["chosen_from"] == labels[2]
    episodes, origin = validation_episodes(corpus[:1], corpus[1:])
    assert origin[corpus[0].task].startswith("1 held out") and len(episodes) == len(corpus)
    assert sorted(e.task for e in episodes) == sorted(e.task for e in corpus)
