"""Robustness evaluation (paper, robustness figure): success rate per source x perturbation x level.

Protocol: every env runs exactly one episode on the evaluation ensemble (80 % stepping-stone
tiles + 20 % gap tiles at 90 % of the stage-1 difficulty); its first ``done`` step gives the
outcome, auto-reset episodes after it are ignored. Success = the episode ran to its time limit
and ended within ``reward.success_radius_m`` (0.5 m) of the goal (``episode/success`` of the env).
Episodes are run in batches of ``eval.num_envs`` until ``eval.episodes`` are collected.

Perturbations (joint_offset and odometry levels are arguments of one compiled rollout; each
shank_length level needs its own physics model, hence its own compile):
  none          single level 0.
  joint_offset  static offset on all joint readings [rad], valid [0, 0.3].
  shank_length  shank length scale of the physics model [-], valid [0.8, 1.2].
  odometry      odometry noise, multiples of the paper's 100 % level [-], valid [0, 10].
"""

from __future__ import annotations

import copy
import csv
import glob
import io
import json
import math
import os

import jax
import jax.numpy as jp
import ml_collections
import numpy as np

from foottof.envs import make_env
from foottof.perception import check_source
from foottof.ppo.checkpoint import load_params_and_normalizer
from foottof.ppo.networks import make_networks

PERTURBATIONS = ("none", "joint_offset", "shank_length", "odometry")
LEVEL_RANGES = {  # valid closed range of the levels of each perturbation
    "none": (0.0, 0.0),
    "joint_offset": (0.0, 0.3),
    "shank_length": (0.8, 1.2),
    "odometry": (0.0, 10.0),
}
TRACED_PERTURBATIONS = ("joint_offset", "odometry")  # levels are rollout arguments (one compile)
LEVEL_UNITS = {"none": "-", "joint_offset": "rad", "shank_length": "scale", "odometry": "x100%"}
PANEL_TITLES = {
    "joint_offset": "A  joint offset [rad]",
    "shank_length": "B  shank length [scale]",
    "odometry": "C  odometry noise [x 100 %]",
}
SCHEMA_VERSION = 1
RESULT_KEYS = (  # exact key set (and CSV column order) of one result row
    "source",
    "perturbation",
    "level",
    "episodes",
    "successes",
    "success_rate",
    "ci_low",
    "ci_high",
    "mean_speed_ms",
    "falls",
)
TOP_KEYS = ("schema_version", "checkpoint", "episode_length_s", "results")
SHIPPED_POLICY_DIRS = ("policies/latest",)  # checked (relative to the repo root) before runs/


