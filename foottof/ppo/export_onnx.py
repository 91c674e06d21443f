"""Export of the actor as one ONNX model with explicit LSTM state, for C++ controllers.

The graph is the computation of :class:`foottof.ppo.export.NumpyPolicy` (the same arrays, read
from :func:`foottof.ppo.export.actor_arrays`), written with ``onnx.helper`` primitives (MatMul,
Add, Split, Sigmoid, Tanh, Mul, Elu): observation normalizer, LSTM layers, MLP head. Inputs and
outputs follow rsl_rl's ``export_policy_as_onnx`` for recurrent policies:

  inputs   obs (N, obs_size) float32, h_in (L, N, H), c_in (L, N, H)
  outputs  actions (N, action_size), h_out (L, N, H), c_out (L, N, H)

A controller feeds h_out / c_out back as h_in / c_in at the next step and zeros at an episode
start. The model's metadata (``metadata_props``, each value JSON) records the observation layout,
the action scale and clip, the default joint positions, the control rate and the checkpoint.

Why primitives and not a converter: jax2onnx and tf2onnx need a traced jax / TF function and
write ONNX's LSTM op from scan loops only where they recognize them; one step of the cell here
is eight ops, and written by hand the graph is exactly NumpyPolicy's, which the tests hold equal
to the JAX policy.
"""

from __future__ import annotations

import json

import numpy as np

OPSET = 17
INPUTS = ("obs", "h_in", "c_in")
OUTPUTS = ("actions", "h_out", "c_out")


