"""Long-horizon task chains (paper Sec. IV-C, Table 3): ``N`` tasks in random order in one episode, without resets.

A chain is ``N`` corpus episodes, each task drawn uniformly from the tasks the corpus has and then one of its
episodes. The robot starts the first at its recorded first state; when a task's episode ends (its reference's last
frame), the next one is moved rigidly in the plane (:func:`relocated`) so that its first root pose is where the
robot stands and the way it faces, its object is placed there, and the robot goes on from its own state (joint
angles, velocities, previous action; the policy's observation history runs on, its newest step re-observed in the
new scene). The chain succeeds when every task succeeds by its own rule (:class:`train.mdp.tasks.TaskMeter`), the robot
never falls and its root never strays more than :attr:`ChainConfig.tolerance_m` (0.6 m, the paper's) from the
commanded root trajectory at any step. A result per chain length: the success rate over the chains of an
evaluation seed, mean and std over the seeds, and the mean number of tasks completed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from pipeline.rotations import rotation_from_wxyz, xyzw_to_wxyz
from pipeline.stage.atomic import write_bytes_atomic, write_json_atomic
from pipeline.terms.observations import heading_yaw
from train.envs.cpu.env import InteractionEnv
from train.episodes import Episode
from train.evaluation.table2 import cell_text, interval95

CHAIN_LENGTHS = (5, 10, 15, 25, 40)
ENDINGS = ("completed", "fell", "strayed", "task_failed")


@dataclass(frozen=True)
class ChainConfig:
    lengths: tuple[int, ...] = (5, 10)
    seeds: tuple[int, ...] = (0, 1, 2)
    chains: int = 4  # per length and seed
    envs: int = 8
    tolerance_m: float = 0.6


def _yaw(qpos: np.ndarray) -> float:
    return float(heading_yaw(np.asarray(qpos, dtype=float)[None, :7])[0])


def _moved(pose: np.ndarray, turn: Rotation, shift: np.ndarray) -> np.ndarray:
    """Poses ``(T, 7+)`` (x y z qw qx qy qz ...) turned about z by ``turn`` and shifted in the plane by ``shift``."""
    out = np.array(pose, dtype=float)
    flat = np.column_stack([out[:, :2], np.zeros(len(out))])
    out[:, :2] = turn.apply(flat)[:, :2] + shift  # heights unchanged
    out[:, 3:7] = xyzw_to_wxyz((turn * rotation_from_wxyz(out[:, 3:7])).as_quat())
    return out


def relocated(e: Episode, x: float, y: float, yaw: float) -> Episode:
    """``e`` moved rigidly in the plane so that its first root position is ``(x, y)`` and its heading ``yaw``:
    the robot's and the objects' poses, the world-frame linear velocities, the reference; body-frame quantities
    (joint angles, angular velocities, actions, torques) are unchanged."""
    sim = e.simulated
    q0 = sim.robot.qpos[0]
    turn = Rotation.from_euler("z", yaw - _yaw(q0))
    shift = np.array([x, y]) - turn.apply([q0[0], q0[1], 0.0])[:2]

    def robot(clip):
        objects = tuple(replace(o, pose=_moved(o.pose, turn, shift)) for o in clip.objects)
        return replace(clip, qpos=_moved(clip.qpos, turn, shift), objects=objects)

    qvel = np.array(sim.qvel, dtype=float)
    qvel[:, :3] = turn.apply(qvel[:, :3])
    object_vel = tuple(np.concatenate([turn.apply(v[:, :3]), v[:, 3:]], axis=1) for v in sim.object_vel)
    moved = replace(
        sim,
        robot=robot(sim.robot),
        qvel=qvel,
        object_vel=object_vel,
        reference_qpos=_moved(sim.reference_qpos, turn, shift),
    )
    return replace(e, simulated=moved, reference=robot(e.reference))


def _switch(env: InteractionEnv, actor, i: int, nxt: Episode) -> None:
    """Environment ``i`` goes on with episode ``nxt``, relocated to where its robot stands, from the robot's state."""
    old = env.slots[i]
    q, v, last = old.data.qpos[:36].copy(), old.data.qvel[:35].copy(), old.last_action.copy()
    env.reset_one(i, relocated(nxt, q[0], q[1], _yaw(q)), 1.0)
    slot = env.slots[i]
    slot.set_state(q, v)
    slot.last_action = last
    fresh = env.observe()
    for key, value in vars(fresh).items():
        actor.history.terms[key][i, -1] = value[i]


