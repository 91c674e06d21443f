"""Where the terrain curriculum stands: curriculum levels per terrain type in a run's checkpoint.

``python -m foottof.lab.levels RUN_DIR [--step N]`` reads the env state saved with a checkpoint
(``train.checkpoint_env_state``, on by default) and prints, per terrain type of the training map,
how many envs are at each curriculum level. The mean level of the learning curve hides this: a
run can hold its box tiles at the top while its stepping stones stay at level 0.
"""

from __future__ import annotations

import argparse
import os
import warnings

import ml_collections
import numpy as np
import orbax.checkpoint as ocp

from foottof import renames
from foottof.ppo.storage.run_dir import CHECKPOINT_SUBDIR
from foottof.terrain.terrain_map import TERRAIN_TYPES, TerrainMapSpec

# Leaves of the 'rollout' item (checkpoint manifest names) holding each env's level and map column.
LEVEL_LEAF = "['env_state'].info['task'].level"
COL_LEAF = "['env_state'].info['task'].col"


def _manager(run_dir: str) -> ocp.CheckpointManager:
    """Read-only orbax manager of ``run_dir``'s checkpoints (creates nothing on a bad path)."""
    root = os.path.abspath(os.path.join(run_dir, CHECKPOINT_SUBDIR))
    if not os.path.isdir(root):
        hint = ""
        if os.path.basename(os.path.normpath(run_dir)).isdigit():
            hint = f"; {run_dir} looks like one checkpoint: give its run directory and --step"
        raise FileNotFoundError(f"no checkpoint in {root}{hint}")
    return ocp.CheckpointManager(root, options=ocp.CheckpointManagerOptions(create=False))


def _resolve(manager: ocp.CheckpointManager, run_dir: str, step: int | None) -> int:
    steps = sorted(manager.all_steps())
    if not steps:
        raise FileNotFoundError(f"no checkpoint in {run_dir}/{CHECKPOINT_SUBDIR}")
    if step is None:
        return steps[-1]
    if step not in steps:
        raise ValueError(f"step={step!r} is not a checkpoint of {run_dir}; it has {steps}")
    return step


def resolve_step(run_dir: str, step: int | None = None) -> int:
    """``step`` if it is a checkpoint of ``run_dir``, the latest one if ``step`` is None."""
    manager = _manager(run_dir)
    try:
        return _resolve(manager, run_dir, step)
    finally:
        manager.close()


def read_rollout_leaves(run_dir: str, names: tuple[str, ...], step: int | None = None) -> dict:
    """Arrays of the named 'rollout' leaves of checkpoint ``step`` (default: the latest).

    Raises:
      FileNotFoundError: no checkpoint, or it was saved without its env state.
      KeyError: a name is not a leaf of the saved env state (the message lists similar ones).
    """
    manager = _manager(run_dir)
    try:
        step = _resolve(manager, run_dir, step)
        manifest = manager.restore(
            step, args=ocp.args.Composite(manifest=ocp.args.JsonRestore())
        ).manifest
        if "rollout" not in manifest:
            raise FileNotFoundError(
                f"checkpoint {step} of {run_dir} holds no env state (saved with "
                f"train.checkpoint_env_state=False)"
            )
        leaf_names = [entry[0] for entry in manifest["rollout"]]
        for n in names:
            if n not in leaf_names:
                near = [x for x in leaf_names if "task" in x][:8]
                raise KeyError(f"{n!r} is not a saved env-state leaf; leaves with 'task': {near}")
        with warnings.catch_warnings():  # orbax warns that it reads the sharding from the file
            warnings.simplefilter("ignore")
            flat = manager.restore(
                step, args=ocp.args.Composite(rollout=ocp.args.StandardRestore())
            ).rollout
    finally:
        manager.close()
    return {n: np.asarray(flat[f"leaf_{leaf_names.index(n):04d}"]) for n in names}


