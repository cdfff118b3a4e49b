"""The paper's evaluation protocol (Table 2, App. "Evaluation Metrics"), one harness for every actor.

Cells: PickUp at object scales 0.4 / 0.6 / 1.0 / 1.4 / 1.6, SitStand at 0.4 / 1.0 / 1.6, Push at 0.6 / 1.0 / 1.4
(hand contact rate), Carry at 1.0 (:data:`TABLE2`). Per cell and evaluation seed, :attr:`EvalConfig.episodes`
episodes of the task are drawn from the corpus (the seed picks them and perturbs the initial joint angles by
:attr:`EvalConfig.joint_noise`), run at the scale in the interaction environment (:mod:`train.envs.cpu.env`) and
scored by :class:`train.mdp.tasks.TaskMeter`. A cell reports the success rate (Push: the mean hand contact rate)
over all its episodes, with its 95% interval (:func:`interval95`), and the standard deviation over the seeds. The
same harness scores the student policy and the QP teacher tracking the fixed 1.0x reference (the paper's
reference-based rows). Every result names its scale: episodes, seeds and what was scored (checkpoint and its
training figures), so a CPU smoke number is never mistaken for a full one.

Every cell also reports ``root_accuracy``, ``R_acc`` (:attr:`train.mdp.tasks.TaskMeter.root_accuracy`: the share of
an episode's control steps with the root within 0.6 m of the commanded root trajectory), the mean over the cell's
episodes pooled over the seeds (each episode weighs the same, as each success does).

Two protocols (:attr:`EvalConfig.protocol`, :mod:`train.evaluation.cells`). ``scaled``, the paper's: a cell's
episodes are the demonstrations, the object scaled by the environment and the command the demonstration's.
``matched``: a cell's episodes are an augmented corpus's variant at that cell's scale (:mod:`retarget.augment`: its
object, placement and reference made for that geometry), run as they are; the QP teacher then tracks a reference made
for the evaluated geometry (the scale-matched teacher). A cell without such episodes is listed under ``"missing"``,
one whose references the success rule rules out under ``"infeasible"``, each with its reason, and shown ``-``.
:attr:`EvalConfig.shape` ``cylinder`` runs every cell with the box drawn as a cylinder (``scaled``: by the
environment; ``matched``: the ``-cylinder`` variants).

An actor may declare ``excluded_tasks`` (a tuple of task names) and ``excluded_reason`` (a sentence) as attributes,
e.g. a vision policy, whose egocentric camera does not see the seat behind it, excludes SitStand
(:func:`not_applicable`). Those tasks' cells are not run; the result records them under ``"not_applicable"`` and the
table shows them ``n/a``, distinct from ``-`` (a cell this evaluation did not run).
"""

from __future__ import annotations

import json
import re
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy import stats
from tqdm import tqdm

from pipeline.dataset.subset import read_subset
from pipeline.errors import InputError
from pipeline.geometry import variant_label
from pipeline.robot import JOINTS_QPOS
from pipeline.stage.atomic import write_bytes_atomic, write_json_atomic
from pipeline.stage.figure import save_figure
from train.dagger import read_log
from train.envs.cpu.env import InteractionEnv
from train.episodes import TASKS, Episode
from train.evaluation.cells import cell_episodes, rule_window, variant_yield
from train.mdp.randomize import Variation
from train.mdp.tasks import Rules

TABLE2: dict[str, tuple[float, ...]] = {
    "PickUp": (0.4, 0.6, 1.0, 1.4, 1.6),
    "SitStand": (0.4, 1.0, 1.6),
    "Push": (0.6, 1.0, 1.4),
    "Carry": (1.0,),
}


@dataclass(frozen=True)
class EvalConfig:
    """``episodes`` per cell and seed: 16 x 3 seeds = 48 episodes a cell, a 95% interval of about +-13 points at a
    50% success rate and +-10 at 80% (Wilson); 4 per seed (issue 27's default) scored the same policy 25% and 62.5%
    on PickUp at 1.0 in two evaluations."""

    seeds: tuple[int, ...] = (0, 1, 2)
    episodes: int = 16  # per cell and seed
    envs: int = 8  # environments stepped together
    threads: int = 1
    joint_noise: float = 0.02  # rad, uniform: initial joint perturbation per episode
    tasks: tuple[str, ...] = TASKS
    scales: tuple[float, ...] | None = None  # only these scales of TABLE2 (None: all)
    rules: Rules = field(default_factory=Rules)
    protocol: str = "scaled"  # or "matched" (module docstring)
    shape: str = "box"  # or "cylinder": every cell's box drawn as a circular cylinder

    def __post_init__(self):
        if self.protocol not in PROTOCOLS:
            raise InputError(None, "protocol", f"unknown protocol {self.protocol!r} (known: {', '.join(PROTOCOLS)})")
        if self.shape not in ("box", "cylinder"):
            raise InputError(None, "shape", f"unknown shape {self.shape!r} (known: box, cylinder)")


