"""Fuzzing the robot loader: a mutated URDF gives a working env on every backend, or a URDFError.

Hypothesis mutates the bundled ``ar6.urdf`` (numbers made NaN, infinite, negative, huge
or garbage; negative masses; degenerate inertias; deleted tags and attributes; wrong
joint types; cycles and duplicate names; bad mesh paths; truncated text; many links)
and a worker process (``tests/fuzz_worker.py``) loads each result: the robot model,
then an env on each installed backend, reset and a few random steps. Every example
must come back as ``ok`` (finite observations and rewards) or ``urdf_error``. Another
exception, a segmentation fault (the worker dies) or a hang (no answer within
:data:`TIME_BOUND` seconds) fails the test with the input that caused it.

The default run is small and derandomized (the same examples every time); the ``slow``
variant draws many more at random. ``ARMREACH_FUZZ_REPORT=FILE`` writes the counts.
"""

from __future__ import annotations

import collections
import contextlib
import copy
import json
import os
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir
from lxml import etree

from armreach_core.robot.bundled import asset_path
from armreach_core.robot.urdf import MAX_URDF_BYTES
from tests.conftest import BACKENDS

REPO = Path(__file__).resolve().parent.parent
#: Seconds one example may take (model, every backend, reset and steps) before it counts as a hang.
TIME_BOUND = 60.0
STEPS = 3
SOURCE = asset_path("ar6", "ar6.urdf").read_bytes()
COUNTS: collections.Counter[str] = collections.Counter()

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
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "tests.fuzz_worker"],
            cwd=REPO,
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

    def build(self, path: Path) -> dict[str, Any]:
        if self.proc is None:
            self.start()
        assert self.proc is not None and self.proc.stdin is not None
        request = {"path": str(path), "backends": BACKENDS, "steps": STEPS}
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


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


# -- mutations --------------------------------------------------------------------------------
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
BAD_NUMBERS = st.sampled_from(
    ["nan", "NaN", "inf", "-inf", "Infinity", "1e309", "-1e309", "1e300", "-1e300", "1e7", "-1e7", "1e6", "-0",
     "0", "-1", "-1e-9", "1e-300", "5e-324", "abc", "", " ", "1e", "0x10", "1_000", "1,2", "--1", "+.5", ".",
     "∞", "1e-3.5", "0.0.1", "１"]
)  # fmt: skip
ANY_NUMBER = st.one_of(
    BAD_NUMBERS,
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(min_value=-1e3, max_value=1e3).map(lambda x: f"{x:.6g}"),
    st.integers(min_value=-(10**40), max_value=10**40).map(str),
)
#: Numbers an engine must cope with: valid for the checks, but extreme for physics.
PLAUSIBLE_NUMBERS = st.one_of(
    st.sampled_from(["0", "-0", "1e-12", "1e-9", "1e-6", "0.001", "1e3", "1e5", "-1e5", "1e6", "-1e6", "3.14159"]),
    st.floats(min_value=-1e6, max_value=1e6).map(lambda x: f"{x:.17g}"),
    st.floats(min_value=-10, max_value=10).map(lambda x: f"{x:.4f}"),
)
JOINT_TYPES = st.sampled_from(
    ["revolute", "continuous", "prismatic", "fixed", "floating", "planar", "", "hinge", "REVOLUTE", "revolute ", "ball"]
)
MESH_PATHS = st.sampled_from(
    ["/etc/passwd", "../../../../etc/passwd", "package://ar6/../../../../etc/hostname", "file:///etc/hostname",
     "missing.stl", "package://", "file://", "package://ar6/ar6.urdf", "ar6.urdf", ".", "/", "/dev/zero",
     "/proc/self/environ", "\x7f.stl", "a" * 300 + ".stl"]
)  # fmt: skip


def _elements(root: etree._Element, tag: str) -> list[etree._Element]:
    return [e for e in root.iter(tag) if isinstance(e.tag, str)]


@st.composite
def _mutate_number(draw: st.DrawFn, root: etree._Element) -> str:
    numbers = [
        (element, attribute)
        for element in root.iter()
        for attribute in element.attrib
        if (element.tag, attribute) in NUMERIC_KEYS
    ]
    element, attribute = draw(st.sampled_from(numbers))
    path = root.getroottree().getpath(element)
    parts = element.get(attribute).split() or ["0"]
    count = len(parts)
    how = draw(st.sampled_from(["one", "one", "all", "plausible", "plausible", "plausible", "fewer", "more"]))
    if how == "one":
        parts[draw(st.integers(0, count - 1))] = draw(ANY_NUMBER)
    elif how == "plausible":
        parts[draw(st.integers(0, count - 1))] = draw(PLAUSIBLE_NUMBERS)
    elif how == "all":
        parts = [draw(ANY_NUMBER) for _ in parts]
    elif how == "fewer":
        parts = parts[:-1]
    else:
        parts.append(draw(ANY_NUMBER))
    element.set(attribute, " ".join(parts))
    return f"number {path}@{attribute}={element.get(attribute)!r}"


