"""Post-training speed on a GPU with the mjlab backend (``--backend mjlab``, :mod:`train.envs.mjlab.env`), side by side
with its own baselines, per number of worlds:

* **physics**: MuJoCo Warp alone on the same worlds (4 substeps per control step, no terms, no restarts);
* **environment**: :class:`train.envs.mjlab.env.MjlabPostTrainEnv` steps (physics, observation, reward terms, restarts),
  the policy's targets held at the current joint angles;
* **post-training**: PPO env steps per second (rollout and update, :func:`train.aip.iteration`) for plain PPO without
  randomisations, with the six randomisations (those the backend runs), and with the AIP and AMP priors too; the
  issue's bar: randomisations and priors together within 20% of the plain run.

Wall time with the GPU synchronised; the first build of each size includes MuJoCo Warp's kernel compile (reported).
Run: ``make bench-train-mjlab [NAME=corpus] POLICY=runs/<RUN>/policy.pt`` on a machine with a CUDA GPU.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import torch

from train.aip import PostTrainConfig, build, iteration
from train.envs.config import PostEnvConfig
from train.envs.mjlab.env import MjlabPostTrainEnv, runnable_episodes
from train.episodes import load_episodes
from train.policy import load_policy


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def environment_rows(name: str, policy: str, envs: int, device: str, steps: int = 100, profile: bool = False) -> None:
    t0 = time.perf_counter()
    env = MjlabPostTrainEnv(runnable_episodes(load_episodes(name)), load_policy(policy).layout.history,
                            PostEnvConfig(envs=envs), device)  # fmt: skip
    built = time.perf_counter() - t0
    hold = env.get_observations()["critic"][:, :29].clone()
    sim = env.env.sim
    for _ in range(10):
        env.step(hold)
    _sync(device)
    t0 = time.perf_counter()
    for _ in range(steps):
        for _ in range(env.env.cfg.decimation):
            sim.step()
    _sync(device)
    physics = steps * envs / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for _ in range(steps):
        env.step(env.get_observations()["critic"][:, :29])
    _sync(device)
    stepped = steps * envs / (time.perf_counter() - t0)
    print(f"{envs:6d} worlds: built in {built:5.1f} s; physics {physics:9.0f} env steps/s; environment "
          f"{stepped:9.0f} env steps/s ({physics / stepped - 1:+.0%} over physics)", flush=True)  # fmt: skip
    if profile:  # where an environment step's time goes (Python's view: a GPU kernel's time lands on its sync)
        import cProfile
        import pstats

        with cProfile.Profile() as p:
            for _ in range(20):
                env.step(env.get_observations()["critic"][:, :29])
            _sync(device)
        pstats.Stats(p).sort_stats("tottime").print_stats(20)
    env.close()


def post_training_rows(name: str, policy: str, envs: int, device: str, iterations: int = 5) -> None:
    cfg = PostTrainConfig(steps_per_env=24, env=PostEnvConfig(envs=envs), backend="mjlab")
    cases = [
        ("plain PPO, plain env", replace(cfg, ablation="-Rand"), ()),
        ("+ randomisations", cfg, ()),
        ("+ AIP + AMP priors", cfg, ("aip", "amp")),
    ]
    base = None
    for label, c, priors in cases:
        env, alg = build(name, policy, c, device, priors)
        obs, _ = iteration(env, alg, env.get_observations(), c.steps_per_env)  # warm-up
        _sync(device)
        t0 = time.perf_counter()
        for _ in range(iterations):
            obs, figures = iteration(env, alg, obs, c.steps_per_env)
        _sync(device)
        rate = iterations * c.steps_per_env * envs / (time.perf_counter() - t0)
        base = base or rate
        print(f"  {envs} worlds, {label:22s}{rate:9.0f} env steps/s  overhead {base / rate - 1:+6.1%}  "
              f"(falls per iteration {figures['falls']})", flush=True)  # fmt: skip
        env.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--name", default="corpus")
    ap.add_argument("--policy", required=True, help="a BC + DAgger policy.pt (runs/<RUN>/policy.pt)")
    ap.add_argument("--envs", default="1024,4096")
    ap.add_argument("--ppo-envs", type=int, default=4096)
    ap.add_argument("--ppo-iterations", type=int, default=5)
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--profile", action="store_true", help="also profile 20 environment steps at the last size")
    args = ap.parse_args()
    print(f"device: {torch.cuda.get_device_name() if args.device.startswith('cuda') else 'cpu'}", flush=True)
    sizes = [int(v) for v in args.envs.split(",")]
    for n in sizes:
        environment_rows(args.name, args.policy, n, args.device, profile=args.profile and n == sizes[-1])
    print(f"post-training, {args.ppo_envs} worlds x 24 steps per PPO iteration, {args.ppo_iterations} iterations "
          "after one warm-up:")  # fmt: skip
    post_training_rows(args.name, args.policy, args.ppo_envs, args.device, args.ppo_iterations)


if __name__ == "__main__":
    main()
