"""MJX physics throughput: control steps/s (4 substeps + JAX PD) of the ANYmal-D model, many envs.

Usage:
  python bench/bench_physics.py [--num_envs 256] [--ground both|hfield|plane] [--nrow 1000]
      [--ncol 3000] [--steps 20] [--set iterations=2 --set cone=elliptic ...]

Each env holds random joint targets (DEFAULT_POSE + 0.3 * N(0, 1), redrawn every control step)
so that the feet move and contacts change. Prints compile time, run time, env control-steps/s and
the process's peak RSS.
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import jax  # noqa: E402
import jax.numpy as jp  # noqa: E402
import numpy as np  # noqa: E402
from mujoco import mjx  # noqa: E402

from foottof import constants  # noqa: E402
from foottof.physics.mjx_backend import control_step  # noqa: E402
from foottof.robot import model  # noqa: E402
from foottof.terrain.heightfield import Heightfield  # noqa: E402


def _parse_value(v: str):
    for cast in (int, float):
        try:
            return cast(v)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(v.lower(), v)


def bench(ground: str, args, tuning: dict) -> None:
    hf = None
    if ground == "hfield":
        # Flat hfield of realistic size, robots spread over its middle.
        hf = Heightfield(
            heights=np.zeros((args.nrow, args.ncol), np.float32),
            x0_m=0.0,
            y0_m=0.0,
            cell_m=args.cell_m,
            z_floor_m=-1.0,
            z_range_m=2.0,
        )
    m = model.make_model(hf, **tuning)
    mx = mjx.put_model(m)
    kp, kd = args.kp, args.kd
    n = args.num_envs

    key = jax.random.PRNGKey(0)
    key_xy, key_run = jax.random.split(key)
    q0 = jp.asarray(model.default_qpos(), jp.float32)
    if hf is not None:  # centre of the field, x, y ~ U(+-1 m) around it
        centre = jp.array([args.ncol * args.cell_m / 2, args.nrow * args.cell_m / 2])
    else:
        centre = jp.zeros(2)
    xy = centre + jax.random.uniform(key_xy, (n, 2), minval=-1.0, maxval=1.0)
    qpos = jp.tile(q0, (n, 1)).at[:, 0:2].set(xy)
    d0 = jax.vmap(lambda q: mjx.make_data(mx).replace(qpos=q))(qpos)
    d0 = jax.jit(jax.vmap(lambda d: mjx.forward(mx, d)))(d0)
    target0 = jp.asarray(constants.DEFAULT_POSE, jp.float32)

    def one_env(d, key):
        def body(d, k):
            q_target = target0 + 0.3 * jax.random.normal(k, (constants.NUM_JOINTS,))
            d, _ = control_step(mx, d, q_target, kp, kd)
            return d, None

        d, _ = jax.lax.scan(body, d, jax.random.split(key, args.steps))
        return d

    run = jax.jit(jax.vmap(one_env), donate_argnums=0)
    keys = jax.random.split(key_run, n)
    t0 = time.perf_counter()
    d = jax.block_until_ready(run(d0, keys))
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(args.reps):
        keys = jax.vmap(lambda k: jax.random.split(k)[0])(keys)
        d = jax.block_until_ready(run(d, keys))
    t_run = (time.perf_counter() - t0) / args.reps
    sps = n * args.steps / t_run
    ok = bool(np.isfinite(np.asarray(d.qpos)).all())
    rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
    size = f"{args.nrow}x{args.ncol}@{args.cell_m}m" if hf is not None else "-"
    print(
        f"{ground:6s} field={size:18s} envs={n} steps={args.steps} "
        f"compile+first={t_first:.1f}s run={t_run:.2f}s control_steps/s={sps:,.0f} "
        f"physics_steps/s={sps * constants.DECIMATION:,.0f} finite={ok} peak_rss={rss_gb:.2f}GB "
        f"device={jax.devices()[0].platform}",
        flush=True,
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--num_envs", type=int, default=256)
    p.add_argument("--steps", type=int, default=20, help="control steps per jitted call")
    p.add_argument("--reps", type=int, default=2, help="timed calls after the first")
    p.add_argument("--ground", choices=("both", "hfield", "plane"), default="both")
    p.add_argument("--nrow", type=int, default=1000, help="hfield rows (along y)")
    p.add_argument("--ncol", type=int, default=3000, help="hfield columns (along x)")
    p.add_argument("--cell_m", type=float, default=0.04, help="hfield vertex spacing [m]")
    p.add_argument("--kp", type=float, default=80.0, help="PD stiffness [N m/rad]")
    p.add_argument("--kd", type=float, default=2.0, help="PD damping [N m s/rad]")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"make_model tuning override, keys: {sorted(model.DEFAULT_TUNING)}",
    )
    args = p.parse_args()
    tuning = {}
    for kv in args.set:
        k, _, v = kv.partition("=")
        tuning[k] = _parse_value(v)
    print(f"tuning: {model._validate_tuning(tuning)}", flush=True)
    grounds = ("hfield", "plane") if args.ground == "both" else (args.ground,)
    for g in grounds:
        bench(g, args, tuning)


if __name__ == "__main__":
    main()
