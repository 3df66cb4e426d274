"""Learners: which library trains an algorithm, Stable-Baselines3 (PyTorch) or SBX (JAX).

Both implement the same algorithms behind the same API (SBX is the SB3 team's JAX port,
built on SB3's base classes), so the rest of armreach (callbacks, checkpoints, replay
buffers, evaluation) does not care which one trained a run. The learner is a preset key
(``learner: sbx``) and a ``--learner`` flag; a run's ``config.yaml`` records it, and a run
without one (written before learners existed) is an SB3 run.

Off-policy runs default to SBX, which trains DDPG, TD3 and SAC faster than SB3 at the
paper's settings; PPO stays on SB3, whose rollouts armreach collects with the policy in NumPy
(:mod:`armreach_core.rl.lean_ppo`).
``armreach bench --learners sb3,sbx`` measures both; the figures and the command are in
docs/learning.md ("Learners side by side").
"""

from __future__ import annotations

import importlib
import inspect
import os
import sys
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from armreach_core.errors import ConfigError
from armreach_core.robot.cache_files import cache_dir

if TYPE_CHECKING:
    import numpy.typing as npt
    from stable_baselines3.common.base_class import BaseAlgorithm

LEARNERS = ("sb3", "sbx")
#: A run config without a ``learner`` setting was trained with this one.
LEGACY_LEARNER = "sb3"
#: The module of each (learner, algorithm): SB3's family is Stable-Baselines3 and its
#: contrib package (TQC, CrossQ); SBX has them all.
MODULES = {
    "sb3": {
        "ppo": "stable_baselines3",
        "ddpg": "stable_baselines3",
        "td3": "stable_baselines3",
        "sac": "stable_baselines3",
        "tqc": "sb3_contrib",
        "crossq": "sb3_contrib",
    },
    "sbx": {algo: "sbx" for algo in ("ppo", "ddpg", "td3", "sac", "tqc", "crossq")},
}
#: Algorithms each learner offers (names as in presets).
ALGORITHMS = {learner: tuple(modules) for learner, modules in MODULES.items()}
CLASS_NAMES = {"ppo": "PPO", "ddpg": "DDPG", "td3": "TD3", "sac": "SAC", "tqc": "TQC", "crossq": "CrossQ"}
#: Preset keys that become constructor arguments of another name.
ARGUMENT_OF = {
    "noise": "action_noise",
    "her": "replay_buffer_class",
    "demonstrations": "replay_buffer_class",
    "policy": "policy_kwargs",
}
#: Algorithms that can act while they learn (``overlap``, on learner sbx; rl.overlap).
OVERLAPPING = ("sac", "td3", "ddpg")
#: Algorithms whose SB3 policy takes a limit guard (``policy.limit_guard``, :mod:`armreach_core.rl.limit_guard`).
GUARDED = ("sac", "td3", "ddpg")
#: Preset keys that are not constructor arguments at all.
NOT_ARGUMENTS = (
    "timesteps",
    "n_envs",
    "torch_threads",
    "env",
    "checkpoint_every",
    "learner",
    "until_success",
    "imitation",
    "vec_env",
    "overlap",
)
#: Where a learner comes from, for the error that says what to install.
INSTALL = {
    "sb3": "pip install 'armreach[rl]' (it brings stable-baselines3 and sb3-contrib)",
    "sbx": "pip install 'armreach[rl]' (it brings sbx-rl and jax)",
}


#: Whether the user set ``XLA_FLAGS`` before armreach ran (then armreach leaves it alone).
_USER_XLA_FLAGS = "XLA_FLAGS" in os.environ
#: The variables that size XLA's CPU thread pool (its flags above do not: JAX's CPU client reads these).
XLA_POOL_VARIABLES = ("PJRT_NPROC", "NPROC")
#: Whether the user set one of them before armreach ran.
_USER_XLA_POOL = any(name in os.environ for name in XLA_POOL_VARIABLES)


def default_learner(algo: str) -> str:
    """The learner a new run of ``algo`` uses when neither the preset nor the command line names one."""
    return "sb3" if algo == "ppo" else "sbx"


