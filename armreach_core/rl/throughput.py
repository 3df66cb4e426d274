"""Training throughput of a learner (SB3 or SBX) on an armreach env, for ``armreach bench``."""

from __future__ import annotations

import time
from typing import Any


def bench_training(
    backend: str,
    algo: str,
    steps: int,
    learner: str = "sb3",
    threads: int | None = None,
    settings: dict[str, Any] | None = None,
) -> float:
    """Env steps/s while ``learner`` trains ``algo`` with the paper preset (after its warm-up and compilation).

    ``threads``: torch CPU threads; default what ``armreach train`` uses (see
    :func:`armreach_core.rl.train.configure_threads`). ``settings``: preset values to
    change, e.g. ``{"train_freq": 4, "gradient_steps": 1}`` (checked like a preset's).
    """
    import tempfile
    from pathlib import Path

    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

    from armreach_core.rl.agents import build_model, make_vec_env
    from armreach_core.rl.config import resolve_config
    from armreach_core.rl.train import configure_threads, probe

    config = resolve_config(algo=algo, preset="paper", backend=backend, learner=learner)
    config = config.with_settings(**(settings or {}))
    if threads is not None:
        config = config.with_settings(torch_threads=threads)
    configure_threads(config.torch_threads, "cpu")
    room = probe(config)  # the limit room, where the settings ask for a guarded policy
    with tempfile.TemporaryDirectory() as tmp:
        env = make_vec_env(config, Path(tmp), 0, 1, append=False)
        try:
            model = build_model(algo, config.settings, env, 0, None, "cpu", room)
            # Past the start: PPO's first rollout, an off-policy algorithm's first updates.
            warm = model.learning_starts + 50 if isinstance(model, OffPolicyAlgorithm) else 2048
            model.learn(warm)
            t0 = time.perf_counter()
            model.learn(steps, reset_num_timesteps=False)
            return (int(model.num_timesteps) - warm) / (time.perf_counter() - t0)
        finally:
            env.close()


#: The name of :func:`bench_training` before learners other than SB3 existed.
bench_sb3 = bench_training
