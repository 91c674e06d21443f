"""Evaluation harness: the test-ensemble env of one cell (DR off, a perturbation) and its policy."""

from __future__ import annotations

import copy
import os
from typing import NamedTuple

import jax
import jax.numpy as jp
import ml_collections

from foottof.envs import AnymalToFEnv, make_env
from foottof.ppo.networks import make_networks
from foottof.ppo.storage.checkpoint import CheckpointUnreadable, load_params_and_normalizer


def eval_config(cfg: ml_collections.ConfigDict, perturbation: str, level: float):
    """Copy of `cfg` for one evaluation cell: DR off, nominal readings, the shank of the cell.

    Joint offset and odometry levels are not config: they are given at reset
    (:func:`perturbed_reset`) and kept by the env across auto-resets. A shank-length level is the
    physics model's ``env.model.shank_scale``.

    Returns:
      (cfg, shank_scale): the config and its ``env.model.shank_scale``.
    """
    c = copy.deepcopy(cfg)
    with c.unlocked():
        c.env.randomization.enabled = False  # no DR, no pushes
        c.env.randomization.joint_offset_rad = 0.0  # nominal readings; levels come at reset
        c.env.randomization.odometry_level = 1.0  # the paper's nominal 100 %
        c.terrain.init_level_max = int(c.eval.num_levels) - 1  # spawn on every row
        c.env.model.shank_scale = float(level) if perturbation == "shank_length" else 1.0
    return c, float(c.env.model.shank_scale)


def perturbed_reset(env, perturbation: str):
    """The one way to start a perturbed episode: ``(key, level) -> State`` of ``env``.

    Joint offset [rad] and odometry level [x 100 %] are (traceable) reset arguments
    (``env.reset_perturbed``) that the env keeps for its auto-reset episodes; for 'none' and
    'shank_length' (the env's physics model, :func:`eval_config`) ``level`` is ignored.
    """
    if perturbation == "joint_offset":
        return lambda key, level: env.reset_perturbed(key, joint_offset_rad=level)
    if perturbation == "odometry":
        return lambda key, level: env.reset_perturbed(key, odometry_level=level)
    return lambda key, level: env.reset(key)


def eval_terrain_map(cfg: ml_collections.ConfigDict, key: jax.Array):
    """The test ensemble: eval.stone_fraction stepping stones (equal split), the rest gaps."""
    from foottof.terrain.terrain_map import build_terrain_map, make_eval_map_spec

    e = cfg.eval
    stones, gaps = tuple(e.stone_types), tuple(e.gap_types)
    frac = float(e.stone_fraction)
    if not 0.0 <= frac <= 1.0:
        raise ValueError(f"eval.stone_fraction={frac} outside the valid range [0, 1]")
    weights = [frac / len(stones)] * len(stones) + [(1 - frac) / len(gaps)] * len(gaps)
    spec = make_eval_map_spec(
        cfg.terrain,
        stones + gaps,
        weights,
        progress=float(e.difficulty_fraction),
        num_levels=int(e.num_levels),
        num_cols=int(e.num_cols),
    )
    return build_terrain_map(key, spec)


def load_policy(cfg, env, obs, checkpoint: str | None, key: jax.Array):
    """(networks, params, normalizer): fresh init if `checkpoint` is None, else restored.

    Raises:
      FileNotFoundError: no checkpoint at `checkpoint`.
      CheckpointUnreadable: the checkpoint cannot be read completely (damaged, partial copy).
      ValueError: the checkpoint's network / observation layout differs from this env's.
    """
    networks = make_networks(env.action_size, cfg.network)
    params = networks.init_params(key, obs)
    normalizer = jax.tree.map(jp.asarray, networks.init_normalizer(obs))  # python floats -> arrays
    if checkpoint is None:
        return networks, params, normalizer
    if not os.path.exists(checkpoint):
        raise FileNotFoundError(f"checkpoint {checkpoint!r} does not exist")
    try:
        params, normalizer = load_params_and_normalizer(checkpoint, params, normalizer)
    except FileNotFoundError as e:
        raise FileNotFoundError(f"checkpoint {checkpoint!r}: {e}") from None
    except CheckpointUnreadable as e:
        raise CheckpointUnreadable(f"checkpoint {checkpoint!r} is unreadable: {e}") from None
    except ValueError as e:
        sizes = {k: int(v.shape[-1]) for k, v in obs.items()}
        raise ValueError(
            f"checkpoint {checkpoint!r} does not fit this env (source={env.source!r}, "
            f"observation sizes {sizes}): {e}"
        ) from None
    return networks, params, normalizer


class EvalSetup(NamedTuple):
    """What one evaluation cell runs: the env and the deterministic policy's pieces."""

    env: AnymalToFEnv
    networks: object  # foottof.ppo.networks.Networks
    params: object
    normalizer: object


def make_eval_env_and_policy(
    cfg: ml_collections.ConfigDict,
    source: str,
    checkpoint: str | None,
    key_map: jax.Array,
    key_init: jax.Array,
    perturbation: str = "none",
    level: float = 0.0,
) -> EvalSetup:
    """The env of one evaluation cell on the test ensemble and the policy (one way to get both).

    Args:
      cfg: full config (c.eval gives the ensemble).
      source: foot-reading source, one of foottof.perception.SOURCES.
      checkpoint: checkpoint path, or None for a freshly initialized (untrained) policy.
      key_map: PRNG key of the terrain map (the same key gives the same ensemble).
      key_init: PRNG key of the policy initialization.
      perturbation, level: the cell; only a shank length changes the env (``eval_config``),
        the other levels are given at reset (:func:`perturbed_reset`).

    Returns:
      EvalSetup(env, networks, params, normalizer).
    """
    c, _ = eval_config(cfg, perturbation, level)
    env = make_env(c, source=source, terrain_map=eval_terrain_map(c, key_map))
    obs = {k: jp.zeros((1, n), jp.float32) for k, n in env.observation_size.items()}  # no compile
    networks, params, normalizer = load_policy(c, env, obs, checkpoint, key_init)
    return EvalSetup(env, networks, params, normalizer)
