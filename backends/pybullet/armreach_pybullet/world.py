"""What a task adds around the arm, by name: boxes, shapes, markers; contacts, clearances and friction by name."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from armreach_core.backend import BodyState
from armreach_core.errors import ArmReachError
from armreach_core.robot.model import FloatArray, RobotModel
from armreach_pybullet.engine import pb

#: Where a body waits while its contact points are dropped (m), far from everything.
PARKING = (0.0, 0.0, 1.0e4)


class World:
    """The boxes and markers of one client, and the contacts of its robot body, all by name.

    ``link_index`` gives each link's PyBullet index (that of the body it was merged into,
    :mod:`armreach_pybullet.merge`); contacts and clearances are those of the links in
    ``colliding``, the links with collision geometry.
    """

    def __init__(
        self, cid: int, robot: RobotModel, body: int, link_index: dict[str, int], colliding: frozenset[str]
    ) -> None:
        self._client, self._robot, self._body, self._link_index = cid, robot, body, link_index
        self._colliding = colliding
        self._markers: dict[str, int] = {}
        self._bodies: dict[str, int] = {}
        #: The bodies with mass, in the order they were added.
        self.free: list[str] = []
        #: The fixed shapes that set_body_pose moves (obstacles).
        self.movable: set[str] = set()

    def add_box(
        self,
        name: str,
        half_extents: tuple[float, float, float],
        mass: float,
        friction: float,
        rgba: tuple[float, float, float, float],
        position: tuple[float, float, float],
    ) -> None:
        cid = self._client
        if name in self._bodies or name in self._link_index:
            raise ArmReachError(f"a body or link called {name!r} already exists")

        extents = [float(h) for h in half_extents]
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=extents, physicsClientId=cid)
        visual = pb.createVisualShape(pb.GEOM_BOX, halfExtents=extents, rgbaColor=list(rgba), physicsClientId=cid)
        body = pb.createMultiBody(
            baseMass=float(mass),
            baseCollisionShapeIndex=shape,
            baseVisualShapeIndex=visual,
            basePosition=[float(p) for p in position],
            physicsClientId=cid,
        )
        self._bodies[name] = body
        if mass > 0:
            self.free.append(name)
        self.set_friction(name, friction)

    def add_shape(
        self,
        name: str,
        shape: str,
        size: tuple[float, ...],
        rgba: tuple[float, float, float, float],
        position: tuple[float, float, float],
    ) -> None:
        cid = self._client
        if name in self._bodies or name in self._link_index:
            raise ArmReachError(f"a body or link called {name!r} already exists")
        collision: dict[str, float | list[float]]
        visual: dict[str, float | list[float]]
        if shape == "box":
            collision, visual = {"halfExtents": list(size)}, {"halfExtents": list(size)}
        elif shape == "sphere":
            collision, visual = {"radius": size[0]}, {"radius": size[0]}
        else:  # a cylinder along z; PyBullet names its length differently for the two shapes
            collision, visual = {"radius": size[0], "height": 2 * size[1]}, {"radius": size[0], "length": 2 * size[1]}
        kind = {"box": pb.GEOM_BOX, "sphere": pb.GEOM_SPHERE, "cylinder": pb.GEOM_CYLINDER}[shape]
        shape_id = pb.createCollisionShape(kind, physicsClientId=cid, **collision)
        visual_id = pb.createVisualShape(kind, rgbaColor=list(rgba), physicsClientId=cid, **visual)
        self._bodies[name] = pb.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=shape_id,
            baseVisualShapeIndex=visual_id,
            basePosition=[float(p) for p in position],
            physicsClientId=cid,
        )
        self.movable.add(name)

    def clearances(self, bodies: list[str], max_distance: float) -> dict[str, FloatArray]:
        """Signed distance from each moving link to each body (``max_distance`` when farther)."""
        cid, robot, own = self._client, self._robot, self._body
        ids = [self._body_id(name) for name in bodies]
        out: dict[str, FloatArray] = {}
        found: dict[int, FloatArray] = {}  # by PyBullet link: the parts of a merged body share it
        for link in robot.link_names:
            index = self._link_index.get(link)
            if link in robot.fixed_links or index is None:
                continue
            if link not in self._colliding:
                out[link] = np.full(len(ids), float(max_distance))
                continue
            if index not in found:
                values = np.full(len(ids), float(max_distance))
                for k, body in enumerate(ids):
                    points = pb.getClosestPoints(
                        own, body, float(max_distance), linkIndexA=index, linkIndexB=-1, physicsClientId=cid
                    )
                    if points:
                        values[k] = min(values[k], min(float(point[8]) for point in points))
                found[index] = values
            out[link] = found[index].copy()
        return out

    def _body_id(self, name: str) -> int:
        try:
            return self._bodies[name]
        except KeyError:
            raise ArmReachError(f"no body called {name!r}; add it with add_box first") from None

    def _shape(self, name: str) -> tuple[int, int]:
        """(PyBullet body, link index) of a robot link or a body."""
        if name in self._bodies:
            return self._bodies[name], -1
        if name in self._link_index:
            return self._body, self._link_index[name]
        raise ArmReachError(f"{name!r} is neither a link of {self._robot.name!r} nor a body")

    def set_body_pose(self, name: str, position: npt.ArrayLike, orientation: npt.ArrayLike) -> None:
        body, cid = self._body_id(name), self._client
        if name not in self.free and name not in self.movable:
            raise ArmReachError(f"body {name!r} is fixed (mass 0); only free bodies can be moved")
        w, x, y, z = (float(v) for v in np.asarray(orientation, dtype=np.float64))
        pos = [float(v) for v in np.asarray(position, dtype=np.float64)]
        # Bullet keeps a body's contact points, and their impulses that warm-start the solver,
        # across a teleport, so the next step would depend on the past: park the body far from
        # everything and run collision detection, which drops them, then place it.
        pb.resetBasePositionAndOrientation(body, PARKING, [0.0, 0.0, 0.0, 1.0], physicsClientId=cid)
        pb.performCollisionDetection(physicsClientId=cid)
        pb.resetBasePositionAndOrientation(body, pos, [x, y, z, w], physicsClientId=cid)
        pb.resetBaseVelocity(body, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], physicsClientId=cid)

    def body_state(self, name: str) -> BodyState:
        body, cid = self._body_id(name), self._client
        pos, (x, y, z, w) = pb.getBasePositionAndOrientation(body, physicsClientId=cid)
        lin, ang = pb.getBaseVelocity(body, physicsClientId=cid)
        return BodyState(np.array(pos), np.array([w, x, y, z]), np.array(lin), np.array(ang))

    def contact_force(self, a: str, b: str) -> float:
        (body_a, link_a), (body_b, link_b) = self._shape(a), self._shape(b)
        points = pb.getContactPoints(
            bodyA=body_a, bodyB=body_b, linkIndexA=link_a, linkIndexB=link_b, physicsClientId=self._client
        )
        return float(sum(point[9] for point in points))

    def links_in_contact(self) -> tuple[str, ...]:
        body, touching = self._body, set()
        for point in pb.getContactPoints(bodyA=body, physicsClientId=self._client):
            if point[8] <= 0.0 or point[9] > 0.0:  # penetrating, or pushing: not a speculative point
                if point[1] == body:
                    touching.add(point[3])
                if point[2] == body:
                    touching.add(point[4])
        index, robot, colliding = self._link_index, self._robot, self._colliding
        return tuple(
            link
            for link in robot.link_names
            if link in colliding and link not in robot.fixed_links and index.get(link, -2) in touching
        )

    def set_friction(self, name: str, friction: float) -> None:
        body, link = self._shape(name)
        pb.changeDynamics(body, link, lateralFriction=float(friction), physicsClientId=self._client)

    def add_marker(self, name: str, radius: float, rgba: tuple[float, float, float, float]) -> None:
        if name in self._markers:
            raise ArmReachError(f"marker {name!r} already exists")

        visual = pb.createVisualShape(pb.GEOM_SPHERE, radius=radius, rgbaColor=rgba, physicsClientId=self._client)
        self._markers[name] = pb.createMultiBody(
            baseMass=0.0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=visual, physicsClientId=self._client
        )

    def set_marker(self, name: str, position: FloatArray) -> None:
        pb.resetBasePositionAndOrientation(
            self._markers[name], position.tolist(), [0.0, 0.0, 0.0, 1.0], physicsClientId=self._client
        )


__all__ = ["PARKING", "World"]
