"""Safe reading of URDF files: no XML entities, resolved mesh paths, clear errors.

Every URDF that armreach touches goes through :func:`read_urdf`. It refuses DTDs and
entity declarations before any XML parser sees the file (so neither a billion-laughs
bomb nor an external entity pointing at a local file is ever expanded), parses with an
lxml parser that resolves nothing and reaches no network, and hands the checked text to
yourdfpy. Mesh references (``package://``, ``file://``, relative or absolute) are
resolved to absolute paths here, once, so that every backend loads the same files.
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass
from pathlib import Path

import yourdfpy
from lxml import etree

from armreach_core.errors import URDFError

#: Largest URDF file accepted, in bytes. Real robot descriptions are far smaller.
MAX_URDF_BYTES = 16 * 1024 * 1024

_DTD_PATTERN = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)


@dataclass(frozen=True)
class ParsedURDF:
    """A URDF read safely: its yourdfpy model, its folder and its XML with meshes resolved."""

    path: Path
    model: yourdfpy.URDF
    resolved_xml: bytes


def _safe_parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_comments=True,
    )


def resolve_mesh_path(filename: str, urdf_dir: Path) -> Path:
    """Map a mesh reference of a URDF to the file it names.

    ``package://PKG/rest`` is looked up as ``PKG/rest`` in the URDF's folder and each
    of its parents, then as ``rest`` in the URDF's folder; ``file://`` is stripped;
    relative paths are relative to the URDF's folder.

    Raises:
        URDFError: no such file exists.
    """
    candidates: list[Path] = []
    if filename.startswith("package://"):
        rest = filename[len("package://") :]
        for folder in (urdf_dir, *urdf_dir.parents):
            candidates.append(folder / rest)
        pkg_relative = rest.split("/", 1)[1] if "/" in rest else rest
        candidates.append(urdf_dir / pkg_relative)
    else:
        plain = filename[len("file://") :] if filename.startswith("file://") else filename
        path = Path(plain)
        candidates.append(path if path.is_absolute() else urdf_dir / path)
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    raise URDFError(
        f"mesh file {filename!r} referenced by the URDF was not found (looked in "
        f"{', '.join(str(c) for c in candidates[:3])}{'...' if len(candidates) > 3 else ''}); "
        "ship the mesh beside the URDF or fix the path"
    )


def read_urdf(path: str | os.PathLike[str]) -> ParsedURDF:
    """Read and check a URDF file.

    Raises:
        URDFError: the file is missing, too large, declares a DTD or entities, is not
            well-formed XML, is not a ``<robot>``, or names a mesh that does not exist.
    """
    urdf_path = Path(path).expanduser()
    if not urdf_path.is_file():
        raise URDFError(f"URDF file not found: {str(urdf_path)!r}; pass the path of an existing .urdf file")
    size = urdf_path.stat().st_size
    if size > MAX_URDF_BYTES:
        raise URDFError(
            f"URDF file {str(urdf_path)!r} is {size} bytes, over the {MAX_URDF_BYTES}-byte limit; "
            "is it really a robot description?"
        )
    data = urdf_path.read_bytes()
    if _DTD_PATTERN.search(data):
        raise URDFError(
            f"URDF file {str(urdf_path)!r} declares a DTD or XML entities, which armreach never expands "
            "(they can read local files or explode in size); remove the <!DOCTYPE>/<!ENTITY> declarations"
        )
    try:
        root = etree.fromstring(data, parser=_safe_parser())
    except etree.XMLSyntaxError as exc:
        raise URDFError(f"URDF file {str(urdf_path)!r} is not well-formed XML: {exc}") from None
    if not isinstance(root.tag, str) or etree.QName(root).localname != "robot":
        raise URDFError(f"URDF file {str(urdf_path)!r} has root element <{root.tag}>, expected <robot>")

    urdf_dir = urdf_path.resolve().parent
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename")
        if not filename:
            raise URDFError(f"URDF file {str(urdf_path)!r} has a <mesh> without a filename attribute")
        mesh.set("filename", str(resolve_mesh_path(filename, urdf_dir)))
    resolved = b'<?xml version="1.0" encoding="utf-8"?>\n' + etree.tostring(root, encoding="utf-8")
    try:
        model = yourdfpy.URDF.load(
            io.BytesIO(resolved),
            build_scene_graph=False,
            load_meshes=False,
            mesh_dir=str(urdf_dir),
        )
    except Exception as exc:  # yourdfpy raises bare ValueError/KeyError/TypeError on bad content
        raise URDFError(f"URDF file {str(urdf_path)!r} could not be parsed: {type(exc).__name__}: {exc}") from None
    return ParsedURDF(path=urdf_path.resolve(), model=model, resolved_xml=resolved)
