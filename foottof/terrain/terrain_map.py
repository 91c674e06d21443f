"""Terrain map: levels x type-columns of tiles in one Heightfield, with spawn and goal per tile."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

from foottof.terrain.heightfield import Heightfield
from foottof.terrain.tiles import (
    SPAWN_SURFACE_Z_M,
    TERRAIN_TYPES,
    TileSpec,
    check_terrain_name,
    generate_tile,
)

# Layout of the last axis of TerrainMap.spawn and of sample_spawn_goal's spawn.
SPAWN_X, SPAWN_Y, SPAWN_YAW, SPAWN_Z = 0, 1, 2, 3


def allocate_columns(weights: Mapping[str, float], num_cols: int) -> tuple[int, ...]:
    """Splits ``num_cols`` tile columns among terrain types in proportion to ``weights``.

    Largest-remainder rounding; when ``num_cols`` allows, every type with a positive weight gets at
    least one column. Columns of one type are contiguous, types in TERRAIN_TYPES order.

    Args:
      weights: type name -> non-negative weight (need not sum to 1).
      num_cols: number of columns, >= 1.

    Returns:
      (num_cols,) type index (into TERRAIN_TYPES) of each column.
    """
    if int(num_cols) != num_cols or num_cols < 1:
        raise ValueError(f"num_cols={num_cols} must be an integer >= 1")
    for name, w in weights.items():
        check_terrain_name(name)
        if not (w >= 0 and math.isfinite(w)):
            raise ValueError(f"weight {w!r} of {name!r} must be finite and >= 0")
    names = [n for n in TERRAIN_TYPES if weights.get(n, 0.0) > 0]
    if not names:
        raise ValueError(f"weights {dict(weights)} need at least one positive entry")
    w = np.array([weights[n] for n in names], np.float64)
    share = w / w.sum() * num_cols
    counts = np.floor(share).astype(int)
    for i in np.argsort(-(share - counts), kind="stable")[: num_cols - counts.sum()]:
        counts[i] += 1
    while num_cols >= len(names) and (counts == 0).any():
        counts[np.argmax(counts)] -= 1
        counts[np.argmin(counts)] += 1
    return tuple(
        TERRAIN_TYPES.index(n) for n, c in zip(names, counts, strict=True) for _ in range(c)
    )


@dataclasses.dataclass(frozen=True)
class TerrainMapSpec:
    """Static description of a terrain map (hashable: a jit static argument).

    Tile (level l, column c) covers world x in [c * L_x, (c + 1) * L_x),
    y in [l * L_y, (l + 1) * L_y)
    (L_x = tile.length_m, L_y = tile.width_m); a flat z = 0 border of ``border_m`` surrounds the
    map. Its generator difficulty is ``lo_c + (hi_c - lo_c) * l / (num_levels - 1)``.

    Attributes:
      tile: geometry of every tile.
      num_levels: rows of tiles (curriculum levels) along +y.
      col_types: (C,) type index (into TERRAIN_TYPES) of each column along +x.
      col_difficulty: (C,) (lo, hi) generator difficulty of each column at level 0 / top level.
      border_m: flat border width [m], a multiple of tile.cell_m.
      spawn_x_spread_m, spawn_y_spread_m, spawn_yaw_spread_rad: uniform +- spread of the sampled
        spawn around the start-platform centre [m, m, rad].
      goal_x_spread_m, goal_y_spread_m: uniform +- spread of the sampled goal around the
        goal-region centre [m].
      flat: every tile is flat ground at z = 0 (same layout, spawns and goals; for learning
        checks on flat ground, configs/flat.py); the tile types only label the columns.
    """

    tile: TileSpec
    num_levels: int
    col_types: tuple[int, ...]
    col_difficulty: tuple[tuple[float, float], ...]
    border_m: float = 1.0
    spawn_x_spread_m: float = 0.1
    spawn_y_spread_m: float = 0.2
    spawn_yaw_spread_rad: float = 0.3
    goal_x_spread_m: float = 0.2
    goal_y_spread_m: float = 0.2
    flat: bool = False

    def __post_init__(self):
        if int(self.num_levels) != self.num_levels or self.num_levels < 1:
            raise ValueError(f"num_levels={self.num_levels} must be an integer >= 1")
        if not self.col_types:
            raise ValueError("col_types must name at least one column")
        for t in self.col_types:
            if not 0 <= t < len(TERRAIN_TYPES):
                raise ValueError(f"col_types entry {t} outside [0, {len(TERRAIN_TYPES) - 1}]")
        if len(self.col_difficulty) != len(self.col_types):
            raise ValueError(
                f"col_difficulty has {len(self.col_difficulty)} entries, col_types "
                f"{len(self.col_types)}"
            )
        for lo, hi in self.col_difficulty:
            if not 0.0 <= lo <= hi <= 1.0:
                raise ValueError(f"difficulty range ({lo}, {hi}) must satisfy 0 <= lo <= hi <= 1")
        nb = self.border_m / self.tile.cell_m
        if self.border_m < 0 or abs(nb - round(nb)) > 1e-6:
            raise ValueError(
                f"border_m={self.border_m} must be a non-negative multiple of cell_m="
                f"{self.tile.cell_m}"
            )
        half_x = (self.tile.n_start - 1) * self.tile.cell_m / 2
        if not 0 <= self.spawn_x_spread_m <= half_x:
            raise ValueError(f"spawn_x_spread_m={self.spawn_x_spread_m} outside [0, {half_x}] m")
        spreads = (self.spawn_y_spread_m, self.goal_x_spread_m, self.goal_y_spread_m)
        if min(spreads) < 0 or self.spawn_yaw_spread_rad < 0:
            raise ValueError(f"spawn/goal spreads must be >= 0, got {spreads}")

    @property
    def num_cols(self) -> int:
        return len(self.col_types)

    @property
    def border_cells(self) -> int:
        return round(self.border_m / self.tile.cell_m)

    @property
    def hfield_shape(self) -> tuple[int, int]:
        """(nrow, ncol) vertices of the map's Heightfield."""
        b = self.border_cells
        return (self.num_levels * self.tile.ny + 2 * b, self.num_cols * self.tile.nx + 2 * b)

    @classmethod
    def from_config(cls, cfg, stage: int) -> TerrainMapSpec:
        """Builds the training map spec of ``stage`` (1 or 2) from the ``c.terrain`` section."""
        if stage not in (1, 2):
            raise ValueError(f"stage={stage!r} must be 1 or 2")
        weights = dict(cfg[f"stage{stage}_weights"])
        ranges = dict(cfg[f"stage{stage}_difficulty"])
        col_types = allocate_columns(weights, int(cfg.num_cols))
        for t in set(col_types):
            if TERRAIN_TYPES[t] not in ranges:
                raise ValueError(
                    f"stage{stage}_difficulty has no range for {TERRAIN_TYPES[t]!r}; "
                    f"it has {sorted(ranges)}"
                )
        return cls(
            tile=TileSpec.from_config(cfg),
            num_levels=int(cfg.num_levels),
            col_types=col_types,
            col_difficulty=tuple(
                tuple(float(v) for v in ranges[TERRAIN_TYPES[t]]) for t in col_types
            ),
            **_spread_kwargs(cfg),
        )