def check_learner(learner: str, algo: str) -> None:
    if learner not in LEARNERS:
        raise ConfigError(f"learner {learner!r} is unknown; use one of {', '.join(LEARNERS)}")
    if algo not in ALGORITHMS[learner]:
        raise ConfigError(f"learner {learner!r} has no {algo!r}; use one of {', '.join(ALGORITHMS[learner])}")


def algo_class(algo: str, learner: str = LEGACY_LEARNER) -> type[BaseAlgorithm]:
    """The class that trains ``algo`` with ``learner``; ConfigError naming the install when it is missing."""
    check_learner(learner, algo)
    if learner == "sbx" and "XLA_FLAGS" not in os.environ:
        configure_xla()  # one thread unless configure_threads chose
    try:
        library = importlib.import_module(MODULES[learner][algo])
    except ImportError as exc:
        raise ConfigError(f"learner {learner!r} is not installed ({exc}); {INSTALL[learner]}") from None
    if (learner, algo) == ("sb3", "ppo"):  # SB3's PPO with a cheaper rollout step (rl.lean_ppo)
        from armreach_core.rl.lean_ppo import LeanPPO

        return LeanPPO
    if (learner, algo) == ("sbx", "sac"):  # SBX's SAC drawing its actions in one call (rl.lean_sac)
        from armreach_core.rl.lean_sac import LeanSAC

        return LeanSAC
    if learner == "sbx" and algo in ("td3", "ddpg"):  # able to act while they learn (rl.overlap)
        from armreach_core.rl.overlap import LeanDDPG, LeanTD3

        return LeanTD3 if algo == "td3" else LeanDDPG
    cls: type[BaseAlgorithm] = getattr(library, CLASS_NAMES[algo])
    return cls


def check_settings(algo: str, learner: str, settings: Mapping[str, Any]) -> None:
    """ConfigError for a preset key the learner's ``algo`` does not take (SB3's SAC has no ``policy_delay``...)."""
    if learner == "sbx":
        configure_xla(int(settings.get("torch_threads", 0)) or 1)  # XLA reads its flags once, when JAX starts
    if settings.get("overlap") and (learner != "sbx" or algo not in OVERLAPPING):
        raise ConfigError(
            f"overlap: only {', '.join(OVERLAPPING)} on learner 'sbx' act while they learn,"
            f" not {algo} on {learner!r}; remove the key"
        )
    if settings.get("policy", {}).get("limit_guard") and (learner != "sb3" or algo not in GUARDED):
        raise ConfigError(
            f"policy.limit_guard: only the SAC, TD3 and DDPG policies of learner 'sb3' keep their targets inside"
            f" the joint limits, not {algo} on {learner!r}; remove the key or use one of them"
        )
    accepted = inspect.signature(algo_class(algo, learner).__init__).parameters
    for key in settings:
        if key in NOT_ARGUMENTS:
            continue
        if ARGUMENT_OF.get(key, key) not in accepted:
            raise ConfigError(
                f"{key}: {CLASS_NAMES[algo]} of learner {learner!r} has no {key!r}; remove the key"
                + ("" if learner == "sbx" else " or use learner sbx")
            )


def activation(learner: str, name: str) -> Any:
    """The activation function object of ``name`` (``relu``, ``tanh``) for ``learner``."""
    if learner == "sbx":
        import flax.linen as nn

        return {"relu": nn.relu, "tanh": nn.tanh}[name]
    import torch

    return {"relu": torch.nn.ReLU, "tanh": torch.nn.Tanh}[name]


def optimizer_kwargs(learner: str, algo: str) -> dict[str, Any]:
    """Optimizer options of the policies.

    SB3: Adam's fused kernel, one call per parameter group instead of a dozen small tensor
    operations per parameter (DDPG on 2 cores: 69 -> 74-79 env steps/s; PPO's update of the
    `fast` preset about 10 % faster). Not for CrossQ,
    whose policy sets its own Adam betas. SBX's optax optimizers are compiled by XLA already.
    """
    return {"optimizer_kwargs": {"fused": True}} if learner == "sb3" and algo != "crossq" else {}


def library_class(model: BaseAlgorithm) -> type[BaseAlgorithm]:
    """The learner library's own class of ``model``: ``PPO`` for armreach's ``LeanPPO``, SBX's ``SAC``
    for ``LeanSAC``, the class itself for the rest."""
    for cls in type(model).__mro__:
        if cls.__module__.split(".")[0] in ("stable_baselines3", "sb3_contrib", "sbx"):
            return cls
    return type(model)


