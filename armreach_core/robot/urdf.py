"""Safe reading of URDF files: no XML entities, resolved mesh paths, clear errors.

Every URDF that armreach touches goes through :func:`read_urdf`. It refuses files over
:data:`MAX_URDF_BYTES` before reading them, and DTDs and entity declarations before any XML
parser sees the file (so neither a billion-laughs bomb nor an external entity pointing at
a local file is ever expanded; a DTD in an encoding the byte scan cannot see, such as
UTF-16, is refused once parsed), parses with an lxml parser that resolves nothing, reaches
no network and drops comments and processing instructions, and hands the checked text to
yourdfpy. Every link and joint is checked first (:mod:`armreach_core.robot.checks`:
plain finite numbers, non-negative masses, valid inertias, unique names), so engines
only ever see values they handle. Mesh references (``package://``, ``file://``,
relative or absolute) are resolved to absolute paths here, once, so that every backend
loads the same files; files outside the URDF's folder or ROS package are refused unless
the user opts in (:func:`resolve_mesh_path`). The text handed on is laid out one element
per line: PyBullet's URDF reader cuts lines longer than :data:`MAX_LINE_BYTES`, which
garbles a one-line (minified) URDF's names and numbers. Another tool's extensions under an
XML prefix the file never declares (Drake's ``drake:acceleration``: ROS's parser reads past
them) are dropped with a warning rather than refused (:func:`_undeclared_prefixes`).
"""

from __future__ import annotations

import io
import logging
import os
import re
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import yourdfpy
from lxml import etree

from armreach_core.errors import URDFError
from armreach_core.robot.checks import check_tree
from armreach_core.robot.freeze import freeze_joints
from armreach_core.robot.packages import ROS_PACKAGE_PATH, Packages
from armreach_core.robot.xacro_sandbox import is_xacro, process_xacro

#: Largest URDF file accepted, in bytes. Real robot descriptions are far smaller.
MAX_URDF_BYTES = 16 * 1024 * 1024
#: Longest line of the URDF text engines are given, in bytes. PyBullet reads a URDF through
#: an 8192-byte line buffer and breaks longer lines, inside a name or a number if need be.
MAX_LINE_BYTES = 8191
#: Set to 1 to let URDFs use meshes outside their own folder or package (see :func:`resolve_mesh_path`).
ALLOW_EXTERNAL_ENV = "ARMREACH_ALLOW_EXTERNAL_MESHES"

_DTD_PATTERN = re.compile(rb"<!\s*(DOCTYPE|ENTITY)", re.IGNORECASE)
_ROBOT_TAG = re.compile(rb"<robot(?=[\s/>])")
#: An XML declaration and the version it gives.
_DECLARATION = re.compile(rb"""<\?xml\s+version\s*=\s*(["'])([0-9]+\.[0-9]+)\1""")


def _lenient(data: bytes) -> bytes:
    """``data`` with what PyBullet's XML reader takes and libxml2 refuses made plain XML, as
    pybullet_data's own descriptions need: blank lines before the XML declaration, and a declared
    version other than 1.0 or 1.1 (``<?xml version="0.0" ?>``). Anything else stays refused."""
    body = data.lstrip(b" \t\r\n")
    if not body.startswith(b"<?xml"):
        return data
    match = _DECLARATION.match(body)
    if match is not None and match.group(2) not in (b"1.0", b"1.1"):
        body = body[: match.start(2)] + b"1.0" + body[match.end(2) :]
    return body


#: Namespace given to a prefix a URDF uses without declaring it, so that its elements and
#: attributes can be told apart and dropped.
UNDECLARED_NAMESPACE = "urn:armreach:undeclared:"
log = logging.getLogger("armreach.robot")


@dataclass(frozen=True)
class ParsedURDF:
    """A URDF read safely: its yourdfpy model, its folder and its XML with meshes resolved."""

    path: Path
    model: yourdfpy.URDF
    resolved_xml: bytes
    #: What ``frozen_joints`` made fixed, one sentence a joint (:func:`~armreach_core.robot.freeze.freeze_joints`).
    frozen: tuple[str, ...] = ()


