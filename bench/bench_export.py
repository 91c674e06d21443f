"""Onboard inference cost of the exported policy, NumPy and ONNX Runtime side by side: time per
50 Hz step, no JAX in the loop.

Usage:
  python bench/bench_export.py [--obs 181] [--calls 2000] [--threads 1]

Exports a freshly initialized actor at the default network size (configs/_ppo.py: LSTM 256,
MLP 512-256-128) for the ANYmal actor observation (181 inputs, 12 actions) as .npz and .onnx and
times, on the same observations in one run, ``NumpyPolicy.__call__`` and an ONNX Runtime
session (CPU provider, --threads intra-op threads) called with explicit LSTM state (normalizer,
LSTM step, MLP head) per call. The 50 Hz control loop leaves 20 ms per step. Set --threads to
pin BLAS / ONNX Runtime threads (the robot's onboard computer shares its cores).
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
    normalizer = networks.init_normalizer(obs)
    xs = np.random.default_rng(0).normal(size=(args.calls, args.obs)).astype(np.float32)
    with tempfile.TemporaryDirectory() as tmp:
        path = export.export_policy(os.path.join(tmp, "policy.npz"), networks, params, normalizer)
        size_kb = os.path.getsize(path) / 1024
        policy = export.NumpyPolicy(path)
        rows = [("NumPy", size_kb, _time(policy, xs))]
        try:
            import onnxruntime as ort

            from foottof.ppo import export_onnx
        except ImportError:
            print("onnxruntime not installed (pip install -e '.[export]'): ONNX row skipped")
        else:
            onnx_path = export_onnx.export_onnx(
                os.path.join(tmp, "policy.onnx"), networks, params, normalizer
            )
            opts = ort.SessionOptions()
            opts.intra_op_num_threads = max(args.threads, 0)
            opts.inter_op_num_threads = 1
            sess = ort.InferenceSession(onnx_path, opts, providers=["CPUExecutionProvider"])
            h = np.zeros((cfg.lstm_num_layers, 1, cfg.lstm_hidden_size), np.float32)
            state = {"h": h, "c": h.copy()}

            def onnx_policy(x):
                a, state["h"], state["c"] = sess.run(
                    None, {"obs": x[None], "h_in": state["h"], "c_in": state["c"]}
                )
                return a

            rows.append(("ONNX Runtime", os.path.getsize(onnx_path) / 1024, _time(onnx_policy, xs)))
    print(
        f"actor: obs {args.obs}, LSTM {cfg.lstm_hidden_size}x{cfg.lstm_num_layers}, "
        f"MLP {tuple(cfg.actor_hidden)}; threads {args.threads or 'default'}; "
        f"{args.calls} calls each (50 Hz budget: 20 ms)"
    )
    print(
        f"{'runtime':14s} {'file KiB':>8s} {'mean ms':>8s} {'median':>8s} {'p99':>8s} {'max':>8s}"
    )
    for name, kb, ms in rows:
        print(
            f"{name:14s} {kb:8.0f} {ms.mean():8.3f} {np.median(ms):8.3f} "
            f"{np.percentile(ms, 99):8.3f} {ms.max():8.3f}"
        )


def _time(policy, xs):
    """Per-call times [ms] of ``policy(x)`` over ``xs`` after 50 warm-up calls."""
    import numpy as np

    for x in xs[:50]:
        policy(x)
    times = np.empty(len(xs))
    for i, x in enumerate(xs):
        t0 = time.perf_counter()
        policy(x)
        times[i] = time.perf_counter() - t0
    return times * 1e3


if __name__ == "__main__":
    main()
