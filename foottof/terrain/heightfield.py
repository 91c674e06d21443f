"""Heightfield container shared by physics (MuJoCo hfield), sensors (ray caster) and terrain."""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from flax import struct


@struct.dataclass
class Heightfield:
    """World-frame terrain heights on MuJoCo's heightfield vertex grid.

    Layout follows MuJoCo exactly (checked with ``mj_ray``): vertex ``(i, j)`` of ``heights``
    (row ``i``, column ``j``) sits at ``x = x0_m + j * cell_m``, ``y = y0_m + i * cell_m``, so rows
    run along +y and columns along +x. MuJoCo triangulates each cell into two triangles; the
    surface the feet collide with and the rays hit is that triangulated surface.

    MuJoCo stores normalized elevations in [0, 1]: ``z = z_floor_m + data * z_range_m``, with the
    hfield geom placed at ``(x0_m + rx, y0_m + ry, z_floor_m)`` and ``size = (rx, ry, z_range_m,
    base_m)``, ``rx = (ncol - 1) * cell_m / 2``, ``ry = (nrow - 1) * cell_m / 2``. Heights outside
    ``[z_floor_m, z_floor_m + z_range_m]`` are clipped when written to MuJoCo.

    Attributes:
      heights: (nrow, ncol) world z of each vertex [m]. The only array leaf, so a new terrain can
        be swapped into a compiled step without recompiling.
      x0_m, y0_m: world x, y of vertex (0, 0) [m] (static).
      cell_m: vertex spacing, the same along x and y [m] (static).
      z_floor_m: world z of elevation 0, the floor of the pits [m] (static).
      z_range_m: elevation range, MuJoCo's size[2] [m] (static).
      base_m: thickness of the solid box under the floor, MuJoCo's size[3] [m] (static).
    """

    heights: jax.Array
    x0_m: float = struct.field(pytree_node=False, default=0.0)
    y0_m: float = struct.field(pytree_node=False, default=0.0)
    cell_m: float = struct.field(pytree_node=False, default=0.04)
    z_floor_m: float = struct.field(pytree_node=False, default=-1.0)
    z_range_m: float = struct.field(pytree_node=False, default=2.0)
    base_m: float = struct.field(pytree_node=False, default=0.1)

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.heights.shape)  # type: ignore[return-value]

    @property
    def nrow(self) -> int:
        return int(self.heights.shape[0])

    @property
    def ncol(self) -> int:
        return int(self.heights.shape[1])

    @property
    def half_extents_m(self) -> tuple[float, float]:
        """MuJoCo's (rx, ry): half sizes along x and y [m]."""
        return ((self.ncol - 1) * self.cell_m / 2.0, (self.nrow - 1) * self.cell_m / 2.0)

    @property
    def geom_pos(self) -> tuple[float, float, float]:
        """World position of the hfield geom [m]."""
        rx, ry = self.half_extents_m
        return (self.x0_m + rx, self.y0_m + ry, self.z_floor_m)

    @property
    def mj_size(self) -> tuple[float, float, float, float]:
        """MuJoCo hfield ``size`` attribute (rx, ry, z_range, base)."""
        rx, ry = self.half_extents_m
        return (rx, ry, self.z_range_m, self.base_m)

    def normalized(self) -> jax.Array:
        """(nrow * ncol,) elevations in [0, 1], row-major, as MuJoCo's ``hfield_data`` wants."""
        data = (jp.asarray(self.heights) - self.z_floor_m) / self.z_range_m
        return jp.clip(data, 0.0, 1.0).reshape(-1)

    def clipped(self) -> Heightfield:
        """The heights MuJoCo actually uses (clipped to the representable range)."""
        lo, hi = self.z_floor_m, self.z_floor_m + self.z_range_m
        return self.replace(heights=jp.clip(self.heights, lo, hi))

    def height_at(self, xy: jax.Array, patch_gather: bool = False) -> jax.Array:
        """Height of MuJoCo's triangulated surface at world (..., 2) points [m], clamped at edges.

        Uses the same triangle split as MuJoCo (diagonal from vertex (i, j) to (i+1, j+1)).
        ``patch_gather`` (static) reads the 2 x 2 vertices around each point as one gather
        instead of four: the same values, and on XLA's CPU backend faster where the lookup is
        materialized (the index is computed once, not per vertex), slower where it is fused into
        its consumer (bench/NOTES.md item 10).
        """
        h = self.clipped().heights
        u = jp.clip((xy[..., 0] - self.x0_m) / self.cell_m, 0.0, self.ncol - 1.000001)
        v = jp.clip((xy[..., 1] - self.y0_m) / self.cell_m, 0.0, self.nrow - 1.000001)
        j = jp.floor(u).astype(jp.int32)
        i = jp.floor(v).astype(jp.int32)
        fu, fv = u - j, v - i
        if patch_gather:
            # i, j can reach nrow - 1, ncol - 1 (the clips above round up in float32), where the
            # four-gather lookup clamps i + 1, j + 1: an edge-replicated row and column match it.
            patch = jax.lax.gather(
                jp.pad(h, ((0, 1), (0, 1)), mode="edge"),
                jp.stack([i, j], axis=-1),
                jax.lax.GatherDimensionNumbers(
                    offset_dims=(i.ndim, i.ndim + 1),
                    collapsed_slice_dims=(),
                    start_index_map=(0, 1),
                ),
                slice_sizes=(2, 2),
                mode=jax.lax.GatherScatterMode.PROMISE_IN_BOUNDS,  # i <= nrow - 1 (padded)
            )
            h00, h01 = patch[..., 0, 0], patch[..., 0, 1]
            h10, h11 = patch[..., 1, 0], patch[..., 1, 1]
        else:
            h00 = h[i, j]
            h01 = h[i, j + 1]
            h10 = h[i + 1, j]
            h11 = h[i + 1, j + 1]
        # Lower triangle (fu >= fv): (0,0), (0,1), (1,1); upper: (0,0), (1,0), (1,1).
        lower = h00 + fu * (h01 - h00) + fv * (h11 - h01)
        upper = h00 + fv * (h10 - h00) + fu * (h11 - h10)
        return jp.where(fu >= fv, lower, upper)