def _spread_kwargs(cfg) -> dict:
    return dict(
        border_m=float(cfg.border_m),
        spawn_x_spread_m=float(cfg.spawn_x_spread_m),
        spawn_y_spread_m=float(cfg.spawn_y_spread_m),
        spawn_yaw_spread_rad=float(cfg.spawn_yaw_spread_rad),
        goal_x_spread_m=float(cfg.goal_x_spread_m),
        goal_y_spread_m=float(cfg.goal_y_spread_m),
        flat=bool(cfg.flat),
    )


def make_eval_map_spec(
    cfg,
    types: Sequence[str],
    weights: Sequence[float],
    progress: float,
    num_levels: int,
    num_cols: int,
) -> TerrainMapSpec:
    """Evaluation ensemble: only ``types``, all at ``progress`` of their stage-1 difficulty range.

    The paper's test set is set by the ``c.eval`` config section (80 % stepping-stone tiles,
    20 % gap tiles at 90 % of stage 1); every tile of a type has the same
    difficulty (``lo + progress * (hi - lo)`` of ``cfg.stage1_difficulty``), the levels (rows) are
    just more random draws.

    Args:
      cfg: the ``c.terrain`` config section.
      types: terrain names; each needs a ``stage1_difficulty`` entry.
      weights: share of columns of each type.
      progress: curriculum progress in [0, 1] within the stage-1 range.
      num_levels, num_cols: map size in tiles.
    """
    if len(types) != len(weights):
        raise ValueError(f"{len(types)} types but {len(weights)} weights")
    if not 0.0 <= progress <= 1.0:
        raise ValueError(f"progress={progress} outside the valid range [0, 1]")
    ranges = dict(cfg.stage1_difficulty)
    for name in types:
        check_terrain_name(name)
        if name not in ranges:
            raise ValueError(
                f"{name!r} is not a stage-1 type with a difficulty range; valid: {sorted(ranges)}"
            )
    col_types = allocate_columns(dict(zip(types, weights, strict=True)), num_cols)
    col_difficulty = []
    for t in col_types:
        lo, hi = (float(v) for v in ranges[TERRAIN_TYPES[t]])
        d = lo + progress * (hi - lo)
        col_difficulty.append((d, d))
    return TerrainMapSpec(
        tile=TileSpec.from_config(cfg),
        num_levels=int(num_levels),
        col_types=col_types,
        col_difficulty=tuple(col_difficulty),
        **_spread_kwargs(cfg),
    )


