"""MuJoCo specifics: the same URDF as PyBullet, kinematic parity, caching, rendering, memory, close.

The engines' dynamic gaps (``armreach parity``'s sequences, per arm and seed) are held in
tests/test_parity.py. Bounds here sit 2-3 times over what was measured, with the
measurement next to each.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from armreach_core import ArmEnv, ArmReach6DOFEnv, URDFError
from armreach_core.backend import Camera, PhysicsConfig
from armreach_core.diagnostics.soak import Bounds, soak_backend
from armreach_core.robot.ik import IKPolicy
from armreach_core.robot.model import RobotModel

mujoco = pytest.importorskip("mujoco")
mjb = pytest.importorskip("armreach_mujoco.backend")
compiled = pytest.importorskip("armreach_mujoco.compiled")
world = pytest.importorskip("armreach_mujoco.world")

pytestmark = pytest.mark.mujoco

AR6_HOME = (0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0.0)


@pytest.fixture(scope="module")
def arms(ar6_urdf: Path, xarm_urdf: Path) -> dict[str, RobotModel]:
    return {
        "ar6": RobotModel(ar6_urdf, ee_link="tool0", home=AR6_HOME),
        "xarm6": RobotModel(xarm_urdf),
    }


def test_plugin_import_does_not_import_mujoco():
    code = "import sys, armreach_mujoco.plugin; assert 'mujoco' not in sys.modules, 'mujoco imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_every_urdf_link_is_a_body_and_markers_are_visual_only(arms):
    backend = mjb.MuJoCoBackend(arms["ar6"], PhysicsConfig())
    backend.add_marker("target", 0.05, (0.9, 0.1, 0.1, 0.8))
    model = backend.model
    for link in arms["ar6"].link_names:
        assert model.body(link).name == link  # KeyError if MuJoCo merged it away
    marker = model.body("armreach_marker_target")
    geom = model.body_geomadr[marker.id]
    assert model.geom_contype[geom] == 0 and model.geom_conaffinity[geom] == 0
    # Bullet's integration: semi-implicit Euler, joint damping explicit
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    assert model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    backend.close()


#: The largest coordinate error of the end effector against the URDF's forward kinematics over
#: 1,000 random configurations, ar6 and xArm6, seeds 7 and 8: MuJoCo 6.7e-16 m (its kinematics are
#: the URDF's, to rounding), PyBullet 8.2e-8 m (xArm6, seed 7). Measured with the test's loop.
FK_ERROR_M = {"mujoco": 2e-15, "pybullet": 2e-7}


@pytest.mark.parametrize("seed", [7, 8])
@pytest.mark.parametrize("arm", ["ar6", "xarm6"])
def test_forward_kinematics_parity_with_pybullet_and_urdf(arms, arm, seed):
    pytest.importorskip("pybullet")
    from armreach_pybullet.backend import PyBulletBackend

    robot = arms[arm]
    physics = PhysicsConfig()
    mj, pb = mjb.MuJoCoBackend(robot, physics), PyBulletBackend(robot, physics)
    configs = robot.sample_configurations(np.random.default_rng(seed), 500)
    reference = robot.forward_kinematics(configs)
    worst_mj = worst_pb = 0.0
    for q, expected in zip(configs, reference, strict=True):
        mj.reset_joints(q)
        pb.reset_joints(q)
        worst_mj = max(worst_mj, float(np.abs(mj.link_position(robot.ee_link) - expected).max()))
        worst_pb = max(worst_pb, float(np.abs(pb.link_position(robot.ee_link) - expected).max()))
    mj.close()
    pb.close()
    assert worst_mj <= FK_ERROR_M["mujoco"], f"MuJoCo FK differs from the URDF by {worst_mj:.2e} m"
    assert worst_pb <= FK_ERROR_M["pybullet"], f"PyBullet FK differs from the URDF by {worst_pb:.2e} m"


def test_both_engines_bound_the_damping_of_light_joints_alike():
    """ar6's wrist joints carry 0.5 N m s/rad of URDF damping on a few grams: both engines bound
    it by M_ii / dt (PyBullet's explicit damping would reverse the joint within a step) and end
    with the same numbers; the heavy joints keep their URDF damping."""
    pytest.importorskip("pybullet")
    dampings = {}
    for name in ("pybullet", "mujoco"):
        env = ArmEnv("reach", backend=name)
        dampings[name] = np.array([env.backend.joint_damping(j) for j in env.robot.joint_names])
        urdf = np.array([j.damping for j in env.robot.joints])
        env.close()
    # measured 8.4e-14 apart: the two engines' M_ii, summed in different orders
    np.testing.assert_allclose(dampings["pybullet"], dampings["mujoco"], rtol=2.5e-13, atol=0)
    bounded = dampings["mujoco"] < urdf
    assert bounded[-1] and not bounded[:4].any()  # wrist 3: 0.5 -> 0.02; shoulder to wrist 1: 0.5


def test_motor_rows_are_the_last_friction_rows():
    """Motors.step writes the reference of the last friction rows: they must be the motor tendons,
    in motor order, with boxes, mimic equalities and joint friction in the model too."""
    pytest.importorskip("armreach_grasp")
    env = ArmEnv("grasp", backend="mujoco")
    env.reset(seed=0)
    backend = env.backend
    backend.set_joint_friction(backend.robot.joint_names[0], 0.5)  # a dof friction row before them
    model, data, shared = backend.model, backend.data, backend.compiled
    from armreach_mujoco.servo import MOTOR_PREFIX

    motors = np.concatenate((shared.motors, shared.held_motors))
    # one motor per actuated joint and per held joint with a servo of its own, in that order
    assert len(shared.motors) == backend.robot.dof and len(shared.held_motors) == len(shared.held_servos)
    names = [model.tendon(m).name for m in motors]
    held = [backend.robot.held_joints[i].name for i in shared.held_servos]
    assert names == [MOTOR_PREFIX + joint for joint in (*backend.robot.joint_names, *held)]
    mujoco.mj_step1(model, data)
    first = data.ne + data.nf - len(motors)
    rows = slice(first, first + len(motors))
    assert np.all(data.efc_type[rows] == mujoco.mjtConstraint.mjCNSTR_FRICTION_TENDON)
    np.testing.assert_array_equal(data.efc_id[rows], motors)
    np.testing.assert_allclose(data.efc_frictionloss[rows], model.tendon_frictionloss[motors])
    env.close()


@pytest.mark.parametrize("timestep", [1 / 240, 1 / 500, 1 / 1000, 0.01])
def test_motor_reference_is_pybullets_law_to_the_bit(ar6_urdf, timestep):
    """MuJoCo computes the motor rows' -v/dt itself (their solref) and Motors adds the position
    term: the reference a physics step used must be the bits of (offset - k q) - v/dt, the formula
    written out in numpy, for any timestep, or trajectories change."""
    robot = RobotModel(ar6_urdf, ee_link="tool0", home=AR6_HOME)
    backend = mjb.MuJoCoBackend(robot, PhysicsConfig(timestep=timestep, visuals=False))
    model, data, motors = backend.model, backend.data, backend._io.motors
    rng = np.random.default_rng(0)
    n = len(motors.qvel)
    stiffness = motors.gains / (timestep * timestep)
    for _ in range(20):
        data.qvel[motors.qvel] = rng.normal(0.0, 2.0, n)
        motors.targets[:] = data.qpos[motors.qpos] + rng.uniform(-0.05, 0.05, n)
        q, v = data.qpos[motors.qpos], data.qvel[motors.qvel]  # copies, before the step
        want = (stiffness * motors.targets - stiffness * q) - v * (1.0 / timestep)
        motors.step(model, data, 1)
        first = data.ne + data.nf - n  # mj_step2 solves with the reference and leaves it in place
        np.testing.assert_array_equal(data.efc_aref[first : first + n], want)
    backend.close()


def test_a_motor_pushes_with_its_effort_and_no_more():
    """A joint asked to move further than its effort allows moves as PyBullet's does."""
    pytest.importorskip("pybullet")
    from armreach_core.robot.statics import gravity_torques

    finals = {}
    for name in ("pybullet", "mujoco"):
        env = ArmEnv("reach", backend=name)
        env.reset(seed=0)
        torques = np.abs(gravity_torques(env.robot, env.robot.home))
        joint = int(np.argmax(torques))
        env.backend.set_effort_limit(env.robot.joint_names[joint], 0.5 * torques[joint])  # cannot hold the arm up
        for _ in range(20):
            env.backend.set_joint_targets(env.robot.home)
            env.backend.step()
        finals[name] = env.backend.read_state().q
        env.close()
    # measured: PyBullet's joint sags 0.720 rad, MuJoCo's 0.721; the engines end 1.63e-3 rad apart
    sag = abs(finals["pybullet"][joint] - env.robot.home[joint])
    assert 0.36 < sag < 1.44, f"sagged {sag:.3f} rad"
    np.testing.assert_allclose(finals["mujoco"], finals["pybullet"], rtol=0, atol=3e-3)


def test_contact_friction_is_bullets_product():
    world_ = pytest.importorskip("armreach_mujoco.world")
    robot = RobotModel(Path(__file__).parents[1] / "assets" / "ar6" / "ar6.urdf", ee_link="tool0", home=AR6_HOME)
    backend = mjb.MuJoCoBackend(robot, PhysicsConfig())
    backend.add_box("cube", (0.02, 0.02, 0.02), 0.1, friction=0.8)
    backend.set_friction("wrist_3_link", 1.2)
    model = backend.model
    seen = set()
    for pair in range(model.npair):
        names = {model.geom(model.pair_geom1[pair]).name, model.geom(model.pair_geom2[pair]).name}
        bodies = {
            model.body(model.geom_bodyid[model.pair_geom1[pair]]).name,
            model.body(model.geom_bodyid[model.pair_geom2[pair]]).name,
        }
        ground = world_.GROUND in names
        cube = world_.BODY_PREFIX + "cube" in names
        link = 1.2 if "wrist_3_link" in bodies else world_.DEFAULT_FRICTION
        expected = (
            0.8 * world_.DEFAULT_FRICTION
            if ground and cube
            else (link * world_.DEFAULT_FRICTION if ground else 0.8 * link)
        )
        assert model.pair_friction[pair, 0] == pytest.approx(expected), (names, bodies)
        seen.add((ground, cube))
    assert seen == {(True, False), (False, True), (True, True)}
    # links fixed to the world get no ground pair (as MuJoCo's and Bullet's own filters)
    for pair in range(model.npair):
        geoms = (model.pair_geom1[pair], model.pair_geom2[pair])
        names = [model.geom(g).name for g in geoms]
        if world_.GROUND in names and world_.BODY_PREFIX + "cube" not in names:
            arm_geom = geoms[1 - names.index(world_.GROUND)]
            assert model.body(model.geom_bodyid[arm_geom]).name not in robot.fixed_links
    backend.close()


def test_links_in_contact_agree_with_pybullet():
    pytest.importorskip("pybullet")
    touching = {}
    for name in ("pybullet", "mujoco"):
        env = ArmEnv("reach", backend=name)
        env.reset(seed=0)
        assert env.backend.links_in_contact() == ()  # home is clear of the ground; the base is not counted
        rng = np.random.default_rng(0)
        for step in range(200):
            env.step(np.clip(rng.normal(0.3, 0.5, env.robot.dof), -1, 1))
            links = env.backend.links_in_contact()
            if links:
                touching[name] = (step, links)
                break
        env.close()
    assert touching["pybullet"] == touching["mujoco"] and touching["mujoco"][1]


@pytest.mark.parametrize("seed", [0, 1])
def test_scripted_reach_succeeds(seed):
    """The IK policy reaches the target: measured in 12 and 17 steps (seeds 0 and 1)."""
    env = ArmReach6DOFEnv(backend="mujoco")
    obs, info = env.reset(seed=seed)
    policy = IKPolicy.for_env(env.unwrapped)
    for _ in range(40):
        obs, _, terminated, _, info = env.step(policy.act(obs[:6], obs[9:12]))
        if terminated:
            break
    env.close()
    assert info["is_success"], f"IK reach ended {info['distance']:.3f} m from the target after 40 steps"


@pytest.mark.parametrize("seed", [0, 1])
def test_holds_home_pose_against_gravity(seed):
    env = ArmReach6DOFEnv(backend="mujoco")
    env.reset(seed=seed)
    for _ in range(50):
        obs, *_ = env.step(np.zeros(6, dtype=np.float32))
    # measured 4.7e-5 rad off home after 50 steps (seeds 0 and 1)
    np.testing.assert_allclose(obs[:6], env.unwrapped.robot.home, rtol=0, atol=1.2e-4)
    env.close()


@pytest.mark.alone
def test_env_creation_is_cached_and_cheap():
    """An env of an arm already compiled skips the compile: measured 1.3-1.6 ms against 5.3-6.1 ms
    after ``compiled.clear_cache()`` (3.8-4.0 times as long), three runs of this test's timing."""

    def build_seconds(clear: bool) -> float:
        if clear:
            compiled.clear_cache()
        start = time.perf_counter()
        ArmReach6DOFEnv(backend="mujoco").close()
        return time.perf_counter() - start

    uncached = min(build_seconds(clear=True) for _ in range(3))
    cached = sum(build_seconds(clear=False) for _ in range(10)) / 10
    assert cached * 1.3 < uncached, f"a cached env took {cached * 1e3:.2f} ms, an uncached one {uncached * 1e3:.2f} ms"


#: RSS growth over 30 MuJoCo env create/reset/step/close cycles after soak's warm-up: measured
#: +0.00 MB over 30, 100 and 300 cycles with seeds 0, 1 and 2 (``soak_backend("mujoco", steps=0,
#: cycles=30, seed=s).cycles.rss_growth_mb``), where RSS moves in allocator steps (-1.36 MB seen in
#: a fresh process). An env left open holds 0.4 MB: never closing them grows RSS by 11-13 MB over
#: the same 30 cycles, which the bound catches.
CYCLE_RSS_MB = 2.0


def test_create_close_cycles_keep_memory_flat():
    report = soak_backend("mujoco", steps=0, cycles=30, seed=0, bounds=Bounds(cycles_rss_mb=CYCLE_RSS_MB))
    cycles = report.cycles
    assert cycles is not None and cycles.cycles == 30
    assert report.passed, report.failures
    assert cycles.fds_growth == 0


def test_self_collision_switch(ar6_urdf):
    robot = RobotModel(ar6_urdf, ee_link="tool0", home=AR6_HOME)
    off = mjb.MuJoCoBackend(robot, PhysicsConfig(self_collision=False)).model
    on = mjb.MuJoCoBackend(robot, PhysicsConfig(self_collision=True)).model
    arm = [g for g in range(off.ngeom) if off.geom_contype[g] == world.ARM_CONTYPE]
    assert arm and all(not (off.geom_contype[g] & off.geom_conaffinity[g]) for g in arm)
    assert all(on.geom_contype[g] & on.geom_conaffinity[g] for g in arm)
    assert on.nexclude >= len(robot.joint_names)
    env = ArmReach6DOFEnv(backend="mujoco", self_collision=True)
    env.reset(seed=0)
    assert env.unwrapped.backend.data.ncon == 0  # base<->shoulder overlap is excluded
    env.close()


def test_close_is_idempotent_and_isolated():
    env_a, env_b = ArmReach6DOFEnv(backend="mujoco"), ArmReach6DOFEnv(backend="mujoco")
    assert env_a.unwrapped.backend.data is not env_b.unwrapped.backend.data
    env_a.reset(seed=1)
    env_b.reset(seed=1)
    env_a.step(np.ones(6, dtype=np.float32))
    assert not np.array_equal(env_a.unwrapped.backend.data.qpos, env_b.unwrapped.backend.data.qpos)
    backend = env_a.unwrapped.backend
    env_a.close()
    env_a.close()
    backend.close()
    env_b.close()


@pytest.mark.parametrize("seed", [0, 1])
def test_read_state_is_one_snapshot(seed):
    """The end effector comes from the joint angles read with it (links brought up to qpos after the step)."""
    env = ArmReach6DOFEnv(backend="mujoco")
    robot, backend = env.unwrapped.robot, env.unwrapped.backend
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    worst = 0.0
    for _ in range(50):
        obs, *_ = env.step(env.action_space.sample())
        state = backend.read_state()
        np.testing.assert_array_equal(obs[6:9], state.ee_pos.astype(np.float32))
        worst = max(worst, float(np.abs(state.ee_pos - robot.forward_kinematics(state.q)).max()))
    env.close()
    # measured 3.3e-16 m (seeds 0 and 1 of the actions)
    assert worst <= 1e-15, f"the end effector differs from the URDF kinematics of q by {worst:.2e} m"


def _model_bytes(model) -> bytes:
    buffer = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return buffer.tobytes()


def test_rendering_never_writes_the_shared_model():
    """Env B renders with another camera (field of view, a framebuffer larger than the model's): A is unchanged."""
    env_a = ArmReach6DOFEnv(backend="mujoco", render_mode="rgb_array")
    wide = Camera(fov=25.0, width=800, height=600)
    env_b = ArmReach6DOFEnv(backend="mujoco", render_mode="rgb_array", camera=wide)
    model = env_a.unwrapped.backend.model
    assert env_b.unwrapped.backend.model is model  # one compiled model for both
    before = _model_bytes(model)
    env_a.reset(seed=0)
    env_b.reset(seed=0)
    frame_a = env_a.render()
    frame_b = env_b.render()
    assert frame_b.shape == (600, 800, 3)
    env_b.step(np.ones(6, dtype=np.float32))
    env_b.render()
    assert _model_bytes(model) == before
    np.testing.assert_array_equal(env_a.render(), frame_a)
    assert frame_a.shape == (360, 480, 3)
    env_a.close()
    env_b.close()
    assert _model_bytes(model) == before


def test_compiled_addresses_are_read_only(arms):
    backend = mjb.MuJoCoBackend(arms["ar6"], PhysicsConfig())
    shared = backend.compiled
    for index in (shared.qpos, shared.qvel, shared.motors):
        with pytest.raises(ValueError, match="read-only"):
            index[0] = 0
    with pytest.raises(TypeError):
        shared.bodies["extra"] = 0
    backend.close()


# -- meshes MuJoCo cannot read (.ply, .dae): converted to .obj with trimesh into a cache folder

#: (link, mesh file, box extents in m, origin z in m) of the arm written by _write_mesh_arm. The
#: ``{ext}`` meshes are converted for MuJoCo; base.stl is read by MuJoCo (and PyBullet) itself.
MESH_LINKS = (
    ("base_link", "../meshes/base.stl", (0.12, 0.12, 0.06), 0.03),
    ("link2", "../meshes/upper.{ext}", (0.08, 0.08, 0.2), 0.1),  # relative to the URDF's folder
    ("link3", "package://testarm/meshes/fore.{ext}", (0.06, 0.06, 0.2), 0.1),
)
#: The mesh arm's end effector against the URDF's kinematics, after steps and over configurations
#: (seeds 7 and 8): measured MuJoCo 2.2e-16 m, PyBullet 2.7e-8 m (the test's loops, printing the max).
MESH_FK_ERROR_M = {"mujoco": 6e-16, "pybullet": 7e-8}
#: A PLY file that trimesh parses but that holds no surface.
EMPTY_PLY = (
    b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
    b"element face 0\nproperty list uchar int vertex_indices\nend_header\n"
)


def _write_mesh_arm(root: Path, ext: str) -> Path:
    """A 6-joint serial arm laid out like a ROS package (``root/testarm/{urdf,meshes}``).

    The links of MESH_LINKS have the same box mesh as visual and collision geometry; the
    others are cylinders. Returns the URDF's path; its end effector is ``tool0``.
    """
    trimesh = pytest.importorskip("trimesh")
    if ext == "dae":
        pytest.importorskip("collada")  # trimesh reads and writes COLLADA through pycollada
    package = root / "testarm"
    (package / "urdf").mkdir(parents=True)
    (package / "meshes").mkdir()

    def inertial(z: float) -> str:
        return (
            f'<inertial><origin xyz="0 0 {z}"/><mass value="1.0"/>'
            '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'
        )

    def shapes(geometry: str, z: float) -> str:
        return "".join(
            f'<{tag}><origin xyz="0 0 {z}"/><geometry>{geometry}</geometry></{tag}>' for tag in ("visual", "collision")
        )

    links = {f"link{i}": inertial(0.05) + shapes('<cylinder radius="0.03" length="0.1"/>', 0.05) for i in range(1, 7)}
    for name, filename, extents, z in MESH_LINKS:
        filename = filename.format(ext=ext)
        trimesh.creation.box(extents=extents).export(package / "meshes" / Path(filename).name)
        links[name] = inertial(z) + shapes(f'<mesh filename="{filename}"/>', z)
    chain = (  # joint, parent, child, origin z, axis
        ("joint1", "base_link", "link1", 0.06, "0 0 1"),
        ("joint2", "link1", "link2", 0.1, "0 1 0"),
        ("joint3", "link2", "link3", 0.2, "0 1 0"),
        ("joint4", "link3", "link4", 0.2, "0 0 1"),
        ("joint5", "link4", "link5", 0.1, "0 1 0"),
        ("joint6", "link5", "link6", 0.1, "0 0 1"),
    )
    joints = "".join(
        f'<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
        f'<origin xyz="0 0 {z}"/><axis xyz="{axis}"/>'
        '<limit lower="-2.5" upper="2.5" effort="50" velocity="3"/><dynamics damping="0.5"/></joint>'
        for name, parent, child, z, axis in chain
    )
    urdf = package / "urdf" / "testarm.urdf"
    urdf.write_text(
        '<?xml version="1.0"?>\n<robot name="testarm">\n'
        '<link name="world"/>\n<joint name="world_joint" type="fixed"><parent link="world"/>'
        '<child link="base_link"/></joint>\n'
        + "".join(f'<link name="{name}">{body}</link>\n' for name, body in sorted(links.items()))
        + joints
        + '\n<link name="tool0"><inertial><mass value="0.001"/>'
        '<inertia ixx="1e-6" ixy="0" ixz="0" iyy="1e-6" iyz="0" izz="1e-6"/></inertial></link>\n'
        '<joint name="tool0_joint" type="fixed"><parent link="link6"/><child link="tool0"/>'
        '<origin xyz="0 0 0.1"/></joint>\n</robot>\n'
    )
    return urdf


def _worst_fk_error(backend, robot: RobotModel, configs) -> float:
    """Largest end-effector gap (m) between ``backend`` and the URDF's kinematics over ``configs``."""
    worst = 0.0
    for q, expected in zip(configs, robot.forward_kinematics(configs), strict=True):
        backend.reset_joints(q)
        worst = max(worst, float(np.abs(backend.link_position(robot.ee_link) - expected).max()))
    return worst


@pytest.fixture
def mesh_cache(tmp_path, monkeypatch) -> Iterator[Path]:
    """The converted-mesh folder, under tmp_path; the models built meanwhile are forgotten afterwards."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    yield tmp_path / "cache" / "armreach" / "meshes"
    compiled.clear_cache()  # they name files under tmp_path


@pytest.mark.parametrize("ext", ["ply", "dae"])
def test_meshes_mujoco_cannot_read_are_converted_and_cached(tmp_path, mesh_cache, monkeypatch, ext):
    urdf = _write_mesh_arm(tmp_path, ext)
    import trimesh

    # PyBullet reads .dae (and .stl) itself, and is handed .ply meshes converted too
    backends = ["mujoco", "pybullet"]
    pytest.importorskip("pybullet")
    for name in backends:
        # rendering: the visual meshes are loaded (and converted) too
        env = ArmReach6DOFEnv(backend=name, urdf=urdf, ee_link="tool0", render_mode="rgb_array")
        robot, backend = env.unwrapped.robot, env.unwrapped.backend
        assert robot.dof == 6
        obs, _ = env.reset(seed=3)
        assert np.isfinite(obs).all()
        env.action_space.seed(3)
        for _ in range(5):
            obs, reward, *_ = env.step(env.action_space.sample())
            assert np.isfinite(obs).all() and np.isfinite(reward)
            q, _ = backend.joint_state()
            np.testing.assert_allclose(
                backend.link_position("tool0"), robot.forward_kinematics(q), rtol=0, atol=MESH_FK_ERROR_M[name]
            )
        configs = np.vstack([robot.home, robot.sample_configurations(np.random.default_rng(7), 8)])
        worst = _worst_fk_error(backend, robot, configs)
        assert worst <= MESH_FK_ERROR_M[name], f"{name} FK differs from the URDF by {worst:.2e} m"
        if name == "mujoco":
            model = backend.model
            assert model.nmesh == 6  # three visual meshes and their three convex hulls for collisions
            assert int(np.sum(model.geom_type == mujoco.mjtGeom.mjGEOM_MESH)) == 6
        env.close()

    # one .obj per converted mesh (<stem>-<digest>.obj), the same box as the original; base.stl is used as it is
    converted = {path.name.split("-")[0]: path for path in mesh_cache.glob("*.obj")}
    assert sorted(converted) == ["fore", "upper"]
    assert sorted(p.suffix for p in mesh_cache.glob("*.obj")) == [".obj", ".obj"]
    assert not list(mesh_cache.glob("*.mtl"))  # no shared material file
    for _, filename, extents, _ in MESH_LINKS[1:]:
        mesh = trimesh.load(converted[Path(filename).stem], force="mesh")
        np.testing.assert_allclose(mesh.extents, extents, atol=1e-9)

    # converted once: a fresh build reads the cached .obj files without trimesh
    stamps = {path: path.stat().st_mtime_ns for path in converted.values()}
    compiled.clear_cache()

    def no_conversion(*args, **kwargs):
        raise AssertionError("the mesh was converted again")

    monkeypatch.setattr(trimesh, "load", no_conversion)
    robot = RobotModel(urdf, ee_link="tool0")
    mjb.MuJoCoBackend(robot, PhysicsConfig()).close()
    assert {path: path.stat().st_mtime_ns for path in converted.values()} == stamps


@pytest.mark.parametrize(
    ("ext", "stem", "content"),
    [
        ("ply", "upper", b"\x00not a mesh\xff" * 8),  # referenced by a relative path
        ("ply", "upper", EMPTY_PLY),  # parses, but MuJoCo would reject the empty copy
        ("dae", "fore", b"\x00not a mesh\xff" * 8),  # referenced through package://
    ],
    ids=["garbage-ply", "empty-ply", "garbage-dae"],
)
def test_unreadable_mesh_is_a_urdf_error_naming_the_file(tmp_path, mesh_cache, ext, stem, content):
    urdf = _write_mesh_arm(tmp_path, ext)
    bad = (urdf.parent.parent / "meshes" / f"{stem}.{ext}").resolve()
    bad.write_bytes(content)
    with pytest.raises(URDFError, match=re.escape(repr(str(bad)))) as caught:
        ArmReach6DOFEnv(backend="mujoco", urdf=urdf, ee_link="tool0")
    assert "convert it to .stl or .obj" in str(caught.value)
    assert not list(mesh_cache.glob(f"{stem}-*"))  # nothing half-written is left to be reused


#: Two fingers under the hand of tests.test_robot's arm: ``a`` actuated (a tool joint), ``b`` following it.
FINGER_A = (
    '<joint name="a" type="prismatic"><parent link="hand"/><child link="left"/>'
    '<limit lower="0.01" upper="0.04" effort="5" velocity="1"/></joint>'
)
FINGER_B = (
    '<joint name="b" type="prismatic"><parent link="hand"/><child link="right"/>'
    '<limit lower="-0.1" upper="0.1" effort="5" velocity="1"/><mimic joint="a" multiplier="-2" offset="0.03"/></joint>'
)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_motor_joints_layout_in_the_state_does_not_change_the_physics(tmp_path, seed):
    """The same arm written with its fingers in either order: with ``a`` first the motor joints
    are contiguous in ``qpos`` (the motors read views of the state), with ``b`` first they are
    not (the motors gather them). The motion is the same to rounding: measured 3.9e-15 (seed 0)
    and 5.7e-15 (seed 1) apart over 30 steps, printing the largest difference below."""
    from tests.test_robot import _arm

    runs, layouts = {}, {}
    for order, tail, links in (
        ("ab", FINGER_A + FINGER_B, ("left", "right")),
        ("ba", FINGER_B + FINGER_A, ("right", "left")),
    ):
        folder = tmp_path / order
        folder.mkdir()
        robot = RobotModel(_arm(folder, tail, links), home=[0.1, 0.2, 0.3, 0.02], tool_joints=("a",))
        backend = mjb.MuJoCoBackend(robot, PhysicsConfig())
        shared = backend.compiled
        layouts[order] = np.concatenate((shared.qpos, shared.held_qpos[shared.held_servos]))
        backend.reset_joints(robot.home)
        rng = np.random.default_rng(seed)
        states = []
        for _ in range(30):
            backend.set_joint_targets(robot.clip(backend.joint_state()[0] + rng.uniform(-0.05, 0.05, robot.dof)))
            backend.step()
            states.append(np.concatenate(backend.joint_state()))
        backend.close()
        runs[order] = np.array(states)
    np.testing.assert_array_equal(layouts["ab"], [0, 1, 2, 3])  # contiguous
    np.testing.assert_array_equal(layouts["ba"], [0, 1, 2, 4])  # b's slot in between
    assert np.ptp(runs["ab"][:, :4], axis=0).min() > 0.01  # every motor joint moved
    np.testing.assert_allclose(runs["ba"], runs["ab"], rtol=0, atol=1.5e-14)


def test_a_mimic_follows_an_actuated_master_and_is_welded_or_held_by_its_own_motor_otherwise(tmp_path):
    """As in PyBullet: a mimic of a joint the arm actuates follows it (a joint equality, no
    motor); a mimic of a held joint is welded where it is held, its link where the URDF's
    kinematics put it, or, without ``rigid_held_joints`` (before ``Reach-v4``), held by a
    motor of its own."""
    from armreach_mujoco.servo import MOTOR_PREFIX
    from tests.test_robot import _arm

    tail = (
        '<joint name="a" type="prismatic"><parent link="hand"/><child link="left"/>'
        '<limit lower="0.01" upper="0.04" effort="5" velocity="1"/></joint>'
        '<joint name="b" type="prismatic"><parent link="hand"/><child link="right"/>'
        '<limit lower="-0.1" upper="0.1" effort="5" velocity="1"/>'
        '<mimic joint="a" multiplier="-2" offset="0.03"/></joint>'
    )
    path = _arm(tmp_path, tail, ("left", "right"))
    held_master = RobotModel(path, home=[0.1, 0.2, 0.3])
    actuated_master = RobotModel(path, home=[0.1, 0.2, 0.3, 0.02], tool_joints=("a",))
    cases = (
        (held_master, PhysicsConfig(), "welded"),
        (held_master, PhysicsConfig(rigid_held_joints=False), "motor"),
        (actuated_master, PhysicsConfig(), "tied"),
    )
    for robot, physics, how in cases:
        backend = mjb.MuJoCoBackend(robot, physics)
        model = backend.model
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "b")
        motor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TENDON, MOTOR_PREFIX + "b") >= 0
        tied = any(model.eq_type[i] == mujoco.mjtEq.mjEQ_JOINT and model.eq_obj1id[i] == b for i in range(model.neq))
        backend.reset_joints(robot.home)
        right = backend.link_position("right")
        backend.close()
        want = {"welded": (False, False, False), "motor": (True, True, False), "tied": (True, False, True)}[how]
        assert (b >= 0, motor, tied) == want
        np.testing.assert_allclose(right, robot.link_transforms(robot.home)["right"][:3, 3], atol=1e-9)
