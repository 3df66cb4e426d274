"""What the names in a URDF say: gripper joints and parts, tool centres.

Names are hints: :mod:`armreach_core.robot.anatomy` uses them only where the tree's structure
leaves a choice open.
"""

from __future__ import annotations

import re
from typing import Any

__all__ = [
    "GRIPPER_WORDS",
    "PART_WORDS",
    "TOOL_CENTRE_NAMES",
    "is_gripper_part",
    "says_gripper",
    "tool_centre_rank",
    "words",
]

#: Words in a joint's name that make it a gripper joint.
GRIPPER_WORDS = ("finger", "gripper", "jaw", "claw", "knuckle")
#: Words in a link's name that make it a moving gripper part (never a default end effector).
PART_WORDS = ("finger", "jaw", "claw", "knuckle")
#: Names of a tool centre, highest priority first, as patterns over the name's lower-case
#: words joined by ``_`` (``panda_hand_tcp``, ``link_eef``, ``tool0``, ``ee_link``...).
TOOL_CENTRE_NAMES = (
    ("tcp", "tcp"),
    ("tool centre", "tool_?cent(?:er|re)(?:_?point)?"),
    ("grasp target", "grasp_?(?:target|point)"),
    ("tool0", "tool_?0"),
    ("ee_link", "ee(?:_?link)?"),
    ("end effector", "end_?effector"),
    ("eef", "eef"),
)
_PATTERNS = [re.compile(f"(?:^|_){pattern}(?:_|$)") for _, pattern in TOOL_CENTRE_NAMES]


def words(name: str) -> str:
    """``name`` as lower-case words joined by ``_`` (camelCase split): ``gripperStator`` -> ``gripper_stator``."""
    spaced = re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()
    return "_".join(part for part in re.split(r"[^a-z0-9]+", spaced) if part)


def is_gripper_part(link: str) -> bool:
    """Whether a link's name says it is a moving gripper part (a finger, a jaw...)."""
    lowered = link.lower()
    return any(word in lowered for word in PART_WORDS)


def tool_centre_rank(link: str) -> int | None:
    """Priority of ``link`` as a tool centre (0 highest), ``None`` if its name is not one."""
    name = words(link)
    return next((rank for rank, pattern in enumerate(_PATTERNS) if pattern.search(name)), None)


def says_gripper(joint: Any) -> bool:
    """Whether a movable joint is a gripper joint by its name, its child's name or a ``<mimic>``."""
    lowered = str(joint.name).lower()
    return (
        joint.mimic is not None or any(word in lowered for word in GRIPPER_WORDS) or is_gripper_part(str(joint.child))
    )
