"""VL53L5CX foot ToF model: zone rays from site frames, zone minimum, clipping, quantization."""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

from foottof import config_check, constants
from foottof.limits import TILT_LIMIT_DEG  # |extra tilt| about each site axis
from foottof.sensors.raycast import ray_heightfield_normal
from foottof.terrain.heightfield import Heightfield


@dataclasses.dataclass(frozen=True)
class ToFSpec:
    """Static sensor geometry and frame rate (hashable; read from config outside jit).

    Zone layout: the FoV is split in the sensor's image plane (pinhole model: uniform in
    ``tan(angle)``, as a flat SPAD array behind a lens) into ``grid x grid`` zones. Zone index
    ``z = row * grid + col``; ``row`` increases along the sensor +x axis (the leg's forward
    direction; row 0 looks most backward) and ``col`` along the sensor +y axis. The optical axis
    is the sensor +z axis.

    Sensor frame = site frame (``site_xmat`` columns: +x forward, +z optical axis) rotated by the
    extra tilt ``R_x(tilt_x) @ R_y(tilt_y)`` (right-handed, about the site axes) and shifted by
    ``offset_m`` (site frame). The sites already include the foot's 15 deg outward tilt.

    Attributes:
      num_sensors: F, sensors per robot; sensor f sits on the f-th site row passed to
        :func:`sense` (several sensors may share a site).
      grid: zones per side (4 or 8).
      fov_deg: full field of view per side [deg].
      max_range_m: readings beyond this are clipped to it and flagged invalid [m].
      resolution_m: range quantization step [m].
      rate_hz: frame rate [Hz] (<= 60 for 4x4, <= 15 for 8x8).
      tilt_deg: F pairs (tilt_x, tilt_y), extra rotation about the site x then y axis [deg].
      offset_m: F triples, sensor origin in the site frame [m].
    """

    num_sensors: int = constants.NUM_FEET
    grid: int = constants.TOF_GRID
    fov_deg: float = constants.TOF_FOV_DEG
    max_range_m: float = constants.TOF_MAX_RANGE_M
    resolution_m: float = 0.001
    rate_hz: float = constants.TOF_RATE_HZ
    tilt_deg: tuple = ((0.0, 0.0),) * constants.NUM_FEET
    offset_m: tuple = ((0.0, 0.0, 0.0),) * constants.NUM_FEET

    @classmethod
    def from_config(cls, sensor_cfg) -> ToFSpec:
        """ToFSpec from the ``sensor`` config section (frame timing: foottof.sensors.timing).

        Raises:
          ValueError: bad resolution, rate, tilt, offsets or sensor count (message names the value).
        """
        n = len(sensor_cfg.sites)
        tilt_x = tuple(float(v) for v in sensor_cfg.tilt_x_deg)
        tilt_y = tuple(float(v) for v in sensor_cfg.tilt_y_deg)
        if len(tilt_x) != n or len(tilt_y) != n:
            raise ValueError(
                f"sensor.tilt_x_deg / tilt_y_deg need one value per site ({n}), got {len(tilt_x)} / "
                f"{len(tilt_y)}"
            )
        return cls(
            num_sensors=n,
            grid=int(sensor_cfg.grid),
            fov_deg=float(sensor_cfg.fov_deg),
            max_range_m=float(sensor_cfg.max_range_m),
            resolution_m=float(sensor_cfg.resolution_m),
            rate_hz=float(sensor_cfg.rate_hz),
            tilt_deg=tuple(zip(tilt_x, tilt_y, strict=True)),
            offset_m=tuple(tuple(float(c) for c in o) for o in sensor_cfg.offset_m),
        )

    def __post_init__(self):
        config_check.check_fields(  # the sensor.* rules, defined once (foottof.config_check)
            "sensor",
            {
                "grid": self.grid,
                "fov_deg": self.fov_deg,
                "max_range_m": self.max_range_m,
                "resolution_m": self.resolution_m,
                "rate_hz": self.rate_hz,
            },
        )
        if self.num_sensors < 1:
            raise ValueError(f"num_sensors must be >= 1, got {self.num_sensors!r}")
        if np.shape(self.tilt_deg) != (self.num_sensors, 2):
            raise ValueError(
                f"tilt_deg must hold num_sensors={self.num_sensors} (tilt_x, tilt_y) pairs, got "
                f"shape {np.shape(self.tilt_deg)}"
            )
        if np.any(np.abs(np.asarray(self.tilt_deg, float)) >= TILT_LIMIT_DEG):
            raise ValueError(
                f"tilt_deg {self.tilt_deg!r} out of range: each extra tilt must be in "
                f"(-{TILT_LIMIT_DEG}, {TILT_LIMIT_DEG}) deg"
            )
        if np.shape(self.offset_m) != (self.num_sensors, 3):
            raise ValueError(
                f"offset_m must hold num_sensors={self.num_sensors} (x, y, z) triples, got shape "
                f"{np.shape(self.offset_m)}"
            )

    @property
    def num_zones(self) -> int:
        return self.grid * self.grid

    @property
    def num_rays(self) -> int:
        """Rays per sensor: (grid + 1)^2 zone corners + grid^2 zone centres (41 for 4x4)."""
        return (self.grid + 1) ** 2 + self.grid**2

    @property
    def frame_period_s(self) -> float:
        return 1.0 / self.rate_hz

    def ray_directions(self) -> np.ndarray:
        """(num_rays, 3) unit ray directions in the sensor frame.

        Order: the (grid + 1)^2 corners row-major (corner (a, b) at row line a, col line b),
        then the grid^2 zone centres row-major (same order as the zones).
        """
        g, half = self.grid, math.tan(math.radians(self.fov_deg / 2.0))
        edges = np.linspace(-half, half, g + 1)
        mids = (edges[:-1] + edges[1:]) / 2.0
        cx, cy = np.meshgrid(edges, edges, indexing="ij")
        mx, my = np.meshgrid(mids, mids, indexing="ij")
        tx = np.concatenate([cx.ravel(), mx.ravel()])
        ty = np.concatenate([cy.ravel(), my.ravel()])
        v = np.stack([tx, ty, np.ones_like(tx)], -1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def zone_rays(self) -> np.ndarray:
        """(num_zones, 5) ray indices per zone: 4 corners in cyclic order, then the centre."""
        g, nc = self.grid, (self.grid + 1) ** 2
        out = []
        for r in range(g):
            for c in range(g):
                corner = lambda a, b: a * (g + 1) + b
                out.append(
                    [
                        corner(r, c),
                        corner(r, c + 1),
                        corner(r + 1, c + 1),
                        corner(r + 1, c),
                        nc + r * g + c,
                    ]
                )
        return np.asarray(out, np.int32)

    def mount_rotations(self) -> np.ndarray:
        """(F, 3, 3) sensor axes in the site frame (columns), from the extra tilts."""
        out = []
        for tx, ty in np.asarray(self.tilt_deg, float):
            a, b = math.radians(tx), math.radians(ty)
            rx = np.array(
                [[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]]
            )
            ry = np.array(
                [[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]]
            )
            out.append(rx @ ry)
        return np.asarray(out)


def make_spec(sensor_cfg) -> ToFSpec:
    """Alias of :meth:`ToFSpec.from_config` (the name before the one adapter convention)."""
    return ToFSpec.from_config(sensor_cfg)


def site_ids(m, names) -> np.ndarray:
    """(F,) MuJoCo site ids of ``names`` (e.g. constants.TOF_SITES), for gathering site frames."""
    import mujoco

    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, n) for n in names]
    missing = [n for n, i in zip(names, ids, strict=True) if i < 0]
    if missing:
        raise ValueError(f"model has no site(s) {missing}")
    return np.asarray(ids, np.int32)


