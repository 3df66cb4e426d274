"""Links fixed to another, merged into it in the URDF PyBullet loads.

Every link of a Bullet multibody costs each physics step its share of the kinematics, the
dynamics recursion and collision detection, whether its joint moves or not. A link fixed to
another (a ``tool0`` frame, a force-torque sensor's flange, a gripper's fixed fingers, the
child of a welded held joint) moves with it as one rigid body, so it is folded into the link
it hangs from before PyBullet reads the URDF (:func:`merge_fixed`): its visuals and
collisions move there, its mass and inertia are added about the common centre of mass,
which is exact for a rigid body. Arms with detailed grippers step 1.4-1.7 times as fast, ar6
1.11 times (docs/benchmarks.md, "Links fixed to another, merged").

Armreach still addresses every link by its URDF name (:class:`Merged`): a merged link's pose
is its owner's link frame times the fixed offset between them; its contacts and clearances
are those of the rigid body it belongs to, counted for the links of that body that have
collision geometry; its mass is its own, and changing it changes the body's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from lxml import etree

from armreach_core.robot.inertia import INERTIA_KEYS, inertia_tensor
from armreach_core.robot.model import FloatArray
from armreach_core.robot.origins import origin_of, set_origin
from armreach_core.robot.statics import BARE_LINK_MASS


@dataclass(frozen=True)
class Merged:
    """Where each URDF link of an arm, as PyBullet loads it, ends up.

    Attributes:
        owner: by link name, the link it is part of in PyBullet: itself for a link whose
            joint moves (and for the root), else the nearest such link above it.
        offset: by link name, its frame in its owner's link frame (4x4; identity for an owner).
        colliding: the links with collision geometry.
        mass: by link name, its own mass as PyBullet loads it (kg; :data:`BARE_LINK_MASS`
            without ``<inertial>``).
    """

    owner: dict[str, str]
    offset: dict[str, FloatArray]
    colliding: frozenset[str]
    mass: dict[str, float]

    def members(self, owner: str) -> list[str]:
        """The links merged into ``owner``, itself first."""
        return [owner, *(link for link, own in self.owner.items() if own == owner and link != owner)]


def _inertial(element: etree._Element) -> tuple[float, FloatArray, FloatArray]:
    """A ``<link>``'s mass, centre of mass (link frame) and inertia tensor about that centre in
    the link's axes; without ``<inertial>``, PyBullet's: :data:`BARE_LINK_MASS` and a unit
    inertia at the link's origin."""
    inertial = element.find("inertial")
    if inertial is None:
        return BARE_LINK_MASS, np.zeros(3), BARE_LINK_MASS * np.eye(3)
    mass_element = inertial.find("mass")
    mass = float(mass_element.get("value", 0.0)) if mass_element is not None else 0.0
    values = dict.fromkeys(INERTIA_KEYS, 0.0)
    tensor = inertial.find("inertia")
    if tensor is not None:
        values.update({key: float(tensor.get(key, 0.0)) for key in INERTIA_KEYS})
    matrix = inertia_tensor(values)
    frame = origin_of(inertial)
    rotation = frame[:3, :3]
    return mass, frame[:3, 3].copy(), rotation @ matrix @ rotation.T


def _combine(parts: list[tuple[float, FloatArray, FloatArray]]) -> tuple[float, FloatArray, FloatArray]:
    """One rigid body's mass, centre and inertia about it from its parts' (parallel axes)."""
    mass = sum(m for m, _, _ in parts)
    centre = sum((m * c for m, c, _ in parts), np.zeros(3)) / mass if mass > 0 else np.zeros(3)
    inertia = np.zeros((3, 3))
    for m, c, tensor in parts:
        d = c - centre
        inertia += tensor + m * (float(d @ d) * np.eye(3) - np.outer(d, d))
    return mass, centre, inertia


def _write_inertial(link: etree._Element, mass: float, centre: FloatArray, inertia: FloatArray) -> None:
    """Make ``link``'s ``<inertial>`` this mass, centre and tensor."""
    for old in link.findall("inertial"):
        link.remove(old)
    inertial = etree.Element("inertial")
    link.insert(0, inertial)
    frame = np.eye(4)
    frame[:3, 3] = centre
    set_origin(inertial, frame)
    etree.SubElement(inertial, "mass", value=repr(float(mass)))
    (ixx, ixy, ixz), (_, iyy, iyz), (_, _, izz) = inertia
    values = (ixx, ixy, ixz, iyy, iyz, izz)
    etree.SubElement(inertial, "inertia", {k: repr(float(v)) for k, v in zip(INERTIA_KEYS, values, strict=True)})


