"""``ArmReach6DOFEnv``: the paper's reaching env, with its docstring tables built from code."""

from __future__ import annotations

import os
from typing import Any

from armreach_core.env import ArmEnv
from armreach_core.plugins.defaults import DEFAULT_BACKEND
from armreach_core.tasks.reach.task import ReachTask

_DOC = """A URDF arm reaches random 3D targets (the paper's *ArmReach6DOFEnv*).

    ## Description

    A serial arm, the bundled UR5-class ``ar6`` or any arm given by its URDF, must bring its
    end effector within 5 cm of a target drawn at random in a ball in front of it, by
    moving its joints in small position steps. The physics engine is a plugin (PyBullet by
    default, MuJoCo built from the same URDF); gravity and a ground plane are on,
    self-collision is off unless ``self_collision=True`` (parent/child pairs excluded), and
    inertias come from the URDF (``inertia_from_file=True``).

    Made with ``gym.make("armreach/Reach-v4", backend="pybullet", urdf=None,
    ee_link=None, render_mode=None)`` after ``import armreach_core``, or by calling this
    class with the same keyword arguments.

    ## Action space

    ``Box(-1, 1, (n,), float32)``, one value per actuated joint (n = 6 for the bundled
    arm). The joint position target is ``θ + a · max_joint_step`` (default 0.05 rad), each
    joint's change at most its URDF velocity limit times the control period
    (``joint_velocity_limits``; ``env.joint_step`` per joint), applied through the backend's
    position control for ``substeps`` physics steps (default 10 × 1/240 s, so the env runs
    at 24 Hz). Actions outside [-1, 1] are
    clipped into it; NaN, inf, a wrong shape or a dtype that is not real numbers (bool,
    complex, str, object) raise :class:`~armreach_core.ActionError` and leave the state
    untouched. With ``control="ee"`` an action is three values instead, the end effector's
    displacement along x, y and z in units of ``ee_step``, turned into joint targets by one
    damped-least-squares step on the URDF model that keeps every joint inside its limits.

    ## Observation space

    ``Box(low, high, (2n + 9,), float32)``; values are clipped into the bounds below.
    For the bundled arm (ar6), as the task's ``layout.table()`` builds it
    (a test keeps this table equal to the code):

    | index | component | unit | low | high | notes |
    |---|---|---|---|---|---|
    | 0–5 | joint angles | rad | [-6.33, -6.33, -3.19, -6.33, -6.33, -6.33] | [6.33, 6.33, 3.19, 6.33, 6.33, 6.33] | θ, the joint limits ± 0.05 (soft limits overshoot) |
    | 6–8 | end-effector position | m | [-1.14, -1.14, -1.14] | [1.14, 1.14, 1.14] | p_e, world frame, from the engine |
    | 9–11 | target position | m | [-0.05, -0.5 , -0.05] | [0.95, 0.5 , 0.95] | p_t, world frame |
    | 12–17 | joint velocities | rad/s | [-6.3, -6.3, -6.3, -6.4, -6.4, -6.4] | [6.3, 6.3, 6.3, 6.4, 6.4, 6.4] | θ̇, bounded by twice the URDF limits |
    | 18–20 | end effector to target | m | [-3.27, -3.27, -3.27] | [3.27, 3.27, 3.27] | p_t − p_e |

    With ``goal_conditioned=True`` the observation is a ``Dict`` with ``observation``
    (joint angles, joint velocities), ``achieved_goal`` (end-effector position, m) and
    ``desired_goal`` (target, m), and :meth:`compute_reward` works on batches (HER).

    ## Rewards

    ``r = -d**p + success_bonus · [d < success_threshold]``, where ``d`` is the
    end-effector-to-target distance in metres; by default ``p = 3`` and the bonus is 10 for
    ``d < 0.05``: ``r = -d³ + 10 · [d < 0.05]``, the paper's reward. A step whose joint
    target left the limits also costs ``joint_limit_penalty`` (default 0). ``info`` holds
    ``distance``, ``is_success``, ``reward_distance`` (−dᵖ), ``reward_success`` and
    ``joint_limit_violation``.

    ## Starting state

    The robot's home configuration with zero velocity (ar6: (0, −π/2, π/2, −π/2, −π/2, 0) rad;
    another URDF: chosen from the URDF, clear of the ground, see ``armreach_core.robot.home``; joints
    off the arm's chain are reset to their hold positions). The target is
    uniform in a ball of radius ``target_radius`` centred at ``target_center`` (ar6: 0.5 m around
    (0.45, 0, 0.45) m; another arm: half its reach ``R`` around the point ``R/2`` forward and
    ``R/2`` up from its base), keeping only points at least ``min_target_height`` (0.05 m) above
    the ground, inside the arm's reachable set computed from the URDF, and at least
    ``success_threshold`` away from the arm's own links at home (``targets_clear_of_arm``). All
    randomness comes from the env's generator (``reset(seed=...)``).

    ## Episode end

    * Termination: success (``d < success_threshold``, 0.05 m); a physics blow-up (a
      non-finite or absurd state, or a step the engine had to reset;
      ``info["physics_unstable"]``, with finite observation and reward); with ``joint_limit_mode="terminate"``, a
      target outside the joint limits (the paper's rule; the default ``"clip"`` clips
      targets into the limits instead, which lets a policy learn near the limits).
    * Truncation: after ``max_episode_steps`` steps (2048, the paper's cap): Gymnasium's
      ``TimeLimit`` under ``gym.make`` (``spec.max_episode_steps`` is 2048, and
      ``gym.make(id, max_episode_steps=N)`` sets another), the env itself when this class
      is constructed directly (``max_episode_steps=N``).

    ## Arguments

    The arm, the backend and the physics: see :class:`~armreach_core.env.ArmEnv`
    (``backend``, ``urdf``, ``robot``, ``ee_link``, ``home``, ``render_mode``,
    ``max_joint_step``, ``joint_velocity_limits``, ``timestep``, ``substeps``,
    ``max_episode_steps``, ``joint_limit_mode``, ``joint_limit_penalty``, ...). The reach task
    adds:

    | argument | default | meaning |
    |---|---|---|
    | ``success_threshold`` | 0.05 | success distance (m) |
    | ``success_bonus`` | 10 | reward added on success |
    | ``distance_exponent`` | 3 | ``p`` of the distance term ``-d**p`` (1 trains faster) |
    | ``target_radius`` | the robot's (ar6: 0.5), else half the reach | radius of the target ball (m) |
    | ``target_center`` | the robot's (ar6: (0.45, 0, 0.45)), else as above | centre of the ball (m, world frame) |
    | ``min_target_height`` | 0.05 | lowest target height (m) |
    | ``targets_clear_of_arm`` | ``True`` | targets keep ``success_threshold`` from the arm's links at home |
    | ``goal_conditioned`` | ``False`` | a ``Dict`` observation for HER |
    | ``scaled_observation`` | ``False`` | the observation in the arm's own units (joint ranges, target ball, velocity limits) |
    | ``control`` | ``"joints"`` | what an action commands: each joint's change, or (``"ee"``) the end effector's displacement |
    | ``ee_step`` | ``max_joint_step`` × the reach | with ``control="ee"``, the displacement (m) of an action of 1 along an axis |

    ## Version history

    Version history: see CHANGELOG.md.
    """


class ArmReach6DOFEnv(ArmEnv):
    __doc__ = _DOC

    def __init__(
        self,
        backend: str = DEFAULT_BACKEND,
        urdf: str | os.PathLike[str] | None = None,
        ee_link: str | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        kwargs.pop("task", None)
        super().__init__(ReachTask.name, backend, urdf, ee_link, render_mode, **kwargs)
