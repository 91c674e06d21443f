"""Terrain: heightfield container, tile generators, terrain map and curriculum."""

from foottof.terrain.curriculum import (
    progress_fraction,
    update_levels,
)
from foottof.terrain.heightfield import Heightfield
from foottof.terrain.terrain_map import (
    SPAWN_X,
    SPAWN_Y,
    SPAWN_YAW,
    SPAWN_Z,
    TerrainMap,
    TerrainMapSpec,
    allocate_columns,
    build_terrain_map,
    make_eval_map_spec,
    sample_spawn_goal,
    tile_at,
)
from foottof.terrain.tiles import (
    SPAWN_SURFACE_Z_M,
    STAGE1_TYPES,
    TERRAIN_TYPES,
    TileSpec,
    generate_tile,
)

__all__ = [
    "Heightfield",
    "SPAWN_SURFACE_Z_M",
    "SPAWN_X",
    "SPAWN_Y",
    "SPAWN_YAW",
    "SPAWN_Z",
    "STAGE1_TYPES",
    "TERRAIN_TYPES",
    "TerrainMap",
    "TerrainMapSpec",
    "TileSpec",
    "allocate_columns",
    "build_terrain_map",
    "generate_tile",
    "make_eval_map_spec",
    "progress_fraction",
    "sample_spawn_goal",
    "tile_at",
    "update_levels",
]
