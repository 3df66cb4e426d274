"""The world a backend starts from: the physics settings, the ground, and the arm loaded from its URDF."""

from __future__ import annotations

import os
import tempfile

from armreach_core.backend import PhysicsConfig
from armreach_core.errors import URDFError
from armreach_core.robot.hulls import simulation_urdf
from armreach_core.robot.meshes import readable
from armreach_core.robot.model import RobotModel
from armreach_core.robot.weld import weld
from armreach_pybullet.engine import engine_output_to_log, pb
from armreach_pybullet.merge import Merged, merge_fixed, unmerged
from armreach_pybullet.weld import welded_joints

#: Sweeps of Bullet's projected Gauss-Seidel solver per physics step (PyBullet's default is 50).
#: Bullet stops once the solution stops changing, so an arm in free space usually needs far
#: fewer; 50 left the motors of an arm with aligned joint axes (xArm7) and links pressed on the
#: ground (Kinova, SO-101) up to 3 cm from the solution, an error of the solver rather than of
#: the physics. 200 comes within 1-3 mm of 1,000 (docs/mujoco-backend.md, "Solver").
SOLVER_ITERATIONS = 200
GROUND_RGBA = (0.86, 0.87, 0.89, 1.0)
#: Half the width of the ground slab (m): far past any arm's reach (KR210's is 3.3 m).
GROUND_HALF_EXTENT = 100.0
#: Depth of the ground slab below z = 0 (m): no link goes through it in one physics step.
GROUND_DEPTH = 1.0
#: Mesh formats PyBullet's URDF loader reads; others are converted to .obj (armreach_core.robot.meshes).
PYBULLET_MESHES = (".obj", ".stl", ".dae")

#: Drag on the arm's links (PyBullet's ``linearDamping`` and ``angularDamping``) unless
#: ``PhysicsConfig.engine_drag`` keeps Bullet's default, 0.04 (a float), which slows every
#: moving link by ``0.04 (1 + |v|) v`` (and its rotation likewise), a force no URDF states and
#: MuJoCo does not apply. While the motors hold their targets it is invisible (they are velocity
#: constraints), but a motor at its effort yields to it: on the KUKA KR16 under the parity's
#: biased actions the engines parted by 13 mm in free space with it and by 0.02 mm without
#: (docs/parity.md, "Heavy arms").
LINK_DRAG = 0.0

#: A body's base pose as PyBullet takes it: position, quaternion (x, y, z, w).
Pose = tuple[list[float], list[float]]


def load_failure(robot: RobotModel, detail: str) -> str:
    """Why PyBullet refused a URDF that armreach's own parser accepted, and what to do."""
    return (
        f"PyBullet cannot load the arm {robot.name!r} ({robot.urdf_path}): {detail}; check the meshes and "
        "elements it names (every mesh was handed over as .obj, .stl or .dae), or try the mujoco backend"
    )


