"""Long-horizon task chains (paper Sec. IV-C, Table 3): ``N`` tasks in random order in one episode, without resets.

A chain is ``N`` corpus episodes, each task drawn uniformly from the tasks the corpus has and then one of its
episodes. The robot starts the first at its recorded first state; when a task's episode ends (its reference's last
frame), the next one is moved rigidly in the plane (:func:`relocated`) so that its first root pose is where the
robot stands and the way it faces, its object is placed there, and the robot goes on from its own state (joint
angles, velocities, previous action; the policy's observation history runs on, its newest step re-observed in the
new scene). The chain succeeds when every task succeeds by its own rule (:class:`train.mdp.tasks.TaskMeter`), the robot
never falls and its root never strays more than :attr:`ChainConfig.tolerance_m` (0.6 m, the paper's) from the
commanded root trajectory at any step. A result per chain length: the success rate over the chains of an
evaluation seed, mean and std over the seeds, the mean number of tasks completed and the mean ``R_acc``.

``R_acc`` of a chain (:func:`run_chains`): the share of all its control steps, over every task, with the root within
0.6 m of the commanded root trajectory (:attr:`train.mdp.tasks.TaskMeter.root_accuracy`, per step the relocated
episode's reference root, :meth:`train.envs.cpu.env.EnvSlot.facts`), over the chain's full length (the sum of its
episodes' lengths): the steps after the chain ended early (a fall, a stray, a failed task) count as off the track.

The tasks are drawn from those of the corpus that the actor does not exclude (its ``excluded_tasks``,
:func:`train.evaluation.table2.not_applicable`: a vision policy leaves SitStand out, so its chains are of PickUp,
Push and Carry); the result names them (``"tasks"``).
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
from train.envs.cpu.env import InteractionEnv, control_steps
from train.episodes import Episode, episode_variant
from train.evaluation.table2 import accuracy_text, cell_text, interval95, not_applicable

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
    if hasattr(actor, "rebind"):  # the QP teacher: a teacher for the next task's reference, no history
        actor.rebind(env, i)
        return
    fresh = env.observe()
    for key, value in vars(fresh).items():
        actor.history.terms[key][i, -1] = value[i]


def run_chains(actor, chains: list[list[Episode]], cfg: ChainConfig) -> list[dict]:
    """Run ``chains`` side by side with ``actor`` (a :class:`train.actors.PolicyActor`); per chain: ``success``,
    ``tasks_completed``, why it ended (``fell``, ``strayed``, ``task_failed``) and ``root_accuracy`` (R_acc over the
    chain's full length, module docstring). A stray is the root farther than ``tolerance_m`` from the commanded
    trajectory, the distance R_acc counts (:attr:`train.mdp.tasks.StepFacts.root_dev_m`)."""
    env = InteractionEnv(actor.env_config())
    env.reset([(c[0], 1.0) for c in chains])
    actor.reset(env)
    stage, result = [0] * len(chains), [None] * len(chains)
    within = [0] * len(chains)  # the steps on the track, over the chain's finished tasks
    while any(r is None for r in result):
        obs, done = env.step(actor.act(env))
        actor.observe(obs)
        for i, s in enumerate(env.slots):
            if result[i] is not None:
                continue
            end = None
            if s.fell:
                end = "fell"
            elif s.last_facts.root_dev_m > cfg.tolerance_m:
                end = "strayed"
            elif done[i] and not s.meter.success:
                end = "task_failed"
            elif done[i] and stage[i] + 1 == len(chains[i]):
                end = "completed"
            elif done[i]:
                within[i] += s.meter.root_within
                stage[i] += 1
                _switch(env, actor, i, chains[i][stage[i]])
            if end is not None:
                s.done = True  # stands still from now on
                completed = stage[i] + (end == "completed")
                accuracy = (within[i] + s.meter.root_within) / sum(control_steps(e) for e in chains[i])
                result[i] = {
                    "success": end == "completed",
                    "tasks_completed": completed,
                    "ended": end,
                    "root_accuracy": accuracy,
                }
    env.close()
    return result


def evaluate_chains(actor, episodes: list[Episode], cfg: ChainConfig = ChainConfig(), label: str = "") -> dict:
    """Table 3 of ``actor`` on the corpus ``episodes`` (module docstring), per chain length; ``"tasks"``: those the
    chains were drawn from, ``"not_applicable"``: those the actor excludes, with its reason (only when some)."""
    excluded = not_applicable(actor)
    by_task: dict[str, list[Episode]] = {}
    for e in episodes:
        if e.task not in excluded and episode_variant(e) in (None, "x1"):  # an augmented corpus: its 1.0x clips
            by_task.setdefault(e.task, []).append(e)
    if not by_task:
        raise ValueError(f"no episode of a task the actor attempts (it excludes {sorted(excluded)})")
    tasks = sorted(by_task)
    out = {"label": label, "config": asdict(cfg), "tasks": tasks, "lengths": {}}
    if excluded:
        out["not_applicable"] = [{"task": t, "reason": why} for t, why in excluded.items()]
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
            "root_accuracy": float(np.mean([r["root_accuracy"] for r in outcomes])),
            "ended": {k: sum(r["ended"] == k for r in outcomes) for k in ENDINGS},
        }
    return out


def markdown(result: dict) -> str:
    """Table 3's layout: success (%) per chain length with its 95% interval, the tasks completed and R_acc (%, the
    mean over the chains; absent from a result written before it)."""
    lengths = list(result["lengths"])
    lines = [
        "| | " + " | ".join(f"N = {n}" for n in lengths) + " |",
        "|---" * (len(lengths) + 1) + "|",
        f"| {result['label']} | " + " | ".join(_length_text(c) for c in result["lengths"].values()) + " |",
    ]
    return "\n".join(lines) + "\n"


def _length_text(c: dict) -> str:
    """One chain length's cell: ``success (interval), k tasks[, R_acc a]``."""
    text = f"{cell_text(c)}, {c['mean_tasks_completed']:.1f} tasks"
    return text + (f", R_acc {accuracy_text(c)}" if "root_accuracy" in c else "")


def write(result: dict, out_dir: Path, scale_note: dict) -> Path:
    """``chains.json`` (the result with ``scale_note``) and ``chains.md`` (the table) in ``out_dir``."""
    out_dir = Path(out_dir)
    c = result["config"]
    line = f"Chains: {c['chains']} per length and seed, seeds {', '.join(map(str, c['seeds']))}, scale 1.0"
    line += f", tasks drawn from {', '.join(result['tasks'])}." if "tasks" in result else "."
    for x in result.get("not_applicable", ()):
        line += f" {x['task']} not applicable: {x['reason']}."
    line += " R_acc: the share of chain steps with the root within 0.6 m of the commanded root trajectory, in %."
    write_json_atomic(out_dir / "chains.json", {"scale": scale_note, "result": result})
    write_bytes_atomic(out_dir / "chains.md", (line + "\n\n" + markdown(result)).encode())
    return out_dir / "chains.json"
