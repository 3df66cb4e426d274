"""MuJoCo adapter: the model is built from the same URDF with ``mujoco.MjSpec``; joints and links by URDF name.

Model
    The resolved URDF (mesh paths already absolute) gets a ``<mujoco><compiler/></mujoco>``
    block (``balanceinertia``, ``strippath=false``, ``discardvisual=false``,
    ``fusestatic=false``, so every URDF link, ``tool0`` included, stays a body whose frame
    is the link frame) and is compiled by MuJoCo's own URDF importer. Meshes MuJoCo cannot
    read (``.dae``, ...) are converted to ``.obj`` with trimesh into a cache folder.
    Everything else is added through MjSpec: timestep, gravity, the ``implicitfast``
    integrator, joint damping from the URDF (URDF ``friction`` is dropped, as PyBullet
    ignores it), one position actuator per joint, the ground plane and the markers
    (mocap bodies with a visual-only sphere). Compiled models are cached per (URDF file,
    modification time, physics settings, markers, bodies); envs share the read-only ``MjModel``
    and each gets its own ``MjData``.

Position control, matched to PyBullet
    PyBullet's ``POSITION_CONTROL`` motor is a velocity-level constraint: each physics step
    it asks for the joint velocity ``positionGain * (target - q) / dt`` (``velocityGain``
    1 cancels the current velocity) and solves for it with at most the URDF effort. The
    arm therefore holds its pose against gravity exactly and closes 20 % of the remaining
    error per physics step. MuJoCo reproduces this with

    * PyBullet's URDF reader gives a moving link without ``<inertial>`` (a bare ``tool0``)
      1 kg and 1 kg m^2 on each axis, which adds ~1 kg m^2 to every joint's inertia; this
      backend does the same (:data:`MISSING_INERTIAL`), without which light wrists move
      ~50x faster than in PyBullet (the bundled ar6 now gives ``tool0`` a 1 g inertial, and
      xarm6 has none missing, so neither needs it);
    * a position actuator forming a velocity servo ``force = kv * (lambda * (target - q) - qd)``
      with ``lambda = POSITION_GAIN / dt`` (``kp = kv * lambda``) and
      ``kv = SERVO_DAMPING * M_ii(home) / dt``. A true constraint is ``kv -> inf``; but MuJoCo
      clamps the force *before* the implicit integrator divides it by ``1 + kv dt / M``, so
      a large ``kv`` clamps too early and chatters (bang-bang). ``kv = 2 M/dt`` was the best
      compromise;
    * gravity compensation routed through the actuators (``gravcomp`` on the arm's bodies,
      ``actuatorgravcomp`` on its joints), so the servo holds the pose like PyBullet's motor
    (added bodies get no gravity compensation);
      the joint's ``actuatorfrcrange`` = URDF effort bounds servo + gravity together;
    * armature :data:`ARMATURE` = 0.01 (xarm6's wrist drifts without it; 0.1 is too much);
      ``implicitfast`` integrator.

    Matched with ``armreach parity`` (:mod:`armreach_core.parity`): both backends start at
    home and run the same seeded sequence of actions ``U(-1, 1)`` (targets ``q + 0.05 a``)
    and a closed-loop IK reach to the seeded target, for 200 control steps, on ar6 and
    pybullet_data's xarm6, and on the one-step error (both engines started from PyBullet's
    state at every step of those runs). Searched: ``SERVO_DAMPING`` 1-4 (and per joint),
    ``SERVO_GAIN_SCALE`` 0.9-1.1, ``ARMATURE`` 0-0.02, with and without the URDF damping
    (PyBullet's motor cancels it), ``kv`` from ``M_ii`` at the current pose every control
    step, and the force limit on the joint (``actuatorfrcrange`` only, ``SERVO_DAMPING``
    2-20). Nothing beat the values above by more than the seed-to-seed spread.
    End-effector RMS gap, seed 0 (mean over seeds 0-9): ar6 random 12.5 mm (11.8),
    ar6 scripted 0.7 mm (1.2), xarm6 random 3.7 mm (5.1), xarm6 scripted 1.6 mm (1.8).
    The remaining gap comes from force saturation:
    PyBullet's motor applies exactly the impulse it needs when that is below the effort
    limit, whereas MuJoCo's servo saturates as soon as ``kv * (lambda e - qd)`` (which
    is ``SERVO_DAMPING`` times the force needed) passes the limit, and then drops the
    implicit damping of that actuator, so joints at the edge of saturation overshoot and
    chatter for a few physics steps. This leaves ~1 mm of end-effector difference per
    control step on ar6 under random actions; the random sequence's targets are
    relative to each engine's own angles, so these add up like a random walk, while the
    closed-loop reach corrects them.

Contacts
    With ``self_collision`` off, the arm's collision geoms collide with the ground and with
    bodies added by :meth:`MuJoCoBackend.add_box` only (contype/conaffinity bits); bodies
    collide with the arm, the ground and each other.

    PyBullet's contacts are rigid; MuJoCo's are soft, so a gripped cube sinks into the
    fingers and slides out of them under default settings. Once a body is added the model
    gets the noslip solver (:data:`NOSLIP_ITERATIONS`) and the bodies' contacts the stiffest
    safe time constant, two physics steps (``solref``, weighted by ``solmix`` over the arm's
    default). Measured with the grasp task's scripted pick (seeds 0-3): without them the
    fingers closed 12 mm into the cube on impact and the lifted cube slid 2.4 mm/s; with
    them a held cube does not slide, but it still sinks 5-9 mm in the grip while it is
    lifted (PyBullet: under 1 mm), because MuJoCo's box-box contact between a finger and
    the cube drops to a single point at times and the cube pivots. Settings searched:
    elliptic cones with ``impratio`` 10, ``solimp`` (0.95, 0.99), contact margins of 2 and
    5 mm; none removed the sinking. With it on they also collide with each other, except
    across each URDF joint (PyBullet's ``URDF_USE_SELF_COLLISION_EXCLUDE_PARENT``); this
    explicit exclusion also covers the base, which is welded to the world and so escapes
    MuJoCo's own parent-child filter.

Rendering
    Offscreen through ``mujoco.Renderer``. Unless ``MUJOCO_GL`` is already set, this module
    sets it to ``egl`` (or ``osmesa``) before importing mujoco when that library is found.
"""