@struct.dataclass
class ToFReading:
    """One noise-free sensor frame.

    Attributes:
      distance_m: (F, Z) zone range [m], quantized; ``max_range_m`` where invalid.
      valid: (F, Z) bool, a return within ``max_range_m``.
      incidence_rad: (F, Z) angle between the ray and the surface normal at the nearest of the
        zone's rays [rad] (0 = perpendicular); 0 where invalid.
    """

    distance_m: jax.Array
    valid: jax.Array
    incidence_rad: jax.Array


def sensor_frames(spec: ToFSpec, site_pos, site_rot):
    """World sensor origins (F, 3) and axes (F, 3, 3) from site frames (F, 3), (F, 3, 3)."""
    site_pos = jp.asarray(site_pos)
    site_rot = jp.asarray(site_rot)
    if site_pos.shape != (spec.num_sensors, 3) or site_rot.shape != (spec.num_sensors, 3, 3):
        raise ValueError(
            f"site_pos / site_rot must have shapes ({spec.num_sensors}, 3) / "
            f"({spec.num_sensors}, 3, 3), got {site_pos.shape} / {site_rot.shape}"
        )
    mount = jp.asarray(spec.mount_rotations(), site_rot.dtype)
    offset = jp.asarray(spec.offset_m, site_pos.dtype)
    rot = site_rot @ mount
    pos = site_pos + jp.einsum("fij,fj->fi", site_rot, offset)
    return pos, rot


