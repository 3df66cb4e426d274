"""Fuzzing the robot loader against an oracle: every mutation of a URDF must build, or must be refused.

Hypothesis mutates the bundled ``ar6.urdf`` and a worker process (``tests/fuzz_worker.py``)
loads each result: the robot model, then an env on each installed backend, reset and a few
random steps. Every mutation class declares what it must give:

* **must build**: the model builds and, on every installed backend, the env resets and
  steps with finite observations and rewards;
* **must be refused**: a :class:`~armreach_core.errors.URDFError` (or ``ConfigError``)
  whose message matches every pattern the mutation gives (what is wrong, where, and the
  fix), never another exception out of an engine.

Must build (:data:`BUILD`, :data:`LAYOUTS`): numbers that leave the arm's shape alone set to
values a small arm may have, spelled in every way the checks take; axes scaled; optional
parts deleted; a joint made another movable type or fixed; unknown elements and attributes;
children reordered; comments and processing instructions; fixed links hung anywhere (up to
the 128 links PyBullet serves); meshes inside the robot's folder; meshes outside it when the
caller opts in; inertias not positive semi-definite (repaired and reported); the text on one
line, indented, in CRLF, UTF-16, Latin-1, with a BOM, without a declaration, padded with
comments.

Must be refused (:data:`REFUSED`, :data:`DAMAGES`): numbers that are no plain decimal,
overflow a double, exceed the checks' bound, or come in the wrong count; negative, NaN or
infinite masses; negative damping, friction and sizes (zero masses, singular inertias and
inertias not positive semi-definite build: they are repaired, see
:mod:`armreach_core.robot.inertia`); required parts deleted; unknown, floating or planar
joint types, or a joint of the chain with no range; cycles, duplicates, dangling links,
second parents, second roots; meshes or textures outside the robot's folder (without the
opt-in); missing meshes; too many links; geometry with no, two or unknown shapes or a zero
scale; empty or reversed ranges, zero axes, mimics of nothing; and the text truncated, with
an invalid byte, over the size limit, with a DTD (UTF-16 too), not a ``<robot>``, or in a
namespace.

An example is up to three must-build mutations of the tree, then at most one must-be-refused
mutation of the tree, then a layout, then at most one damage of the text, which the reader
meets first: it must give that damage's refusal, else the tree's, else build. Anything else,
a segmentation fault (the worker dies) or a hang (no answer within :data:`TIME_BOUND`
seconds) fails the test with the mutations that caused it.
:func:`test_the_oracle_fails_on_wrong_outcomes` shows the oracle itself failing on wrong
answers.

The default run is derandomized (the same examples every time): each class forced a few
times, and a few mixed examples; the ``slow`` variant draws many more mixed ones at random.
``ARMREACH_FUZZ_REPORT=FILE`` writes how often each class was drawn and each outcome came back.
"""

from __future__ import annotations

import base64
import codecs
import collections
import contextlib
import copy
import json
import math
import os
import re
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from lxml import etree

from armreach_core.robot.bundled import asset_path
from armreach_core.robot.checks import MAX_LINKS, MAX_MAGNITUDE
from armreach_core.robot.urdf import ALLOW_EXTERNAL_ENV, MAX_LINE_BYTES, MAX_URDF_BYTES
from tests.conftest import BACKENDS

REPO = Path(__file__).resolve().parent.parent
#: Seconds one example may take (model, every backend, reset and steps) before it counts as a hang.
TIME_BOUND = 60.0
STEPS = 3
SOURCE = asset_path("ar6", "ar6.urdf").read_bytes()
COUNTS: collections.Counter[str] = collections.Counter()
#: Most links of a body whose joints PyBullet reads back (getJointState fails on every joint of a
#: body with 128 joints or more); armreach's own limit is MAX_LINKS.
PYBULLET_LINKS = 128
#: A 1x1 PNG image.
PIXEL_PNG = "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNk+M9QDwADhgGAWjR9awAAAABJRU5ErkJggg=="
#: A tetrahedron every engine reads.
TETRAHEDRON_OBJ = "v 0 0 0\nv 0.05 0 0\nv 0 0.05 0\nv 0 0 0.05\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"

pytestmark = pytest.mark.skipif(not BACKENDS, reason="no physics backend installed")
# Hypothesis's own files (no example database is used) go to the temporary folder, not the checkout.
set_hypothesis_home_dir(os.path.join(tempfile.gettempdir(), "armreach-hypothesis"))


