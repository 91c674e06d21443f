"""Distillation of a privileged teacher into a sensor-only student (on-policy DAgger).

rsl_rl's ``Distillation`` (rsl_rl/algorithms/distillation.py, v2.3) as a variant of our PPO
iteration: the env is stepped with the student's sampled actions, the loss is the mean squared
error between the student's action means and the teacher's deterministic action, and the
student's LSTM is trained by truncated backprop over each rollout with its state carried across
iterations. Everything else (rollout, minibatches, checkpoints, resume, logging) is the PPO
trainer's (foottof.ppo.train, foottof.ppo.runner):

- :class:`TeacherEnv` wraps the batched env whose actor observation is the teacher's (the
  student's inputs first, the privileged ones appended, e.g. ``env.actor_terrain``). It runs the
  teacher on that observation with the teacher's LSTM carry (kept in ``State.info``, so it is
  checkpointed with the env state and a resume is bit-exact), shows the student only the first
  ``student_obs_size`` inputs, and puts the teacher's action in ``obs['teacher_action']``, which
  the networks do not read and the rollout stores with the observation.
- :func:`distill_loss` replaces the PPO loss when ``train.teacher`` is set.

The student's critic is not trained here: it starts as the teacher's (same critic inputs) so
that PPO fine-tuning (``train.init_from`` = the student) starts from a value function of the task.
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from brax.envs.base import State

from foottof.ppo import networks as net

TEACHER_ACTION_KEY = "teacher_action"  # obs key of the teacher's action (not a network input)
TEACHER_OBS_KEY = "teacher_state"  # obs key of the teacher's whole actor observation
TEACHER_CARRY_KEY = "teacher_carry"  # State.info key of the teacher's LSTM carry


class TeacherEnv:
    """A batched env whose observation the teacher reads, shown to a student (see module doc).

    Args:
      env: batched env (``reset(keys (N, 2))``, ``step(state, actions (N, A))``) with dict
        observations {'state': teacher actor obs, 'privileged_state': critic obs}.
      teacher: (Networks, params, normalizer) of the teacher.
      student_obs_size: the student reads ``obs['state'][..., :student_obs_size]``.
    """

    def __init__(self, env, teacher, student_obs_size: int):
        self.env = env
        self.teacher_networks, self.teacher_params, self.teacher_normalizer = teacher
        self.student_obs_size = int(student_obs_size)

    def __getattr__(self, name):
        return getattr(self.env, name)

    @property
    def mirror(self):
        """The mirror maps of the student's rollout (ppo.symmetry, foottof.ppo.symmetry): the
        student's view (the first ``student_obs_size`` of the teacher's inputs), the teacher's
        inputs and its action (a mirrored sequence's label: the mirror of the teacher's action)."""
        from foottof.envs.symmetry import Mirror

        inner = self.env.mirror
        teacher = inner.obs[net.ACTOR_KEY]
        obs = dict(inner.obs)
        obs[net.ACTOR_KEY] = teacher.first(self.student_obs_size)
        obs[TEACHER_OBS_KEY] = teacher
        obs[TEACHER_ACTION_KEY] = inner.action
        return Mirror(obs, inner.action)

    def _wrap(self, state: State, carry, reset: jax.Array) -> State:
        """The inner state seen by the student, with the teacher's action for its observation."""
        obs = state.obs
        carry, action, _, _ = self.teacher_networks.step(
            self.teacher_params, self.teacher_normalizer, carry, obs, reset
        )
        view = dict(obs)
        view[net.ACTOR_KEY] = obs[net.ACTOR_KEY][..., : self.student_obs_size]
        view[TEACHER_OBS_KEY] = obs[net.ACTOR_KEY]
        view[TEACHER_ACTION_KEY] = action
        return state.replace(obs=view, info={**state.info, TEACHER_CARRY_KEY: carry})

    def _inner(self, state: State) -> State:
        obs = {k: v for k, v in state.obs.items() if k not in (TEACHER_OBS_KEY, TEACHER_ACTION_KEY)}
        obs[net.ACTOR_KEY] = state.obs[TEACHER_OBS_KEY]
        info = {k: v for k, v in state.info.items() if k != TEACHER_CARRY_KEY}
        return state.replace(obs=obs, info=info)

    def reset(self, keys: jax.Array) -> State:
        state = self.env.reset(keys)
        n = keys.shape[0]
        return self._wrap(state, self.teacher_networks.init_carry(n), jp.ones((n,), bool))

    def step(self, state: State, actions: jax.Array) -> State:
        carry = state.info[TEACHER_CARRY_KEY]
        nxt = self.env.step(self._inner(state), actions)
        return self._wrap(nxt, carry, nxt.done.astype(bool))  # a new episode: fresh teacher carry