from __future__ import annotations

import contextlib
import ctypes.util
import hashlib
import logging
import os
import threading
from collections import OrderedDict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from lxml import etree

from armreach_core.backend import NO_OBJECTS, ArmState, Backend, BodyState, Camera, PhysicsConfig
from armreach_core.errors import ArmReachError, BackendUnavailableError, URDFError
from armreach_core.robot import FloatArray, RobotModel


def _choose_gl() -> None:
    if "MUJOCO_GL" in os.environ:
        return
    if ctypes.util.find_library("EGL"):
        os.environ["MUJOCO_GL"] = "egl"
    elif ctypes.util.find_library("OSMesa"):
        os.environ["MUJOCO_GL"] = "osmesa"


_choose_gl()

import mujoco  # noqa: E402 - MUJOCO_GL must be chosen first

#: PyBullet's motor gains, which this backend imitates (see the module docstring).
POSITION_GAIN = 0.2
VELOCITY_GAIN = 1.0
#: Servo damping kv of joint i = SERVO_DAMPING * (M_ii at home + armature) / dt.
SERVO_DAMPING = 2.0
#: Scale on the servo's position gain (compensates the implicit integrator's lag).
SERVO_GAIN_SCALE = 1.0
#: Rotor inertia added to every actuated joint (kg m^2, or kg for prismatic joints).
ARMATURE = 0.01
#: Gravity compensation through the actuators (PyBullet's motor holds the pose exactly).
GRAVITY_COMPENSATION = True
#: Mass (kg) and principal inertia (kg m^2) PyBullet gives a moving link whose URDF has no <inertial>
#: (its URDF parser's default, with a warning); used here too so both engines move the same bodies.
#: ``None`` keeps MuJoCo's reading (a massless link).
MISSING_INERTIAL: tuple[float, float] | None = (1.0, 1.0)
GROUND_RGBA = (0.86, 0.87, 0.89, 1.0)
#: Mesh formats MuJoCo reads itself; others are converted to .obj with trimesh.
NATIVE_MESHES = (".stl", ".obj", ".msh")
#: Collision bits: the arm is type 2 and collides with type 1 (the ground), and with type 2
#: too when self-collision is on. Added bodies are type 4 and collide with all three.
ARM_CONTYPE, GROUND_CONTYPE, BODY_CONTYPE = 2, 1, 4
BODY_PREFIX = "armreach_body_"
#: Contact settings once bodies are added (see the module docstring, "Contacts"): noslip
#: solver iterations, and the contact time constant of bodies in physics steps (MuJoCo's
#: stiffest safe value is 2) with a solmix weight that makes it win against the arm's.
NOSLIP_ITERATIONS = 10
BODY_SOLREF_STEPS = 2.0
BODY_SOLMIX = 100.0
MODEL_CACHE_SIZE = 32
#: MuJoCo warnings raised when a step diverges (it then resets the state to the model's defaults).
_INSTABILITY_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQACC,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADCTRL,
)

