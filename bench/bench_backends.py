"""Physics backends side by side: bare MuJoCo C, the env on MuJoCo C, the env on MJX; training.

Usage: python bench/bench_backends.py [--envs 64 256 1024] [--steps 20] [--config configs/cpu.py]
       [--threads 0] [--train_envs 256] [--train_iterations 3] [--skip_mjx_at 4096]

Env-steps/s of, per number of envs (zero actions, robots standing at the env's spawns):
  bare C    mujoco.batch.Batch of the env's model, same threads, (NumPy PD, step) x 4 from Python;
  C phys    the C backend alone (foottof.physics, pure_callback in a jitted vmap);
  env C     the full env step (physics + sensing + obs + reward + auto-reset) on MuJoCo C;
  env MJX   the same on MJX;
and the ratios env C / bare C and env C / env MJX. Then one training iteration (rollout + PPO
update, configs/cpu.py's network) per backend at --train_envs envs. Compile times apart.
"""

import argparse
import os
import sys
import time

import jax
import jax.numpy as jp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from configs import load_config  # noqa: E402
from foottof import constants  # noqa: E402
from foottof.envs import make_env, make_training_env  # noqa: E402
from foottof.robot import pd_torque  # noqa: E402


def time_steps(fn, state, steps):
    """(last state, seconds per call) of ``steps`` chained calls ``state = fn(state)`` of a
    compiled, warm ``fn``. Also bench/gpu_check.py's env-step timing."""
    t0 = time.perf_counter()
    for _ in range(steps):
        state = fn(state)
    jax.block_until_ready(state)
    return state, (time.perf_counter() - t0) / steps


def time_iterations(iteration, state, iterations):
    """(last state, seconds per iteration) of a compiled training iteration (``Train.iteration``):
    one warm-up call, then ``iterations`` timed ones. Also bench/gpu_check.py's."""
    state, metrics = iteration(state)
    jax.block_until_ready(metrics)
    t0 = time.perf_counter()
    for _ in range(iterations):
        state, metrics = iteration(state)
    jax.block_until_ready((state, metrics))
    return state, (time.perf_counter() - t0) / iterations


def _timeit(fn, state, steps):
    t0 = time.perf_counter()
    state = jax.block_until_ready(fn(state))
    compile_s = time.perf_counter() - t0
    return compile_s, time_steps(fn, state, steps)[1]


def _bare_c(env, qpos, steps):
    """Seconds per control step of the bare batch: NumPy PD + Batch.step, no JAX."""
    phys = env.physics
    n = qpos.shape[0]
    b = phys.batch(n)
    b.bind("qpos")[:] = qpos
    b.bind("qvel")[:] = 0.0
    b.bind("qacc_warmstart")[:] = 0.0
    q, qd, ctrl = b.bind("qpos"), b.bind("qvel"), b.bind("ctrl")
    target = np.asarray(constants.DEFAULT_POSE, np.float64)
    kp, kd = float(env.cfg.env.control.kp), float(env.cfg.env.control.kd)

    def control_step():
        for _ in range(phys.num_substeps):
            ctrl[:] = pd_torque(target, q[:, 7:19], qd[:, 6:18], kp, kd, **phys.control_kw)
            b.step()

    control_step()
    t0 = time.perf_counter()
    for _ in range(steps):
        control_step()
    return (time.perf_counter() - t0) / steps


def _env_step_time(env, n, steps):
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), n))
    action = jp.zeros((n, 12))
    env_step = jax.jit(lambda s: jax.vmap(env.step)(s, action))
    c, t = _timeit(env_step, state, steps)
    return state, c, t


def _physics_step_time(env, state, steps):
    p = env.physics
    n = state.pipeline_state.qpos.shape[0]
    target = jp.broadcast_to(jp.asarray(constants.DEFAULT_POSE, jp.float32), (n, 12))
    kp, kd = float(env.cfg.env.control.kp), float(env.cfg.env.control.kd)
    step = jax.vmap(p.step, in_axes=(0, 0, None, None, None, None))
    return _timeit(
        jax.jit(lambda d: step(d, target, kp, kd, 1.0, 0.0)[0]), state.pipeline_state, steps
    )


