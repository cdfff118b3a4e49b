"""The vision stage's speed on the CPU (issue 42's bars), one thread (``torch.set_num_threads(1)``):

* **depth images per CPU-second** at the default camera (:class:`train.vision.camera.DepthCamera`, 64 x 40) in the
  interaction environment's real scenes: the G1 and the object of a PickUp and a Push episode at scale 1.0, at
  ``--states`` states along each episode (the MoCap policy acting), clean (``camera.render``) and through the training
  sensor model (:class:`train.vision.noise.DepthSensor` with the :class:`~train.vision.noise.DepthNoise` defaults);
  the bar: >= 1000 images per CPU-second;
* **env step with depth against without**: ``--envs`` environments (:class:`train.envs.cpu.env.InteractionEnv`,
  ``EnvConfig.for_policy``; PickUp and Push alternating) replaying the MoCap policy's actions recorded once, so no
  policy call is timed: ``env.step`` (physics and the observation) against ``env.step`` plus reading every
  environment's depth sensor (:class:`train.vision.actor.DepthSensors`, clean and default noise); the bar: <= 2.5x;
* **student training windows per CPU-second**: :func:`train.vision.distill.fit` of a fresh student
  (:func:`train.vision.student.vision_student` of the MoCap policy) on synthetic :class:`DepthWindows` (random frames
  of the right shapes: the cost does not depend on the values), batch 256; beside it the MoCap policy's own BC
  (:func:`train.bc.fit`) on the same batch size, so the depth encoder's cost shows. No bar in the issue.

Every figure is measured ``--repeats`` times, the cases interleaved round by round (a load that comes and goes hits
them alike); the table shows the median and the range. CPU-seconds are ``time.process_time()``; wall times are in the
JSON. The figures go to ``--out`` (default ``runs/bench/vision.json``).

Run: ``make bench-vision [POLICY=runs/<RUN>/policy.pt] [CORPUS=corpus]`` (default policy:
``runs/adam_seed0/policy.pt``, a BC + DAgger MoCap policy: ``make train-bc``).
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import torch

torch.set_num_threads(1)

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from pipeline.errors import InputError  # noqa: E402
from pipeline.stage.atomic import write_json_atomic  # noqa: E402
from pipeline.stage.paths import stage_dir  # noqa: E402
from train.actors import PolicyActor  # noqa: E402
from train.bc import BCConfig, WindowTensors  # noqa: E402
from train.bc import fit as bc_fit  # noqa: E402
from train.envs.cpu.env import EnvConfig, InteractionEnv  # noqa: E402
from train.episodes import load_episodes  # noqa: E402
from train.policy import load_policy  # noqa: E402
from train.vision.actor import DepthSensors  # noqa: E402
from train.vision.camera import DepthCamera  # noqa: E402
from train.vision.distill import DistillConfig  # noqa: E402
from train.vision.distill import fit as distill_fit  # noqa: E402
from train.vision.noise import DepthNoise, DepthSensor  # noqa: E402
from train.vision.student import vision_student  # noqa: E402
from train.vision.windows import MM, DepthWindows  # noqa: E402

TASKS = ("PickUp", "Push")
BATCH = 256


def _spread(values: list[float]) -> dict:
    return {"median": float(np.median(values)), "min": float(min(values)), "max": float(max(values)), "all": values}


def rollout(policy, episodes) -> tuple[np.ndarray, InteractionEnv, list[list[np.ndarray]]]:
    """The MoCap policy acting on ``episodes`` (one environment each, scale 1.0) to the end of the longest: its
    actions ``(T, E, 29)`` (a finished environment's rows repeat its last action: it stands still anyway), the
    environment, and every environment's ``qpos`` at each step (``states[i][t]``)."""
    actor = PolicyActor(policy)
    env = InteractionEnv(actor.env_config())
    env.reset([(e, 1.0) for e in episodes])
    actor.reset(env)
    actions, states = [], [[s.data.qpos.copy()] for s in env.slots]
    done = np.zeros(env.num_envs, bool)
    while not done.all():
        a = actor.act(env)
        if actions:
            a[done] = actions[-1][done]
        actions.append(a)
        live = ~done
        obs, done = env.step(a)
        actor.observe(obs)
        for i in np.flatnonzero(live):
            states[i].append(env.slots[i].data.qpos.copy())
    return np.array(actions), env, states


def depth_images(env: InteractionEnv, states, count: int, repeats: int) -> dict:
    """Images per CPU-second (and per wall-second) of ``camera.render`` and ``DepthSensor.read`` over ``count``
    states evenly along each environment's episode (their kinematics computed once, outside the timing)."""
    camera = DepthCamera()
    scenes = []  # (model, data) with the kinematics of one state; per environment, in episode order
    for slot, qs in zip(env.slots, states):
        m, per = slot.scene.model, []
        for k in np.linspace(0, len(qs) - 1, count).round().astype(int):
            d = mujoco.MjData(m)
            d.qpos[:] = qs[k]
            mujoco.mj_kinematics(m, d)
            per.append((m, d))
        scenes.append(per)
    n = sum(len(p) for p in scenes)
    camera.render(*scenes[0][0])  # warm-up
    rng = np.random.default_rng(0)
    out = {k: {"cpu": [], "wall": []} for k in ("clean", "sensor")}
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        for per in scenes:
            for m, d in per:
                camera.render(m, d)
        out["clean"]["cpu"].append(n / (time.process_time() - c0))
        out["clean"]["wall"].append(n / (time.perf_counter() - w0))
        sensors = [DepthSensor(camera, DepthNoise(), rng) for _ in scenes]  # one per episode, as the actor has
        c0, w0 = time.process_time(), time.perf_counter()
        for sensor, per in zip(sensors, scenes):
            for m, d in per:
                sensor.read(m, d)
        out["sensor"]["cpu"].append(n / (time.process_time() - c0))
        out["sensor"]["wall"].append(n / (time.perf_counter() - w0))
    return {
        "images_per_round": n,
        "camera": f"{camera.width} x {camera.height}",
        **{k: {"cpu": _spread(v["cpu"]), "wall": _spread(v["wall"])} for k, v in out.items()},
    }


def env_steps(policy, episodes, actions: np.ndarray, envs: int, steps: int, repeats: int) -> dict:
    """CPU- and wall-seconds per control step of ``envs`` environments replaying ``actions`` (``episodes[i % E]``
    takes column ``i % E``): without depth, with clean depth, with the default sensor; rounds interleaved."""
    assign = [(episodes[i % len(episodes)], 1.0) for i in range(envs)]
    cols = [i % len(episodes) for i in range(envs)]
    replay = actions[:steps][:, cols]
    env = InteractionEnv(EnvConfig.for_policy(policy.layout))
    cases = {"without": None, "clean": DepthNoise.off(), "sensor": DepthNoise()}
    times = {k: {"cpu": [], "wall": []} for k in cases}
    for r in range(repeats):
        for key, noise in cases.items():
            env.reset(assign)  # the scenes are rebuilt outside the timing (the distance fields stay cached)
            sensors = None
            if noise is not None:
                sensors = DepthSensors(DepthCamera(), noise, seed=r)
                sensors.reset(env)
            c0, w0 = time.process_time(), time.perf_counter()
            for a in replay:
                env.step(a)
                if sensors is not None:
                    sensors.read(env)
            times[key]["cpu"].append((time.process_time() - c0) / len(replay))
            times[key]["wall"].append((time.perf_counter() - w0) / len(replay))
    env.close()
    out: dict = {"envs": envs, "steps": len(replay)}
    for key in cases:
        out[key] = {
            "ms_per_step_cpu": _spread([1e3 * t for t in times[key]["cpu"]]),
            "ms_per_step_wall": _spread([1e3 * t for t in times[key]["wall"]]),
        }
        if key != "without":  # per round: the rounds are interleaved, so a ratio compares like with like
            cpu = [w / o for w, o in zip(times[key]["cpu"], times["without"]["cpu"])]
            wall = [w / o for w, o in zip(times[key]["wall"], times["without"]["wall"])]
            out[key] |= {"ratio_cpu": _spread(cpu), "ratio_wall": _spread(wall)}
    return out


def synthetic_windows(policy, camera: DepthCamera, frames: int, windows: int, gen: torch.Generator):
    """``(DepthWindows, WindowTensors)`` of random frames with the policy's and the camera's shapes: ``windows``
    windows of consecutive frames (history ``l``), the same rows in both."""
    lay, steps = policy.layout, policy.config.history
    start = torch.randint(frames - steps + 1, (windows,), generator=gen)
    rows = start[:, None] + torch.arange(steps)
    proprio = torch.randn(frames, lay.proprio_dim, generator=gen)
    command = torch.randn(frames, lay.root_command_dim, generator=gen)
    action = 0.3 * torch.randn(windows, lay.action_dim, generator=gen)
    shape = (frames, camera.height, camera.width)
    mm = torch.randint(int(camera.near * MM), int(camera.far * MM) + 1, shape, generator=gen, dtype=torch.int32)
    depth = mm.to(torch.uint16)
    latent = torch.randn(frames, policy.config.latent, generator=gen)
    df = torch.randn(frames, lay.df_dim, generator=gen)
    return (
        DepthWindows(proprio, command, depth, latent, rows, action),
        WindowTensors(proprio, command, df, rows, action),
    )


def training(policy, frames: int, windows: int, steps: int, repeats: int) -> dict:
    """Windows per CPU-second of the student's :func:`train.vision.distill.fit` and the MoCap policy's BC
    :func:`train.bc.fit` on the same synthetic windows, batch :data:`BATCH`; one Adam each across the rounds."""
    torch.manual_seed(0)
    camera = DepthCamera()
    depth_data, bc_data = synthetic_windows(policy, camera, frames, windows, torch.Generator().manual_seed(0))
    student = vision_student(policy, camera)
    teacher = copy.deepcopy(policy)
    s_cfg, b_cfg = DistillConfig(fit_steps=steps, batch=BATCH), BCConfig(steps=steps, batch=BATCH, log_every=steps)
    s_opt = torch.optim.Adam(student.trainable_parameters(), lr=s_cfg.lr)
    b_opt = torch.optim.Adam(teacher.trainable_parameters(), lr=b_cfg.lr)
    runs = {
        "student": lambda seed: distill_fit(student, depth_data, s_cfg, s_opt, seed),
        "bc": lambda seed: bc_fit(teacher, bc_data, replace(b_cfg, seed=seed), opt=b_opt),
    }
    for run in runs.values():  # warm-up
        run(0)
    rates = {k: {"cpu": [], "wall": []} for k in runs}
    for r in range(repeats):
        for key, run in runs.items():
            c0, w0 = time.process_time(), time.perf_counter()
            run(r + 1)
            rates[key]["cpu"].append(steps * BATCH / (time.process_time() - c0))
            rates[key]["wall"].append(steps * BATCH / (time.perf_counter() - w0))
    params = {
        "student": sum(p.numel() for p in student.trainable_parameters()),
        "encoder": sum(p.numel() for p in student.encoder.parameters()),
        "bc": sum(p.numel() for p in teacher.trainable_parameters()),
    }
    return {
        "batch": BATCH,
        "steps_per_round": steps,
        "frames": frames,
        "windows": windows,
        "trainable_parameters": params,
        **{
            k: {"windows_per_s_cpu": _spread(v["cpu"]), "windows_per_s_wall": _spread(v["wall"])}
            for k, v in rates.items()
        },
    }


def _cell(s: dict, fmt: str) -> str:
    return f"{s['median']:{fmt}} ({s['min']:{fmt}}-{s['max']:{fmt}})"


def table(res: dict) -> list[str]:
    img, env, fit = res["depth_images"], res["env_step"], res["training"]
    rows = [
        ("depth images / CPU-s, 64 x 40, clean render", ">= 1000", img["clean"]["cpu"], ".0f", lambda v: v >= 1000),
        ("depth images / CPU-s, 64 x 40, default sensor", ">= 1000", img["sensor"]["cpu"], ".0f", lambda v: v >= 1000),
        (
            f"env step with depth / without, {env['envs']} envs, default sensor",
            "<= 2.5x",
            env["sensor"]["ratio_cpu"],
            ".2f",
            lambda v: v <= 2.5,
        ),
        (
            f"env step with depth / without, {env['envs']} envs, clean depth",
            "<= 2.5x",
            env["clean"]["ratio_cpu"],
            ".2f",
            lambda v: v <= 2.5,
        ),
        ("student training windows / CPU-s, batch 256", "-", fit["student"]["windows_per_s_cpu"], ".0f", None),
        ("MoCap BC windows / CPU-s, batch 256 (reference)", "-", fit["bc"]["windows_per_s_cpu"], ".0f", None),
    ]
    lines = ["| measure | target | measured: median (min-max) | met |", "|---|---|---|---|"]
    for label, target, s, fmt, ok in rows:
        met = "-" if ok is None else ("yes" if ok(s["median"]) else "no")
        lines.append(f"| {label} | {target} | {_cell(s, fmt)} | {met} |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", default="runs/adam_seed0/policy.pt", help="a MoCap policy.pt (BC + DAgger)")
    ap.add_argument("--name", default="corpus", help="the corpus under datasets/")
    ap.add_argument("--states", type=int, default=40, help="rendered states along each episode")
    ap.add_argument("--envs", type=int, default=8)
    ap.add_argument("--steps", type=int, default=150, help="control steps per env-step round")
    ap.add_argument("--fit-steps", type=int, default=10, help="Adam steps per training round")
    ap.add_argument("--windows", type=int, default=4000, help="synthetic training windows")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out", type=Path, default=Path("runs/bench/vision.json"))
    a = ap.parse_args()
    try:
        res = bench(a)
    except InputError as exc:
        sys.exit(f"error: {exc}")
    write_json_atomic(a.out, res)
    print(
        f"vision bench: {a.policy} on {a.name} ({', '.join(res['episodes'])}, scale 1.0), 1 thread, "
        f"{a.repeats} interleaved rounds; load average {res['load_average'][0]:.1f} at the start"
    )
    print("\n".join(res["table"]))
    ms = res["env_step"]
    print(
        f"env step, {ms['envs']} envs x {ms['steps']} steps: without {ms['without']['ms_per_step_cpu']['median']:.1f} "
        f"ms, + clean depth {ms['clean']['ms_per_step_cpu']['median']:.1f} ms, + default sensor "
        f"{ms['sensor']['ms_per_step_cpu']['median']:.1f} ms per step (CPU)"
    )
    print(f"figures (wall times too): {a.out}; {res['seconds']:.0f} s in all")


def bench(a: argparse.Namespace) -> dict:
    """Every figure of the module docstring; a missing policy or corpus is a one-line :class:`InputError`."""
    if not Path(a.policy).is_file():
        raise InputError(a.policy, "--policy", "no such policy (train a MoCap policy: `make train-bc`)")
    sim = stage_dir(a.name, "physicalized")
    if not (sim / "meta" / "info.json").is_file():
        raise InputError(sim, "--name", f"no corpus {a.name!r} here (build it: `make corpus CORPUS={a.name}`)")
    t0, load = time.perf_counter(), os.getloadavg()
    policy = load_policy(a.policy)
    episodes = load_episodes(a.name, TASKS)
    episodes = [next(e for e in episodes if e.task == t) for t in TASKS if any(e.task == t for e in episodes)]
    actions, env, states = rollout(policy, episodes)
    res = {
        "policy": a.policy,
        "corpus": a.name,
        "episodes": [e.simulated.robot.source for e in episodes],
        "rollout_steps": [len(s) - 1 for s in states],
        "threads": torch.get_num_threads(),
        "repeats": a.repeats,
        "load_average": load,
        "depth_images": depth_images(env, states, a.states, a.repeats),
    }
    env.close()
    res["env_step"] = env_steps(policy, episodes, actions, a.envs, min(a.steps, len(actions)), a.repeats)
    res["training"] = training(policy, 2 * a.windows, a.windows, a.fit_steps, a.repeats)
    res["seconds"] = time.perf_counter() - t0
    res["load_average_end"] = os.getloadavg()
    res["table"] = table(res)
    return res


if __name__ == "__main__":
    main()
