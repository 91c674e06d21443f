"""ToF ray cast: the adaptive strip walk's rounds side by side, on rays a trained policy produces.

Usage:
  python bench/bench_raycast.py [--checkpoint policies/stage1] [--config configs/stage1_cpu.py]
      [--difficulty 0.25] [--envs 64] [--steps 200] [--rounds "((6, 1.0), (None, 0.2))" ...]

1. Records the world ToF rays (4 feet x 41 rays) of the policy (sampled actions, as in training)
   on the evaluation ensemble at ``--difficulty``, every 4th control step of ``--envs`` envs.
2. Prints how many rays are still unfinished (no hit yet, more strips within range) after k
   strips: what the rounds (``foottof.sensors.raycast.ROUNDS``) are sized from.
3. Times ``ray_heightfield_normal`` vmapped over 256 envs x 164 rays (a stage-1 training step's
   rays) for: every ray walking every strip, the shipped ROUNDS and each ``--rounds``; checks
   that all give bit-identical distances and normals. Three timed passes over all batches each,
   alternating, so a busy machine slows all alike; read the ratios.
"""

from __future__ import annotations

import argparse
import ast
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import jax  # noqa: E402
import jax.numpy as jp  # noqa: E402
import numpy as np  # noqa: E402

from configs import load_config  # noqa: E402
from foottof.eval import harness  # noqa: E402
from foottof.robot import kinematics  # noqa: E402
from foottof.sensors import raycast, tof  # noqa: E402

BATCH_ENVS = 256  # envs per timed call (configs/stage1_cpu.py)


def record_rays(setup, num_envs: int, steps: int, key):
    """(R, 3) origins and (R, 3) directions of the ToF rays along a rollout (every 4th step)."""
    env, nets = setup.env, setup.networks
    sensing = env.sensing
    spec = sensing.spec
    feet = np.asarray(sensing.feet, np.int32)

    def rays(d):
        fk = kinematics.world_foot_kinematics(d.qpos, sensing.shank_scale)
        pos, dirs = tof.sensor_rays(spec, fk.tof_pos[feet], fk.tof_rot[feet])
        return jp.broadcast_to(pos[:, None, :], dirs.shape).reshape(-1, 3), dirs.reshape(-1, 3)

    reset, step = jax.vmap(env.reset), jax.vmap(env.step)

    @jax.jit
    def run(key):
        act = nets.policy_fn(setup.params, setup.normalizer, deterministic=False)
        key_reset, key_run = jax.random.split(key)
        state = reset(jax.random.split(key_reset, num_envs))
        carry, first = nets.init_carry(num_envs), jp.ones((num_envs,), bool)

        def body(c, k):
            state, carry, reset_flags = c
            carry, action = act(carry, state.obs, reset_flags, k)
            state = step(state, action)
            return (state, carry, state.done > 0.5), jax.vmap(rays)(state.pipeline_state)

        _, out = jax.lax.scan(body, (state, carry, first), jax.random.split(key_run, steps))
        return out

    o, d = run(key)
    return np.asarray(o[::4]).reshape(-1, 3), np.asarray(d[::4]).reshape(-1, 3)


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--checkpoint", default="policies/stage1")
    p.add_argument("--config", default="configs/stage1_cpu.py")
    p.add_argument("--difficulty", type=float, default=0.25, help="eval.difficulty_fraction")
    p.add_argument("--envs", type=int, default=64, help="envs of the recording rollout")
    p.add_argument("--steps", type=int, default=200, help="control steps of the recording")
    p.add_argument("--rounds", nargs="*", default=["((6, 1.0), (None, 0.2))"])
    args = p.parse_args()
    cfg = load_config(args.config)
    cfg.eval.difficulty_fraction = args.difficulty
    keys = jax.random.split(jax.random.PRNGKey(0), 3)
    setup = harness.make_eval_env_and_policy(cfg, "tof", args.checkpoint, keys[0], keys[1])
    hf, max_range = setup.env.hfield, setup.env.sensing.spec.max_range_m
    o, d = record_rays(setup, args.envs, args.steps, keys[2])
    n_strips = raycast.num_strips(hf, max_range)
    print(f"{len(o):,} rays of {args.checkpoint} at difficulty {args.difficulty}; "
          f"a {max_range} m ray crosses up to {n_strips} strips")  # fmt: skip

    # Unfinished after k strips (the walk's own `more` flag).
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    meta = hf.replace(heights=np.zeros(hf.heights.shape, np.float32))
    h = hf.clipped().heights.astype(jp.float32).reshape(-1)
    fracs = []
    for k in (1, 2, 3, 4, 6, 8, 10, 12, 14, 16, 20):
        walk = jax.jit(jax.vmap(lambda a, b, k=k: raycast._walk(h, meta, a, b, max_range, 0, k)))
        fracs.append(f"{k}: {float(jp.mean(walk(jp.asarray(o), jp.asarray(u))[2])):.3f}")
    print("unfinished after k strips: " + ", ".join(fracs), flush=True)

    # Timed casts: full walk, shipped rounds, --rounds.
    per = o.shape[0] // (args.envs * len(range(0, args.steps, 4)))  # rays per env
    b = BATCH_ENVS * per
    batches = [
        (jp.asarray(o[i : i + b].reshape(BATCH_ENVS, per, 3)),
         jp.asarray(d[i : i + b].reshape(BATCH_ENVS, per, 3)))
        for i in range(0, len(o) - b + 1, b)
    ]  # fmt: skip
    shipped = raycast.ROUNDS
    variants = {"full walk": None, f"shipped {shipped}": shipped}
    variants.update({f"--rounds {r}": ast.literal_eval(r) for r in args.rounds})
    fns = {}
    for name, rounds in variants.items():
        if rounds is None:
            cast = lambda o, d: raycast._cast(hf, o, d, max_range, True, adaptive=False)  # noqa: E731
        else:
            raycast.ROUNDS = rounds  # read when traced
            cast = lambda o, d: raycast.ray_heightfield_normal(hf, o, d, max_range)  # noqa: E731
        fns[name] = jax.jit(jax.vmap(cast))
        jax.block_until_ready(fns[name](*batches[0]))
    raycast.ROUNDS = shipped
    ref = [fns["full walk"](*x) for x in batches]
    times = {k: [] for k in fns}
    for _ in range(3):
        for name, f in fns.items():
            t0 = time.perf_counter()
            for x in batches:
                jax.block_until_ready(f(*x))
            times[name].append((time.perf_counter() - t0) / len(batches) * 1e3)
    base = min(times[f"shipped {shipped}"])
    print(f"ms per call ({BATCH_ENVS} envs x {per} rays, {len(batches)} batches), 3 passes:")
    for name, f in fns.items():
        same = all(
            np.array_equal(np.asarray(a[0]), np.asarray(r[0]))
            and np.array_equal(np.asarray(a[1]), np.asarray(r[1]))
            for a, r in zip((f(*x) for x in batches), ref, strict=True)
        )
        ms = " / ".join(f"{t:.0f}" for t in times[name])
        print(f"  {name:60s} {ms:>16}  x{min(times[name]) / base:.2f} of shipped"
              f"  identical to full walk: {same}")  # fmt: skip


if __name__ == "__main__":
    main()
