"""Builds envs from URDF files on request, in a process of its own (see tests/test_fuzz_urdf.py).

Reads one JSON request per line on stdin, ``{"path": ..., "backends": [...], "steps": N}``,
and answers one JSON line per request on the stdout it was started with:
``{"outcome": "ok" | "urdf_error" | "error", "detail": ...}``. ``ok`` means that every
backend built the env and that reset and ``steps`` random-action steps gave finite
observations and rewards. Warnings are errors, as under pytest. A segmentation fault or
a hang ends or stalls this process, which the test sees from outside.
"""

from __future__ import annotations

import json
import os
import sys
import traceback
import warnings


def _hide_modules() -> None:
    for name in os.environ.get("ARMREACH_TEST_HIDE", "").split(","):
        if name.strip():
            sys.modules[name.strip()] = None  # type: ignore[assignment]


def _build(path: str, backends: list[str], steps: int) -> dict[str, str]:
    import numpy as np

    from armreach_core import ArmReach6DOFEnv, URDFError
    from armreach_core.robot.model import RobotModel

    try:
        RobotModel(path)
    except URDFError as exc:
        return {"outcome": "urdf_error", "detail": f"model: {exc}"}
    built = []
    for backend in backends:
        try:
            env = ArmReach6DOFEnv(backend=backend, urdf=path)
        except URDFError as exc:
            return {"outcome": "urdf_error", "detail": f"{backend}: {exc}"}
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


def main() -> None:
    _hide_modules()
    warnings.simplefilter("error")
    warnings.filterwarnings("ignore", category=DeprecationWarning, module="pybullet_utils.*")
    warnings.filterwarnings("ignore", message=".*pkg_resources.*", category=DeprecationWarning)
    protocol = os.fdopen(os.dup(1), "w", encoding="utf-8")
    os.dup2(2, 1)  # whatever the engines print goes to stderr, not into the answers
    import armreach_core  # noqa: F401 - load the plugins once, before the first request

    protocol.write(json.dumps({"outcome": "ready"}) + "\n")
    protocol.flush()
    for line in sys.stdin:
        request = json.loads(line)
        try:
            answer = _build(request["path"], request["backends"], int(request["steps"]))
        except Exception:
            answer = {"outcome": "error", "detail": traceback.format_exc(limit=6)}
        protocol.write(json.dumps(answer) + "\n")
        protocol.flush()


if __name__ == "__main__":
    main()
