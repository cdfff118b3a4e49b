"""A training run (``lessmimic train-bc``): one folder ``runs/<RUN>/`` holding its config, checkpoints and logs.

1. the DF-latent VAE and behaviour cloning on the corpus's features dataset (:func:`train.bc.train_bc`):
   ``vae.pt``, ``bc_log.jsonl``, ``bc_report.json``, ``policy_bc.pt``;
2. DAgger from the QP teacher in the interaction environment (:func:`train.dagger.dagger`):
   ``dagger_log.jsonl``, ``policy_dagger<i>.pt``, ``dagger_data.pt``;
3. ``policy.pt``: the run's policy, the mean of the last three DAgger iterations' weights, or of the three whose
   student does best on its worst task in validation rollouts (``select_episodes`` > 0;
   :mod:`train.evaluation.select`: ``validation.jsonl``, ``selection.json``), and ``report.json``
   (written last) with the run's scale: corpus episodes and frames, BC steps and samples, DAgger iterations and
   windows, the chosen checkpoint, seconds.

A rerun with the same config resumes: finished parts are kept (the VAE, the BC policy, finished DAgger
iterations). A rerun asking only for more DAgger iterations continues the run (iteration ``i`` depends on the
iterations before it and never on their number, so the result is the longer run's); any other config over an
existing run folder stops with one line asking for ``--overwrite``.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict
from pathlib import Path

from pipeline.errors import InputError
from pipeline.stage.atomic import write_json_atomic
from pipeline.stage.paths import stage_dir
from train.bc import BCConfig, WindowTensors, train_bc
from train.config import TrainConfig
from train.dagger import DAggerConfig, dagger, read_log
from train.episodes import load_episodes
from train.evaluation.select import SelectConfig, choose
from train.policy import PolicyConfig, load_policy, save_policy
from train.vae import VAEConfig, split_episodes


def _claim(run_dir: Path, config: TrainConfig, overwrite: bool) -> None:
    """``run_dir`` holds this config's run (or none) or a shorter DAgger run of it; a run of other settings there is
    a one-line error."""
    settings, path = asdict(config), run_dir / "config.json"
    if overwrite and run_dir.exists():
        shutil.rmtree(run_dir)
    if path.is_file():
        recorded = {**asdict(TrainConfig()), **json.loads(path.read_text())}  # a setting added since: its default
        diff = sorted(k for k in settings if recorded.get(k) != settings[k])
        longer = diff == ["dagger_iterations"] and settings["dagger_iterations"] > recorded["dagger_iterations"]
        if diff and not longer and diff != ["select_episodes"]:  # another choice of checkpoint: the same training
            msg = f"a run with other settings ({', '.join(diff)}) is here; pass --overwrite"
            raise InputError(run_dir, "config", msg)
    write_json_atomic(path, settings)


def train(config: TrainConfig, run_dir: str | Path, *, overwrite: bool = False) -> dict:
    """The run (module docstring); its report."""
    run_dir = Path(run_dir)
    features = stage_dir(config.name, "features")
    if not (features / "meta" / "info.json").is_file():
        raise InputError(
            features, "meta/info.json", "no features dataset here: run `make corpus` (or the three stages) first"
        )
    episodes = load_episodes(config.name, valid_only=False)  # the features dataset's episodes, in its order
    _claim(run_dir, config, overwrite)
    policy_config = PolicyConfig(backbone=config.backbone, history=config.history)
    bc = BCConfig(steps=config.bc_steps, batch=config.batch, seed=config.seed)
    if not (run_dir / "policy_bc.pt").is_file():
        report = train_bc(
            features,
            run_dir,
            bc,
            policy_config,
            VAEConfig(),
            vae_steps=config.vae_steps,
            device=config.device,
            contract=config.contract,
        )
        save_policy(
            load_policy(run_dir / "policy.pt", device=config.device), run_dir / "policy_bc.pt", bc_report=report
        )
    policy = load_policy(run_dir / "policy_bc.pt", device=config.device)
    train_eps, held = split_episodes(len(episodes), bc.holdout)
    data = WindowTensors.from_dataset(features, config.history, train_eps, policy.layout)
    heldout = WindowTensors.from_dataset(features, config.history, held, policy.layout) if held else None
    dagger_config = DAggerConfig(
        iterations=config.dagger_iterations,
        episodes=config.dagger_episodes,
        probe=config.dagger_probe,
        envs=config.envs,
        fit_steps=config.dagger_fit_steps,
        seed=config.seed,
    )

    def valid(indices: list[int]) -> list:
        return [episodes[i] for i in indices if episodes[i].simulated.validation.get("valid", False)]

    train_valid = valid(train_eps)
    dagger(policy, data, train_valid, run_dir, dagger_config, bc, heldout)
    select = SelectConfig(episodes=config.select_episodes, envs=config.envs)
    chosen = choose(run_dir, valid(held), train_valid, select)["chosen"]
    rows = read_log(run_dir)
    last = rows[-1] if rows else {}
    bc_seconds = json.loads((run_dir / "bc_report.json").read_text()).get("seconds", 0.0)
    report = {
        "config": asdict(config),
        "scale": {
            "corpus": config.name,
            "corpus_episodes": len(episodes),
            "corpus_frames": sum(e.frames for e in episodes),
            "bc_steps": config.bc_steps,
            "bc_samples": config.bc_steps * config.batch,
            "dagger_iterations": config.dagger_iterations,
            "dagger_episodes_per_iteration": config.dagger_episodes,
            "dagger_windows": last.get("aggregated_windows", 0),
            "dagger_last": last,
            "chosen_checkpoint": chosen,
            "device": config.device,
        },
        "policy": str(run_dir / "policy.pt"),
        "seconds": bc_seconds + sum(r.get("seconds", 0.0) for r in rows),  # summed over resumed parts
    }
    write_json_atomic(run_dir / "report.json", report)
    return report
