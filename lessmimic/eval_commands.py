"""``lessmimic eval``: the paper's Table 2 cells and Table 3 chains of a policy, its ONNX export or the QP teacher,
kept apart from the training commands of :mod:`lessmimic.train_commands`."""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import InputError


def check_corpus(policy, path: str, name: str) -> None:
    """A one-line error unless ``policy`` reads the corpus ``name``'s DF links (of its contract) and acts for its
    actuator profile."""
    from pipeline.stage.paths import stage_dir
    from train.policy import dataset_layout

    want = dataset_layout(stage_dir(name, "features"), policy.layout.history, policy.layout.contract)
    if bad := policy.layout.mismatch({"links": want.links, "actuator_profile": want.actuator_profile}):
        raise InputError(path, *bad)


def _load_scored(path: str):
    """The policy an evaluation scores: a checkpoint (MoCap-DF or vision) or its ONNX export (onnxruntime)."""
    if Path(path).suffix == ".onnx":  # an exported file, run by onnxruntime in the same harness
        from train.export.runtime import OnnxPolicy

        return OnnxPolicy(path)
    from train.export.onnx_policy import load_any_policy

    return load_any_policy(path)


def _kind(policy) -> str:
    return "vision" if getattr(policy, "camera", None) is not None else "policy"


def _actor(policy, clean_depth: bool):
    """The evaluation's actor of ``policy``: a vision student's sees its camera through the training sensor model
    (:class:`train.vision.noise.DepthNoise`) unless ``clean_depth``."""
    from train.actors import PolicyActor

    if getattr(policy, "camera", None) is None:
        return PolicyActor(policy)
    from train.vision.actor import VisionActor
    from train.vision.noise import DepthNoise

    return VisionActor(policy, DepthNoise.off() if clean_depth else DepthNoise(), seed=0)


def _cmd_eval(a: argparse.Namespace) -> int:
    from dataclasses import replace

    import torch

    from train.actors import PolicyActor, TeacherActor
    from train.episodes import load_episodes
    from train.evaluation.table2 import EvalConfig, evaluate, markdown, scale_note, write
    from train.policy import load_policy

    torch.set_num_threads(a.threads)
    episodes = load_episodes(a.name)
    cfg = EvalConfig(
        seeds=tuple(int(s) for s in a.seeds.split(",")),
        episodes=a.episodes,
        envs=a.envs,
        protocol=a.protocol,
        shape=a.shape,
    )
    tag = (
        ""
        if (a.protocol, a.shape) == ("scaled", "box")
        else f" [{a.protocol}{', cylinder' if a.shape != 'box' else ''}]"
    )
    if a.scales:
        cfg = replace(cfg, scales=tuple(float(x) for x in a.scales.split(",")))
    results, scored = [], []  # scored: (actor, label) of the policies whose chains run too
    if a.policy:
        policy = _load_scored(a.policy)
        check_corpus(policy, a.policy, a.name)
        scored.append((_actor(policy, a.clean_depth), f"{_kind(policy)} ({Path(a.policy).parent.name}){tag}"))
        teacher = getattr(policy, "teacher", None) or getattr(policy, "metadata", {}).get("teacher")
        if teacher and Path(teacher["path"]).is_file():  # a vision student: its MoCap teacher in the same run
            label = f"MoCap teacher ({Path(teacher['path']).parent.name}){tag}"
            scored.append((PolicyActor(load_policy(teacher["path"])), label))
        results += [evaluate(actor, episodes, cfg, label, corpus=a.name) for actor, label in scored]
    if a.teacher:
        reference = "scale-matched reference" if a.protocol == "matched" else "1.0x reference"
        results.append(evaluate(TeacherActor(), episodes, cfg, f"QP teacher, {reference}{tag}", corpus=a.name))
    if a.demo_loop:  # the released viewer's loop, replicated, on the export in its contract (train/export/demo_loop.py)
        from train.export.demo_loop import evaluate_demo_loop

        cells = {
            f"{task}@1": evaluate_demo_loop(a.demo_loop, episodes, task, cfg.seeds, cfg.episodes)
            for task in a.demo_tasks.split(",")
        }
        results.append({"label": f"viewer-loop replica ({Path(a.demo_loop).name})", "cells": cells})
    if not results:
        raise InputError(None, "--policy", "nothing to evaluate: pass --policy, --teacher and/or --demo-loop")
    out = Path(a.out) if a.out else (Path(a.policy).parent / "eval" if a.policy else Path("runs") / "eval")
    note = scale_note(a.name, cfg, a.policy)
    print(write(results, out, note))
    print(markdown(results))
    if a.chains:
        _eval_chains(a, episodes, cfg, scored, out, note)
    return 0