def _segment_dist(a, b):
    """Distance from the origin to segments a-b, (..., 3) each."""
    ab = b - a
    s = jp.clip(-jp.sum(a * ab, -1) / jp.maximum(jp.sum(ab * ab, -1), 1e-12), 0.0, 1.0)
    return jp.linalg.norm(a + s[..., None] * ab, axis=-1)


def _triangle_plane_dist(a, b, c):
    """Distance from the origin to triangle abc's plane where its foot lies inside, else inf."""
    n = jp.cross(b - a, c - a)
    nn = jp.sum(n * n, -1)
    ok = nn > 1e-12
    s = jp.sum(a * n, -1) / jp.where(ok, nn, 1.0)
    foot = s[..., None] * n
    inside = jp.ones(s.shape, bool)
    for p, q in ((a, b), (b, c), (c, a)):
        inside = inside & (jp.sum(jp.cross(q - p, foot - p) * n, -1) >= 0.0)
    return jp.where(ok & inside, jp.abs(s) * jp.sqrt(nn), jp.inf)


def zone_minimum(spec: ToFSpec, hit_dist, hit_valid, dirs_world):
    """Nearest distance per zone from its 5 rays, by linear interpolation of the hit points.

    Each zone is covered by the fan of 4 triangles (centre, corner_i, corner_i+1) through its hit
    points; the reading is the smallest distance from the sensor origin to that piecewise-linear
    patch (closest point on each triangle whose 3 rays hit; plus segments and single hit points
    where some rays miss). On a plane this is the exact nearest radial distance in the zone, even
    when the nearest point lies inside the zone (a ToF measures the path length, i.e. radial
    range). Zones where no ray hits within range are invalid.

    Args:
      spec: sensor spec.
      hit_dist: (F, R) ray hit distance [m] (-1 = miss).
      hit_valid: (F, R) bool.
      dirs_world: (F, R, 3) unit ray directions.

    Returns:
      dist: (F, Z) [m] (inf where invalid); nearest_ray: (F, Z) index into the zone's 5 rays.
    """
    zr = jp.asarray(spec.zone_rays())  # (Z, 5)
    pts = jp.where(hit_valid[..., None], hit_dist[..., None] * dirs_world, 0.0)[:, zr]  # (F,Z,5,3)
    ok = hit_valid[:, zr]  # (F, Z, 5)
    dv = jp.where(ok, hit_dist[:, zr], jp.inf)
    best = jp.min(dv, -1)
    nearest = jp.argmin(dv, -1)
    ctr, ok_c = pts[..., 4, :], ok[..., 4]
    for i in range(4):
        a, ok_a = pts[..., i, :], ok[..., i]
        b, ok_b = pts[..., (i + 1) % 4, :], ok[..., (i + 1) % 4]
        best = jp.minimum(best, jp.where(ok_a & ok_b, _segment_dist(a, b), jp.inf))
        best = jp.minimum(best, jp.where(ok_a & ok_c, _segment_dist(a, ctr), jp.inf))
        tri = _triangle_plane_dist(ctr, a, b)
        best = jp.minimum(best, jp.where(ok_a & ok_b & ok_c, tri, jp.inf))
    return best, nearest


