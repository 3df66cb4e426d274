"""Acting while the learner updates: SBX's off-policy agents on both cores (``overlap: true``).

XLA runs a compiled call after the Python that dispatched it has returned, on a thread of its
own, so an SBX learner's updates can run on one core while the env steps on the other. Two
things stood in the way. SBX reads the losses back (``.item()``) right after dispatching the
updates, which waits for them; and XLA runs calls one after another, so the next action's
forward pass waited for the updates too.

With :meth:`Overlap.use_overlap`, the losses logged are those of the previous training call
(computed by then), and the exploring actions come from a :class:`NumpyActor`: the actor's
network evaluated with numpy on the parameters as they were before the updates in flight.
The policy that acts is one training call (``gradient_steps`` updates) behind the one being
trained, as in actor-learner designs; the number and order of updates is unchanged. A run
is the same every time it is made, but it is not SBX's own run to the bit. Deterministic
actions (evaluation), gSDE and dict observations act on the latest parameters, SBX's way.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
from sbx import DDPG, TD3

from armreach_core.errors import ConfigError

Array = npt.NDArray[np.float32]


def _relu(x: Array) -> Array:
    return np.maximum(x, np.float32(0.0))


#: numpy versions of the activations a preset can name (``policy.activation``).
ACTIVATIONS: dict[str, Callable[[Array], Array]] = {"relu": _relu, "tanh": np.tanh}


class NumpyActor:
    """SBX's actor network in numpy: dense layers, then SAC's mean and log-std heads
    (``gaussian``) or TD3's single head through ``tanh``.

    Built from the actor's parameters (``actor_state.params``), which it copies; acting then
    needs no XLA call, so it does not wait for the learner's.
    """

    def __init__(self, params: Any, activation: str, gaussian: bool, rng: np.random.Generator) -> None:
        layers = params["params"]
        dense = [
            (np.array(d["kernel"]), np.array(d["bias"])) for d in (layers[f"Dense_{i}"] for i in range(len(layers)))
        ]
        heads = 2 if gaussian else 1
        self.hidden, self.heads = dense[:-heads], dense[-heads:]
        self.activation = ACTIVATIONS[activation]
        self.rng = rng

    def features(self, observations: npt.NDArray[Any]) -> Array:
        x = np.asarray(observations, dtype=np.float32).reshape(len(observations), -1)
        for kernel, bias in self.hidden:
            x = self.activation(x @ kernel + bias)
        return x

    def gaussian(self, observations: npt.NDArray[Any]) -> tuple[Array, Array]:
        """SAC's mean and standard deviation before ``tanh``, the log std clipped as SBX's."""
        x = self.features(observations)
        (mean_w, mean_b), (std_w, std_b) = self.heads
        return x @ mean_w + mean_b, np.exp(np.clip(x @ std_w + std_b, -20.0, 2.0))

    def act(self, observations: npt.NDArray[Any]) -> Array:
        """An action in [-1, 1]: SAC's exploring sample ``tanh(mean + std * noise)``, or TD3's
        deterministic ``tanh`` output (its exploration noise is added by SB3 after)."""
        if len(self.heads) == 1:
            kernel, bias = self.heads[0]
            out: Array = np.tanh(self.features(observations) @ kernel + bias)
            return out
        mean, std = self.gaussian(observations)
        return np.tanh(mean + std * self.rng.standard_normal(mean.shape, dtype=np.float32))


class Overlap:
    """Mixin for an SBX off-policy algorithm: with :meth:`use_overlap`, act while learning."""

    #: Act while the learner updates (module docstring).
    overlap: bool = False
    #: The hidden layers' activation, by a preset's name, for :class:`NumpyActor`.
    overlap_activation: str = "relu"
    #: SAC's two heads (True) or TD3's one.
    gaussian_actor: bool = False
    _acting: NumpyActor | None = None
    _losses: Any = None
    _overlap_rng: np.random.Generator | None = None
    # the algorithm's own, for mypy
    policy: Any
    seed: int | None
    use_sde: bool
    action_space: Any

    def use_overlap(self, activation: str) -> None:
        """Act while learning, the network's hidden layers using ``activation`` (a preset's name)."""
        if activation not in ACTIVATIONS:
            known = ", ".join(sorted(ACTIVATIONS))
            raise ConfigError(f"overlap: activation {activation!r} has no numpy actor; use one of {known}")
        if self.use_sde:
            raise ConfigError("overlap: gSDE's exploration needs SBX's own sampler; remove overlap or use_sde")
        self.overlap, self.overlap_activation = True, activation

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_acting", "_losses", "_overlap_rng"]  # type: ignore[misc]

    def _train(self, *args: Any) -> Any:
        """SBX's compiled updates; with :attr:`overlap`, returned without waiting for them."""
        if not self.overlap:
            return super()._train(*args)  # type: ignore[misc]
        if self._overlap_rng is None:
            self._overlap_rng = np.random.default_rng(0 if self.seed is None else self.seed)
        # the parameters the updates start from, the previous call's result: copying them waits for it
        params = self.policy.actor_state.params
        self._acting = NumpyActor(params, self.overlap_activation, self.gaussian_actor, self._overlap_rng)
        *states, losses = super()._train(*args)  # type: ignore[misc]
        shown = losses if self._losses is None else self._losses  # computed: .item() does not wait
        self._losses = losses
        return (*states, shown)

    def sbx_acts(self, observation: Any, deterministic: bool) -> bool:
        """Whether SBX's own path acts: deterministic actions, gSDE, dict observations."""
        return deterministic or self.use_sde or isinstance(observation, dict)

    def as_sbx_action(self, sample: npt.NDArray[Any], vectorized: bool) -> npt.NDArray[Any]:
        """What SBX's ``BaseJaxPolicy.predict`` does with an actor's sample in [-1, 1]."""
        actions = np.asarray(sample).reshape((-1, *self.action_space.shape))
        if self.policy.squash_output:
            actions = np.asarray(self.policy.unscale_action(np.clip(actions, -1, 1)))
        else:
            actions = np.clip(actions, self.action_space.low, self.action_space.high)
        return actions if vectorized else actions.squeeze(axis=0)

    def predict(
        self,
        observation: Any,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        if self._acting is None or self.sbx_acts(observation, deterministic):
            return super().predict(observation, state, episode_start, deterministic)  # type: ignore[misc,no-any-return]
        observation, vectorized = self.policy.prepare_obs(observation)
        return self.as_sbx_action(self._acting.act(np.asarray(observation)), vectorized), state


class LeanTD3(Overlap, TD3):  # type: ignore[misc]  # _train: SBX's classmethod, overridden per instance
    """SBX's TD3, able to act while it learns."""


class LeanDDPG(Overlap, DDPG):  # type: ignore[misc]
    """SBX's DDPG, able to act while it learns."""