PROTOCOLS = ("scaled", "matched")


def _run(actor, batch: list[Episode], scale: float, rng: np.random.Generator, cfg: EvalConfig) -> list[dict]:
    env = InteractionEnv(actor.env_config(threads=cfg.threads, rules=cfg.rules))
    shape = Variation(cylinder=True) if cfg.shape == "cylinder" and cfg.protocol == "scaled" else None
    env.reset([(e, scale, shape) for e in batch])
    for s in env.slots:
        q = s.data.qpos.copy()
        q[JOINTS_QPOS] += rng.uniform(-cfg.joint_noise, cfg.joint_noise, JOINTS_QPOS.stop - JOINTS_QPOS.start)
        s.set_state(q[:36], s.data.qvel[:35].copy(), q[36:])
    actor.reset(env)
    done = np.zeros(env.num_envs, bool)
    while not done.all():
        obs, done = env.step(actor.act(env))
        actor.observe(obs)
    env.close()
    return [{**m.summary(), "fell": s.fell} for m, s in zip(env.meters(), env.slots)]


def not_applicable(actor) -> dict[str, str]:
    """The tasks ``actor`` does not attempt, each with the actor's reason: its ``excluded_tasks`` attribute (absent:
    none) and ``excluded_reason`` (absent: a generic one). An unknown task name is an error, not a silent no-op."""
    tasks = tuple(getattr(actor, "excluded_tasks", ()))
    if unknown := [t for t in tasks if t not in TASKS]:
        raise ValueError(f"excluded_tasks: unknown task(s) {unknown}; known: {TASKS}")
    reason = getattr(actor, "excluded_reason", "") or "not applicable to this actor"
    return {t: reason for t in tasks}


def evaluate(actor, episodes: list[Episode], cfg: EvalConfig = EvalConfig(), label: str = "", corpus: str = "") -> dict:
    """The Table 2 results of ``actor`` on the corpus ``episodes`` (module docstring); the tasks the actor excludes
    are listed, with its reason, as ``"not_applicable": [{"task", "reason"}]`` (only when there are some)."""
    excluded = not_applicable(actor)
    tasks = [t for t in cfg.tasks if t not in excluded]
    cells = {
        (t, s): cell_episodes(episodes, t, s, cfg.protocol, cfg.shape)
        for t in tasks
        for s in TABLE2[t]
        if cfg.scales is None or s in cfg.scales
    }
    out = {"label": label, "config": asdict(cfg), "cells": {}}
    if excluded:
        out["not_applicable"] = [{"task": t, "reason": why} for t, why in excluded.items()]
    for (task, scale), (pool, _) in list(cells.items()):
        name = f"{task}@{scale:g}"
        if not pool and any(e.task == task for e in episodes):
            what = "valid episode of the variant" if cfg.protocol == "matched" else "demonstration (x1)"
            found = variant_yield(corpus, task, variant_label(scale, cfg.shape)) if corpus else ""
            reason = f"the corpus has no {what}" + (f": {found}" if found else "")
            out.setdefault("missing", []).append({"cell": name, "reason": reason})
        elif cfg.protocol == "matched" and (why := rule_window(task, pool, cfg.rules)):
            out.setdefault("infeasible", []).append({"cell": name, "reason": why})
            cells[(task, scale)] = ([], 1.0)
    for (task, scale), (pool, run_scale) in tqdm(
        [(k, v) for k, v in cells.items() if v[0]], desc=f"eval {label}", unit="cell"
    ):
        outcomes = []
        for seed in cfg.seeds:
            rng = np.random.default_rng(zlib.crc32(f"{seed}|{task}|{scale}".encode()))
            pick = rng.choice(len(pool), cfg.episodes, replace=len(pool) < cfg.episodes)
            runs = []
            for k in range(0, len(pick), cfg.envs):
                runs += _run(actor, [pool[i] for i in pick[k : k + cfg.envs]], run_scale, rng, cfg)
            outcomes.append(runs)
        out["cells"][f"{task}@{scale:g}"] = {
            **summarize_cell(task, scale, outcomes, cfg.seeds),
            **(_seated([r for runs in outcomes for r in runs], cfg) if task == "SitStand" else {}),
        }
    return out