log = logging.getLogger("armreach.mujoco")


def _log_warning(message: Any) -> None:
    log.warning("mujoco: %s", str(message).strip())


# MuJoCo's default warning handler prints and appends to MUJOCO_LOG.TXT in the current
# folder; a diverging step (reported through Backend.diverged) would litter users' folders.
if mujoco.get_mju_user_warning() is None:
    mujoco.set_mju_user_warning(_log_warning)


@dataclass(frozen=True)
class _Marker:
    name: str
    radius: float
    rgba: tuple[float, float, float, float]


@dataclass(frozen=True)
class _Box:
    name: str
    half_extents: tuple[float, float, float]
    mass: float
    friction: float
    rgba: tuple[float, float, float, float]
    position: tuple[float, float, float]


@dataclass(frozen=True)
class _Scene:
    """What tasks added to the world: markers, boxes and friction coefficients of robot links."""

    markers: tuple[_Marker, ...] = ()
    boxes: tuple[_Box, ...] = ()
    frictions: tuple[tuple[str, float], ...] = ()


@dataclass(frozen=True)
class _Compiled:
    """A compiled model and the addresses the backend reads (shared by every env that uses it)."""

    model: Any  # mujoco.MjModel
    qpos: npt.NDArray[np.intp]
    qvel: npt.NDArray[np.intp]
    actuators: npt.NDArray[np.intp]
    bodies: dict[str, int]
    mocap: dict[str, int]
    free: dict[str, tuple[int, int]]  # body name -> (qpos address, dof address) of its free joint


_cache: OrderedDict[tuple[Any, ...], _Compiled] = OrderedDict()
_cache_lock = threading.Lock()


def _mesh_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "armreach" / "mujoco-meshes"


def _convert_mesh(path: Path) -> Path:
    """A copy of ``path`` MuJoCo can read (.obj), converted once with trimesh and cached."""
    stat = path.stat()
    digest = hashlib.sha1(f"{path}:{stat.st_mtime_ns}:{stat.st_size}".encode()).hexdigest()[:16]
    out = _mesh_cache_dir() / f"{path.stem}-{digest}.obj"
    if not out.is_file():
        import trimesh

        fix = "fix the file, or convert it to .stl or .obj and point the URDF at that"
        try:
            mesh = trimesh.load(str(path), force="mesh")
        except Exception as exc:
            detail = str(exc) if type(exc).__name__ in str(exc) else f"{type(exc).__name__}: {exc}"
            raise URDFError(
                f"MuJoCo cannot read mesh {str(path)!r} and trimesh could not convert it ({detail}); {fix}"
            ) from exc
        vertices, faces = len(getattr(mesh, "vertices", ())), len(getattr(mesh, "faces", ()))
        if faces == 0 or vertices < 4:  # MuJoCo rejects it, naming only the converted copy
            raise URDFError(
                f"mesh {str(path)!r} has {vertices} vertices and {faces} triangles once read by trimesh, "
                f"and MuJoCo needs at least 4 vertices and a triangle; {fix}"
            )
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(f".{os.getpid()}.tmp.obj")
        from trimesh.exchange.obj import export_obj

        # Geometry only: a material file would be shared by every converted mesh in the folder.
        tmp.write_text(export_obj(mesh, include_texture=False, write_texture=False), encoding="utf-8")
        os.replace(tmp, out)
    return out


def _urdf_for_mujoco(robot: RobotModel) -> str:
    root = etree.fromstring(robot.parsed.resolved_xml)
    for mesh in root.iter("mesh"):
        filename = Path(mesh.get("filename", ""))
        if filename.suffix.lower() not in NATIVE_MESHES:
            mesh.set("filename", str(_convert_mesh(filename)))
    for old in root.findall("mujoco"):
        root.remove(old)
    block = etree.SubElement(root, "mujoco")
    etree.SubElement(
        block,
        "compiler",
        balanceinertia="true",
        strippath="false",
        discardvisual="false",
        fusestatic="false",
        angle="radian",
    )
    return etree.tostring(root, encoding="unicode")