# ---------------------------------------------------------------------------------------------
# Pure helpers (NumPy, no env)
def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % for the default z).

    Returns (low, high) in [0, 1]; (0, 1) for n = 0.
    """
    if n < 0 or successes < 0 or successes > n:
        raise ValueError(f"successes={successes}, n={n}: need 0 <= successes <= n")
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def first_episode_outcomes(
    done: np.ndarray, success: np.ndarray, failed: np.ndarray, speed: np.ndarray
) -> dict:
    """Outcome of each env's *first* episode from per-step rollout arrays.

    Args:
      done, success, failed: (T, B) per-step flags of the env (``state.done``,
        ``episode/success``, ``episode/failed``); values > 0.5 count as set.
      speed: (T, B) horizontal base speed at each step [m/s].

    Returns:
      dict of (B,) arrays: ``finished`` (bool, a done occurred), ``success`` (bool, at the first
      done), ``failed`` (bool, at the first done), ``mean_speed_ms`` (mean speed over the steps up
      to and including the first done; over all T steps if none), ``length`` (steps of the first
      episode).
    """
    done = np.asarray(done) > 0.5
    if done.ndim != 2:
        raise ValueError(f"done has shape {done.shape}; expected (T, B)")
    t_steps, _ = done.shape
    finished = done.any(axis=0)
    first = np.where(finished, done.argmax(axis=0), t_steps - 1)  # (B,)
    cols = np.arange(done.shape[1])
    succ = (np.asarray(success)[first, cols] > 0.5) & finished
    fail = (np.asarray(failed)[first, cols] > 0.5) & finished
    mask = np.arange(t_steps)[:, None] <= first[None, :]  # steps of the first episode
    length = mask.sum(axis=0)
    mean_speed = (np.asarray(speed) * mask).sum(axis=0) / np.maximum(length, 1)
    return {
        "finished": finished,
        "success": succ,
        "failed": fail,
        "mean_speed_ms": mean_speed,
        "length": length,
    }


def summarize(source: str, perturbation: str, level: float, outcomes: dict) -> dict:
    """One result row (keys RESULT_KEYS) from concatenated first-episode outcomes."""
    n = int(outcomes["success"].shape[0])
    k = int(outcomes["success"].sum())
    lo, hi = wilson_interval(k, n)
    return {
        "source": source,
        "perturbation": perturbation,
        "level": float(level),
        "episodes": n,
        "successes": k,
        "success_rate": k / n if n else float("nan"),
        "ci_low": lo,
        "ci_high": hi,
        "mean_speed_ms": float(np.mean(outcomes["mean_speed_ms"])) if n else float("nan"),
        "falls": int(outcomes["failed"].sum()),
    }


def check_levels(perturbation: str, levels) -> tuple[float, ...]:
    """Validates the perturbation name and its levels; 'none' has the single level 0."""
    if perturbation not in PERTURBATIONS:
        raise ValueError(
            f"unknown perturbation {perturbation!r}; valid choices: {list(PERTURBATIONS)}"
        )
    if perturbation == "none":
        return (0.0,)
    parsed = []
    for v in levels:
        try:
            parsed.append(float(v))
        except (TypeError, ValueError):
            raise ValueError(
                f"{perturbation} level {v!r} is not a number; valid range "
                f"{list(LEVEL_RANGES[perturbation])}"
            ) from None
    levels = tuple(parsed)
    if not levels:
        raise ValueError(f"no levels given for perturbation {perturbation!r}")
    lo, hi = LEVEL_RANGES[perturbation]
    for v in levels:
        if not (lo <= v <= hi) or not math.isfinite(v):
            raise ValueError(
                f"{perturbation} level {v} outside the valid range [{lo}, {hi}] "
                f"({LEVEL_UNITS[perturbation]})"
            )
    return levels


def default_levels(eval_cfg: ml_collections.ConfigDict, perturbation: str) -> tuple[float, ...]:
    """The sweep levels of c.eval for `perturbation`."""
    table = {
        "none": (0.0,),
        "joint_offset": eval_cfg.joint_offset_levels,
        "shank_length": eval_cfg.shank_length_levels,
        "odometry": eval_cfg.odometry_levels,
    }
    return tuple(float(v) for v in table[perturbation])


# ---------------------------------------------------------------------------------------------
# Config / env / policy
def eval_config(cfg: ml_collections.ConfigDict, perturbation: str, level: float):
    """Copy of `cfg` for one evaluation cell: DR off, the perturbation applied.

    Returns (cfg, shank_scale) -- the shank scale is an env constructor argument.
    """
    c = copy.deepcopy(cfg)
    with c.unlocked():
        c.env.randomization.enabled = False  # no DR, no pushes
        c.env.randomization.joint_offset_rad = 0.0
        c.env.randomization.odometry_level = 1.0  # the paper's nominal 100 %
        c.terrain.init_level_max = int(c.eval.num_levels) - 1  # spawn on every row
        shank = 1.0
        if perturbation == "joint_offset":
            c.env.randomization.joint_offset_rad = float(level)
        elif perturbation == "odometry":
            c.env.randomization.odometry_level = float(level)
        elif perturbation == "shank_length":
            shank = float(level)
    return c, shank


def eval_terrain_map(cfg: ml_collections.ConfigDict, key: jax.Array):
    """The test ensemble: eval.stone_fraction stepping stones (equal split), the rest gaps."""
    from foottof.terrain.terrain_map import build_terrain_map, make_eval_map_spec

    e = cfg.eval
    stones, gaps = tuple(e.stone_types), tuple(e.gap_types)
    frac = float(e.stone_fraction)
    if not 0.0 <= frac <= 1.0:
        raise ValueError(f"eval.stone_fraction={frac} outside the valid range [0, 1]")
    weights = [frac / len(stones)] * len(stones) + [(1 - frac) / len(gaps)] * len(gaps)
    spec = make_eval_map_spec(
        cfg.terrain,
        stones + gaps,
        weights,
        progress=float(e.difficulty_fraction),
        num_levels=int(e.num_levels),
        num_cols=int(e.num_cols),
    )
    return build_terrain_map(key, spec)


def find_checkpoint(repo_root: str) -> str | None:
    """Default checkpoint: a shipped policy (policies/latest), else the newest run under runs/."""
    for rel in SHIPPED_POLICY_DIRS:
        path = os.path.join(repo_root, rel)
        if _has_checkpoint(path):
            return path
    runs = [d for d in glob.glob(os.path.join(repo_root, "runs", "*")) if _has_checkpoint(d)]
    if not runs:
        return None
    return max(runs, key=lambda d: os.path.getmtime(os.path.join(d, "checkpoints")))


def _has_checkpoint(path: str) -> bool:
    ck = os.path.join(path, "checkpoints")
    return os.path.isdir(ck) and any(n.isdigit() for n in os.listdir(ck))


def run_config_path(checkpoint: str) -> str | None:
    """config.json of the run holding `checkpoint` (run dir, checkpoints/ or a step dir)."""
    p = os.path.abspath(checkpoint)
    for _ in range(3):
        if os.path.isfile(os.path.join(p, "config.json")):
            return os.path.join(p, "config.json")
        p = os.path.dirname(p)
    return None


def with_run_network(cfg: ml_collections.ConfigDict, checkpoint: str | None):
    """`cfg` with c.network taken from the checkpoint's run config (if it has one)."""
    path = run_config_path(checkpoint) if checkpoint else None
    if path is None:
        return cfg
    with open(path) as f:
        saved = json.load(f)
    if "network" not in saved:
        return cfg
    c = copy.deepcopy(cfg)
    with c.unlocked():
        for k, v in saved["network"].items():
            if k in c.network:
                c.network[k] = tuple(v) if isinstance(v, list) else v
    return c


