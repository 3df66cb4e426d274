"""The reach task: the paper's ArmReach6DOFEnv.

- :mod:`.task`: :class:`~.task.ReachTask`, the engine-independent target, reward and success.
- :mod:`.env`: :class:`~.env.ArmReach6DOFEnv`, the public env (``armreach/Reach-v4``).
- ``rl_zoo3.yml``: the task's rl-baselines3-zoo hyperparameters.
"""
