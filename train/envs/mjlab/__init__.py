"""The mjlab backend (``--backend mjlab``), by kind of term as mjlab lays out a task: :mod:`~train.envs.mjlab.env`
(the configuration and the rsl_rl ``VecEnv``), :mod:`~train.envs.mjlab.worlds` (the reference state every term
reads), :mod:`~train.envs.mjlab.events`, :mod:`~train.envs.mjlab.actions`, :mod:`~train.envs.mjlab.observations`,
:mod:`~train.envs.mjlab.rewards`, :mod:`~train.envs.mjlab.terminations`, and :mod:`~train.envs.mjlab.object` (each
world's object)."""
