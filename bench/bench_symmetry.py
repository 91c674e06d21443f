"""Training throughput with ppo.symmetry off and on, in one run (bench/NOTES.md).

    python bench/bench_symmetry.py                                   # configs/teacher_cpu.py
    python bench/bench_symmetry.py --config configs/stage1_cpu.py --num-envs 128 --iterations 4

Builds the ToF env of ``--config`` once and two trainers on it (the flag off and on, the rest of
the config as it is, at ``--num-envs``), compiles both, then times their iterations alternately
(off, on, off, on, ...) so that a load shared with other processes weighs on both alike. Prints
env-steps/s (rollout + update) of each and their ratio. With the flag on each step also runs the
policy on the mirrored observation (its carry only), and each minibatch holds twice the
sequences.
"""

import argparse
import importlib.util
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import jax  # noqa: E402

from foottof.envs import make_training_env  # noqa: E402
from foottof.ppo import train as train_lib  # noqa: E402


def _config(path: str):
    spec = importlib.util.spec_from_file_location("bench_config", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.get_config()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/teacher_cpu.py")
    p.add_argument("--num-envs", type=int, default=64)
    p.add_argument("--iterations", type=int, default=3, help="timed iterations per arm")
    args = p.parse_args()

    cfg = _config(args.config)
    cfg.ppo.num_envs = args.num_envs
    env = make_training_env(cfg)
    arms = {}
    for flag in (False, True):
        c = cfg.copy_and_resolve_references()
        c.ppo.symmetry = flag
        trainer = train_lib.make_train(env, c)
        t0 = time.perf_counter()
        state = trainer.init(jax.random.PRNGKey(0))
        iteration = trainer.iteration.lower(state).compile()
        state, metrics = iteration(state)  # warm-up
        jax.block_until_ready(metrics)
        print(f"symmetry={flag}: init + compile + 1 iteration {time.perf_counter() - t0:.1f} s")
        arms[flag] = [iteration, state, 0.0, trainer.steps_per_iteration]
    for _ in range(args.iterations):
        for arm in arms.values():
            t0 = time.perf_counter()
            arm[1], metrics = arm[0](arm[1])
            jax.block_until_ready((arm[1], metrics))
            arm[2] += time.perf_counter() - t0
    sps = {flag: args.iterations * a[3] / a[2] for flag, a in arms.items()}
    print(
        f"config={args.config} num_envs={args.num_envs} num_steps={cfg.ppo.num_steps} "
        f"epochs={cfg.ppo.num_epochs} minibatches={cfg.ppo.num_minibatches} "
        f"backend={jax.default_backend()} iterations={args.iterations} per arm, alternated"
    )
    for flag, v in sps.items():
        print(
            f"symmetry={flag}: {v:,.0f} env-steps/s ({arms[flag][2] / args.iterations:.2f} s/iteration)"
        )
    print(f"on / off: {sps[True] / sps[False]:.2f}")


if __name__ == "__main__":
    main()
