"""SBX's SAC with its exploring action drawn in one compiled call, and able to act while it learns.

To draw an action, SBX's SAC policy first splits its random key with ``jax.random.split``
and unpacks the pair, three JAX operations dispatched one by one from Python, and then runs
its compiled sampler: on a 2-core CPU about 320 microseconds for the split against 80 for
the sample, at every env step. :class:`LeanSAC` splits the key inside the compiled sampler,
so one call returns the action and both new keys. The keys, and so the actions and the whole
run, are SBX's own to the bit (``tests/test_lean_sac.py``). Deterministic actions, gSDE and
dict observations take SBX's own path. Only the algorithm class differs: a saved model loads
with ``sbx.SAC`` as with this class. With ``overlap: true`` it acts on a numpy copy of its
actor while the learner updates (:mod:`armreach_core.rl.overlap`).
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np
from sbx import SAC

from armreach_core.rl.overlap import Overlap


@jax.jit
def _split_and_sample(actor_state: Any, observations: Any, key: Any) -> tuple[Any, Any, Any]:
    """SBX's ``reset_noise`` then ``sample_action``, compiled as one function."""
    key, noise_key = jax.random.split(key, 2)
    action = actor_state.apply_fn(actor_state.params, observations).sample(seed=noise_key)
    return action, key, noise_key


class LeanSAC(Overlap, SAC):  # type: ignore[misc]  # _train: see rl.overlap
    """SBX's SAC whose exploring actions come from :func:`_split_and_sample`, or from the
    acting copy while the learner works (:class:`~armreach_core.rl.overlap.Overlap`)."""

    gaussian_actor = True

    def predict(
        self,
        observation: Any,
        state: tuple[np.ndarray, ...] | None = None,
        episode_start: np.ndarray | None = None,
        deterministic: bool = False,
    ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        policy = self.policy
        if self.sbx_acts(observation, deterministic):
            return SAC.predict(self, observation, state, episode_start, deterministic)
        observation, vectorized = policy.prepare_obs(observation)
        if self._acting is not None:  # acting while the learner updates (rl.overlap)
            sample = self._acting.act(np.asarray(observation))
        else:
            action, policy.key, policy.noise_key = _split_and_sample(policy.actor_state, observation, policy.key)
            sample = np.array(action)
        return self.as_sbx_action(sample, vectorized), state