def _links_without_inertial(robot: RobotModel) -> list[str]:
    """Links with no ``<inertial>`` that move (a movable joint lies between them and the root)."""
    urdf = robot.parsed.model.robot
    parent_joint = {str(j.child): j for j in urdf.joints}
    moving: list[str] = []
    for link in urdf.links:
        if link.inertial is not None:
            continue
        name, moves = str(link.name), False
        while name in parent_joint:
            joint = parent_joint[name]
            if str(joint.type) != "fixed":
                moves = True
                break
            name = str(joint.parent)
        if moves:
            moving.append(str(link.name))
    return moving


def _build(robot: RobotModel, physics: PhysicsConfig, scene: _Scene) -> _Compiled:
    try:
        spec = mujoco.MjSpec.from_string(_urdf_for_mujoco(robot))
    except ValueError as exc:  # MuJoCo's URDF importer refused the file
        raise URDFError(
            f"MuJoCo cannot read {robot.urdf_path}: {' '.join(str(exc).split())}; fix the element it names"
        ) from None
    spec.modelname = robot.name
    spec.option.timestep = physics.timestep
    spec.option.gravity = list(physics.gravity)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.compiler.boundmass = 1e-6
    spec.compiler.boundinertia = 1e-10
    if not physics.inertia_from_file:
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
        spec.compiler.inertiagrouprange = [0, 0]
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]

    # -- contacts
    arm_affinity = GROUND_CONTYPE | (ARM_CONTYPE if physics.self_collision else 0)
    for geom in spec.geoms:
        if geom.contype or geom.conaffinity:
            geom.contype, geom.conaffinity = ARM_CONTYPE, arm_affinity
    if physics.self_collision:
        body_names = {body.name for body in spec.bodies}
        for joint in robot.parsed.model.robot.joints:
            parent, child = str(joint.parent), str(joint.child)
            if parent in body_names and child in body_names and "world" not in (parent, child):
                spec.add_exclude(bodyname1=parent, bodyname2=child)

    # -- links without <inertial>: PyBullet's default, except on the root and what is welded to it
    if MISSING_INERTIAL is not None:
        mass, inertia = MISSING_INERTIAL
        for link in _links_without_inertial(robot):
            body = spec.body(link)
            if body is not None:
                body.explicitinertial = True
                body.mass = mass
                body.inertia = [inertia, inertia, inertia]
                body.ipos = [0.0, 0.0, 0.0]
                body.iquat = [1.0, 0.0, 0.0, 0.0]

    # -- joints and actuators
    for body in spec.bodies:
        if body.name != "world" and GRAVITY_COMPENSATION:
            body.gravcomp = 1.0
    for joint_spec in robot.joints:
        joint = spec.joint(joint_spec.name)
        if joint is None:
            raise ArmReachError(f"MuJoCo did not create joint {joint_spec.name!r} of {robot.urdf_path}")
        joint.damping = [joint_spec.damping, *list(joint.damping)[1:]]  # mujoco 4 adds nonlinear terms
        joint.frictionloss = 0.0
        joint.armature = ARMATURE
        joint.actgravcomp = GRAVITY_COMPENSATION
        joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_TRUE
        joint.actfrcrange = [-joint_spec.effort, joint_spec.effort]
        act = spec.add_actuator(name=joint_spec.name, target=joint_spec.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=1.0, kv=1.0)  # real gains below, once the inertia is known
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-joint_spec.effort, joint_spec.effort]

    # -- scene: a white sky like PyBullet's, a light, the ground and the markers
    spec.add_texture(
        name="armreach_sky",
        type=mujoco.mjtTexture.mjTEXTURE_SKYBOX,
        builtin=mujoco.mjtBuiltin.mjBUILTIN_FLAT,
        rgb1=[1.0, 1.0, 1.0],
        rgb2=[1.0, 1.0, 1.0],
        width=16,
        height=16,
    )
    world = spec.worldbody
    world.add_light(pos=[0.0, -0.5, 3.0], dir=[0.0, 0.2, -1.0], diffuse=[0.5, 0.5, 0.5], castshadow=False)
    if physics.ground:
        world.add_geom(
            name="armreach_ground",
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[1.5, 1.5, 0.01],
            rgba=list(GROUND_RGBA),
            contype=GROUND_CONTYPE,
            conaffinity=ARM_CONTYPE,
            group=2,
        )
    for marker in scene.markers:
        body = world.add_body(name=f"armreach_marker_{marker.name}", mocap=True)
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[marker.radius, 0.0, 0.0],
            rgba=list(marker.rgba),
            contype=0,
            conaffinity=0,
            group=2,
            mass=0.0,
        )

    if scene.boxes:
        spec.option.noslip_iterations = NOSLIP_ITERATIONS
    for box in scene.boxes:  # after the gravity compensation above: bodies fall
        body = world.add_body(name=BODY_PREFIX + box.name, pos=list(box.position))
        if box.mass > 0:
            body.add_freejoint(name=BODY_PREFIX + box.name)
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(box.half_extents),
            rgba=list(box.rgba),
            friction=[box.friction, 0.005, 0.0001],
            contype=BODY_CONTYPE,
            conaffinity=GROUND_CONTYPE | ARM_CONTYPE | BODY_CONTYPE,
            group=2,
            solref=[BODY_SOLREF_STEPS * physics.timestep, 1.0],
            solmix=BODY_SOLMIX,
            **({"mass": box.mass} if box.mass > 0 else {}),
        )
    for link, friction in scene.frictions:
        link_body = spec.body(link)
        for geom in link_body.geoms:
            geom.friction = [friction, *list(geom.friction)[1:]]

    try:
        model = spec.compile()
    except ValueError as exc:  # e.g. an inertia MuJoCo rejects; the message names the body
        raise URDFError(
            f"MuJoCo cannot compile {robot.urdf_path}: {' '.join(str(exc).split())}; fix the element it names"
        ) from None
    qpos = np.array([model.jnt_qposadr[model.joint(n).id] for n in robot.joint_names], dtype=np.intp)
    qvel = np.array([model.jnt_dofadr[model.joint(n).id] for n in robot.joint_names], dtype=np.intp)
    actuators = np.array([model.actuator(n).id for n in robot.joint_names], dtype=np.intp)

    # Servo gains from the joint-space inertia at home: kv large against it, kp = kv * lambda.
    data = mujoco.MjData(model)
    data.qpos[qpos] = robot.home
    mujoco.mj_forward(model, data)
    diag = np.empty(len(qvel))
    unit, column = np.zeros(model.nv), np.zeros(model.nv)
    for i, dof in enumerate(qvel):  # M_ii through mj_mulM: the same call in mujoco 3 and 4
        unit[:] = 0.0
        unit[dof] = 1.0
        mujoco.mj_mulM(model, data, column, unit)
        diag[i] = column[dof]
    kv = SERVO_DAMPING * diag / physics.timestep
    kp = kv * SERVO_GAIN_SCALE * POSITION_GAIN / physics.timestep
    for act, p, v in zip(actuators, kp, kv, strict=True):
        model.actuator_gainprm[act, 0] = p
        model.actuator_biasprm[act, 1] = -p
        model.actuator_biasprm[act, 2] = -v

    bodies = {model.body(i).name: i for i in range(model.nbody)}
    mocap = {m.name: int(model.body_mocapid[bodies[f"armreach_marker_{m.name}"]]) for m in scene.markers}
    free = {}
    for box in scene.boxes:
        if box.mass > 0:
            joint = model.joint(BODY_PREFIX + box.name).id
            free[box.name] = (int(model.jnt_qposadr[joint]), int(model.jnt_dofadr[joint]))
    return _Compiled(model=model, qpos=qpos, qvel=qvel, actuators=actuators, bodies=bodies, mocap=mocap, free=free)


