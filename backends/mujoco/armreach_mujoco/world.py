"""The world around the arm in the ``MjSpec``: physics options, contacts, ground, markers, boxes, friction.

Contacts
    With ``self_collision`` off, the arm's collision geoms collide with the ground and with
    added boxes only (contype/conaffinity bits); boxes collide with the arm, the ground and
    each other. With it on, the arm's links also collide with each other, except across
    each URDF joint (PyBullet's ``URDF_USE_SELF_COLLISION_EXCLUDE_PARENT``); this explicit
    exclusion also covers the base, which is welded to the world and so escapes MuJoCo's
    own parent-child filter.

    Friction is Bullet's: every pair the arm, the ground and the boxes can form is an
    explicit MuJoCo contact pair whose coefficient is the *product* of the two surfaces'
    lateral frictions, as Bullet combines them (MuJoCo would take the larger). A link's
    friction is its URDF ``<contact><lateral_friction>``, else PyBullet's default 0.5, or
    what a task set; the ground's is PyBullet's 0.5. Arm-arm contacts (with
    ``self_collision``) keep MuJoCo's rule.

    MuJoCo's contacts are soft where PyBullet's are rigid, so once a box is added the model
    gets the noslip solver and the boxes' contacts the stiffest safe time constant; a
    gripped cube then does not slide, but still sinks a few mm in the grip. The
    measurements and what else was tried are in ``docs/mujoco-backend.md``.
"""

from __future__ import annotations

import contextlib
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

from armreach_core.backend import PhysicsConfig
from armreach_core.robot.model import RobotModel
from armreach_mujoco.engine import mujoco

RGBA = tuple[float, float, float, float]
Vec3 = tuple[float, float, float]

GROUND_RGBA = (0.86, 0.87, 0.89, 1.0)
#: Collision bits: the arm is type 2 and collides with type 1 (the ground), and with type 2
#: too when self-collision is on. Added boxes are type 4 and collide with all three.
ARM_CONTYPE, GROUND_CONTYPE, BODY_CONTYPE = 2, 1, 4
#: MuJoCo names of what this package adds, so they cannot clash with the URDF's links.
BODY_PREFIX = "armreach_body_"
MARKER_PREFIX = "armreach_marker_"
#: Contact settings once boxes are added: noslip solver iterations, and the contact time
#: constant of boxes in physics steps (MuJoCo's stiffest safe value is 2) with a solmix
#: weight that makes it win against the arm's.
NOSLIP_ITERATIONS = 10
BODY_SOLREF_STEPS = 2.0
BODY_SOLMIX = 100.0
#: The arm's contacts with the ground, as close to Bullet's rigid ones as MuJoCo stays stable:
#: the time constant in physics steps (2 is MuJoCo's floor) and the solver impedance.
CONTACT_SOLREF_STEPS = 2.0
CONTACT_IMPEDANCE = (0.99, 0.99, 0.001, 0.5, 2.0)
#: PyBullet's lateral friction of a link or body that does not set one (the ground's too).
DEFAULT_FRICTION = 0.5
GROUND = "armreach_ground"
GEOM_TYPES = {
    "box": mujoco.mjtGeom.mjGEOM_BOX,
    "sphere": mujoco.mjtGeom.mjGEOM_SPHERE,
    "cylinder": mujoco.mjtGeom.mjGEOM_CYLINDER,
}
ARM_GEOM_PREFIX = "armreach_geom_"


@dataclass(frozen=True)
class Marker:
    name: str
    radius: float
    rgba: RGBA


@dataclass(frozen=True)
class Box:
    """A box, or with ``shape`` a sphere or cylinder (``half_extents`` then holds its sizes, padded with 0).

    ``movable``: a fixed body that ``set_body_pose`` moves (a mocap body).
    """

    name: str
    half_extents: Vec3
    mass: float
    friction: float
    rgba: RGBA
    position: Vec3
    shape: str = "box"
    movable: bool = False


@dataclass(frozen=True)
class Extras:
    """What tasks added to the world: markers, boxes and friction coefficients of robot links.

    Part of the compiled-model cache key: envs that added the same things share a model.
    """

    markers: tuple[Marker, ...] = ()
    boxes: tuple[Box, ...] = ()
    frictions: tuple[tuple[str, float], ...] = ()


def set_options(spec: Any, physics: PhysicsConfig) -> None:
    """Timestep, gravity, the integrator, inertia bounds, headlight."""
    spec.option.timestep = physics.timestep
    spec.option.gravity = list(physics.gravity)
    # semi-implicit Euler with explicit joint damping, as Bullet integrates (see armreach_mujoco.servo)
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_EULERDAMP
    # projected Gauss-Seidel on the dual, Bullet's kind of solver: as close to PyBullet as Newton
    # on the corpus's contact phases, and 40 % faster on ar6 (docs/mujoco-backend.md)
    spec.option.solver = mujoco.mjtSolver.mjSOL_PGS
    # Coulomb's circular friction cone, as Bullet's (a sliding link meets the same friction in
    # every direction); MuJoCo's default pyramid gives diagonal slides less (docs/mujoco-backend.md)
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.compiler.boundmass = 1e-6
    spec.compiler.boundinertia = 1e-10
    # Bullet's joint limits are rigid rows; MuJoCo's default ones are soft (a 0.02 s time
    # constant): the joints' limits get the contacts' time constant. MuJoCo's impedance (0.9-0.95)
    # stays: at 0.99, a motor holding a joint on its limit kept PGS at its iteration cap on the
    # Pandas, 35 % slower for no better parity (docs/mujoco-backend.md)
    for joint in spec.joints:
        joint.solref_limit = [CONTACT_SOLREF_STEPS * physics.timestep, 1.0]
    if not physics.inertia_from_file:
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE
        spec.compiler.inertiagrouprange = [0, 0]
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]


