"""Full training throughput (env steps/s including the PPO update) for an env factory.

    python bench/bench_train.py                       # the cue-memory toy env
    python bench/bench_train.py --env mypkg.mod:make_env --num-envs 4096 --hidden 256

`--env module:function` names a factory `() -> batched env` (see foottof.ppo.train); the lead plugs
the locomotion env in here. Prints compile time apart from the timed iterations.
"""

import argparse
import importlib
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import jax  # noqa: E402
import ml_collections  # noqa: E402

from configs import _ppo  # noqa: E402
from foottof.ppo import train as train_lib  # noqa: E402


def _factory(spec: str):
    if spec == "memory":
        sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
        import toy_envs  # the tests' cue-recall memory env

        return toy_envs.make_memory_env
    module, _, name = spec.partition(":")
    if not name:
        raise ValueError(f"--env={spec!r}; expected 'memory' or 'module:function'")
    return getattr(importlib.import_module(module), name)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--env", default="memory", help="'memory' or module:function")
    p.add_argument("--num-envs", type=int, default=256)
    p.add_argument("--num-steps", type=int, default=24)
    p.add_argument("--num-minibatches", type=int, default=4)
    p.add_argument("--num-epochs", type=int, default=5)
    p.add_argument("--policy", default="lstm", choices=("lstm", "mlp"))
    p.add_argument("--hidden", type=int, default=256, help="LSTM units")
    p.add_argument("--iterations", type=int, default=10, help="timed iterations")
    args = p.parse_args()

    cfg = ml_collections.ConfigDict()
    cfg.ppo = _ppo.get_section()
    cfg.network = _ppo.get_network_section()
    cfg.ppo.num_envs = args.num_envs
    cfg.ppo.num_steps = args.num_steps
    cfg.ppo.num_minibatches = args.num_minibatches
    cfg.ppo.num_epochs = args.num_epochs
    cfg.network.policy = args.policy
    cfg.network.lstm_hidden_size = args.hidden

    env = _factory(args.env)()
    trainer = train_lib.make_train(env, cfg)
    t0 = time.perf_counter()
    state = jax.block_until_ready(trainer.init(jax.random.PRNGKey(0)))
    init_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    iteration = trainer.iteration.lower(state).compile()
    compile_s = time.perf_counter() - t0
    state, metrics = iteration(state)  # warm-up
    jax.block_until_ready(metrics)
    t0 = time.perf_counter()
    for _ in range(args.iterations):
        state, metrics = iteration(state)
    jax.block_until_ready((state, metrics))
    run_s = time.perf_counter() - t0
    steps = args.iterations * trainer.steps_per_iteration
    print(
        f"backend={jax.default_backend()} devices={jax.device_count()} env={args.env} "
        f"policy={args.policy} hidden={args.hidden} num_envs={args.num_envs} "
        f"num_steps={args.num_steps} epochs={args.num_epochs} minibatches={args.num_minibatches}"
    )
    print(f"init {init_s:.2f} s, compile {compile_s:.2f} s")
    print(
        f"{args.iterations} iterations in {run_s:.3f} s: {steps / run_s:,.0f} env-steps/s "
        f"({run_s / args.iterations * 1e3:.1f} ms/iteration, rollout + update)"
    )


if __name__ == "__main__":
    main()
