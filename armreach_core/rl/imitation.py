"""Imitation before reinforcement: behaviour cloning and DAgger on a task's reference controller.

A task with a reference controller (:meth:`armreach_core.task.Task.demonstrator`) can teach
an off-policy run's actor before (or instead of) any reinforcement learning. The preset key
``imitation: {episodes: N, rounds: R, rollouts: M, gradient_steps: G, beta: b}``:

1. runs the controller for ``N`` seeded episodes and fits the actor to its actions
   (behaviour cloning: the mean squared error of the actor's deterministic action); with
   ``noise: s``, Gaussian noise of spread ``s`` is added to each action taken, and the label
   stays the controller's clean action, so the data show how to get back to its path
   (DART: Laskey et al., "DART: Noise Injection for Robust Imitation Learning", 2017);
2. for each of ``R`` rounds, rolls out ``M`` episodes in which the learner acts (the
   controller's action is taken instead with probability ``b**round``), asks the
   controller what it would do in every state the learner visited, adds those labels to
   the data and fits the actor again (DAgger: Ross, Gordon and Bagnell, "A Reduction of
   Imitation Learning and Structured Prediction to No-Regret Online Learning", 2011).

With ``workers: W`` the episodes of each stage run in ``W`` processes, each with an env of its
own (:mod:`armreach_core.rl.collection`); every episode draws its noise from a generator keyed by
its seed, so the data are the same for any ``W``.

Each fit takes ``G`` Adam steps of ``batch_size`` samples, the run's learning rate. The run's
``timesteps`` of reinforcement learning follow from the cloned actor (0: none). The env
steps of imitation are reported apart from the run's own (``imitation.json``).

``fit_threads: T`` runs each fit on ``T`` torch threads, the run's own (``torch_threads``)
again after it: the collection's worker processes wait while the actor is fitted, so their
cores are free (on 2 cores, 2 threads fit a 256x256 actor about 1.4 times as fast).

``limit_weight: w`` adds to each fit's loss ``w`` times the mean square of how far an action
would take a joint's target past its limit, less the controller's own margin (its
``limit_margin``, in actions): the states record each joint's room to its limits
(:func:`armreach_core.rl.collection.limit_room`). Under the paper's rule such a target ends the
episode, and a clone's small errors near a limit the controller rests on were its commonest
failure.

``episode_steps: S`` ends imitation's episodes after ``S`` steps instead of the training env's
``max_episode_steps``: a large arm's reference may need more steps to a far target than a
training episode holds, and a demonstration cut short never shows the end of its path.

With the run's ``until_success`` (:mod:`armreach_core.rl.validation`), the actor is evaluated
on held-out targets after every fit, a row of ``validation.csv`` each; at the first that
passes, the rounds left and the reinforcement learning are skipped, as an evaluation during
reinforcement learning would have stopped it. The next round's episodes need only the fitted
actor, so they start on the workers before that evaluation and run beside it (the workers
stand back for it, :data:`~armreach_core.rl.collection.WORKER_NICENESS`); when it passes they
are dropped. Once they end, the workers help the judge: its episodes are shared between them and
the training process (:mod:`armreach_core.rl.judge_help`). A stage's ``seconds`` are its wait
for its episodes and its fit.
Implemented for the SB3 learner, whose actors are PyTorch modules.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from armreach_core.rl.collection import Collector, Dataset, Rollout, episode
from armreach_core.rl.demonstrations import DEMO_SEED, reference_controller
from armreach_core.rl.validation import Share, Validation
from armreach_core.threads import torch_threads

#: Seeds of the learner's rollouts start here, past any demonstration episode's.
ROLLOUT_SEED = DEMO_SEED + 500_000

__all__ = ["ROLLOUT_SEED", "Dataset", "episode", "fit", "imitate"]


def clean_action(policy: Any, obs: Any) -> Any:
    """The deterministic action of an SB3 ``policy``'s actor for the tensor ``obs``, with its gradient.

    For SAC (no gSDE) the tanh of the actor's mean, the mode ``policy._predict`` returns, without
    the log-std head and the distribution it also builds: the same values and gradients, bit for
    bit; with Adam's ``foreach`` a fit takes a tenth less time. Other actors (TD3, DDPG; SAC with
    gSDE) are called as ``_predict`` calls them. A policy's limit guard
    (:mod:`armreach_core.rl.limit_guard`) is not applied: the fit sees the network's own action.
    """
    import torch as th

    actor = policy.actor
    if hasattr(actor, "latent_pi"):
        if not getattr(actor, "use_sde", False):
            features = actor.extract_features(obs, actor.features_extractor)
            return th.tanh(actor.mu(actor.latent_pi(features)))
        return actor(obs, deterministic=True)
    return actor(obs)


def fit(
    model: Any,
    data: Dataset,
    steps: int,
    batch_size: int,
    learning_rate: float,
    seed: int,
    *,
    limit_weight: float = 0.0,
    limit_margin: float = 0.0,
) -> float:
    """Fit ``model``'s actor to ``data`` (``steps`` Adam steps); the mean loss of the last tenth.

    With ``limit_weight`` and a room to the limits for every state (:attr:`Dataset.rooms`), the
    loss adds that weight times the mean square of how far each predicted action goes past its
    room less ``limit_margin`` (the controller's own margin, so that its labels cost nothing).
    """
    import torch as th

    policy = model.policy
    obs = th.as_tensor(np.stack(data.observations), device=model.device)
    target = th.as_tensor(np.stack(data.actions), device=model.device)
    rooms = None
    if limit_weight > 0 and data.rooms and len(data.rooms) == len(data):
        rooms = th.as_tensor(np.stack(data.rooms), device=model.device) - limit_margin
    parameters = list(model.actor.parameters())
    optimizer = th.optim.Adam(parameters, lr=learning_rate, foreach=True)  # the per-tensor loop's steps, bit for bit
    generator = th.Generator().manual_seed(seed)
    policy.set_training_mode(True)
    losses = []
    for _ in range(steps):
        index = th.randint(len(target), (min(batch_size, len(target)),), generator=generator)
        predicted = clean_action(policy, obs[index])
        loss = th.nn.functional.mse_loss(predicted, target[index])
        if rooms is not None:  # past the room up (row 0) or down (row 1): the paper's rule ends the episode
            room = rooms[index]
            past = th.relu(predicted - room[:, 0]) + th.relu(-predicted - room[:, 1])
            loss = loss + limit_weight * past.square().mean()
        optimizer.zero_grad()
        loss.backward()  # type: ignore[no-untyped-call]
        optimizer.step()
        losses.append(loss.item())
    policy.set_training_mode(False)
    actor_target = getattr(model, "actor_target", None)
    if actor_target is not None:  # TD3 and DDPG: the target actor starts from the cloned one
        actor_target.load_state_dict(model.actor.state_dict())
    tail = losses[-max(1, steps // 10) :]
    return float(np.mean(tail)) if tail else float("nan")


def imitate(
    model: Any,
    env: Any,
    spec: Mapping[str, Any],
    seed: int,
    log: Callable[[str], None] | None = None,
    env_kwargs: Mapping[str, Any] | None = None,
    judge: Callable[[Share], Validation] | None = None,
    evaluation_kwargs: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Teach ``model``'s actor ``env``'s reference controller (see the module docstring); what each stage did.

    ``env_kwargs`` build the envs of the worker processes (``workers`` above 1). ``judge``
    evaluates the actor on held-out targets after each stage's fit (the run's ``until_success``),
    making its looks' tallies with the :class:`~armreach_core.rl.validation.Share` it is given;
    once one passes, the stages left are not run. With ``evaluation_kwargs`` (the judge's env),
    the workers help it (:mod:`armreach_core.rl.judge_help`).
    """
    demonstrator = reference_controller(env, "imitation")
    episodes, rounds = int(spec.get("episodes", 100)), int(spec.get("rounds", 4))
    rollouts, beta = int(spec.get("rollouts", 50)), float(spec.get("beta", 0.5))
    noise, workers = float(spec.get("noise", 0.0)), int(spec.get("workers", 1))
    steps, batch = int(spec.get("gradient_steps", 2000)), int(model.batch_size)
    rate = float(model.lr_schedule(1.0))
    limits = {
        "limit_weight": float(spec.get("limit_weight", 0.0)),
        "limit_margin": float(getattr(demonstrator, "limit_margin", 0.0)),
    }
    threads = int(spec.get("fit_threads", 0))
    data = Dataset()
    stages: list[dict[str, Any]] = []

    def stage_rollout(stage: int) -> tuple[range, Rollout]:
        """The seeds of ``stage``'s episodes and how they run: the controller's (with noise), then DAgger's."""
        if stage == 0:
            first = DEMO_SEED + seed * 10_000
            return range(first, first + episodes), Rollout(None, 1.0, noise, (seed, 0x1A17, 0))
        first = ROLLOUT_SEED + seed * 100_000 + (stage - 1) * rollouts
        return range(first, first + rollouts), Rollout(model.policy, beta**stage, 0.0, (seed, 0x1A17, stage))

    with Collector(env, demonstrator, env_kwargs, workers, evaluation_kwargs) as collector:
        pending = collector.start(*stage_rollout(0))
        for stage in range(rounds + 1):
            t0 = time.perf_counter()
            seeds, rollout = stage_rollout(stage)
            before = len(data)
            collected = pending.result()
            data.extend(collected)
            outcomes = collected.outcomes
            if stage == 0:
                from armreach_core.rl.standardize import standardize_from

                standardize_from(model, np.stack(data.observations))
            with torch_threads(threads):
                loss = fit(model, data, steps, batch, rate, seed + stage, **limits)
            record = {
                "stage": "demonstrations" if stage == 0 else f"dagger {stage}",
                "episodes": len(seeds),
                "expert_share": rollout.beta,
                "states": len(data) - before,
                "dataset": len(data),
                "success_rate": float(np.mean([o["success"] for o in outcomes])),
                "touch_rate": float(np.mean([o["touched"] for o in outcomes])),
                "loss": loss,
                "seconds": time.perf_counter() - t0,
            }
            if stage < rounds:  # the next round needs only the fitted actor: its episodes run while the judge does
                pending = collector.start(*stage_rollout(stage + 1))
            held = judge(collector.share(model.policy)) if judge is not None else None
            if held is not None:
                record["held_out"] = {
                    "episodes": held.episodes,
                    "successes": held.successes,
                    "passed": held.passed,
                    "seconds": held.seconds,
                }
            stages.append(record)
            if log is not None:
                judged = "" if held is None else f", held-out {held.successes}/{held.episodes}"
                log(
                    f"imitation {record['stage']}: {len(seeds)} episodes (expert share {rollout.beta:.2f}), "
                    f"success {record['success_rate']:.0%}, touching {record['touch_rate']:.0%}, "
                    f"{len(data)} states, loss {loss:.4f}{judged}, {record['seconds']:.0f} s"
                )
            if held is not None and held.passed:
                pending.cancel()
                break
    return {"stages": stages, "env_steps": len(data), "workers": workers}
