"""Arms derived from the corpus: a public description, renamed or rehung, written to a test's folder.

A derived file keeps its arm's meshes (their references made absolute), so build it with
``allow_external_meshes=True``. The edits are plain XML: they show what changed from the
published description, and nothing else is written by hand.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import pytest

from armreach_core.diagnostics.corpus import corpus_arm
from armreach_core.robot.urdf import resolve_mesh_path


class Description:
    """A corpus arm's URDF as an XML tree, with the edits a test makes to it."""

    def __init__(self, arm: str) -> None:
        path = corpus_arm(arm).path
        if path is None:
            pytest.skip(f"{arm} is not installed: {corpus_arm(arm).install}")
        self.source = path
        self.root = ET.parse(path).getroot()
        for mesh in self.root.iter("mesh"):
            mesh.set("filename", str(resolve_mesh_path(mesh.get("filename", ""), path.parent)))

    def joint(self, name: str) -> ET.Element:
        found = self.root.find(f"joint[@name='{name}']")
        assert found is not None, name
        return found

    def rename_link(self, old: str, new: str) -> Description:
        for element in self.root.iter():
            if (
                element.tag in ("link", "parent", "child")
                and element.get("name" if element.tag == "link" else "link") == old
            ):
                element.set("name" if element.tag == "link" else "link", new)
        return self

    def rename_joint(self, old: str, new: str) -> Description:
        for element in self.root.iter():
            if element.tag in ("joint", "mimic") and element.get("name" if element.tag == "joint" else "joint") == old:
                element.set("name" if element.tag == "joint" else "joint", new)
        return self

    def rehang(self, joint: str, parent: str, xyz: str | None = None) -> Description:
        """Hang ``joint`` (and its child) from ``parent``, at ``xyz`` there if given."""
        element = self.joint(joint)
        element.find("parent").set("link", parent)  # type: ignore[union-attr]
        if xyz is not None:
            origin = element.find("origin")
            if origin is None:
                origin = ET.SubElement(element, "origin")
            origin.set("xyz", xyz)
            origin.set("rpy", "0 0 0")
        return self

    def add(self, kind: str, name: str, parent: str, child: str, xyz: str = "0 0 0", extra: str = "") -> Description:
        """Add a link ``child`` joined to ``parent`` by a new joint (limits given for movable ones)."""
        ET.SubElement(self.root, "link", name=child)
        limit = '<limit lower="-1" upper="1" effort="1" velocity="1"/>' if kind in ("revolute", "prismatic") else ""
        joint = ET.fromstring(
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="0 0 1"/>{limit}{extra}</joint>'
        )
        self.root.append(joint)
        return self

    def scale(self, k: float) -> Description:
        """The same arm ``k`` times as large: lengths times k, masses k**3, inertias k**5, efforts k**4."""

        def times(text: str | None, factor: float) -> str:
            return " ".join(repr(float(v) * factor) for v in (text or "1 1 1").split())

        for element in self.root.iter():
            if element.tag == "origin" and element.get("xyz") is not None:
                element.set("xyz", times(element.get("xyz"), k))
            elif element.tag == "box":
                element.set("size", times(element.get("size"), k))
            elif element.tag in ("cylinder", "sphere", "capsule"):
                for key in ("radius", "length"):
                    if element.get(key) is not None:
                        element.set(key, times(element.get(key), k))
            elif element.tag == "mesh":
                element.set("scale", times(element.get("scale"), k))
            elif element.tag == "mass":
                element.set("value", times(element.get("value"), k**3))
            elif element.tag == "inertia":
                for key, value in element.attrib.items():
                    element.set(key, times(value, k**5))
            elif element.tag == "limit" and element.get("effort") is not None:
                element.set("effort", times(element.get("effort"), k**4))
        for joint in self.root.iter("joint"):
            limit = joint.find("limit")
            if joint.get("type") == "prismatic" and limit is not None:
                for key in ("lower", "upper"):
                    if limit.get(key) is not None:
                        limit.set(key, times(limit.get(key), k))
        return self

    def edit(self, change: Callable[[ET.Element], None]) -> Description:
        change(self.root)
        return self

    def write(self, folder: Path, name: str = "derived.urdf") -> str:
        path = folder / name
        ET.ElementTree(self.root).write(path, encoding="unicode", xml_declaration=True)
        return str(path)
