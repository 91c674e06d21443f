"""Batching adapters between single envs and the trainer (as Brax keeps its wrappers in envs/).

The trainer's env contract (foottof.ppo.train): ``reset(keys (N, 2)) -> State``,
``step(state, actions (N, A)) -> State`` with auto-reset inside ``step``. ``VmapEnv`` makes it
from a single env that auto-resets itself (our locomotion env); ``wrap_brax_env`` from any single
Brax ``Env``.
"""

from __future__ import annotations

import jax


class VmapEnv:
    """Batched view of a single env that auto-resets itself (reset/step vmapped over envs)."""

    def __init__(self, env):
        self.env = env

    def reset(self, keys: jax.Array):
        return jax.vmap(self.env.reset)(keys)

    def step(self, state, actions: jax.Array):
        return jax.vmap(self.env.step)(state, actions)

    def __getattr__(self, name):
        return getattr(self.env, name)


def wrap_brax_env(env, episode_length: int, action_repeat: int = 1, randomization_fn=None):
    """Any single Brax `Env` -> the batched, time-limited, auto-resetting env the trainer expects.

    Brax's VmapWrapper + EpisodeWrapper (sets done and info['truncation'] at `episode_length`)
    + AutoResetWrapper (resets to the env's first state of this env slot).
    """
    from brax.envs.wrappers import training as brax_training

    if episode_length < 1:
        raise ValueError(f"episode_length={episode_length}; must be >= 1")
    return brax_training.wrap(env, episode_length, action_repeat, randomization_fn)


__all__ = ["VmapEnv", "wrap_brax_env"]
