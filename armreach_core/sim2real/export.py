"""Exporting a trained policy: its network as ONNX (and as plain arrays), and a card to run it anywhere.

A run's deterministic policy is a multilayer perceptron from the flat observation to the
action; :func:`policy_layers` reads its layers from an SB3 (PyTorch) or SBX (JAX) model,
whichever learner trained it (PPO: the action mean, clipped to [-1, 1]; DDPG, TD3 and
SAC: the actor, squashed by ``tanh``). :func:`export_run` writes into one folder

* ``policy.onnx``: the network (``Gemm`` and activation nodes; input ``observation``
  float32 ``(batch, size)``, output ``action``);
* ``policy.npz``: the same layers as arrays, for :mod:`armreach_core.sim2real.runtime`
  without onnxruntime;
* ``card.json``: everything else a robot needs (see :func:`policy_card`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from armreach_core.errors import ConfigError
from armreach_core.rl.learners import learner_of, library_class

CARD_FORMAT = "armreach-policy-card"
CARD_VERSION = 1
#: Activations the export and the runtime know, by their ONNX operator.
ACTIVATIONS = {"relu": "Relu", "tanh": "Tanh", "identity": "Identity"}


@dataclass(frozen=True)
class Layer:
    """``activation(x @ weight.T + bias)``."""

    weight: npt.NDArray[np.float32]
    bias: npt.NDArray[np.float32]
    activation: str


def _torch_activation(module: Any) -> str | None:
    name = type(module).__name__.lower()
    return name if name in ACTIVATIONS else None


def _torch_layers(modules: Sequence[Any]) -> list[Layer]:
    layers: list[Layer] = []
    for module in modules:
        if type(module).__name__ == "Linear":
            weight = module.weight.detach().cpu().numpy().astype(np.float32)
            layers.append(Layer(weight, module.bias.detach().cpu().numpy().astype(np.float32), "identity"))
        elif (act := _torch_activation(module)) is not None and layers:
            layers[-1] = Layer(layers[-1].weight, layers[-1].bias, act)
        elif type(module).__name__ not in ("Flatten", "Identity"):
            raise ConfigError(f"cannot export a policy layer of type {type(module).__name__}; only MLPs are exported")
    return layers


def _flax_layers(params: Any, activation: str, squash: str) -> list[Layer]:
    dense = sorted(
        ((name, value) for name, value in params.items() if name.startswith("Dense_")),
        key=lambda item: int(item[0].split("_")[1]),
    )
    if not dense:
        raise ConfigError("cannot export this SBX policy: no Dense layers found")
    layers = [
        Layer(np.asarray(v["kernel"], dtype=np.float32).T, np.asarray(v["bias"], dtype=np.float32), activation)
        for _, v in dense
    ]
    last = layers[-1]
    layers[-1] = Layer(last.weight, last.bias, squash)
    return layers


def policy_layers(model: Any) -> tuple[list[Layer], str]:
    """The deterministic policy of ``model`` as layers, and what bounds its output (``clip`` or ``tanh``)."""
    algo = library_class(model).__name__.lower()
    if learner_of(model) == "sbx":
        return _sbx_layers(model, algo)
    policy = model.policy
    if algo == "ppo":
        layers = _torch_layers([*policy.mlp_extractor.policy_net, policy.action_net])
        return _standardized(layers, policy.pi_features_extractor), "clip"
    if algo in ("td3", "ddpg"):
        return _standardized(_torch_layers(list(policy.actor.mu)), policy.actor.features_extractor), "tanh"
    if algo == "sac":
        layers = _torch_layers([*policy.actor.latent_pi, policy.actor.mu])
        layers = [*layers[:-1], Layer(layers[-1].weight, layers[-1].bias, "tanh")]
        return _standardized(layers, policy.actor.features_extractor), "tanh"
    raise ConfigError(f"cannot export a {library_class(model).__name__} policy; exported are PPO, DDPG, TD3 and SAC")


def _standardized(layers: list[Layer], extractor: Any) -> list[Layer]:
    """``layers`` taking the raw observation: an imitation policy's :class:`Standardize` inputs
    (``(x - mean) / std``, :mod:`armreach_core.rl.standardize`) folded into the first layer."""
    from armreach_core.rl.standardize import Standardize

    if not isinstance(extractor, Standardize):
        return layers
    mean, std = extractor.mean.detach().cpu().numpy(), extractor.std.detach().cpu().numpy()
    return fold_scaling(layers, mean, std)


def _sbx_layers(model: Any, algo: str) -> tuple[list[Layer], str]:
    policy = model.policy
    activation = getattr(getattr(policy, "activation_fn", None), "__name__", "relu")
    activation = activation if activation in ACTIVATIONS else "relu"
    params = policy.actor_state.params
    params = params.get("params", params)
    if algo == "sac":  # SBX's SAC actor: Dense hidden layers, a mean head, then a log-std head (not needed)
        dense = sorted((k for k in params if k.startswith("Dense_")), key=lambda k: int(k.split("_")[1]))
        return _flax_layers({k: params[k] for k in dense[:-1]}, activation, "tanh"), "tanh"
    if algo in ("td3", "ddpg"):
        return _flax_layers(params, activation, "tanh"), "tanh"
    raise ConfigError(f"cannot export an SBX {algo} policy; exported are DDPG, TD3 and SAC")


def fold_scaling(layers: Sequence[Layer], shift: npt.ArrayLike, scale: npt.ArrayLike, offset: int = 0) -> list[Layer]:
    """``layers`` taking the inputs from ``offset`` on in SI units: the scaling ``(x - shift) / scale``
    the policy was trained behind (a task's ``observation_scaling``) folded into the first layer."""
    first = layers[0]
    shift64, scale64 = np.asarray(shift, dtype=np.float64), np.asarray(scale, dtype=np.float64)
    part = slice(offset, offset + len(scale64))
    weight = first.weight.astype(np.float64)
    folded = weight[:, part] / scale64
    bias = first.bias.astype(np.float64) - folded @ shift64
    weight[:, part] = folded
    return [Layer(weight.astype(np.float32), bias.astype(np.float32), first.activation), *layers[1:]]


def observation_keys(space: Any) -> list[str] | None:
    """The keys of a Dict observation in the order the policy concatenates them; None for a flat one."""
    spaces = getattr(space, "spaces", None)
    return None if spaces is None else list(spaces)


def write_onnx(layers: Sequence[Layer], bound: str, size: int, path: Path) -> None:
    """``layers`` as an ONNX graph (opset 17); ``bound`` ``clip`` adds a Clip to [-1, 1]."""
    try:
        import onnx
        from onnx import TensorProto, helper, numpy_helper
    except ImportError:
        raise ConfigError("writing ONNX needs the onnx package: pip install 'armreach[deploy]'") from None
    nodes, inits = [], []
    current = "observation"
    for i, layer in enumerate(layers):
        inits += [numpy_helper.from_array(layer.weight, f"W{i}"), numpy_helper.from_array(layer.bias, f"b{i}")]
        nodes.append(helper.make_node("Gemm", [current, f"W{i}", f"b{i}"], [f"z{i}"], transB=1))
        current = f"z{i}"
        if layer.activation != "identity":
            nodes.append(helper.make_node(ACTIVATIONS[layer.activation], [current], [f"a{i}"]))
            current = f"a{i}"
    if bound == "clip":
        inits += [
            numpy_helper.from_array(np.array(-1.0, np.float32), "low"),
            numpy_helper.from_array(np.array(1.0, np.float32), "high"),
        ]
        nodes.append(helper.make_node("Clip", [current, "low", "high"], ["action"]))
    else:
        nodes.append(helper.make_node("Identity", [current], ["action"]))
    actions = int(layers[-1].weight.shape[0])
    graph = helper.make_graph(
        nodes,
        "armreach_policy",
        [helper.make_tensor_value_info("observation", TensorProto.FLOAT, ["batch", size])],
        [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", actions])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="armreach")
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def write_arrays(layers: Sequence[Layer], bound: str, path: Path) -> None:
    arrays: dict[str, Any] = {"bound": np.array(bound), "activations": np.array([la.activation for la in layers])}
    for i, layer in enumerate(layers):
        arrays[f"W{i}"], arrays[f"b{i}"] = layer.weight, layer.bias
    np.savez(path, **arrays)


def save_card(card: dict[str, Any], path: Path) -> None:
    path.write_text(json.dumps(card, indent=2) + "\n")


__all__ = [
    "CARD_FORMAT",
    "CARD_VERSION",
    "Layer",
    "observation_keys",
    "policy_layers",
    "save_card",
    "write_arrays",
    "write_onnx",
]
