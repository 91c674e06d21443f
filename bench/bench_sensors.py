"""Foot ToF sensing cost vs MJX physics: time per control step at N envs, and their ratio.

Usage:
  python bench/bench_sensors.py [--envs 256] [--envs 4096 --envs 8192] [--steps 5] [--reps 2]

Terrain: stepping stones and gaps over a pit (8 x 8 m at 4 cm), robots spread over it in the
nominal stance holding random joint targets. Per control step it times (a) physics: 4 MJX
substeps with the JAX PD (foottof.physics.mjx_backend.control_step); (b) ToF sensing:
foottof.sensors.sense for 4 feet x 41 rays from the ``{leg}_tof`` sites, plus the sensor timing
and degradation step; and reports (b) / ((a) + (b)). Compile time is reported apart.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import jax  # noqa: E402
import jax.numpy as jp  # noqa: E402
import numpy as np  # noqa: E402
from mujoco import mjx  # noqa: E402

from configs import _sensor  # noqa: E402
from foottof import constants, sensors  # noqa: E402
from foottof.physics.mjx_backend import control_step  # noqa: E402
from foottof.robot import model  # noqa: E402
from foottof.terrain.heightfield import Heightfield  # noqa: E402


def _terrain(n: int = 201, cell: float = 0.04, seed: int = 0) -> Heightfield:
    """Stepping stones (0.2-0.5 m, tops -0.1..0.1 m) with gaps over a -0.6 m pit, flat centre."""
    rng = np.random.default_rng(seed)
    h = np.full((n, n), -0.6, np.float32)
    for i in range(0, n - 12, 12):
        for j in range(0, n - 12, 12):
            a, b = rng.integers(5, 12, 2)
            h[i : i + a, j : j + b] = rng.uniform(-0.1, 0.1)
    c = n // 2
    h[c - 25 : c + 25, c - 25 : c + 25] = 0.0  # spawn area
    return Heightfield(heights=jp.asarray(h), x0_m=-c * cell, y0_m=-c * cell, cell_m=cell)


def _time(fn, *args, reps: int):
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    t_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in range(reps):
        out = jax.block_until_ready(fn(*args))
    return out, t_first, (time.perf_counter() - t0) / reps


def bench(n: int, args) -> None:
    hf = _terrain()
    m = model.make_model(hf)
    mx = mjx.put_model(m)
    ids = sensors.site_ids(m, constants.TOF_SITES)
    noise_cfg = _sensor.get_noise_section()
    spec = sensors.make_spec(_sensor.get_section())
    tspec = sensors.make_timing_spec(spec, noise_cfg)
    bounds = sensors.bounds_from_config(noise_cfg, 2, tspec)
    noise = sensors.load_model()

    key_xy, key_run, key_tof = jax.random.split(jax.random.PRNGKey(0), 3)
    q0 = jp.asarray(model.default_qpos(), jp.float32)
    xy = jax.random.uniform(key_xy, (n, 2), minval=-0.8, maxval=0.8)
    d0 = jax.vmap(lambda q: mjx.make_data(mx).replace(qpos=q))(
        jp.tile(q0, (n, 1)).at[:, :2].set(xy)
    )
    d0 = jax.jit(jax.vmap(lambda d: mjx.forward(mx, d)))(d0)
    target0 = jp.asarray(constants.DEFAULT_POSE, jp.float32)
    steps = args.steps

    def physics(d, keys):
        def one_env(d, key):
            def body(d, k):
                q = target0 + 0.3 * jax.random.normal(k, (constants.NUM_JOINTS,))
                return control_step(mx, d, q, 80.0, 2.0)[0], None

            return jax.lax.scan(body, d, jax.random.split(key, steps))[0]

        return jax.vmap(one_env)(d, keys)

    def read(d):
        pos, rot = d.site_xpos[ids], d.site_xmat[ids].reshape(-1, 3, 3)
        return sensors.sense(spec, hf, pos, rot)

    def tof(d, st, keys):  # sensing + timing/degradation, repeated `steps` times (same poses)
        def one_env(d, st, key):
            def body(st, k):
                st, obs = sensors.step(tspec, noise, st, read(d), k)
                return st, obs.distance_m.sum()

            return jax.lax.scan(body, st, jax.random.split(key, steps))

        return jax.vmap(one_env)(d, st, keys)

    keys = jax.random.split(key_run, n)
    st0 = jax.jit(jax.vmap(lambda d, k: sensors.reset(tspec, bounds, noise, k, read(d))[0]))(
        d0, jax.random.split(key_tof, n)
    )
    d1, c_phys, t_phys = _time(jax.jit(physics), d0, keys, reps=args.reps)
    _, c_tof, t_tof = _time(jax.jit(tof), d1, st0, keys, reps=args.reps)
    r = jax.jit(jax.vmap(read))(d1)
    frac_valid = float(np.asarray(r.valid).mean())
    per_phys, per_tof = t_phys / steps * 1e3, t_tof / steps * 1e3
    print(
        f"envs={n} device={jax.devices()[0].platform} rays/env={spec.num_sensors * spec.num_rays} "
        f"strips/ray={sensors.num_strips(hf, spec.max_range_m)} | physics {per_phys:.1f} ms/step "
        f"(compile+first {c_phys:.0f} s) | tof {per_tof:.1f} ms/step (compile+first {c_tof:.0f} s) "
        f"| tof share of env step {per_tof / (per_phys + per_tof):.1%} "
        f"| valid zones {frac_valid:.0%}",
        flush=True,
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--envs", type=int, action="append", help="number of envs (repeatable)")
    p.add_argument("--steps", type=int, default=5, help="control steps per jitted call")
    p.add_argument("--reps", type=int, default=2, help="timed calls after the first")
    args = p.parse_args()
    envs = args.envs or ([256] if jax.devices()[0].platform == "cpu" else [256, 4096, 8192])
    for n in envs:
        bench(n, args)


if __name__ == "__main__":
    main()