def _safe_parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        # libxml2's own caps (a comment or a text over 10 MB) would refuse a file under
        # MAX_URDF_BYTES, read in full already, as "not well-formed"; that size bounds them
        huge_tree=True,
        remove_comments=True,
        remove_pis=True,  # MuJoCo's XML reader takes a processing instruction for a malformed declaration
    )


def allow_external_meshes_default() -> bool:
    """Whether ``ARMREACH_ALLOW_EXTERNAL_MESHES`` opts in to meshes outside the robot's folder."""
    return os.environ.get(ALLOW_EXTERNAL_ENV, "").strip().lower() in ("1", "true", "yes", "on")


def mesh_roots(urdf_dir: Path, package: str | None = None, packages: Packages | None = None) -> list[Path]:
    """The folders a URDF in ``urdf_dir`` may take files from, without opting in.

    The URDF's own folder; the ROS package it lives in: the nearest folder at or above it
    holding a ``package.xml``, or its parent when the URDF sits in a ``urdf/`` or
    ``robots/`` folder (the usual ``urdf/`` and ``meshes/`` siblings); the packages the
    user named or put on ``ROS_PACKAGE_PATH`` (:class:`~armreach_core.robot.packages.Packages`);
    and, for ``package://PKG/...``, the folder of ``PKG``.
    """
    packages = packages or Packages.of(urdf_dir)
    return packages.roots(*([package] if package else []))


