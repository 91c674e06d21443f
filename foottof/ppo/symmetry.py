"""Mirror symmetry for the recurrent policy: mirrored copies of whole rollout sequences.

rsl_rl's symmetry data augmentation (``rsl_rl/algorithms/ppo.py``, ``symmetry_cfg``
``use_data_augmentation``) appends to every minibatch the mirror image of each sample: the
mirrored observation, the mirrored action, and the original's old log-probability, value,
advantage and return (a symmetric task pays a mirrored episode what it paid the original). It
refuses recurrent policies, because a mirrored sample needs the memory the policy would hold
had it lived the mirrored episode, and a minibatch of single steps has none. Our minibatches are
whole rollout sequences re-run from a stored carry, so the mirrored copy of a sequence is a
sequence too, and it needs only its own first carry.

**The mirrored carry.** During the rollout the policy also runs on the mirrored observations
from each episode's start (:func:`mirror_carry_step`: one extra forward pass per step, its
action unused; its carry resets where the episode resets), and each rollout stores the carry of
that pass at its first step beside the policy's own. A mirrored sequence therefore starts from
the carry the policy would really have on the mirrored episode at that step, and the update
re-runs it from there as it re-runs the original (truncated BPTT over the rollout). The
alternatives were cheaper and wrong: a zero carry (the memory of a fresh episode mid-episode),
or the original's carry (the memory of the left-right mirror image of what the policy saw). The
tracked carry is carried across iterations in ``TrainState.mirror_carry`` and checkpointed with
the rollout, so a resume stays bit-exact. Like rsl_rl, the KL that steers the adaptive learning
rate is taken over the original sequences, and the observation normalizer sees only them.

For distillation (foottof.ppo.distill) the mirrored sequence's label is the mirror of the
teacher's action: the student learns the mirror image of what the teacher did; the teacher is
not re-run on the mirrored sequences.
"""

from __future__ import annotations

import jax
import jax.numpy as jp

from foottof.ppo import networks as net
from foottof.ppo.losses import Minibatch


def mirror_carry_step(networks: net.Networks, params, normalizer, mirror, carry, obs, reset):
    """The policy's carry after one step on the mirrored observation ``mirror(obs)``.

    Args:
      mirror: the env's foottof.envs.symmetry.Mirror.
      carry: the carry of the previous step on the mirrored observations, (N, H) leaves.
      obs: this step's observation (N, ...); reset: (N,) bool, an episode starts here.
    """
    mirrored = mirror.observation(net.select_obs(obs))
    return networks.step(params, normalizer, carry, mirrored, reset)[0]


def augment(mb: Minibatch, mirror) -> Minibatch:
    """``mb`` (B whole sequences) followed along the env axis by their B mirrored copies.

    A copy holds the mirrored observations (every key of the observation, e.g. a teacher's
    action too) and actions (and action means), starts from ``mb.mirror_carry``, and keeps the
    original's resets, old log-probabilities, values, advantages and returns.

    Returns:
      Minibatch with leaves (T, 2 B, ...), carry (2 B, H) leaves, ``mirror_carry`` None.
    """
    if mb.mirror_carry is None:
        raise ValueError("a minibatch to mirror needs the mirrored sequences' carry")

    def twice(x, y=None):
        return jp.concatenate([x, x if y is None else y], axis=1)  # (T, B) -> (T, 2 B)

    return Minibatch(
        carry=jax.tree.map(lambda c, m: jp.concatenate([c, m], axis=0), mb.carry, mb.mirror_carry),
        obs=jax.tree.map(twice, mb.obs, mirror.observation(mb.obs)),
        resets=twice(mb.resets),
        actions=twice(mb.actions, mirror.action(mb.actions)),
        log_probs=twice(mb.log_probs),
        means=twice(mb.means, mirror.action(mb.means)),
        log_std=mb.log_std,
        values=twice(mb.values),
        advantages=twice(mb.advantages),
        returns=twice(mb.returns),
    )


def env_mirror(env):
    """The env's mirror maps (its ``mirror`` attribute, through wrappers).

    Raises:
      ValueError: the env has none.
    """
    mirror = getattr(env, "mirror", None)
    if mirror is None:
        raise ValueError(
            f"ppo.symmetry=True needs an env with mirror maps (a `mirror` attribute, "
            f"foottof.envs.symmetry.Mirror); {type(env).__name__} has none"
        )
    return mirror
