"""Where a robot description's ROS packages live, and which folders it may read.

A description names files through ROS packages: ``package://NAME/meshes/...`` in a URDF,
``$(find NAME)`` in a xacro. :class:`Packages` answers where ``NAME`` is, in this order:

1. a folder the user named (``package_dirs={NAME: PATH}``, ``--package-dir NAME=PATH``);
2. the description's own package: the nearest folder at or above it holding a
   ``package.xml`` whose ``<name>`` is ``NAME`` (or, with no ``package.xml``, a ``urdf/`` or
   ``robots/`` folder's parent, or a folder called ``NAME`` at or above the description);
3. a package on ``ROS_PACKAGE_PATH``: the folders it lists are searched for ``package.xml``
   files, and a package is known by the ``<name>`` its ``package.xml`` declares, whatever
   its folder is called (a ``kuka_kr210`` folder holding ``kuka_kr210_support``).

Reading is confined (:meth:`Packages.roots`): the description's folder, its own package,
and the packages the user named or put on ``ROS_PACKAGE_PATH``. Nothing else is read
unless the user opts in (``allow_external_meshes``).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from lxml import etree

#: The environment variable listing folders that hold ROS packages (``os.pathsep``-separated).
ROS_PACKAGE_PATH = "ROS_PACKAGE_PATH"
#: Folders whose parent is taken as the package root of a description inside them (ROS layout).
PACKAGE_SUBFOLDERS = ("urdf", "robots")
#: How deep below a ``ROS_PACKAGE_PATH`` folder ``package.xml`` files are looked for.
SEARCH_DEPTH = 5
#: Largest ``package.xml`` read, in bytes.
MAX_MANIFEST_BYTES = 1024 * 1024


def package_name(folder: Path) -> str | None:
    """The ``<name>`` that ``folder/package.xml`` declares (``None``: no readable manifest)."""
    manifest = folder / "package.xml"
    try:
        if not manifest.is_file() or manifest.stat().st_size > MAX_MANIFEST_BYTES:
            return None
        parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
        root = etree.fromstring(manifest.read_bytes(), parser=parser)
    except (OSError, ValueError, etree.XMLSyntaxError):
        return None
    name = root.findtext("name")
    return name.strip() if name and name.strip() else None


def own_package(folder: Path) -> Path | None:
    """The package a description in ``folder`` belongs to: the nearest folder at or above it
    with a ``package.xml``, else ``folder``'s parent when ``folder`` is a ``urdf/`` or ``robots/`` folder."""
    for candidate in (folder, *folder.parents):
        if (candidate / "package.xml").is_file():
            return candidate
    return folder.parent if folder.name in PACKAGE_SUBFOLDERS else None


def _manifests(top: Path, depth: int) -> Iterator[Path]:
    """Folders holding a ``package.xml`` at or below ``top`` (not below a package: ROS's rule)."""
    if (top / "package.xml").is_file():
        yield top
        return
    if depth <= 0:
        return
    try:
        children = sorted(entry for entry in top.iterdir() if entry.is_dir() and not entry.name.startswith("."))
    except OSError:
        return
    for child in children:
        yield from _manifests(child, depth - 1)


def ros_package_path(value: str | None = None) -> dict[str, Path]:
    """The packages on ``ROS_PACKAGE_PATH`` (or ``value``), by the name their ``package.xml`` declares.

    The first folder that declares a name wins, as in ROS.
    """
    text = os.environ.get(ROS_PACKAGE_PATH, "") if value is None else value
    found: dict[str, Path] = {}
    for entry in text.split(os.pathsep):
        if not entry.strip():
            continue
        top = Path(entry).expanduser()
        if not top.is_dir():
            continue
        for folder in _manifests(top.resolve(), SEARCH_DEPTH):
            name = package_name(folder)
            if name is not None:
                found.setdefault(name, folder)
    return found


@dataclass(frozen=True)
class Packages:
    """The packages a description in ``folder`` may use (see the module docstring for the order).

    Attributes:
        folder: the description's folder.
        named: packages the user named, name -> folder.
        on_path: packages on ``ROS_PACKAGE_PATH``, name -> folder.
    """

    folder: Path
    named: Mapping[str, Path] = field(default_factory=dict)
    on_path: Mapping[str, Path] = field(default_factory=dict)

    @classmethod
    def of(cls, folder: Path, package_dirs: Mapping[str, str] | None = None) -> Packages:
        """The packages of a description in ``folder``, the user's ``package_dirs`` and ``ROS_PACKAGE_PATH``."""
        named = {name: Path(path).expanduser().resolve() for name, path in (package_dirs or {}).items()}
        return cls(folder.resolve(), named, ros_package_path())

    @property
    def own(self) -> Path | None:
        """The description's own package folder."""
        return own_package(self.folder)

    def find(self, name: str) -> Path | None:
        """The folder of package ``name`` (``None``: nowhere the rules look)."""
        if name in self.named:
            return self.named[name]
        own = self.own
        if own is not None and (package_name(own) == name or own.name == name):
            return own
        if name in self.on_path:
            return self.on_path[name]
        for candidate in (self.folder, *self.folder.parents):
            if candidate.name == name:
                return candidate
        return None

    def roots(self, *also: str) -> list[Path]:
        """The folders files may be read from: the description's folder, its own package, the
        packages the user named or put on ``ROS_PACKAGE_PATH``, and the packages ``also`` names."""
        roots = [self.folder]
        if self.own is not None:
            roots.append(self.own)
        roots += list(self.named.values()) + list(self.on_path.values())
        roots += [found for found in (self.find(name) for name in also) if found is not None]
        return list(dict.fromkeys(roots))

    def known(self) -> list[str]:
        """The package names this description can use, for messages."""
        own = self.own
        names = [*self.named, *self.on_path]
        if own is not None:
            names.append(package_name(own) or own.name)
        return sorted(set(names))