def load_policy(cfg, env, obs, checkpoint: str | None, key: jax.Array):
    """(networks, params, normalizer): fresh init if `checkpoint` is None, else restored.

    Raises:
      FileNotFoundError: no checkpoint at `checkpoint`.
      ValueError: the checkpoint's network / observation layout differs from this env's.
    """
    networks = make_networks(env.action_size, cfg.network)
    params = networks.init_params(key, obs)
    normalizer = jax.tree.map(jp.asarray, networks.init_normalizer(obs))  # python floats -> arrays
    if checkpoint is None:
        return networks, params, normalizer
    if not os.path.exists(checkpoint):
        raise FileNotFoundError(f"checkpoint {checkpoint!r} does not exist")
    try:
        params, normalizer = load_params_and_normalizer(checkpoint, params, normalizer)
    except FileNotFoundError as e:
        raise FileNotFoundError(f"checkpoint {checkpoint!r}: {e}") from None
    except ValueError as e:
        sizes = {k: int(v.shape[-1]) for k, v in obs.items()}
        raise ValueError(
            f"checkpoint {checkpoint!r} does not fit this env (source={env.source!r}, "
            f"observation sizes {sizes}): {e}"
        ) from None
    return networks, params, normalizer


def make_rollout(env, networks, num_envs: int, steps: int, perturbation: str = "none"):
    """jit-ed (params, normalizer, key, level) -> per-step (T, B) arrays done/success/failed/speed.

    ``level`` is a traced argument for the ``TRACED_PERTURBATIONS`` (the first episode of every
    env starts with ``env.reset_perturbed``), so one compile serves a whole sweep; for 'none' and
    'shank_length' it is ignored (the latter lives in the env's physics model).
    """
    if perturbation not in PERTURBATIONS:
        raise ValueError(
            f"unknown perturbation {perturbation!r}; valid choices: {list(PERTURBATIONS)}"
        )
    rcfg = env.cfg.env.randomization
    step = jax.vmap(env.step)

    def reset(keys, level):
        if perturbation == "joint_offset":
            return jax.vmap(lambda k: env.reset_perturbed(k, level, rcfg.odometry_level))(keys)
        if perturbation == "odometry":
            return jax.vmap(lambda k: env.reset_perturbed(k, rcfg.joint_offset_rad, level))(keys)
        return jax.vmap(env.reset)(keys)

    def rollout(params, normalizer, key, level):
        key_reset, key_run = jax.random.split(key)
        state = reset(jax.random.split(key_reset, num_envs), level)
        act = networks.policy_fn(params, normalizer, deterministic=True)
        carry = networks.init_carry(num_envs)
        first = jp.ones((num_envs,), bool)

        def body(c, k):
            state, carry, reset_flags = c
            carry, action = act(carry, state.obs, reset_flags, k)
            state = step(state, action)
            out = (
                state.done,
                state.metrics["episode/success"],
                state.metrics["episode/failed"],
                state.metrics["episode/speed_ms"],
            )
            return (state, carry, state.done > 0.5), out

        _, outs = jax.lax.scan(body, (state, carry, first), jax.random.split(key_run, steps))
        return outs

    return jax.jit(rollout)