def _train_iteration(cfg, physics_name, num_envs, iterations, one_epoch=False):
    """(compile s, env-steps/s) of one training iteration; ``one_epoch``: 1 epoch of the same
    minibatches instead of the config's ``ppo.num_epochs`` (the difference is the other epochs)."""
    from foottof.ppo import train as train_lib

    cfg = cfg.copy_and_resolve_references()
    cfg.env.physics = physics_name
    cfg.ppo.num_envs = num_envs
    if one_epoch:
        cfg.ppo.num_epochs = 1
    env = make_training_env(cfg)
    trainer = train_lib.make_train(env, cfg)
    state = jax.block_until_ready(trainer.init(jax.random.PRNGKey(0)))
    t0 = time.perf_counter()
    iteration = trainer.iteration.lower(state).compile()
    compile_s = time.perf_counter() - t0
    _, run_s = time_iterations(iteration, state, iterations)
    return compile_s, trainer.steps_per_iteration / run_s


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--envs", type=int, nargs="+", default=[64, 256, 1024])
    p.add_argument("--steps", type=int, default=20, help="timed control steps per size")
    p.add_argument("--config", default="configs/cpu.py")
    p.add_argument("--threads", type=int, default=0, help="MuJoCo C threads (0: all CPUs)")
    p.add_argument("--train_envs", type=int, default=256, help="0: skip the training bench")
    p.add_argument("--train_iterations", type=int, default=3, help="timed iterations")
    p.add_argument("--skip_mjx_at", type=int, default=4096, help="no MJX env at >= this many")
    p.add_argument("--train_backends", nargs="+", default=["mujoco", "mjx"])
    args = p.parse_args()
    cfg = load_config(args.config)
    cfg.env.physics_threads = args.threads
    envs = {}
    for name in ("mujoco", "mjx"):
        c = cfg.copy_and_resolve_references()
        c.env.physics = name
        envs[name] = make_env(c)
    nthread = envs["mujoco"].physics.nthread
    print(
        f"JAX backend {jax.default_backend()}, {os.cpu_count()} CPUs, MuJoCo threads {nthread}, "
        f"map {envs['mujoco'].hfield.shape} vertices, {args.steps} timed steps, zero actions"
    )
    head = (
        f"{'envs':>6} {'bare C':>8} {'C phys':>8} {'env C':>8} {'env MJX':>8} "
        f"{'envC/bare':>9} {'envC/MJX':>8}  compile s (C phys / env C / env MJX)"
    )
    print(head, flush=True)
    bare_s = {}  # envs -> seconds per control step of bare C
    for n in args.envs:
        state_c, c_envc, t_envc = _env_step_time(envs["mujoco"], n, args.steps)
        c_phys, t_phys = _physics_step_time(envs["mujoco"], state_c, args.steps)
        t_bare = _bare_c(
            envs["mujoco"], np.asarray(state_c.pipeline_state.qpos, np.float64), args.steps
        )
        bare_s[n] = t_bare
        if n < args.skip_mjx_at:
            _, c_envx, t_envx = _env_step_time(envs["mjx"], n, max(args.steps // 4, 2))
        else:
            c_envx, t_envx = float("nan"), float("nan")
        sps = {
            k: n / t
            for k, t in (("bare", t_bare), ("phys", t_phys), ("envc", t_envc), ("envx", t_envx))
        }
        print(
            f"{n:>6} {sps['bare']:>8.0f} {sps['phys']:>8.0f} {sps['envc']:>8.0f} "
            f"{sps['envx']:>8.0f} {sps['envc'] / sps['bare']:>9.2f} "
            f"{sps['envc'] / sps['envx']:>8.1f}  {c_phys:.1f} / {c_envc:.1f} / {c_envx:.1f}",
            flush=True,
        )
    if args.train_envs:
        print(
            f"training iteration (rollout + PPO update), {args.config} network, "
            f"{args.train_envs} envs x {cfg.ppo.num_steps} steps:"
        )
        full = {}
        for name in args.train_backends:
            c, sps = _train_iteration(cfg, name, args.train_envs, args.train_iterations)
            full[name] = sps
            print(f"  {name:>6}: {sps:>8,.0f} env-steps/s (compile {c:.1f} s)", flush=True)
        if "mujoco" in full and cfg.ppo.num_epochs > 1:
            # The update's share, and the most any env could give: bare C physics + the update.
            steps = args.train_envs * cfg.ppo.num_steps
            _, sps1 = _train_iteration(
                cfg, "mujoco", args.train_envs, args.train_iterations, one_epoch=True
            )
            e, m = cfg.ppo.num_epochs, cfg.ppo.num_minibatches
            update_s = (steps / full["mujoco"] - steps / sps1) * e / (e - 1)
            print(
                f"  mujoco, 1 epoch: {sps1:,.0f} env-steps/s -> the update ({e} epochs x {m} "
                f"minibatches) takes ~{update_s:.2f} s of the {steps / full['mujoco']:.2f} s "
                f"iteration"
            )
            if args.train_envs in bare_s:
                physics_s = bare_s[args.train_envs] * cfg.ppo.num_steps
                print(
                    f"  bound: bare C physics of the rollout {physics_s:.2f} s + the update "
                    f"{update_s:.2f} s -> at most {steps / (physics_s + update_s):,.0f} "
                    f"env-steps/s with everything else free",
                    flush=True,
                )


if __name__ == "__main__":
    main()
