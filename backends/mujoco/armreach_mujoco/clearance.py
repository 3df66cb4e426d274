"""Signed distances from the robot's links to added bodies, on a scratch ``MjData``.

The arm is posed in a second ``MjData`` of the same model (forward kinematics only), so a
query at another configuration leaves the env's own state untouched. Distances come from
``mj_geomDistance`` between each collision geom of a link and the body's geom: the same
shapes the contacts use (meshes as their convex hulls, as PyBullet does).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ArmReachError
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_mujoco.compiled import CompiledModel
from armreach_mujoco.engine import mujoco
from armreach_mujoco.world import ARM_CONTYPE, BODY_PREFIX


class Clearance:
    """Link-to-body distances of one model (built lazily by the backend, once per model)."""

    def __init__(self, robot: RobotModel, compiled: CompiledModel, model: Any) -> None:
        self.robot, self.compiled, self.model = robot, compiled, model
        self.scratch = mujoco.MjData(model)
        self.links: dict[str, list[int]] = {}
        for link in robot.link_names:
            body = compiled.bodies.get(link)
            if link in robot.fixed_links or body is None:
                continue
            start, count = int(model.body_geomadr[body]), int(model.body_geomnum[body])
            self.links[link] = [g for g in range(start, start + count) if int(model.geom_contype[g]) & ARM_CONTYPE]

    def _geom(self, name: str) -> int:
        try:
            return int(self.model.geom(BODY_PREFIX + name).id)
        except KeyError:
            raise ArmReachError(f"no body called {name!r}; add it with add_shape or add_box first") from None

    def distances(
        self, data: Any, bodies: Sequence[str], q: npt.ArrayLike | None, max_distance: float
    ) -> dict[str, FloatArray]:
        model, scratch = self.model, self.scratch
        geoms = [self._geom(name) for name in bodies]
        scratch.qpos[:] = data.qpos
        scratch.mocap_pos[:] = data.mocap_pos
        scratch.mocap_quat[:] = data.mocap_quat
        if q is not None:
            scratch.qpos[self.compiled.qpos] = np.asarray(q, dtype=np.float64)
        mujoco.mj_kinematics(model, scratch)
        out: dict[str, FloatArray] = {}
        limit = float(max_distance)
        for link, own in self.links.items():
            values = np.full(len(geoms), limit)
            for k, other in enumerate(geoms):
                for geom in own:
                    values[k] = min(values[k], float(mujoco.mj_geomDistance(model, scratch, geom, other, limit, None)))
            out[link] = values
        return out
