"""Depth rendering on mjlab (issue 42: "mjlab depth at 4096 worlds, env steps per second with depth"): the project's
mjlab post-training environment (:class:`train.envs.mjlab.env.MjlabPostTrainEnv`, as ``make bench-train-mjlab``
builds it) built twice over ``--envs`` worlds, without and with the depth camera of
:class:`train.vision.camera.DepthCamera` (64 x 40 by default) as mjlab's camera sensor
(:func:`train.envs.mjlab.camera.depth_sensor_cfg`: MuJoCo Warp's ray-cast renderer, every world at once, run by
mjlab's ``sim.sense()`` in each ``env.step``).

* **the sensor**: one of the scene's ``sensors`` (``MjlabPostTrainEnv(..., sensors=...)``); nothing else changes;
* **the steps**: the policy's targets held fixed at the first observation's joint angles (no policy call is timed);
  with depth, each step also reads every world's image (:func:`train.envs.mjlab.camera.read_depth`);
* **the figures**: env steps per second without and with depth (``--repeats`` rounds of ``--steps`` steps after
  ``--warmup``, median and range; wall time with the device synchronised), their ratio, depth images per second (one
  camera per world: the env steps per second with depth), and the build seconds (the first build includes MuJoCo
  Warp's kernel compile, the second the renderer's);
* **the image check**: world 0's image after the first step (the episode's first state, the G1 standing) is finite,
  within ``[near, far]``, at least a quarter of its pixels nearer than ``far``, and its bottom row (the floor in front
  of the feet, 77 degrees below the horizon) nearer than ``far``; the same counted over every world.

The table goes to stdout, the figures to ``--out`` (default ``runs/bench/vision_mjlab.json``).
Run: ``make bench-vision-mjlab [POLICY=runs/<RUN>/policy.pt] [CORPUS=corpus]`` on a machine with a CUDA GPU
(``--device cpu --envs 2 --steps 3`` is a smoke test of the same code: MuJoCo Warp's CPU backend, minutes of kernel
compiling the first time).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import torch

from pipeline.errors import InputError
from pipeline.stage.atomic import write_json_atomic
from pipeline.stage.paths import stage_dir
from train.envs.config import PostEnvConfig
from train.envs.mjlab.camera import depth_sensor_cfg, read_depth
from train.envs.mjlab.env import MjlabPostTrainEnv, check_device, runnable_episodes
from train.episodes import load_episodes
from train.policy import load_policy
from train.vision.camera import DepthCamera

SENSOR = "depth_camera"


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        import warp as wp

        wp.synchronize()
        torch.cuda.synchronize()


def check_image(depth: torch.Tensor, camera: DepthCamera) -> dict:
    """World 0's image of ``depth`` (N, H, W) and the count of worlds whose image passes the same test (module
    docstring)."""
    finite = torch.isfinite(depth).flatten(1).all(1)
    inside = ((depth >= camera.near) & (depth <= camera.far)).flatten(1).all(1)
    near = (depth < camera.far).flatten(1).float().mean(1)
    bottom = (depth[:, -1] < camera.far).all(1)
    ok = finite & inside & (near >= 0.25) & bottom
    d0 = depth[0]
    return {
        "world0": {
            "min": float(d0.min()),
            "median": float(d0.median()),
            "max": float(d0.max()),
            "nearer_than_far": float(near[0]),
            "bottom_row_mean": float(d0[-1].mean()),
            "top_row_mean": float(d0[0].mean()),
            "rows_mean": [round(float(v), 3) for v in d0.mean(1)],
        },
        "sane": bool(ok[0]),
        "sane_worlds": int(ok.sum()),
        "worlds": int(depth.shape[0]),
    }


def measure(episodes, history: int, args: argparse.Namespace, camera: DepthCamera | None) -> dict:
    """Build the environment (with ``camera``'s sensor unless None), step it with fixed targets; its figures."""
    t0 = time.perf_counter()
    sensors = (depth_sensor_cfg(camera, SENSOR),) if camera else ()
    env = MjlabPostTrainEnv(episodes, history, PostEnvConfig(envs=args.envs), args.device, sensors=sensors)
    built = time.perf_counter() - t0
    sensor = env.env.scene[SENSOR] if camera else None
    hold = env.get_observations()["critic"][:, :29].clone()  # the first state's joint angles, held

    def step() -> None:
        env.step(hold)
        if sensor is not None:
            read_depth(sensor, camera)

    res: dict = {"build_s": built}
    env.step(hold)
    if sensor is not None:
        res["image"] = check_image(read_depth(sensor, camera), camera)
    for _ in range(max(args.warmup - 1, 0)):
        step()
    rates = []
    for _ in range(args.repeats):
        _sync(args.device)
        t0 = time.perf_counter()
        for _ in range(args.steps):
            step()
        _sync(args.device)
        rates.append(args.steps * args.envs / (time.perf_counter() - t0))
    res["env_steps_per_s"] = {"median": statistics.median(rates), "min": min(rates), "max": max(rates), "all": rates}
    env.close()
    return res


def _rate(s: dict) -> str:
    r = s["env_steps_per_s"]
    return f"{r['median']:,.0f} ({r['min']:,.0f}-{r['max']:,.0f})"


def table(res: dict) -> list[str]:
    plain, depth = res["without"], res["with"]
    img = depth["image"]
    w0 = img["world0"]
    return [
        f"| {res['envs']} worlds, {res['device_name']} | figure |",
        "|---|---|",
        f"| env steps/s without depth (median, range) | {_rate(plain)} |",
        f"| env steps/s with depth {res['camera']} (median, range) | {_rate(depth)} |",
        f"| ratio without / with | {res['ratio']:.2f}x |",
        f"| depth images/s (1 camera per world) | {res['images_per_s']:,.0f} |",
        f"| build s without / with (first includes the kernel compile) | {plain['build_s']:.1f} / "
        f"{depth['build_s']:.1f} |",
        f"| image, world 0: min / median / max m | {w0['min']:.3f} / {w0['median']:.3f} / {w0['max']:.3f} |",
        f"| image, world 0: pixels nearer than far; bottom / top row mean m | {w0['nearer_than_far']:.0%}; "
        f"{w0['bottom_row_mean']:.2f} / {w0['top_row_mean']:.2f} |",
        f"| image sane (floor seen, within [near, far]): world 0; worlds | {'yes' if img['sane'] else 'NO'}; "
        f"{img['sane_worlds']} of {img['worlds']} |",
    ]


def bench(args: argparse.Namespace) -> dict:
    """Every figure of the module docstring; a missing policy, corpus or GPU is a one-line :class:`InputError`."""
    check_device(args.device)
    if not Path(args.policy).is_file():
        raise InputError(args.policy, "--policy", "no such policy (train a MoCap policy: `make train-bc`)")
    sim = stage_dir(args.name, "physicalized")
    if not (sim / "meta" / "info.json").is_file():
        raise InputError(sim, "--name", f"no corpus {args.name!r} here (build it: `make corpus CORPUS={args.name}`)")
    t0, load = time.perf_counter(), os.getloadavg()
    camera = DepthCamera()
    episodes = runnable_episodes(load_episodes(args.name))
    history = load_policy(args.policy).layout.history
    cuda = args.device.startswith("cuda")
    res = {
        "policy": args.policy,
        "corpus": args.name,
        "episodes": len(episodes),
        "device": args.device,
        "device_name": torch.cuda.get_device_name() if cuda else "cpu",
        "envs": args.envs,
        "steps": args.steps,
        "warmup": args.warmup,
        "repeats": args.repeats,
        "camera": f"{camera.width} x {camera.height}",
        "load_average": load,
    }
    print(f"building {args.envs} worlds without depth ...", flush=True)
    res["without"] = measure(episodes, history, args, None)
    print(f"  built in {res['without']['build_s']:.1f} s; {_rate(res['without'])} env steps/s", flush=True)
    print(f"building {args.envs} worlds with depth ({res['camera']}) ...", flush=True)
    res["with"] = measure(episodes, history, args, camera)
    print(f"  built in {res['with']['build_s']:.1f} s; {_rate(res['with'])} env steps/s", flush=True)
    if cuda:
        res["max_memory_allocated_gib"] = torch.cuda.max_memory_allocated() / 2**30
    plain, depth = res["without"]["env_steps_per_s"]["median"], res["with"]["env_steps_per_s"]["median"]
    res["ratio"] = plain / depth
    res["images_per_s"] = depth
    res["seconds"] = time.perf_counter() - t0
    res["table"] = table(res)
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--name", default="corpus", help="the corpus under datasets/")
    ap.add_argument("--policy", default="runs/adam_seed0/policy.pt", help="a policy.pt (its observation history)")
    ap.add_argument("--envs", type=int, default=4096)
    ap.add_argument("--steps", type=int, default=100, help="env steps per timed round")
    ap.add_argument("--warmup", type=int, default=10, help="env steps before the timed rounds")
    ap.add_argument("--repeats", type=int, default=3, help="timed rounds per environment")
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--out", type=Path, default=Path("runs/bench/vision_mjlab.json"))
    args = ap.parse_args()
    try:
        res = bench(args)
    except InputError as exc:
        sys.exit(f"error: {exc}")
    write_json_atomic(args.out, res)
    print(f"mjlab depth bench: {args.policy} on {args.name} ({res['episodes']} episodes), {args.envs} worlds on "
          f"{res['device_name']}, {args.repeats} rounds of {args.steps} steps after {args.warmup}; load average "
          f"{res['load_average'][0]:.1f} at the start")  # fmt: skip
    print("\n".join(res["table"]))
    print(f"figures: {args.out}; {res['seconds']:.0f} s in all")
    if not res["with"]["image"]["sane"]:
        sys.exit("error: world 0's depth image is not sane (see the table)")


if __name__ == "__main__":
    main()
