"""Evaluation throughput per foot-reading source: policy + env rollout env-steps/s.

Usage:
  python bench/bench_eval.py [--envs 64 250] [--steps 50] [--sources tof mock_ideal mock_aggre]
                             [--config configs/base.py]

Runs the robustness rollout (foottof.eval.robustness.make_rollout: deterministic LSTM policy,
env with auto-reset, no perturbation) on the evaluation ensemble (80 % stepping stones + 20 %
gaps at 90 % stage-1 difficulty) with a freshly initialized policy of the config's network size,
and prints env-steps/s, compile time, peak memory, and the projected wall time of one 1000-episode
cell (episodes x episode steps / throughput).
"""

import argparse
import os
import resource
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import jax  # noqa: E402

from configs import load_config  # noqa: E402
from foottof.eval import robustness as rb  # noqa: E402
from foottof.eval.harness import make_eval_env_and_policy  # noqa: E402
from foottof.perception import check_source  # noqa: E402


def _gpu_peak_mib() -> str:
    try:
        stats = jax.devices()[0].memory_stats() or {}
    except Exception:  # noqa: BLE001 - CPU backends may not report
        return "n/a"
    peak = stats.get("peak_bytes_in_use")
    return f"{peak / 2**20:,.0f}" if peak else "n/a"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--envs", type=int, nargs="+", default=[64, 250])
    p.add_argument("--steps", type=int, default=50, help="timed control steps per rollout")
    p.add_argument("--sources", nargs="+", default=["tof", "mock_ideal", "mock_aggre"])
    p.add_argument("--config", default="configs/base.py")
    args = p.parse_args()
    for s in args.sources:
        check_source(s, allow_all=False)
    cfg = load_config(args.config)
    key = jax.random.PRNGKey(0)
    print(f"device: {jax.devices()[0].device_kind}  config: {args.config}  steps: {args.steps}")
    print(
        f"{'source':<11}{'envs':>6}{'compile s':>11}{'env-steps/s':>13}{'1000 ep. cell':>15}"
        f"{'RSS MiB':>9}{'GPU MiB':>9}"
    )
    for source in args.sources:
        env, nets, params, norm = make_eval_env_and_policy(cfg, source, None, key, key)
        for n in args.envs:
            rollout = rb.make_rollout(env, nets, n, args.steps)
            t0 = time.perf_counter()
            jax.block_until_ready(rollout(params, norm, key, 0.0))
            compile_s = time.perf_counter() - t0
            t0 = time.perf_counter()
            jax.block_until_ready(rollout(params, norm, jax.random.PRNGKey(1), 0.0))
            sps = n * args.steps / (time.perf_counter() - t0)
            cell_min = 1000 * env.episode_steps / sps / 60
            rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
            print(
                f"{source:<11}{n:>6}{compile_s:>11.1f}{sps:>13,.0f}{cell_min:>12.1f} min"
                f"{rss:>9,.0f}{_gpu_peak_mib():>9}",
                flush=True,
            )


if __name__ == "__main__":
    main()
