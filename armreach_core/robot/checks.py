"""Checks on a URDF's XML before any parser or engine interprets it.

yourdfpy, PyBullet and MuJoCo each read a URDF's numbers with their own parser, and
they disagree on what is not plainly a number (``nan``, ``1_000``, ``0x10``, ``1,2,3``,
a missing component), and none of them is safe against every bad value: a duplicate
joint name crashes PyBullet's loader (segmentation fault), a negative mass or a
non-positive-definite inertia stops MuJoCo's compiler, a NaN origin gives NaN
observations. :func:`check_tree` therefore checks every link and joint of the XML with
one strict rule set, and raises :class:`~armreach_core.errors.URDFError` naming the
element, the attribute and the fix:

* numbers are plain decimals (``-1.5``, ``2e-3``), as many as the attribute needs,
  finite, and at most :data:`MAX_MAGNITUDE` in size (metres, kilograms, radians);
* masses, damping and friction are not negative; geometry sizes are positive; a movable
  joint's axis has a direction;
* an ``<inertial>`` has both ``<mass>`` and ``<inertia>``; geometry has its sizes; a
  ``<dynamics>`` has damping or friction;
* link and joint names are unique, joint types are URDF types that the engines simulate
  as URDF says (no ``floating`` or ``planar`` joint: armreach models a fixed-base arm), a
  joint's ``<parent>`` and ``<child>`` name links of the URDF, a ``<mimic>`` names another
  joint of the URDF, and a URDF has at most :data:`MAX_LINKS` links.

A zero mass, and an inertia no rigid body has (not positive semi-definite, more compact than
a steel ball of the link's mass, a point mass among them, wider than the whole robot, or
breaking the triangle inequality), are accepted; the second kind is reported (a warning on
``armreach.robot``) and repaired once, the same way for both engines
(:mod:`armreach_core.robot.inertia`). The tensor built from the six numbers is
symmetric; an engine that rotates it and finds it asymmetric by rounding (PyBullet's inverse
dynamics, on heavy links) is answered by the backend, not refused here.

Extension blocks (``<gazebo>``, ``<transmission>``, ``<mujoco>``...) are not checked:
no engine armreach drives reads them.
"""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Iterable

from lxml import etree

from armreach_core.errors import URDFError
from armreach_core.robot.inertia import INERTIA_KEYS, repairs

log = logging.getLogger("armreach.robot")

#: Largest magnitude accepted for a length (m), mass (kg), moment of inertia (kg·m²),
#: angle (rad) or joint limit. Far beyond any robot, and small enough that squares and
#: float32 observation bounds cannot overflow.
MAX_MAGNITUDE = 1e6
#: Most links a URDF may have (engines build every link; real arms have tens).
MAX_LINKS = 1000
#: Shortest joint axis accepted (its direction is what counts; MuJoCo refuses axes under 1e-6).
MIN_AXIS_LENGTH = 1e-5
#: Joint types the URDF format defines.
URDF_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
#: Joint types armreach's engines load as the URDF means them. A floating or planar joint
#: inside an arm is refused by MuJoCo's importer or left to PyBullet's own reading.
SIMULATED_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed")

# ASCII digits and whitespace only: Python's float() and str.split() also take other scripts'
# digits (１, ٣) and spaces (U+00A0), which no engine reads as numbers or separators
_NUMBER = re.compile(r"^[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?$")
_SPACES = re.compile(r"[ \t\n\r]+")

Element = etree._Element


def _where(element: Element) -> str:
    """``<tag>`` of the link or joint it belongs to, for messages."""
    parts = []
    node: Element | None = element
    while node is not None and node.tag != "robot":
        name = node.get("name")
        tag = str(node.tag)
        if node.tag in ("link", "joint") and name is not None:
            parts.append(f"{tag} {name!r}")
            break
        parts.append(f"<{tag}>")
        node = node.getparent()
    return " of ".join(parts) if parts else f"<{element.tag}>"


def _numbers(
    element: Element,
    attribute: str,
    count: int,
    *,
    required: bool = False,
    bound: float | None = MAX_MAGNITUDE,
    minimum: float | None = None,
    strictly: bool = False,
    fix: str = "",
) -> list[float] | None:
    """The ``count`` numbers of ``element``'s ``attribute``, checked; ``None`` when absent.

    ``fix`` ends the message when a value is below ``minimum``.
    """
    raw = element.get(attribute)
    where = f"{attribute}={raw!r} of {_where(element)}"
    if raw is None:
        if required:
            raise URDFError(f"{_where(element)} has no {attribute}= attribute; the URDF format requires it: add it")
        return None
    parts = _SPACES.split(raw.strip(" \t\n\r")) if raw.strip(" \t\n\r") else []
    if len(parts) != count or not all(_NUMBER.match(p) for p in parts):
        kind = "a number" if count == 1 else f"{count} numbers separated by spaces"
        raise URDFError(f"{where} is not {kind}; write plain decimals such as 0.5 or 2e-3 (no nan, inf or commas)")
    values = [float(p) for p in parts]
    for value in values:
        if not math.isfinite(value):  # a decimal too large for a double, such as 1e999
            raise URDFError(f"{where} overflows a double; use a finite value")
        if bound is not None and abs(value) > bound:
            raise URDFError(f"{where} is beyond ±{bound:g}; no robot needs such a value, check the units")
        if minimum is not None and (value <= minimum if strictly else value < minimum):
            relation = ">" if strictly else ">="
            raise URDFError(f"{where} must be {relation} {minimum:g}; {fix or 'correct the sign'}")
    return values