def hfield_xml(hf: Heightfield, name: str = "terrain", geom_attrs: str = "") -> tuple[str, str]:
    """MJCF snippets for ``hf``: (asset element, worldbody geom element).

    The asset carries only sizes; write the data with :func:`write_to_mjmodel` after compiling
    (MuJoCo normalizes ``elevation`` given in XML, so we set ``hfield_data`` directly).
    """
    rx, ry, zr, base = hf.mj_size
    px, py, pz = hf.geom_pos
    asset = (
        f'<hfield name="{name}" nrow="{hf.nrow}" ncol="{hf.ncol}" '
        f'size="{rx:.6f} {ry:.6f} {zr:.6f} {base:.6f}"/>'
    )
    geom = (
        f'<geom name="{name}" type="hfield" hfield="{name}" pos="{px:.6f} {py:.6f} {pz:.6f}" '
        f"{geom_attrs}/>"
    )
    return asset, geom


def write_to_mjmodel(m, hf: Heightfield, name: str = "terrain") -> None:
    """Write ``hf`` into a compiled ``mujoco.MjModel`` in place (same shape required)."""
    import mujoco

    hid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_HFIELD, name)
    if hid < 0:
        raise ValueError(f"MjModel has no hfield named {name!r}")
    nrow, ncol = int(m.hfield_nrow[hid]), int(m.hfield_ncol[hid])
    if (nrow, ncol) != hf.shape:
        raise ValueError(f"heightfield shape {hf.shape} != model hfield shape {(nrow, ncol)}")
    adr = int(m.hfield_adr[hid])
    m.hfield_data[adr : adr + nrow * ncol] = np.asarray(hf.normalized(), dtype=np.float32)


def write_to_mjx(mx, hf: Heightfield, hfield_id: int = 0):
    """Return an ``mjx.Model`` whose hfield ``hfield_id`` holds ``hf`` (pure; jit-able, no recompile).

    Assumes the model has this single hfield starting at address 0 of ``hfield_data``.
    """
    del hfield_id
    data = hf.normalized().astype(mx.hfield_data.dtype)
    return mx.replace(hfield_data=mx.hfield_data.at[: data.shape[0]].set(data))
