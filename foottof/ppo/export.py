"""Export of the actor (normalizer + LSTM + MLP head) to one .npz and a NumPy-only inference class.

`NumpyPolicy` imports only NumPy (this module imports JAX lazily, inside `export_policy`), so it can
run on the robot. It returns the deterministic action mean, in float32, for one robot.
"""

import json

import numpy as np

_GATES = ("i", "f", "g", "o")  # flax LSTM gate order: input, forget, cell, output


def export_policy(path: str, networks, params, normalizer) -> str:
    """Writes the actor of `params` (+ the actor-obs part of `normalizer`) to `path` (.npz).

    Args:
      path: output file; '.npz' is appended by NumPy if missing.
      networks: foottof.ppo.networks.Networks used in training.
      params: trained network variables.
      normalizer: running observation statistics of the same run.

    Returns:
      The path written.
    """
    arrays, meta = actor_arrays(networks, params, normalizer)
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), np.uint8)
    np.savez(path, **arrays)
    return path if path.endswith(".npz") else path + ".npz"


def actor_arrays(networks, params, normalizer) -> tuple[dict, dict]:
    """(arrays, meta) of the actor: normalizer mean/std, LSTM weights per layer (gates i, f, g,
    o concatenated: w_x (in, 4H), w_h (H, 4H), b (4H,)), MLP head (with meta["obs_skip"] its
    first layer reads [LSTM output, normalized obs]); float32 NumPy."""
    import jax

    module = networks.module
    p = jax.device_get(params)["params"]
    norm = jax.device_get(normalizer)
    mean, std = norm.mean, norm.std
    if isinstance(mean, dict):  # dict observation: the actor reads 'state'
        mean, std = mean["state"], std["state"]
    arrays = {
        "obs_mean": np.asarray(mean, np.float32),
        "obs_std": np.asarray(std, np.float32),
    }
    if module.recurrent:
        for layer in range(module.lstm_num_layers):
            cell = p["memory_a"][f"lstm_{layer}"]
            arrays[f"lstm_{layer}/w_x"] = np.concatenate(
                [cell[f"i{g}"]["kernel"] for g in _GATES], axis=1
            ).astype(np.float32)  # (in, 4H)
            arrays[f"lstm_{layer}/w_h"] = np.concatenate(
                [cell[f"h{g}"]["kernel"] for g in _GATES], axis=1
            ).astype(np.float32)  # (H, 4H)
            arrays[f"lstm_{layer}/b"] = np.concatenate(
                [cell[f"h{g}"]["bias"] for g in _GATES]
            ).astype(np.float32)  # (4H,)
    names = [f"dense_{i}" for i in range(len(module.actor_hidden))] + ["out"]
    for name in names:
        arrays[f"actor/{name}/kernel"] = np.asarray(p["actor"][name]["kernel"], np.float32)
        arrays[f"actor/{name}/bias"] = np.asarray(p["actor"][name]["bias"], np.float32)
    meta = {
        "recurrent": bool(module.recurrent),
        "lstm_num_layers": int(module.lstm_num_layers) if module.recurrent else 0,
        "lstm_hidden_size": int(module.lstm_hidden_size),
        "actor_layers": names,
        "obs_skip": bool(module.obs_skip),
        "activation": module.activation,
        "normalize_observations": bool(networks.normalize_observations),
        "action_size": int(module.action_size),
        "obs_size": int(arrays["obs_mean"].shape[-1]),
    }
    return arrays, meta


def _sigmoid(x: np.ndarray) -> np.ndarray:
    """1 / (1 + exp(-x)) without overflow: exp only of -|x| <= 0 (x >= 0: the same formula)."""
    e = np.exp(-np.abs(x))
    return np.where(x >= 0, 1.0 / (1.0 + e), e / (1.0 + e))


_ACT = {
    "elu": lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0))),
    "relu": lambda x: np.maximum(x, 0),
    "tanh": np.tanh,
    "silu": lambda x: x * _sigmoid(x),
}


class NumpyPolicy:
    """Deterministic policy from an exported .npz: `reset()` per episode, then `policy(obs)`."""

    def __init__(self, path: str):
        with np.load(path) as f:
            self.arrays = {k: f[k] for k in f.files}
        self.meta = json.loads(self.arrays.pop("meta").tobytes().decode())
        self.obs_size = self.meta["obs_size"]
        self.action_size = self.meta["action_size"]
        self._act = _ACT[self.meta["activation"]]
        self.reset()

    def reset(self) -> None:
        """Zeros the LSTM state (what the trainer does at an episode start)."""
        h = self.meta["lstm_hidden_size"]
        n = self.meta["lstm_num_layers"]
        self.carry = [(np.zeros(h, np.float32), np.zeros(h, np.float32)) for _ in range(n)]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Action mean (action_size,) float32 for one observation (obs_size,) (the actor obs)."""
        a = self.arrays
        x = np.asarray(obs, np.float32)
        if x.shape != (self.obs_size,):
            raise ValueError(f"obs shape {x.shape}; expected ({self.obs_size},)")
        if self.meta["normalize_observations"]:
            x = (x - a["obs_mean"]) / a["obs_std"]
        obs_in = x
        for layer, (c, h) in enumerate(self.carry):
            z = x @ a[f"lstm_{layer}/w_x"] + h @ a[f"lstm_{layer}/w_h"] + a[f"lstm_{layer}/b"]
            i, f, g, o = np.split(z, 4)
            c = _sigmoid(f) * c + _sigmoid(i) * np.tanh(g)
            h = _sigmoid(o) * np.tanh(c)
            self.carry[layer] = (c, h)
            x = h
        if self.meta.get("obs_skip", False):
            x = np.concatenate([x, obs_in])
        for name in self.meta["actor_layers"]:
            x = x @ a[f"actor/{name}/kernel"] + a[f"actor/{name}/bias"]
            if name != "out":
                x = self._act(x)
        return x.astype(np.float32)