def build_model(arrays: dict, meta: dict, metadata: dict | None = None):
    """The ONNX ModelProto of an exported actor (``arrays`` / ``meta`` as in the .npz)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    nodes, inits = [], []

    def const(name: str, value) -> str:
        inits.append(numpy_helper.from_array(np.asarray(value), name))
        return name

    def node(op: str, inputs: list[str], name: str, n_out: int = 1, **attrs) -> list[str]:
        outs = [name] if n_out == 1 else [f"{name}_{k}" for k in range(n_out)]
        nodes.append(helper.make_node(op, inputs, outs, name=name, **attrs))
        return outs

    obs_size, action_size = int(meta["obs_size"]), int(meta["action_size"])
    layers, hidden = int(meta["lstm_num_layers"]), int(meta["lstm_hidden_size"])
    x = "obs"
    if meta["normalize_observations"]:
        x = node("Sub", [x, const("obs_mean", arrays["obs_mean"])], "obs_centred")[0]
        x = node("Div", [x, const("obs_std", arrays["obs_std"])], "obs_normalized")[0]
    obs_in = x
    h_outs, c_outs = [], []
    for layer in range(max(layers, 0)):
        p = f"lstm_{layer}"
        idx = const(f"{p}/index", np.array(layer, np.int64))
        h = node("Gather", ["h_in", idx], f"{p}/h", axis=0)[0]
        c = node("Gather", ["c_in", idx], f"{p}/c", axis=0)[0]
        zx = node("MatMul", [x, const(f"{p}/w_x", arrays[f"{p}/w_x"])], f"{p}/zx")[0]
        zh = node("MatMul", [h, const(f"{p}/w_h", arrays[f"{p}/w_h"])], f"{p}/zh")[0]
        z = node("Add", [zx, zh], f"{p}/zxh")[0]
        z = node("Add", [z, const(f"{p}/b", arrays[f"{p}/b"])], f"{p}/z")[0]
        split = const(f"{p}/split", np.full(4, hidden, np.int64))
        i, f, g, o = node("Split", [z, split], f"{p}/gates", n_out=4, axis=1)
        i = node("Sigmoid", [i], f"{p}/i")[0]
        f = node("Sigmoid", [f], f"{p}/f")[0]
        g = node("Tanh", [g], f"{p}/g")[0]
        o = node("Sigmoid", [o], f"{p}/o")[0]
        fc = node("Mul", [f, c], f"{p}/fc")[0]
        ig = node("Mul", [i, g], f"{p}/ig")[0]
        c = node("Add", [fc, ig], f"{p}/c_new")[0]
        h = node("Mul", [o, node("Tanh", [c], f"{p}/tanh_c")[0]], f"{p}/h_new")[0]
        axes = const(f"{p}/axes", np.array([0], np.int64))
        h_outs.append(node("Unsqueeze", [h, axes], f"{p}/h_out")[0])
        c_outs.append(node("Unsqueeze", [c, axes], f"{p}/c_out")[0])
        x = h
    if h_outs:
        node("Concat", h_outs, "h_out", axis=0)
        node("Concat", c_outs, "c_out", axis=0)
    else:  # an MLP policy: the state passes through untouched
        node("Identity", ["h_in"], "h_out")
        node("Identity", ["c_in"], "c_out")
    if meta.get("obs_skip", False):  # the head reads [LSTM output, normalized obs]
        x = node("Concat", [x, obs_in], "actor/skip", axis=1)[0]
    for name in meta["actor_layers"]:
        k = const(f"actor/{name}/kernel", arrays[f"actor/{name}/kernel"])
        b = const(f"actor/{name}/bias", arrays[f"actor/{name}/bias"])
        x = node("Add", [node("MatMul", [x, k], f"actor/{name}/mm")[0], b], f"actor/{name}")[0]
        if name != "out":
            x = _activation(node, meta["activation"], x, f"actor/{name}/act")
    node("Identity", [x], "actions")

    n, lh = "batch", [max(layers, 1), "batch", hidden]
    graph = helper.make_graph(
        nodes,
        "foottof_actor",
        [
            helper.make_tensor_value_info("obs", TensorProto.FLOAT, [n, obs_size]),
            helper.make_tensor_value_info("h_in", TensorProto.FLOAT, lh),
            helper.make_tensor_value_info("c_in", TensorProto.FLOAT, lh),
        ],
        [
            helper.make_tensor_value_info("actions", TensorProto.FLOAT, [n, action_size]),
            helper.make_tensor_value_info("h_out", TensorProto.FLOAT, lh),
            helper.make_tensor_value_info("c_out", TensorProto.FLOAT, lh),
        ],
        inits,
    )
    model = helper.make_model(
        graph, producer_name="foottof", opset_imports=[helper.make_opsetid("", OPSET)]
    )
    model.ir_version = 8  # readable by ONNX Runtime >= 1.10
    for k, v in (metadata or {}).items():
        entry = model.metadata_props.add()
        entry.key, entry.value = k, json.dumps(v)
    onnx.checker.check_model(model, full_check=True)
    return model


def _activation(node, name: str, x: str, out: str) -> str:
    if name == "elu":
        return node("Elu", [x], out, alpha=1.0)[0]
    if name == "relu":
        return node("Relu", [x], out)[0]
    if name == "tanh":
        return node("Tanh", [x], out)[0]
    if name == "silu":
        return node("Mul", [x, node("Sigmoid", [x], out + "_sig")[0]], out)[0]
    raise ValueError(f"activation {name!r} has no ONNX form; valid: elu, relu, tanh, silu")


def export_onnx(path: str, networks, params, normalizer, metadata: dict | None = None) -> str:
    """Writes the actor of `params` (+ the actor part of `normalizer`) to `path` as ONNX.

    Args:
      path: output file (.onnx).
      networks, params, normalizer: as for foottof.ppo.export.export_policy.
      metadata: extra entries for the model's metadata_props (values are JSON-encoded).

    Returns:
      The path written.
    """
    import onnx

    from foottof.ppo.export import actor_arrays

    arrays, meta = actor_arrays(networks, params, normalizer)
    model = build_model(arrays, meta, {"foottof_network": meta, **(metadata or {})})
    onnx.save(model, path)
    return path


def deployment_metadata(cfg, env, checkpoint: str | None) -> dict:
    """What a controller needs besides the weights: observation layout, action scale and clip,
    default joint positions, control rate, the checkpoint (JSON-serializable)."""
    from foottof import constants
    from foottof.envs.observations import actor_obs_layout

    layout = actor_obs_layout(env.sensing.num_sensors, env.sensing.num_zones)
    return {
        "observation_layout": [
            {"name": n, "start": a, "stop": b, "what": w} for n, a, b, w in layout
        ],
        "observation_clip": float(cfg.env.clip_observations),
        "action_scale": float(constants.ACTION_SCALE),
        "action_clip": float(cfg.env.clip_actions),
        "joint_target": "default_joint_pos + action_scale * clip(action, -clip, clip) [rad]",
        "joint_names": list(constants.JOINT_NAMES),
        "default_joint_pos": [float(v) for v in constants.DEFAULT_POSE],
        "control_rate_hz": 1.0 / float(constants.CONTROL_DT_S),
        "source": env.source,
        "checkpoint": checkpoint or "untrained",
        "state_reset": "zero h_in and c_in at each episode start",
    }