def reconstruction_target(obs: dict, size: int) -> jax.Array:
    """(..., size) the first ``size`` of the teacher's inputs the student does not read: its
    terrain inputs after the student's own (foot patches first, for the ToF env)."""
    start = obs[net.ACTOR_KEY].shape[-1]
    return obs[TEACHER_OBS_KEY][..., start : start + size]


def distill_loss(
    params, networks: net.Networks, normalizer, batch, reconstruction_weight: float = 0.0
) -> tuple[jax.Array, dict]:
    """Mean squared error between the student's action means (re-run over the rollout from its
    stored carry) and the teacher's actions, over (T, B, A); rsl_rl's ``loss_type="mse"``. With
    a belief decoder (network.reconstruct = K > 0) plus ``reconstruction_weight`` x the mean
    squared error of its output against the first K privileged inputs
    (:func:`reconstruction_target`), Miki et al. 2022's student loss.

    Returns:
      (loss, metrics): 'loss/imitation' (the action term), 'loss/reconstruction' (the decoder's
      term, unweighted; with a decoder only), and for the trainer's guards and progress line
      'loss/policy' (= the whole loss), 'loss/value' 0, 'loss/entropy' (of the action std, not
      trained), 'ppo/kl' 0, 'ppo/clip_fraction' 0.
    """
    size = networks.module.reconstruct_size
    args = (params, normalizer, batch.carry, batch.obs, batch.resets)
    if size:  # static
        means, recon = networks.unroll_reconstruction(*args)
    else:
        means = networks.unroll(*args)[0]
    log_std = networks.action_log_std(params)
    target = jax.lax.stop_gradient(batch.obs[TEACHER_ACTION_KEY])
    imitation = jp.mean(jp.square(means - target))
    loss, extra = imitation, {}
    if size:
        heights = jax.lax.stop_gradient(reconstruction_target(batch.obs, size))
        rec = jp.mean(jp.square(recon - heights))
        loss = imitation + reconstruction_weight * rec
        extra = {"loss/reconstruction": rec}
    zero = jp.zeros(())
    return loss, {
        "loss/imitation": imitation,
        **extra,
        "loss/policy": loss,
        "loss/value": zero,
        "loss/entropy": jp.mean(net.gaussian_entropy(log_std)),
        "ppo/kl": zero,
        "ppo/clip_fraction": zero,
    }


def student_from_teacher(student_params, student_normalizer, teacher_params, teacher_normalizer):
    """The student's initial params and normalizer cut from the teacher's (Extreme Parkour
    initialises its student from the teacher's actor): every leaf copied, the actor's input
    leaves (the LSTM input kernels, the 'state' normalizer) cut to the student's first inputs;
    a student's belief decoder (network.reconstruct), which the teacher lacks, kept as given.
    Returns None when the two networks differ otherwise (e.g. an MLP teacher, another size).
    """

    from flax import traverse_util

    def cut(s, t):
        s, t = np.asarray(s), np.asarray(t)
        if s.shape == t.shape:
            return t
        if s.ndim >= 1 and s.shape[1:] == t.shape[1:] and s.shape[0] < t.shape[0]:
            return t[: s.shape[0]]
        raise ValueError(f"shape {t.shape} does not cut to {s.shape}")

    try:
        # a student's belief decoder (network.reconstruct) has no teacher leaves: it keeps its init
        flat_s = traverse_util.flatten_dict(student_params)
        flat_t = traverse_util.flatten_dict(teacher_params)
        own = {k for k in flat_s if k[:2] == ("params", "decoder")}
        if set(flat_s) - own != set(flat_t):
            return None
        params = traverse_util.unflatten_dict(
            {k: (v if k in own else cut(v, flat_t[k])) for k, v in flat_s.items()}
        )
        normalizer = jax.tree.map(cut, student_normalizer, teacher_normalizer)
    except ValueError:
        return None
    return (
        jax.tree.map(lambda s, x: jp.asarray(x, s.dtype), student_params, params),
        jax.tree.map(lambda s, x: jp.asarray(x, s.dtype), student_normalizer, normalizer),
    )
