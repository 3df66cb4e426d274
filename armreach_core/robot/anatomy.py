"""What a URDF's tree says about an arm: where its chain ends, its gripper, its end effector.

:func:`default_end_effector` finds them from the tree and the names alone; nothing here
is tuned to one arm. Walking down from the root link, along the only subtree that holds
movable joints, the arm's chain ends at the link a gripper hangs from (its *mount*):

* the next movable joint is a mimic joint, or its name says gripper (:data:`GRIPPER_WORDS`:
  finger, gripper, jaw...), or its child link is a moving gripper part (:data:`PART_WORDS`;
  a link called ``gripper`` is the gripper's body, which the wrist turns, not a part); or
* the tree branches into two or more subtrees with movable joints, each either named as a
  gripper throughout or holding fewer movable joints than the chain above it (the Panda's
  fingers). Gripper-named branches beside a single other branch are fingers off the chain,
  and the walk goes on into the other one.

The walk never stops before the first movable joint: the arm keeps at least its chain up
to the gripper. Every movable joint below the mount is a gripper joint. Branches that are
none of these (two arms on one torso) make the end effector ambiguous: a
:class:`~armreach_core.errors.URDFError` lists the candidates.

The default end effector is a tool centre named in the URDF (:data:`TOOL_CENTRE_NAMES`, in
that priority) rigidly attached to the mount, else the mount itself; without a gripper, the
tool centre or the tip of the chain. Tips at the same position are equivalent (a UR's
``ee_link`` and ``tool0``): the first one in priority and URDF order is taken.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import URDFError

#: Joint types that armreach actuates.
MOVABLE_TYPES = ("revolute", "continuous", "prismatic")
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
#: Tips closer than this (m) are at the same position.
SAME_PLACE = 1e-9

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


@dataclass(frozen=True)
class EndEffector:
    """The default end effector, why it was chosen, and the gripper joints found on the way."""

    link: str
    reason: str
    gripper_joints: tuple[str, ...]


class Tree:
    """A URDF's links and joints (yourdfpy objects), with the movable joints below each link."""

    def __init__(self, name: str, root: str, links: Iterable[str], joints: Iterable[Any]) -> None:
        self.name = name
        self.root = root
        self.children: dict[str, list[Any]] = {link: [] for link in links}
        self.parent_joint: dict[str, Any] = {}
        for joint in joints:
            self.children[str(joint.parent)].append(joint)
            self.parent_joint[str(joint.child)] = joint
        order = [root]  # breadth first: parents before children
        for link in order:
            order.extend(str(j.child) for j in self.children[link])
        self.order = order
        #: Movable joints below each link, and the most met on one path down from it.
        self.count: dict[str, int] = {}
        self.depth: dict[str, int] = {}
        for link in reversed(order):
            self.count[link] = sum(self.count[str(j.child)] + self._moves(j) for j in self.children[link])
            self.depth[link] = max((self.depth[str(j.child)] + self._moves(j) for j in self.children[link]), default=0)

    @staticmethod
    def _moves(joint: Any) -> int:
        return 1 if str(joint.type) in MOVABLE_TYPES else 0

    def movable_below(self, link: str) -> list[str]:
        """Names of the movable joints in the subtree of ``link``, in breadth-first order."""
        out, frontier = [], [link]
        for here in frontier:
            for joint in self.children[here]:
                if self._moves(joint):
                    out.append(str(joint.name))
                frontier.append(str(joint.child))
        return out

    def _branch_joints(self, joint: Any) -> list[Any]:
        """``joint`` and every joint below it."""
        out, frontier = [joint], [str(joint.child)]
        for here in frontier:
            for below in self.children[here]:
                out.append(below)
                frontier.append(str(below.child))
        return out

    def _gripper_branch(self, joint: Any) -> bool:
        movable = [j for j in self._branch_joints(joint) if self._moves(j)]
        return bool(movable) and all(says_gripper(j) for j in movable)

    def rigid_group(self, link: str) -> dict[str, npt.NDArray[np.float64]]:
        """Links rigidly attached to ``link`` (through fixed joints), with their transforms from the group's top."""
        top = link
        while top in self.parent_joint and str(self.parent_joint[top].type) == "fixed":
            top = str(self.parent_joint[top].parent)
        group = {top: np.eye(4)}
        frontier = [top]
        for here in frontier:
            for joint in self.children[here]:
                if str(joint.type) == "fixed":
                    origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=np.float64)
                    group[str(joint.child)] = group[here] @ origin
                    frontier.append(str(joint.child))
        return group

    # -- the walk ----------------------------------------------------------------------
    def mount(self, start: str | None = None, arm: int = 0) -> tuple[str, tuple[str, ...]]:
        """The link the arm's chain ends at, and the gripper joints below it (none: the chain's tip).

        ``start`` is where the walk begins (default the root), with ``arm`` movable joints above it.

        Raises:
            URDFError: the tree branches into arms, not fingers; the message lists the candidates.
        """
        link = start or self.root
        while True:
            branches = [j for j in self.children[link] if self._moves(j) or self.count[str(j.child)]]
            if not branches:
                return link, ()
            if len(branches) > 1:
                others = [j for j in branches if not self._gripper_branch(j)]
                short = all(self.depth[str(j.child)] + self._moves(j) < arm for j in branches)
                if arm >= 1 and (not others or short):
                    return link, tuple(self.movable_below(link))
                if len(others) != 1:
                    raise self._ambiguous(link, branches)
                branches = others  # fingers beside the arm's continuation stay off the chain
            joint = branches[0]
            if self._moves(joint) and arm >= 1 and says_gripper(joint):
                return link, tuple(self.movable_below(link))
            arm += self._moves(joint)
            link = str(joint.child)

    def _ambiguous(self, link: str, branches: list[Any]) -> URDFError:
        candidates = []
        for joint in branches:
            try:
                child = str(joint.child)
                candidates.append(self.choose(self.mount(child, self._movable_above(child))).link)
            except URDFError:  # branches within the branch: its deepest link
                below = [name for name in self.order if self._descends(name, str(joint.child))]
                candidates.append(max(below, key=lambda name: self._movable_above(name)))
        spelled = "; ".join(f'ee_link="{c}" (Python) or --ee-link {c} (command line)' for c in candidates)
        return URDFError(
            f"the chain of {self.name!r} branches at link {link!r} into {len(branches)} subtrees with movable "
            f"joints ({', '.join(repr(str(j.name)) for j in branches)}) that are not a gripper's fingers, so the "
            f"end effector is ambiguous; choose one of the candidates: {spelled}"
        )

    def _descends(self, link: str, ancestor: str) -> bool:
        while link != ancestor and link in self.parent_joint:
            link = str(self.parent_joint[link].parent)
        return link == ancestor

    def _movable_above(self, link: str) -> int:
        count = 0
        while link in self.parent_joint:
            count += self._moves(self.parent_joint[link])
            link = str(self.parent_joint[link].parent)
        return count

    # -- the end effector --------------------------------------------------------------
    def choose(self, found: tuple[str, tuple[str, ...]]) -> EndEffector:
        """The default end effector at the mount ``found`` (see the module docstring).

        Raises:
            URDFError: two tool centres of the same priority at different places.
        """
        mount, gripper = found
        group = self.rigid_group(mount)
        if not gripper:  # the chain's tip: only links from the last moving link down
            group = {name: t for name, t in group.items() if self._descends(name, mount)}
        usable = {name: t for name, t in group.items() if not is_gripper_part(name)}
        at = f"the link the gripper ({', '.join(gripper)}) hangs from" if gripper else "the tip of the arm's chain"
        ranked = sorted(
            (rank, self.order.index(name), name) for name in usable if (rank := tool_centre_rank(name)) is not None
        )
        if ranked:
            best = [name for rank, _, name in ranked if rank == ranked[0][0]]
            place = usable[best[0]][:3, 3]
            if any(np.linalg.norm(usable[name][:3, 3] - place) > SAME_PLACE for name in best):
                spelled = "; ".join(f'ee_link="{c}" (Python) or --ee-link {c} (command line)' for c in best)
                raise URDFError(
                    f"{self.name!r} names {len(best)} tool centres at different places at {at} "
                    f"({', '.join(repr(c) for c in best)}), so the end effector is ambiguous; choose one: {spelled}"
                )
            link = best[0]
            same = [n for _, _, n in ranked if n != link and np.linalg.norm(usable[n][:3, 3] - place) <= SAME_PLACE]
            kind = TOOL_CENTRE_NAMES[ranked[0][0]][0]
            reason = f"the tool centre the URDF names ({kind}) at {at}, {mount!r}"
            if same:
                reason += f"; {', '.join(repr(n) for n in same)} at the same place"
            return EndEffector(link, reason, gripper)
        if gripper:
            return EndEffector(mount, at, gripper)
        leaves = [name for name in usable if not self.children[name]]
        if leaves and all(np.linalg.norm(usable[n][:3, 3] - usable[leaves[0]][:3, 3]) <= SAME_PLACE for n in leaves):
            return EndEffector(leaves[0], at, ())
        return EndEffector(mount, "the last moving link of the arm's chain (its fixed tips differ)", ())


def default_end_effector(tree: Tree) -> EndEffector:
    """The end effector :class:`RobotModel` uses when none is given (see the module docstring).

    Raises:
        URDFError: the choice is ambiguous; the message lists the candidates.
    """
    return tree.choose(tree.mount())
