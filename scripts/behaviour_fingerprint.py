"""SHA-256 fingerprints of the stage-1 env and the trainer at a fixed seed, to show a refactor
changed no behaviour: run before and after, compare the printed lines.

    python scripts/behaviour_fingerprint.py   # ~2-3 min on 2 cores

Prints one digest (and one of the values alone) for a 50-step rollout of the stage-1 env (configs/stage1_cpu.py, 8 envs,
actions ~ N(0, 1) from a fixed key: observations, rewards, dones, metrics, physics state) and one
for one training iteration (the resulting TrainState and metrics, 8 envs x 8 steps).
"""

import hashlib
import os
import sys

import jax
import jax.numpy as jp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from configs import stage1_cpu  # noqa: E402
from foottof.envs import make_env, make_training_env  # noqa: E402
from foottof.ppo import train as train_lib  # noqa: E402


def digest(tree, names: bool = True) -> str:
    """Digest of every leaf's bytes, in tree order, with (names=True) or without its key path
    (names=False: a rename that keeps the keys' order, e.g. foottof.renames, keeps the digest)."""
    h = hashlib.sha256()
    for path, leaf in jax.tree_util.tree_flatten_with_path(jax.device_get(tree))[0]:
        if names:
            h.update(jax.tree_util.keystr(path).encode())
        h.update(np.ascontiguousarray(np.asarray(leaf)).tobytes())
    return h.hexdigest()[:16]


def line(what: str, tree) -> str:
    return f"{what}: {digest(tree)} (values only: {digest(tree, names=False)})"


def main() -> None:
    cfg = stage1_cpu.get_config()
    cfg.ppo.num_envs, cfg.ppo.num_steps, cfg.ppo.num_minibatches = 8, 8, 2
    env = make_env(cfg)
    n = 8
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), n))
    step = jax.jit(jax.vmap(env.step))
    outs = []
    for k in jax.random.split(jax.random.PRNGKey(1), 50):
        state = step(state, jax.random.normal(k, (n, 12)))
        outs.append((state.obs, state.reward, state.done, state.metrics, state.pipeline_state))
    print(line(f"env rollout (50 steps x {n} envs)", outs))
    trainer = train_lib.make_train(make_training_env(cfg), cfg)
    ts = trainer.init(jax.random.PRNGKey(0))
    ts, metrics = trainer.iteration(ts)
    print(line("one training iteration", (ts, metrics)))


if __name__ == "__main__":
    jp.zeros(())  # backend up before timing-sensitive work
    main()