def run_terrain(run_dir: str) -> tuple[ml_collections.ConfigDict, int]:
    """(terrain section, stage) of ``run_dir``'s saved config, read migrated
    (renames.read_saved_config)."""
    cfg = ml_collections.ConfigDict(renames.read_saved_config(os.path.join(run_dir, "config.json")))
    return cfg.terrain, int(cfg.stage)


def smallest_stones(
    terrain, stage: int, counts: dict[str, np.ndarray], share: float = 0.05
) -> dict[str, float]:
    """Nominal stone size [m] at the highest level that holds at least ``share`` of the type's
    envs, per stone type of ``counts``: the smallest stone the type trains on (a few envs
    promoted once do not count). Its curriculum: terrain.stone_curriculum (a run saved without
    one reads "gaps_first", migrated by run_terrain)."""
    from foottof.terrain.tiles import STONE_TYPES, stone_params

    curriculum = str(terrain.stone_curriculum)
    ranges = terrain[f"stage{stage}_difficulty"]
    out = {}
    for name, c in counts.items():
        if name not in STONE_TYPES or c.sum() == 0:
            continue
        top = int(np.flatnonzero(c >= share * c.sum())[-1])
        lo, hi = ranges[name]
        d = lo + (hi - lo) * top / max(len(c) - 1, 1)
        out[name] = float(stone_params(name, d, curriculum)["size"])
    return out


def level_counts(run_dir: str, step: int | None = None) -> dict[str, np.ndarray]:
    """Envs per curriculum level, per terrain type, in checkpoint ``step`` of ``run_dir``.

    Returns:
      {terrain type: (num_levels,) int counts}, in the order of the map's columns; the counts of
      all types add up to the run's number of envs.
    """
    terrain, stage = run_terrain(run_dir)
    spec = TerrainMapSpec.from_config(terrain, stage)
    leaves = read_rollout_leaves(run_dir, (LEVEL_LEAF, COL_LEAF), step)
    level, col = leaves[LEVEL_LEAF].reshape(-1), leaves[COL_LEAF].reshape(-1)
    if col.min() < 0 or col.max() >= spec.num_cols:
        raise ValueError(f"map columns {col.min()}..{col.max()} outside [0, {spec.num_cols - 1}]")
    types = np.asarray(spec.col_types)[col]
    out = {}
    for t in dict.fromkeys(spec.col_types):  # map order, each type once
        out[TERRAIN_TYPES[t]] = np.bincount(level[types == t], minlength=spec.num_levels)
    return out


def mean_level(counts: np.ndarray) -> float:
    """Mean curriculum level of one type's (num_levels,) envs-per-level counts (0 when empty)."""
    return float(np.dot(counts, np.arange(len(counts))) / max(counts.sum(), 1))


def format_table(counts: dict[str, np.ndarray], stones: dict[str, float] | None = None) -> str:
    """Plain-text table: one row per type, envs per level, then the type's mean level (and,
    given ``stones``, the smallest stone it trains on [m])."""
    num_levels = len(next(iter(counts.values())))
    head = f"{'terrain type':<18}" + "".join(f"{i:>5}" for i in range(num_levels)) + "   mean"
    head += "  smallest stone [m]" if stones is not None else ""
    lines = [head]
    for name, c in counts.items():
        line = f"{name:<18}" + "".join(f"{int(v):>5}" for v in c) + f"  {mean_level(c):5.2f}"
        if stones is not None and name in stones:
            line += f"  {stones[name]:18.2f}"
        lines.append(line)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run_dir", help="run directory of train.py (or a policies/ folder)")
    p.add_argument("--step", type=int, default=None, help="checkpoint number (default: latest)")
    a = p.parse_args(argv)
    try:
        step = resolve_step(a.run_dir, a.step)
        counts = level_counts(a.run_dir, step)
        terrain, stage = run_terrain(a.run_dir)
        stones = smallest_stones(terrain, stage, counts)
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(f"error: {e}") from None
    curriculum = terrain.stone_curriculum
    print(f"envs per curriculum level, checkpoint {step} (stone curriculum {curriculum})")
    print(format_table(counts, stones))


if __name__ == "__main__":
    main()
