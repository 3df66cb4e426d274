"""Meshes in every format trimesh reads, handed to each engine in one it reads.

PyBullet reads ``.obj``, ``.stl`` and ``.dae``; MuJoCo ``.obj``, ``.stl`` and ``.msh``. A
description may use any format trimesh reads (glTF/GLB, PLY, OFF, 3MF, DAE for MuJoCo...):
such a mesh is converted once to ``.obj`` (all its parts, their transforms applied) into the
cache the hulls use (:func:`armreach_core.robot.cache_files.cache_dir`), keyed by the file's name
and contents. A collision mesh becomes its convex hull first
(:mod:`armreach_core.robot.hulls`), which is already an ``.obj``.

An ``.obj`` carries no colour here, so a visual whose URDF gives no ``<material>`` colour
gets the converted mesh's own main colour (a glTF's base colour or its vertex or face
colours), which both engines draw; textures are not carried over.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from lxml import etree

from armreach_core.errors import URDFError
from armreach_core.robot.cache_files import cache_dir, file_key
from armreach_core.robot.hulls import write_obj

log = logging.getLogger("armreach.meshes")

#: The cache folder of converted meshes (under armreach's cache, beside the hulls).
CACHE_KIND = "meshes"


def converted(path: Path) -> Path:
    """An ``.obj`` copy of the mesh at ``path`` (converted once with trimesh, then cached).

    Raises:
        URDFError: trimesh cannot read the file, or it holds no triangles.
    """
    out = cache_dir(CACHE_KIND) / f"{path.stem}-{file_key(path)}.obj"
    if out.is_file():
        return out
    mesh = _load(path)
    colour = _main_colour(mesh)
    if colour is not None:
        out.with_suffix(".rgba").parent.mkdir(parents=True, exist_ok=True)
        out.with_suffix(".rgba").write_text(" ".join(f"{c:.4f}" for c in colour), encoding="utf-8")
    return write_obj(mesh, out)


def colour_of(path: Path) -> tuple[float, ...] | None:
    """The main colour (r, g, b, a in [0, 1]) of a mesh :func:`converted` wrote, if it had one."""
    try:
        return tuple(float(v) for v in path.with_suffix(".rgba").read_text(encoding="utf-8").split())
    except (OSError, ValueError):
        return None


def _load(path: Path) -> Any:
    import trimesh

    fix = "fix the file, or convert it to .stl or .obj and point the URDF at that"
    try:
        mesh = trimesh.load(str(path), force="mesh")
    except Exception as exc:
        detail = str(exc) if type(exc).__name__ in str(exc) else f"{type(exc).__name__}: {exc}"
        raise URDFError(f"mesh {str(path)!r} could not be read by trimesh to convert it ({detail}); {fix}") from None
    vertices, faces = len(getattr(mesh, "vertices", ())), len(getattr(mesh, "faces", ()))
    if faces == 0 or vertices < 4:  # engines reject it, naming only the converted copy
        raise URDFError(
            f"mesh {str(path)!r} has {vertices} vertices and {faces} triangles once read by trimesh, "
            f"and engines need at least 4 vertices and a triangle; {fix}"
        )
    return mesh


def _main_colour(mesh: Any) -> tuple[float, ...] | None:
    """The mesh's main colour in [0, 1], or ``None`` when it has none of its own."""
    try:
        visual = mesh.visual
        if getattr(visual, "kind", None) is None:
            return None
        if visual.kind == "texture":
            material = getattr(visual, "material", None)
            colour = getattr(material, "main_color", None)
        else:
            colour = visual.main_color
        if colour is None:
            return None
        values = tuple(float(c) / 255.0 for c in list(colour)[:4])
    except Exception as exc:  # a colour is a nicety: the mesh itself converted
        log.info("mesh colour not read (%s)", exc)
        return None
    return values if len(values) == 4 else None


def readable(xml: bytes, formats: Sequence[str]) -> bytes:
    """``xml`` (a resolved URDF) with every mesh an engine reading ``formats`` cannot read
    replaced by its converted ``.obj``, visuals without a colour given the mesh's own.

    Raises:
        URDFError: a mesh that trimesh cannot convert.
    """
    root = etree.fromstring(xml)
    wanted = {suffix.lower() for suffix in formats}
    changed = False
    for mesh in root.iter("mesh"):
        filename = Path(mesh.get("filename", ""))
        if filename.suffix.lower() in wanted or not filename.is_file():
            continue
        copy = converted(filename)
        mesh.set("filename", str(copy))
        changed = True
        geometry = mesh.getparent()
        visual = geometry.getparent() if geometry is not None else None
        colour = colour_of(copy)
        if visual is not None and visual.tag == "visual" and colour is not None and not _has_colour(visual):
            for old in visual.findall("material"):
                visual.remove(old)
            material = etree.SubElement(visual, "material", name=f"{copy.stem}_colour")
            etree.SubElement(material, "color", rgba=" ".join(f"{c:.4f}" for c in colour))
    return bytes(etree.tostring(root)) if changed else xml


def _has_colour(visual: etree._Element) -> bool:
    material = visual.find("material")
    return material is not None and material.find("color") is not None
