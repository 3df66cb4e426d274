"""The driver seam: what ``armreach deploy`` needs from an arm, and how drivers are found.

A driver reads the arm's joint state, sends joint targets and reports the time of each
reading. Drivers are plugins in their own entry-point group, ``armreach.drivers``, each
entry a ``module:Class`` string resolved only when that driver is asked for (as backends'
classes are), so a broken driver never stops the others::

    [project.entry-points."armreach.drivers"]
    myarm = "armreach_myarm.driver:MyArmDriver"

The class is built as ``Class(robot, control_dt, **options)``. ``drivers/template`` is a
driver distribution to start from, with the contract tests every driver must pass.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError
from armreach_core.robot.model import RobotModel

#: The entry-point group drivers register in.
DRIVER_GROUP = "armreach.drivers"


@dataclass(frozen=True)
class Reading:
    """One joint state: ``stamp`` (s, the driver's clock) and positions, with velocities and efforts where known."""

    stamp: float
    position: npt.NDArray[np.float64]
    velocity: npt.NDArray[np.float64] | None = None
    effort: npt.NDArray[np.float64] | None = None


class Driver(ABC):
    """One arm. Joint vectors are in ``robot.joint_names`` order, in the URDF's signs and zeros.

    Args:
        robot: the arm's model (from the policy card's arm).
        control_dt: the control period (s) the caller runs at.
    """

    def __init__(self, robot: RobotModel, control_dt: float) -> None:
        self.robot = robot
        self.control_dt = float(control_dt)

    @abstractmethod
    def read(self) -> Reading:
        """The latest joint state (returns at once; a state that did not change keeps its stamp)."""

    @abstractmethod
    def send(self, targets: npt.NDArray[np.float64]) -> None:
        """Send joint position targets (rad or m), one per joint."""

    @abstractmethod
    def close(self) -> None:
        """Leave the arm holding its last target, and release it. Safe to call twice."""

    def __enter__(self) -> Driver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def available_drivers() -> list[str]:
    """Names of the installed drivers."""
    return sorted({ep.name for ep in entry_points(group=DRIVER_GROUP)})


def load_driver_class(name: str) -> type[Driver]:
    """The driver class registered as ``name``; ConfigError naming the installed ones or the import failure."""
    found = [ep for ep in entry_points(group=DRIVER_GROUP) if ep.name == name]
    if not found:
        names = ", ".join(available_drivers()) or "none"
        raise ConfigError(f"no driver {name!r} is installed (installed: {names}); install its distribution")
    if len(found) > 1:
        raise ConfigError(f"driver {name!r} is registered by {len(found)} distributions; uninstall one")
    try:
        cls: Any = found[0].load()
    except Exception as exc:  # a third party's import error, reported by name
        raise ConfigError(f"driver {name!r} ({found[0].value}) failed to import: {exc}") from None
    if not (isinstance(cls, type) and issubclass(cls, Driver)):
        raise ConfigError(f"driver {name!r} ({found[0].value}) is not a Driver subclass")
    return cls


__all__ = ["DRIVER_GROUP", "Driver", "Reading", "available_drivers", "load_driver_class"]