def evaluate_sweep(
    cfg: ml_collections.ConfigDict,
    source: str,
    perturbation: str,
    levels,
    checkpoint: str | None,
    key: jax.Array,
    progress=None,
) -> list[dict]:
    """Runs eval.episodes first episodes at every level of one (source, perturbation); rows.

    Every level sees the same terrain map, policy and episode draws (spawn, goal, sensor noise):
    a paired comparison, in which only the perturbation differs. Joint-offset and odometry levels
    share one compiled rollout; every shank-length level needs its own physics model (compile).

    Args:
      cfg: full config (c.eval gives episodes, num_envs and the ensemble).
      source: foot-reading source.
      perturbation, levels: validated by check_levels.
      checkpoint: checkpoint path, or None for a freshly initialized (untrained) policy.
      key: PRNG key (terrain map, policy init, episodes).
      progress: optional tqdm bar, advanced by the episodes of each batch.

    Returns:
      One result row (keys RESULT_KEYS) per level, in the order of ``levels``.
    """
    check_source(source, allow_all=False)
    levels = check_levels(perturbation, levels)
    episodes, num_envs = int(cfg.eval.episodes), int(cfg.eval.num_envs)
    if episodes < 1 or num_envs < 1:
        raise ValueError(f"eval.episodes={episodes}, eval.num_envs={num_envs}: both must be >= 1")
    num_envs = min(num_envs, episodes)
    key_map, key_init, key_run = jax.random.split(key, 3)
    traced = perturbation in TRACED_PERTURBATIONS
    groups = [levels] if traced or perturbation == "none" else [(lv,) for lv in levels]
    rows = []
    for group in groups:
        c, shank = eval_config(cfg, "none" if traced else perturbation, group[0])
        env = make_env(
            c, source=source, terrain_map=eval_terrain_map(c, key_map), shank_scale=shank
        )
        obs = jax.jit(jax.vmap(env.reset))(jax.random.split(key_init, num_envs)).obs
        networks, params, normalizer = load_policy(c, env, obs, checkpoint, key_init)
        rollout = make_rollout(env, networks, num_envs, env.episode_steps, perturbation)
        for level in group:
            parts, collected, k_run = [], 0, key_run
            while collected < episodes:
                k_run, k = jax.random.split(k_run)
                outs = jax.device_get(rollout(params, normalizer, k, jp.float32(level)))
                res = first_episode_outcomes(*outs)
                take = min(num_envs, episodes - collected)
                parts.append({n: v[:take] for n, v in res.items()})
                collected += take
                if progress is not None:
                    progress.update(take)
            merged = {n: np.concatenate([p[n] for p in parts]) for n in parts[0]}
            rows.append(summarize(source, perturbation, level, merged))
    return rows


