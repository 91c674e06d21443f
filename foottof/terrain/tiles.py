"""Pure-JAX generators of the nine training terrain tiles (heights in metres, static shapes)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import jax
import jax.numpy as jp
import numpy as np

from foottof import config_check, constants
from foottof.limits import ENSEMBLE_KNOT, STONE_TYPES  # noqa: F401 (re-exported)

# The paper's nine types, in order: stage 1 (first five), then the four stage-2 additions.
TERRAIN_TYPES = (
    "grid_stones",
    "two_row_stones",
    "rough_boxes",
    "platform_gap",
    "mixed_row_stones",
    "beam",
    "stairs",
    "pyramid_up",
    "pyramid_down",
)
STAGE1_TYPES = TERRAIN_TYPES[:5]
PIT_TYPES = ("grid_stones", "two_row_stones", "platform_gap", "mixed_row_stones", "beam")

# Spawn surface height per type: every start platform (and goal region) is flat at z = 0 [m], so
# the spawn surface is 0 for all nine types; the env adds its base height on top.
SPAWN_SURFACE_Z_M = {name: 0.0 for name in TERRAIN_TYPES}

# Rendering (how solids are drawn on the vertex grid). The heightfield is piecewise linear between
# vertices, so a solid whose outermost vertices lie inside its outline has a flat top one cell
# shorter than the outline on average, and every gap opens one cell wider than nominal at the top
# (a 5 cm gap on a 4 cm grid became a ~9 cm V-trench that swallowed a 6.3 cm foot ~20 cm deep). A
# vertex is therefore solid when it lies within half a cell of a stone, platform or beam: the mean
# flat-top extent is then the nominal size and the mean top opening of a gap the nominal gap (for
# gaps wider than two cells); gaps narrower than one cell, which no foot fits, are not drawn.
#
# Cracks (see _finish). A gap 4-12 cm wide is drawn as one or two pit vertices: a V-notch whose
# sloped walls wedge a foot sphere (MuJoCo C: a 3.15 cm foot pressed with 130 N stuck 0.26 m deep
# in a one-vertex notch, 0.77 m in a two-vertex one; ../shared/probes/crack_notch_drop.py). A real
# crack narrower than the foot (diameter D) only lets the foot dip by the sag of a circle over a
# chord, r - sqrt(r^2 - (w / 2)^2) <= r. So a pit vertex whose gap is nominally narrower than the
# foot is drawn that sag below the surrounding top (the foot cannot sink deeper than the drawn
# bottom), and only gaps at least as wide as the foot are drawn to the pit floor; a foot that goes
# into one of those is a fall, ended by the env's stuck-foot termination (env.foot_stuck_depth_m)
# rather than left wedged. The stone curricula never draw gaps narrower than the foot past
# level 0 (see STONE_CURRICULA), platform gaps at their easiest level do.

TWO_ROW_HALF_SPACING_M = 0.30  # row centres at y = centre +- this; ANYmal-D feet are at +-0.31 m
STAIRS_MAX_RISE_M = 0.8  # total rise (or drop) of a stairs tile is capped at this [m]
PYRAMID_MAX_HEIGHT_M = 0.6  # pyramids are truncated (flat top / bottom) at this height [m]

# Stone curricula (terrain.stone_curriculum), piecewise linear in the difficulty d through their
# knots. Both end at the same values from d = 0.72 on (the evaluation ensemble: 90 % of the
# stage-1 range (0, 0.8)): those of the earlier linear schedules (size, gap, spread, jitter), so
# the ensemble's stones and gaps are the same whichever curriculum a policy trained on. Jitter is
# a fraction of the gap. At d = 0 (level 0) every gap is 4-6 cm wide, narrower than the 6.3 cm
# foot, and drawn as a shallow crack (harmless, as a real one is); from d = 0.08 on every gap is
# wider than the foot (at least 0.8 x the nominal gap) and drawn to the pit floor. Only a
# difficulty in (0.007, 0.08) mixes the two (gaps of 5.3-7.9 cm straddle the foot): no level of
# the stage-1 range lies there.
#
# "size_first" (the default since 2026-12-07; the paper's "dense grid stones", legged_gym's
# stones that shrink at a fixed 0.1 m gap): the stones shrink to the ensemble's size while the
# gaps stay 0.10 m and the tops level (d 0 -> 0.36, geometric steps of ~0.75 per level of 10 over
# (0, 0.8)), then the gaps widen to the ensemble's (0.36 -> 0.54, with the jitter, the missing
# stones and the two-row lateral offsets), then the tops spread (0.54 -> 0.72).
# "gaps_first" (before; what configs saved without terrain.stone_curriculum trained on): the gaps
# between few, large stones widen (d 0 -> 0.4, stones keep their size, level tops), then the
# stones shrink and the height spread grows (0.4 -> 0.72): a policy met stones of the ensemble's
# size only at level 8.
STONE_CURRICULA = {
    "size_first": {
        "knots": (0.0, 0.08, 0.18, 0.27, 0.36, 0.54, 0.72, 1.0),
        # name: {parameter: values at the knots}
        "grid_stones": {
            "size": (1.00, 0.76, 0.55, 0.40, 0.2976, 0.2976, 0.2976, 0.18),  # stone top [m]
            "gap": (0.05, 0.10, 0.10, 0.10, 0.10, 0.266, 0.266, 0.35),  # nominal gap [m]
            "dz": (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.144, 0.20),  # top height spread, p-p [m]
            "jitter": (0.10, 0.10, 0.10, 0.10, 0.10, 0.25, 0.25, 0.25),  # x gap, per axis [-]
            "f_lo": (1.0, 0.98, 0.96, 0.94, 0.9196, 0.9196, 0.9196, 0.90),  # size x U(f_lo, 1)
        },
        "two_row_stones": {
            "size": (0.80, 0.635, 0.49, 0.38, 0.2976, 0.2976, 0.2976, 0.18),
            "gap": (0.05, 0.10, 0.10, 0.10, 0.10, 0.338, 0.338, 0.45),
            "dz": (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.108, 0.15),
            "jitter": (0.10, 0.10, 0.10, 0.10, 0.10, 0.20, 0.20, 0.20),
            "f_lo": (1.0, 0.98, 0.96, 0.94, 0.9196, 0.9196, 0.9196, 0.90),
            "lateral": (0.0, 0.0, 0.0, 0.0, 0.0, 0.036, 0.036, 0.05),  # lateral jitter, +- [m]
        },
        "mixed_row_stones": {
            "size": (0.90, 0.69, 0.49, 0.365, 0.2696, 0.2696, 0.2696, 0.18),  # largest top [m]
            "gap": (0.05, 0.10, 0.10, 0.10, 0.10, 0.302, 0.302, 0.40),
            "dz": (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.144, 0.20),
            "jitter": (0.10, 0.10, 0.10, 0.10, 0.10, 0.25, 0.25, 0.25),
            "f_lo": (1.0, 0.96, 0.91, 0.86, 0.806, 0.806, 0.806, 0.75),
            "keep": (1.0, 1.0, 1.0, 1.0, 1.0, 0.892, 0.892, 0.85),  # P(a stone is present) [-]
        },
    },
    "gaps_first": {
        "knots": (0.0, 0.4, 0.72, 1.0),
        "grid_stones": {
            "size": (1.00, 1.00, 0.2976, 0.18),  # stone top size [m]
            "gap": (0.05, 0.20, 0.266, 0.35),  # nominal gap between stones [m]
            "dz": (0.0, 0.0, 0.144, 0.20),  # peak-to-peak spread of the top heights [m]
            "jitter": (0.10, 0.10, 0.25, 0.25),  # centre jitter ~ U(+-this x gap) per axis [-]
            "f_lo": (1.0, 1.0, 0.9196, 0.90),  # size factor ~ U(f_lo, 1) per axis [-]
        },
        "two_row_stones": {
            "size": (0.80, 0.80, 0.2976, 0.18),
            "gap": (0.05, 0.24, 0.338, 0.45),
            "dz": (0.0, 0.0, 0.108, 0.15),
            "jitter": (0.10, 0.10, 0.20, 0.20),
            "f_lo": (1.0, 1.0, 0.9196, 0.90),
            "lateral": (0.0, 0.0, 0.036, 0.05),  # lateral jitter of each stone, +- [m]
        },
        "mixed_row_stones": {
            "size": (0.90, 0.90, 0.2696, 0.18),  # largest stone top; each ~ U(f_lo, 1) x size [m]
            "gap": (0.05, 0.22, 0.302, 0.40),
            "dz": (0.0, 0.0, 0.144, 0.20),  # low bricks dz lower, high stones dz higher [m]
            "jitter": (0.10, 0.10, 0.25, 0.25),
            "f_lo": (1.0, 1.0, 0.806, 0.75),
            "keep": (1.0, 1.0, 0.892, 0.85),  # probability that a stone is present [-]
        },
    },
}
STONE_CURRICULUM_NAMES = tuple(STONE_CURRICULA)  # valid terrain.stone_curriculum values
DEFAULT_STONE_CURRICULUM = "size_first"
# The default curriculum's knots and schedules (earlier code imported these names).
STONE_KNOTS = STONE_CURRICULA[DEFAULT_STONE_CURRICULUM]["knots"]
STONE_SCHEDULES = {
    k: v for k, v in STONE_CURRICULA[DEFAULT_STONE_CURRICULUM].items() if k != "knots"
}


@dataclasses.dataclass(frozen=True)
class TileSpec:
    """Static geometry of one tile (hashable, usable as a jit static argument).

    The tile's local vertex (i, j) sits at x = j * cell_m, y = i * cell_m (Heightfield layout: rows
    along +y, columns along +x). The robot walks along +x from the start platform (columns
    ``j < n_start``) to the goal region (columns ``j >= nx - n_goal``), both flat at z = 0; the
    course in between holds the terrain, with a pit at ``pit_z_m`` under stones and beams.

    Its fields obey config_check's terrain.* rules (a field named ``x_m`` here is the config's
    ``terrain.tile_x_m``) and ``env.model.foot_radius_m``; a bad one raises their one-line error.

    Attributes:
      length_m: extent along +x [m]; ``nx = length_m / cell_m`` vertex columns.
      width_m: extent along +y [m]; ``ny = width_m / cell_m`` vertex rows.
      cell_m: vertex spacing [m], at most foottof.limits.MAX_CELL_M.
      platform_length_m: start platform length along x [m].
      goal_length_m: goal region length along x [m].
      pit_z_m: pit floor z [m]; also the Heightfield floor (elevation 0).
      z_range_m: heights are clipped to [pit_z_m, pit_z_m + z_range_m] [m].
      foot_radius_m: foot sphere radius that sets how cracks are drawn (see Cracks above) [m].
      stone_curriculum: which of STONE_CURRICULA the stone types follow in d.
    """

    length_m: float = 6.0
    width_m: float = 4.0
    cell_m: float = 0.04
    platform_length_m: float = 1.6
    goal_length_m: float = 1.0
    pit_z_m: float = -1.0
    z_range_m: float = 2.0
    foot_radius_m: float = constants.FOOT_RADIUS_M
    stone_curriculum: str = DEFAULT_STONE_CURRICULUM

    def __post_init__(self):
        config_check.check_fields(  # the terrain.* rules, held once (foottof.config_check)
            "terrain",
            {
                "tile_length_m": self.length_m,
                "tile_width_m": self.width_m,
                "cell_m": self.cell_m,
                "platform_length_m": self.platform_length_m,
                "goal_length_m": self.goal_length_m,
                "pit_z_m": self.pit_z_m,
                "z_range_m": self.z_range_m,
                "stone_curriculum": self.stone_curriculum,
            },
        )
        config_check.check_fields("env.model", {"foot_radius_m": self.foot_radius_m})

    @property
    def nx(self) -> int:
        return round(self.length_m / self.cell_m)

    @property
    def ny(self) -> int:
        return round(self.width_m / self.cell_m)

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx): vertex rows (along +y) and columns (along +x)."""
        return (self.ny, self.nx)

    @property
    def n_start(self) -> int:
        """Number of start-platform vertex columns."""
        return round(self.platform_length_m / self.cell_m)

    @property
    def n_goal(self) -> int:
        """Number of goal-region vertex columns."""
        return round(self.goal_length_m / self.cell_m)

    @property
    def course_x0_m(self) -> float:
        """Local x of the first course vertex (the start platform ends one cell before) [m]."""
        return self.n_start * self.cell_m

    @property
    def course_x1_m(self) -> float:
        """Local x of the first goal-region vertex [m]."""
        return (self.nx - self.n_goal) * self.cell_m

    @property
    def spawn_xy_m(self) -> tuple[float, float]:
        """Local (x, y) of the start-platform centre on the tile centre line [m]."""
        return ((self.n_start - 1) * self.cell_m / 2.0, (self.ny - 1) * self.cell_m / 2.0)

    @property
    def goal_xy_m(self) -> tuple[float, float]:
        """Local (x, y) of the goal-region centre on the tile centre line [m]."""
        x = (self.nx - self.n_goal + self.nx - 1) * self.cell_m / 2.0
        return (x, (self.ny - 1) * self.cell_m / 2.0)

    @classmethod
    def from_config(cls, cfg) -> TileSpec:
        """Builds the spec from the ``c.terrain`` config section."""
        return cls(
            length_m=float(cfg.tile_length_m),
            width_m=float(cfg.tile_width_m),
            cell_m=float(cfg.cell_m),
            platform_length_m=float(cfg.platform_length_m),
            goal_length_m=float(cfg.goal_length_m),
            pit_z_m=float(cfg.pit_z_m),
            z_range_m=float(cfg.z_range_m),
            stone_curriculum=str(cfg.stone_curriculum),
        )


