"""Environments: the goal-reaching ANYmal-D ToF task (Brax Env API)."""

from __future__ import annotations

from foottof.envs.anymal_tof import AnymalToFEnv


def make_env(cfg, source: str | None = None, **kwargs) -> AnymalToFEnv:
    """Single (unbatched) env from a full config; ``source`` overrides ``cfg.env.source``."""
    return AnymalToFEnv(cfg, source=source or cfg.env.source, **kwargs)


def make_training_env(cfg, **kwargs):
    """Batched env for the trainer: ``reset(keys (N, 2))``, ``step(state, actions (N, 12))``."""
    from foottof.ppo.train import VmapEnv  # the one batching adapter (the trainer's contract)

    return VmapEnv(make_env(cfg, **kwargs))


__all__ = ["AnymalToFEnv", "make_env", "make_training_env"]
