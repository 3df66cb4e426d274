"""Evaluation: seeded episodes of the paper's task, per-episode records and summary metrics.

Episode ``i`` is reset with ``seed + i``, so every algorithm and backend sees the same
targets. Metrics follow the paper: success rate, steps to goal (mean ± std over
successes), final reward (mean episode return), and jerk (rad/s³, third finite
difference of joint angles at the control rate, over successful episodes). Tasks with
obstacles add collisions (steps touching one, ``info["collision"]``) and the least
clearance of each episode (``info["clearance"]``, m).
"""

from __future__ import annotations

import csv
import dataclasses
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from armreach_core.diagnostics.smoothness import jerk, mean_jerk
from armreach_core.env import JOINT_LIMIT_MODES, ArmEnv
from armreach_core.errors import ConfigError
from armreach_core.rl import runs
from armreach_core.rl.agents import Agent, IKAgent, SB3Agent, env_kwargs
from armreach_core.rl.config import RunConfig
from armreach_core.rl.learners import algo_class
from armreach_core.rl.metrics import MeanStd, steps_to_goal


@dataclass(frozen=True)
class Episode:
    """One evaluation episode."""

    index: int
    seed: int
    success: bool
    steps: int
    final_distance: float
    episode_return: float
    mean_jerk: float
    joint_limit_violations: int
    #: How the episode ended: one of :data:`ENDINGS`.
    ended_by: str = ""
    #: Steps on which the arm touched an obstacle (tasks that report ``info["collision"]``).
    collisions: int = 0
    #: Least link-to-obstacle distance over the episode (m); NaN for tasks without obstacles.
    min_clearance: float = float("nan")
    #: Steps after which a moving link touched anything (the ground, a body, itself); counted
    #: only when asked (``count_contacts``), else 0.
    contact_steps: int = 0
    #: Steps from the first such step to the last, both counted (0 without contact): how long the
    #: episode was in touch, whatever an engine reports of a link resting on a surface in between
    #: (MuJoCo's soft contact lets a link pressed on the ground part from it for a step).
    contact_span: int = 0


#: How an episode can end: the goal reached, a joint limit (the paper's rule), the step limit,
#: or a physics blow-up.
ENDINGS = ("success", "joint_limit", "time_limit", "physics")
#: One more ending of tasks with obstacles that end an episode at a touch (``info["collision_end"]``).
COLLISION_END = "collision"


def _ending(info: dict[str, Any], truncated: bool) -> str:
    if info.get("is_success"):
        return "success"
    if info.get("physics_unstable"):
        return "physics"
    if info.get("collision_end"):
        return COLLISION_END
    if truncated:
        return "time_limit"
    return "joint_limit" if info.get("joint_limit_violation") else "time_limit"


@dataclass
class EvaluationResult:
    """All episodes of one evaluation of a controller, plus the jerk trace of the jerk-over-time figure."""

    backend: str
    episodes: list[Episode]
    control_dt: float
    jerk_trace: npt.NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    seconds: float = 0.0
    source: str = ""
    #: What a joint-limit violation does: ``terminate`` (the paper's rule) or ``clip``.
    joint_limit_mode: str = "terminate"
    #: Whether each episode's contact steps were counted.
    contacts_counted: bool = False

    def summary(self) -> dict[str, Any]:
        successes = [e.success for e in self.episodes]
        stg = steps_to_goal([e.steps for e in self.episodes], successes)
        returns = MeanStd.of([e.episode_return for e in self.episodes])
        jerks = MeanStd.of([e.mean_jerk for e in self.episodes if e.success])
        return {
            "backend": self.backend,
            "episodes": len(self.episodes),
            "success_rate": float(np.mean(successes)) if successes else float("nan"),
            "steps_to_goal_mean": stg.mean,
            "steps_to_goal_std": stg.std,
            "final_reward_mean": returns.mean,
            "final_reward_std": returns.std,
            "jerk_mean": jerks.mean,
            "jerk_std": jerks.std,
            "final_distance_mean": float(np.mean([e.final_distance for e in self.episodes])),
            "control_dt": self.control_dt,
            "seconds": self.seconds,
            "controller": self.source,
            "joint_limit_mode": self.joint_limit_mode,
            "ended_by": {end: sum(1 for e in self.episodes if e.ended_by == end) for end in self._endings()},
            **self._collision_summary(),
            **self._contact_summary(),
        }

    def _contact_summary(self) -> dict[str, Any]:
        if not self.contacts_counted:
            return {}
        return {
            "contact_steps": int(sum(e.contact_steps for e in self.episodes)),
            "contact_episode_rate": float(np.mean([e.contact_steps > 0 for e in self.episodes])),
            "contact_span_steps": int(sum(e.contact_span for e in self.episodes)),
        }

    def _endings(self) -> tuple[str, ...]:
        obstacles = any(np.isfinite(e.min_clearance) for e in self.episodes)
        return (*ENDINGS, COLLISION_END) if obstacles else ENDINGS

    def _collision_summary(self) -> dict[str, Any]:
        """Collisions per episode, the share of episodes with any, and the least clearance: tasks with obstacles."""
        clearances = [e.min_clearance for e in self.episodes if np.isfinite(e.min_clearance)]
        if not clearances:
            return {}
        return {
            "collisions_per_episode": float(np.mean([e.collisions for e in self.episodes])),
            "collision_episode_rate": float(np.mean([e.collisions > 0 for e in self.episodes])),
            "min_clearance_mean": float(np.mean(clearances)),
            "min_clearance_min": float(np.min(clearances)),
        }