# ----------------------------------------------------------------------------------------------
# Helpers.


def _lerp(easy: float, hard: float, d: jax.Array) -> jax.Array:
    return easy + (hard - easy) * d


def stone_params(name: str, d, curriculum: str = DEFAULT_STONE_CURRICULUM) -> dict:
    """The stone schedule of ``name`` in ``curriculum`` (STONE_CURRICULA) at difficulty ``d``
    (piecewise linear between the curriculum's knots; exactly a knot's values at a knot)."""
    if curriculum not in STONE_CURRICULA:
        raise ValueError(
            f"stone curriculum {curriculum!r}; valid choices: {', '.join(STONE_CURRICULUM_NAMES)}"
        )
    table = STONE_CURRICULA[curriculum]
    knots = jp.asarray(table["knots"], jp.float32)
    return {k: jp.interp(d, knots, jp.asarray(v, jp.float32)) for k, v in table[name].items()}


def crack_sag_m(width_m, foot_radius_m: float):
    """How far a sphere of ``foot_radius_m`` dips into a straight crack of ``width_m`` with
    vertical walls: the sagitta r - sqrt(r^2 - (w/2)^2); ``foot_radius_m`` (the sphere's bottom
    reaches the crack's mouth) when the crack is as wide as the foot or wider [m]."""
    r = foot_radius_m
    half = jp.minimum(jp.asarray(width_m, jp.float32) / 2, r)
    return r - jp.sqrt(jp.maximum(r * r - half * half, 0.0))


