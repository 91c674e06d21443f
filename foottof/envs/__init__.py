"""Environments: the goal-reaching ANYmal-D ToF task (Brax Env API)."""

from __future__ import annotations

from foottof.envs.anymal_tof import AnymalToFEnv
from foottof.envs.wrappers import VmapEnv, wrap_brax_env


def make_env(cfg, source: str | None = None, **kwargs) -> AnymalToFEnv:
    """Single (unbatched) env from a full config; ``source`` overrides ``cfg.env.source``."""
    return AnymalToFEnv(cfg, source=source or cfg.env.source, **kwargs)


def make_training_env(cfg, **kwargs):
    """Batched env for the trainer: ``reset(keys (N, 2))``, ``step(state, actions (N, 12))``."""
    return VmapEnv(make_env(cfg, **kwargs))


__all__ = ["AnymalToFEnv", "VmapEnv", "make_env", "make_training_env", "wrap_brax_env"]
