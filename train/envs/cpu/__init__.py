"""The CPU backend: :mod:`~train.envs.cpu.env` (``N`` scenes in native MuJoCo: BC, DAgger and the evaluation step
it), :mod:`~train.envs.cpu.vec_env` (the restarting rsl_rl ``VecEnv`` of post-training) and
:mod:`~train.envs.cpu.rewards` (the task rewards on its state)."""
