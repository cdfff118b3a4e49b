"""The interaction environment on two backends: ``cpu`` (native MuJoCo, :mod:`train.envs.cpu`) and ``mjlab``
(MuJoCo Warp on a GPU, :mod:`train.envs.mjlab`), with the same observations, rewards and terminations
(``tests/test_mjlab_env.py`` checks them against each other on one state)."""