def _grid(spec: TileSpec) -> tuple[jax.Array, jax.Array]:
    """(ny, nx) local x and y of every vertex [m]."""
    x = jp.arange(spec.nx, dtype=jp.float32) * spec.cell_m
    y = jp.arange(spec.ny, dtype=jp.float32) * spec.cell_m
    return jp.meshgrid(x, y)  # xy indexing: (ny, nx)


def _n_max(extent_m: float, min_pitch_m: float) -> int:
    """Static bound on the count of cells of pitch >= min_pitch_m over extent_m (+ margin)."""
    return int(math.ceil(extent_m / min_pitch_m)) + 3


def _cell(u: jax.Array, pitch: jax.Array, n: int) -> tuple[jax.Array, jax.Array]:
    """Periodic cells along u: (table index in [0, n), position inside the cell in [0, pitch)).

    Cell k covers [k * pitch, (k + 1) * pitch); index k + 1 is used so cell -1 has an entry too.
    """
    k = jp.floor(u / pitch)
    local = u - k * pitch
    return jp.clip(k.astype(jp.int32) + 1, 0, n - 1), local


def _segments(
    u: jax.Array, gaps: jax.Array, lengths: jax.Array, half_cell: float
) -> tuple[jax.Array, jax.Array]:
    """Alternating (gap k, solid k) segments laid from u = 0: (index of the nearest solid
    segment, -1 before the first; u is in a gap; index k of the (gap k, solid k) pair u is in).

    A vertex counts as in a gap only if it lies more than ``half_cell`` inside it (see
    Rendering at the top of this module).

    Args:
      u: (...) position along the course [m].
      gaps: (n,) gap lengths [m]; gap k precedes solid k.
      lengths: (n,) solid lengths [m].
      half_cell: half the vertex spacing [m].
    """
    pitch = gaps + lengths
    starts = jp.concatenate([jp.zeros((1,), pitch.dtype), jp.cumsum(pitch)[:-1]])
    k = jp.clip(jp.searchsorted(starts, u, side="right") - 1, 0, gaps.shape[0] - 1)
    rel = u - starts[k]
    in_gap = jp.abs(rel - gaps[k] / 2) < gaps[k] / 2 - half_cell
    # A solid vertex in the first half of gap k belongs to solid k - 1 (-1: before the first).
    return jp.where(rel < gaps[k] / 2, k - 1, k), in_gap, k


