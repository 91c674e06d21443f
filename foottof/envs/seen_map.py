"""Where the foot sensors have looked this episode: a per-env grid of the terrain cells that a
ToF ray has hit (env.actor_terrain_seen, a teacher limited to what its ToF student can know).

The grid is world-aligned and anchored at the episode's spawn: cells of ``cell_m`` from
``back_m`` behind the spawn to ``ahead_m`` in front of it along world x (the walking direction of
every tile), ``half_width_m`` either side along y. Each control step marks the cells of the
noise-free ray hits of every foot sensor (:func:`foottof.sensors.tof.sense_and_hits`); a point
outside the grid reads as never seen. The terrain is static, so a cell once hit stays known for
the episode: what a student could at best remember of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jp


@dataclass(frozen=True)
class SeenGrid:
    """The static geometry of the grid (a hashable spec: close over it in jitted code).

    Attributes:
      cell_m: cell size [m] (the heightfield's vertex spacing).
      back_m, ahead_m: extent behind / in front of the spawn along world x [m].
      half_width_m: extent either side of the spawn along world y [m].
    """

    cell_m: float = 0.04
    back_m: float = 1.0
    ahead_m: float = 7.0
    half_width_m: float = 2.0

    def __post_init__(self):
        for name in ("cell_m", "back_m", "ahead_m", "half_width_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"SeenGrid.{name}={v} must be a finite length > 0 [m]")

    @property
    def shape(self) -> tuple[int, int]:
        """(cells along x, cells along y)."""
        nx = int(math.ceil((self.back_m + self.ahead_m) / self.cell_m))
        ny = int(math.ceil(2 * self.half_width_m / self.cell_m))
        return nx, ny

    def init(self, spawn_xy: jax.Array) -> tuple[jax.Array, jax.Array]:
        """(origin (2,) world x, y of cell (0, 0)'s low corner [m], seen (nx, ny) bool, all False)
        of a fresh episode spawned at ``spawn_xy``."""
        origin = jp.asarray(spawn_xy, jp.float32)[:2] - jp.array(
            [self.back_m, self.half_width_m], jp.float32
        )
        return origin, jp.zeros(self.shape, bool)

    def _cells(self, origin, xy):
        ij = jp.floor((xy[..., :2] - origin) / self.cell_m).astype(jp.int32)
        nx, ny = self.shape
        inside = (ij[..., 0] >= 0) & (ij[..., 0] < nx) & (ij[..., 1] >= 0) & (ij[..., 1] < ny)
        return ij, inside

    def mark(self, origin, seen, points, ok) -> jax.Array:
        """``seen`` with the cells of ``points`` (N, 2 or 3) world [m] set where ``ok`` (N,)."""
        ij, inside = self._cells(origin, points)
        keep = ok & inside
        nx, ny = self.shape
        # points to drop go to an out-of-range index, which scatter's mode="drop" ignores
        i = jp.where(keep, ij[..., 0], nx)
        j = jp.where(keep, ij[..., 1], ny)
        return seen.at[i, j].set(True, mode="drop")

    def lookup(self, origin, seen, points) -> jax.Array:
        """(...,) bool: whether the cell of each of ``points`` (..., 2 or 3) world [m] is marked
        (False outside the grid)."""
        ij, inside = self._cells(origin, points)
        nx, ny = self.shape
        got = seen[jp.clip(ij[..., 0], 0, nx - 1), jp.clip(ij[..., 1], 0, ny - 1)]
        return got & inside