def run_episodes(
    make_env: Callable[[], gym.Env[Any, Any]],
    agent: Agent,
    episodes: int,
    seed: int = 10_000,
    *,
    on_frame: Callable[[int, ArmEnv], None] | None = None,
    count_contacts: bool = False,
) -> EvaluationResult:
    """Run ``episodes`` seeded episodes of ``agent`` and record them.

    ``make_env`` makes an :class:`ArmEnv`, possibly wrapped (robustness perturbations);
    ``count_contacts`` counts each episode's steps with a moving link touching anything
    (where the backend answers contact queries).
    """
    if episodes < 1:
        raise ConfigError(f"episodes must be >= 1, got {episodes}")
    env = make_env()
    base = env.unwrapped
    if not isinstance(base, ArmEnv):
        env.close()
        raise ConfigError(f"evaluation needs an armreach env, got {type(base).__name__}")
    records: list[Episode] = []
    traces: list[npt.NDArray[np.float64]] = []
    t0 = time.perf_counter()
    try:
        dt = base.physics.control_dt
        for i in range(episodes):
            obs, info = env.reset(seed=seed + i)
            qs = [base.backend.joint_state()[0].copy()]
            total, violations, steps, collisions, contacts = 0.0, 0, 0, 0, 0
            first_contact = last_contact = -1
            clearance = float(info.get("clearance", np.nan))
            if on_frame is not None:
                on_frame(i, base)
            while True:
                obs, reward, terminated, truncated, info = env.step(agent.act(obs, base))
                qs.append(base.backend.joint_state()[0].copy())
                total += float(reward)
                violations += int(info.get("joint_limit_violation", False))
                collisions += int(info.get("collision", False))
                if count_contacts and base.backend.links_in_contact():
                    contacts += 1
                    first_contact = steps if first_contact < 0 else first_contact
                    last_contact = steps
                clearance = min(clearance, float(info.get("clearance", np.nan)))
                steps += 1
                if on_frame is not None:
                    on_frame(i, base)
                if terminated or truncated:
                    break
            q = np.asarray(qs)
            success = bool(info["is_success"])
            if success:
                traces.append(jerk(q, dt))
            records.append(
                Episode(
                    i,
                    seed + i,
                    success,
                    steps,
                    float(info["distance"]),
                    total,
                    mean_jerk(q, dt),
                    violations,
                    _ending(info, truncated),
                    collisions,
                    clearance,
                    contacts,
                    last_contact - first_contact + 1 if first_contact >= 0 else 0,
                )
            )
    finally:
        env.close()
    seconds = time.perf_counter() - t0
    trace = _average_trace(traces)
    return EvaluationResult(base.backend_name, records, dt, trace, seconds, contacts_counted=count_contacts)


def _average_trace(traces: list[npt.NDArray[np.float64]]) -> npt.NDArray[np.float64]:
    """Mean jerk at each time step over the episodes still running at that step."""
    if not traces:
        return np.zeros(0)
    length = max(t.size for t in traces)
    total = np.zeros(length)
    count = np.zeros(length)
    for t in traces:
        total[: t.size] += t
        count[: t.size] += 1
    return np.asarray(total / np.maximum(count, 1), dtype=np.float64)