def _drawn_solid(offset: jax.Array, extent: jax.Array, spec: TileSpec) -> jax.Array:
    """A vertex at ``offset`` from the centre of a solid ``extent`` wide is drawn solid: within
    half a cell of its outline (see Rendering at the top of this module)."""
    return jp.abs(offset) <= extent / 2 + spec.cell_m / 2


def _finish(
    z: jax.Array,
    spec: TileSpec,
    pit_in_course: jax.Array | None = None,
    gap_width_m: jax.Array | float | None = None,
) -> jax.Array:
    """Draws the pits, sets the start platform and goal region to z = 0 and clips to the
    representable range.

    Args:
      z: (ny, nx) surface heights (at pit vertices: the top of the solid they belong to) [m].
      spec: tile geometry.
      pit_in_course: (ny, nx) bool, vertices in a gap (None: no pits).
      gap_width_m: nominal width of the gap each pit vertex lies in, or an upper bound on it
        (scalar or (ny, nx)) [m]. Where it is narrower than the foot (2 x spec.foot_radius_m), the
        vertex is drawn ``crack_sag_m`` below ``z`` instead of at the pit floor (Cracks, above).
        None: every pit vertex at the pit floor.
    """
    col = jp.arange(spec.nx)[None, :]
    course = (col >= spec.n_start) & (col < spec.nx - spec.n_goal)
    if pit_in_course is not None:
        pit_z = jp.full(z.shape, spec.pit_z_m, jp.float32)
        if gap_width_m is not None:
            width = jp.broadcast_to(jp.asarray(gap_width_m, jp.float32), z.shape)
            crack = z - crack_sag_m(width, spec.foot_radius_m)
            pit_z = jp.where(width < 2 * spec.foot_radius_m, crack, pit_z)
        z = jp.where(pit_in_course, pit_z, z)
    z = jp.where(course, z, 0.0)
    return jp.clip(z, spec.pit_z_m, spec.pit_z_m + spec.z_range_m).astype(jp.float32)


