"""``lessmimic train-bc``, ``train-aip``, ``export`` and ``eval``: the training commands (:mod:`train`);
the rest of the command line is :mod:`lessmimic.cli`, which registers these with :func:`add_train`."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from lessmimic.eval_commands import add_eval, check_corpus
from pipeline.errors import InputError


def _cmd_train_bc(a: argparse.Namespace) -> int:
    import torch

    from train.ablation import ablated
    from train.config import TrainConfig
    from train.run import train

    torch.set_num_threads(a.threads)
    ab = ablated(a.name, a.run, a.ablation, "pre", a.backbone)
    cfg = TrainConfig(
        name=ab.corpus,
        backbone=ab.backbone,
        vae_steps=a.vae_steps,
        bc_steps=a.bc_steps,
        dagger_iterations=a.dagger_iterations,
        dagger_episodes=a.dagger_episodes,
        dagger_probe=a.dagger_probe,
        dagger_fit_steps=a.dagger_fit_steps,
        envs=a.envs,
        select_episodes=a.select_episodes,
        seed=a.seed,
        device=a.device,
        contract=a.contract,
    )
    report = train(cfg, ab.run, overwrite=a.overwrite)
    scale, last = report["scale"], report["scale"].get("dagger_last", {})
    rmse, success = last.get("action_rmse", float("nan")), last.get("success", float("nan"))
    print(
        f"trained {report['policy']} in {report['seconds'] / 60:.1f} min: {scale['corpus_episodes']} corpus episodes "
        f"({scale['corpus_frames']} frames), BC {scale['bc_steps']} steps x {cfg.batch}, DAgger "
        f"{scale['dagger_iterations']} iterations ({scale['dagger_windows']} windows); last on-policy action RMSE "
        f"{rmse:.3f} rad, rollout success {success:.2f}; policy.pt is {scale['chosen_checkpoint']}"
    )
    return 0


def _cmd_export(a: argparse.Namespace) -> int:
    import torch

    torch.set_num_threads(a.threads)
    if a.viewer_site is not None and a.format != "lessmimic-demo":
        raise InputError(a.viewer_site, "--viewer-site", "only with --format lessmimic-demo (the viewer's files)")
    if a.format == "lessmimic-demo":
        from train.export.demo import DEMO_FILES, export_demo

        out = export_demo(a.policy, a.out, overwrite=a.overwrite, viewer_site=a.viewer_site)
        sizes = ", ".join(f"{f} {(out / f).stat().st_size / 1e6:.2f} MB" for f in DEMO_FILES)
        print(f"exported {a.policy} in the released demo's contract -> {out}/ ({sizes})")
        if a.viewer_site is not None:  # what the viewer's page fetches, resolved as it resolves it
            from train.export.viewer_site import site_report

            config = json.loads((out / DEMO_FILES[0]).read_text())
            print("\n".join(f"  {line}" for line in site_report(a.viewer_site, config)))
        return 0
    from train.export.onnx_policy import CHECK_BATCH, export_onnx

    r = export_onnx(a.policy, a.out, overwrite=a.overwrite)
    print(
        f"exported {a.policy} -> {r.path} ({r.bytes / 1e6:.2f} MB) in {r.seconds:.1f} s; onnxruntime vs torch "
        f"{r.check_max_abs:.1e} rad at most on {CHECK_BATCH} observations drawn around the normalisers' statistics"
    )
    return 0


def _cmd_distill(a: argparse.Namespace) -> int:
    import torch

    from train.episodes import load_episodes
    from train.export.metadata import sha256
    from train.policy import load_policy
    from train.vision.distill import DistillConfig, distill, distill_randomization, with_overrides

    torch.set_num_threads(a.threads)
    teacher = load_policy(a.teacher)
    check_corpus(teacher, a.teacher, a.name)
    cfg = with_overrides(
        DistillConfig(),
        iterations=a.iterations,
        episodes=a.episodes,
        probe=a.probe,
        envs=a.envs,
        fit_steps=a.fit_steps,
        align=a.align,
        seed=a.seed,
    )
    if a.randomization != "narrow":
        from dataclasses import replace

        cfg = replace(cfg, randomization=distill_randomization(a.randomization))
    source = {"path": str(a.teacher), "sha256": sha256(a.teacher), "corpus": a.name}
    distill(teacher, source, load_episodes(a.name), a.run, cfg, overwrite=a.overwrite)
    report = json.loads((Path(a.run) / "report.json").read_text())
    scale, last = report["scale"], report["last"]
    print(
        f"distilled {report['policy']} from {a.teacher} in {report['seconds'] / 60:.1f} min: "
        f"{scale['distill_iterations']} iterations, {scale['episodes']} episodes, {scale['env_steps']} env steps, "
        f"{scale['windows']} windows; last probe: success {last['student']['success']:.2f}, action RMSE "
        f"{last['student']['action_rmse']:.3f} rad, R_acc {last['student']['root_accuracy']:.2f}"
    )
    return 0


def _cmd_train_aip(a: argparse.Namespace) -> int:
    import torch

    from train.ablation import PRE_TRAINING, ablated
    from train.aip import PostTrainConfig, post_train
    from train.envs.config import PostEnvConfig

    torch.set_num_threads(a.threads)
    ab = ablated(a.name, a.run, a.ablation, "post")
    mjlab = a.backend == "mjlab"
    d = PostTrainConfig()
    cfg = PostTrainConfig(
        iterations=d.iterations if a.iterations is None else a.iterations,
        steps_per_env=d.steps_per_env if a.steps_per_env is None else a.steps_per_env,
        env=PostEnvConfig(envs=a.envs or (4096 if mjlab else PostEnvConfig().envs), threads=a.env_threads),
        ablation=ab.post,
        seed=a.seed,
        backend=a.backend,
    )
    policy = ab.run / "policy.pt"
    if not policy.is_file():
        make = "make train-bc" + (f" ABLATION={a.ablation}" if a.ablation in PRE_TRAINING else "")
        raise InputError(policy, "policy.pt", f"no BC + DAgger policy here: run `{make}` first")
    out = ab.post_dir.with_name(ab.post_dir.name + "-mjlab") if mjlab else ab.post_dir  # a GPU run beside the CPU's
    device = a.device or ("cuda" if mjlab else "cpu")
    if mjlab:
        from train.envs.mjlab.env import check_device

        check_device(device)
    row = post_train(ab.corpus, policy, out, cfg, device=device)
    print(
        f"post-trained {out / 'policy.pt'}: {row.get('iteration', -1) + 1} PPO iterations, {row.get('env_steps', 0)} "
        f"env steps; last task reward {row.get('task_reward', float('nan')):.3f}, AIP reward "
        f"{row.get('aip_reward', float('nan')):.3f}, AMP reward {row.get('amp_reward', float('nan')):.3f}"
    )
    return 0


def add_train(sub) -> None:
    p = sub.add_parser(
        "train-bc",
        help="pre-train the interaction policy: the DF VAE, behaviour cloning on the corpus's features, DAgger from "
        "the QP teacher (runs/<RUN>/)",
    )
    p.add_argument("--name", default="corpus", help="the corpus: datasets/<NAME>/ (default corpus: `make corpus`)")
    p.add_argument("--run", default="runs/bc", help="the run folder (default runs/bc); a rerun resumes")
    p.add_argument("--overwrite", action="store_true", help="start the run afresh")
    p.add_argument("--backbone", choices=("transformer", "mlp"), default="transformer", help="policy backbone")
    p.add_argument(
        "--ablation",
        default="",
        help="-Syn (on datasets/<NAME>-syn/, into <RUN>-Syn) or -Trans (MLP, into <RUN>-Trans): train.ablation",
    )
    from train.config import TrainConfig  # the defaults: the laptop scale

    d = TrainConfig()
    p.add_argument("--vae-steps", type=int, default=d.vae_steps)
    p.add_argument("--bc-steps", type=int, default=d.bc_steps, help=f"behaviour-cloning steps (batch {d.batch})")
    p.add_argument("--dagger-iterations", type=int, default=d.dagger_iterations)
    p.add_argument(
        "--dagger-episodes", type=int, default=d.dagger_episodes, help="episodes per DAgger iteration (beta-mixture)"
    )
    p.add_argument("--dagger-probe", type=int, default=d.dagger_probe, help="student-only episodes per iteration")
    p.add_argument("--dagger-fit-steps", type=int, default=d.dagger_fit_steps)
    p.add_argument("--envs", type=int, default=d.envs, help="environments stepped together")
    p.add_argument(
        "--select-episodes",
        type=int,
        default=d.select_episodes,
        help="validation rollouts per task and candidate that choose policy.pt (default 0: the last candidate, "
        "the mean of the last three iterations' weights)",
    )
    p.add_argument(
        "--contract",
        default="lessmimic",
        choices=("lessmimic", "lessmimic_demo"),
        help="the observation contract (default lessmimic, the paper's); lessmimic_demo: the released web demo's "
        "(its 7 bodies' 4-part DF, unit latents, the command with its task condition), for `lessmimic export "
        "--format lessmimic-demo`; train it on a corpus physicalized with PROFILE=lessmimic_demo",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="cpu", help="torch device (cpu, cuda)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (1 is fastest on a loaded 2-core machine)")
    p.set_defaults(func=_cmd_train_bc)
    p = sub.add_parser(
        "train-aip",
        help="post-train a run's BC + DAgger policy: PPO with the AIP and AMP style priors (runs/<RUN>/aip<ABLATION>/)",
    )
    p.add_argument("--name", default="corpus", help="the corpus (its valid episodes and its reference buffers)")
    p.add_argument("--run", default="runs/bc", help="the BC + DAgger run folder (its policy.pt); a rerun resumes")
    p.add_argument(
        "--ablation",
        default="",
        help="-AIP (no interaction prior), -Rand (no randomisation), or -Syn / -Trans (post-train <RUN>-Syn / "
        "<RUN>-Trans, -Syn on datasets/<NAME>-syn/): train.ablation",
    )
    # defaults from train.aip.PostTrainConfig when the command runs (importing it here costs every command ~5 s)
    p.add_argument("--iterations", type=int, default=None, help="PPO iterations (default: the laptop scale, 600)")
    p.add_argument("--steps-per-env", type=int, default=None, help="rollout steps per env and iteration (default 24)")
    p.add_argument("--envs", type=int, default=None, help="environments stepped together (default: cpu 8, mjlab 4096)")
    p.add_argument("--env-threads", type=int, default=1, help="threads stepping the environments")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--backend", default="cpu", help="cpu (native MuJoCo) or mjlab (MuJoCo Warp on a GPU)")
    p.add_argument("--device", default=None, help="torch device (cpu; cuda for --backend mjlab)")
    p.add_argument("--threads", type=int, default=1, help="torch threads")
    p.set_defaults(func=_cmd_train_aip)
    p = sub.add_parser(
        "distill",
        help="distil a MoCap-DF policy (pi_full) into a vision student on egocentric depth: DAgger under the "
        "physical and perceptual randomisations (runs/<RUN>/)",
    )
    p.add_argument("--name", default="corpus", help="the corpus whose episodes are rolled out (default corpus)")
    p.add_argument("--teacher", required=True, help="pi_full: a policy checkpoint (runs/<RUN>/policy.pt, .../aip/...)")
    p.add_argument("--run", default="runs/vision", help="the run folder (default runs/vision); a rerun resumes")
    p.add_argument("--overwrite", action="store_true", help="start the run afresh")
    p.add_argument("--iterations", type=int, default=None, help="DAgger iterations (default 12)")
    p.add_argument("--episodes", type=int, default=None, help="mixture episodes per iteration (default 16)")
    p.add_argument("--probe", type=int, default=None, help="student-only episodes per iteration (default 8)")
    p.add_argument("--envs", type=int, default=None, help="environments stepped together (default 8)")
    p.add_argument("--fit-steps", type=int, default=None, help="Adam steps per refit (default 800)")
    p.add_argument(
        "--align",
        type=float,
        default=None,
        help="weight of the latent alignment loss (default 0: the paper's Eq. 8, actions only; > 0: the ablation)",
    )
    p.add_argument(
        "--randomization",
        default="narrow",
        choices=("narrow", "full", "off"),
        help="the physical randomisations: narrow (default: post-training's six, object scale 0.9-1.1, boxes kept), "
        "full (post-training's: scales 0.4-1.6, cylinders; for a post-trained teacher), off (the sensor's only)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1)
    p.set_defaults(func=_cmd_distill)
    p = sub.add_parser(
        "export", help="a trained policy (runs/<RUN>/policy.pt, any interaction policy) as ONNX with its metadata"
    )
    p.add_argument("--policy", required=True, help="the checkpoint (runs/<RUN>/policy.pt, runs/<RUN>/aip/policy.pt)")
    p.add_argument(
        "--format",
        default="onnx",
        choices=("onnx", "lessmimic-demo"),
        help="onnx: one file with its metadata (default); lessmimic-demo: the released web demo's three files, for a "
        "policy trained with --contract lessmimic_demo",
    )
    p.add_argument(
        "--out", default=None, help="the ONNX file (default: beside the checkpoint, .onnx; lessmimic-demo: a folder)"
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing export")
    p.add_argument(
        "--viewer-site",
        default=None,
        help="lessmimic-demo: the viewer's site folder (holding its index.html); the files go where its page fetches "
        "them, DIR/examples/checkpoints/g1/ (the released JSON there needs --overwrite)",
    )
    p.add_argument("--threads", type=int, default=1)
    p.set_defaults(func=_cmd_export)
    add_eval(sub)