def compiled_model(robot: RobotModel, physics: PhysicsConfig, scene: _Scene | None = None) -> _Compiled:
    """The compiled model for ``robot``, cached per (URDF file, mtime, physics, scene, gains)."""
    scene = scene or _Scene()
    try:
        mtime = robot.urdf_path.stat().st_mtime_ns
    except OSError:
        mtime = -1
    key = (
        str(robot.urdf_path),
        mtime,
        hashlib.sha1(robot.parsed.resolved_xml).hexdigest(),
        tuple(robot.home.tolist()),
        robot.joint_names,
        physics,
        scene,
        (POSITION_GAIN, SERVO_DAMPING, SERVO_GAIN_SCALE, ARMATURE, GRAVITY_COMPENSATION),
        (NOSLIP_ITERATIONS, BODY_SOLREF_STEPS, BODY_SOLMIX),
    )
    with _cache_lock:
        hit = _cache.get(key)
        if hit is not None:
            _cache.move_to_end(key)
            return hit
    compiled = _build(robot, physics, scene)
    with _cache_lock:
        _cache[key] = compiled
        while len(_cache) > MODEL_CACHE_SIZE:
            _cache.popitem(last=False)
    return compiled


def clear_cache() -> None:
    """Forget every compiled model (for tests and gain tuning)."""
    with _cache_lock:
        _cache.clear()