def load_agent(run_dir: Path, config: RunConfig, backend: str | None = None, *, trust: bool = False) -> Agent:
    """The run's controller: its final model (else its latest checkpoint), or the IK reference.

    Raises:
        ConfigError: no model, a damaged one, or a run folder not safe to unpickle from
            (see :func:`armreach_core.rl.runs.check_trusted`; ``trust`` skips that check).
    """
    if not config.learns:
        return IKAgent(float(config.settings.get("damping", 0.05)))
    runs.check_trusted(run_dir, trust=trust)
    model_path, checkpoint = run_dir / runs.MODEL, run_dir / runs.CHECKPOINT
    if model_path.is_file() and checkpoint.is_file() and checkpoint.stat().st_mtime > model_path.stat().st_mtime + 1:
        warnings.warn(
            f"{checkpoint} is newer than {model_path} (a resumed run was interrupted); evaluating {runs.MODEL}",
            RunWarning,
            stacklevel=2,
        )
    for path in (model_path, checkpoint):
        if path.is_file():
            # HER models need an env with the goal spaces to load; a policy needs nothing else.
            env = ArmEnv(**env_kwargs(config, backend=backend)) if config.uses_her else None
            try:
                return SB3Agent(algo_class(config.algo, config.learner).load(path, env=env, device="cpu"), path)
            except Exception as exc:
                raise ConfigError(f"cannot load {path}: {exc}; the file is damaged or not an SB3 model") from exc
            finally:
                if env is not None:
                    env.close()
    raise ConfigError(f"{run_dir} has no {runs.MODEL} or {runs.CHECKPOINT}; train it first")


class RunWarning(UserWarning):
    """Something about a run folder the user should know before trusting a number."""


def evaluate_run(
    run_dir: Path,
    *,
    episodes: int = 100,
    backend: str | None = None,
    seed: int = 10_000,
    max_episode_steps: int | None = None,
    trust: bool = False,
    viewer: bool = False,
    joint_limit_mode: str = "terminate",
    arm: Mapping[str, Any] | None = None,
    count_contacts: bool = False,
) -> EvaluationResult:
    """Evaluate a run folder on the paper's task (2048-step limit), optionally on another backend.

    ``trust`` loads the model even from a folder another user owns or may write to;
    ``viewer`` shows the episodes in a live window (``render_mode="human"``, real time);
    ``joint_limit_mode="clip"`` clips targets into the limits instead of ending the
    episode at a violation (the paper's rule, the default). ``arm`` overrides the run's
    arm (``urdf``, ``ee_link``, ``home``, ``base_position``, ``base_orientation``): the same
    policy on another start pose, base placement or arm, as long as its observation and
    action spaces stay the policy's. ``count_contacts``: as in :func:`run_episodes`.
    """
    if joint_limit_mode not in JOINT_LIMIT_MODES:
        raise ConfigError(f"--joint-limit-mode must be one of {', '.join(JOINT_LIMIT_MODES)}, got {joint_limit_mode!r}")
    config = runs.read_config(run_dir)
    if max_episode_steps is not None:
        if max_episode_steps < 1:
            raise ConfigError(f"--max-episode-steps must be positive, got {max_episode_steps}")
        config = dataclasses.replace(config, eval_max_episode_steps=max_episode_steps)
    agent = load_agent(run_dir, config, backend, trust=trust)
    kwargs = env_kwargs(config, backend=backend, evaluation=True)
    kwargs.update({key: value for key, value in (arm or {}).items() if value is not None})
    kwargs["joint_limit_mode"] = joint_limit_mode
    if arm and isinstance(agent, SB3Agent):
        _check_spaces(agent, kwargs)
    if viewer:
        kwargs["render_mode"] = "human"
    evaluation = run_episodes(lambda: ArmEnv(**kwargs), agent, episodes, seed, count_contacts=count_contacts)
    evaluation.source = agent.describe() if isinstance(agent, (SB3Agent, IKAgent)) else ""
    evaluation.joint_limit_mode = joint_limit_mode
    return evaluation


def _check_spaces(agent: SB3Agent, kwargs: dict[str, Any]) -> None:
    """ConfigError when the env the arm flags build does not fit the policy's spaces."""
    env = ArmEnv(**kwargs)
    try:
        for what in ("observation_space", "action_space"):
            want, have = getattr(agent.model, what), getattr(env, what)
            if getattr(want, "shape", None) != getattr(have, "shape", None):
                raise ConfigError(
                    f"the arm flags give an env whose {what.replace('_', ' ')} is {have}, but the run's policy "
                    f"expects {want}: evaluate a policy on an arm with as many joints as the one it was trained on"
                )
    finally:
        env.close()


def save_evaluation(evaluation: EvaluationResult, out: Path) -> dict[str, Any]:
    """Write ``summary.json``, ``episodes.csv`` and ``jerk_trace.csv`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    summary = evaluation.summary()
    runs.write_json(out / "summary.json", summary)
    with runs.atomic_path(out / "episodes.csv") as tmp, open(tmp, "w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(Episode.__dataclass_fields__))
        writer.writeheader()
        for episode in evaluation.episodes:
            writer.writerow(asdict(episode))
    with runs.atomic_path(out / "jerk_trace.csv") as tmp:
        times = np.arange(evaluation.jerk_trace.size) * evaluation.control_dt
        np.savetxt(tmp, np.column_stack([times, evaluation.jerk_trace]), delimiter=",", header="time_s,jerk_rad_s3")
    return summary
