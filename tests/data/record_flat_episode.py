"""Records the test fixture flat_episode.npz: 500 control steps of the shipped flat policy
(policies/flat, mean actions) on flat ground, 4 s episodes so the recording holds two resets.

    python tests/data/record_flat_episode.py   # from the repo root, ~1 min on 2 cores

Saved: ``obs`` (500, 181) float32, the actor observations the policy was given, and ``first``
(500,) bool, True where an episode starts (the LSTM state is zero there). The export tests run
the JAX policy, NumpyPolicy and ONNX Runtime on these and compare their actions.
"""

import os
import sys

import jax
import jax.numpy as jp
import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)

from configs import flat  # noqa: E402
from foottof.eval.harness import make_eval_env_and_policy  # noqa: E402
from foottof.ppo.storage.run_dir import with_run_network  # noqa: E402

STEPS = 500


def main() -> None:
    checkpoint = os.path.join(ROOT, "policies", "flat")
    cfg = with_run_network(flat.get_config(), checkpoint)
    cfg.env.episode_length_s = 4.0  # 200 steps: resets at steps 200 and 400
    key = jax.random.PRNGKey(11)
    env, nets, params, norm = make_eval_env_and_policy(cfg, "tof", checkpoint, key, key)
    state = jax.jit(jax.vmap(env.reset))(key[None])
    act = nets.policy_fn(params, norm, deterministic=True)
    step = jax.vmap(env.step)

    @jax.jit
    def run(state):
        def body(carry, k):
            state, lstm, first = carry
            lstm, action = act(lstm, state.obs, first, k)
            nxt = step(state, action)
            return (nxt, lstm, nxt.done > 0.5), (state.obs["state"][0], first[0])

        init = (state, nets.init_carry(1), jp.ones((1,), bool))
        return jax.lax.scan(body, init, jax.random.split(key, STEPS))[1]

    obs, first = jax.device_get(run(state))
    assert first.sum() == 3, first.sum()  # the start and two resets
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "flat_episode.npz")
    np.savez_compressed(out, obs=np.asarray(obs, np.float32), first=np.asarray(first, bool))
    print(f"wrote {out}: {STEPS} steps, episode starts at {np.flatnonzero(first).tolist()}")


if __name__ == "__main__":
    main()
