"""Benchmark: full env step (physics + sensors + obs + reward + reset) vs its bare physics step.

Usage: python bench/bench_env.py [--envs 64 256 1024] [--steps 20] [--config configs/cpu.py]
       [--physics mjx|mujoco|auto]
Prints env-steps/s of both, their ratio, compile times and peak memory (RSS, and GPU memory
when a GPU is present). On a GPU, run with --envs 4096 8192. Both backends side by side, with
bare MuJoCo C and training iterations: bench/bench_backends.py.
"""

import argparse
import os
import resource
import sys
import time

import jax
import jax.numpy as jp

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from configs import load_config  # noqa: E402
from foottof import constants  # noqa: E402
from foottof.envs import make_env  # noqa: E402


def _timeit(fn, state, steps):
    t0 = time.time()
    state = fn(state)
    jax.block_until_ready(state)
    compile_s = time.time() - t0
    t0 = time.time()
    for _ in range(steps):
        state = fn(state)
    jax.block_until_ready(state)
    return compile_s, (time.time() - t0) / steps


def main():
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--envs", type=int, nargs="+", default=[64, 256, 1024])
    p.add_argument("--steps", type=int, default=20, help="timed control steps per size")
    p.add_argument("--config", default="configs/cpu.py")
    p.add_argument("--physics", default="mjx", help="env.physics: mjx | mujoco | auto")
    args = p.parse_args()
    cfg = load_config(args.config)
    cfg.env.physics = args.physics
    env = make_env(cfg)
    kp, kd = float(cfg.env.control.kp), float(cfg.env.control.kd)
    default_q = jp.asarray(constants.DEFAULT_POSE)
    print(
        f"backend {jax.default_backend()}, physics {env.backend}, map {env.hfield.shape} vertices"
    )
    print(
        f"{'envs':>6} {'env sps':>10} {'physics sps':>12} {'ratio':>6} {'compile env/phys s':>19}"
    )
    for n in args.envs:
        state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), n))
        action = jp.zeros((n, 12))
        env_step = jax.jit(lambda s, a=action: jax.vmap(env.step)(s, a))
        c_env, t_env = _timeit(env_step, state, args.steps)

        def phys(d):
            d, _ = jax.vmap(lambda d: env.physics.step(d, default_q, kp, kd, 1.0, 0.0))(d)
            return d

        c_phys, t_phys = _timeit(jax.jit(phys), state.pipeline_state, args.steps)
        sps_env, sps_phys = n / t_env, n / t_phys
        print(
            f"{n:>6} {sps_env:>10.0f} {sps_phys:>12.0f} {sps_env / sps_phys:>6.2f} "
            f"{c_env:>9.1f}/{c_phys:<8.1f}"
        )
    rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    print(f"peak RSS {rss_gb:.2f} GB")
    for dev in jax.devices():
        stats = getattr(dev, "memory_stats", lambda: None)()
        if stats and "peak_bytes_in_use" in stats:
            print(f"{dev}: peak memory {stats['peak_bytes_in_use'] / 2**30:.2f} GiB")


if __name__ == "__main__":
    main()