@struct.dataclass
class TerrainMap:
    """A generated map. L = spec.num_levels, C = spec.num_cols.

    Attributes:
      hfield: the whole map, (L * ny + 2b, C * nx + 2b) vertices, world origin at the low corner of
        tile (0, 0) (``x0_m = y0_m = -border_m``).
      spawn: (L, C, 4) nominal spawn per tile: world x, y [m], yaw [rad] (0 = facing +x, towards
        the goal) and z of the start-platform surface [m] (0 for every type; add the base height).
        Index with SPAWN_X, SPAWN_Y, SPAWN_YAW, SPAWN_Z.
      goal: (L, C, 2) world x, y of the goal-region centre [m].
      col_type: (C,) int32 type index (into TERRAIN_TYPES) of each column.
      level_difficulty: (L,) curriculum progress of each level, ``l / (L - 1)`` (0 if L == 1).
      difficulty: (L, C) generator difficulty of each tile.
      spec: the static spec it was built from.
    """

    hfield: Heightfield
    spawn: jax.Array
    goal: jax.Array
    col_type: jax.Array
    level_difficulty: jax.Array
    difficulty: jax.Array
    spec: TerrainMapSpec = struct.field(pytree_node=False)

    @property
    def num_levels(self) -> int:
        return self.spec.num_levels

    @property
    def num_cols(self) -> int:
        return self.spec.num_cols


def _difficulty_table(spec: TerrainMapSpec) -> tuple[np.ndarray, np.ndarray]:
    levels = spec.num_levels
    progress = np.arange(levels, dtype=np.float32) / max(levels - 1, 1)
    lo = np.array([r[0] for r in spec.col_difficulty], np.float32)
    hi = np.array([r[1] for r in spec.col_difficulty], np.float32)
    return progress, lo[None, :] + (hi - lo)[None, :] * progress[:, None]


@functools.cache
def tile_generator(type_index: int, tile: TileSpec):
    """``(key, difficulty) -> (ny, nx)`` heights of one tile of a type, jitted once per process
    for each (type, tile geometry): every map that shares them, whatever its size, reuses it."""
    return jax.jit(functools.partial(generate_tile, TERRAIN_TYPES[type_index], spec=tile))


