"""Exporting a trained policy: its network as ONNX (and as plain arrays), and a card to run it anywhere.

A run's deterministic policy is a multilayer perceptron from the flat observation to the
action; :func:`policy_layers` reads its layers from an SB3 (PyTorch) or SBX (JAX) model,
whichever learner trained it (PPO: the action mean, clipped to [-1, 1]; DDPG, TD3 and
SAC: the actor, squashed by ``tanh``). :func:`export_run` writes into one folder

* ``policy.onnx``: the network (``Gemm`` and activation nodes; input ``observation``
  float32 ``(batch, size)``, output ``action``), and a policy's limit guard
  (:mod:`armreach_core.rl.limit_guard`) as the last nodes;
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

from armreach_core.actions import LimitRoom
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


def exported_room(model: Any) -> LimitRoom | None:
    """The limit guard of ``model``'s policy, if it has one, on the card's observation: the joint
    angles read as they are (a task's scaling is folded into the first layer, not the guard)."""
    from armreach_core.rl.limit_guard import guard_of

    guard = guard_of(getattr(model, "policy", None))
    if guard is None:
        return None
    low, high = (tuple(float(v) for v in values.tolist()) for values in (guard.low, guard.high))
    return LimitRoom.unscaled(guard.start, guard.stop, low, high, guard.step)


def _guard_nodes(room: LimitRoom, action: str) -> tuple[list[Any], list[Any]]:
    """ONNX nodes (and initializers) that take ``action`` to the guarded ``action`` output."""
    from onnx import helper, numpy_helper

    inits = [
        numpy_helper.from_array(np.array([room.start], np.int64), "guard_start"),
        numpy_helper.from_array(np.array([room.stop], np.int64), "guard_stop"),
        numpy_helper.from_array(np.array([1], np.int64), "guard_axis"),
        numpy_helper.from_array(np.asarray(room.low, np.float32), "guard_low"),
        numpy_helper.from_array(np.asarray(room.high, np.float32), "guard_high"),
        numpy_helper.from_array(np.array(room.step, np.float32), "guard_step"),
        numpy_helper.from_array(np.array(-1.0, np.float32), "guard_min"),
        numpy_helper.from_array(np.array(1.0, np.float32), "guard_max"),
    ]
    nodes = [
        helper.make_node("Slice", ["observation", "guard_start", "guard_stop", "guard_axis"], ["q"]),
        helper.make_node("Sub", ["guard_low", "q"], ["below"]),
        helper.make_node("Div", ["below", "guard_step"], ["room_low"]),
        helper.make_node("Sub", ["guard_high", "q"], ["above"]),
        helper.make_node("Div", ["above", "guard_step"], ["room_high"]),
        helper.make_node("Max", [action, "room_low"], ["raised"]),
        helper.make_node("Min", ["raised", "room_high"], ["kept"]),
        helper.make_node("Clip", ["kept", "guard_min", "guard_max"], ["action"]),
    ]
    return nodes, inits


def write_onnx(layers: Sequence[Layer], bound: str, size: int, path: Path, room: LimitRoom | None = None) -> None:
    """``layers`` as an ONNX graph (opset 17); ``bound`` ``clip`` adds a Clip to [-1, 1]; ``room``
    (:func:`exported_room`) the policy's limit guard."""
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
        nodes.append(helper.make_node("Clip", [current, "low", "high"], ["bounded"]))
    else:
        nodes.append(helper.make_node("Identity", [current], ["bounded"]))
    if room is None:
        nodes.append(helper.make_node("Identity", ["bounded"], ["action"]))
    else:
        guard_nodes, guard_inits = _guard_nodes(room, "bounded")
        nodes, inits = nodes + guard_nodes, inits + guard_inits
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


def write_arrays(layers: Sequence[Layer], bound: str, path: Path, room: LimitRoom | None = None) -> None:
    arrays: dict[str, Any] = {"bound": np.array(bound), "activations": np.array([la.activation for la in layers])}
    if room is not None:
        arrays["guard_slice"] = np.array([room.start, room.stop], np.int64)
        arrays["guard_low"], arrays["guard_high"] = np.asarray(room.low, np.float32), np.asarray(room.high, np.float32)
        arrays["guard_step"] = np.array(room.step, np.float32)
    for i, layer in enumerate(layers):
        arrays[f"W{i}"], arrays[f"b{i}"] = layer.weight, layer.bias
    np.savez(path, **arrays)


def save_card(card: dict[str, Any], path: Path) -> None:
    path.write_text(json.dumps(card, indent=2) + "\n")


__all__ = [
    "CARD_FORMAT",
    "CARD_VERSION",
    "Layer",
    "exported_room",
    "observation_keys",
    "policy_layers",
    "save_card",
    "write_arrays",
    "write_onnx",
]
