"""One env's ``MjData``, read and written by URDF joint, link and body name.

Every read comes from the same physics state: positions and velocities from ``qpos`` and
``qvel``, link and body poses from ``xpos``/``xquat``, which the backend brings up to
``qpos`` after each step (``mj_step`` computes them before its last integration).
Contacts are those found at the start of the last physics step.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.backend import NO_OBJECTS, ArmState, BodyState
from armreach_core.errors import ArmReachError
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_mujoco.compiled import CompiledModel
from armreach_mujoco.engine import mujoco
from armreach_mujoco.native import NativeMotors
from armreach_mujoco.servo import Motors
from armreach_mujoco.world import BODY_PREFIX


class StateIO:
    """Joint, link and body state of one ``MjData`` of ``compiled``'s model (which it only reads)."""

    def __init__(self, robot: RobotModel, compiled: CompiledModel, data: Any) -> None:
        self.robot = robot
        self.compiled = compiled
        self.model = compiled.model
        self.data = data
        self._qpos, self._qvel = compiled.qpos, compiled.qvel
        self._ee = compiled.bodies[robot.ee_link]
        self._held = len(compiled.held_present) > 0
        present = compiled.held_present
        self._held_targets = np.array([robot.held_joints[present[i]].position for i in compiled.held_servos])
        self._has_free = bool(compiled.free)
        servoed = compiled.held_servos
        #: the motors: the arm's joints first, then the held joints that have one
        kind = NativeMotors if compiled.native else Motors
        self.motors: Motors | NativeMotors = kind(
            np.concatenate((self._qpos, compiled.held_qpos[servoed])),
            np.concatenate((self._qvel, compiled.held_qvel[servoed])),
        )
        self._targets = self.motors.targets[: robot.dof]  # a view: the arm's motor targets
        # MjData's arrays, fetched once (each attribute access costs a binding call)
        self._qpos_all, self._qvel_all, self._xpos = data.qpos, data.qvel, data.xpos

    # -- writes ------------------------------------------------------------------------
    def home(self) -> None:
        """The arm at home, holding it."""
        self._qpos_all[self._qpos] = self.robot.home
        self._targets[:] = self.robot.home
        self._hold(self.robot.home)
        mujoco.mj_forward(self.model, self.data)

    def _hold(self, q: FloatArray) -> None:
        """Held joints (fingers...) where they belong when the arm is at ``q``, their motors holding them."""
        if self._held:
            self.data.qpos[self.compiled.held_qpos] = self.robot.held_positions(q)[self.compiled.held_present]
            self.motors.targets[self.robot.dof :] = self._held_targets

    def carry_over(self, old: StateIO) -> None:
        """Take the arm's, the boxes' and the markers' state from ``old`` (another model of the same robot)."""
        data, before = self.data, old.compiled
        data.qpos[self._qpos] = old.data.qpos[before.qpos]
        data.qvel[self._qvel] = old.data.qvel[before.qvel]
        data.qpos[self.compiled.held_qpos] = old.data.qpos[before.held_qpos]
        data.qvel[self.compiled.held_qvel] = old.data.qvel[before.held_qvel]
        self.motors.targets[:] = old.motors.targets
        self.motors.gains[:] = old.motors.gains
        data.time = old.data.time
        for name, (qadr, vadr) in self.compiled.free.items():
            if name in before.free:
                old_qadr, old_vadr = before.free[name]
                data.qpos[qadr : qadr + 7] = old.data.qpos[old_qadr : old_qadr + 7]
                data.qvel[vadr : vadr + 6] = old.data.qvel[old_vadr : old_vadr + 6]
        for name, index in self.compiled.mocap.items():
            previous = before.mocap.get(name)
            if previous is not None:
                data.mocap_pos[index] = old.data.mocap_pos[previous]
        for name, index in self.compiled.movable.items():
            previous = before.movable.get(name)
            if previous is not None:
                data.mocap_pos[index] = old.data.mocap_pos[previous]
                data.mocap_quat[index] = old.data.mocap_quat[previous]
        mujoco.mj_forward(self.model, data)

    def reset_joints(self, q: npt.ArrayLike) -> None:
        values = np.asarray(q, dtype=np.float64)
        data = self.data
        data.qpos[self._qpos] = values
        data.qvel[:] = 0.0
        data.qacc_warmstart[:] = 0.0
        self._targets[:] = values
        self._hold(values)
        mujoco.mj_forward(self.model, data)

    def set_joint_targets(self, q: FloatArray) -> None:
        self._targets[:] = q

    def set_marker(self, name: str, position: FloatArray) -> None:
        try:
            index = self.compiled.mocap[name]
        except KeyError:
            raise ArmReachError(f"marker {name!r} does not exist; add it first") from None
        self.data.mocap_pos[index] = position

    def set_body_pose(self, name: str, position: npt.ArrayLike, orientation: npt.ArrayLike) -> None:
        quat = np.asarray(orientation, dtype=np.float64)
        data = self.data
        mocap = self.compiled.movable.get(name)
        if mocap is not None:  # a fixed shape: its mocap body
            data.mocap_pos[mocap] = np.asarray(position, dtype=np.float64)
            data.mocap_quat[mocap] = quat / np.linalg.norm(quat)
            mujoco.mj_forward(self.model, data)
            return
        qadr, vadr = self._free(name)
        data.qpos[qadr : qadr + 3] = np.asarray(position, dtype=np.float64)
        data.qpos[qadr + 3 : qadr + 7] = quat / np.linalg.norm(quat)
        data.qvel[vadr : vadr + 6] = 0.0
        data.qacc_warmstart[:] = 0.0
        mujoco.mj_forward(self.model, data)

    # -- reads -------------------------------------------------------------------------
    def joint_state(self) -> tuple[FloatArray, FloatArray]:
        return self._qpos_all[self._qpos], self._qvel_all[self._qvel]  # index arrays: copies

    def read_state(self) -> ArmState:
        q, qd = self._qpos_all[self._qpos], self._qvel_all[self._qvel]
        objects = {name: self.body_state(name) for name in self.compiled.free} if self._has_free else NO_OBJECTS
        return ArmState(q, qd, self._xpos[self._ee].copy(), objects)

    def link_position(self, link: str) -> FloatArray:
        if link == self.robot.root_link:  # a root called "world" is MuJoCo's own world body, at the origin
            return np.array(self.robot.base_position, dtype=np.float64)
        try:
            index = self.compiled.bodies[link]
        except KeyError:
            raise ArmReachError(f"link {link!r} is not part of {self.robot.name!r}") from None
        position: FloatArray = self._xpos[index].copy()
        return position

    def body_state(self, name: str) -> BodyState:
        body = self.compiled.bodies.get(BODY_PREFIX + name)
        if body is None:
            raise ArmReachError(f"no body called {name!r}; add it with add_box first")
        data = self.data
        position, orientation = data.xpos[body].copy(), data.xquat[body].copy()
        if name not in self.compiled.free:
            return BodyState(position, orientation, np.zeros(3), np.zeros(3))
        _, vadr = self.compiled.free[name]
        # a free joint's velocity: linear in the world frame, angular in the body's frame
        linear = data.qvel[vadr : vadr + 3].copy()
        angular = data.xmat[body].reshape(3, 3) @ data.qvel[vadr + 3 : vadr + 6]
        return BodyState(position, orientation, linear, angular)

    def contact_force(self, a: str, b: str) -> float:
        pair = {self._body_id(a), self._body_id(b)}
        model, data = self.model, self.data
        total, wrench = 0.0, np.zeros(6)
        geom_body = model.geom_bodyid
        for i in range(data.ncon):
            contact = data.contact[i]
            if {int(geom_body[contact.geom1]), int(geom_body[contact.geom2])} == pair:
                mujoco.mj_contactForce(model, data, i, wrench)
                total += float(wrench[0])
        return total

    def links_in_contact(self) -> tuple[str, ...]:
        model, data = self.model, self.data
        if data.ncon == 0:
            return ()
        geom_body = model.geom_bodyid
        touching = set()
        for contact in data.contact[: data.ncon]:
            touching.add(int(geom_body[contact.geom1]))
            touching.add(int(geom_body[contact.geom2]))
        robot, bodies = self.robot, self.compiled.bodies
        return tuple(
            link for link in robot.link_names if link not in robot.fixed_links and bodies.get(link, -1) in touching
        )

    # -- names -------------------------------------------------------------------------
    def _body_id(self, name: str) -> int:
        """MuJoCo body of a robot link or an added body."""
        bodies = self.compiled.bodies
        if BODY_PREFIX + name in bodies:
            return bodies[BODY_PREFIX + name]
        if name in bodies and name in self.robot.link_names:
            return bodies[name]
        raise ArmReachError(f"{name!r} is neither a link of {self.robot.name!r} nor a body")

    def _free(self, name: str) -> tuple[int, int]:
        try:
            return self.compiled.free[name]
        except KeyError:
            if BODY_PREFIX + name in self.compiled.bodies:
                raise ArmReachError(f"body {name!r} is fixed (mass 0); only free bodies can be moved") from None
            raise ArmReachError(f"no body called {name!r}; add it with add_box first") from None
