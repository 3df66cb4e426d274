"""An engine's own exception, during a build or a step, as an :class:`ArmReachError` a user can act on.

Engines fail with their own types (``pybullet.error``, a ``SystemError`` from a C extension,
MuJoCo's ``ValueError``...), whose text names neither the robot description nor what to do.
:func:`engine_failure` wraps such an exception into one that names the arm, its file, the link
the engine named (or, when it named none, the heaviest link, the usual culprit of numerical
trouble), and the fix.
"""

from __future__ import annotations

import re

from armreach_core.errors import ArmReachError
from armreach_core.robot.kinematics import ArmKinematics


def suspect_link(robot: ArmKinematics, message: str) -> str:
    """The link an engine's ``message`` names, else the heaviest link, as words for a message."""
    names = [str(link.name) for link in robot.parsed.model.robot.links]
    named = [name for name in names if re.search(rf"(?<![\w]){re.escape(name)}(?![\w])", message)]
    if named:
        return f"link {max(named, key=len)!r}, which the engine names"

    def mass(name: str) -> float:
        inertial = robot.parsed.model.link_map[name].inertial
        return 0.0 if inertial is None or inertial.mass is None else float(inertial.mass)

    heaviest = max(names, key=mass)
    return f"link {heaviest!r} ({mass(heaviest):g} kg, the heaviest: the engine named none)"


def engine_failure(robot: ArmKinematics, backend: str, stage: str, exc: BaseException) -> ArmReachError:
    """The error to raise, ``from None``, for ``exc`` raised by ``backend``'s engine while ``stage``
    (``"building"``, ``"resetting"``, ``"stepping"``) the arm ``robot``."""
    detail = " ".join(str(exc).split()) or "no message"
    return ArmReachError(
        f"the {backend} engine failed while {stage} the arm {robot.name!r} ({robot.urdf_path}): "
        f"{type(exc).__name__}: {detail}; look first at {suspect_link(robot, detail)}: check its <inertial> "
        "(mass in kg, inertia in kg·m² about its centre of mass, positive and plausible for its size) and its "
        "meshes, or try the other backend"
    )