# ----------------------------------------------------------------------------------------------
# Generators: (key, difficulty in [0, 1], spec) -> (ny, nx) heights [m]. Easy -> hard values are
# interpolated linearly in the difficulty d; "size" is the top extent of a stone before the cell
# quantization (the flat top spans the vertices inside it).


def _grid_stones(key: jax.Array, d: jax.Array, spec: TileSpec) -> jax.Array:
    """Regular grid of square stones over the pit, jittered, with random top heights."""
    sp = stone_params("grid_stones", d, spec.stone_curriculum)
    size, gap, dz, jit = sp["size"], sp["gap"], sp["dz"], sp["jitter"]
    pitch = size + gap
    x, y = _grid(spec)
    nkx = _n_max(spec.course_x1_m - spec.course_x0_m, 0.53)
    nky = _n_max(spec.width_m, 0.53)
    k_z, k_jx, k_jy, k_fx, k_fy, k_ph = jax.random.split(key, 6)
    top = jax.random.uniform(k_z, (nky, nkx), minval=-0.5, maxval=0.5) * dz  # ~ U(+-dz/2)
    jx = jax.random.uniform(k_jx, (nky, nkx), minval=-1.0, maxval=1.0) * jit * gap  # centre jitter
    jy = jax.random.uniform(k_jy, (nky, nkx), minval=-1.0, maxval=1.0) * jit * gap
    f_lo = sp["f_lo"]  # size factor ~ U(f_lo, 1)
    fx = jax.random.uniform(k_fx, (nky, nkx), minval=f_lo, maxval=1.0)
    fy = jax.random.uniform(k_fy, (nky, nkx), minval=f_lo, maxval=1.0)
    phase_y = jax.random.uniform(k_ph, (), maxval=1.0) * pitch  # grid phase across y
    kx, lx = _cell(x - spec.course_x0_m - gap / 2, pitch, nkx)
    ky, ly = _cell(y - phase_y, pitch, nky)
    inside = _drawn_solid(lx - pitch / 2 - jx[ky, kx], size * fx[ky, kx], spec) & _drawn_solid(
        ly - pitch / 2 - jy[ky, kx], size * fy[ky, kx], spec
    )
    widest = gap * (1 + 2 * jit) + size * (1 - f_lo)  # no gap of the tile is wider [m]
    return _finish(top[ky, kx], spec, pit_in_course=~inside, gap_width_m=widest)


def _two_row_stones(key: jax.Array, d: jax.Array, spec: TileSpec) -> jax.Array:
    """Two rows of square stones along x (left and right feet), independently staggered."""
    sp = stone_params("two_row_stones", d, spec.stone_curriculum)
    size, gap, dz, jit, lateral = sp["size"], sp["gap"], sp["dz"], sp["jitter"], sp["lateral"]
    pitch = size + gap
    x, y = _grid(spec)
    n = _n_max(spec.course_x1_m - spec.course_x0_m, 0.63)
    y_mid = (spec.ny - 1) * spec.cell_m / 2
    inside = jp.zeros(x.shape, bool)
    z = jp.zeros(x.shape, jp.float32)
    for side, k_row in zip((-1.0, 1.0), jax.random.split(key, 2), strict=True):
        k_z, k_jx, k_jy, k_f, k_ph = jax.random.split(k_row, 5)
        top = jax.random.uniform(k_z, (n,), minval=-0.5, maxval=0.5) * dz  # ~ U(+-dz/2)
        jx = jax.random.uniform(k_jx, (n,), minval=-1.0, maxval=1.0) * jit * gap
        jy = jax.random.uniform(k_jy, (n,), minval=-1.0, maxval=1.0) * lateral
        f = jax.random.uniform(k_f, (n,), minval=sp["f_lo"])  # size ~ U(f_lo, 1)
        phase = jax.random.uniform(k_ph, (), maxval=0.5) * pitch  # row stagger ~ U(0, pitch/2)
        k, lx = _cell(x - spec.course_x0_m - gap / 2 - phase, pitch, n)
        yc = y_mid + side * TWO_ROW_HALF_SPACING_M + jy[k]
        row = _drawn_solid(lx - pitch / 2 - jx[k], size * f[k], spec) & _drawn_solid(
            y - yc, size * f[k], spec
        )
        z = jp.where(row & ~inside, top[k], z)
        inside = inside | row
    # Along a row no gap is wider than this; beside the rows (and between them, once they no
    # longer touch) lies open pit.
    widest = gap * (1 + 2 * jit) + size * (1 - sp["f_lo"])
    off = jp.abs(y - y_mid)
    rows_touch = size + 2 * lateral >= 2 * TWO_ROW_HALF_SPACING_M
    in_band = jp.where(
        rows_touch,
        off <= TWO_ROW_HALF_SPACING_M + size / 2 - lateral,
        jp.abs(off - TWO_ROW_HALF_SPACING_M) <= size / 2 - lateral,
    )
    widest = jp.where(in_band, widest, jp.inf)
    return _finish(z, spec, pit_in_course=~inside, gap_width_m=widest)


