"""GAE with timeout bootstrapping and rsl_rl's clipped PPO loss over whole-sequence minibatches."""

from typing import Any, NamedTuple

import jax
import jax.numpy as jp

from foottof.ppo import networks as net


class Minibatch(NamedTuple):
    """Whole env sequences of one rollout; B envs of the minibatch, T steps, A actions."""

    carry: Any  # LSTM carry at the start of the rollout, (B, H) leaves
    obs: Any  # (T, B, ...) observations (array or dict)
    resets: jax.Array  # (T, B) True where an episode starts at step t (carry reset before the step)
    actions: jax.Array  # (T, B, A) sampled actions
    log_probs: jax.Array  # (T, B) log pi_old(a|s)
    means: jax.Array  # (T, B, A) action means of the behaviour policy
    log_std: jax.Array  # (A,) log std of the behaviour policy (state-independent)
    values: jax.Array  # (T, B) V_old(s_t)
    advantages: jax.Array  # (T, B) (normalized) GAE advantages
    returns: jax.Array  # (T, B) value targets = GAE advantages + values
    # ppo.symmetry: the policy's carry at the rollout start on the mirrored observations, (B, H)
    # leaves (foottof.ppo.symmetry); None without it
    mirror_carry: Any = None


def bootstrap_truncation(
    rewards: jax.Array, values: jax.Array, truncation: jax.Array, gamma: float
) -> jax.Array:
    """rsl_rl timeout bootstrap: r_t + gamma * V(s_t) * truncation_t.

    With auto-reset the truncated next state s_{t+1} is gone; rsl_rl approximates V(s_{t+1}) by
    V(s_t). The step still counts as done in GAE, so nothing else is bootstrapped across it.

    Args:
      rewards, values, truncation: (T, B); truncation is 1 where the episode hit its time limit.
    """
    return rewards + gamma * values * truncation


def compute_gae(
    rewards: jax.Array,
    values: jax.Array,
    dones: jax.Array,
    last_value: jax.Array,
    gamma: float,
    lam: float,
) -> tuple[jax.Array, jax.Array]:
    """Generalized advantage estimation (rsl_rl RolloutStorage.compute_returns).

    delta_t = r_t + gamma * (1 - d_t) * V_{t+1} - V_t
    A_t = delta_t + gamma * lam * (1 - d_t) * A_{t+1}

    Args:
      rewards: (T, B) rewards (already bootstrapped on truncation).
      values: (T, B) V(s_t).
      dones: (T, B) 1 where the episode ended at step t (termination or truncation).
      last_value: (B,) V(s_T) of the observation after the last step.
      gamma, lam: discount and GAE lambda.

    Returns:
      (advantages (T, B), returns (T, B)) with returns = advantages + values.
    """
    next_values = jp.concatenate([values[1:], last_value[None]], axis=0)
    not_done = 1.0 - dones.astype(rewards.dtype)
    deltas = rewards + gamma * not_done * next_values - values

    def f(adv, xs):
        delta, nd = xs
        adv = delta + gamma * lam * nd * adv
        return adv, adv

    _, advantages = jax.lax.scan(f, jp.zeros_like(last_value), (deltas, not_done), reverse=True)
    return advantages, advantages + values


def ppo_loss(
    params: Any,
    networks: net.Networks,
    normalizer: Any,
    batch: Minibatch,
    *,
    clip_param: float,
    value_loss_coef: float,
    entropy_coef: float,
    use_clipped_value_loss: bool,
    kl_envs: int | None = None,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """Clipped surrogate + (clipped) value loss - entropy bonus, averaged over (T, B).

    ``kl_envs`` (static): the KL (the adaptive rate's) over the first ``kl_envs`` envs only, the
    rollout's own sequences when mirrored copies follow them (ppo.symmetry, as rsl_rl); None: all.

    Returns:
      (loss, metrics) with 'loss/policy', 'loss/value', 'loss/entropy' (the entropy, not its
      weighted term), 'ppo/kl' (rsl_rl KL(old || new) mean) and 'ppo/clip_fraction'.
    """
    means, log_std, values = networks.unroll(
        params, normalizer, batch.carry, batch.obs, batch.resets
    )
    log_probs = net.gaussian_log_prob(batch.actions, means, log_std)
    ratio = jp.exp(log_probs - batch.log_probs)
    surrogate = -batch.advantages * ratio
    surrogate_clipped = -batch.advantages * jp.clip(ratio, 1.0 - clip_param, 1.0 + clip_param)
    policy_loss = jp.mean(jp.maximum(surrogate, surrogate_clipped))

    if use_clipped_value_loss:
        values_clipped = batch.values + jp.clip(values - batch.values, -clip_param, clip_param)
        value_loss = jp.mean(
            jp.maximum((values - batch.returns) ** 2, (values_clipped - batch.returns) ** 2)
        )
    else:
        value_loss = jp.mean((values - batch.returns) ** 2)

    entropy = net.gaussian_entropy(log_std)
    loss = policy_loss + value_loss_coef * value_loss - entropy_coef * entropy

    kl = net.gaussian_kl(
        jax.lax.stop_gradient(batch.means),
        jp.exp(batch.log_std),
        jax.lax.stop_gradient(means),
        jax.lax.stop_gradient(jp.exp(log_std)),
    )
    clip_fraction = jp.mean((jp.abs(ratio - 1.0) > clip_param).astype(jp.float32))
    metrics = {
        "loss/policy": policy_loss,
        "loss/value": value_loss,
        "loss/entropy": entropy,
        "ppo/kl": jp.mean(kl if kl_envs is None else kl[:, :kl_envs]),
        "ppo/clip_fraction": jax.lax.stop_gradient(clip_fraction),
    }
    return loss, metrics
