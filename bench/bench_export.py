"""Onboard inference cost of the exported NumPy policy: time per 50 Hz step, no JAX in the loop.

Usage:
  python bench/bench_export.py [--obs 181] [--calls 2000] [--threads 1]

Exports a freshly initialized actor at the default network size (configs/_ppo.py: LSTM 256,
MLP 512-256-128) for the ANYmal actor observation (181 inputs, 12 actions) and times
``NumpyPolicy.__call__`` (normalizer, LSTM step, MLP head) per call. The 50 Hz control loop
leaves 20 ms per step. Set --threads to pin BLAS threads (the robot's onboard computer shares
its cores with other processes).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--obs", type=int, default=181, help="actor observation size")
    ap.add_argument("--calls", type=int, default=2000, help="timed policy calls")
    ap.add_argument("--threads", type=int, default=1, help="BLAS threads (0 = library default)")
    args = ap.parse_args()
    if args.threads > 0:
        for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[var] = str(args.threads)

    import jax
    import jax.numpy as jp
    import numpy as np

    from configs import _ppo
    from foottof import constants
    from foottof.ppo import export
    from foottof.ppo import networks as net

    cfg = _ppo.get_network_section()
    networks = net.make_networks(constants.NUM_JOINTS, cfg)
    obs = jp.zeros((1, args.obs))
    params = jax.jit(networks.init_params)(jax.random.PRNGKey(0), obs)
    with tempfile.TemporaryDirectory() as tmp:
        path = export.export_policy(
            os.path.join(tmp, "policy.npz"), networks, params, networks.init_normalizer(obs)
        )
        size_kb = os.path.getsize(path) / 1024
        policy = export.NumpyPolicy(path)
    xs = np.random.default_rng(0).normal(size=(args.calls, args.obs)).astype(np.float32)
    for x in xs[:50]:  # warm-up
        policy(x)
    times = np.empty(args.calls)
    for i, x in enumerate(xs):
        t0 = time.perf_counter()
        policy(x)
        times[i] = time.perf_counter() - t0
    ms = times * 1e3
    print(
        f"NumPy policy: obs {args.obs}, LSTM {cfg.lstm_hidden_size}x{cfg.lstm_num_layers}, "
        f"MLP {tuple(cfg.actor_hidden)}, file {size_kb:.0f} KiB, BLAS threads "
        f"{args.threads or 'default'}"
    )
    print(
        f"per call [ms]: mean {ms.mean():.3f}  median {np.median(ms):.3f}  "
        f"p99 {np.percentile(ms, 99):.3f}  max {ms.max():.3f}   (50 Hz budget: 20 ms)"
    )
    print(f"calls/s: {1.0 / times.mean():,.0f}")


if __name__ == "__main__":
    main()