def summarize_cell(task: str, scale: float, runs_per_seed: list[list[dict]], seeds) -> dict:
    """A cell of Table 2 from its episodes' outcomes, one list per evaluation seed (each outcome a
    :meth:`train.mdp.tasks.TaskMeter.summary` plus ``fell``): the mean over seeds of the success rate (Push: the
    contact rate), its spread over seeds, the 95% interval over every episode (:func:`interval95`), falls, length,
    and the mean ``root_accuracy`` (R_acc) over every episode."""
    key = "contact_rate" if task == "Push" else "success"
    per_seed = [float(np.mean([r[key] for r in runs])) for runs in runs_per_seed]
    outcomes = [r for runs in runs_per_seed for r in runs]
    low, high = interval95([r[key] for r in outcomes], binary=task != "Push")
    return {
        "task": task,
        "scale": scale,
        "metric": "contact_rate" if task == "Push" else "success_rate",
        "mean": float(np.mean(per_seed)),
        "ci95": [low, high],
        "episodes": len(outcomes),
        "std": float(np.std(per_seed)),
        "per_seed": per_seed,
        "episodes_per_seed": len(runs_per_seed[0]),
        "seeds": list(seeds),
        "falls": int(sum(r["fell"] for r in outcomes)),
        "mean_steps": float(np.mean([r["steps"] for r in outcomes])),
        "root_accuracy": float(np.mean([r["root_accuracy"] for r in outcomes])),
    }


def interval95(values: list[float], binary: bool) -> tuple[float, float]:
    """The 95% interval of the mean of a cell's ``values`` (one per episode, pooled over the seeds): Wilson's score
    interval for successes (0 or 1; it stays inside [0, 1] and is not empty at 0% or 100%, unlike the normal
    approximation), Student's t for contact rates (fractions), clipped to [0, 1]."""
    n = len(values)
    if binary:
        ci = stats.binomtest(int(round(sum(values))), n).proportion_ci(0.95, "wilson")
        return float(ci.low), float(ci.high)
    mean = float(np.mean(values))
    half = float(stats.t.ppf(0.975, n - 1) * np.std(values, ddof=1) / np.sqrt(n)) if n > 1 else 1.0
    return max(0.0, mean - half), min(1.0, mean + half)


def _seated(outcomes: list[dict], cfg: EvalConfig) -> dict:
    """Why SitStand cells fail: the share of episodes with pelvis-chair contact for the rule's duration at any root
    height, and the median root height in contact (the rule also asks for 0.3-0.6 m)."""
    z = [r["seated_root_z_m"] for r in outcomes if r["seated_root_z_m"] is not None]
    return {
        "seated_any_height_rate": float(np.mean([r["seated_s"] >= cfg.rules.sit_s for r in outcomes])),
        "seated_root_z_m": float(np.median(z)) if z else None,
    }


def markdown(results: list[dict]) -> str:
    """The Table 2 layout, two rows per result: its success (the mean and its 95% interval, in %, :func:`cell_text`),
    then ``<label>: R_acc``, each cell's mean root tracking accuracy in %. A row of its own rather than a figure in
    each cell (or one mean per row): the cells stay short enough to read across twelve columns, R_acc lines up under
    the success it belongs to, and rows that ran different cells (vision: no SitStand) are compared cell by cell,
    which a row mean would not do. ``n/a``: a task the actor excludes (the reason is in its result); ``ruled out``: a
    cell the success rule rules out for its references, ``no clip``: a cell whose variant the corpus lacks (both with
    their reasons in ``eval.json``); ``-``: a cell not run. A result written before R_acc (no cell has
    ``root_accuracy``) has no R_acc row."""
    cols = [(t, s) for t in TASKS for s in TABLE2[t]]
    head = "| | " + " | ".join(f"{t} {s:g}" for t, s in cols) + " |"
    lines = [head, "|---" * (len(cols) + 1) + "|"]
    for r in results:
        na = {x["task"] for x in r.get("not_applicable", ())}
        marks = {x["cell"]: "ruled out" for x in r.get("infeasible", ())} | {
            x["cell"]: "no clip" for x in r.get("missing", ())
        }
        found = [(t, r["cells"].get(f"{t}@{s:g}", marks.get(f"{t}@{s:g}"))) for t, s in cols]
        lines.append(_row(r["label"], found, na, cell_text))
        if any(isinstance(c, dict) and "root_accuracy" in c for _, c in found):
            lines.append(_row(f"{r['label']}: R_acc", found, na, accuracy_text))
    return "\n".join(lines) + "\n"


