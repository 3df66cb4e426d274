"""The backend contract: one suite every backend runs from its own distribution's tests.

A backend's test folder subclasses :class:`BackendContract` and names its backend::

    from armreach_core.diagnostics.contract import BackendContract

    class TestMyEngine(BackendContract):
        backend = "my-engine"

Every test goes through public API only: the backend is built from the bundled robot (and
optionally another URDF, :attr:`BackendContract.urdf`) and checked against the URDF model,
which knows no engine. The suite needs pytest; it skips when the backend's engine is not
installed.

:class:`ContractBounds` holds the suite's numbers. Its defaults are what any backend must
meet; a backend's own tests set :attr:`BackendContract.bounds` to what that engine
measures (with the measured values next to them), so that a change that makes the engine
worse fails its own suite long before it fails everyone's::

    class TestMyEngine(BackendContract):
        backend = "my-engine"
        bounds = ContractBounds(fk_m=1e-12, hold_rad=1e-5)  # measured 2e-13 m, 4e-6 rad
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import ClassVar

import numpy as np
import pytest

from armreach_core.backend import Backend, Camera, PhysicsConfig
from armreach_core.errors import ArmReachError, BackendUnavailableError, ConfigError
from armreach_core.plugins.defaults import DEFAULT_ROBOT
from armreach_core.plugins.lookup import load_backend_class, load_robot, robot_spec
from armreach_core.robot.model import RobotModel

#: How far the engine's end effector may sit from the URDF's forward kinematics (m), by default.
FK_TOLERANCE = 1e-6
#: The dynamics changes :meth:`BackendContract.test_a_dynamics_change_takes_effect_in_this_world_only` makes.
DYNAMICS_CHANGES = ("mass", "damping", "friction", "gain", "effort", "armature")


@dataclass(frozen=True)
class ContractBounds:
    """The numbers of the contract: upper bounds on errors, lower bounds on effects.

    Attributes:
        fk_m: end effector against the URDF's forward kinematics, after steps (m).
        hold_rad: joint error after holding home against gravity for one second (rad).
        track_rad: joint error two seconds after a target 0.1 rad from home (rad).
        rest_height_m: height error of a 2 cm box one second after it is dropped 28 cm (m).
        rest_speed_m_s: its speed then (m/s).
        change_effect_rad: the least each dynamics change of :data:`DYNAMICS_CHANGES`
            must move the joints in 20 control steps (rad).
    """

    fk_m: float = FK_TOLERANCE
    hold_rad: float = 0.02
    track_rad: float = 0.02
    rest_height_m: float = 0.005
    rest_speed_m_s: float = 0.01
    change_effect_rad: Mapping[str, float] = field(
        default_factory=lambda: MappingProxyType(dict.fromkeys(DYNAMICS_CHANGES, 1e-3))
    )


class BackendContract:
    """What every backend must do. Subclass it in a test module and set :attr:`backend`."""

    #: The registered backend name under test.
    backend: ClassVar[str]
    #: A URDF to test instead of the bundled robot (``None``: the bundled robot).
    urdf: ClassVar[str | os.PathLike[str] | None] = None
    #: The numbers the backend is held to (default: what any backend must meet).
    bounds: ClassVar[ContractBounds] = ContractBounds()
    #: Dynamics changes known to make the engine diverge within 20 steps, with the reason: their
    #: test is expected to fail (strictly: it fails the suite once the engine no longer diverges).
    diverging_changes: ClassVar[Mapping[str, str]] = MappingProxyType({})

    # -- fixtures ----------------------------------------------------------------------
    @pytest.fixture
    def robot(self) -> RobotModel:
        if self.urdf is not None:
            return load_robot(self.urdf)
        spec = robot_spec(DEFAULT_ROBOT)
        return load_robot(spec.urdf, spec.ee_link, spec.home)

    @pytest.fixture
    def engine(self) -> type[Backend]:
        try:
            return load_backend_class(self.backend)
        except BackendUnavailableError as exc:
            pytest.skip(str(exc))

    @pytest.fixture
    def world(self, engine: type[Backend], robot: RobotModel) -> Iterator[Backend]:
        backend = engine(robot, PhysicsConfig())
        yield backend
        backend.close()

    # -- the contract ------------------------------------------------------------------
    def test_name_matches_the_registration(self, engine: type[Backend]) -> None:
        assert engine.name == self.backend

    def test_reset_teleports_to_the_pose_at_rest(self, world: Backend, robot: RobotModel) -> None:
        q = robot.clip(robot.home + 0.1)
        world.reset_joints(q)
        got, qd = world.joint_state()
        np.testing.assert_allclose(got, q, atol=1e-9)
        np.testing.assert_allclose(qd, 0.0, atol=1e-9)

    @pytest.mark.parametrize("seed", [0, 1])
    def test_state_is_one_snapshot_that_matches_the_urdf(self, world: Backend, robot: RobotModel, seed: int) -> None:
        rng = np.random.default_rng(seed)
        world.reset_joints(robot.home)
        for _ in range(5):
            world.set_joint_targets(robot.clip(world.joint_state()[0] + rng.uniform(-0.05, 0.05, robot.dof)))
            world.step()
            state = world.read_state()
            np.testing.assert_allclose(state.ee_pos, robot.forward_kinematics(state.q), rtol=0, atol=self.bounds.fk_m)
            # the link query and the snapshot read the same engine state
            np.testing.assert_array_equal(world.link_position(robot.ee_link), state.ee_pos)

    def test_position_control_holds_and_tracks(self, world: Backend, robot: RobotModel) -> None:
        world.reset_joints(robot.home)
        for _ in range(24):  # one second at the default control rate
            world.step()
        np.testing.assert_allclose(world.joint_state()[0], robot.home, rtol=0, atol=self.bounds.hold_rad)  # gravity
        target = robot.clip(robot.home + 0.1)
        world.set_joint_targets(target)
        for _ in range(48):
            world.step()
        np.testing.assert_allclose(world.joint_state()[0], target, rtol=0, atol=self.bounds.track_rad)
        assert not world.diverged()

    def test_same_inputs_give_the_same_motion(self, engine: type[Backend], robot: RobotModel) -> None:
        def run() -> np.ndarray[tuple[int, ...], np.dtype[np.float64]]:
            world = engine(robot, PhysicsConfig())
            try:
                world.reset_joints(robot.home)
                rng = np.random.default_rng(1)
                for _ in range(20):
                    world.set_joint_targets(robot.clip(world.joint_state()[0] + rng.uniform(-0.05, 0.05, robot.dof)))
                    world.step()
                return np.concatenate(world.joint_state())
            finally:
                world.close()

        np.testing.assert_array_equal(run(), run())

    def test_worlds_are_isolated(self, engine: type[Backend], robot: RobotModel) -> None:
        a, b = engine(robot, PhysicsConfig()), engine(robot, PhysicsConfig())
        try:
            a.reset_joints(robot.home)
            b.reset_joints(robot.home)
            a.set_joint_targets(robot.clip(robot.home + 0.2))
            for _ in range(10):
                a.step()
            np.testing.assert_allclose(b.joint_state()[0], robot.home, atol=1e-9)
        finally:
            a.close()
            b.close()

    def test_unknown_link_is_an_armreach_error(self, world: Backend) -> None:
        with pytest.raises(ArmReachError, match="not part of"):
            world.link_position("no-such-link")

    def test_markers_and_rendering_need_no_display(self, world: Backend, robot: RobotModel) -> None:
        world.add_marker("contract-marker", 0.05, (1.0, 0.0, 0.0, 1.0))
        world.reset_joints(robot.home)
        world.set_marker("contract-marker", robot.forward_kinematics(robot.home))
        image = world.render(Camera(width=64, height=48))
        assert image.shape == (48, 64, 3)
        assert image.dtype == np.uint8
        assert image.std() > 1.0  # not blank

    def test_a_free_box_falls_and_rests_on_the_ground(self, world: Backend, robot: RobotModel) -> None:
        try:
            world.add_box("contract-box", (0.02, 0.02, 0.02), 0.1, position=(0.0, -0.6, 0.3))
        except NotImplementedError:
            pytest.skip(f"backend {self.backend!r} has no bodies")
        world.reset_joints(robot.home)
        world.set_body_pose("contract-box", (0.0, -0.6, 0.3))
        assert world.free_bodies() == ("contract-box",)
        for _ in range(48):
            world.step()
        body = world.body_state("contract-box")
        assert body.is_finite()
        assert abs(body.position[2] - 0.02) <= self.bounds.rest_height_m  # resting on the ground
        assert np.linalg.norm(body.linear_velocity) <= self.bounds.rest_speed_m_s
        assert world.read_state().objects["contract-box"].position[2] == pytest.approx(body.position[2])

    def test_links_in_contact_name_the_links_in_the_ground(self, world: Backend, robot: RobotModel) -> None:
        from armreach_core.robot.home import ground_violations

        world.reset_joints(robot.home)
        world.step()
        try:
            assert world.links_in_contact() == ()  # home is clear of the ground; the base is not counted
        except NotImplementedError:
            pytest.skip(f"backend {self.backend!r} has no contact queries")
        rng = np.random.default_rng(0)
        sunk = [
            (q, low)
            for q in robot.sample_configurations(rng, 500)
            for low in [ground_violations(robot, q, clearance=-0.02)]
            if low
        ]
        # the pose that puts links least deep past 2 cm: much deeper, the ground throws the arm off within a step
        deep = min(sunk, key=lambda pose: -min(pose[1].values()))
        world.reset_joints(deep[0])
        world.step()
        touching = set(world.links_in_contact())
        assert touching & set(deep[1])  # a link put 2 cm into the ground, still touching after a step
        assert touching <= set(robot.link_names) - robot.fixed_links

    def test_shapes_move_and_link_clearances_pose_the_arm_without_moving_it(
        self, world: Backend, robot: RobotModel
    ) -> None:
        try:
            world.add_shape("contract-sphere", "sphere", (0.05,), position=(0.0, 0.0, 5.0))
            world.add_shape("contract-pole", "cylinder", (0.02, 0.3), position=(0.0, 0.0, 5.0))
        except NotImplementedError:
            pytest.skip(f"backend {self.backend!r} has no shapes")
        world.reset_joints(robot.home)
        names = ["contract-sphere", "contract-pole"]
        far = world.link_clearances(names, max_distance=0.2)
        assert set(far) == set(robot.link_names) - robot.fixed_links
        assert all(np.all(values == 0.2) for values in far.values())  # both 5 m up: out of range
        world.set_body_pose("contract-sphere", robot.forward_kinematics(robot.home))  # on the end effector
        near = world.link_clearances(names, max_distance=0.2)
        assert min(float(v[0]) for v in near.values()) < 0.0  # a link overlaps it
        assert all(float(v[1]) == 0.2 for v in near.values())  # the pole is still out of range
        q = robot.sample_configurations(np.random.default_rng(3), 1)[0]
        posed = world.link_clearances(names, q=q, max_distance=0.2)
        assert np.array_equal(world.joint_state()[0], robot.home)  # the world was left as it was
        world.reset_joints(q)
        moved = world.link_clearances(names, max_distance=0.2)
        for link, values in posed.items():
            np.testing.assert_allclose(values, moved[link], atol=1e-9)

    @pytest.mark.parametrize("change", DYNAMICS_CHANGES)
    def test_a_dynamics_change_takes_effect_in_this_world_only(
        self, engine: type[Backend], robot: RobotModel, change: str, request: pytest.FixtureRequest
    ) -> None:
        if change in self.diverging_changes:
            request.applymarker(pytest.mark.xfail(reason=self.diverging_changes[change], strict=True))

        def apply(world: Backend) -> None:
            if change == "mass":
                for link in robot.link_names:
                    if world.link_mass(link) > 0:
                        world.set_link_mass(link, 3.0 * world.link_mass(link))
            for joint in robot.joint_names:
                if change == "damping":
                    world.set_joint_damping(joint, 20.0 * world.joint_damping(joint) + 1.0)
                elif change == "friction":
                    world.set_joint_friction(joint, 2.0 * world.effort_limit(joint))
                elif change == "gain":
                    world.set_servo_gain(joint, 0.3)
                elif change == "effort":
                    world.set_effort_limit(joint, 0.1 * world.effort_limit(joint))
                elif change == "armature":
                    world.set_joint_armature(joint, world.joint_armature(joint) + 2.0)

        diverged: list[int] = []  # the steps of the changed world that went unstable

        def motion(world: Backend) -> np.ndarray[tuple[int, ...], np.dtype[np.float64]]:
            world.reset_joints(robot.home)
            for step in range(20):
                world.set_joint_targets(robot.clip(world.joint_state()[0] + 0.05))
                world.step()
                if world is changed and (world.diverged() or not np.isfinite(world.joint_state()[1]).all()):
                    diverged.append(step)
            return world.joint_state()[0]

        changed, other = engine(robot, PhysicsConfig()), engine(robot, PhysicsConfig())
        try:
            try:
                apply(changed)
            except (NotImplementedError, ConfigError):  # ConfigError: the engine cannot represent it
                pytest.skip(f"backend {self.backend!r} cannot change {change}")
            effect = np.abs(motion(changed) - motion(other)).max()
            least = self.bounds.change_effect_rad.get(change, 1e-3)  # bounds written before armature lack it
            assert effect >= least, f"{change} moved the joints by {effect:.2e} rad"
            assert not diverged, f"the {change} change made the engine diverge at steps {diverged}"
            fresh = engine(robot, PhysicsConfig())
            try:
                np.testing.assert_array_equal(motion(other), motion(fresh))  # the other world is unaffected
            finally:
                fresh.close()
        finally:
            changed.close()
            other.close()

    def test_close_twice_is_safe(self, engine: type[Backend], robot: RobotModel) -> None:
        world = engine(robot, PhysicsConfig())
        world.close()
        world.close()