def _eval_chains(a: argparse.Namespace, episodes, cfg, scored: list, out: Path, note: dict) -> None:
    """Table 3: the scored policies' chains (a vision student's MoCap teacher drawn from the student's tasks), then
    the QP teacher's (``--teacher``: its ceiling, each task tracking its own reference) in ``out/qp_teacher``."""
    from train.actors import TeacherActor
    from train.evaluation import chains

    lengths = tuple(int(n) for n in a.chains.split(","))
    ccfg = chains.ChainConfig(lengths=lengths, seeds=cfg.seeds, chains=a.chains_per_seed, envs=a.envs)
    excluded = getattr(scored[0][0], "excluded_tasks", ()) if scored else ()
    for k, (actor, label) in enumerate(scored):  # the MoCap teacher's chains beside its student's
        if k and excluded:  # drawn from the student's tasks, so the two rows compare the same chains
            actor.excluded_tasks = excluded
            actor.excluded_reason = "left out of the chains to match its vision student's"
        result = chains.evaluate_chains(actor, episodes, ccfg, label)
        print(chains.write(result, out if k == 0 else out / "teacher", note))
        print(chains.markdown(result))
    if a.teacher:
        result = chains.evaluate_chains(TeacherActor(), episodes, ccfg, "QP teacher, each task's reference")
        print(chains.write(result, out / "qp_teacher", note))
        print(chains.markdown(result))


def add_eval(sub) -> None:
    p = sub.add_parser("eval", help="the paper's Table 2 evaluation of a policy and/or the QP teacher baseline")
    p.add_argument(
        "--policy",
        default=None,
        help="a policy checkpoint (runs/<RUN>/policy.pt) or its ONNX export (.onnx); a vision student's is scored "
        "with its MoCap teacher in the same run",
    )
    p.add_argument(
        "--teacher",
        action="store_true",
        help="also score the QP teacher tracking the 1.0x reference (--protocol matched: the scale-matched one)",
    )
    p.add_argument(
        "--demo-loop",
        default=None,
        help="also score a `lessmimic export --format lessmimic-demo` folder in the replica of the released viewer's "
        "loop (its 2 ms physics, PD law and voxel-grid distance field) at scale 1.0",
    )
    p.add_argument("--demo-tasks", default="PickUp", help="the tasks of --demo-loop (default PickUp)")
    p.add_argument("--name", default="corpus", help="the corpus whose episodes are evaluated (default corpus)")
    p.add_argument("--seeds", default="0,1,2", help="evaluation seeds (default 0,1,2)")
    p.add_argument(
        "--episodes",
        type=int,
        default=16,
        help="episodes per cell and seed (default 16: a cell's 95%% interval ~+-10-13)",
    )
    p.add_argument("--envs", type=int, default=8)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument(
        "--chains", default="", help="also the long-horizon chains of the policy (Table 3), e.g. 5,10 (lengths)"
    )
    p.add_argument("--chains-per-seed", type=int, default=4, help="chains per length and seed (default 4)")
    p.add_argument("--out", default=None, help="output folder (default: the policy's run folder /eval)")
    p.add_argument("--scales", default="", help="only these object scales of Table 2, e.g. 1.0 (default: all)")
    p.add_argument(
        "--protocol",
        default="scaled",
        choices=("scaled", "matched"),
        help="scaled (the paper's): the demonstrations with the object scaled; matched: an augmented corpus's "
        "variant made for each cell's scale (the QP teacher then tracks a scale-matched reference)",
    )
    p.add_argument("--shape", default="box", choices=("box", "cylinder"), help="cylinder: every box as a cylinder")
    p.add_argument("--clean-depth", action="store_true", help="a vision policy's camera without the sensor noise model")
    p.set_defaults(func=_cmd_eval)