def _rough_boxes(key: jax.Array, d: jax.Array, spec: TileSpec) -> jax.Array:
    """Gap-free field of square boxes with random heights (no pit)."""
    size = _lerp(0.50, 0.25, d)  # box size [m]
    dz = _lerp(0.04, 0.30, d)  # peak-to-peak spread of the box heights [m]
    x, y = _grid(spec)
    nkx = _n_max(spec.course_x1_m - spec.course_x0_m, 0.25)
    nky = _n_max(spec.width_m, 0.25)
    k_z, k_ph = jax.random.split(key)
    top = jax.random.uniform(k_z, (nky, nkx), minval=-0.5, maxval=0.5) * dz  # ~ U(+-dz/2)
    phase = jax.random.uniform(k_ph, (2,), maxval=1.0) * size  # grid phase in x, y
    kx, _ = _cell(x - spec.course_x0_m - phase[0], size, nkx)
    ky, _ = _cell(y - phase[1], size, nky)
    return _finish(top[ky, kx], spec)


def _platform_gap(key: jax.Array, d: jax.Array, spec: TileSpec) -> jax.Array:
    """Full-width platforms separated by gaps over the pit."""
    gap = _lerp(0.05, 0.75, d)  # largest gap width; each gap ~ U(0.85, 1) * gap [m]
    len_lo = _lerp(1.0, 0.6, d)  # platform length ~ U(len_lo, len_hi) [m]
    len_hi = _lerp(1.6, 1.0, d)
    dz = _lerp(0.0, 0.20, d)  # peak-to-peak spread of the platform heights [m]
    x, _ = _grid(spec)
    n = _n_max(spec.course_x1_m - spec.course_x0_m, 1.0)
    k_g, k_l, k_z = jax.random.split(key, 3)
    gaps = gap * jax.random.uniform(k_g, (n,), minval=0.85, maxval=1.0)
    lengths = jax.random.uniform(k_l, (n,), minval=len_lo, maxval=len_hi)
    top = jax.random.uniform(k_z, (n,), minval=-0.5, maxval=0.5) * dz  # ~ U(+-dz/2)
    k, in_gap, g = _segments(x - spec.course_x0_m, gaps, lengths, spec.cell_m / 2)
    z = jp.where(k >= 0, top[jp.maximum(k, 0)], 0.0)  # before the first platform: start level
    # A pit vertex lies in gap g, between platforms g - 1 (the start platform for g = 0) and g.
    lower = jp.minimum(jp.where(g > 0, top[jp.maximum(g - 1, 0)], 0.0), top[g])
    z = jp.where(in_gap, lower, z)  # a crack dips below the lower of its two platforms
    return _finish(z, spec, pit_in_course=in_gap, gap_width_m=gaps[g])


def _mixed_row_stones(key: jax.Array, d: jax.Array, spec: TileSpec) -> jax.Array:
    """Rows of stones across y, each row randomly shifted; mixed sizes, bricks and high stones."""
    sp = stone_params("mixed_row_stones", d, spec.stone_curriculum)
    size, gap, dz, jit, keep = sp["size"], sp["gap"], sp["dz"], sp["jitter"], sp["keep"]
    pitch = size + gap
    x, y = _grid(spec)
    nkx = _n_max(spec.course_x1_m - spec.course_x0_m, 0.55)
    nky = _n_max(spec.width_m, 0.55) + 1
    k_kind, k_z, k_jx, k_jy, k_fx, k_fy, k_ph, k_keep = jax.random.split(key, 8)
    # kind ~ {regular 0.6, low brick 0.25, high stone 0.15}; regular tops ~ U(+-0.1 dz).
    kind = jax.random.choice(k_kind, 3, (nky, nkx), p=jp.array([0.6, 0.25, 0.15]))
    regular = jax.random.uniform(k_z, (nky, nkx), minval=-0.1, maxval=0.1) * dz
    top = jp.where(kind == 1, -dz, jp.where(kind == 2, dz, regular))
    jx = jax.random.uniform(k_jx, (nky, nkx), minval=-1.0, maxval=1.0) * jit * gap
    jy = jax.random.uniform(k_jy, (nky, nkx), minval=-1.0, maxval=1.0) * jit * gap
    f_lo = sp["f_lo"]  # size factor ~ U(f_lo, 1)
    fx = jax.random.uniform(k_fx, (nky, nkx), minval=f_lo, maxval=1.0)
    fy = jax.random.uniform(k_fy, (nky, nkx), minval=f_lo, maxval=1.0)
    present = jax.random.uniform(k_keep, (nky, nkx)) < keep
    phase_y = jax.random.uniform(k_ph, (nkx,), maxval=1.0) * pitch  # per-row shift across y
    kx, lx = _cell(x - spec.course_x0_m - gap / 2, pitch, nkx)
    ky, ly = _cell(y - phase_y[kx], pitch, nky)
    inside = (
        present[ky, kx]
        & _drawn_solid(lx - pitch / 2 - jx[ky, kx], size * fx[ky, kx], spec)
        & _drawn_solid(ly - pitch / 2 - jy[ky, kx], size * fy[ky, kx], spec)
    )
    widest = gap * (1 + 2 * jit) + size * (1 - f_lo)  # between present stones [m]
    widest = jp.where(keep < 1.0, jp.inf, widest)  # a missing stone leaves a wide hole
    return _finish(top[ky, kx], spec, pit_in_course=~inside, gap_width_m=widest)