def _row(label: str, found: list[tuple[str, dict | str | None]], na: set[str], text) -> str:
    """One markdown row: ``text(cell)`` per ``(task, cell)``, ``n/a`` for the tasks in ``na``, a cell's mark (a
    string) as it is, ``-`` for no cell."""
    cells = ["n/a" if t in na else "-" if c is None else c if isinstance(c, str) else text(c) for t, c in found]
    return f"| {label} | " + " | ".join(cells) + " |"


def accuracy_text(c: dict) -> str:
    """A cell's (or a chain length's) ``root_accuracy`` in %; ``-`` when it has none (written before R_acc)."""
    return f"{100 * c['root_accuracy']:.1f}" if "root_accuracy" in c else "-"


def cell_text(c: dict) -> str:
    """``mean (low-high)`` in %; a result written before the intervals: ``mean +- std``."""
    if "ci95" not in c:
        return f"{100 * c['mean']:.1f} +- {100 * c['std']:.1f}"
    low, high = c["ci95"]
    return f"{100 * c['mean']:.1f} ({100 * low:.0f}-{100 * high:.0f})"


def scale_note(corpus: str, cfg: EvalConfig, checkpoint: str | Path | None = None) -> dict:
    """What an evaluation is worth: the corpus, episodes per cell and seed, the seeds and, for a policy checkpoint,
    its training scale from the ``report.json`` of its run folder (``"unknown"`` without one). An intermediate
    checkpoint of the run (``policy_bc.pt``, ``policy_dagger<i>.pt``, a vision student's ``policy_distill<i>.pt``) gets
    its own iterations and windows from the run's log, not the finished run's."""
    note = {"corpus": corpus, "episodes_per_cell_and_seed": cfg.episodes, "seeds": list(cfg.seeds)}
    note |= {"protocol": cfg.protocol, "shape": cfg.shape}
    if checkpoint is not None:
        checkpoint = Path(checkpoint)
        report = checkpoint.parent / "report.json"
        scale = json.loads(report.read_text()).get("scale", "unknown") if report.is_file() else "unknown"
        step = re.fullmatch(r"policy_(bc|dagger(\d+))\.pt", checkpoint.name)
        if isinstance(scale, dict) and step:
            rows = read_log(checkpoint.parent)
            i = -1 if step.group(1) == "bc" else int(step.group(2))
            last = rows[i] if 0 <= i < len(rows) else {}
            scale = {
                **scale,
                "dagger_iterations": i + 1,
                "dagger_windows": last.get("aggregated_windows", 0),
                "dagger_last": last,
            }
        distilled = re.fullmatch(r"policy_distill(\d+)\.pt", checkpoint.name)
        if isinstance(scale, dict) and distilled:  # a vision student's intermediate checkpoint
            scale = distill_scale(scale, checkpoint.parent, int(distilled.group(1)))
        note["policy"] = {"checkpoint": str(checkpoint), "training_scale": scale}
        subset = read_subset(scale["corpus"]) if isinstance(scale, dict) and "corpus" in scale else None
        if subset is not None:  # trained on some variants of an augmented corpus: the others are held out
            note["policy"] |= {"trained_variants": subset["variants"], "held_out_variants": subset["held_out"]}
    return note


def distill_scale(scale: dict, run_dir: Path, i: int) -> dict:
    """A distillation's ``scale`` (:func:`train.vision.distill.report`) at its iteration ``i`` (from its log)."""
    from train.vision.distill import log_scale, read_log  # the vision stage only when a student is scored

    return {**scale, **log_scale(read_log(run_dir)[: i + 1])}