def _is_file(path: Path) -> bool:
    """``path.is_file()``, False for names the system cannot even look up (too long, NUL bytes)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _inside(path: Path, roots: list[Path]) -> bool:
    return any(path == root or path.is_relative_to(root) for root in roots)


def _find(
    filename: str, urdf_dir: Path, allow_external: bool, what: str, packages: Packages | None = None
) -> tuple[Path | None, list[Path]]:
    """The file a reference names (``None`` if none exists) and the places looked in."""
    packages = packages or Packages.of(urdf_dir)
    candidates: list[Path] = []
    package: str | None = None
    if filename.startswith("package://"):
        rest = filename[len("package://") :].lstrip("/")  # package:///NAME/...: NAME/... (pinocchio reads it so)
        package, _, pkg_relative = rest.partition("/")
        folder = packages.find(package)
        if folder is not None and pkg_relative:
            candidates.append(folder / pkg_relative)
        for above in (urdf_dir, *urdf_dir.parents):
            candidates.append(above / rest)
        own = packages.own
        candidates += [root / pkg_relative for root in (urdf_dir, *([own] if own else [])) if pkg_relative]
    else:
        plain = filename[len("file://") :] if filename.startswith("file://") else filename
        path = Path(plain)
        candidates.append(path if path.is_absolute() else urdf_dir / path)
    roots = mesh_roots(urdf_dir, package, packages)
    outside: Path | None = None
    for candidate in candidates:
        if _is_file(candidate):
            real = candidate.resolve()
            if allow_external or _inside(real, roots):
                return real, candidates
            outside = outside or real
    if outside is not None:
        raise URDFError(
            f"{what} {filename!r} referenced by the URDF is {str(outside)!r}, outside the robot's folder "
            f"({', '.join(str(r) for r in roots)}); armreach does not read files outside a URDF's folder or "
            f"package unless asked to: name its package with package_dirs={{NAME: PATH}} (--package-dir NAME=PATH), "
            f"move the {what} inside, or opt in with allow_external_meshes=True "
            f"(or {ALLOW_EXTERNAL_ENV}=1) if you trust this URDF"
        )
    return None, candidates


def resolve_mesh_path(
    filename: str, urdf_dir: Path, *, allow_external: bool = False, packages: Packages | None = None
) -> Path:
    """Map a mesh reference of a URDF to the file it names.

    ``package://PKG/rest`` (or ``package:///PKG/rest``, as example-robot-data's full TALOS writes
    it) is looked up as ``rest`` in the folder of package ``PKG``
    (:meth:`~armreach_core.robot.packages.Packages.find`), then as ``PKG/rest`` in the URDF's
    folder and each of its parents, then as ``rest`` in the URDF's folder and its package
    root; ``file://`` is stripped; relative paths are relative to the URDF's folder.

    Unless ``allow_external``, the file (symbolic links followed) must lie inside one of
    :func:`mesh_roots`: a URDF from elsewhere must not make armreach read, say,
    ``../../.ssh/id_rsa`` or ``/etc/shadow`` and hand it to an engine.

    Raises:
        URDFError: no such file exists, or it lies outside the robot's folder.
    """
    packages = packages or Packages.of(urdf_dir)
    found, candidates = _find(filename, urdf_dir, allow_external, "mesh", packages)
    if found is None:
        package = (
            filename[len("package://") :].lstrip("/").partition("/")[0] if filename.startswith("package://") else None
        )
        fix = "ship the mesh beside the URDF or fix the path"
        if package is not None and packages.find(package) is None:
            fix = (
                f"no package {package!r} is known (known: {', '.join(packages.known()) or 'none'}): say where it is "
                f"with package_dirs={{{package!r}: PATH}} (--package-dir {package}=PATH) or {ROS_PACKAGE_PATH}, "
                "or fix the path"
            )
        raise URDFError(
            f"mesh file {filename!r} referenced by the URDF was not found (looked in "
            f"{', '.join(str(c) for c in candidates[:3])}{'...' if len(candidates) > 3 else ''}); {fix}"
        )
    return found


def _dtd_error(urdf_path: Path) -> URDFError:
    return URDFError(
        f"URDF file {str(urdf_path)!r} declares a DTD or XML entities, which armreach never expands "
        "(they can read local files or explode in size); remove the <!DOCTYPE>/<!ENTITY> declarations"
    )


def _undeclared_prefixes(parser: etree.XMLParser) -> list[str]:
    """The XML prefixes a file ``parser`` failed on uses undeclared, if that is all that is wrong with it."""
    errors = list(parser.error_log)  # the parser's own: an exception's log also holds the thread's earlier errors
    if not errors or any(e.type != etree.ErrorTypes.NS_ERR_UNDEFINED_NAMESPACE for e in errors):
        return []
    found = (re.match(r"Namespace prefix (\S+) ", e.message) for e in errors)
    return sorted({m.group(1) for m in found if m is not None and re.fullmatch(r"[A-Za-z_][\w.-]*", m.group(1))})


def _prefixed(key: str) -> str:
    """``{urn:armreach:undeclared:drake}acceleration`` -> ``drake:acceleration``."""
    name = etree.QName(key)
    return f"{str(name.namespace)[len(UNDECLARED_NAMESPACE) :]}:{name.localname}"


def _parse(data: bytes, urdf_path: Path) -> etree._Element:
    """``data`` parsed; elements and attributes under prefixes it never declares are dropped, with a warning."""
    parser = _safe_parser()
    try:
        return etree.fromstring(data, parser=parser)
    except etree.XMLSyntaxError as exc:
        error = URDFError(
            f"URDF file {str(urdf_path)!r} is not well-formed XML: {exc}; fix the markup at that line and column "
            "(a truncated file, a stray byte or an unclosed tag)"
        )
        prefixes = _undeclared_prefixes(parser)
        tag = _ROBOT_TAG.search(data)
        if not prefixes or tag is None:
            raise error from None
    declared = b"".join(f' xmlns:{p}="{UNDECLARED_NAMESPACE}{p}"'.encode() for p in prefixes)
    try:
        root = etree.fromstring(data[: tag.end()] + declared + data[tag.end() :], parser=_safe_parser())
    except etree.XMLSyntaxError:
        raise error from None
    dropped: Counter[str] = Counter()
    ours = "{" + UNDECLARED_NAMESPACE
    for element in list(root.iter()):
        for key in [str(k) for k in element.attrib if str(k).startswith(ours)]:
            dropped[_prefixed(key)] += 1
            del element.attrib[key]
        parent = element.getparent()
        # the outermost foreign element goes, with what it holds (already removed from the tree)
        if str(element.tag).startswith(ours) and parent is not None and not str(parent.tag).startswith(ours):
            dropped[f"<{_prefixed(str(element.tag))}>"] += 1
            parent.remove(element)
    etree.cleanup_namespaces(root)
    log.warning(
        "URDF file %r uses the XML prefix%s %s without declaring %s: another tool's extensions (%s), which no engine "
        "here reads; dropped",
        str(urdf_path),
        "es" if len(prefixes) > 1 else "",
        ", ".join(repr(p) for p in prefixes),
        "them" if len(prefixes) > 1 else "it",
        ", ".join(f"{name} x{count}" for name, count in sorted(dropped.items())),
    )
    return root


def _laid_out(root: etree._Element, urdf_path: Path) -> bytes:
    """``root`` as UTF-8 text, one element per line, every line at most :data:`MAX_LINE_BYTES`."""
    etree.indent(root, space=" ")  # only whitespace between elements changes
    text = b'<?xml version="1.0" encoding="utf-8"?>\n' + etree.tostring(root, encoding="utf-8")
    for line in text.split(b"\n"):
        if len(line) > MAX_LINE_BYTES:
            start = line.lstrip()[:60].decode("utf-8", "replace")
            raise URDFError(
                f"URDF file {str(urdf_path)!r}: an element is {len(line)} bytes long ({start!r}...), over the "
                f"{MAX_LINE_BYTES}-byte line PyBullet reads, which would cut it in the middle of a name or a number; "
                "shorten its attribute values (names, mesh paths)"
            )
    return text


def read_urdf(
    path: str | os.PathLike[str],
    *,
    allow_external_meshes: bool | None = None,
    package_dirs: Mapping[str, str] | None = None,
    xacro_args: Mapping[str, str] | None = None,
    allow_xacro_env: bool = False,
    frozen_joints: Mapping[str, float] | None = None,
) -> ParsedURDF:
    """Read and check a URDF file, or a xacro file (processed first: :mod:`armreach_core.robot.xacro_sandbox`).

    Args:
        path: the URDF or xacro file.
        allow_external_meshes: accept meshes outside the URDF's folder or package
            (default: the ``ARMREACH_ALLOW_EXTERNAL_MESHES`` environment variable, else no).
        package_dirs: where ROS packages live, name -> folder (``$(find NAME)``,
            ``package://NAME/...``; :class:`~armreach_core.robot.packages.Packages`).
        xacro_args: a xacro file's arguments (``<xacro:arg>``), name -> value.
        allow_xacro_env: let a xacro file read environment variables (``$(env ...)``, ``$(optenv ...)``).
        frozen_joints: movable joints made fixed at a value, name -> rad or m
            (:mod:`armreach_core.robot.freeze`).

    Raises:
        URDFError: the file is missing, too large, declares a DTD or entities, is not
            well-formed XML, is not a ``<robot>``, breaks a rule of
            :mod:`armreach_core.robot.checks`, or names a mesh that does not exist or lies
            outside its folder.
    """
    if allow_external_meshes is None:
        allow_external_meshes = allow_external_meshes_default()
    urdf_path = Path(path).expanduser()
    if not _is_file(urdf_path):
        raise URDFError(f"URDF file not found: {str(urdf_path)!r}; pass the path of an existing .urdf file")
    size = urdf_path.stat().st_size
    too_big = (
        f"over armreach's limit of {MAX_URDF_BYTES} bytes (MAX_URDF_BYTES); robot descriptions are far smaller: "
        "check that this is the right file, and strip padding and long comments"
    )
    if size > MAX_URDF_BYTES:
        raise URDFError(f"URDF file {str(urdf_path)!r} is {size} bytes, {too_big}")
    with open(urdf_path, "rb") as handle:  # at most the limit, even if the file grew since stat()
        data = handle.read(MAX_URDF_BYTES + 1)
    if len(data) > MAX_URDF_BYTES:
        raise URDFError(f"URDF file {str(urdf_path)!r} grew while being read, {too_big}")
    data = _lenient(data)
    if _DTD_PATTERN.search(data):
        raise _dtd_error(urdf_path)
    urdf_dir = urdf_path.resolve().parent
    packages = Packages.of(urdf_dir, package_dirs)
    if is_xacro(urdf_path, data):
        data = process_xacro(urdf_path, xacro_args or {}, packages, allow_env=allow_xacro_env)
        if _DTD_PATTERN.search(data):
            raise _dtd_error(urdf_path)
    elif xacro_args:
        raise URDFError(
            f"xacro_args were given but {str(urdf_path)!r} is not a xacro file (no xacro markup); drop the arguments"
        )
    root = _parse(data, urdf_path)
    if root.getroottree().docinfo.internalDTD is not None:  # in an encoding the byte scan does not read (UTF-16)
        raise _dtd_error(urdf_path)
    if not isinstance(root.tag, str) or etree.QName(root).localname != "robot":
        raise URDFError(
            f"URDF file {str(urdf_path)!r} has root element <{root.tag}>, expected <robot>; is it a URDF? "
            "(an SDF or MJCF file must be converted to URDF first)"
        )
    namespace = etree.QName(root).namespace
    if namespace is not None:
        raise URDFError(
            f"URDF file {str(urdf_path)!r}: the <robot> element is in the XML namespace {namespace!r}, so none of "
            "its elements is a URDF element; remove the xmlns= attribute (prefixed ones such as xmlns:xacro= "
            "are fine)"
        )
    if not root.get("name"):
        raise URDFError(
            f"URDF file {str(urdf_path)!r}: the <robot> element has no name= attribute; the URDF format requires "
            'one, such as <robot name="my_arm">'
        )
    try:
        check_tree(root)
        frozen = freeze_joints(root, frozen_joints or {})
    except URDFError as exc:
        raise URDFError(f"URDF file {str(urdf_path)!r}: {exc}") from None

    for mesh in root.iter("mesh"):
        filename = mesh.get("filename")
        if not filename:
            raise URDFError(f"URDF file {str(urdf_path)!r} has a <mesh> without a filename attribute")
        found = resolve_mesh_path(filename, urdf_dir, allow_external=allow_external_meshes, packages=packages)
        mesh.set("filename", str(found))
    for texture in root.iter("texture"):  # engines that draw textures read these files too
        filename = texture.get("filename")
        if filename:
            found, _ = _find(filename, urdf_dir, allow_external_meshes, "texture", packages)
            if found is not None:  # a missing texture only loses colour, as in every URDF viewer
                texture.set("filename", str(found))
    resolved = _laid_out(root, urdf_path)
    try:
        model = yourdfpy.URDF.load(
            io.BytesIO(resolved),
            build_scene_graph=False,
            load_meshes=False,
            mesh_dir=str(urdf_dir),
        )
    except KeyError as exc:  # an attribute the format requires, read without a check
        raise URDFError(
            f"URDF file {str(urdf_path)!r} could not be parsed: an element lacks the attribute {exc}, which the URDF "
            "format requires; add it"
        ) from None
    except Exception as exc:  # yourdfpy raises bare ValueError/TypeError/AttributeError on bad content
        raise URDFError(f"URDF file {str(urdf_path)!r} could not be parsed: {type(exc).__name__}: {exc}") from None
    return ParsedURDF(path=urdf_path.resolve(), model=model, resolved_xml=resolved, frozen=frozen)
