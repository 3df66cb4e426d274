"""URDF → ``mujoco.MjSpec`` with MuJoCo's own URDF importer; every URDF link stays a body.

The resolved URDF (mesh paths already absolute) gets a ``<mujoco><compiler/></mujoco>``
block (``strippath=false``, ``discardvisual=false``, ``fusestatic=false``, so every link,
``tool0`` included, is a body whose frame is the link frame). Meshes MuJoCo cannot read
(``.dae``, ``.glb``, ``.ply``...) are converted once to ``.obj`` (:mod:`armreach_core.robot.meshes`).
Links that move but have no ``<inertial>`` get PyBullet's default inertial (see
:func:`spec_from_urdf`). The robot is placed at its base pose (:func:`place_base`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from lxml import etree

from armreach_core.errors import URDFError
from armreach_core.robot.hulls import MAX_HULL_VERTICES, simulation_urdf
from armreach_core.robot.meshes import readable
from armreach_core.robot.model import RobotModel
from armreach_core.robot.statics import BARE_LINK_MASS, bare_mass
from armreach_core.robot.weld import weld
from armreach_mujoco.engine import mujoco

#: Mesh formats MuJoCo reads itself; others are converted to .obj with trimesh.
NATIVE_MESHES = (".stl", ".obj", ".msh")


def urdf_for_mujoco(
    robot: RobotModel,
    visuals: bool = True,
    welded: Mapping[str, float] | None = None,
    max_vertices: int | None = MAX_HULL_VERTICES,
) -> str:
    """The robot's resolved URDF with readable mesh paths and MuJoCo's compiler block.

    Collision meshes are their convex hulls (what MuJoCo collides anyway) and, without
    ``visuals``, there are no visual meshes (:func:`armreach_core.robot.hulls.simulation_urdf`).
    The held joints in ``welded`` are fixed joints at the positions it gives
    (:mod:`armreach_core.robot.weld`); hulls keep at most ``max_vertices`` vertices.
    """
    urdf = weld(simulation_urdf(robot, visuals=visuals, max_vertices=max_vertices), robot, welded or {})
    root = etree.fromstring(readable(urdf, NATIVE_MESHES))
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


def links_without_inertial(robot: RobotModel) -> list[str]:
    """Links with no ``<inertial>`` whose own joint moves (frames fixed to another link are
    massless: :func:`armreach_core.robot.inertia.massless_frames`)."""
    links = robot.parsed.model.link_map
    return [link for link in robot.link_names if links[link].inertial is None and bare_mass(robot, link) > 0]


def spec_from_urdf(
    robot: RobotModel,
    visuals: bool = True,
    welded: Mapping[str, float] | None = None,
    max_vertices: int | None = MAX_HULL_VERTICES,
) -> Any:
    """An ``MjSpec`` of the robot alone, as MuJoCo imports it, with PyBullet's missing inertials.

    PyBullet's URDF reader gives a link without ``<inertial>`` whose joint moves 1 kg and
    1 kg m² on each axis (with a warning); MuJoCo would make it massless, and it is copied
    here for parity. A frame fixed to another link comes massless from the URDF both engines
    load (:func:`armreach_core.robot.inertia.massless_frames`).
    """
    try:
        spec = mujoco.MjSpec.from_string(urdf_for_mujoco(robot, visuals, welded, max_vertices))
    except ValueError as exc:  # MuJoCo's URDF importer refused the file
        raise URDFError(
            f"MuJoCo cannot read {robot.urdf_path}: {' '.join(str(exc).split())}; fix the element it names"
        ) from None
    spec.modelname = robot.name
    for link in links_without_inertial(robot):
        body = spec.body(link)
        if body is not None:
            body.explicitinertial = True
            body.mass = BARE_LINK_MASS
            body.inertia = [BARE_LINK_MASS] * 3
            body.ipos = [0.0, 0.0, 0.0]
            body.iquat = [1.0, 0.0, 0.0, 0.0]
    place_base(spec, robot)
    return spec


def place_base(spec: Any, robot: RobotModel) -> None:
    """Move what the URDF put in the world (the root link's body, or, when the root link is
    called ``world`` and MuJoCo merged it into its own world, that link's children and
    geoms) to the robot's base pose. Call before anything else is added to the world."""
    if robot.base_position == (0.0, 0.0, 0.0) and robot.base_orientation == (1.0, 0.0, 0.0, 0.0):
        return
    position = np.asarray(robot.base_position, dtype=np.float64)
    rotation = np.asarray(robot.base_orientation, dtype=np.float64)
    world = spec.worldbody
    for element in (*world.bodies, *world.geoms, *world.sites):
        pos, quat = np.zeros(3), np.zeros(4)
        mujoco.mju_rotVecQuat(pos, np.asarray(element.pos, dtype=np.float64), rotation)
        mujoco.mju_mulQuat(quat, rotation, np.asarray(element.quat, dtype=np.float64))
        element.pos = (pos + position).tolist()
        element.quat = quat.tolist()
