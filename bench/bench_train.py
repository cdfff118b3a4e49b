"""Training-side speed on the CPU, side by side with its baseline:

* **environment**: control steps per CPU-second of :class:`train.envs.cpu.env.InteractionEnv` (4 physics substeps, then
  the
  online observation: proprio, root command, DF terms of 14 links) against raw ``mj_step`` of the same scenes at
  4 substeps (no observation); the issue's bar: within 25% of raw. Per task scene and for ``--envs`` environments
  stepped in 1 and 2 threads (wall time then, both cores);
* **teacher**: the QP teacher's cost per query (:meth:`train.teacher.Teacher.act`), tracking its episode;
* **BC**: behaviour-cloning samples per second (:func:`train.bc.fit`) for the Transformer and the MLP policy;
* **post-training**: PPO env steps per CPU-second (rollout and update together, :func:`train.aip.iteration`) for
  plain PPO on the plain environment, with the six randomisations, and with both style priors (AIP + AMP) too;
  the issue's bar: the randomisations and the discriminators together within 20% of the plain run. The policy is a
  BC policy trained for a few steps on the corpus (the cost does not depend on its quality, only through falls).

Run: ``make bench-train [NAME=corpus]`` (default: the default chain's datasets; built in a temporary folder when
missing). Actions replay each episode's recorded actions, so the robots move as in the data.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import torch

torch.set_num_threads(1)

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from pipeline.stage.paths import stage_dir  # noqa: E402
from train.envs.cpu.env import EnvConfig, InteractionEnv  # noqa: E402
from train.episodes import load_episodes  # noqa: E402
from train.teacher import Teacher  # noqa: E402

STEPS = 200


def _raw(env: InteractionEnv, actions: np.ndarray) -> float:
    """Control steps per CPU-second of plain ``mj_step`` x 4 on the environments' own scenes."""
    datas = [mujoco.MjData(s.scene.model) for s in env.slots]
    for d, s in zip(datas, env.slots):
        d.qpos[:], d.qvel[:] = s.data.qpos, s.data.qvel
    c0 = time.process_time()
    for t in range(STEPS):
        for d, s in zip(datas, env.slots):
            d.ctrl[:] = actions[t]
            for _ in range(4):
                mujoco.mj_step(s.scene.model, d)
    return STEPS * len(datas) / (time.process_time() - c0)


def _env(episodes, actions: np.ndarray, threads: int) -> tuple[float, float]:
    """(control steps per CPU-second, per wall-second) of the environment with its observation."""
    env = InteractionEnv(EnvConfig(threads=threads))
    env.reset([(e, 1.0) for e in episodes])
    c0, w0 = time.process_time(), time.perf_counter()
    for t in range(STEPS):
        env.step(np.repeat(actions[t][None], env.num_envs, 0))
    n = STEPS * env.num_envs
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    env.close()
    return n / cpu, n / wall


def environment_table(episodes, envs: int) -> None:
    print(f"environment, {envs} envs x {STEPS} control steps (4 substeps each), replaying recorded actions:")
    print(f"  {'task':10s}{'raw mj_step':>14s}{'env':>10s}{'env/raw':>9s}{'2 threads (wall)':>18s}")
    for e in episodes:
        batch = [e] * envs
        actions = e.simulated.action[:STEPS]
        actions = (
            np.concatenate([actions, np.repeat(actions[-1:], STEPS - len(actions), 0)])
            if len(actions) < STEPS
            else actions
        )
        env = InteractionEnv()
        env.reset([(x, 1.0) for x in batch])
        raw = _raw(env, actions)
        cpu, _ = _env(batch, actions, 1)
        _, wall2 = _env(batch, actions, 2)
        print(f"  {e.task:10s}{raw:14.0f}{cpu:10.0f}{cpu / raw:9.2f}{wall2:18.0f}   steps/s")


