"""Renamed public names, defined once (imports no JAX), and the migrations that keep what older
code wrote readable: saved run configs (config.json), metrics.csv columns, evaluation result
rows and per-episode documents, checkpoints (their env metrics), and command-line overrides.

Speeds were suffixed ``_ms`` (metres per second), which reads as milliseconds; they are ``_mps``
now (CHANGELOG.md, 2026-12-02, third round).
"""

from __future__ import annotations

import json

# Config fields: old dotted path -> new dotted path.
CONFIG_FIELDS = {
    "env.randomization.push_vel_ms": "env.randomization.push_vel_mps",
    "reward.guidance_max_speed_ms": "reward.guidance_max_speed_mps",
    "reward.stall_speed_ms": "reward.stall_speed_mps",
}
# Env metrics (state.metrics keys, metrics.csv columns, TensorBoard tags): old -> new.
METRICS = {
    "episode/speed_ms": "episode/speed_mps",
    "task/speed_ms": "task/speed_mps",
}
# Config fields added after evaluations were made, with the default that reproduces the older
# behaviour: a run config saved before one existed is migrated to it once, when it is read
# (read_saved_config), and draw fingerprints leave them out at that default (legacy_config_dict),
# so evaluations from before the field existed still pair with ones made after.
ADDED_FIELDS = {
    "network.obs_skip": False,  # off: the heads read the LSTM output only
    "network.reconstruct": 0,  # no belief decoder
    "ppo.reconstruction_weight": 0.5,  # read only with network.reconstruct > 0
    "reward.scales.task": 0.0,  # off: no position reward in the last task_window_s
    "reward.task_window_s": 2.0,  # read only when the task term is on
    "reward.guidance_goal_pay": True,  # guidance pays full credit within the success radius
    "reward.guidance_decay_start_iteration": 0,  # read only when the decay end is > 0
    "reward.guidance_decay_end_iteration": 0,  # 0: the guidance bias never decays
    "reward.stall_toward_goal": False,  # stall: slow in any direction (not toward the goal)
    "reward.overall_scale": 1.0,  # every reward term as scaled
    "train.teacher": "",  # PPO, no distillation
    "train.student_privileged_inputs": 0,  # the student reads its sensors only
    "train.teacher_change_ok": False,  # a resumed student keeps the teacher it started with
    "env.actor_terrain": False,  # off: the actor reads its sensors only (no teacher inputs)
    "env.actor_terrain_seen": False,  # a teacher's terrain inputs are true everywhere
    "env.actor_terrain_fine": False,  # a teacher's terrain inputs are 10 cm apart only
    "env.critic_height_scan": False,  # off: the critic reads no base-centred height scan
    "env.foot_stuck_depth_m": 0.0,  # off: a foot in a gap does not end the episode
    "terrain.no_promotion_on_fall": False,  # a failed episode may still be promoted
    "env.physics": "auto",  # MuJoCo C on a CPU JAX backend, else MJX
    "env.physics_threads": 0,  # os.cpu_count() MuJoCo C threads
    "network.max_noise_std": 0.0,  # no cap on the action std
    "reward.scales.overspeed": 0.0,  # off: base speed is not penalized
    "reward.overspeed_mps": 0.6,  # read only when the overspeed term is on
    "terrain.stone_curriculum": "gaps_first",  # stones shrink last (tiles.STONE_CURRICULA)
    "ppo.symmetry": False,  # off: no mirrored copies of the rollout sequences
}
# Config fields removed (2026-12-07, twenty-ninth session: experiment flags no shipped policy or
# documented config used), with the default at which the behaviour was the code's of today. A
# saved run config holding one at that default reads as if it never had it; at another value it
# is refused (migrate_config_dict): this code cannot reproduce that run. The code that had them:
# git commit REMOVED_AT.
REMOVED_AT = "75dbea4"
REMOVED_FIELDS = {
    "reward.guidance_peaked": False,  # guidance fell above its speed (2 vmax - v)
    "reward.scales.foot_clearance": 0.0,  # swing-height penalty (Isaac Lab's Spot)
    "reward.clearance_target_m": 0.12,  # its swing height; read only with foot_clearance on
    "reward.scales.timeout": 0.0,  # the deadline away from the goal priced like a fall
    "terrain.stretch_prob": 0.0,  # share of episodes on a level above the curriculum's
    "terrain.stretch_min_level": 7,  # their lowest level; read only with stretch_prob on
    "ppo.low_noise_share": 0.0,  # share of envs acting at a lower action std
    "ppo.low_noise_scale": 0.25,  # their std multiplier; read only with low_noise_share on
}
# Read only where the field they depend on is on: any value is dropped when that one is off.
_REMOVED_DEPENDS = {
    "reward.clearance_target_m": "reward.scales.foot_clearance",
    "terrain.stretch_min_level": "terrain.stretch_prob",
    "ppo.low_noise_scale": "ppo.low_noise_share",
}
# Added fields that were already in the configs of the evaluations kept (results/): draw
# fingerprints hash them at every value, as those evaluations did; ADDED_FIELDS gives only the
# value that run configs saved before they existed are migrated to.
HASHED_AT_DEFAULT = frozenset(
    {
        "env.critic_height_scan",
        "env.foot_stuck_depth_m",
        "terrain.no_promotion_on_fall",
        "env.physics",
        "env.physics_threads",
        "network.max_noise_std",
    }
)