def scale_line(note: dict) -> str:
    """What the table's numbers are worth, in one line: the corpus, episodes, seeds and the policy's training scale."""
    line = (
        f"Scale: corpus `{note['corpus']}`, {note['episodes_per_cell_and_seed']} episodes per cell and seed, "
        f"seeds {', '.join(map(str, note['seeds']))}; success in % (Push: hand contact rate) over every episode of a "
        "cell, with its 95% interval in brackets (Wilson; Push: Student's t over episodes); R_acc: the share of "
        "control steps with the root within 0.6 m (horizontally) of the commanded root trajectory, the steps a fall "
        "cut off counting as off it, in % averaged over a cell's episodes; n/a: a task the actor does not attempt "
        "(why: eval.json)."
    )
    policy = note.get("policy")
    if policy:
        s = policy.get("training_scale")
        s = s if isinstance(s, dict) else {}
        of = f" of `{s['corpus']}`" if "corpus" in s else ""  # the training corpus (-Syn: another one)
        trained = (
            f"{s['corpus_episodes']} corpus episodes{of} ({s['corpus_frames']} frames), BC {s['bc_steps']} steps "
            f"({s['bc_samples']} samples), DAgger {s['dagger_iterations']} iterations x "
            f"{s['dagger_episodes_per_iteration']} episodes ({s['dagger_windows']} windows), on {s['device']}"
            if "corpus_episodes" in s
            else distilled_text(s)
            if "distill_iterations" in s
            else "unknown (no report.json beside it)"
        )
        post = s.get("post_training")
        if post:
            trained += (
                f", then post-trained {post['iterations']} PPO iterations ({post['env_steps']} env steps in "
                f"{post['envs']} envs, ablation {post['ablation']})"
            )
        line += f" Policy `{policy['checkpoint']}`, trained on {trained}."
        if "trained_variants" in policy:
            line += (
                f" Its corpus holds the object variants {', '.join(policy['trained_variants'])}; held out (never "
                f"trained on): {', '.join(policy['held_out_variants'])}."
            )
    protocol = note.get("protocol", "scaled")
    line += (
        " Protocol `matched`: each cell runs the corpus's episodes of the variant at its scale, made for that geometry."
        if protocol == "matched"
        else " Protocol `scaled` (the paper's): each cell runs the demonstrations with the object scaled."
    ) + (" Every box drawn as a circular cylinder." if note.get("shape") == "cylinder" else "")
    return line


def distilled_text(s: dict) -> str:
    """A vision student's training scale (:func:`train.vision.distill.report`), in words."""
    return (
        f"a distillation from `{s['teacher']}`: {s['distill_iterations']} DAgger iterations, {s['episodes']} episodes "
        f"({s['env_steps']} env steps), {s['windows']} windows, refits of {s['fit_steps_per_iteration']} x "
        f"{s['batch']}, latent alignment weight {s['align']:g}, on {s['device']}"
    )


def plot(results: list[dict], path: Path) -> None:
    """Success (Push: contact rate) against object scale, one panel per task, one line per result."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(TASKS), figsize=(4 * len(TASKS), 3.2), sharey=True)
    for ax, task in zip(axes, TASKS):
        for r in results:
            cells = [c for c in r["cells"].values() if c["task"] == task]
            if cells:
                x = [c["scale"] for c in cells]
                y = np.array([100 * c["mean"] for c in cells])
                bounds = np.array([[100 * v for v in c.get("ci95", (c["mean"], c["mean"]))] for c in cells])
                ax.errorbar(x, y, [y - bounds[:, 0], bounds[:, 1] - y], marker="o", capsize=2, label=r["label"])
        ax.set_title(task + (" (contact rate)" if task == "Push" else ""))
        ax.set_xlabel("object scale")
        ax.set_ylim(-5, 105)
    axes[0].set_ylabel("%")
    lines = {label: h for ax in axes for h, label in zip(*ax.get_legend_handles_labels())}  # a task may lack a row
    fig.legend(list(lines.values()), list(lines), fontsize=7, loc="lower right")
    fig.tight_layout()
    save_figure(fig, path, dpi=100)


def write(results: list[dict], out_dir: Path, scale_note: dict) -> Path:
    """``eval.json`` (every result with ``scale_note``: what was scored, at what training scale), ``eval.md``
    (the table) and ``eval.png`` in ``out_dir``."""
    out_dir = Path(out_dir)
    write_json_atomic(out_dir / "eval.json", {"scale": scale_note, "results": results})
    write_bytes_atomic(out_dir / "eval.md", (scale_line(scale_note) + "\n\n" + markdown(results)).encode())
    plot(results, out_dir / "eval.png")
    return out_dir / "eval.json"