def _beam(key: jax.Array, d: jax.Array, spec: TileSpec) -> jax.Array:
    """A beam along x over the pit, made of segments with small offsets and gaps."""
    width = _lerp(0.80, 0.16, d)  # beam top width [m]
    offset = _lerp(0.0, 0.06, d)  # lateral offset of each segment, +- [m]
    dz = _lerp(0.0, 0.08, d)  # peak-to-peak spread of the segment heights [m]
    gap = _lerp(0.0, 0.15, d)  # largest gap between segments; each ~ U(0.5, 1) * gap [m]
    x, y = _grid(spec)
    n = _n_max(spec.course_x1_m - spec.course_x0_m, 0.8)
    k_g, k_l, k_z, k_y = jax.random.split(key, 4)
    gaps = gap * jax.random.uniform(k_g, (n,), minval=0.5, maxval=1.0)
    gaps = gaps.at[0].set(0.0)  # the beam starts at the platform edge
    lengths = jax.random.uniform(k_l, (n,), minval=0.8, maxval=1.6)  # segment length [m]
    top = jax.random.uniform(k_z, (n,), minval=-0.5, maxval=0.5) * dz  # ~ U(+-dz/2)
    yc = (spec.ny - 1) * spec.cell_m / 2 + jax.random.uniform(k_y, (n,), minval=-1.0) * offset
    k, in_gap, _ = _segments(x - spec.course_x0_m, gaps, lengths, spec.cell_m / 2)
    k = jp.maximum(k, 0)  # gap 0 is empty: nothing lies before the first segment
    on_beam = ~in_gap & _drawn_solid(y - yc[k], width, spec)
    return _finish(top[k], spec, pit_in_course=~on_beam)


def _stairs(key: jax.Array, d: jax.Array, spec: TileSpec) -> jax.Array:
    """Full-width stairs up to a landing and back down (or down and back up), mirrored."""
    rise = _lerp(0.05, 0.25, d)  # nominal step rise; each ~ U(0.85, 1.15) * rise [m]
    tread = _lerp(0.45, 0.28, d)  # nominal tread depth; each ~ U(0.9, 1.1) * tread [m]
    x, _ = _grid(spec)
    x_first, x_last = spec.course_x0_m, spec.course_x1_m - spec.cell_m
    half_run = (x_last - x_first) / 2
    n = _n_max(half_run, 0.25)
    k_r, k_t, k_s = jax.random.split(key, 3)
    rises = rise * jax.random.uniform(k_r, (n,), minval=0.85, maxval=1.15)
    treads = tread * jax.random.uniform(k_t, (n,), minval=0.9, maxval=1.1)
    riser_at = jp.cumsum(treads)  # distance of riser k from the course end [m]
    valid = (riser_at <= half_run - 0.3) & (jp.cumsum(rises) <= STAIRS_MAX_RISE_M)
    dist = half_run - jp.abs(x - (x_first + x_last) / 2)  # distance from the nearer course end
    z = jp.sum(jp.where(valid & (dist[..., None] >= riser_at), rises, 0.0), axis=-1)
    sign = jp.where(jax.random.bernoulli(k_s), 1.0, -1.0)  # up-then-down or down-then-up
    return _finish(sign * z, spec)


