"""Terrain config section: tile geometry, per-stage map layout, spawn spread, curriculum."""

import ml_collections


def get_section() -> ml_collections.ConfigDict:
    """Returns the ``c.terrain`` section (see foottof/terrain/terrain_map.py for how it is read)."""
    c = ml_collections.ConfigDict()
    # Tile geometry (one tile = one terrain type at one difficulty; robot walks along +x).
    c.tile_length_m = 6.0  # tile extent along +x, the walking direction [m]
    c.tile_width_m = 4.0  # tile extent along +y [m]
    c.cell_m = 0.04  # heightfield vertex spacing, <= 0.04 [m]
    c.platform_length_m = 1.6  # flat start platform at low x, surface z = 0 [m]
    c.goal_length_m = 1.0  # flat goal region at high x, surface z = 0 [m]
    c.pit_z_m = -1.0  # pit floor under stones and beams = Heightfield floor z_floor_m [m]
    c.z_range_m = 2.0  # heightfield elevation range: heights live in [pit_z_m, pit_z_m + this] [m]
    c.border_m = 1.0  # flat z = 0 border around the whole map [m]
    c.flat = False  # every tile flat at z = 0 (learning checks: configs/flat.py) [-]
    # Map layout: rows = difficulty levels (along +y), columns = terrain types (along +x).
    c.num_levels = 10  # curriculum levels = tile rows of the map
    c.num_cols = 20  # tile columns of the map, split among types by the stage weights
    # Stage 1: the five stage-1 types, mostly stepping stones. Weight = share of columns.
    c.stage1_weights = ml_collections.ConfigDict()
    c.stage1_weights.grid_stones = 0.30  # share of columns [-]
    c.stage1_weights.two_row_stones = 0.20  # share of columns [-]
    c.stage1_weights.rough_boxes = 0.10  # share of columns [-]
    c.stage1_weights.platform_gap = 0.15  # share of columns [-]
    c.stage1_weights.mixed_row_stones = 0.25  # share of columns [-]
    # Generator difficulty (lo, hi) spanned by levels 0 .. num_levels - 1, per type, stage 1.
    c.stage1_difficulty = ml_collections.ConfigDict()
    c.stage1_difficulty.grid_stones = (0.0, 0.8)  # difficulty at level 0, top level [-]
    c.stage1_difficulty.two_row_stones = (0.0, 0.8)  # difficulty at level 0, top level [-]
    c.stage1_difficulty.rough_boxes = (0.0, 0.8)  # difficulty at level 0, top level [-]
    c.stage1_difficulty.platform_gap = (0.0, 0.8)  # difficulty at level 0, top level [-]
    c.stage1_difficulty.mixed_row_stones = (0.0, 0.8)  # difficulty at level 0, top level [-]
    # Stage 2: all nine types; stage-1 types start in a harder range.
    c.stage2_weights = ml_collections.ConfigDict()
    c.stage2_weights.grid_stones = 0.15  # share of columns [-]
    c.stage2_weights.two_row_stones = 0.15  # share of columns [-]
    c.stage2_weights.rough_boxes = 0.05  # share of columns [-]
    c.stage2_weights.platform_gap = 0.10  # share of columns [-]
    c.stage2_weights.mixed_row_stones = 0.15  # share of columns [-]
    c.stage2_weights.beam = 0.10  # share of columns [-]
    c.stage2_weights.stairs = 0.10  # share of columns [-]
    c.stage2_weights.pyramid_up = 0.10  # share of columns [-]
    c.stage2_weights.pyramid_down = 0.10  # share of columns [-]
    c.stage2_difficulty = ml_collections.ConfigDict()
    c.stage2_difficulty.grid_stones = (0.4, 1.0)  # difficulty at level 0, top level [-]
    c.stage2_difficulty.two_row_stones = (0.4, 1.0)  # difficulty at level 0, top level [-]
    c.stage2_difficulty.rough_boxes = (0.4, 1.0)  # difficulty at level 0, top level [-]
    c.stage2_difficulty.platform_gap = (0.4, 1.0)  # difficulty at level 0, top level [-]
    c.stage2_difficulty.mixed_row_stones = (0.4, 1.0)  # difficulty at level 0, top level [-]
    c.stage2_difficulty.beam = (0.0, 1.0)  # difficulty at level 0, top level [-]
    c.stage2_difficulty.stairs = (0.0, 1.0)  # difficulty at level 0, top level [-]
    c.stage2_difficulty.pyramid_up = (0.0, 1.0)  # difficulty at level 0, top level [-]
    c.stage2_difficulty.pyramid_down = (0.0, 1.0)  # difficulty at level 0, top level [-]
    # Spawn and goal spread (uniform, +-), around the start-platform / goal-region centres.
    c.spawn_x_spread_m = 0.1  # spawn x ~ U(+-this) around the start platform centre [m]
    c.spawn_y_spread_m = 0.2  # spawn y ~ U(+-this) around the tile centre line [m]
    c.spawn_yaw_spread_rad = 0.3  # spawn yaw ~ U(+-this) around +x [rad]
    c.goal_x_spread_m = 0.2  # goal x ~ U(+-this) around the goal region centre [m]
    c.goal_y_spread_m = 0.2  # goal y ~ U(+-this) around the tile centre line [m]
    # Stone curriculum: how stone size, gap and height spread move with the difficulty
    # (foottof.terrain.tiles.STONE_CURRICULA): "size_first" shrinks the stones to the ensemble's
    # size at 0.10 m gaps first, then widens the gaps, then spreads the tops; "gaps_first" (runs
    # saved before 2026-12-07) widens the gaps first and shrinks the stones last. Both hold the
    # same stones from d = 0.72 (the evaluation ensemble) on.
    c.stone_curriculum = "size_first"
    # Curriculum (foottof/terrain/curriculum.py).
    c.init_level_max = 2  # initial level ~ U{0..init_level_max} [level]
    c.down_progress_frac = 0.5  # move down when covered < this fraction of the goal distance [-]
    c.up_progress_frac = 0.8  # move up when covered >= this fraction (or reached the goal) [-]
    c.no_promotion_on_fall = True  # an episode that ended in a failure is not promoted [-]
    return c
