"""Does a seen teacher (env.actor_terrain_seen) look before it steps? On its own mean-action
rollouts: where each foot touches down, had a foot sensor's ray hit that cell before; and how
much of its terrain inputs it has seen, by foot-patch position and scan row.

    python scripts/seen_coverage.py runs/teacher_seen_cpu [--envs 256] [--steps 300]   # ~2 min
    python scripts/seen_coverage.py policies/teacher --plain   # the plain teacher, same counts

Fresh episodes at the curriculum's starting levels of configs/teacher_seen_cpu.py (levels 0-2 of
every stage-1 type; ``--max-level L``: levels 0-L). A touchdown is a foot whose contact flag (the critic's) goes 0 -> 1; its
cell is looked up in the grid of the step before (what the foot sensors had hit until then).
With ``--plain`` the policy is a plain teacher (env.actor_terrain): it reads the true heights
everywhere and the grid only counts what its rays hit. Prints JSON: touchdowns, the share on seen cells (front and hind feet), the share of the
teacher's 153 terrain points seen, by patch offset (front / hind feet) and by scan row.
"""

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import jax  # noqa: E402
import jax.numpy as jp  # noqa: E402
import numpy as np  # noqa: E402

from configs import teacher_seen_cpu  # noqa: E402
from foottof.envs import VmapEnv  # noqa: E402
from foottof.envs.anymal_tof import SEEN_KEY, AnymalToFEnv  # noqa: E402
from foottof.envs.observations import (  # noqa: E402
    ACTOR_SCAN_ROWS,
    ACTOR_TERRAIN_INPUTS,
    FOOT_PATCH_OFFSETS_M,
)
from foottof.ppo import checkpoint as ckpt  # noqa: E402
from foottof.ppo import networks as net  # noqa: E402
from foottof.robot import kinematics  # noqa: E402

OWN = 181  # the ToF student's inputs (4 sensors x 16 zones)
CONTACT = slice(181 + 36, 181 + 40)  # the critic's foot contacts (after its clean obs, patches)


class _Unmasked(AnymalToFEnv):
    """The seen env whose terrain heights are true everywhere (a plain teacher's inputs), the
    seen flags still after them."""

    def _actor_terrain(self, seen, fk, patches, scan, base_pos, base_quat):
        out = super()._actor_terrain(seen, fk, patches, scan, base_pos, base_quat)
        true = jp.concatenate([patches, scan[: ACTOR_SCAN_ROWS * 9]])
        return jp.concatenate([true, out[ACTOR_TERRAIN_INPUTS:]])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("run", help="a seen teacher's run or policy folder")
    ap.add_argument("--envs", type=int, default=256)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--plain", action="store_true", help="RUN is a plain teacher (actor_terrain)")
    ap.add_argument("--max-level", type=int, default=None, help="levels ~ U{0..this} (default 2)")
    a = ap.parse_args()
    cfg = teacher_seen_cpu.get_config()
    with cfg.unlocked():
        cfg.ppo.num_envs = a.envs
        if a.max_level is not None:
            cfg.terrain.init_level_max = a.max_level
    single = (_Unmasked if a.plain else AnymalToFEnv)(cfg, source=cfg.env.source)
    env, grid_spec = VmapEnv(single), single.seen_grid
    n_in = OWN + ACTOR_TERRAIN_INPUTS * (1 if a.plain else 2)  # what the policy reads

    def view(obs):
        return dict(obs, state=obs["state"][:, :n_in])

    state = jax.jit(env.reset)(jax.random.split(jax.random.PRNGKey(a.seed), a.envs))
    nets = net.make_networks(env.action_size, cfg.network)
    params = jax.jit(nets.init_params)(jax.random.PRNGKey(0), view(state.obs))
    norm = jax.jit(nets.init_normalizer)(view(state.obs))
    params, norm = ckpt.load_params_and_normalizer(a.run, params, norm, grow=False)

    @jax.jit
    def one(state, carry, reset):
        carry, means, *_ = nets.step(params, norm, carry, view(state.obs), reset)
        nxt = env.step(state, means)
        feet = kinematics.world_foot_kinematics(nxt.pipeline_state.qpos).foot_pos  # (N, 4, 3)
        origin, grid = state.info[SEEN_KEY]  # before this step's rays
        before = jax.vmap(grid_spec.lookup)(origin, grid, feet)  # (N, 4)
        return nxt, carry, nxt.done.astype(bool), before

    carry, reset = nets.init_carry(a.envs), jp.ones((a.envs,), bool)
    contact = np.asarray(state.obs["privileged_state"][:, CONTACT]) > 0
    touch_seen, touch_n = np.zeros(4), np.zeros(4)
    flags = []
    for _ in range(a.steps):
        state, carry, reset, before = one(state, carry, reset)
        now = np.asarray(state.obs["privileged_state"][:, CONTACT]) > 0
        done = np.asarray(reset)
        down = now & ~contact & ~done[:, None]  # a touchdown within the same episode
        touch_n += down.sum(0)
        touch_seen += (down & np.asarray(before)).sum(0)
        contact = now
        flags.append(np.asarray(state.obs["state"][:, OWN + ACTOR_TERRAIN_INPUTS :]))
    f = np.concatenate(flags)  # (samples, 153)
    patch = f[:, :36].reshape(-1, 4, 9)
    scan = f[:, 36:].reshape(-1, ACTOR_SCAN_ROWS, 9)
    offsets = [f"{dx:+.1f},{dy:+.1f}" for dx, dy in FOOT_PATCH_OFFSETS_M]
    out = {
        "run": a.run,
        "touchdowns": int(touch_n.sum()),
        "touchdowns_on_seen_cells": float(touch_seen.sum() / max(touch_n.sum(), 1)),
        "front_feet": float(touch_seen[:2].sum() / max(touch_n[:2].sum(), 1)),
        "hind_feet": float(touch_seen[2:].sum() / max(touch_n[2:].sum(), 1)),
        "seen_share_all_points": float(f.mean()),
        "seen_share_patch_front": dict(
            zip(offsets, patch[:, :2].mean((0, 1)).round(3).tolist(), strict=True)
        ),
        "seen_share_patch_hind": dict(
            zip(offsets, patch[:, 2:].mean((0, 1)).round(3).tolist(), strict=True)
        ),
        "seen_share_scan_rows_m": {
            f"{x:+.1f}": float(v)
            for x, v in zip(
                np.linspace(-0.6, 0.6, ACTOR_SCAN_ROWS), scan.mean((0, 2)).round(3), strict=True
            )
        },
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
