"""How much of the true foot-local terrain a belief student's memory holds: the R^2 of its
decoder (network.reconstruct) against the teacher's foot patches, on the student's own rollouts.

    python scripts/belief_r2.py policies/student [--envs 256] [--steps 150]   # ~3 min

The student acts with its mean actions in its distillation env (configs/distill_cpu.py,
the run's teacher), from fresh episodes at the curriculum's starting levels; the first 20 steps
are left out. Prints the overall R^2 (1 - MSE / variance of the target, per input, averaged), the
MSE over patch points more than 10 cm below the foot centre (gaps, lower surfaces) and the rest,
then R^2 per patch position (the 3 x 3 grid of observations.FOOT_PATCH_OFFSETS_M) and per foot.
"""

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import jax  # noqa: E402
import jax.numpy as jp  # noqa: E402
import numpy as np  # noqa: E402

from configs import distill_cpu  # noqa: E402
from foottof.constants import FEET  # noqa: E402
from foottof.envs.observations import FOOT_PATCH_OFFSETS_M  # noqa: E402
from foottof.ppo import distill, teacher  # noqa: E402
from foottof.ppo import networks as net  # noqa: E402
from foottof.ppo.storage import checkpoint as ckpt  # noqa: E402

WARMUP = 20  # steps left out at the start (the memory is empty)


def r2(pred: np.ndarray, target: np.ndarray) -> float:
    return float(1.0 - ((pred - target) ** 2).mean() / target.var(axis=0).mean())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", help="a belief student's run or policy folder")
    ap.add_argument("--envs", type=int, default=256)
    ap.add_argument("--steps", type=int, default=150)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    if a.steps <= WARMUP:
        raise SystemExit(f"--steps={a.steps} must be > {WARMUP} (the warm-up left out)")
    cfg = distill_cpu.get_config()
    with cfg.unlocked():
        cfg.ppo.num_envs = a.envs
        cfg.network.reconstruct = 36
    env, _ = teacher.make_distill_env(cfg)
    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(a.seed), a.envs))
    nets = net.make_networks(env.action_size, cfg.network)
    params = jax.jit(nets.init_params)(jax.random.PRNGKey(0), state.obs)
    norm = jax.jit(nets.init_normalizer)(state.obs)
    params, norm = ckpt.load_params_and_normalizer(a.run, params, norm, grow=False)

    @jax.jit
    def one(state, carry, reset):
        seq = jax.tree.map(lambda x: x[None], state.obs)
        means, recon = nets.unroll_reconstruction(params, norm, carry, seq, reset[None])
        c, *_ = nets.step(params, norm, carry, state.obs, reset)
        nxt = env.step(state, means[0])
        return nxt, c, nxt.done.astype(bool), recon[0], distill.reconstruction_target(state.obs, 36)

    carry, reset = nets.init_carry(a.envs), jp.ones((a.envs,), bool)
    preds, targets = [], []
    for t in range(a.steps):
        state, carry, reset, p, y = one(state, carry, reset)
        if t >= WARMUP:
            preds.append(np.asarray(p))
            targets.append(np.asarray(y))
    p, y = np.concatenate(preds), np.concatenate(targets)
    below = y < -0.1
    out = {
        "run": a.run,
        "samples": int(p.shape[0]),
        "r2": r2(p, y),
        "target_var": float(y.var(axis=0).mean()),
        "frac_below_10cm": float(below.mean()),
        "mse_below_10cm": float(((p - y) ** 2)[below].mean()),
        "mse_rest": float(((p - y) ** 2)[~below].mean()),
        "r2_by_offset_m": {
            f"{dx:+.1f},{dy:+.1f}": r2(p[:, j::9], y[:, j::9])
            for j, (dx, dy) in enumerate(FOOT_PATCH_OFFSETS_M)
        },
        "r2_by_foot": {
            f: r2(p[:, 9 * i : 9 * i + 9], y[:, 9 * i : 9 * i + 9]) for i, f in enumerate(FEET)
        },
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