def added_default(field: str):
    """The old-behaviour default of an ADDED_FIELDS entry (dotted path): what a config saved
    before the field existed is migrated to (migrate_config_dict), so that default is written
    once."""
    if field not in ADDED_FIELDS:
        raise KeyError(f"{field!r} is not an added field; added fields: {sorted(ADDED_FIELDS)}")
    return ADDED_FIELDS[field]


# Evaluation result rows (results_*.json/csv) and per-episode outcomes (episodes_*.json).
RESULT_KEYS = {"mean_speed_ms": "mean_speed_mps"}


def read_saved_config(path: str) -> dict:
    """The saved run config at ``path`` (a run's config.json), migrated (migrate_config_dict):
    the one reader of saved run configs, so the code that reads one reads every field directly.

    Raises:
      ValueError: as migrate_config_dict (a removed field set away from its default).
    """
    with open(path) as f:
        return migrate_config_dict(json.load(f))


def migrate_config_dict(saved: dict) -> dict:
    """A saved run config (the nested dict of config.json) as today's code reads it (a copy):
    renamed fields moved to their new names (a field present under both names keeps the new
    one), removed fields (REMOVED_FIELDS) dropped, and added fields (ADDED_FIELDS) the run was
    saved without filled in at their old-behaviour default.

    An added field is filled in only where the dict holding it is there (``env`` for
    ``env.physics``, ``reward.scales`` for ``reward.scales.task``): a section the saved dict
    lacks is not created. Its readers tell a run that says nothing about a section from one that
    does by the section's presence (run_dir.with_run_network takes c.network from a run only
    where it has one, with_run_curriculum the terrain likewise, the runner compares sections),
    so a section made of defaults alone would stand in for settings the run never had.

    Raises:
      ValueError: one line naming a removed field the run set away from its default (and the
        commit whose code still has it).
    """
    out = _copy(saved)
    for old, new in CONFIG_FIELDS.items():
        _move(out, old, new)
    found = {}
    for field in REMOVED_FIELDS:
        *path, leaf = field.split(".")
        parent = _walk(out, path)
        if parent is not None and leaf in parent:
            found[field] = parent.pop(leaf)
    for field, value in found.items():
        on = _REMOVED_DEPENDS.get(field)
        if on is not None and found.get(on, REMOVED_FIELDS[on]) == REMOVED_FIELDS[on]:
            continue  # read only when `on` is on, and it is off
        if value != REMOVED_FIELDS[field]:
            raise ValueError(
                f"the run config sets {field}={value!r}, a field removed on 2026-12-07 (its "
                f"default {REMOVED_FIELDS[field]!r} is today's behaviour): this code cannot "
                f"resume or reproduce that run; the code at git commit {REMOVED_AT} can"
            )
    for field, default in ADDED_FIELDS.items():
        *path, leaf = field.split(".")
        parent = _walk(out, path)
        if parent is not None:
            parent.setdefault(leaf, default)
    return out


def legacy_config_dict(current: dict) -> dict:
    """A config dict with renamed fields under their old names and added fields at their old-
    behaviour default left out (a copy): what draw fingerprints hash
    (foottof.eval.results.draws_fingerprint), so evaluations made before and after a rename or
    an addition still pair episode by episode."""
    out = _copy(current)
    for added, default in ADDED_FIELDS.items():
        if added in HASHED_AT_DEFAULT:
            continue
        *path, leaf = added.split(".")
        parent = _walk(out, path)
        if parent is not None and leaf in parent and parent[leaf] == default:
            del parent[leaf]
    for old, new in CONFIG_FIELDS.items():
        _move(out, new, old)
    return out


def migrate_columns(fields: list[str]) -> list[str]:
    """metrics.csv header with renamed metric columns under their new names (order kept)."""
    return [METRICS.get(f, f) for f in fields]


def migrate_row(row: dict) -> dict:
    """A result row or per-episode cell with renamed keys under their new names (order kept)."""
    return {RESULT_KEYS.get(k, k): v for k, v in row.items()}


def old_override(argv: list[str]) -> str | None:
    """An error line for the first ``--config.<old name>`` override in argv (None: none): the
    config is locked, so ml_collections would only say the field does not exist."""
    for arg in argv:
        if not arg.startswith("--config."):
            continue
        name = arg[len("--config.") :].split("=", 1)[0]
        if name in CONFIG_FIELDS:
            return (
                f"error: --config.{name} was renamed to --config.{CONFIG_FIELDS[name]} "
                f"(speeds are suffixed _mps, metres per second; CHANGELOG.md)"
            )
    return None


def _move(d: dict, src: str, dst: str) -> None:
    """Moves the leaf at dotted path ``src`` of the nested dict ``d`` to ``dst`` (in place; a leaf
    already at ``dst`` is kept; nothing happens where ``src`` or the parent of ``dst`` is absent)."""
    *src_path, src_leaf = src.split(".")
    *dst_path, dst_leaf = dst.split(".")
    parent = _walk(d, src_path)
    if parent is None or src_leaf not in parent:
        return
    value = parent.pop(src_leaf)
    target = _walk(d, dst_path)
    if target is not None:
        target.setdefault(dst_leaf, value)


def _copy(d):
    return {k: _copy(v) for k, v in d.items()} if isinstance(d, dict) else d


def _walk(d: dict, path: list[str]) -> dict | None:
    for k in path:
        d = d.get(k) if isinstance(d, dict) else None
        if not isinstance(d, dict):
            return None
    return d