def sensor_rays(spec: ToFSpec, site_pos, site_rot):
    """(F, 3) world sensor origins [m] and (F, R, 3) unit world ray directions of every sensor
    (site pose as in :func:`cast_rays`)."""
    pos, rot = sensor_frames(spec, site_pos, site_rot)
    return pos, jp.einsum("fij,rj->fri", rot, jp.asarray(spec.ray_directions(), rot.dtype))


def cast_rays(spec: ToFSpec, hfield: Heightfield, site_pos, site_rot):
    """Casts every sensor's rays against the heightfield up to ``max_range_m``.

    The rays :func:`sense` turns into zone readings (also used to draw them in videos).

    Args:
      spec: sensor spec (static).
      hfield: terrain.
      site_pos: (F, 3) world position of each sensor's site [m].
      site_rot: (F, 3, 3) site axes as columns.

    Returns:
      origins (F, 3) world sensor origins [m], dirs (F, R, 3) unit world ray directions,
      t (F, R) hit distance [m] (-1 = no hit within range), normals (F, R, 3) at the hits.
    """
    pos, dirs = sensor_rays(spec, site_pos, site_rot)
    f, r = spec.num_sensors, spec.num_rays
    origins = jp.broadcast_to(pos[:, None, :], (f, r, 3)).reshape(-1, 3)
    t, n = ray_heightfield_normal(hfield, origins, dirs.reshape(-1, 3), spec.max_range_m)
    return pos, dirs, t.reshape(f, r), n.reshape(f, r, 3)


def sense(spec: ToFSpec, hfield: Heightfield, site_pos, site_rot) -> ToFReading:
    """The reading of :func:`sense_and_hits` (see there)."""
    return sense_and_hits(spec, hfield, site_pos, site_rot)[0]


def sense_and_hits(spec: ToFSpec, hfield: Heightfield, site_pos, site_rot):
    """Noise-free VL53L5CX frame of every sensor of one robot.

    Casts ``spec.num_rays`` rays per sensor (41 for 4x4) against the heightfield up to
    ``max_range_m``, takes the zone minimum (:func:`zone_minimum`), quantizes to
    ``resolution_m`` and clips: no return within ``max_range_m`` -> ``max_range_m``, invalid.
    jit-able; vmap over envs with ``in_axes=(None, None, 0, 0)`` for (spec, hfield, pos, rot)
    (``spec`` is static: close over it).

    Args:
      spec: sensor spec (static).
      hfield: terrain.
      site_pos: (F, 3) world position of each sensor's site [m] (``d.site_xpos[ids]``).
      site_rot: (F, 3, 3) site axes as columns (``d.site_xmat[ids].reshape(-1, 3, 3)``).

    Returns:
      (ToFReading with (F, Z) arrays, hit points (F, R, 3) world [m] of every ray, hit (F, R)
      bool: the ray hit the terrain within ``max_range_m``; where not, the point is the origin).
    """
    origins, dirs, t, n = cast_rays(spec, hfield, site_pos, site_rot)
    hit = t >= 0.0
    dist, nearest = zone_minimum(spec, t, hit, dirs)
    zr = jp.asarray(spec.zone_rays())
    ray_idx = jp.take_along_axis(jp.broadcast_to(zr, dist.shape + (5,)), nearest[..., None], -1)[
        ..., 0
    ]  # (F, Z) index into the sensor's rays
    cos_inc = jp.abs(
        jp.sum(
            jp.take_along_axis(dirs, ray_idx[..., None], 1)
            * jp.take_along_axis(n, ray_idx[..., None], 1),
            -1,
        )
    )
    valid = dist <= spec.max_range_m
    q = spec.resolution_m
    dist_q = jp.minimum(jp.round(dist / q) * q, spec.max_range_m)
    incidence = jp.where(valid, jp.arccos(jp.clip(cos_inc, 0.0, 1.0)), 0.0)
    reading = ToFReading(
        distance_m=jp.where(valid, dist_q, spec.max_range_m).astype(jp.float32),
        valid=valid,
        incidence_rad=incidence.astype(jp.float32),
    )
    points = origins[:, None, :] + jp.where(hit, t, 0.0)[..., None] * dirs
    return reading, points, hit
