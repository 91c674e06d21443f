"""Tiny JAX envs for trainer tests and benchmarks: a cue-recall memory task."""

import jax
import jax.numpy as jp
from brax.envs.base import State

from foottof.envs.wrappers import VmapEnv


class CueMemoryEnv:
    """Single-env memory task with its own auto-reset.

    At step 0 the observation shows a cue c ~ U{-1, +1} and a first-step flag; at every later step
    both read 0. The action a (1,) is rewarded at steps 1..L-1 with r = -|clip(a, -2, 2) - c|;
    step 0 pays 0. A memoryless policy sees identical observations at steps >= 1 whatever the
    cue, so its expected reward per step there is <= -(|a - 1| + |a + 1|) / 2 <= -1; recalling
    the cue earns 0.
    The episode terminates (done=1, truncation=0) after L steps; metrics:
    'episode/success' (1 if every rewarded action had the cue's sign; read at done steps) and
    'reward/recall' (the step reward).

    Args:
      episode_length: L >= 2 steps per episode.
      privileged: if True, obs is {'state': (2,), 'privileged_state': (3,) = state + cue} (the
        critic sees the cue, the actor does not); else a (2,) array.
      teacher: if True, obs is {'state': (3,), 'privileged_state': (3,)}, both state + cue: a
        teacher's actor sees the cue at every step (a memoryless policy solves it), and a student
        reading the first 2 inputs must remember it (foottof.ppo.distill).
    """

    action_size = 1

    def __init__(self, episode_length: int = 8, privileged: bool = False, teacher: bool = False):
        if episode_length < 2:
            raise ValueError(f"episode_length={episode_length}; must be >= 2")
        self.episode_length = int(episode_length)
        self.privileged = bool(privileged)
        self.teacher = bool(teacher)

    @property
    def mirror(self):
        """The task's mirror (ppo.symmetry): the cue and the action change sign (c -> -c,
        a -> -a pays the same reward), the first-step flag stays."""
        from foottof.envs.symmetry import Mirror, SignedPerm

        state = SignedPerm([0, 1], [-1.0, 1.0])
        full = SignedPerm([0, 1, 2], [-1.0, 1.0, -1.0])  # state + cue
        action = SignedPerm([0], [-1.0])
        if self.teacher:
            return Mirror({"state": full, "privileged_state": full}, action)
        if self.privileged:
            return Mirror({"state": state, "privileged_state": full}, action)
        return Mirror(state, action)

    @property
    def observation_size(self):
        if self.teacher:
            return {"state": (3,), "privileged_state": (3,)}
        if self.privileged:
            return {"state": (2,), "privileged_state": (3,)}
        return 2

    def _obs(self, cue, t):
        first = (t == 0).astype(jp.float32)
        state = jp.stack([cue * first, first])  # cue (shown at t=0 only), first-step flag
        if self.teacher:
            full = jp.concatenate([state, cue[None]])
            return {"state": full, "privileged_state": full}
        if self.privileged:
            return {"state": state, "privileged_state": jp.concatenate([state, cue[None]])}
        return state

    def reset(self, key: jax.Array) -> State:
        key, key_cue = jax.random.split(key)
        cue = jp.where(jax.random.bernoulli(key_cue), 1.0, -1.0)  # c ~ U{-1, +1}
        t = jp.zeros((), jp.int32)
        zero = jp.zeros(())
        info = {"key": key, "cue": cue, "t": t, "correct": zero, "truncation": zero}
        metrics = {"episode/success": zero, "reward/recall": zero}
        return State(None, self._obs(cue, t), zero, zero, metrics, info)

    def step(self, state: State, action: jax.Array) -> State:
        info = state.info
        cue, t = info["cue"], info["t"]
        a = jp.clip(action[0], -2.0, 2.0)
        rewarded = t >= 1
        reward = jp.where(rewarded, -jp.abs(a - cue), 0.0)
        correct = info["correct"] + (rewarded & (jp.sign(a) == cue)).astype(jp.float32)
        t = t + 1
        done = t >= self.episode_length
        success = (correct == self.episode_length - 1).astype(jp.float32)
        # Auto-reset: a new cue for the next episode, drawn from the state's own key.
        key, key_cue = jax.random.split(info["key"])
        new_cue = jp.where(jax.random.bernoulli(key_cue), 1.0, -1.0)  # c ~ U{-1, +1}
        cue = jp.where(done, new_cue, cue)
        t = jp.where(done, 0, t)
        correct = jp.where(done, 0.0, correct)
        info = {
            "key": key, "cue": cue, "t": t, "correct": correct,
            "truncation": jp.zeros(()),
        }  # fmt: skip
        metrics = {"episode/success": jp.where(done, success, 0.0), "reward/recall": reward}
        return state.replace(
            obs=self._obs(cue, t),
            reward=reward,
            done=done.astype(jp.float32),
            metrics=metrics,
            info=info,
        )


def make_memory_env(
    episode_length: int = 8, privileged: bool = False, teacher: bool = False
) -> VmapEnv:
    """Batched CueMemoryEnv (reset(keys (N, 2)), step(state, actions (N, 1)))."""
    return VmapEnv(CueMemoryEnv(episode_length, privileged, teacher))