def _check_origin(parent: Element) -> None:
    origin = parent.find("origin")
    if origin is not None:
        _numbers(origin, "xyz", 3)
        _numbers(origin, "rpy", 3)


#: The end of a message about a shape's size below zero.
_SIZE_FIX = "a shape's sizes are lengths in metres, all positive"


def _check_geometry(holder: Element) -> None:
    _check_origin(holder)
    geometry = holder.find("geometry")
    if geometry is None:
        raise URDFError(f"{_where(holder)} has no <geometry>; add one or remove the element")
    shapes = [child for child in geometry if isinstance(child.tag, str)]
    if len(shapes) != 1:
        found = ", ".join(f"<{shape.tag}>" for shape in shapes) or "none"
        raise URDFError(
            f"<geometry> of {_where(holder)} must hold exactly one shape, found {len(shapes)} ({found}); keep one "
            "box, cylinder, sphere or mesh, and give each further shape a <visual> or <collision> of its own"
        )
    shape = shapes[0]
    if shape.tag == "box":
        _numbers(shape, "size", 3, required=True, minimum=0.0, strictly=True, fix=_SIZE_FIX)
    elif shape.tag in ("cylinder", "capsule"):
        _numbers(shape, "radius", 1, required=True, minimum=0.0, strictly=True, fix=_SIZE_FIX)
        _numbers(shape, "length", 1, required=True, minimum=0.0, strictly=True, fix=_SIZE_FIX)
    elif shape.tag == "sphere":
        _numbers(shape, "radius", 1, required=True, minimum=0.0, strictly=True, fix=_SIZE_FIX)
    elif shape.tag == "mesh":
        if not shape.get("filename"):
            raise URDFError(
                f"<mesh> of {_where(holder)} has no filename= attribute; name the mesh file, such as "
                'filename="package://my_arm/meshes/link.stl"'
            )
        scale = _numbers(shape, "scale", 3)
        if scale is not None and any(s == 0.0 for s in scale):
            raise URDFError(f"scale={shape.get('scale')!r} of {_where(shape)} has a zero factor; use non-zero factors")
    else:
        raise URDFError(f"{_where(shape)} is not a URDF shape; use box, cylinder, sphere or mesh")
    material = holder.find("material")
    if material is not None:
        color = material.find("color")
        if color is not None:
            _numbers(color, "rgba", 4)


def _check_inertial(inertial: Element) -> None:
    _check_origin(inertial)
    mass = inertial.find("mass")
    inertia = inertial.find("inertia")
    if mass is None or inertia is None:
        missing = "<mass value=...>" if mass is None else "<inertia ixx=... izz=...>"
        raise URDFError(f"{_where(inertial)} has no {missing}; an <inertial> needs both <mass> and <inertia>")
    never_negative = "a mass is never negative: give the link's mass in kg"
    _numbers(mass, "value", 1, required=True, minimum=0.0, fix=never_negative)
    for key in INERTIA_KEYS:  # a tensor no body has is repaired, and reported (robot.inertia)
        _numbers(inertia, key, 1, required=True)


def _check_link(link: Element) -> None:
    inertial = link.find("inertial")
    if inertial is not None:
        _check_inertial(inertial)
    for holder in (*link.findall("visual"), *link.findall("collision")):
        _check_geometry(holder)


