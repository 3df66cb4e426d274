"""Builds envs from URDF files on request, in a process of its own (see tests/test_fuzz_urdf.py).

Reads one JSON request per line on stdin,
``{"path": ..., "backends": [...], "steps": N, "allow_external_meshes": bool}``, and answers
one JSON line per request on the stdout it was started with:

* ``{"outcome": "ok", "detail": "mujoco,pybullet"}``: the robot model built, and every
  backend built the env, whose reset and ``steps`` random-action steps gave finite
  observations and rewards;
* ``{"outcome": "refused", "error": "URDFError", "stage": "model" | backend, "detail": message}``:
  armreach refused the file on purpose (a ``URDFError`` or a ``ConfigError``);
* ``{"outcome": "error", "detail": ...}``: anything else (another exception, with its
  traceback, or a non-finite value).

Warnings are errors, as under pytest. A segmentation fault or a hang ends or stalls this
process, which the test sees from outside. The reach task's reachability map is drawn from
:data:`MAP_SAMPLES` poses instead of its 120 000: the map's precision is not under test here,
and it is most of the time an env takes to build. An arm refused because that coarse map
holds no interior voxel is built again with the full map before the answer.
"""

from __future__ import annotations

import json
import os
import sys
import traceback
import warnings
from typing import Any

from tests.hidden_modules import hide

#: Poses the reachability map of each robot is drawn from: one batch (the map draws 20 000 at a time).
MAP_SAMPLES = 20_000


def _refused(stage: str, exc: Exception) -> dict[str, str]:
    return {"outcome": "refused", "error": type(exc).__name__, "stage": stage, "detail": str(exc)}


def _build(request: dict[str, Any]) -> dict[str, str]:
    import numpy as np

    from armreach_core import ArmReach6DOFEnv, ConfigError, URDFError
    from armreach_core.robot.model import RobotModel

    path, steps = request["path"], int(request["steps"])
    allow = bool(request.get("allow_external_meshes", False))
    try:
        RobotModel(path, allow_external_meshes=allow)
    except (URDFError, ConfigError) as exc:
        return _refused("model", exc)
    built = []
    for backend in request["backends"]:
        try:
            env = ArmReach6DOFEnv(backend=backend, urdf=path, allow_external_meshes=allow)
        except (URDFError, ConfigError) as exc:
            return _refused(backend, exc)
        try:
            rng = np.random.default_rng(0)
            obs, _ = env.reset(seed=0)
            values = [obs]
            for _ in range(steps):
                obs, reward, terminated, truncated, _ = env.step(rng.uniform(-1.0, 1.0, env.action_space.shape))
                values += [obs, np.float64(reward)]
                if terminated or truncated:
                    obs, _ = env.reset()
                    values.append(obs)
            if not all(np.all(np.isfinite(v)) for v in values):
                return {"outcome": "error", "detail": f"{backend}: non-finite observation or reward"}
        finally:
            env.close()
        built.append(backend)
    return {"outcome": "ok", "detail": ",".join(built)}


#: The refusal of an arm whose map holds no interior voxel, which the coarse map may give alone.
NO_TARGETS = "so it has no targets to reach"


def _with_full_map(request: dict[str, Any], samples: int) -> dict[str, str]:
    """``request`` built again with the map's own ``samples``: the coarse map's precision is not
    under test, and an arm that barely reaches above the ground may leave it empty."""
    from armreach_core.robot import workspace

    def forget() -> None:
        workspace.reachability_map.cache_clear()
        workspace._clear_voxels.cache_clear()

    workspace.SAMPLES = samples
    forget()
    try:
        return _build(request)
    finally:
        workspace.SAMPLES = MAP_SAMPLES
        forget()


def main() -> None:
    hide()
    warnings.simplefilter("error")
    warnings.filterwarnings("ignore", category=DeprecationWarning, module="pybullet_utils.*")
    warnings.filterwarnings("ignore", message=".*pkg_resources.*", category=DeprecationWarning)
    protocol = os.fdopen(os.dup(1), "w", encoding="utf-8")
    os.dup2(2, 1)  # whatever the engines print goes to stderr, not into the answers
    import armreach_core  # noqa: F401 - load the plugins once, before the first request
    from armreach_core.robot import workspace

    full = workspace.SAMPLES
    workspace.SAMPLES = MAP_SAMPLES  # the maps' cache key says so too: they never pass for full ones

    protocol.write(json.dumps({"outcome": "ready"}) + "\n")
    protocol.flush()
    for line in sys.stdin:
        request = json.loads(line)
        try:
            answer = _build(request)
            if answer["outcome"] == "refused" and NO_TARGETS in answer.get("detail", ""):
                answer = _with_full_map(request, full)
        except Exception:
            answer = {"outcome": "error", "detail": traceback.format_exc(limit=6)}
        protocol.write(json.dumps(answer) + "\n")
        protocol.flush()


if __name__ == "__main__":
    main()