def teacher_table(episodes) -> None:
    print("teacher query (QP solve + mj_forward), tracking its own episode from its first state:")
    for e in episodes:
        env = InteractionEnv()
        env.reset([(e, 1.0)])
        slot = env.slots[0]
        teacher = Teacher(e, slot.scene.model)
        times = []
        while not slot.done:
            c0 = time.process_time()
            a = teacher.act(slot.data, slot.t)
            times.append(time.process_time() - c0)
            env.step(a[None])
        p90 = 1000 * np.percentile(times, 90)
        print(f"  {e.task:10s}{1000 * np.mean(times):8.2f} ms/query (p90 {p90:.2f}), {len(times)} queries")


def bc_table(name: str) -> None:
    from train.bc import bc_speed

    for backbone in ("transformer", "mlp"):
        print(f"BC {backbone}: {bc_speed(stage_dir(name, 'features'), backbone):.0f} samples/s (1 thread)")


def post_training_table(name: str, envs: int, iterations: int = 4, repeats: int = 9) -> None:
    """PPO env steps per CPU-second of the three cases, ``repeats`` rounds of ``iterations`` iterations each, the
    cases interleaved round by round (a load that comes and goes hits all three alike); the median round per case.
    One round of 4 iterations per case gave overheads from -12% to +48% on the same code on a loaded laptop: the
    rounds differ in how many episodes fall and restart (a restart rebuilds the scene)."""
    from dataclasses import replace

    from train.aip import PostTrainConfig, build, iteration
    from train.bc import BCConfig, train_bc
    from train.envs.config import PostEnvConfig
    from train.policy import PolicyConfig
    from train.vae import VAEConfig

    run = tempfile.mkdtemp()
    train_bc(stage_dir(name, "features"), run, BCConfig(steps=200), PolicyConfig(), VAEConfig(), vae_steps=200)
    cfg = PostTrainConfig(steps_per_env=24, env=PostEnvConfig(envs=envs))
    cases = [
        ("plain PPO, plain env", replace(cfg, ablation="-Rand"), ()),
        ("+ six randomisations", cfg, ()),
        ("+ AIP + AMP priors", cfg, ("aip", "amp")),
    ]
    built = []
    for _, c, priors in cases:
        env, alg = build(name, os.path.join(run, "policy.pt"), c, priors=priors)
        obs, _ = iteration(env, alg, env.get_observations(), c.steps_per_env)  # warm-up
        built.append([env, alg, obs])
    rates: list[list[float]] = [[] for _ in cases]
    for _ in range(repeats):
        for k, (env, alg, obs) in enumerate(built):
            c0 = time.process_time()
            for _ in range(iterations):
                obs, _ = iteration(env, alg, obs, cfg.steps_per_env)
            built[k][2] = obs
            rates[k].append(iterations * cfg.steps_per_env * envs / (time.process_time() - c0))
    print(f"post-training, {envs} envs x 24 steps per PPO iteration; median of {repeats} interleaved rounds of "
          f"{iterations} iterations (min-max):")  # fmt: skip
    base = float(np.median(rates[0]))
    for (label, _, _), r, (env, _, _) in zip(cases, rates, built):
        rate = float(np.median(r))
        spread = f"({min(r):.0f}-{max(r):.0f})"
        print(f"  {label:24s}{rate:8.0f} env steps/CPU-s {spread:11s} overhead {base / rate - 1:+6.1%}")
        env.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--name", default="default")
    ap.add_argument("--envs", type=int, default=8)
    args = ap.parse_args()
    if not (stage_dir(args.name, "features") / "meta" / "info.json").is_file():
        from features.stage import run_stage as features
        from lessmimic.chain import retarget
        from physicalize.stage import run_stage as physicalize

        os.environ["LESSMIMIC_DATASETS"] = tempfile.mkdtemp()
        retarget(None, args.name)
        physicalize(args.name)
        features(args.name)
    episodes = load_episodes(args.name)
    one_per_task = list({e.task: e for e in episodes}.values())
    environment_table(one_per_task, args.envs)
    teacher_table(one_per_task)
    bc_table(args.name)
    post_training_table(args.name, args.envs)


if __name__ == "__main__":
    main()