def merge_fixed(urdf: bytes) -> tuple[bytes, Merged]:
    """``urdf`` (the arm as PyBullet loads it, held joints welded) with every link fixed to
    another merged into it, and where each link went.

    A merged link's visuals and collisions move to its owner with their origins composed,
    its mass and inertia are added to the owner's about their common centre, and the joints
    hanging from it hang from the owner. (PyBullet's own ``URDF_MERGE_FIXED_LINKS`` drops the
    owner's centre-of-mass offset: on ar6 it moved the wrist's centre 6 cm, and the arm's end 2 mm
    from the unmerged arm's in 300 steps.)
    """
    root = etree.fromstring(urdf)
    merged = _where(root)  # read before the tree changes
    links = {str(element.get("name")): element for element in root.findall("link")}
    parts: dict[str, list[tuple[float, FloatArray, FloatArray]]] = {}
    for name, element in links.items():
        owner = merged.owner[name]
        if owner == name:
            continue
        offset = merged.offset[name]
        target = links[owner]
        for tag in ("visual", "collision"):
            for child in element.findall(tag):
                set_origin(child, offset @ origin_of(child))
                target.append(child)
        mass, centre, tensor = _inertial(element)  # a massless link's inertia counts too (Franka's link8)
        turn = offset[:3, :3]
        parts.setdefault(owner, []).append((mass, turn @ centre + offset[:3, 3], turn @ tensor @ turn.T))
        root.remove(element)
    hung = {str(j.find("child").get("link")) for j in root.findall("joint")}  # type: ignore[union-attr]
    for owner, extra in parts.items():
        if owner in hung:  # the root is the fixed base: its mass moves nothing, and it keeps its frame
            _write_inertial(links[owner], *_combine([_inertial(links[owner]), *extra]))
    for joint in root.findall("joint"):
        below = str(joint.find("child").get("link"))  # type: ignore[union-attr]
        if merged.owner[below] != below:
            root.remove(joint)
            continue
        parent = joint.find("parent")
        assert parent is not None
        name = str(parent.get("link"))
        if merged.owner[name] != name:
            parent.set("link", merged.owner[name])
            set_origin(joint, merged.offset[name] @ origin_of(joint))
    return bytes(etree.tostring(root)), merged


def _where(root: etree._Element) -> Merged:
    """Which link each link of the URDF ``root`` (the arm as PyBullet loads it, held joints
    welded) is part of once :func:`merge_fixed` has merged the links fixed to another, and where."""
    above = {str(j.find("child").get("link")): j for j in root.findall("joint")}  # type: ignore[union-attr]
    owner: dict[str, str] = {}
    offset: dict[str, FloatArray] = {}
    colliding: set[str] = set()
    mass: dict[str, float] = {}

    def place(link: str) -> None:
        joint = above.get(link)
        if joint is None or joint.get("type") != "fixed":
            owner[link], offset[link] = link, np.eye(4)
            return
        parent = str(joint.find("parent").get("link"))  # type: ignore[union-attr]
        if parent not in owner:
            place(parent)
        owner[link], offset[link] = owner[parent], offset[parent] @ origin_of(joint)

    for element in root.findall("link"):
        name = str(element.get("name"))
        if name not in owner:
            place(name)
        if element.find("collision") is not None:
            colliding.add(name)
        mass[name] = _inertial(element)[0]
    return Merged(owner=owner, offset=offset, colliding=frozenset(colliding), mass=mass)


def unmerged(urdf: bytes) -> Merged:
    """Every link of ``urdf`` as its own link (``PhysicsConfig.merge_fixed_links`` off)."""
    merged = _where(etree.fromstring(urdf))
    return Merged(
        owner={link: link for link in merged.owner},
        offset={link: np.eye(4) for link in merged.owner},
        colliding=merged.colliding,
        mass=merged.mass,
    )


__all__ = ["Merged", "merge_fixed", "unmerged"]