def evaluate_cell(
    cfg: ml_collections.ConfigDict,
    source: str,
    perturbation: str,
    level: float,
    checkpoint: str | None,
    key: jax.Array,
    progress=None,
) -> dict:
    """One (source, perturbation, level) cell: ``evaluate_sweep`` with a single level."""
    return evaluate_sweep(cfg, source, perturbation, (level,), checkpoint, key, progress)[0]


# ---------------------------------------------------------------------------------------------
# Output
def results_document(rows: list[dict], checkpoint: str | None, episode_length_s: float) -> dict:
    """The results JSON document (keys TOP_KEYS; each row keys RESULT_KEYS)."""
    for r in rows:
        if tuple(r) != RESULT_KEYS:
            raise ValueError(f"result row keys {tuple(r)} differ from {RESULT_KEYS}")
    return {
        "schema_version": SCHEMA_VERSION,
        "checkpoint": checkpoint or "untrained (fresh init)",
        "episode_length_s": float(episode_length_s),
        "results": rows,
    }


def csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=RESULT_KEYS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    return buf.getvalue()


def format_table(rows: list[dict]) -> str:
    """Human-readable table of result rows."""
    head = (
        f"{'source':<11}{'perturbation':<14}{'level':>7}{'episodes':>9}{'success':>9}"
        f"{'rate':>7}  {'95% CI':<13}{'speed m/s':>10}{'falls':>7}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['source']:<11}{r['perturbation']:<14}{r['level']:>7.3g}{r['episodes']:>9d}"
            f"{r['successes']:>9d}{r['success_rate']:>7.3f}  "
            f"[{r['ci_low']:.3f},{r['ci_high']:.3f}]{r['mean_speed_ms']:>10.3f}{r['falls']:>7d}"
        )
    return "\n".join(lines)


def write_atomic(files: dict[str, bytes]) -> None:
    """Writes every {path: bytes} to path.tmp first, then renames all (no partial outputs)."""
    tmps = []
    try:
        for path, data in files.items():
            os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
            tmp = path + ".tmp"
            with open(tmp, "wb") as f:
                f.write(data)
            tmps.append((tmp, path))
    except BaseException:
        for tmp, _ in tmps:
            if os.path.exists(tmp):
                os.remove(tmp)
        raise
    for tmp, path in tmps:
        os.replace(tmp, path)


def result_basename(source: str, perturbation: str) -> str:
    return f"results_{source}_{perturbation}"


def write_results(out_dir: str, source_flag: str, perturbation: str, doc: dict) -> dict:
    """Writes results_<source>_<perturbation>.{json,csv} and robustness.png (all results in
    out_dir on shared axes); returns {kind: path}."""
    from foottof.eval.plots import robustness_png

    base = os.path.join(out_dir, result_basename(source_flag, perturbation))
    paths = {"json": base + ".json", "csv": base + ".csv", "png": os.path.join(out_dir,
                                                                                "robustness.png")}
    others = [p for p in glob.glob(os.path.join(out_dir, "results_*.json")) if p != paths["json"]]
    rows = list(doc["results"])
    seen = {(r["source"], r["perturbation"], r["level"]) for r in rows}
    for p in sorted(others, key=os.path.getmtime, reverse=True):  # newest first wins
        try:
            with open(p) as f:
                more = [r for r in json.load(f)["results"] if tuple(r) == RESULT_KEYS]
        except (OSError, ValueError, KeyError, TypeError):
            continue  # a foreign or damaged file: not plotted
        for r in more:
            if (r["source"], r["perturbation"], r["level"]) not in seen:
                seen.add((r["source"], r["perturbation"], r["level"]))
                rows.append(r)
    write_atomic(
        {
            paths["json"]: json.dumps(doc, indent=2).encode(),
            paths["csv"]: csv_text(doc["results"]).encode(),
            paths["png"]: robustness_png(rows),
        }
    )
    return paths