@st.composite
def _mutate_inertial(draw: st.DrawFn, root: etree._Element) -> str:
    link = draw(st.sampled_from([link for link in _elements(root, "link") if link.find("inertial") is not None]))
    inertial = link.find("inertial")
    kind = draw(st.sampled_from(["negative mass", "zero mass", "zero", "degenerate", "negative", "triangle",
                                 "products", "tiny", "huge"]))  # fmt: skip
    # an earlier mutation of the same URDF may have deleted either element
    mass = inertial.find("mass")
    if mass is None:
        mass = etree.SubElement(inertial, "mass", value="1")
    inertia = inertial.find("inertia")
    if inertia is None:
        inertia = etree.SubElement(inertial, "inertia")
    values = {
        "zero": ["0"] * 6,
        "degenerate": ["1", "0", "0", "0", "0", "0"],
        "negative": ["-1", "0", "0", "1", "0", "1"],
        "triangle": ["1", "0", "0", "1", "0", "5"],
        "products": ["1", "2", "2", "1", "2", "1"],
        "tiny": ["1e-20", "0", "0", "1e-20", "0", "1e-20"],
        "huge": ["1e6", "0", "0", "1e6", "0", "1e6"],
    }
    if kind == "negative mass":
        mass.set("value", repr(-draw(st.floats(min_value=1e-9, max_value=1e3))))
    elif kind == "zero mass":
        mass.set("value", "0")
    else:
        for key, value in zip(("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), values[kind], strict=True):
            inertia.set(key, value)
    return f"inertial {link.get('name')}: {kind}"


@st.composite
def _delete(draw: st.DrawFn, root: etree._Element) -> str:
    elements = [e for e in root.iter() if isinstance(e.tag, str) and e is not root]
    element = draw(st.sampled_from(elements))
    if element.attrib and draw(st.booleans()):
        attribute = draw(st.sampled_from(sorted(element.attrib)))
        del element.attrib[attribute]
        return f"delete {root.getroottree().getpath(element)}@{attribute}"
    path = root.getroottree().getpath(element)
    parent = element.getparent()
    assert parent is not None
    parent.remove(element)
    return f"delete {path}"


@st.composite
def _joint_type(draw: st.DrawFn, root: etree._Element) -> str:
    joint = draw(st.sampled_from(_elements(root, "joint")))
    kind = draw(JOINT_TYPES)
    joint.set("type", kind)
    return f"joint {joint.get('name')} type={kind!r}"


@st.composite
def _structure(draw: st.DrawFn, root: etree._Element) -> str:
    links = [link.get("name") for link in _elements(root, "link")]
    joints = _elements(root, "joint")
    kind = draw(st.sampled_from(["cycle", "self loop", "duplicate link", "duplicate joint", "dangling",
                                 "reparent", "swap", "second parent", "second root"]))  # fmt: skip
    if kind in ("cycle", "self loop", "dangling", "second parent"):
        parent = draw(st.sampled_from(links))
        child = {
            "cycle": links[0],
            "self loop": parent,
            "dangling": "no_such_link",
            "second parent": draw(st.sampled_from(links)),
        }[kind]
        etree.SubElement(root, "joint", name=f"fuzz_{kind.replace(' ', '_')}", type="fixed")
        root[-1].append(etree.Element("parent", link=parent))
        root[-1].append(etree.Element("child", link=child))
    elif kind == "duplicate link":
        root.append(copy.deepcopy(draw(st.sampled_from(_elements(root, "link")))))
    elif kind == "duplicate joint":
        joint = copy.deepcopy(draw(st.sampled_from(joints)))
        joint.find("child").set("link", "fuzz_extra")
        root.append(joint)
        root.append(etree.Element("link", name="fuzz_extra"))
    elif kind == "reparent":
        draw(st.sampled_from(joints)).find("parent").set("link", draw(st.sampled_from(links)))
    elif kind == "swap":
        joint = draw(st.sampled_from(joints))
        parent, child = joint.find("parent"), joint.find("child")
        a, b = parent.get("link"), child.get("link")
        parent.set("link", b)
        child.set("link", a)
    else:
        root.append(etree.Element("link", name="fuzz_island"))
    return f"structure: {kind}"


@st.composite
def _mesh(draw: st.DrawFn, root: etree._Element) -> str:
    link = draw(st.sampled_from(_elements(root, "link")))
    filename = draw(MESH_PATHS)
    holder = etree.SubElement(link, draw(st.sampled_from(["visual", "collision"])))
    geometry = etree.SubElement(holder, "geometry")
    etree.SubElement(geometry, "mesh", filename=filename)
    return f"mesh {filename!r} on {link.get('name')}"


@st.composite
def _many_links(draw: st.DrawFn, root: etree._Element) -> str:
    """Dummy links on fixed joints (a comb on the base, or a chain), up to past the link limit."""
    count = draw(st.integers(1, 1100))
    shape = draw(st.sampled_from(["comb", "chain"]))
    parent = "base_link"
    for i in range(count):
        root.append(etree.Element("link", name=f"fuzz_{i}"))
        joint = etree.SubElement(root, "joint", name=f"fuzz_j{i}", type="fixed")
        joint.append(etree.Element("parent", link=parent))
        joint.append(etree.Element("child", link=f"fuzz_{i}"))
        joint.append(etree.Element("origin", xyz="0 0 0.001"))
        if shape == "chain":
            parent = f"fuzz_{i}"
    return f"{count} extra links ({shape})"


MUTATIONS = [_mutate_number, _mutate_number, _mutate_inertial, _delete, _delete, _joint_type, _structure, _mesh]


class Mutated:
    """A mutated URDF's text and what was done to it (shown, instead of the text, when a test fails)."""

    def __init__(self, text: bytes, notes: list[str]) -> None:
        self.text, self.notes = text, notes

    def __repr__(self) -> str:
        return f"Mutated({len(self.text)} bytes: {'; '.join(self.notes)})"


@st.composite
def mutated_urdfs(draw: st.DrawFn) -> Mutated:
    """ar6.urdf after one to three mutations (rarely, many links), then maybe a damaged text or padding."""
    root = etree.fromstring(SOURCE)
    notes = []
    for _ in range(draw(st.sampled_from([1, 1, 2, 3]))):
        notes.append(draw(draw(st.sampled_from(MUTATIONS))(root)))
    if draw(st.integers(0, 19)) == 0:
        notes.append(draw(_many_links(root)))
    text = etree.tostring(root, xml_declaration=True, encoding="utf-8")
    damage = draw(st.sampled_from(["none"] * 12 + ["truncate", "flip", "pad"]))
    if damage == "truncate":
        text = text[: draw(st.integers(0, len(text) - 1))]
    elif damage == "flip":
        at = draw(st.integers(0, len(text) - 1))
        text = text[:at] + bytes([draw(st.integers(0, 255))]) + text[at + 1 :]
    elif damage == "pad":  # whitespace up to just under, or just over, the size limit
        target = MAX_URDF_BYTES + draw(st.sampled_from([-64, 1]))
        text = text + b" " * max(target - len(text), 0)
    if damage != "none":
        notes.append(damage)
    return Mutated(text, notes)


# -- the tests --------------------------------------------------------------------------------
def _check(worker: Worker, scratch: Path, example: Mutated) -> None:
    text, notes = example.text, example.notes
    COUNTS["inputs"] += 1
    path = scratch / f"fuzz-{COUNTS['inputs']}.urdf"  # a new name: caches key on path and mtime
    path.write_bytes(text)
    answer = worker.build(path)
    COUNTS[answer["outcome"]] += 1
    try:
        assert answer["outcome"] in ("ok", "urdf_error"), (
            f"{answer['outcome']} for mutations {notes}:\n{answer['detail']}\n(input kept at {path})"
        )
    finally:
        if answer["outcome"] in ("ok", "urdf_error"):
            path.unlink()


FAST = settings(
    max_examples=40,
    deadline=None,
    database=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.function_scoped_fixture],
)


@FAST
@given(example=mutated_urdfs())
def test_mutated_urdf_gives_an_env_or_a_urdf_error(worker, scratch, example):
    _check(worker, scratch, example)


@pytest.mark.slow
@settings(FAST, max_examples=int(os.environ.get("ARMREACH_FUZZ_EXAMPLES", "2000")), derandomize=False)
@given(example=mutated_urdfs())
def test_mutated_urdf_gives_an_env_or_a_urdf_error_many(worker, scratch, example):
    _check(worker, scratch, example)


def test_the_worker_reports_crashes_and_hangs(scratch):
    """The harness itself can fail: a worker killed by a signal, or one that never answers."""
    w = Worker()
    w.start()
    assert w.proc is not None
    w.proc.send_signal(signal.SIGSEGV)  # what a segmentation fault delivers
    assert w.build(scratch / "x.urdf")["outcome"] == "crash"
    w.start()
    assert w.proc is not None and w.proc.stdin is not None
    w.proc.stdin.write(b'{"path": "x", "backends": [], "steps": "not a number"}\n')
    w.proc.stdin.flush()
    assert w._answer(30.0)["outcome"] == "error"
    w.proc.stdin.write(b"\n")  # not JSON: the worker dies, and a dead worker is a crash
    w.proc.stdin.flush()
    assert w._answer(30.0)["outcome"] == "crash"
    w.start()
    assert w.proc is not None
    w.proc.send_signal(signal.SIGSTOP)  #: it will never answer
    assert w._answer(1.0)["outcome"] == "hang"
    assert w.proc is None
