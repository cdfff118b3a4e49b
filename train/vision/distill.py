"""Visual-motor distillation (paper Sec. III-D, Eq. 8): DAgger from the frozen MoCap policy pi_full into the vision
student pi_vis (:mod:`train.vision.student`). Read top to bottom:

1. iteration ``i`` rolls out :attr:`DistillConfig.episodes` episodes (PickUp, Push and Carry: SitStand's seat is
   behind the camera; task weights follow the last iteration's failures, :func:`train.dagger.task_weights`), each
   under a draw of the six randomisations of post-training (:mod:`train.mdp.randomize`: geometry, physics, initial
   state, command offset per episode; actuation noise per step) and the student's depth sensor under the
   perceptual ones (:mod:`train.vision.noise`: extrinsics per episode, jitter, noise, dropout, holes, edges,
   quantisation, latency, repeated frames). At every step the environment executes pi_full's targets with
   probability ``beta_i = beta0 * decay^i`` and the student's otherwise, and pi_full, reading the exact DF of the
   state, labels the student's window. ``beta_0 = 1`` (the first iteration is the teacher's own rollouts, as DAgger
   starts) and a fast decay: the paper states no mixture (its student acts), so the student acts alone from a few
   iterations on. Then the student alone runs :attr:`DistillConfig.probe` fixed episodes at scale 1.0, no physical
   randomisation, its sensor noise on (what the evaluation scores), labelled and aggregated the same way;
2. the student is refitted on every window so far (:func:`fit`) with one Adam optimiser across the refits, on

       L = || pi_vis(o_vis) - normalize(a_full) ||^2  (+ align * || E_phi(D) - z_VAE(u) ||^2 over the window's steps)

   the paper's Eq. (8) by default (``align = 0``); the alignment term (the abstract's "aligns DF latents with
   egocentric depth features") is the ablation switch;
3. a row of ``distill_log.jsonl`` per iteration: beta, the on-policy action error, episode length, falls, success
   and ``R_acc`` of the mixture's rollouts and (``student``) of the probe, the refit's losses (and latent cosine).

The physical randomisation's ranges are post-training's except the object scale: 0.9-1.1 instead of 0.4-1.6 and
boxes stay boxes, because pi_full here (a BC + DAgger policy, not the paper's post-trained one) scores 0% at every
scale but 1.0 (README, Train I): labels of a failing teacher teach failing. A post-trained teacher takes the full
ranges (``--randomization full``); ``--randomization off`` keeps only the sensor's (the ablation).

Measured (laptop scale, teacher: Train I's best seed, one training seed, 24 evaluation episodes a cell at scale 1.0,
the README's table): after 12 iterations (65k env steps, 41 min on one core) PickUp 79.2, Push contact 87.7, Carry
8.3% against the teacher's 91.7 / 93.9 / 16.7; at 8 iterations Eq. (8) alone 54.2 / 70.5 / 33.3, with the alignment
term 75.0 / 83.1 / 8.3, without the physical randomisation 62.5 / 75.0 / 8.3 (intervals of +-15-20 points). In its
own rollouts under the narrow randomisation the teacher succeeded in 2 of 16 episodes, 8 of 16 without it. A second
training seed after 12 iterations: 62.5 / 66.0 / 16.7; both seeds after 20: 66.7 / 80.6 / 12.5 and 66.7 / 72.9 / 4.2
(PickUp ~0.73x its teacher's, Push 0.78-0.93x).

The run folder holds each iteration's student (``policy_distill<i>.pt``), its new windows (``distill_data<i>.pt``,
written once), the optimiser and the log: a rerun resumes after the last finished iteration. Deterministic for a
seed on the CPU.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from pipeline.errors import InputError
from pipeline.stage.atomic import write_json_atomic, write_torch_atomic
from train.actors import PolicyActor
from train.dagger import draw_episodes, probe_episodes, task_weights
from train.dagger import read_log as read_dagger_log
from train.envs.cpu.env import EnvConfig, InteractionEnv
from train.episodes import Episode
from train.mdp import randomize as R
from train.policy import InteractionPolicy
from train.vision.actor import VisionActor
from train.vision.camera import DepthCamera
from train.vision.noise import DepthNoise
from train.vision.student import EncoderConfig, VisionPolicy, load_vision_policy, save_vision_policy, vision_student
from train.vision.windows import DepthBatch, DepthWindows, WindowRecorder, check_depth_memory

VISION_TASKS = ("PickUp", "Push", "Carry")


RANDOMIZATIONS = ("narrow", "full", "off")


def distill_randomization(kind: str = "narrow") -> R.RandomizationConfig:
    """The physical randomisation of a distillation: ``narrow`` (default) post-training's ranges with the object scale
    0.9-1.1 and boxes kept, ``full`` post-training's own, ``off`` none (the sensor's randomisation only; the
    ablation) (module docstring)."""
    if kind not in RANDOMIZATIONS:
        raise ValueError(f"randomization must be one of {RANDOMIZATIONS}, got {kind!r}")
    if kind == "off":
        return R.RandomizationConfig.off()
    return R.RandomizationConfig() if kind == "full" else R.RandomizationConfig(scale=(0.9, 1.1), cylinder_prob=0.0)


@dataclass(frozen=True)
class DistillConfig:
    """Iterations, episodes per iteration (mixture / probe), environments stepped together, the beta schedule, the
    refit (``fit_steps`` Adam steps of ``batch`` windows at ``lr``, Table A1's rate), the alignment weight, the depth
    memory cap, the seed and the randomisations (module docstring)."""

    iterations: int = 12
    episodes: int = 16
    probe: int = 8
    envs: int = 8
    beta0: float = 1.0
    beta_decay: float = 0.5
    fit_steps: int = 800
    batch: int = 256
    lr: float = 1e-3
    grad_clip: float = 1.0
    align: float = 0.0
    task_floor: float = 0.25
    depth_memory_mb: float = 4000.0
    seed: int = 0
    randomization: R.RandomizationConfig = field(default_factory=distill_randomization)
    noise: DepthNoise = field(default_factory=DepthNoise)
    camera: DepthCamera = field(default_factory=DepthCamera)
    encoder: EncoderConfig = field(default_factory=EncoderConfig)


def collect(
    student: VisionPolicy,
    teacher: InteractionPolicy,
    batch: list[tuple[Episode, R.Variation | None]],
    beta: float,
    rng: np.random.Generator,
    cfg: DistillConfig,
) -> tuple[DepthWindows, dict]:
    """Roll ``batch`` out ``cfg.envs`` at a time under the beta-mixture (module docstring, 1.); the student's windows
    labelled by ``teacher``, and the rollouts' figures."""
    recorded: list[DepthWindows] = []
    sq_err, count, lengths, falls, success, r_acc, tasks = 0.0, 0, [], 0, [], [], {}
    noise_rng = np.random.default_rng(rng.integers(2**63))
    for k in range(0, len(batch), cfg.envs):
        part = batch[k : k + cfg.envs]
        env = InteractionEnv(EnvConfig.for_policy(teacher.layout))
        env.reset([(e, 1.0) if v is None else (e, v.scale, v) for e, v in part])
        pupil, label = VisionActor(student, cfg.noise, noise_rng), PolicyActor(teacher)
        pupil.reset(env)
        label.reset(env)
        rec = WindowRecorder(len(part), student.config.history)
        done = np.zeros(env.num_envs, bool)
        _record(rec, ~done, pupil, teacher)
        while not done.all():
            live = ~done
            a_student, a_teacher = pupil.act(env), label.act(env)
            rec.windows(live, a_teacher)
            sq_err += float(((a_student - a_teacher)[live] ** 2).sum())
            count += int(live.sum()) * a_student.shape[1]
            use_teacher = (rng.random(env.num_envs) < beta)[:, None]
            executed = R.actuation_noise(np.where(use_teacher, a_teacher, a_student), _noise(part, cfg), rng)
            obs, done = env.step(executed)
            pupil.observe(obs)
            label.observe(obs)
            _record(rec, ~done, pupil, teacher)
        env.close()
        recorded.append(rec.tensors())
        lengths += [s.t for s in env.slots]
        falls += sum(s.fell for s in env.slots)
        for (e, _), m in zip(part, env.meters()):
            summary = m.summary()
            success.append(m.success)
            r_acc.append(summary.get("root_accuracy", float("nan")))
            tally = tasks.setdefault(e.task, [0, 0])
            tally[0], tally[1] = tally[0] + int(m.success), tally[1] + 1
    data = DepthWindows.concat(recorded)
    figures = {
        "action_rmse": float(np.sqrt(sq_err / max(count, 1))),
        "episode_length": float(np.mean(lengths)),
        "falls": int(falls),
        "success": float(np.mean(success)),
        "root_accuracy": float(np.mean(r_acc)),
        "tasks": tasks,
        "windows": len(data),
        "env_steps": int(sum(lengths)),
    }
    return data, figures


def _noise(part: list, cfg: DistillConfig) -> float:
    """The actuation noise of a batch: the randomisation's for randomised episodes, none for the probe."""
    return cfg.randomization.action_noise_rad if part[0][1] is not None else 0.0


def _record(rec: WindowRecorder, which: np.ndarray, pupil: VisionActor, teacher: InteractionPolicy) -> None:
    """The newest frame of the environments ``which``: the student's terms and pi_full's latent of the same state."""
    terms = pupil.history.terms
    with torch.no_grad():
        z = teacher.latents(torch.as_tensor(terms["df"][:, -1:], dtype=torch.float32))[:, 0].numpy()
    rec.frames(which, terms["proprio"][:, -1], terms["root_command"][:, -1], terms["depth"][:, -1], z)


def distill_loss(student: VisionPolicy, b: DepthBatch, align: float) -> tuple[torch.Tensor, dict]:
    """Eq. (8) on normalised actions, plus ``align`` times the latent MSE (module docstring, 2.); the figures."""
    z = student.latents(b.depth)
    action = (student.head(b.proprio, b.root_command, z) - student.norm["action"].normalize(b.action)).pow(2).mean()
    loss, figures = action, {"action_loss": action.detach()}
    if align > 0:
        latent = (z - b.latent).pow(2).mean()
        loss = loss + align * latent
        figures |= {
            "latent_loss": latent.detach(),
            "latent_cosine": torch.cosine_similarity(z, b.latent, -1).mean().detach(),
        }
    return loss, figures


def fit(student: VisionPolicy, data: DepthWindows, cfg: DistillConfig, opt: torch.optim.Optimizer, seed: int) -> dict:
    """``cfg.fit_steps`` Adam steps on :func:`distill_loss`, the rate on a cosine from ``cfg.lr`` to 0 (as
    :func:`train.bc.fit`); the mean figures of the last tenth of the steps."""
    gen = torch.Generator().manual_seed(seed)
    for group in opt.param_groups:
        group["lr"] = cfg.lr
    student.train()
    tail, sums, t0 = max(cfg.fit_steps // 10, 1), {}, time.perf_counter()
    for step in range(cfg.fit_steps):
        for group in opt.param_groups:
            group["lr"] = cfg.lr * 0.5 * (1.0 + math.cos(math.pi * step / cfg.fit_steps))
        loss, figures = distill_loss(student, data.sample(cfg.batch, gen), cfg.align)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(student.trainable_parameters(), cfg.grad_clip)
        opt.step()
        if step >= cfg.fit_steps - tail:
            for key, v in figures.items():
                sums[key] = sums.get(key, 0.0) + float(v)
    student.eval()
    seconds = time.perf_counter() - t0
    return {
        **{k: v / tail for k, v in sums.items()},
        "windows_per_s": cfg.fit_steps * cfg.batch / seconds,
        "seconds": seconds,
    }


LOG = "distill_log.jsonl"


def read_log(run_dir: str | Path) -> list[dict]:
    """The finished iterations' rows of the distillation's log (:func:`train.dagger.read_log`)."""
    return read_dagger_log(run_dir, LOG)


def log_scale(rows: list[dict]) -> dict:
    """The training scale of the iterations ``rows``: their count, episodes, env steps and aggregated windows."""
    return {
        "distill_iterations": len(rows),
        "episodes": sum(n for r in rows for tally in (r["tasks"], r["student"]["tasks"]) for _, n in tally.values()),
        "env_steps": sum(r["env_steps"] + r["student"]["env_steps"] for r in rows),
        "windows": rows[-1]["aggregated_windows"] if rows else 0,
    }


def distill(
    teacher: InteractionPolicy,
    teacher_source: dict,
    episodes: list[Episode],
    run_dir: str | Path,
    cfg: DistillConfig,
    overwrite: bool = False,
) -> VisionPolicy:
    """Run (or resume) the distillation (module docstring); the last iteration's student, also ``run_dir/policy.pt``.
    A depth buffer over the memory cap or another distillation in ``run_dir`` is a one-line error before anything
    is written."""
    run_dir = Path(run_dir)
    episodes = [e for e in episodes if e.task in VISION_TASKS]
    if not episodes:
        raise InputError(teacher_source.get("corpus"), "episodes", f"no valid episode of {', '.join(VISION_TASKS)}")
    frames = cfg.iterations * (cfg.episodes + cfg.probe) * max(e.frames for e in episodes)
    check_depth_memory(frames, cfg.camera.height, cfg.camera.width, cfg.depth_memory_mb, run_dir)
    claim_run(run_dir, cfg, teacher_source, overwrite)
    rows = read_log(run_dir)
    torch.manual_seed(cfg.seed)
    student = vision_student(teacher, cfg.camera, cfg.encoder, teacher_source)
    parts: list[DepthWindows] = []
    if rows:
        student = load_vision_policy(run_dir / f"policy_distill{len(rows) - 1}.pt")
        parts = [
            DepthWindows(**torch.load(run_dir / f"distill_data{i}.pt", weights_only=True)) for i in range(len(rows))
        ]
    opt = torch.optim.Adam(student.trainable_parameters(), lr=cfg.lr)
    opt_path = run_dir / "distill_optimizer.pt"
    saved = torch.load(opt_path, weights_only=True) if rows and opt_path.is_file() else {}
    if saved.get("iteration") == len(rows) - 1:
        opt.load_state_dict(saved["state"])
    tasks = sorted({e.task for e in episodes})
    probe = [(e, None) for e in probe_episodes(episodes, cfg.probe, cfg.seed)]
    settings = _settings(cfg, teacher_source)
    for it in tqdm(range(len(rows), cfg.iterations), desc="distill", unit="iteration"):
        t0 = time.perf_counter()
        rng = np.random.default_rng([cfg.seed, it])
        weights = task_weights(tasks, rows[-1] if rows else None, cfg.task_floor)
        chosen = draw_episodes(episodes, cfg.episodes, weights, tasks, rng)
        beta = cfg.beta0 * cfg.beta_decay**it
        new, figures = collect(student, teacher, [(e, R.draw(cfg.randomization, rng)) for e in chosen], beta, rng, cfg)
        own, figures["student"] = collect(student, teacher, probe, 0.0, np.random.default_rng([cfg.seed, 7, it]), cfg)
        new = DepthWindows.concat([new, own])
        parts.append(new)
        fitted = fit(student, DepthWindows.concat(parts), cfg, opt, cfg.seed + it)
        row = {
            "iteration": it,
            "beta": beta,
            "task_weights": dict(zip(tasks, weights.round(4).tolist())),
            **figures,
            "aggregated_windows": sum(len(p) for p in parts),
            "fit": fitted,
            "seconds": time.perf_counter() - t0,
        }
        write_torch_atomic(run_dir / f"distill_data{it}.pt", new.state())
        save_vision_policy(student, run_dir / f"policy_distill{it}.pt", distill=settings)
        write_torch_atomic(opt_path, {"iteration": it, "state": opt.state_dict()})
        with (run_dir / LOG).open("a", encoding="utf-8") as f:  # last: the row marks it finished
            f.write(json.dumps(row) + "\n")
        rows.append(row)
    save_vision_policy(student, run_dir / "policy.pt", distill=settings)
    write_json_atomic(run_dir / "report.json", report(rows, cfg, teacher_source, run_dir))
    return student


def _settings(cfg: DistillConfig, teacher_source: dict) -> dict:
    return {"config": json.loads(json.dumps(asdict(cfg))), "teacher": teacher_source}


def report(rows: list[dict], cfg: DistillConfig, teacher_source: dict, run_dir: Path) -> dict:
    """The run's scale (iterations, episodes, env steps, windows) and teacher, for every result that scores it."""
    last = rows[-1] if rows else {}
    return {
        "policy": str(run_dir / "policy.pt"),
        "teacher": teacher_source,
        "scale": {
            "teacher": teacher_source.get("path"),
            **log_scale(rows),
            "fit_steps_per_iteration": cfg.fit_steps,
            "batch": cfg.batch,
            "align": cfg.align,
            "device": "cpu",
        },
        "last": last,
        "seconds": sum(r["seconds"] for r in rows),
    }


def claim_run(run_dir: Path, cfg: DistillConfig, teacher_source: dict, overwrite: bool) -> None:
    """``run_dir`` holds this distillation (or none, or a shorter one of it); another one there is a one-line error
    unless ``overwrite`` (then it is removed)."""
    settings, path = _settings(cfg, teacher_source), run_dir / "distill.json"
    if overwrite and run_dir.exists():
        shutil.rmtree(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    if path.is_file():
        recorded = json.loads(path.read_text())
        old = {**recorded["config"], "teacher": recorded["teacher"]}
        new = {**settings["config"], "teacher": settings["teacher"]}
        diff = sorted(k for k in new if k != "iterations" and old.get(k) != new[k])  # more iterations: resumed
        if diff:
            raise InputError(
                run_dir,
                "distill.json",
                f"a distillation of other settings ({', '.join(diff)}) is here; pass --overwrite",
            )
    write_json_atomic(path, settings)


def with_overrides(cfg: DistillConfig, **kw) -> DistillConfig:
    """``cfg`` with the given fields replaced (None: kept)."""
    return replace(cfg, **{k: v for k, v in kw.items() if v is not None})