# -- the worker -----------------------------------------------------------------------------
class Worker:
    """A long-lived ``tests/fuzz_worker.py`` process, restarted after a crash or a hang."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen[bytes] | None = None
        self.buffer = b""

    def start(self) -> None:
        env = {key: value for key, value in os.environ.items() if key != ALLOW_EXTERNAL_ENV}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.fuzz_worker"],
            cwd=REPO,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
        )
        self.buffer = b""
        ready = self._answer(120.0)
        assert ready == {"outcome": "ready"}, ready

    def _answer(self, timeout: float) -> dict[str, Any]:
        assert self.proc is not None and self.proc.stdout is not None
        deadline = time.monotonic() + timeout
        with selectors.DefaultSelector() as selector:
            selector.register(self.proc.stdout, selectors.EVENT_READ)
            while b"\n" not in self.buffer:
                left = deadline - time.monotonic()
                if left <= 0 or not selector.select(left):
                    self.stop()
                    return {"outcome": "hang", "detail": f"no answer within {timeout:.0f} s"}
                chunk = os.read(self.proc.stdout.fileno(), 65536)
                if not chunk:
                    code = self.proc.wait()
                    self.stop()
                    return {"outcome": "crash", "detail": f"the worker died with exit status {code}"}
                self.buffer += chunk
        line, _, self.buffer = self.buffer.partition(b"\n")
        answer: dict[str, Any] = json.loads(line)
        return answer

    def build(self, path: Path, allow_external_meshes: bool = False) -> dict[str, Any]:
        if self.proc is None:
            self.start()
        assert self.proc is not None and self.proc.stdin is not None
        request = {
            "path": str(path),
            "backends": BACKENDS,
            "steps": STEPS,
            "allow_external_meshes": allow_external_meshes,
        }
        self.proc.stdin.write((json.dumps(request) + "\n").encode())
        self.proc.stdin.flush()
        return self._answer(TIME_BOUND)

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()
            for pipe in (self.proc.stdin, self.proc.stdout):
                if pipe is not None:
                    with contextlib.suppress(OSError):  # a dead reader: nothing left to flush
                        pipe.close()
            self.proc = None


@pytest.fixture(scope="module")
def worker():
    w = Worker()
    yield w
    w.stop()
    report = os.environ.get("ARMREACH_FUZZ_REPORT")
    if report:
        Path(report).write_text(json.dumps(dict(COUNTS), indent=2, sort_keys=True) + "\n")


@dataclass(frozen=True)
class Place:
    """Where the mutated URDFs are written (``robot/``, with a mesh and a link out) and a folder beside it."""

    robot: Path
    outside: Path


@pytest.fixture(scope="module")
def place(tmp_path_factory) -> Place:
    root = tmp_path_factory.mktemp("fuzz")
    robot, outside = root / "robot", root / "outside"
    (robot / "meshes").mkdir(parents=True)
    outside.mkdir()
    (robot / "meshes" / "tip.obj").write_text(TETRAHEDRON_OBJ)
    (outside / "tip.obj").write_text(TETRAHEDRON_OBJ)
    (outside / "skin.png").write_bytes(base64.b64decode(PIXEL_PNG))
    (robot / "meshes" / "link.obj").symlink_to(outside / "tip.obj")  # a link out of the folder
    return Place(robot, outside)


@dataclass(frozen=True)
class Site:
    """What a mutation may refer to: the folders, and whether the caller opts in to files outside."""

    place: Place
    allow_external_meshes: bool


# -- what a mutation must give ---------------------------------------------------------------
@dataclass(frozen=True)
class Change:
    """One mutation: its class, what it did, and the patterns its refusal must match (``None``: it must build,
    or, where ``may_refuse`` names them, be refused with those)."""

    kind: str
    note: str
    refused: tuple[str, ...] | None = None
    may_refuse: tuple[str, ...] = ()

    def __repr__(self) -> str:
        verdict = "must build" if self.refused is None else "must be refused"
        if self.refused is None and self.may_refuse:
            verdict = f"must build or be refused with {self.may_refuse}"
        return f"{self.kind}: {self.note} ({verdict})"


def _refuse(kind: str, note: str, *patterns: str) -> Change:
    return Change(kind, note, patterns)


def _q(text: str | None) -> str:
    """A regex for ``repr(text)`` as a message quotes it."""
    return re.escape(repr(text))


def judge(expected: Change | None, answer: dict[str, Any], where: str = "") -> None:
    """Fail unless ``answer`` is what ``expected`` declares (``None``: a build)."""
    outcome, detail = answer["outcome"], answer.get("detail", "")
    context = f"{expected or 'no refusal drawn (must build)'}{where}"
    assert outcome in ("ok", "refused"), f"{outcome} for {context}:\n{detail}"
    if expected is None or expected.refused is None:
        may = () if expected is None else expected.may_refuse
        if may and outcome == "refused" and all(re.search(p, detail, re.DOTALL) for p in may):
            assert answer["error"] == "URDFError" and "Traceback" not in detail, f"{context}:\n{detail}"
            return
        assert outcome == "ok", f"declared to build, but refused ({answer.get('stage')}) for {context}:\n{detail}"
        return
    assert outcome == "refused", f"declared to be refused, but it built on {detail} for {context}"
    assert answer["error"] in ("URDFError", "ConfigError"), f"{answer['error']} for {context}:\n{detail}"
    assert "Traceback" not in detail, f"a traceback in the message for {context}:\n{detail}"
    missing = [p for p in expected.refused if not re.search(p, detail, re.DOTALL)]
    assert not missing, f"the refusal does not say {missing} for {context}; it says:\n{detail}"


# -- the tree ----------------------------------------------------------------------------------
def _elements(root: etree._Element, tag: str) -> list[etree._Element]:
    return [e for e in root.iter(tag) if isinstance(e.tag, str)]


def _links(root: etree._Element) -> list[str]:
    return [str(link.get("name")) for link in root.findall("link")]


def _owner(element: etree._Element) -> str:
    """The name of the link or joint ``element`` belongs to."""
    node: etree._Element | None = element
    while node is not None and node.tag not in ("link", "joint"):
        node = node.getparent()
    return str(node.get("name")) if node is not None else ""


def _descendants(root: etree._Element, link: str) -> set[str]:
    children: dict[str, list[str]] = collections.defaultdict(list)
    for joint in root.findall("joint"):
        children[str(joint.find("parent").get("link"))].append(str(joint.find("child").get("link")))
    found, todo = set(), [link]
    while todo:
        name = todo.pop()
        if name not in found:
            found.add(name)
            todo += children[name]
    return found


def _joints_of_type(root: etree._Element, *types: str) -> list[etree._Element]:
    return [j for j in root.findall("joint") if j.get("type") in types]


def _numeric_keys() -> set[tuple[str, str]]:
    """(tag, attribute) of every number in ar6.urdf, such as ("origin", "xyz")."""
    found = set()
    for element in etree.fromstring(SOURCE).iter():
        for attribute, value in element.attrib.items():
            try:
                [float(p) for p in value.split()]
            except ValueError:
                continue
            if value.split() and attribute != "name":
                found.add((str(element.tag), attribute))
    return found


NUMERIC_KEYS = _numeric_keys()
#: Numbers the checks leave unbounded (efforts, speeds, damping, friction).
UNBOUNDED = {("limit", "effort"), ("limit", "velocity"), ("dynamics", "damping"), ("dynamics", "friction")}


def _numbers(root: etree._Element, keys: set[tuple[str, str]] = NUMERIC_KEYS) -> list[tuple[etree._Element, str]]:
    return [(e, a) for e in root.iter() for a in e.attrib if (e.tag, a) in keys]


# -- must build ----------------------------------------------------------------------------------
def _sane(tag: str, attribute: str, parent: etree._Element | None) -> st.SearchStrategy[float]:
    """Values of a number that a small arm may have: every engine must take them."""
    if parent is not None and parent.get("type") == "prismatic" and attribute in ("lower", "upper"):
        return st.floats(-0.2, -0.01) if attribute == "lower" else st.floats(0.01, 0.2)  # metres
    if (tag, attribute) == ("origin", "xyz"):
        # a centre of mass near its link: test_a_heavy_link_with_its_centre_of_mass_off_axis_builds_on_pybullet
        return st.floats(-0.1, 0.1) if parent is not None and parent.tag == "inertial" else st.floats(-0.3, 0.3)
    return {
        ("origin", "rpy"): st.floats(-math.pi, math.pi),
        ("mass", "value"): st.floats(0.05, 5.0),
        ("cylinder", "radius"): st.floats(0.01, 0.3),
        ("cylinder", "length"): st.floats(0.01, 0.3),
        ("color", "rgba"): st.floats(0.0, 1.0),
        ("limit", "lower"): st.floats(-3.0, -0.05),
        ("limit", "upper"): st.floats(0.05, 3.0),
        ("limit", "effort"): st.floats(30.0, 300.0),  # weaker motors may hold no pose: nothing to reach
        ("limit", "velocity"): st.floats(0.1, 5.0),
        ("dynamics", "damping"): st.floats(0.0, 2.0),
        ("dynamics", "friction"): st.floats(0.0, 1.0),
    }.get((tag, attribute), st.floats(1e-4, 0.5) if tag == "inertia" else st.just(0.0))


SPELLINGS: list[Callable[[float], str]] = [repr, "{:.6g}".format, "{:+.4f}".format, "{:.3E}".format, "{:e}".format]


def _shapeless(element: etree._Element) -> bool:
    """Whether a number of ``element`` leaves the arm's shape alone: not a joint's origin or axis,
    nor a collision's (which the home must keep clear of the ground and of the other links)."""
    parent = element.getparent()
    return not (
        element.tag == "axis"
        or (element.tag == "origin" and parent is not None and parent.tag in ("joint", "collision"))
        or any(ancestor.tag == "collision" for ancestor in element.iterancestors())
    )