def build_terrain_map(key: jax.Array, spec: TerrainMapSpec) -> TerrainMap:
    """Generates every tile of ``spec`` from ``key`` and assembles the map.

    Each tile comes from its type's jitted generator (:func:`tile_generator`), compiled once per
    process and type, so a new key, map size or curriculum table compiles nothing new
    (bench/NOTES.md item 9). Call it eagerly: under an outer ``jax.jit`` XLA inlines one call per
    tile (the 200-tile stage-1 map then compiled for ~6 min).

    Args:
      key: PRNG key; tile (l, c) uses ``jax.random.split(key, (L, C))[l, c]``.
      spec: static map description.

    Returns:
      The TerrainMap.
    """
    tile = spec.tile
    levels, cols = spec.num_levels, spec.num_cols
    progress, diff = _difficulty_table(spec)
    keys = jax.random.split(key, (levels, cols))
    rows = [
        jp.concatenate(
            [
                tile_generator(spec.col_types[c], tile)(keys[lv, c], diff[lv, c])
                for c in range(cols)
            ],
            axis=1,
        )
        for lv in range(levels)
    ]
    heights = jp.concatenate(rows, axis=0)  # (L * ny, C * nx)
    if spec.flat:
        heights = jp.zeros_like(heights)
    b = spec.border_cells
    heights = jp.pad(heights, b, constant_values=0.0)
    hfield = Heightfield(
        heights=heights,
        x0_m=-b * tile.cell_m,
        y0_m=-b * tile.cell_m,
        cell_m=tile.cell_m,
        z_floor_m=tile.pit_z_m,
        z_range_m=tile.z_range_m,
    )
    ll, cc = np.meshgrid(np.arange(levels), np.arange(cols), indexing="ij")
    x_tile, y_tile = cc * tile.length_m, ll * tile.width_m
    sx, sy = tile.spawn_xy_m
    gx, gy = tile.goal_xy_m
    spawn_z = np.array([SPAWN_SURFACE_Z_M[TERRAIN_TYPES[t]] for t in spec.col_types])
    spawn = np.stack(
        [
            x_tile + sx,
            y_tile + sy,
            np.zeros_like(x_tile, float),
            np.broadcast_to(spawn_z, ll.shape),
        ],
        axis=-1,
    )
    goal = np.stack([x_tile + gx, y_tile + gy], axis=-1)
    return TerrainMap(
        hfield=hfield,
        spawn=jp.asarray(spawn, jp.float32),
        goal=jp.asarray(goal, jp.float32),
        col_type=jp.asarray(spec.col_types, jp.int32),
        level_difficulty=jp.asarray(progress),
        difficulty=jp.asarray(diff),
        spec=spec,
    )


def tile_at(tmap: TerrainMap, xy: jax.Array) -> tuple[jax.Array, jax.Array]:
    """The tile under world points (clamped to the map's tiles; the border maps to the edge tile).

    Args:
      tmap: the map.
      xy: (..., 2) world x, y [m].

    Returns:
      (level, col): (...) int32 each.
    """
    tile = tmap.spec.tile
    col = jp.floor(xy[..., 0] / tile.length_m).astype(jp.int32)
    level = jp.floor(xy[..., 1] / tile.width_m).astype(jp.int32)
    return jp.clip(level, 0, tmap.num_levels - 1), jp.clip(col, 0, tmap.num_cols - 1)


def sample_spawn_goal(
    key: jax.Array, tmap: TerrainMap, level: jax.Array, col: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Samples a spawn pose and goal on tile (level, col), spread uniformly per the spec.

    Works on any batch shape of ``level`` / ``col`` with one key (or vmap it).

    Args:
      key: PRNG key.
      tmap: the map.
      level, col: (...) int tile indices.

    Returns:
      spawn: (..., 4) x, y, yaw, z (platform surface) [m, m, rad, m]; x ~ U(+-spawn_x_spread_m),
        y ~ U(+-spawn_y_spread_m), yaw ~ U(+-spawn_yaw_spread_rad) around the nominal spawn.
      goal: (..., 2) x, y [m]; +- U(goal_x_spread_m), U(goal_y_spread_m) around the nominal goal.
    """
    s = tmap.spec
    level, col = jp.asarray(level, jp.int32), jp.asarray(col, jp.int32)
    u = jax.random.uniform(key, level.shape + (6,), minval=-1.0, maxval=1.0)  # ~ U(-1, 1)
    spread = jp.array(
        [s.spawn_x_spread_m, s.spawn_y_spread_m, s.spawn_yaw_spread_rad, 0.0], jp.float32
    )
    spawn = tmap.spawn[level, col] + u[..., :4] * spread  # z not spread
    goal = tmap.goal[level, col] + u[..., 4:] * jp.array([s.goal_x_spread_m, s.goal_y_spread_m])
    return spawn, goal
