"""What a URDF's tree says about an arm: where its chain ends, its gripper, its end effector.

:func:`default_end_effector` finds them from the tree's structure first and the names second;
nothing here is tuned to one arm. Walking down from the root link, along the only subtree that
holds movable joints, the arm's chain ends at the link a gripper hangs from (its *mount*).

A movable joint on the way is an **arm joint** (a wrist) when it carries another joint that
moves on its own (not a ``<mimic>``), or carries the tool centre the URDF names: a jaw moves
against another jaw and carries neither, so such a joint is never held, whatever its or its
child's name says (an SO-100 whose gripper body ``Fixed_Jaw`` hangs on ``wrist_roll``).
Otherwise it is a **gripper joint**, and the chain ends above it, when

* it is a ``<mimic>`` joint, or other joints mimic it (a finger linkage); or
* (a hint, used only where the structure leaves the choice open) its name says gripper
  (:mod:`armreach_core.robot.names`: finger, gripper, jaw...) or its child link is a moving
  gripper part (a link called ``gripper`` is the gripper's body, which the wrist turns, not a
  part), unless every movable joint above it says so too: the word then names the whole arm
  (a TriFinger finger, whose joints are all ``finger_...``), not a gripper at its end.

Where the tree branches into two or more subtrees with movable joints, a subtree is a
finger when it carries no tool centre and either mimics or is mimicked by a sibling, or is a
prismatic joint beside another (parallel fingers), or is named as a gripper throughout. All
fingers, or subtrees all shallower than the chain above them (the Panda's fingers): the
gripper hangs here. Fingers beside a single other subtree hang off the chain, and the walk
goes on into the other one; so does it into the one subtree whose movable joints carry the
named tool centre (a wrist beside a jaw off the chain).

The walk never stops before the first movable joint: the arm keeps at least its chain up
to the gripper. Every movable joint below the mount is a gripper joint. Branches that are
none of these (two arms on one torso) make the end effector ambiguous: a
:class:`~armreach_core.errors.URDFError` lists the candidates.

The default end effector is a tool centre named in the URDF
(:data:`~armreach_core.robot.names.TOOL_CENTRE_NAMES`, in that priority) rigidly attached to
the mount, else the mount itself; without a gripper, the tool centre or the tip of the chain
(named like the arm's own links, a tip counts even if its name says finger). When tool
centres compete, one past the gripper mount (below it in the tree, between the fingers: a
WidowX's ``ee_gripper_link`` beats its ``ee_arm_link``) wins over those at or above the
mount. Tips at the same position are equivalent (a UR's ``ee_link`` and ``tool0``): the
first one in priority and URDF order is taken. Of tool centres of the same standing at
different places, one hanging from the others through fixed joints wins (the end of a chain
of tool frames: iiwa_link_ee below iiwa_link_ee_x); otherwise they are a real tie (an error).
Every decision is kept with its reason (:attr:`EndEffector.decisions`) and logged.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import URDFError
from armreach_core.robot.names import TOOL_CENTRE_NAMES, is_gripper_part, says_gripper, tool_centre_rank

#: Joint types that armreach actuates.
MOVABLE_TYPES = ("revolute", "continuous", "prismatic")
#: Tips closer than this (m) are at the same position.
SAME_PLACE = 1e-9


@dataclass(frozen=True)
class EndEffector:
    """The default end effector, why it was chosen, and the gripper joints found on the way.

    ``decisions`` says, one line each, why joints were taken for the arm or the gripper and
    why one tool centre won over others.
    """

    link: str
    reason: str
    gripper_joints: tuple[str, ...]
    decisions: tuple[str, ...] = ()


class Tree:
    """A URDF's links and joints (yourdfpy objects), with the movable joints below each link."""

    def __init__(self, name: str, root: str, links: Iterable[str], joints: Iterable[Any]) -> None:
        self.name = name
        self.root = root
        self.children: dict[str, list[Any]] = {link: [] for link in links}
        self.parent_joint: dict[str, Any] = {}
        #: Joints by name, and the joints that mimic each joint.
        self.joints: dict[str, Any] = {}
        self.followers: dict[str, list[str]] = {}
        for joint in joints:
            self.children[str(joint.parent)].append(joint)
            self.parent_joint[str(joint.child)] = joint
            self.joints[str(joint.name)] = joint
            if joint.mimic is not None and self._moves(joint):
                self.followers.setdefault(str(joint.mimic.joint), []).append(str(joint.name))
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
        #: Why joints were taken for the arm or the gripper, in the order decided (see :meth:`mount`).
        self.decisions: list[str] = []

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

    def _tool_centres_below(self, joint: Any) -> list[str]:
        """Links below ``joint`` (its child included) whose names make them a tool centre."""
        return [str(j.child) for j in self._branch_joints(joint) if tool_centre_rank(str(j.child)) is not None]

    def _moves_tool_centre(self, joint: Any) -> bool:
        """Whether a movable joint at or below ``joint`` carries a tool centre the URDF names (a wrist does)."""
        for tool in self._tool_centres_below(joint):
            link = tool
            while link != str(joint.parent):
                above = self.parent_joint[link]
                if self._moves(above):
                    return True
                link = str(above.parent)
        return False

    def _finger(self, joint: Any, siblings: list[Any]) -> str | None:
        """Why the subtree of ``joint`` is a finger beside ``siblings``, or ``None`` if it is not one."""
        movable = [j for j in self._branch_joints(joint) if self._moves(j)]
        if not movable or self._tool_centres_below(joint):
            return None
        names = {str(j.name) for s in siblings for j in self._branch_joints(s) if s is not joint}
        for j in movable:
            master = str(j.mimic.joint) if j.mimic is not None else None
            if master in names or names & set(self.followers.get(str(j.name), ())):
                return "it moves with a sibling through a <mimic>"
        prismatic = [
            s for s in siblings if s is not joint and str(s.type) == "prismatic" and not self.count[str(s.child)]
        ]
        if str(joint.type) == "prismatic" and not self.count[str(joint.child)] and prismatic:
            return "a prismatic finger beside another"
        if all(says_gripper(j) for j in movable):
            return "its joints' names say gripper (a hint)"
        return None

    def _jaw(self, joint: Any) -> tuple[bool, str | None]:
        """Whether a movable joint on the chain moves a jaw (ends the chain), and why (``None``: nothing to say)."""
        name = str(joint.name)
        hint = says_gripper(joint)
        if hint and joint.mimic is None and self._named_like_the_arm(joint):
            self.decisions.append(f"{name!r} is an arm joint: its name says gripper, as every joint above it does")
            hint = False
        if joint.mimic is not None:
            return True, f"{name!r} is a gripper joint: it mimics {str(joint.mimic.joint)!r}"
        own = [j for j in self.movable_below(str(joint.child)) if self.joints[j].mimic is None]
        if own:
            if not hint:
                return False, None
            return False, (
                f"{name!r} is an arm joint although its name or its child's says gripper: it carries {own[0]!r}, "
                "which moves on its own, so it is a wrist, never a jaw"
            )
        if name in self.followers:
            return True, f"{name!r} is a gripper joint: {', '.join(map(repr, self.followers[name]))} mimic it"
        tools = self._tool_centres_below(joint)
        if tools and hint:
            return False, (
                f"{name!r} is an arm joint although its name or its child's says gripper: it carries the tool "
                f"centre {tools[0]!r}"
            )
        if hint:
            return (
                True,
                f"{name!r} is a gripper joint: the last joint of the chain, and its name or its child's says so",
            )
        return False, None

    def _named_like_the_arm(self, joint: Any) -> bool:
        """Whether ``joint`` has movable joints above it and every one of them says gripper too."""
        above = [j for j in self._joints_above(str(joint.parent)) if self._moves(j)]
        return bool(above) and all(says_gripper(j) for j in above)

    def _joints_above(self, link: str) -> Iterator[Any]:
        """The joints between ``link`` and the root, nearest first."""
        while link in self.parent_joint:
            yield self.parent_joint[link]
            link = str(self.parent_joint[link].parent)

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
        The reasons for its choices are appended to :attr:`decisions`.

        Raises:
            URDFError: the tree branches into arms, not fingers; the message lists the candidates.
        """
        link = start or self.root
        while True:
            branches = [j for j in self.children[link] if self._moves(j) or self.count[str(j.child)]]
            if not branches:
                return link, ()
            if len(branches) > 1:
                why = {str(j.name): self._finger(j, branches) for j in branches}
                others = [j for j in branches if why[str(j.name)] is None]
                short = all(self.depth[str(j.child)] + self._moves(j) < arm for j in branches)
                wrists = [j for j in branches if self._moves_tool_centre(j)]
                if arm >= 1 and len(wrists) == 1:  # the one subtree whose joints move the tool centre goes on
                    for j in branches:
                        if j is not wrists[0]:
                            why[str(j.name)] = why[str(j.name)] or f"{str(wrists[0].name)!r} moves the tool centre"
                    others, short = wrists, False
                if arm >= 1 and (not others or short):
                    self.decisions.append(
                        f"the gripper hangs from {link!r}: its subtrees "
                        + "; ".join(
                            f"{str(j.name)!r}: {why[str(j.name)] or 'shallower than the arm'}" for j in branches
                        )
                    )
                    return link, tuple(self.movable_below(link))
                if len(others) != 1:
                    raise self._ambiguous(link, branches)
                for j in branches:
                    if j is not others[0]:
                        self.decisions.append(
                            f"{str(j.name)!r} is a finger off the chain at {link!r}: {why[str(j.name)]}"
                        )
                branches = others  # fingers beside the arm's continuation stay off the chain
            joint = branches[0]
            if self._moves(joint) and arm >= 1:
                jaw, reason = self._jaw(joint)
                if reason is not None:
                    self.decisions.append(reason)
                if jaw:
                    return link, tuple(self.movable_below(link))
            arm += self._moves(joint)
            link = str(joint.child)

    def gripper_below(self, chain: list[str]) -> tuple[str, ...]:
        """The gripper joints of the arm whose joints from the root are ``chain`` (an end effector given):
        from the root, or where the tree branches above the arm (wheels, a mast, a second arm), from
        the chain's last movable joint down."""
        try:
            return self.mount()[1]
        except URDFError:
            moving = [name for name in chain if self._moves(self.joints[name])]
            if not moving:
                raise
            self.decisions.clear()
            return self.mount(str(self.joints[moving[-1]].child), len(moving))[1]

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
        return sum(self._moves(j) for j in self._joints_above(link))

    # -- the end effector --------------------------------------------------------------
    def choose(self, found: tuple[str, tuple[str, ...]]) -> EndEffector:
        """The default end effector at the mount ``found`` (see the module docstring).

        Raises:
            URDFError: two tool centres of the same standing at different places.
        """
        mount, gripper = found
        group = self.rigid_group(mount)
        if not gripper:  # the chain's tip: only links from the last moving link down
            group = {name: t for name, t in group.items() if self._descends(name, mount)}
        arm_word = not gripper and is_gripper_part(mount)  # the chain's own last link says finger: the arm's word
        usable = {name: t for name, t in group.items() if arm_word or not is_gripper_part(name)}
        at = f"the link the gripper ({', '.join(gripper)}) hangs from" if gripper else "the tip of the arm's chain"
        ranked = sorted(
            (rank, self.order.index(name), name) for name in usable if (rank := tool_centre_rank(name)) is not None
        )
        notes = list(self.decisions)
        if gripper and ranked:
            past = [r for r in ranked if r[2] != mount and self._descends(r[2], mount)]
            if past and len(past) < len(ranked):
                ahead = {name for *_, name in past}
                behind = [name for *_, name in ranked if name not in ahead]
                notes.append(
                    f"tool centre {past[0][2]!r} is past the gripper mount {mount!r} (between the fingers), so it "
                    f"wins over {', '.join(map(repr, behind))}, at or above the mount"
                )
                ranked = past
        if ranked:
            best = [name for rank, _, name in ranked if rank == ranked[0][0]]
            place = usable[best[0]][:3, 3]
            apart = any(np.linalg.norm(usable[name][:3, 3] - place) > SAME_PLACE for name in best)
            nested = sorted(best, key=self.order.index)  # breadth first: parents first
            if apart and all(self._descends(b, a) for a, b in itertools.pairwise(nested)):
                notes.append(
                    f"tool centre {nested[-1]!r} hangs from {', '.join(map(repr, nested[:-1]))} through fixed joints, "
                    "so it wins: the end of that chain of tool frames"
                )
                best, place, apart = [nested[-1]], usable[nested[-1]][:3, 3], False
            if apart:
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
            return EndEffector(link, reason, gripper, tuple(notes))
        if gripper:
            return EndEffector(mount, at, gripper, tuple(notes))
        leaves = [name for name in usable if not self.children[name]]
        if leaves and all(np.linalg.norm(usable[n][:3, 3] - usable[leaves[0]][:3, 3]) <= SAME_PLACE for n in leaves):
            return EndEffector(leaves[0], at, (), tuple(notes))
        return EndEffector(mount, "the last moving link of the arm's chain (its fixed tips differ)", (), tuple(notes))


def default_end_effector(tree: Tree) -> EndEffector:
    """The end effector :class:`RobotModel` uses when none is given (see the module docstring).

    Raises:
        URDFError: the choice is ambiguous; the message lists the candidates.
    """
    tree.decisions.clear()
    return tree.choose(tree.mount())