def run_chains(actor, chains: list[list[Episode]], cfg: ChainConfig) -> list[dict]:
    """Run ``chains`` side by side with ``actor`` (a :class:`train.actors.PolicyActor`); per chain: ``success``,
    ``tasks_completed`` and why it ended (``fell``, ``strayed``, ``task_failed``)."""
    env = InteractionEnv(actor.env_config())
    env.reset([(c[0], 1.0) for c in chains])
    actor.reset(env)
    stage, result = [0] * len(chains), [None] * len(chains)
    while any(r is None for r in result):
        obs, done = env.step(actor.act(env))
        actor.observe(obs)
        for i, s in enumerate(env.slots):
            if result[i] is not None:
                continue
            sim = s.episode.simulated
            ref = sim.robot.qpos[min(s.t, sim.frames - 1), :2]
            end = None
            if s.fell:
                end = "fell"
            elif np.linalg.norm(s.data.qpos[:2] - ref) > cfg.tolerance_m:
                end = "strayed"
            elif done[i] and not s.meter.success:
                end = "task_failed"
            elif done[i] and stage[i] + 1 == len(chains[i]):
                end = "completed"
            elif done[i]:
                stage[i] += 1
                _switch(env, actor, i, chains[i][stage[i]])
            if end is not None:
                s.done = True  # stands still from now on
                completed = stage[i] + (end == "completed")
                result[i] = {"success": end == "completed", "tasks_completed": completed, "ended": end}
    env.close()
    return result


def evaluate_chains(actor, episodes: list[Episode], cfg: ChainConfig = ChainConfig(), label: str = "") -> dict:
    """Table 3 of ``actor`` on the corpus ``episodes`` (module docstring), per chain length."""
    by_task: dict[str, list[Episode]] = {}
    for e in episodes:
        by_task.setdefault(e.task, []).append(e)
    tasks = sorted(by_task)
    out = {"label": label, "config": asdict(cfg), "lengths": {}}
    for n in tqdm(cfg.lengths, desc=f"chains {label}", unit="length"):
        per_seed, outcomes = [], []
        for seed in cfg.seeds:
            rng = np.random.default_rng([seed, n, 31])
            chains = []
            for _ in range(cfg.chains):
                picks = [tasks[k] for k in rng.integers(len(tasks), size=n)]
                chains.append([by_task[t][rng.integers(len(by_task[t]))] for t in picks])
            runs = []
            for k in range(0, len(chains), cfg.envs):
                runs += run_chains(actor, chains[k : k + cfg.envs], cfg)
            per_seed.append(float(np.mean([r["success"] for r in runs])))
            outcomes += runs
        out["lengths"][str(n)] = {
            "mean": float(np.mean(per_seed)),
            "ci95": list(interval95([r["success"] for r in outcomes], binary=True)),
            "std": float(np.std(per_seed)),
            "per_seed": per_seed,
            "chains_per_seed": cfg.chains,
            "seeds": list(cfg.seeds),
            "mean_tasks_completed": float(np.mean([r["tasks_completed"] for r in outcomes])),
            "ended": {k: sum(r["ended"] == k for r in outcomes) for k in ENDINGS},
        }
    return out


def markdown(result: dict) -> str:
    """Table 3's layout: success (%) per chain length with its 95% interval, and the tasks completed."""
    lengths = list(result["lengths"])
    lines = [
        "| | " + " | ".join(f"N = {n}" for n in lengths) + " |",
        "|---" * (len(lengths) + 1) + "|",
        f"| {result['label']} | "
        + " | ".join(f"{cell_text(c)}, {c['mean_tasks_completed']:.1f} tasks" for c in result["lengths"].values())
        + " |",
    ]
    return "\n".join(lines) + "\n"


def write(result: dict, out_dir: Path, scale_note: dict) -> Path:
    """``chains.json`` (the result with ``scale_note``) and ``chains.md`` (the table) in ``out_dir``."""
    out_dir = Path(out_dir)
    c = result["config"]
    line = f"Chains: {c['chains']} per length and seed, seeds {', '.join(map(str, c['seeds']))}, scale 1.0."
    write_json_atomic(out_dir / "chains.json", {"scale": scale_note, "result": result})
    write_bytes_atomic(out_dir / "chains.md", (line + "\n\n" + markdown(result)).encode())
    return out_dir / "chains.json"
