"""``ArmGraspEnv``: pick a cube from a table and lift it, with its docstring tables built from code."""

from __future__ import annotations

import os
from typing import Any

from armreach_core.env import ArmEnv

_DOC = """The bundled arm with a parallel gripper picks a cube from a table and lifts it 10 cm.

    Made with ``gym.make("armreach/Grasp-v3", backend="pybullet", render_mode=None)``
    after ``import armreach_core`` (the ``armreach-grasp`` distribution registers it), or
    by calling this class with the same keyword arguments. The robot is ``ar6-gripper``:
    ar6 with a box palm on ``tool0`` and two prismatic fingers (0–40 mm each, 20 N),
    end effector ``tcp`` between the fingers. Runs on every backend that implements the
    body methods of :class:`~armreach_core.backend.Backend` (PyBullet, MuJoCo).

    ## Action space

    ``Box(-1, 1, (7,), float32)``: six arm values and one gripper command. Arm joint
    targets are ``θ + a[:6] · max_joint_step`` (default 0.05 rad), as in the reach env;
    the gripper command sets both finger targets to ``(a[6] + 1) / 2 · 40 mm`` (−1
    closed, +1 open). Position control runs ``substeps`` physics steps per action
    (default 10 × 1/240 s, 24 Hz).

    ## Observation space

    ``Box(low, high, (38,), float32)``; values are clipped into the bounds below, as
    the task's ``layout.table()`` builds them (a test
    keeps this table equal to the code):

    | index | component | unit | low | high | notes |
    |---|---|---|---|---|---|
    | 0–7 | joint positions | rad, m | [-6.28, -6.28, -3.14, -6.28, -6.28, -6.28,  0.  ,  0.  ] | [6.28, 6.28, 3.14, 6.28, 6.28, 6.28, 0.04, 0.04] | θ (arm), finger openings |
    | 8–15 | joint velocities | rad/s, m/s | [-6.3, -6.3, -6.3, -6.4, -6.4, -6.4, -0.4, -0.4] | [6.3, 6.3, 6.3, 6.4, 6.4, 6.4, 0.4, 0.4] | bounded by twice the URDF limits |
    | 16–18 | gripper position | m | [-1.5, -1.5, -1.5] | [1.5, 1.5, 1.5] | p_e, the tool centre point |
    | 19–21 | object position | m | [-1.5, -1.5, -1.5] | [1.5, 1.5, 1.5] | p_o, the cube's centre |
    | 22–25 | object orientation | 1 | [-1., -1., -1., -1.] | [1., 1., 1., 1.] | quaternion (w, x, y, z) |
    | 26–28 | object linear velocity | m/s | [-5., -5., -5.] | [5., 5., 5.] | world frame |
    | 29–31 | object angular velocity | rad/s | [-20., -20., -20.] | [20., 20., 20.] | world frame |
    | 32–34 | gripper to object | m | [-3., -3., -3.] | [3., 3., 3.] | p_o − p_e |
    | 35–37 | goal position | m | [-1.5, -1.5, -1.5] | [1.5, 1.5, 1.5] | p_g, the start raised by lift_height |

    With ``goal_conditioned=True`` the observation is a ``Dict`` with ``observation``
    (indices 0–34 above), ``achieved_goal`` (the cube's position, m) and ``desired_goal``
    (the goal, m), and :meth:`compute_reward` works on batches (HER).

    ## Rewards

    ``reward_type="sparse"`` (default): ``r = -[d ≥ 0.03]``, where ``d`` is the
    cube-to-goal distance in metres (``-1`` per step, ``0`` on success).
    ``reward_type="dense"``: ``r = -d - d_grip`` with ``d_grip`` the gripper-to-cube
    distance; in the goal-conditioned env ``compute_reward`` reads ``d_grip`` from
    ``info["gripper_to_object"]`` (it does not depend on the goal, so relabelling keeps it
    valid). ``info`` holds ``distance``, ``gripper_to_object``, ``lift`` (the cube's height
    above its start, m), ``is_success`` and ``joint_limit_violation``.

    ## Starting state

    The arm at home (ar6's, fingers open), pointing down above the table. A table (a fixed
    box, top at z = 5 cm, x 0.25–0.75 m, y ±0.35 m) and a 4 cm, 0.1 kg cube resting on it,
    its centre uniform in x ∈ [0.4, 0.6] m, y ∈ [−0.15, 0.15] m and its yaw uniform in
    ±π/4; the goal is 10 cm above the cube's start. Friction 1.0 on the cube, the table and
    the fingers. All randomness comes from the env's generator (``reset(seed=...)``).

    ## Episode end

    * Termination: success (``d < success_threshold``, 0.03 m); a non-finite physics
      state (``info["physics_unstable"]``); with ``joint_limit_mode="terminate"``, an arm
      target outside the joint limits.
    * Truncation: after ``max_episode_steps`` steps (100): Gymnasium's ``TimeLimit`` under
      ``gym.make`` (``spec.max_episode_steps``), the env itself when this class is
      constructed directly.

    ## Arguments

    See :class:`~armreach_core.env.ArmEnv`; the grasp task adds ``reward_type``,
    ``success_threshold``, ``lift_height``, ``object_size``, ``object_mass``, ``friction``,
    ``object_range``, ``object_yaw`` and ``goal_conditioned``
    (:class:`armreach_grasp.task.GraspTask`). Another URDF needs ``ee_link`` and
    ``tool_joints`` (its finger joints), e.g.
    ``gym.make("armreach/Grasp-v3", urdf=..., ee_link="tcp", tool_joints=["f1", "f2"])``.

    ## Version history

    * v0: initial version.
    """


class ArmGraspEnv(ArmEnv):
    __doc__ = _DOC

    def __init__(
        self,
        backend: str = "pybullet",
        urdf: str | os.PathLike[str] | None = None,
        ee_link: str | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        kwargs.pop("task", None)
        # a cube held by friction between two fingers: PyBullet's direct solver moved it 1.0-2.9 mm
        # (RMS over a scripted grasp) from MuJoCo's, Gauss-Seidel 0.03-0.04 mm
        kwargs.setdefault("iterative_solver", True)
        super().__init__("grasp", backend, urdf, ee_link, render_mode, **kwargs)