def _check_joint(joint: Element) -> None:
    kind = joint.get("type")
    if kind is None:
        raise URDFError(f"{_where(joint)} has no type= attribute; give it one of {', '.join(URDF_JOINT_TYPES)}")
    if kind not in URDF_JOINT_TYPES:
        raise URDFError(f"{_where(joint)} has type {kind!r}; URDF joint types are {', '.join(URDF_JOINT_TYPES)}")
    if kind not in SIMULATED_JOINT_TYPES:
        raise URDFError(
            f"{_where(joint)} has type {kind!r}; armreach simulates a fixed-base arm, with "
            f"{', '.join(SIMULATED_JOINT_TYPES)} joints only: make it one of those (fixed, for a base or a part "
            "bolted on)"
        )
    for end in ("parent", "child"):
        found = joint.findall(end)
        if len(found) != 1:
            raise URDFError(f"{_where(joint)} needs exactly one <{end} link=...>, found {len(found)}; give it one")
        if not found[0].get("link"):
            raise URDFError(f"<{end}> of {_where(joint)} has no link= attribute; name the {end} link")
    _check_origin(joint)
    axis = joint.find("axis")
    if axis is not None:
        xyz = _numbers(axis, "xyz", 3, required=True)  # the format requires it; leave <axis> out for 1 0 0
        length = math.hypot(*xyz) if xyz is not None else 1.0
        if kind != "fixed" and length < MIN_AXIS_LENGTH:
            raise URDFError(
                f"<axis xyz={axis.get('xyz')!r}> of {_where(joint)} has no direction (its length {length:.3g} is "
                f'under {MIN_AXIS_LENGTH:g}, which MuJoCo refuses); give the joint\'s unit axis, such as xyz="0 0 1"'
            )
    limit = joint.find("limit")
    if limit is not None:
        lower = _numbers(limit, "lower", 1)
        upper = _numbers(limit, "upper", 1)
        _numbers(limit, "effort", 1, bound=None)
        _numbers(limit, "velocity", 1, bound=None)
        if lower is not None and upper is not None and lower[0] > upper[0] and kind in ("revolute", "prismatic"):
            raise URDFError(f"<limit> of {_where(joint)} has lower {lower[0]} > upper {upper[0]}; swap them")
    dynamics = joint.find("dynamics")
    if dynamics is not None:
        if dynamics.get("damping") is None and dynamics.get("friction") is None:
            raise URDFError(
                f"<dynamics> of {_where(joint)} has neither damping= nor friction=, which PyBullet's reader refuses; "
                "give one (0 for none) or remove the element"
            )
        _numbers(dynamics, "damping", 1, bound=None, minimum=0.0, fix="use 0 for none")
        _numbers(dynamics, "friction", 1, bound=None, minimum=0.0, fix="use 0 for none")
    mimic = joint.find("mimic")
    if mimic is not None:
        _numbers(mimic, "multiplier", 1)
        _numbers(mimic, "offset", 1)
        master = mimic.get("joint")
        if not master:
            raise URDFError(f"<mimic> of {_where(joint)} has no joint= attribute; name the joint it follows")
        if master == joint.get("name"):
            raise URDFError(f"<mimic> of {_where(joint)} names the joint itself; name the joint it follows")
    safety = joint.find("safety_controller")
    if safety is not None:
        for key in ("soft_lower_limit", "soft_upper_limit", "k_position", "k_velocity"):
            _numbers(safety, key, 1, bound=None)


def _unique(elements: Iterable[Element], kind: str) -> None:
    seen: set[str] = set()
    for element in elements:
        name = element.get("name")
        if not name:
            raise URDFError(f"a <{kind}> has no name= attribute; every {kind} needs a unique name")
        if name in seen:
            raise URDFError(f"{kind} name {name!r} is used twice; {kind} names must be unique")
        seen.add(name)


def check_tree(root: Element) -> None:
    """Check every ``<link>`` and ``<joint>`` of a URDF's ``<robot>`` element.

    Raises:
        URDFError: the first problem found, naming the element and the fix.
    """
    links = root.findall("link")
    joints = root.findall("joint")
    for kind, elements in (("links", links), ("joints", joints)):
        if len(elements) > MAX_LINKS:
            raise URDFError(
                f"the URDF has {len(elements)} {kind}, over armreach's limit of {MAX_LINKS}; is it a robot arm?"
            )
    _unique(links, "link")
    _unique(joints, "joint")
    for material in root.findall("material"):  # shared materials, named by the visuals
        color = material.find("color")
        if color is not None:
            _numbers(color, "rgba", 4)
    for link in links:
        _check_link(link)
    for joint in joints:
        _check_joint(joint)
    for inertia, _, why in repairs(root):
        log.warning(
            "%s is no rigid body's (%s); both engines get the repaired inertia "
            "(armreach_core/robot/inertia.py): give the link its real moments",
            _where(inertia), why,
        )  # fmt: skip
    link_names = {link.get("name") for link in links}
    for joint in joints:
        for end in ("parent", "child"):
            name = joint.find(end).get("link")  # type: ignore[union-attr]  # checked by _check_joint
            if name not in link_names:
                raise URDFError(
                    f"<{end} link={name!r}> of {_where(joint)} names no link of the URDF; fix the name, or add "
                    f'<link name="{name}"/>'
                )
    names = {joint.get("name") for joint in joints}
    for joint in joints:
        mimic = joint.find("mimic")
        if mimic is not None and mimic.get("joint") not in names:
            raise URDFError(
                f"<mimic joint={mimic.get('joint')!r}> of {_where(joint)} names no joint of the URDF; "
                "name the joint it follows"
            )
