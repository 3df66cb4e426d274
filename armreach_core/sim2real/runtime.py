"""Running an exported policy without torch or JAX: NumPy, or onnxruntime where it is installed.

:class:`PolicyRuntime` reads a folder written by ``armreach export`` (``card.json``,
``policy.npz``, ``policy.onnx``) and maps an observation (flat, or the Dict of a
goal-conditioned env, concatenated in the card's order) to the action the trained model
chooses deterministically.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.actions import LimitRoom
from armreach_core.errors import ConfigError

#: Engines: ``numpy`` (always there) and ``onnxruntime`` (``pip install 'armreach[deploy]'``).
ENGINES = ("numpy", "onnxruntime")


def _activation(name: str, x: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    if name == "relu":
        return np.maximum(x, np.float32(0.0))
    if name == "tanh":
        return np.tanh(x)
    if name == "identity":
        return x
    raise ConfigError(f"exported policy uses activation {name!r}, which this runtime does not know")


def _room(data: Any) -> LimitRoom | None:
    """The limit guard written into ``policy.npz``, if the policy has one."""
    if "guard_slice" not in data:
        return None
    start, stop = (int(v) for v in data["guard_slice"])
    low, high = (tuple(float(v) for v in data[key]) for key in ("guard_low", "guard_high"))
    return LimitRoom.unscaled(start, stop, low, high, float(data["guard_step"]))


class PolicyRuntime:
    """An exported policy, ready to act.

    Args:
        folder: what ``armreach export`` wrote.
        engine: ``numpy`` (default) or ``onnxruntime``.
    """

    def __init__(self, folder: str | os.PathLike[str], engine: str = "numpy") -> None:
        self.folder = Path(folder)
        card_path = self.folder / "card.json"
        if not card_path.is_file():
            raise ConfigError(f"{self.folder} has no card.json; make it with `armreach export RUN --out {self.folder}`")
        #: The policy card (see :func:`armreach_core.sim2real.card.policy_card`).
        self.card: dict[str, Any] = json.loads(card_path.read_text())
        if engine not in ENGINES:
            raise ConfigError(f"engine={engine!r}; use one of {', '.join(ENGINES)}")
        self.engine = engine
        self._keys: list[str] | None = self.card["observation"].get("keys")
        self._session: Any = None
        if engine == "onnxruntime":
            try:
                import onnxruntime
            except ImportError:
                raise ConfigError("engine 'onnxruntime' needs it installed: pip install 'armreach[deploy]'") from None
            self._session = onnxruntime.InferenceSession(
                str(self.folder / "policy.onnx"), providers=["CPUExecutionProvider"]
            )
        else:
            with np.load(self.folder / "policy.npz", allow_pickle=False) as data:
                activations = [str(a) for a in data["activations"]]
                self._layers = [(data[f"W{i}"], data[f"b{i}"], act) for i, act in enumerate(activations)]
                self._bound = str(data["bound"])
                self._room = _room(data)

    def flat(self, observation: npt.ArrayLike | Mapping[str, npt.ArrayLike]) -> npt.NDArray[np.float32]:
        """The observation as the network's input, ``(batch, size)`` float32."""
        if isinstance(observation, Mapping):
            if self._keys is None:
                raise ConfigError("this policy takes a flat observation, not a dict")
            parts = [np.atleast_2d(np.asarray(observation[k], dtype=np.float32)) for k in self._keys]
            x = np.concatenate(parts, axis=-1)
        else:
            x = np.atleast_2d(np.asarray(observation, dtype=np.float32))
        size = int(self.card["observation"]["size"])
        if x.shape[-1] != size:
            raise ConfigError(f"observation has {x.shape[-1]} values, the policy takes {size}")
        return x

    def act(self, observation: npt.ArrayLike | Mapping[str, npt.ArrayLike]) -> npt.NDArray[np.float32]:
        """The action (``(actions,)`` for one observation, ``(batch, actions)`` for a batch), in [-1, 1]."""
        single = not isinstance(observation, Mapping) and np.ndim(observation) == 1
        single = single or (isinstance(observation, Mapping) and np.ndim(next(iter(observation.values()))) == 1)
        x = self.flat(observation)
        if self._session is not None:
            y = np.asarray(self._session.run(["action"], {"observation": x})[0], dtype=np.float32)
        else:
            y = x
            for weight, bias, activation in self._layers:
                y = _activation(activation, y @ weight.T + bias)
            if self._bound == "clip":
                y = np.clip(y, -1.0, 1.0)
            if self._room is not None:
                y = self._room.clip(x, y)
        return y[0] if single else y


__all__ = ["ENGINES", "PolicyRuntime"]