class MuJoCoBackend(Backend):
    """The optional MuJoCo backend."""

    name = "mujoco"

    def __init__(self, robot: RobotModel, physics: PhysicsConfig) -> None:
        super().__init__(robot, physics)
        self._scene = _Scene()
        self._renderer: Any = None
        self._renderer_size = (0, 0)
        self._closed = False
        self._diverged = False
        self._load(compiled_model(robot, physics))

    def _load(self, compiled: _Compiled) -> None:
        old, before = getattr(self, "data", None), getattr(self, "_compiled", None)
        self._compiled = compiled
        self.model = compiled.model
        self.data = mujoco.MjData(self.model)
        self._qpos, self._qvel, self._act = compiled.qpos, compiled.qvel, compiled.actuators
        self._ee = compiled.bodies[self.robot.ee_link]
        # MjData's arrays, fetched once (each attribute access costs a binding call)
        self._ctrl, self._qpos_all, self._qvel_all, self._xpos = (
            self.data.ctrl,
            self.data.qpos,
            self.data.qvel,
            self.data.xpos,
        )
        self._half_dt = 0.5 * self.model.opt.timestep
        # what the clock advances by in one control step, less half a physics step of slack
        self._step_span = (self.physics.substeps - 0.5) * self.model.opt.timestep
        if old is None or before is None:
            self.data.qpos[self._qpos] = self.robot.home
            self.data.ctrl[self._act] = self.robot.home
        else:  # something was added to the scene: carry the state over, by name
            data = self.data
            data.qpos[self._qpos] = old.qpos[before.qpos]
            data.qvel[self._qvel] = old.qvel[before.qvel]
            data.ctrl[self._act] = old.ctrl[before.actuators]
            data.time = old.time
            for name, (qadr, vadr) in compiled.free.items():
                if name in before.free:
                    old_qadr, old_vadr = before.free[name]
                    data.qpos[qadr : qadr + 7] = old.qpos[old_qadr : old_qadr + 7]
                    data.qvel[vadr : vadr + 6] = old.qvel[old_vadr : old_vadr + 6]
            for name, index in compiled.mocap.items():
                previous = before.mocap.get(name)
                if previous is not None:
                    data.mocap_pos[index] = old.mocap_pos[previous]
        mujoco.mj_forward(self.model, self.data)
        if self._renderer is not None:
            self._close_renderer()

    def _live(self) -> None:
        if self._closed:
            raise ArmReachError("the MuJoCo backend is closed")

    # -- control -----------------------------------------------------------------------
    def reset_joints(self, q: npt.ArrayLike) -> None:
        self._live()
        values = np.asarray(q, dtype=np.float64)
        data = self.data
        data.qpos[self._qpos] = values
        data.qvel[:] = 0.0
        data.qacc_warmstart[:] = 0.0
        data.ctrl[self._act] = values
        mujoco.mj_forward(self.model, data)
        self._diverged = False

    def set_joint_targets(self, q: FloatArray) -> None:
        self._ctrl[self._act] = q

    def step(self) -> None:
        # A diverging step makes MuJoCo reset mjData, its clock included: the clock then lags
        # behind where `substeps` physics steps take it. Reading it costs ~0.1 µs, against
        # ~3 µs for MuJoCo's warning counters, which are needed only when the clock starts
        # at 0 (a reset in the first substep would then go unseen).
        data = self.data
        start = data.time
        if start < self._half_dt:
            self._step_counting_warnings()
        else:
            mujoco.mj_step(self.model, data, nstep=self.physics.substeps)
            self._diverged = data.time < start + self._step_span
        # mj_step leaves xpos at the pose before its last integration: bring links up to qpos
        mujoco.mj_kinematics(self.model, data)

    def _step_counting_warnings(self) -> None:
        # MuJoCo resets mjData (warning counters included) and then counts the warning
        # that made it reset: zero the counters, step, and look.
        warnings = self.data.warning
        for kind in _INSTABILITY_WARNINGS:
            warnings[kind].number = 0
        mujoco.mj_step(self.model, self.data, nstep=self.physics.substeps)
        self._diverged = any(warnings[kind].number > 0 for kind in _INSTABILITY_WARNINGS)

    def diverged(self) -> bool:
        return self._diverged

    # -- state -------------------------------------------------------------------------
    def joint_state(self) -> tuple[FloatArray, FloatArray]:
        return self._qpos_all[self._qpos], self._qvel_all[self._qvel]  # index arrays: copies

    def read_state(self) -> ArmState:
        if self._compiled.free:
            return super().read_state()
        q, qd = self.joint_state()
        return ArmState(q, qd, self._xpos[self._ee].copy(), NO_OBJECTS)

    def link_position(self, link: str) -> FloatArray:
        try:
            index = self._compiled.bodies[link]
        except KeyError:
            raise ArmReachError(f"link {link!r} is not part of {self.robot.name!r}") from None
        return self.data.xpos[index].copy()

    def bare_loop(self, deltas: FloatArray) -> None:
        model, data, substeps = self.model, self.data, self.physics.substeps
        lower, upper = self.robot.lower, self.robot.upper
        act, qpos_index, qvel_index = self._act, self._qpos, self._qvel
        ee = self._compiled.bodies[self.robot.ee_link]
        q = data.qpos[qpos_index]  # indexing with an array copies
        for delta in deltas:
            data.ctrl[act] = np.minimum(np.maximum(q + delta, lower), upper)
            mujoco.mj_step(model, data, nstep=substeps)
            mujoco.mj_kinematics(model, data)
            q = data.qpos[qpos_index]
            _qd = data.qvel[qvel_index]
            _ee = data.xpos[ee].copy()

    # -- markers and rendering -----------------------------------------------------------
    def add_marker(self, name: str, radius: float, rgba: tuple[float, float, float, float]) -> None:
        self._live()
        if any(m.name == name for m in self._scene.markers):
            raise ArmReachError(f"marker {name!r} already exists")
        marker = _Marker(name, float(radius), (float(rgba[0]), float(rgba[1]), float(rgba[2]), float(rgba[3])))
        self._rebuild(replace(self._scene, markers=(*self._scene.markers, marker)))

    def _rebuild(self, scene: _Scene) -> None:
        self._load(compiled_model(self.robot, self.physics, scene))
        self._scene = scene

    def set_marker(self, name: str, position: FloatArray) -> None:
        try:
            index = self._compiled.mocap[name]
        except KeyError:
            raise ArmReachError(f"marker {name!r} does not exist; add it first") from None
        self.data.mocap_pos[index] = position

    # -- bodies, contacts, friction ---------------------------------------------------------
    def add_box(
        self,
        name: str,
        half_extents: tuple[float, float, float],
        mass: float,
        *,
        friction: float = 1.0,
        rgba: tuple[float, float, float, float] = (0.8, 0.3, 0.2, 1.0),
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self._live()
        if name in self._compiled.bodies or any(b.name == name for b in self._scene.boxes):
            raise ArmReachError(f"a body or link called {name!r} already exists")
        box = _Box(
            name,
            (float(half_extents[0]), float(half_extents[1]), float(half_extents[2])),
            float(mass),
            float(friction),
            (float(rgba[0]), float(rgba[1]), float(rgba[2]), float(rgba[3])),
            (float(position[0]), float(position[1]), float(position[2])),
        )
        self._rebuild(replace(self._scene, boxes=(*self._scene.boxes, box)))

    def free_bodies(self) -> tuple[str, ...]:
        return tuple(self._compiled.free)

    def _body_id(self, name: str) -> int:
        """MuJoCo body of a robot link or an added body."""
        bodies = self._compiled.bodies
        if BODY_PREFIX + name in bodies:
            return bodies[BODY_PREFIX + name]
        if name in bodies and name in self.robot.link_names:
            return bodies[name]
        raise ArmReachError(f"{name!r} is neither a link of {self.robot.name!r} nor a body")

    def _free(self, name: str) -> tuple[int, int]:
        try:
            return self._compiled.free[name]
        except KeyError:
            if any(b.name == name for b in self._scene.boxes):
                raise ArmReachError(f"body {name!r} is fixed (mass 0); only free bodies can be moved") from None
            raise ArmReachError(f"no body called {name!r}; add it with add_box first") from None

    def set_body_pose(self, name: str, position: npt.ArrayLike, orientation: npt.ArrayLike = (1, 0, 0, 0)) -> None:
        self._live()
        qadr, vadr = self._free(name)
        quat = np.asarray(orientation, dtype=np.float64)
        data = self.data
        data.qpos[qadr : qadr + 3] = np.asarray(position, dtype=np.float64)
        data.qpos[qadr + 3 : qadr + 7] = quat / np.linalg.norm(quat)
        data.qvel[vadr : vadr + 6] = 0.0
        data.qacc_warmstart[:] = 0.0
        mujoco.mj_forward(self.model, data)

    def body_state(self, name: str) -> BodyState:
        if BODY_PREFIX + name not in self._compiled.bodies:
            raise ArmReachError(f"no body called {name!r}; add it with add_box first")
        body = self._compiled.bodies[BODY_PREFIX + name]
        data = self.data
        position, orientation = data.xpos[body].copy(), data.xquat[body].copy()
        if name not in self._compiled.free:
            return BodyState(position, orientation, np.zeros(3), np.zeros(3))
        _, vadr = self._compiled.free[name]
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

    def set_friction(self, name: str, friction: float) -> None:
        self._live()
        boxes = self._scene.boxes
        if any(b.name == name for b in boxes):
            boxes = tuple(replace(b, friction=float(friction)) if b.name == name else b for b in boxes)
            self._rebuild(replace(self._scene, boxes=boxes))
            return
        if name not in self.robot.link_names:
            raise ArmReachError(f"{name!r} is neither a link of {self.robot.name!r} nor a body")
        frictions = (*(f for f in self._scene.frictions if f[0] != name), (name, float(friction)))
        self._rebuild(replace(self._scene, frictions=frictions))

    def render(self, camera: Camera) -> npt.NDArray[np.uint8]:
        self._live()
        model = self.model
        if self._renderer is None or self._renderer_size != (camera.width, camera.height):
            self._close_renderer()
            model.vis.global_.offwidth = max(int(model.vis.global_.offwidth), camera.width)
            model.vis.global_.offheight = max(int(model.vis.global_.offheight), camera.height)
            try:
                self._renderer = mujoco.Renderer(model, height=camera.height, width=camera.width)
            except Exception as exc:
                raise BackendUnavailableError(
                    f"MuJoCo cannot render offscreen (MUJOCO_GL={os.environ.get('MUJOCO_GL', '')!r}): {exc}. "
                    "Install EGL (`apt-get install libegl1`, with MUJOCO_GL=egl) or OSMesa "
                    "(`apt-get install libosmesa6`, with MUJOCO_GL=osmesa and PYOPENGL_PLATFORM=osmesa)"
                ) from exc
            self._renderer_size = (camera.width, camera.height)
            self._scene_option = mujoco.MjvOption()
            has_visuals = bool(np.any(model.geom_group == 1))
            self._scene_option.geomgroup[:] = [0 if has_visuals else 1, 1, 1, 0, 0, 0]
        free = mujoco.MjvCamera()
        free.type = mujoco.mjtCamera.mjCAMERA_FREE
        free.lookat[:] = camera.target
        free.distance = camera.distance
        free.azimuth = camera.yaw + 90.0  # PyBullet's yaw 0 looks along +y, MuJoCo's azimuth 0 along +x
        free.elevation = camera.pitch
        model.vis.global_.fovy = camera.fov
        mujoco.mj_kinematics(model, self.data)  # markers moved since the last step
        mujoco.mj_camlight(model, self.data)
        self._renderer.update_scene(self.data, camera=free, scene_option=self._scene_option)
        return np.ascontiguousarray(self._renderer.render())

    def _close_renderer(self) -> None:
        renderer, self._renderer = self._renderer, None
        if renderer is not None:
            with contextlib.suppress(Exception):
                renderer.close()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._close_renderer()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()


__all__ = ["MuJoCoBackend", "clear_cache", "compiled_model"]