def set_arm_contacts(spec: Any, robot: RobotModel, physics: PhysicsConfig) -> None:
    """Collision bits of the arm's geoms and, with self-collision, the exclusions across joints.

    Call before anything else is added to the spec: every geom it holds is taken for the arm's.
    """
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


def add_scene(spec: Any, physics: PhysicsConfig, extras: Extras) -> None:
    """A white sky like PyBullet's, a light, the ground, markers, boxes and link frictions."""
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
            name=GROUND,
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[1.5, 1.5, 0.01],
            rgba=list(GROUND_RGBA),
            contype=GROUND_CONTYPE,
            conaffinity=ARM_CONTYPE,
            group=2,
        )
    for marker in extras.markers:  # mocap bodies with a visual-only sphere
        body = world.add_body(name=MARKER_PREFIX + marker.name, mocap=True)
        body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[marker.radius, 0.0, 0.0],
            rgba=list(marker.rgba),
            contype=0,
            conaffinity=0,
            group=2,
            mass=0.0,
        )

    if extras.boxes:
        spec.option.noslip_iterations = NOSLIP_ITERATIONS
    for box in extras.boxes:
        body = world.add_body(name=BODY_PREFIX + box.name, pos=list(box.position), mocap=box.movable)
        if box.mass > 0:
            body.add_freejoint(name=BODY_PREFIX + box.name)
        body.add_geom(
            name=BODY_PREFIX + box.name,
            type=GEOM_TYPES[box.shape],
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
    for link, friction in extras.frictions:
        for geom in spec.body(link).geoms:
            geom.friction = [friction, *list(geom.friction)[1:]]


def link_frictions(robot: RobotModel) -> dict[str, float]:
    """Each link's lateral friction as PyBullet reads it: ``<contact><lateral_friction value>``, else 0.5."""
    frictions = dict.fromkeys(robot.link_names, DEFAULT_FRICTION)
    root = ET.fromstring(robot.parsed.resolved_xml)
    for link in root.iter("link"):
        element = link.find("contact/lateral_friction")
        if element is not None and link.get("name") in frictions:
            with contextlib.suppress(ValueError):  # PyBullet keeps its default too
                frictions[str(link.get("name"))] = float(element.get("value", DEFAULT_FRICTION))
    return frictions


def add_contact_pairs(spec: Any, robot: RobotModel, physics: PhysicsConfig, extras: Extras) -> None:
    """Explicit contact pairs with Bullet's friction (the product) between arm, ground and boxes.

    Call last: the arm's geoms are those of the URDF's links that collide.
    """
    frictions = link_frictions(robot)
    frictions.update(dict(extras.frictions))
    links = set(robot.link_names)
    static = robot.fixed_links
    arm: list[tuple[str, float, bool]] = []  # (geom name, friction, fixed to the world)
    for body in spec.bodies:
        if body.name not in links:
            continue
        for geom in body.geoms:
            if geom.contype & ARM_CONTYPE:
                if not geom.name:
                    geom.name = f"{ARM_GEOM_PREFIX}{len(arm)}"
                arm.append((geom.name, frictions[body.name], body.name in static))
    surfaces = [(GROUND, DEFAULT_FRICTION)] if physics.ground else []
    boxes = [(BODY_PREFIX + box.name, box.friction) for box in extras.boxes]
    box_solref = [BODY_SOLREF_STEPS * physics.timestep, 1.0]  # as the boxes' own geoms
    stiff = [CONTACT_SOLREF_STEPS * physics.timestep, 1.0]
    for name, friction, fixed in arm:
        for surface, other in surfaces if not fixed else ():  # MuJoCo skips static-static pairs too
            _pair(spec, name, surface, friction * other, stiff, CONTACT_IMPEDANCE)
        for box, other in boxes:
            _pair(spec, name, box, friction * other, box_solref, None)
    for i, (box, friction) in enumerate(boxes):
        for surface, other in [*surfaces, *boxes[i + 1 :]]:
            _pair(spec, box, surface, friction * other, box_solref, None)


def _pair(
    spec: Any, geom1: str, geom2: str, friction: float, solref: list[float], solimp: tuple[float, ...] | None
) -> None:
    pair = spec.add_pair(geomname1=geom1, geomname2=geom2)
    pair.friction = [friction, friction, 0.005, 0.0001, 0.0001]
    pair.solref = solref
    if solimp is not None:
        pair.solimp = list(solimp)