def learner_of(model: BaseAlgorithm) -> str:
    """``sbx`` or ``sb3``: the learner whose class ``model`` is (or derives from)."""
    return "sbx" if library_class(model).__module__.split(".")[0] == "sbx" else "sb3"


def policy_parameters(model: BaseAlgorithm) -> dict[str, npt.NDArray[Any]]:
    """The learned arrays of ``model`` by name, as NumPy arrays, whichever learner trained it.

    SB3: the policy's ``state_dict`` (networks and target networks) and SAC's entropy
    coefficient. SBX: ``params`` and ``target_params`` of each Flax train state of the policy
    and of the model (SAC's entropy coefficient is one). Optimizer states are left out. Two
    models trained alike hold equal arrays under equal names.
    """
    import numpy as np

    if learner_of(model) == "sbx":
        import jax
        from flax.training.train_state import TrainState

        owners = {"policy": vars(model.policy), "model": vars(model)}
        tree = {
            f"{owner}.{name}": {"params": state.params, "target_params": getattr(state, "target_params", None)}
            for owner, attributes in owners.items()
            for name, state in attributes.items()
            if isinstance(state, TrainState)
        }
        leaves, _ = jax.tree_util.tree_flatten_with_path(tree)
        return {jax.tree_util.keystr(path): np.asarray(leaf) for path, leaf in leaves}
    arrays = {name: tensor.detach().cpu().numpy() for name, tensor in model.policy.state_dict().items()}
    log_ent_coef = getattr(model, "log_ent_coef", None)
    if log_ent_coef is not None:
        arrays["log_ent_coef"] = log_ent_coef.detach().cpu().numpy()
    return arrays


#: JAX's persistent compilation cache, in armreach's cache folder: SBX compiles its updates
#: again for every new model (each run, resumed run and evaluation), seconds on 2 cores, and
#: with the cache reads back what an earlier process compiled. Every program is kept (no
#: minimum compile time or size); the size limit makes JAX lock the folder, so processes
#: training side by side share it.
XLA_CACHE_KIND = "xla"
XLA_CACHE_SETTINGS = {
    "jax_persistent_cache_min_compile_time_secs": 0.0,
    "jax_persistent_cache_min_entry_size_bytes": 0,
    "jax_compilation_cache_max_size": 2**29,
}


def use_xla_cache() -> None:
    """Keep what XLA compiles in armreach's cache folder (:data:`XLA_CACHE_KIND`), unless the
    user chose a cache (``JAX_COMPILATION_CACHE_DIR``, an empty value for none)."""
    if "JAX_COMPILATION_CACHE_DIR" in os.environ:
        return
    settings = {"jax_compilation_cache_dir": str(cache_dir(XLA_CACHE_KIND)), **XLA_CACHE_SETTINGS}
    if "jax" in sys.modules:
        import jax

        for name, value in settings.items():
            jax.config.update(name, value)  # type: ignore[no-untyped-call]
    else:  # read by JAX when it starts, here and in the processes this one starts
        os.environ.update({name.upper(): str(value) for name, value in settings.items()})


def configure_xla(threads: int = 1) -> None:
    """Ask XLA (JAX's compiler) for ``threads`` CPU threads, unless the user set ``XLA_FLAGS``,
    and keep what it compiles (:func:`use_xla_cache`).

    The threads take effect only before JAX is imported (XLA reads its flags once): a run's
    ``check_settings`` sets it from the run's thread count before anything imports SBX.
    One thread by default, as for torch. JAX's CPU client sizes its pool from ``PJRT_NPROC``
    (every core without it, whatever the flags say), so that is set too, unless the user set
    it or ``NPROC``.
    """
    use_xla_cache()
    if not _USER_XLA_FLAGS and "jax" not in sys.modules:
        os.environ["XLA_FLAGS"] = (
            f"--xla_cpu_multi_thread_eigen={'true' if threads > 1 else 'false'} intra_op_parallelism_threads={threads}"
        )
        if not _USER_XLA_POOL:
            os.environ["PJRT_NPROC"] = str(threads)
