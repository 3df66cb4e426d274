"""The corpus: public arm descriptions nobody here wrote, that every arm-level promise is tested on.

One list, one line per arm. The descriptions come from package registries, with their
meshes: ``example-robot-data`` (PyPI; installed by ``make install``) and ``pybullet_data``
(installed with PyBullet). Nothing here is tuned to an arm: each line says only where the
URDF is. An arm whose package is not installed is reported as missing, never downloaded.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import TypeVar

T = TypeVar("T")

#: Where each source keeps its files, and how to install it.
SOURCES = {
    "example-robot-data": ("cmeel.prefix/share/example-robot-data/robots", "pip install example-robot-data"),
    "pybullet_data": ("", "pip install pybullet"),
}


@dataclass(frozen=True)
class CorpusArm:
    """One arm: a name, the package it comes from, and the URDF's path inside that package."""

    name: str
    source: str
    relative: str

    @property
    def path(self) -> Path | None:
        """The URDF on this machine, or ``None`` when its package is not installed."""
        root = _source_root(self.source)
        if root is None:
            return None
        path = root / self.relative
        return path if path.is_file() else None

    @property
    def install(self) -> str:
        return SOURCES[self.source][1]


CORPUS: tuple[CorpusArm, ...] = (
    CorpusArm("ur3", "example-robot-data", "ur_description/urdf/ur3_robot.urdf"),
    CorpusArm("ur5", "example-robot-data", "ur_description/urdf/ur5_robot.urdf"),
    CorpusArm("ur5-gripper", "example-robot-data", "ur_description/urdf/ur5_gripper.urdf"),
    CorpusArm("ur10", "example-robot-data", "ur_description/urdf/ur10_robot.urdf"),
    CorpusArm("kinova-jaco", "example-robot-data", "kinova_description/robots/kinova.urdf"),
    CorpusArm("z1", "example-robot-data", "z1_description/urdf/z1.urdf"),
    CorpusArm("so100", "example-robot-data", "so_arm_description/urdf/so100.urdf"),
    CorpusArm("so101", "example-robot-data", "so_arm_description/urdf/so101.urdf"),
    CorpusArm("xarm7", "example-robot-data", "xarm_description/urdf/xarm7.urdf"),
    CorpusArm("panda", "example-robot-data", "panda_description/urdf/panda.urdf"),
    CorpusArm("talos-left-arm", "example-robot-data", "talos_data/robots/talos_left_arm.urdf"),
    CorpusArm("kuka-iiwa", "pybullet_data", "kuka_iiwa/model.urdf"),
    CorpusArm("franka-panda", "pybullet_data", "franka_panda/panda.urdf"),
    CorpusArm("xarm6", "pybullet_data", "xarm/xarm6_robot.urdf"),
)


def _source_root(source: str) -> Path | None:
    if source == "pybullet_data":
        try:
            import pybullet_data
        except ImportError:
            return None
        return Path(pybullet_data.getDataPath())
    try:
        folder = metadata.distribution(source).locate_file(SOURCES[source][0])
    except metadata.PackageNotFoundError:
        return None
    path = Path(str(folder))
    return path if path.is_dir() else None


def corpus_arm(name: str) -> CorpusArm:
    """The corpus arm called ``name`` (a :class:`~armreach_core.errors.ConfigError` names the others)."""
    from armreach_core.errors import ConfigError

    for arm in CORPUS:
        if arm.name == name:
            return arm
    raise ConfigError(f"no corpus arm {name!r}; the corpus has {', '.join(a.name for a in CORPUS)}")


def for_each_corpus_arm(
    run: Callable[[CorpusArm, Path], T],
    *,
    log: Callable[[str], None] = print,
    arms: Sequence[str] | None = None,
) -> dict[str, T]:
    """``run(arm, urdf)`` on every installed corpus arm (or on those named in ``arms``, in that
    order): the results by arm name.

    An arm whose package is not installed is skipped, with a line to ``log`` that says how
    to install it.

    Raises:
        ConfigError: a name in ``arms`` that is not a corpus arm.
    """
    results: dict[str, T] = {}
    for arm in CORPUS if arms is None else [corpus_arm(name) for name in arms]:
        path = arm.path
        if path is None:
            log(f"{arm.name}: not installed ({arm.install})")
            continue
        results[arm.name] = run(arm, path)
    return results