def build_world(cid: int, physics: PhysicsConfig) -> None:
    """Gravity, time step and constraint solver of client ``cid``, and the ground when ``physics`` has one.

    The solver is Bullet's direct one (Dantzig's MLCP), which solves the motors' and contacts'
    rows exactly in one pass, unless ``physics.iterative_solver`` keeps projected Gauss-Seidel.
    Gauss-Seidel needs up to :data:`SOLVER_ITERATIONS` sweeps where joints are nearly coaxial or
    links rest on the ground (xArm7, the KR16, the Panda: 0.37-0.49 of ar6's env steps/s),
    and it converges to the same motion (docs/benchmarks.md, "Detailed and heavy arms").

    With ``physics.bounded_ground`` the ground is a slab whose top face is the plane z = 0
    (:data:`GROUND_HALF_EXTENT` m to each side, :data:`GROUND_DEPTH` m deep) rather than
    Bullet's infinite plane: a plane's bounding box holds every link, so every physics step
    tested each link's hulls against it, on a detailed arm most of the step's collision time
    (Vega: 24 of 40 µs); the slab's box meets only links that come down to it.
    """
    pb.setGravity(*physics.gravity, physicsClientId=cid)
    pb.setTimeStep(physics.timestep, physicsClientId=cid)
    pb.setPhysicsEngineParameter(numSolverIterations=SOLVER_ITERATIONS, physicsClientId=cid)
    if not physics.iterative_solver:
        with engine_output_to_log():  # Bullet prints which solver it switched to
            pb.setPhysicsEngineParameter(constraintSolverType=pb.CONSTRAINT_SOLVER_LCP_DANTZIG, physicsClientId=cid)
    if physics.ground:
        if physics.bounded_ground:
            shape = pb.createCollisionShape(
                pb.GEOM_BOX,
                halfExtents=[GROUND_HALF_EXTENT, GROUND_HALF_EXTENT, GROUND_DEPTH / 2],
                collisionFramePosition=[0.0, 0.0, -GROUND_DEPTH / 2],
                physicsClientId=cid,
            )
        else:
            shape = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=cid)
        visual = pb.createVisualShape(
            pb.GEOM_BOX, halfExtents=[1.5, 1.5, 0.001], rgbaColor=GROUND_RGBA, physicsClientId=cid
        )
        pb.createMultiBody(0.0, shape, visual, basePosition=[0, 0, 0], physicsClientId=cid)


def load_robot(cid: int, robot: RobotModel, physics: PhysicsConfig) -> tuple[int, Pose, Merged]:
    """Load ``robot`` into client ``cid`` at its base pose, with a fixed base: its body id, that
    pose, and where its links went.

    Held joints are welded at their hold positions (:mod:`armreach_pybullet.weld`), and links
    fixed to another are merged into it (:mod:`armreach_pybullet.merge`).

    Raises:
        URDFError: PyBullet refused the URDF (the client is then disconnected).
    """
    flags = 0
    if physics.inertia_from_file:
        flags |= pb.URDF_USE_INERTIA_FROM_FILE
    if physics.self_collision:
        flags |= pb.URDF_USE_SELF_COLLISION | pb.URDF_USE_SELF_COLLISION_EXCLUDE_PARENT
    w, x, y, z = robot.base_orientation
    base_pose = (list(robot.base_position), [x, y, z, w])  # PyBullet's quaternions are (x, y, z, w)
    with tempfile.TemporaryDirectory(prefix="armreach-") as tmp:
        path = os.path.join(tmp, "robot.urdf")
        with open(path, "wb") as handle:
            urdf = simulation_urdf(robot, visuals=physics.visuals, max_vertices=physics.hull_vertices)
            urdf = weld(urdf, robot, welded_joints(robot, physics))
            urdf, merged = merge_fixed(urdf) if physics.merge_fixed_links else (urdf, unmerged(urdf))
            handle.write(readable(urdf, PYBULLET_MESHES))
        try:
            with engine_output_to_log():
                body = pb.loadURDF(
                    path,
                    basePosition=base_pose[0],
                    baseOrientation=base_pose[1],
                    useFixedBase=True,
                    flags=flags,
                    physicsClientId=cid,
                )
        except pb.error as exc:
            pb.disconnect(physicsClientId=cid)
            raise URDFError(load_failure(robot, str(exc))) from None
    if body < 0:
        pb.disconnect(physicsClientId=cid)
        raise URDFError(load_failure(robot, "loadURDF returned no body"))
    # Bullet drags every link of a multibody by default; the URDF states no such drag and MuJoCo
    # applies none, so the arm gets none (see LINK_DRAG)
    if not physics.engine_drag:  # else Bullet's own default stays, bit for bit (a float 0.04)
        pb.changeDynamics(body, -1, linearDamping=LINK_DRAG, angularDamping=LINK_DRAG, physicsClientId=cid)
    return int(body), base_pose, merged


__all__ = [
    "GROUND_DEPTH",
    "GROUND_HALF_EXTENT",
    "GROUND_RGBA",
    "LINK_DRAG",
    "PYBULLET_MESHES",
    "SOLVER_ITERATIONS",
    "Pose",
    "build_world",
    "load_failure",
    "load_robot",
]
