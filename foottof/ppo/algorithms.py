"""The training algorithms the one training step takes: PPO and distillation, each its minibatch loss.

As rsl_rl's ``algorithms/ppo.py`` and ``algorithms/distillation.py`` over one rollout storage: the
rollout, GAE, minibatches, optimizer and learning-rate rule (foottof.ppo.train) are shared; an
algorithm is the loss its gradient steps take, chosen once from the config (:func:`from_config`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import NamedTuple

import ml_collections

from foottof.ppo import distill, losses


class Algorithm(NamedTuple):
    """One training algorithm: what its gradient steps minimize.

    ``loss(params, networks, normalizer, minibatch, kl_envs=None) -> (loss, metrics)``; the
    metrics hold 'loss/policy', 'loss/value', 'loss/entropy', 'ppo/kl' and 'ppo/clip_fraction'
    (what the trainer's guards, learning-rate rule and progress line read). ``kl_envs`` (static):
    with mirrored copies after the rollout's sequences (ppo.symmetry), how many are the rollout's.
    """

    name: str  # "ppo" | "distillation"
    loss: Callable


def ppo(
    clip_param: float, value_loss_coef: float, entropy_coef: float, use_clipped_value_loss: bool
) -> Algorithm:
    """PPO: the clipped surrogate, (clipped) value loss and entropy bonus (losses.ppo_loss)."""
    loss = functools.partial(
        losses.ppo_loss,
        clip_param=clip_param,
        value_loss_coef=value_loss_coef,
        entropy_coef=entropy_coef,
        use_clipped_value_loss=use_clipped_value_loss,
    )
    return Algorithm("ppo", loss)


def distillation(reconstruction_weight: float = 0.0) -> Algorithm:
    """DAgger: the student's action means fit the teacher's actions (distill.distill_loss), plus
    ``reconstruction_weight`` x its belief decoder's error where it has one."""

    def loss(params, networks, normalizer, batch, kl_envs=None):
        del kl_envs  # no KL: the imitation loss has no old policy to stay near
        return distill.distill_loss(params, networks, normalizer, batch, reconstruction_weight)

    return Algorithm("distillation", loss)


def from_config(cfg: ml_collections.ConfigDict) -> Algorithm:
    """Distillation where ``train.teacher`` is set (ppo.reconstruction_weight), else PPO (the
    ppo section's clip_param, value_loss_coef, entropy_coef, use_clipped_value_loss)."""
    p, train_cfg = cfg.ppo, cfg.get("train", None)
    if train_cfg is not None and train_cfg.teacher:
        return distillation(float(p.reconstruction_weight))
    return ppo(
        clip_param=float(p.clip_param),
        value_loss_coef=float(p.value_loss_coef),
        entropy_coef=float(p.entropy_coef),
        use_clipped_value_loss=bool(p.use_clipped_value_loss),
    )