def _pyramid(key: jax.Array, d: jax.Array, spec: TileSpec, sign: float) -> jax.Array:
    """Four-faceted pyramid (sign +1) or inverted pyramid (-1) over the course, truncated."""
    slope = _lerp(0.05, 0.45, d)  # nominal face slope; the tile's ~ U(0.9, 1.1) * slope [-]
    rough = _lerp(0.0, 0.02, d)  # per-vertex roughness ~ U(+-rough) [m]
    x, y = _grid(spec)
    k_s, k_a, k_r = jax.random.split(key, 3)
    slope = slope * jax.random.uniform(k_s, (), minval=0.9, maxval=1.1)
    inset = jax.random.uniform(k_a, (2,), maxval=0.3)  # base inset at each x end ~ U(0, 0.3) [m]
    x_first, x_last = spec.course_x0_m + inset[0], spec.course_x1_m - spec.cell_m - inset[1]
    dist_x = jp.minimum(x - x_first, x_last - x)
    dist_y = jp.minimum(y, (spec.ny - 1) * spec.cell_m - y)
    h = jp.minimum(slope * jp.clip(jp.minimum(dist_x, dist_y), 0.0), PYRAMID_MAX_HEIGHT_M)
    noise = jax.random.uniform(k_r, x.shape, minval=-1.0, maxval=1.0) * rough
    return _finish(sign * h + noise, spec)


_GENERATORS: dict[str, Callable[[jax.Array, jax.Array, TileSpec], jax.Array]] = {
    "grid_stones": _grid_stones,
    "two_row_stones": _two_row_stones,
    "rough_boxes": _rough_boxes,
    "platform_gap": _platform_gap,
    "mixed_row_stones": _mixed_row_stones,
    "beam": _beam,
    "stairs": _stairs,
    "pyramid_up": lambda key, d, spec: _pyramid(key, d, spec, 1.0),
    "pyramid_down": lambda key, d, spec: _pyramid(key, d, spec, -1.0),
}
assert tuple(_GENERATORS) == TERRAIN_TYPES


def check_terrain_name(name: str) -> int:
    """Returns the index of ``name`` in TERRAIN_TYPES; ValueError naming the choices if unknown."""
    if name not in TERRAIN_TYPES:
        raise ValueError(
            f"unknown terrain type {name!r}; valid choices: {', '.join(TERRAIN_TYPES)}"
        )
    return TERRAIN_TYPES.index(name)


def check_difficulty(difficulty) -> None:
    """ValueError if a concrete difficulty lies outside [0, 1]; traced values are not checked."""
    try:
        value = np.asarray(difficulty, dtype=np.float64)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return  # traced: clipped to [0, 1] by the generator
    if value.size and not (np.all(np.isfinite(value)) and value.min() >= 0 and value.max() <= 1):
        raise ValueError(f"difficulty={difficulty!r} outside the valid range [0, 1]")


def generate_tile(
    name: str, key: jax.Array, difficulty: float | jax.Array, spec: TileSpec | None = None
) -> jax.Array:
    """Generates one terrain tile.

    Jit- and vmap-able over ``key`` and ``difficulty``; ``name`` and ``spec`` are static (pass them
    as static arguments under ``jax.jit``). A concrete difficulty outside [0, 1] raises ValueError;
    a traced difficulty is clipped to [0, 1].

    Difficulty 0 -> 1: stepping stones follow ``spec.stone_curriculum`` (STONE_CURRICULA,
    piecewise linear). "size_first": large stones (grid 1.0 m, two-row 0.8 m, mixed 0.9 m)
    shrink to the ensemble's 0.27-0.30 m at 0.10 m gaps (d 0 -> 0.36), then the gaps widen
    (-> 0.54), then the tops spread (-> 0.72); "gaps_first": the gaps widen first, the stones
    shrink last. From d = 0.72 on both match the earlier linear schedules (stones -> 0.18 m;
    grid gaps -> 0.35 m, two-row -> 0.45 m, mixed -> 0.40 m). The other types are linear in d:
    platform gaps widen (0.05 -> 0.75 m), box heights spread (0.04 -> 0.30 m), the beam narrows
    (0.80 -> 0.16 m), stairs steepen (rise 0.05 -> 0.25 m, tread 0.45 -> 0.28 m) and pyramid faces
    steepen (slope 0.05 -> 0.45). Gaps narrower than the foot are drawn as shallow cracks (see
    Cracks at the top of this module).

    Args:
      name: one of TERRAIN_TYPES (static).
      key: PRNG key; the only source of randomness (placement jitter, heights, sizes).
      difficulty: scalar in [0, 1].
      spec: tile geometry (static); ``TileSpec()`` if None.

    Returns:
      (ny, nx) float32 heights [m] in the Heightfield layout (rows along +y, columns along +x), in
      [spec.pit_z_m, spec.pit_z_m + spec.z_range_m]. Start platform (columns < spec.n_start) and
      goal region (columns >= nx - spec.n_goal) are flat at z = 0 (the spawn surface of every type).
    """
    check_terrain_name(name)
    check_difficulty(difficulty)
    spec = TileSpec() if spec is None else spec
    d = jp.clip(jp.asarray(difficulty, jp.float32), 0.0, 1.0)
    return _GENERATORS[name](key, d, spec)