@st.composite
def _sane_number(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """A number that leaves the arm's shape alone set to a value a small arm may have, spelled
    in any of the ways the checks take (exponents, signs, tabs or newlines between numbers)."""
    keys = NUMERIC_KEYS - {("inertia", "ixy"), ("inertia", "ixz"), ("inertia", "iyz")}
    element, attribute = draw(st.sampled_from([(e, a) for e, a in _numbers(root, keys) if _shapeless(e)]))
    parent = element.getparent()
    strategy = _sane(str(element.tag), attribute, parent)
    parts = element.get(attribute, "").split()
    parts[draw(st.integers(0, len(parts) - 1))] = draw(st.sampled_from(SPELLINGS))(draw(strategy))
    separator = draw(st.sampled_from([" ", " ", "  ", "\t", "\n"]))
    element.set(attribute, draw(st.sampled_from(["", " "])) + separator.join(parts))
    return Change("sane number", f"{root.getroottree().getpath(element)}@{attribute}={element.get(attribute)!r}")


@st.composite
def _axis(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """A joint's axis set to its direction times a length from 1e-3 to 1e3: not a unit vector."""
    axis = draw(st.sampled_from([axis for axis in _elements(root, "axis") if axis.get("xyz")]))
    xyz = [float(x) for x in axis.get("xyz", "").split()]
    length = draw(st.sampled_from([1e-3, 0.5, 2.0, 7.0, 1e3])) / math.hypot(*xyz)
    axis.set("xyz", " ".join(f"{x * length:.9g}" for x in xyz))
    return Change("axis scaled", f"joint {_owner(axis)} axis {axis.get('xyz')!r}")


#: Optional parts of a URDF (XPath from a <link> or <joint>, attribute or None for the element):
#: every engine has a default for each. (A joint's origin and axis are optional too, but change
#: the arm's shape: a home clear of the ground and of the other links may no longer exist.)
OPTIONAL = [
    ("dynamics", None), ("dynamics", "damping"), ("dynamics", "friction"), ("limit", "effort"), ("limit", "velocity"),
    ("inertial", None), ("inertial/origin", None), ("inertial/origin", "xyz"), ("inertial/origin", "rpy"),
    ("visual", None), ("collision", None), ("visual/origin", None), ("collision/origin", "rpy"),
    ("visual/material", None), ("visual/material", "name"), ("visual/material/color", None),
    ("visual/material/color", "rgba"),
]  # fmt: skip


@st.composite
def _delete_optional(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    found = [
        (element, attribute)
        for owner in (*root.findall("link"), *root.findall("joint"))
        for path, attribute in OPTIONAL
        for element in owner.findall(path)
        if attribute is None or element.get(attribute) is not None
        # PyBullet refuses a <dynamics> with neither attribute: see _joint_values
        if not (element.tag == "dynamics" and attribute and len(element.attrib) == 1)
    ]
    element, attribute = draw(st.sampled_from(found))
    path = root.getroottree().getpath(element)
    if attribute is None:
        parent = element.getparent()
        assert parent is not None
        parent.remove(element)
    else:
        del element.attrib[attribute]
    return Change("optional part deleted", f"{path}" + (f"@{attribute}" if attribute else ""))


#: The refusal of an arm whose end effector reaches no volume (armreach_core.tasks.reach.task).
NO_VOLUME = r"reaches no volume at least .* above the ground .* check the URDF's joint limits"


@st.composite
def _joint_type_ok(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """A joint of the arm made another movable type, or fixed (while five others move)."""
    movable = _joints_of_type(root, "revolute", "prismatic", "continuous")
    joint = draw(st.sampled_from([j for j in root.findall("joint") if not j.get("name", "").startswith("fuzz_")]))
    limited = joint.find("limit") is not None and joint.find("limit").get("lower") is not None
    kinds = ["revolute", "prismatic", "continuous"] if limited else ["continuous"]
    if len(movable) > 5 or joint not in movable:  # at most one joint of the arm held still
        kinds.append("fixed")
    kind = draw(st.sampled_from(kinds))
    joint.set("type", kind)
    if kind == "prismatic":  # a range in metres
        joint.find("limit").set("lower", repr(draw(_sane("limit", "lower", joint))))
        joint.find("limit").set("upper", repr(draw(_sane("limit", "upper", joint))))
    note = f"joint {joint.get('name')} type={kind!r}"
    moved_by = {j.find("child").get("link") for j in movable if j is not joint}
    if kind in ("prismatic", "fixed") and joint.find("parent").get("link") not in moved_by:
        # the arm no longer turns about its base: its other joints may all move it in one plane
        # (ar6's do), a reach of no volume, which must be refused as such
        return Change("joint type changed", note, may_refuse=(NO_VOLUME,))
    return Change("joint type changed", note)


#: Characters XML text may hold.
XML_CHARACTERS = st.characters(codec="utf-8", exclude_categories=["Cs", "Cc", "Co", "Cn"])
UNKNOWN_TAGS = ["gazebo", "fuzz", "sensor", "ros2_control", "{http://www.ros.org/wiki/xacro}property"]
UNKNOWN_ATTRIBUTES = ["fuzz", "note", "units", "author", "{http://www.ros.org/wiki/xacro}if"]


@st.composite
def _unknown(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """An element or attribute that no URDF reader knows: every reader skips it."""
    holders = [root, *(e for tag in ("link", "joint", "visual", "collision", "inertial") for e in _elements(root, tag))]
    holder = draw(st.sampled_from(holders))
    text = draw(st.text(XML_CHARACTERS, max_size=12))
    if draw(st.booleans()):
        tag = draw(st.sampled_from(UNKNOWN_TAGS))
        element = etree.Element(tag, name=text)
        element.text = text
        etree.SubElement(element, "pose", xyz="nan nan nan")  # not URDF: never read
        holder.insert(draw(st.integers(0, len(holder))), element)
        return Change("unknown element", f"<{etree.QName(tag).localname}> in {root.getroottree().getpath(holder)}")
    attribute = draw(st.sampled_from(UNKNOWN_ATTRIBUTES))
    holder.set(attribute, text)
    return Change("unknown attribute", f"{etree.QName(attribute).localname}= on {root.getroottree().getpath(holder)}")


@st.composite
def _reorder(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    holders = [root, *(e for tag in ("link", "joint", "visual", "collision", "inertial") for e in _elements(root, tag))]
    holder = draw(st.sampled_from([h for h in holders if len(h) > 1]))
    children = draw(st.permutations(list(holder)))
    for child in children:
        holder.append(child)  # appending moves it
    return Change("reordered", f"children of {root.getroottree().getpath(holder)}")


@st.composite
def _comments(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """Comments and processing instructions anywhere inside the tree: they mean nothing to a URDF."""
    holders = [e for e in root.iter() if isinstance(e.tag, str)]
    for _ in range(draw(st.integers(1, 4))):
        holder = draw(st.sampled_from(holders))
        text = draw(st.text(XML_CHARACTERS, max_size=20))
        if draw(st.booleans()):
            node: etree._Element = etree.Comment(text.replace("-", "_"))
        else:
            node = etree.ProcessingInstruction("fuzz", text.replace("?>", ""))
        holder.insert(draw(st.integers(0, len(holder))), node)
    return Change("comments", "comments and processing instructions")


@st.composite
def _extra_links(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """Bare links on fixed joints (a comb, or a chain) hung from any link, up to PyBullet's
    :data:`PYBULLET_LINKS` (see test_a_robot_of_more_links_than_pybullet_serves_builds)."""
    start = len(root.findall("link"))
    if start >= PYBULLET_LINKS:
        return Change("extra links", f"none: {start} links already")
    count = draw(st.integers(1, min(60, PYBULLET_LINKS - start)))
    shape = draw(st.sampled_from(["comb", "chain"]))
    parent = hung = draw(st.sampled_from(_links(root)))
    for i in range(start, start + count):
        root.append(etree.Element("link", name=f"fuzz_{i}"))
        joint = etree.SubElement(root, "joint", name=f"fuzz_j{i}", type="fixed")
        joint.append(etree.Element("parent", link=parent))
        joint.append(etree.Element("child", link=f"fuzz_{i}"))
        joint.append(etree.Element("origin", xyz="0 0 0.001"))
        if shape == "chain":
            parent = f"fuzz_{i}"
    return Change("extra links", f"{count} fixed links ({shape}) under {hung}")


@st.composite
def _mesh_inside(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """A mesh inside the robot's folder, named in any of the ways URDFs name meshes."""
    link = draw(st.sampled_from(root.findall("link")))
    inside = at.place.robot / "meshes" / "tip.obj"
    filename = draw(
        st.sampled_from(["meshes/tip.obj", "./meshes/tip.obj", "package://robot/meshes/tip.obj", str(inside),
                         f"file://{inside}", "meshes/../meshes/tip.obj"])
    )  # fmt: skip
    holder = etree.SubElement(link, draw(st.sampled_from(["visual", "collision"])))
    mesh = etree.SubElement(etree.SubElement(holder, "geometry"), "mesh", filename=filename)
    if draw(st.booleans()):
        mesh.set("scale", draw(st.sampled_from(["1 1 1", "0.5 0.5 0.5", "-1 1 1", "2 1 0.5"])))
    return Change("mesh inside", f"mesh {filename!r} on {link.get('name')}")


@st.composite
def _not_psd(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    link = draw(st.sampled_from([link for link in root.findall("link") if link.find("inertial/inertia") is not None]))
    kind = draw(st.sampled_from(["negative", "products", "negative product"]))
    values = {
        "negative": ["-1", "0", "0", "1", "0", "1"],
        "products": ["1", "2", "2", "1", "2", "1"],
        "negative product": ["0.01", "-0.5", "0", "0.01", "0", "0.01"],
    }[kind]
    inertia = link.find("inertial/inertia")
    for key, value in zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), values, strict=True):
        inertia.set(key, value)
    return Change("inertia not positive semi-definite", f"{link.get('name')}: {kind}")  # repaired, and reported


BUILD = [_sane_number, _sane_number, _axis, _delete_optional, _joint_type_ok, _unknown, _reorder, _comments,
         _extra_links, _mesh_inside, _not_psd]  # fmt: skip


# -- must be refused -----------------------------------------------------------------------------
NOT_DECIMALS = ["nan", "NaN", "inf", "-inf", "Infinity", "abc", "", "1e", "0x10", "1_000", "1,2", "--1", "+-1", ".",
                "∞", "1e-3.5", "0.0.1", "１", "٣", "0\u00a00", "e5", "0b1", "1e+"]  # fmt: skip


def _set_one_number(
    draw: st.DrawFn, root: etree._Element, value: st.SearchStrategy[str], keys: set[tuple[str, str]] = NUMERIC_KEYS
) -> tuple[etree._Element, str, str]:
    """One number of one numeric attribute replaced by a drawn text: (element, attribute, note)."""
    element, attribute = draw(st.sampled_from(_numbers(root, keys)))
    parts = element.get(attribute, "").split()
    parts[draw(st.integers(0, len(parts) - 1))] = draw(value)
    element.set(attribute, " ".join(parts))
    return element, attribute, f"{root.getroottree().getpath(element)}@{attribute}={element.get(attribute)!r}"


@st.composite
def _not_a_decimal(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    element, attribute, note = _set_one_number(draw, root, st.sampled_from(NOT_DECIMALS))
    return _refuse(
        "not a decimal", note, rf"{attribute}=.* of <{element.tag}>", r"is not (a number|\d numbers)", "plain decimals"
    )


@st.composite
def _overflow(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    element, attribute, note = _set_one_number(draw, root, st.sampled_from(["1e309", "-1e309", "2e308", "-1e400"]))
    return _refuse("overflow", note, rf"{attribute}=.* of <{element.tag}>", "overflows a double; use a finite value")


@st.composite
def _beyond(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    big = st.floats(MAX_MAGNITUDE, 1e300, exclude_min=True).flatmap(lambda v: st.sampled_from([repr(v), repr(-v)]))
    element, attribute, note = _set_one_number(draw, root, big, NUMERIC_KEYS - UNBOUNDED)
    return _refuse(
        "beyond the bound", note, rf"{attribute}=.* of <{element.tag}>", r"beyond ±1e\+06", "check the units"
    )


@st.composite
def _count(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    element, attribute = draw(st.sampled_from(_numbers(root)))
    parts = element.get(attribute, "").split()
    parts = parts[:-1] if draw(st.booleans()) else [*parts, "0.5"]
    element.set(attribute, " ".join(parts))
    note = f"{root.getroottree().getpath(element)}@{attribute}={element.get(attribute)!r}"
    return _refuse("wrong count", note, rf"{attribute}=.* of <{element.tag}>", r"is not (a number|\d numbers)")


@st.composite
def _bad_mass(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """A negative, NaN or infinite mass: MuJoCo's compiler stops, PyBullet's mass matrix fails."""
    link = draw(st.sampled_from([link for link in root.findall("link") if link.find("inertial/mass") is not None]))
    value = draw(st.one_of(st.floats(-1e3, -1e-9).map(repr), st.sampled_from(["nan", "NaN", "-inf", "inf", "-0.5"])))
    link.find("inertial/mass").set("value", value)
    name = link.get("name")
    if value.lstrip("-").lower() in ("nan", "inf"):
        return _refuse(
            "bad mass", f"{name}: {value}", rf"value={_q(value)} of <mass> .*link {_q(name)}", "plain decimals"
        )
    return _refuse(
        "bad mass", f"{name}: {value}", rf"value={_q(value)} of <mass> .*link {_q(name)} must be >= 0", "mass in kg"
    )


@st.composite
def _negative(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """Damping, friction or a shape's size below zero (or a size of zero)."""
    keys = {("dynamics", "damping"), ("dynamics", "friction"), ("cylinder", "radius"), ("cylinder", "length")}
    element, attribute = draw(st.sampled_from(_numbers(root, keys)))
    value = draw(st.one_of(st.floats(-1e3, -1e-9).map(repr), st.just("0" if element.tag == "cylinder" else "-1")))
    element.set(attribute, value)
    fix = "use 0 for none" if element.tag == "dynamics" else "lengths in metres, all positive"
    where = rf"{attribute}={_q(value)} of <{element.tag}>.*{_q(_owner(element))} must be >=? 0"
    return _refuse("negative", f"{root.getroottree().getpath(element)}@{attribute}={value!r}", where, fix)


#: Required parts of a link (XPath, attribute or None for the element) and what their absence is called.
LINK_PARTS = [
    ("inertial/mass", None, r"no <mass value=\.\.\.>"), ("inertial/inertia", None, r"no <inertia ixx="),
    ("inertial/mass", "value", "no value="), ("inertial/inertia", "ixx", "no ixx="),
    ("inertial/inertia", "iyz", "no iyz="), ("*/geometry", None, "no <geometry>"),
    ("*/geometry/*", None, "exactly one shape, found 0"), ("*/geometry/cylinder", "radius", "no radius="),
    ("*/geometry/cylinder", "length", "no length="), ("*/geometry/mesh", "filename", "no filename="),
]  # fmt: skip


@st.composite
def _missing(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """A part the URDF format requires, deleted."""
    candidates: list[tuple[etree._Element, str | None, tuple[str, ...]]] = [
        (root, "name", (r"<robot> element has no name=",))
    ]
    for link in root.findall("link"):
        name = _q(link.get("name"))
        candidates += [
            (link, "name", (r"a <link> has no name= attribute",)),
            # every link here is a joint's parent or child
            (link, None, (rf"link={name}> of joint .* names no link of the URDF",)),
        ]
        for part, attribute, said in LINK_PARTS:
            for element in link.findall(part):
                if attribute is None or element.get(attribute) is not None:
                    candidates.append((element, attribute, (said, name)))
    for joint in root.findall("joint"):
        name = _q(joint.get("name"))
        candidates += [
            (joint, "name", (r"a <joint> has no name= attribute",)),
            (joint, "type", (rf"joint {name} has no type= attribute; give it one of",)),
            (joint.find("parent"), None, (rf"joint {name} needs exactly one <parent link=\.\.\.>, found 0",)),
            (joint.find("child"), None, (rf"joint {name} needs exactly one <child link=\.\.\.>, found 0",)),
            (joint.find("parent"), "link", (rf"<parent> of joint {name} has no link= attribute",)),
            (joint, None, (r"exactly one root link, found .* \(links no joint connects\)",)),
        ]
        if joint.find("axis") is not None and joint.find("axis").get("xyz") is not None:
            candidates.append((joint.find("axis"), "xyz", (rf"<axis> of joint {name} has no xyz=",)))
        limit = joint.find("limit")
        if joint.get("type") in ("revolute", "prismatic") and limit is not None:
            said = (
                rf"{joint.get('type')} joint {name} has no <limit lower=\.\.\. upper=\.\.\.>",
                "add the joint's range",
            )
            candidates.append((limit, None, said))  # one bound left out is 0, as URDF says (test_urdf_errors)
    element, attribute, patterns = draw(st.sampled_from(candidates))
    path = root.getroottree().getpath(element)
    if attribute is None:
        parent = element.getparent()
        assert parent is not None
        parent.remove(element)
    else:
        del element.attrib[attribute]
    return _refuse("required part deleted", path + (f"@{attribute}" if attribute else ""), *patterns)


@st.composite
def _bad_joint_type(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    joint = draw(st.sampled_from(root.findall("joint")))
    name = _q(joint.get("name"))
    unlimited = joint.find("limit") is None and not joint.get("name", "").startswith("fuzz_")
    kind = draw(st.sampled_from(["", "hinge", "REVOLUTE", "revolute ", "ball", "floating", "planar"]
                                + (["revolute", "prismatic"] if unlimited else [])))  # fmt: skip
    joint.set("type", kind)
    note = f"joint {joint.get('name')} type={kind!r}"
    if kind in ("floating", "planar"):
        return _refuse("joint type", note, rf"joint {name} has type {_q(kind)}; armreach simulates a fixed-base arm")
    if kind in ("revolute", "prismatic"):  # a joint of the chain that the URDF gives no range
        return _refuse("joint type", note, rf"{kind} joint {name} has no <limit lower=\.\.\. upper=\.\.\.>")
    return _refuse("joint type", note, rf"joint {name} has type {_q(kind)}; URDF joint types are")


@st.composite
def _structure(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    links = _links(root)
    joints = root.findall("joint")
    root_link = next(name for name in links if name not in {j.find("child").get("link") for j in joints})
    kind = draw(st.sampled_from(["cycle", "self loop", "duplicate link", "duplicate joint", "dangling",
                                 "second parent", "second root", "swap", "into its own subtree"]))  # fmt: skip

    def joint(name: str, parent: str, child: str) -> None:
        element = etree.SubElement(root, "joint", name=name, type="fixed")
        element.append(etree.Element("parent", link=parent))
        element.append(etree.Element("child", link=child))

    two_parents = r"is the child of two joints .*; a URDF must be a tree"
    if kind == "cycle":
        joint("fuzz_cycle", draw(st.sampled_from(links)), root_link)
        return _refuse("structure", kind, r"(a cycle|form a cycle)")
    if kind == "self loop":
        link = draw(st.sampled_from(links))
        joint("fuzz_loop", link, link)
        return _refuse("structure", f"{kind} on {link}", two_parents if link != root_link else r"a cycle")
    if kind == "duplicate link":
        link = copy.deepcopy(draw(st.sampled_from(root.findall("link"))))
        root.insert(draw(st.integers(0, len(root))), link)
        return _refuse("structure", f"{kind} {link.get('name')}", rf"link name {_q(link.get('name'))} is used twice")
    if kind == "duplicate joint":  # PyBullet's loader used to crash on these (segmentation fault)
        copied = copy.deepcopy(draw(st.sampled_from(joints)))
        copied.find("child").set("link", "fuzz_extra")
        root.append(copied)
        root.append(etree.Element("link", name="fuzz_extra"))
        return _refuse(
            "structure", f"{kind} {copied.get('name')}", rf"joint name {_q(copied.get('name'))} is used twice"
        )
    if kind == "dangling":
        end = draw(st.sampled_from(["parent", "child"]))
        other = draw(st.sampled_from(links))
        joint(
            "fuzz_dangling", "no_such_link" if end == "parent" else other, "no_such_link" if end == "child" else other
        )
        return _refuse(
            "structure", f"{kind} {end}", rf"<{end} link='no_such_link'> of joint 'fuzz_dangling' names no link"
        )
    if kind == "second parent":
        child = draw(st.sampled_from([name for name in links if name != root_link]))
        joint("fuzz_second", draw(st.sampled_from(links)), child)
        return _refuse("structure", f"{kind} of {child}", two_parents)
    if kind == "second root":
        root.append(etree.Element("link", name="fuzz_island"))
        return _refuse("structure", kind, r"exactly one root link, found .*'fuzz_island'")
    if kind == "swap":  # the parent, which has a parent of its own, becomes a child too
        chosen = draw(st.sampled_from([j for j in joints if j.find("parent").get("link") != root_link]))
        parent, child = chosen.find("parent"), chosen.find("child")
        a, b = parent.get("link"), child.get("link")
        parent.set("link", str(b))
        child.set("link", str(a))
        return _refuse("structure", f"{kind} {chosen.get('name')}", two_parents)
    chosen = draw(st.sampled_from(joints))
    below = sorted(_descendants(root, str(chosen.find("child").get("link"))))
    chosen.find("parent").set("link", draw(st.sampled_from(below)))
    return _refuse("structure", f"{kind}: {chosen.get('name')}", r"(a cycle|form a cycle|child of two joints)")


@st.composite
def _mesh_outside(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """A mesh or texture outside the robot's folder: refused unless the caller opted in."""
    link = draw(st.sampled_from(root.findall("link")))
    outside = at.place.outside / "tip.obj"
    meshes = ["../outside/tip.obj", str(outside), f"file://{outside}", "package://robot/../outside/tip.obj",
              "meshes/link.obj"]  # fmt: skip
    system = [path for path in ("/etc/passwd", "/etc/hostname", "/proc/self/environ") if os.path.isfile(path)]
    allow = at.allow_external_meshes
    filename = draw(st.sampled_from(meshes if allow else meshes + system + ["../../../../../../../../etc/passwd"]))
    holder = etree.SubElement(link, draw(st.sampled_from(["visual", "collision"])))
    mesh = etree.SubElement(etree.SubElement(holder, "geometry"), "mesh", filename="meshes/tip.obj")
    what = draw(st.sampled_from(["mesh", "texture"] if holder.tag == "visual" else ["mesh"]))
    if what == "mesh":
        mesh.set("filename", filename)
    else:
        filename = "../outside/skin.png"
        material = etree.SubElement(holder, "material", name="fuzz_skin")
        etree.SubElement(material, "texture", filename=filename)
    note = f"{what} {filename!r} on {link.get('name')}, opted in: {allow}"
    if allow:
        return Change("file outside, opted in", note)
    return _refuse(
        "file outside", note, rf"{what} {_q(filename)}.* outside the robot's folder",
        rf"allow_external_meshes=True \(or {ALLOW_EXTERNAL_ENV}=1\)",
    )  # fmt: skip


@st.composite
def _mesh_missing(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    link = draw(st.sampled_from(root.findall("link")))
    filename = draw(
        st.sampled_from(["missing.stl", "meshes/missing.obj", "package://robot/meshes/missing.stl", "package://",
                         "file://", ".", "/", "meshes", "/dev/null", "/dev/zero", "a" * 300 + ".stl", "\x7f.stl",
                         "package://no_such_package/tip.obj"])
    )  # fmt: skip
    holder = etree.SubElement(link, draw(st.sampled_from(["visual", "collision"])))
    etree.SubElement(etree.SubElement(holder, "geometry"), "mesh", filename=filename)
    return _refuse(
        "mesh missing", f"{filename[:40]!r} on {link.get('name')}", rf"mesh file {_q(filename)} .*was not found",
        "fix the path",
    )  # fmt: skip


@st.composite
def _too_many_links(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    start = len(root.findall("link"))
    count = draw(st.integers(MAX_LINKS - start + 1, MAX_LINKS - start + 100))
    for i in range(start, start + count):
        root.append(etree.Element("link", name=f"fuzz_{i}"))
        joint = etree.SubElement(root, "joint", name=f"fuzz_j{i}", type="fixed")
        joint.append(etree.Element("parent", link="base_link"))
        joint.append(etree.Element("child", link=f"fuzz_{i}"))
    return _refuse(
        "too many links", f"{count} more links", rf"has {start + count} links, over armreach's limit of 1000"
    )


@st.composite
def _geometry(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    geometry = draw(st.sampled_from(_elements(root, "geometry")))
    where = rf"of link {_q(_owner(geometry))}"
    kind = draw(st.sampled_from(["second shape", "unknown element", "unknown shape", "zero scale"]))
    if kind == "second shape":
        etree.SubElement(geometry, "sphere", radius="0.1")
        return _refuse("geometry", kind, rf"{where} must hold exactly one shape, found 2", "keep one box, cylinder")
    if kind == "unknown element":
        geometry.insert(draw(st.integers(0, len(geometry))), etree.Element("fuzz"))
        return _refuse("geometry", kind, rf"{where} must hold exactly one shape, found 2", "keep one box, cylinder")
    for shape in list(geometry):
        geometry.remove(shape)
    if kind == "unknown shape":
        etree.SubElement(geometry, "cone", radius="0.1", length="0.1")
        return _refuse("geometry", kind, rf"<cone> .*{where} is not a URDF shape; use box, cylinder, sphere or mesh")
    etree.SubElement(geometry, "mesh", filename="meshes/tip.obj", scale=draw(st.sampled_from(["1 0 1", "0 0 0"])))
    return _refuse("geometry", kind, rf"scale=.* of <mesh> .*{where} has a zero factor; use non-zero factors")


@st.composite
def _joint_values(draw: st.DrawFn, root: etree._Element, at: Site) -> Change:
    """A joint's range empty or reversed, its axis zero, a <mimic> of no other joint, or an empty <dynamics>."""
    kinds = ["reversed range", "empty range", "zero axis", "mimic of nothing", "mimic of itself", "empty dynamics"]
    kind = draw(st.sampled_from(kinds))
    limited = [j for j in _joints_of_type(root, "revolute", "prismatic") if j.find("limit") is not None]
    if kind in ("reversed range", "empty range"):
        joint = draw(st.sampled_from(limited))
        name = _q(joint.get("name"))
        value = draw(st.floats(-3.0, 3.0))
        lower, upper = (value + draw(st.floats(1e-3, 3.0)), value) if kind == "reversed range" else (value, value)
        joint.find("limit").set("lower", repr(lower))
        joint.find("limit").set("upper", repr(upper))
        if kind == "reversed range":
            return _refuse(
                "joint values", f"{kind} of {joint.get('name')}", rf"<limit> of joint {name} has lower .* > upper"
            )
        said = rf"joint {name} has lower limit .* >= upper limit"
        fix = r"give it a range \(lower < upper\), or make it type=\"fixed\""
        return _refuse("joint values", f"{kind} of {joint.get('name')}", said, fix)
    movable = _joints_of_type(root, "revolute", "prismatic", "continuous")
    joint = draw(st.sampled_from(movable))
    name = _q(joint.get("name"))
    if kind == "zero axis":
        axis = joint.find("axis")
        if axis is None:
            axis = etree.SubElement(joint, "axis")
        axis.set("xyz", draw(st.sampled_from(["0 0 0", "0 -0 0", "0.0 0e3 -0", "0 0 1e-9", "1e-6 -1e-6 0"])))
        return _refuse("joint values", f"{kind} of {joint.get('name')}", rf"of joint {name} has no direction")
    if kind == "empty dynamics":
        for dynamics in joint.findall("dynamics"):
            joint.remove(dynamics)
        etree.SubElement(joint, "dynamics")
        return _refuse("joint values", f"{kind} of {joint.get('name')}", rf"<dynamics> of joint {name} has neither")
    if kind == "mimic of nothing":
        etree.SubElement(joint, "mimic", joint="no_such_joint")
        return _refuse("joint values", kind, rf"<mimic joint='no_such_joint'> of joint {name} names no joint")
    etree.SubElement(joint, "mimic", joint=str(joint.get("name")))
    return _refuse("joint values", kind, rf"<mimic> of joint {name} names the joint itself")


REFUSED = [_not_a_decimal, _overflow, _beyond, _count, _bad_mass, _negative, _missing, _bad_joint_type,
           _structure, _mesh_outside, _mesh_missing, _too_many_links, _geometry, _joint_values]  # fmt: skip


# -- the text ----------------------------------------------------------------------------------
#: Ways to lay out and encode a URDF's text: every reader must take each.
LAYOUTS = ["as is", "one line", "indented", "CRLF", "no declaration", "BOM", "UTF-16", "Latin-1", "comments around",
           "padded"]  # fmt: skip
#: Damage to the text, which the reader must refuse before looking at the tree.
DAMAGES = ["truncated", "invalid byte", "over the size limit", "DTD", "not a robot", "namespace"]


class Mutated:
    """A mutated URDF's text, whether the caller opts in to external meshes, and what was done to it."""

    def __init__(self, text: bytes, allow_external_meshes: bool, changes: list[Change]) -> None:
        self.text, self.allow_external_meshes, self.changes = text, allow_external_meshes, changes

    @property
    def expected(self) -> Change | None:
        """The refusal the reader meets first (the text's damage, then the tree's), or ``None``: must build."""
        refusals = [change for change in self.changes if change.refused is not None]
        optional = [change for change in self.changes if change.may_refuse]  # builds, or may be refused
        return refusals[-1] if refusals else optional[-1] if optional else None

    def __repr__(self) -> str:  # shown, instead of the text, when a test fails
        return f"Mutated({len(self.text)} bytes, opted in: {self.allow_external_meshes}, {self.changes})"


def _one_line(root: etree._Element) -> None:
    """Drop the whitespace between elements."""
    for element in root.iter():
        if len(element) and (element.text or "").strip() == "":
            element.text = None
        if (element.tail or "").strip() == "":
            element.tail = None


def _encode(draw: st.DrawFn, root: etree._Element, layout: str) -> bytes:
    if layout == "one line":
        _one_line(root)
    elif layout == "indented":
        etree.indent(root, space=draw(st.sampled_from(["  ", "\t", ""])))
    body = etree.tostring(root, encoding="unicode")
    declaration = '<?xml version="1.0" encoding="{}"?>\n'
    if layout == "UTF-16":
        return (declaration.format("UTF-16") + body).encode("utf-16")
    if layout == "Latin-1":
        return (declaration.format("ISO-8859-1") + body).encode("latin-1", "xmlcharrefreplace")
    text = declaration.format("utf-8") + body
    if layout == "no declaration":
        text = body
    elif layout == "CRLF":
        text = text.replace("\n", "\r\n")
    elif layout == "comments around":
        text = text.replace("?>\n", "?>\n<!-- before -->\n<?fuzz before?>\n", 1) + "\n<!-- after -->\n"
    elif layout == "padded":
        text += "\n<!--" + " " * draw(st.integers(0, 100_000)) + "-->\n" + " " * draw(st.integers(0, 1000))
    data = text.encode()
    return codecs.BOM_UTF8 + data if layout == "BOM" else data


#: Layouts in UTF-8, which every damage applies to (the others take the first three).
UTF8_LAYOUTS = [layout for layout in LAYOUTS if layout not in ("UTF-16", "Latin-1")]


def _damage(draw: st.DrawFn, data: bytes, layout: str, kind: str | None = None) -> tuple[bytes, Change]:
    if kind is None:
        kind = draw(st.sampled_from(DAMAGES if layout in UTF8_LAYOUTS else DAMAGES[:3]))
    malformed = ("is not well-formed XML", "fix the markup")
    if kind == "truncated":  # somewhere before the end of </robot>
        end = "</robot>".encode("utf-16-le" if layout == "UTF-16" else "latin-1")
        at = draw(st.integers(0, data.rfind(end) + len(end) - 1))
        return data[:at], _refuse("damage", f"truncated to {at} bytes", *malformed)
    if kind == "invalid byte":  # never valid in XML 1.0, nor in UTF-8
        if layout == "UTF-16":  # any two bytes make a character there: cut one instead
            at = draw(st.integers(0, len(data) - 1))
            return data[:at] + data[at + 1 :], _refuse("damage", f"byte {at} deleted", *malformed)
        at = draw(st.integers(0, len(data) - 1))
        byte = draw(st.sampled_from([0x00, 0x01, 0x08, 0x0B, 0x1F] + ([0xFF, 0xFE] if layout in UTF8_LAYOUTS else [])))
        return data[:at] + bytes([byte]) + data[at + 1 :], _refuse("damage", f"byte {byte:#x} at {at}", *malformed)
    if kind == "over the size limit":
        size = MAX_URDF_BYTES + draw(st.integers(1, 64))
        filler = size - len(data) - len(b"<!---->")
        padding = b"<!--" + b" " * filler + b"-->" if draw(st.booleans()) else b" " * (filler + len(b"<!---->"))
        return data + padding, _refuse(
            "damage", f"padded to {size} bytes", rf"is {size} bytes, over armreach's limit of {MAX_URDF_BYTES} bytes",
            "strip padding",
        )  # fmt: skip
    text = data.decode("utf-8").lstrip("\ufeff")
    if kind == "DTD":
        utf16 = draw(st.booleans())  # a DTD the reader's byte scan cannot see
        choices = ['<!DOCTYPE robot [<!ENTITY x "y">]>', "<!DOCTYPE robot>", '<!DOCTYPE robot SYSTEM "robot.dtd">']
        dtd = draw(st.sampled_from(choices if utf16 else [*choices, "<!doctype robot>", "<!ENTITY x 'y'>"]))
        text = text.replace("?>", "?>\n" + dtd, 1) if text.startswith("<?xml") else dtd + "\n" + text
        encoded = text.replace('encoding="utf-8"', 'encoding="UTF-16"').encode("utf-16") if utf16 else text.encode()
        note = f"{dtd!r}" + (" in UTF-16" if utf16 else "")
        return encoded, _refuse("damage", note, r"declares a DTD or XML entities.*remove the <!DOCTYPE>")
    if kind == "not a robot":
        start = text.index("<robot")
        return (text[:start] + "<sdf>" + text[start:] + "</sdf>").encode(), _refuse(
            "damage", "inside <sdf>", r"has root element <sdf>, expected <robot>; is it a URDF\?"
        )
    # the root tag as written: ``<robot name=...>``, or a bare ``<robot>`` where a mutation took its name
    namespaced = re.sub(r"<robot(?=[\s/>])", '<robot xmlns="http://example.com/robot"', text, count=1)
    return namespaced.encode(), _refuse(
        "damage", "default namespace", r"in the XML namespace 'http://example.com/robot'.*remove the xmlns= attribute"
    )


Mutation = Callable[[etree._Element, Site], st.SearchStrategy[Change]]


@st.composite
def mutated_urdfs(
    draw: st.DrawFn,
    place: Place,
    build: Mutation | None = None,
    refused: Mutation | None = None,
    damage: str | None = None,
    layout: str | None = None,
) -> Mutated:
    """ar6.urdf after up to three must-build mutations, maybe a must-be-refused one, a layout, maybe damage.

    ``build``, ``refused``, ``damage`` and ``layout`` force one class: ``build`` or ``layout``
    with no refusal and no damage, ``refused`` with no damage.
    """
    root = etree.fromstring(SOURCE)
    allow = draw(st.sampled_from([False, False, False, True]))
    at = Site(place, allow)
    forced = build is not None or layout is not None
    changes = [draw(build(root, at))] if build is not None else []
    changes += [draw(draw(st.sampled_from(BUILD))(root, at)) for _ in range(draw(st.integers(0, 3 - len(changes))))]
    if refused is not None or (not forced and damage is None and draw(st.booleans())):
        changes.append(draw((refused or draw(st.sampled_from(REFUSED)))(root, at)))
    if layout is None:
        layout = draw(st.sampled_from(LAYOUTS if damage in (None, *DAMAGES[:3]) else UTF8_LAYOUTS))
    changes.append(Change("layout", layout))
    data = _encode(draw, root, layout)
    if damage is not None or (not forced and refused is None and draw(st.sampled_from([False] * 4 + [True]))):
        data, change = _damage(draw, data, layout, damage)
        changes.append(change)
    return Mutated(data, allow, changes)


# -- the tests --------------------------------------------------------------------------------
def _check(worker: Worker, place: Place, example: Mutated) -> None:
    COUNTS["inputs"] += 1
    for change in example.changes:
        COUNTS[f"class {change.kind}"] += 1
    path = place.robot / f"fuzz-{COUNTS['inputs']}.urdf"  # a new name: caches key on path and mtime
    path.write_bytes(example.text)
    answer = worker.build(path, example.allow_external_meshes)
    COUNTS[f"outcome {answer['outcome']}"] += 1
    judge(example.expected, answer, f"\n  all changes: {example.changes}\n  (input kept at {path})")
    path.unlink()


FAST = settings(
    max_examples=25,
    deadline=None,
    database=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.function_scoped_fixture],
)


@FAST
@given(data=st.data())
def test_a_mutated_urdf_builds_or_is_refused_as_declared(worker, place, data):
    _check(worker, place, data.draw(mutated_urdfs(place)))


@pytest.mark.parametrize("mutation", list(dict.fromkeys(BUILD)), ids=lambda m: m.__name__.strip("_"))
@settings(FAST, max_examples=2)
@given(data=st.data())
def test_each_must_build_class_builds(worker, place, mutation, data):
    _check(worker, place, data.draw(mutated_urdfs(place, build=mutation)))


@pytest.mark.parametrize("layout", LAYOUTS)
@settings(FAST, max_examples=1)
@given(data=st.data())
def test_each_layout_builds(worker, place, layout, data):
    _check(worker, place, data.draw(mutated_urdfs(place, layout=layout)))


@pytest.mark.parametrize("mutation", REFUSED, ids=lambda m: m.__name__.strip("_"))
@settings(FAST, max_examples=8)
@given(data=st.data())
def test_each_must_be_refused_class_as_declared(worker, place, mutation, data):
    _check(worker, place, data.draw(mutated_urdfs(place, refused=mutation)))


@pytest.mark.parametrize("damage", DAMAGES)
@settings(FAST, max_examples=4)
@given(data=st.data())
def test_each_damage_is_refused(worker, place, damage, data):
    _check(worker, place, data.draw(mutated_urdfs(place, damage=damage)))


def test_a_one_line_urdf_longer_than_pybullet_reads_a_line_builds(worker, place):
    """PyBullet cuts lines longer than 8191 bytes, inside names and numbers: armreach lays the text out."""
    root = etree.fromstring(SOURCE)
    names = [link.get("name") for link in root.findall("link")]
    for i in range(60):
        root.append(etree.Element("link", name=f"extra_{i}"))
        joint = etree.SubElement(root, "joint", name=f"extra_j{i}", type="fixed")
        etree.SubElement(joint, "parent", link=str(names[i % len(names)]))
        etree.SubElement(joint, "child", link=f"extra_{i}")
        etree.SubElement(joint, "origin", xyz=f"0.{i:03d}71 0 0.0123456789")
    _one_line(root)
    path = place.robot / "one-line.urdf"
    path.write_bytes(etree.tostring(root))
    assert b"\n" not in path.read_bytes() and path.stat().st_size > MAX_LINE_BYTES
    judge(None, worker.build(path))


@pytest.mark.slow
@settings(FAST, max_examples=int(os.environ.get("ARMREACH_FUZZ_EXAMPLES", "2000")), derandomize=False)
@given(data=st.data())
def test_a_mutated_urdf_builds_or_is_refused_as_declared_many(worker, place, data):
    _check(worker, place, data.draw(mutated_urdfs(place)))


@pytest.mark.skipif("pybullet" not in BACKENDS, reason="PyBullet is not installed")
def test_a_robot_of_more_links_than_pybullet_serves_builds(worker, place):
    """ar6 and 120 bare links on fixed joints: 129 links, 128 joints. PyBullet reads back no
    joint of a body with 128 joints or more (getJointState fails), but the links fixed to
    another are merged into it before it loads the arm (armreach_pybullet.merge), so both
    engines build it."""
    root = etree.fromstring(SOURCE)
    for i in range(PYBULLET_LINKS - len(root.findall("link")) + 1):
        root.append(etree.Element("link", name=f"extra_{i}"))
        joint = etree.SubElement(root, "joint", name=f"extra_j{i}", type="fixed")
        etree.SubElement(joint, "parent", link="world")
        etree.SubElement(joint, "child", link=f"extra_{i}")
    path = place.robot / "many-links.urdf"
    path.write_bytes(etree.tostring(root))
    judge(None, worker.build(path))


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_heavy_link_with_its_centre_of_mass_off_axis_builds_on_pybullet(tmp_path, backend):
    """An industrial arm's upper arm: 120 kg, its centre of mass 0.3 m and 0.4 m off two axes.

    A must-build case the fuzzer's sane numbers stay clear of (centres of mass within 0.1 m,
    masses up to 5 kg). PyBullet's inverse dynamics refuses it (its inertia about the joint
    is asymmetric by rounding); the backend then takes the joint inertias from the URDF.
    """
    from armreach_core import ArmReach6DOFEnv

    root = etree.fromstring(SOURCE)
    inertial = next(link for link in root.findall("link") if link.get("name") == "upper_arm_link").find("inertial")
    inertial.find("mass").set("value", "120")
    inertial.find("origin").set("xyz", "0.3 0.4 0.2")
    path = tmp_path / "heavy.urdf"
    path.write_bytes(etree.tostring(root))
    env = ArmReach6DOFEnv(backend=backend, urdf=path)
    try:
        env.reset(seed=0)
        for _ in range(3):
            observation, *_ = env.step(env.action_space.sample())
        assert all(math.isfinite(float(x)) for x in observation)
    finally:
        env.close()


def test_the_oracle_fails_on_wrong_outcomes():
    """A build where a refusal was declared, a refusal where a build was, a message that does not say
    the problem or the fix, an engine's exception, a crash: each fails."""
    negative_mass = _refuse("bad mass", "x: -1", r"value='-1' of <mass>", "mass in kg")
    refused = {"outcome": "refused", "error": "URDFError", "stage": "model", "detail": "value='-1' of <mass> ..."}
    built = {"outcome": "ok", "detail": "mujoco,pybullet"}
    judge(None, built)
    judge(negative_mass, {**refused, "detail": "value='-1' of <mass> must be >= 0; give the link's mass in kg"})
    planar = Change("joint type changed", "joint shoulder_pan_joint type='fixed'", may_refuse=(NO_VOLUME,))
    no_volume = "the arm of 'a.urdf' reaches no volume at least 0.05 m above the ground (reach about 1.25 m), so it "
    no_volume += "has no targets to reach; check the URDF's joint limits and link lengths, or lower min_target_height"
    judge(planar, built)
    judge(planar, {**refused, "stage": "mujoco", "detail": no_volume})
    wrong = [
        (negative_mass, built),
        (None, refused),
        (Change("sane number", "x"), refused),
        (negative_mass, {**refused, "detail": "value='-1' of <mass> must be >= 0"}),  # no fix
        (negative_mass, {**refused, "error": "ValueError"}),
        (negative_mass, {**refused, "detail": "Traceback (most recent call last): value='-1' of <mass> mass in kg"}),
        (negative_mass, {"outcome": "error", "detail": "pybullet.error: ..."}),
        (None, {"outcome": "crash", "detail": "the worker died"}),
        (planar, refused),  # a refusal other than the one it may meet
        (None, {**refused, "detail": no_volume}),  # no change that may leave the arm without a volume
    ]
    for expected, answer in wrong:
        with pytest.raises(AssertionError):
            judge(expected, answer)


def test_the_worker_reports_crashes_and_hangs(worker, place):
    """The harness itself can fail: a worker that raises, dies of a signal, or never answers."""
    if worker.proc is None:
        worker.start()
    assert worker.proc is not None and worker.proc.stdin is not None
    worker.proc.stdin.write(b'{"path": "x", "backends": [], "steps": "not a number"}\n')
    worker.proc.stdin.flush()
    assert worker._answer(30.0)["outcome"] == "error"
    worker.proc.send_signal(signal.SIGSEGV)  # what a segmentation fault delivers
    assert worker.build(place.robot / "x.urdf")["outcome"] == "crash"
    assert worker.proc is None
    worker.start()
    assert worker.proc is not None
    worker.proc.send_signal(signal.SIGSTOP)  #: it will never answer
    assert worker._answer(1.0)["outcome"] == "hang"
    assert worker.proc is None
