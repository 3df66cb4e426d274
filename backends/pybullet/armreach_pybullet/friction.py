"""Coulomb joint friction next to PyBullet's position motors, solved by Bullet's own constraint solver.

PyBullet ignores a URDF's joint ``friction``, and its recipe for friction, a velocity motor
with target 0 and the friction as its force, would replace the joint's position motor (a
joint has one motor). A torque applied from the last velocity is one step late: the stiff
velocity-level servo cancels it (measured: no effect even at 1.5 times the effort limit).

So friction is a constraint solved together with the servo: a gear constraint (velocity
ratio 1, no position term) between the joint and a joint of an anchor body that is held
at rest, with the friction as the constraint's force bound. The solver then keeps the
joint still unless the other torques (servo, gravity, contacts) exceed the friction,
exactly as MuJoCo's ``frictionloss`` does. The anchor is made on the first friction set
and removed when every friction is 0 again;
it has no collision or visual shapes and sits far away, so nothing else sees it.

Limit: Bullet's iterative solver settles the servo against the friction in about
``effort * dt / (M_ii * v)`` iterations; on a very light joint (a wrist roll with
``M_ii`` ~1e-4 kg·m²) driven with a friction above its effort limit, that exceeds the
solver's iterations and the servo still moves the joint. Below the effort limit the stiff
servo overcomes the friction anyway, as a real servo with that much torque would.
"""

from __future__ import annotations

from armreach_pybullet.engine import pb

#: Where the anchor body sits (m): far from the scene.
ANCHOR_POSITION = (0.0, 0.0, -1.0e4)
#: Force bound of the motors that hold the anchor's joints at rest: far above any friction.
ANCHOR_HOLD = 1.0e9


class JointFriction:
    """The friction of a body's joints (by PyBullet joint index), made on first use."""

    def __init__(self, client: int, body: int, joints: list[int]) -> None:
        self._client, self._body, self._joints = client, body, list(joints)
        self._anchor = -1
        self._constraints: list[int] = []
        self.values = [0.0] * len(joints)

    def set(self, slot: int, friction: float) -> None:
        """Bound the friction torque (N·m, or N) of ``joints[slot]``."""
        self.values[slot] = float(friction)
        if not any(self.values):
            self._remove()  # back to the world as built
        elif self._anchor < 0:
            self._build()
        else:
            pb.changeConstraint(self._constraints[slot], maxForce=float(friction), physicsClientId=self._client)

    def reset(self) -> None:
        """Bring the anchor back to rest (with the robot's reset, so that episodes do not depend on earlier ones)."""
        if self._anchor < 0:
            return
        for k in range(len(self._joints)):
            pb.resetJointState(self._anchor, k, 0.0, 0.0, physicsClientId=self._client)

    def _remove(self) -> None:
        if self._anchor < 0:
            return
        for constraint in self._constraints:
            pb.removeConstraint(constraint, physicsClientId=self._client)
        pb.removeBody(self._anchor, physicsClientId=self._client)
        self._constraints, self._anchor = [], -1

    def _build(self) -> None:
        cid, n = self._client, len(self._joints)
        self._anchor = pb.createMultiBody(
            baseMass=0.0,
            basePosition=ANCHOR_POSITION,
            linkMasses=[1.0] * n,
            linkCollisionShapeIndices=[-1] * n,
            linkVisualShapeIndices=[-1] * n,
            linkPositions=[(0.0, 0.0, 0.0)] * n,
            linkOrientations=[(0.0, 0.0, 0.0, 1.0)] * n,
            linkInertialFramePositions=[(0.0, 0.0, 0.0)] * n,
            linkInertialFrameOrientations=[(0.0, 0.0, 0.0, 1.0)] * n,
            linkParentIndices=[0] * n,
            linkJointTypes=[pb.JOINT_REVOLUTE] * n,
            linkJointAxis=[(0.0, 0.0, 1.0)] * n,
            physicsClientId=cid,
        )
        links = list(range(n))
        pb.setJointMotorControlArray(
            self._anchor,
            links,
            pb.VELOCITY_CONTROL,
            targetVelocities=[0.0] * n,
            forces=[ANCHOR_HOLD] * n,
            physicsClientId=cid,
        )
        for joint, link, value in zip(self._joints, links, self.values, strict=True):
            constraint = pb.createConstraint(
                self._body,
                joint,
                self._anchor,
                link,
                pb.JOINT_GEAR,
                (0.0, 0.0, 1.0),
                (0.0, 0.0, 0.0),
                (0.0, 0.0, 0.0),
                physicsClientId=cid,
            )
            pb.changeConstraint(constraint, gearRatio=1.0, erp=0.0, maxForce=value, physicsClientId=cid)
            self._constraints.append(constraint)
