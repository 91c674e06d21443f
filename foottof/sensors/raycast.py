"""Exact ray casting against MuJoCo's triangulated heightfield in pure JAX (mj_ray semantics)."""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jp
import numpy as np
from jax.custom_batching import custom_vmap

from foottof.terrain.heightfield import Heightfield

MISS = -1.0  # distance returned for a miss or a hit beyond max_range_m (same sentinel as mj_ray)
_MINVAL = 1e-15  # MuJoCo's mjMINVAL: box faces with |direction component| below it are skipped


def num_strips(hfield: Heightfield, max_range_m: float) -> int:
    """Static number of grid strips a ray of length ``max_range_m`` can cross.

    A unit direction moves at most ``max_range_m / cell_m`` cells along its dominant horizontal
    axis, so it crosses at most ``floor(max_range_m / cell_m) + 1`` grid lines of that axis and
    visits at most ``floor(max_range_m / cell_m) + 2`` strips (one-cell-wide columns/rows).
    """
    return int(math.floor(max_range_m / hfield.cell_m)) + 2


def _check_range(max_range_m) -> float:
    try:
        r = float(max_range_m)
    except (TypeError, jax.errors.ConcretizationTypeError) as e:
        raise ValueError(
            f"max_range_m must be a static Python float > 0 [m] (it fixes the traced loop size), "
            f"got {max_range_m!r}"
        ) from e
    if not (math.isfinite(r) and r > 0.0):
        raise ValueError(f"max_range_m must be a finite float > 0 [m], got {max_range_m!r}")
    return r


def _box_faces(lo, hi, o, d):
    """MuJoCo ``ray_box`` face hits of an axis-aligned box (one ray).

    Args:
      lo, hi: (3,) box corners [m] (Python floats).
      o, d: (3,) ray origin [m] and unit direction.

    Returns:
      (6,) distance to faces (-x, +x, -y, +y, -z, +z) [m], ``inf`` where the ray does not cross
      that face at a non-negative distance inside the face rectangle (MuJoCo's ``all`` array).
    """
    lo = jp.asarray(lo, o.dtype)
    hi = jp.asarray(hi, o.dtype)
    centre, half = (lo + hi) / 2.0, (hi - lo) / 2.0
    lp = o - centre
    out = []
    for i in range(3):
        ok_axis = jp.abs(d[i]) > _MINVAL
        di = jp.where(ok_axis, d[i], 1.0)
        for side in (-1.0, 1.0):
            sol = (side * half[i] - lp[i]) / di
            p = lp + sol * d
            inside = jp.ones((), bool)
            for j in range(3):
                if j != i:
                    inside = inside & (jp.abs(p[j]) <= half[j])
            out.append(jp.where(ok_axis & (sol >= 0.0) & inside, sol, jp.inf))
    return jp.stack(out)


_FACE_NORMALS = (
    (-1.0, 0.0, 0.0),
    (1.0, 0.0, 0.0),
    (0.0, -1.0, 0.0),
    (0.0, 1.0, 0.0),
    (0.0, 0.0, -1.0),
    (0.0, 0.0, 1.0),
)


class _Ray(NamedTuple):
    """One ray in the walk's grid coordinates: p is the dominant horizontal axis (columns, or
    rows where the ray is more along y), q the other; (p, q) in vertices, z in metres."""

    o: jax.Array  # (3,) origin [m]
    d: jax.Array  # (3,) unit direction
    p0: jax.Array  # origin's p, q [vertices]
    q0: jax.Array
    dp: jax.Array  # vertices per metre along the ray, along p and q
    dq: jax.Array
    n_p: jax.Array  # vertices along p, q
    n_q: jax.Array
    s_p: jax.Array  # flat-index strides of p, q in h_flat
    s_q: jax.Array
    base: int  # index in h_flat of the ray's terrain
    max_range_m: float


def _walk(h_flat, hf: Heightfield, o, d, max_range_m: float, first: int, count: int, base=0):
    """First surface-triangle hit of one ray among strips ``first .. first + count - 1``.

    ``base``: index in ``h_flat`` of the ray's terrain (several terrains laid end to end).

    Strips are visited in the order the ray crosses them, so a hit in strip s is closer than any
    hit in a later strip (ties keep the earlier strip).

    Returns:
      t: hit distance [m] (inf if none); g: (2,) (dz/dp, dz/dq) of the hit triangle [m/cell];
      more: whether strip ``first + count`` could still hold a hit (the walk is unfinished).
    """
    nrow, ncol = hf.nrow, hf.ncol
    cell = hf.cell_m
    xlo, ylo = hf.x0_m, hf.y0_m
    dt = o.dtype

    # --- surface triangles: walk the strips of the dominant horizontal axis -------------------
    u0, v0 = (o[0] - xlo) / cell, (o[1] - ylo) / cell  # column / row vertex coordinates
    du, dv = d[0] / cell, d[1] / cell  # cells per metre along the ray
    swap = jp.abs(dv) > jp.abs(du)  # walk rows (p = row) when the ray is more along y
    p0, q0 = jp.where(swap, v0, u0), jp.where(swap, u0, v0)
    dp, dq = jp.where(swap, dv, du), jp.where(swap, du, dv)
    n_p, n_q = jp.where(swap, nrow, ncol), jp.where(swap, ncol, nrow)  # vertices along p, q
    s_p, s_q = jp.where(swap, ncol, 1), jp.where(swap, 1, ncol)  # flat-index strides
    ray = _Ray(o, d, p0, q0, dp, dq, n_p, n_q, s_p, s_q, base, max_range_m)

    def scan_body(carry, s):
        best_t, best_g = carry
        t4, g4 = _strip_hits(h_flat, ray, s)
        i = jp.argmin(t4)
        closer = t4[i] < best_t
        return (jp.where(closer, t4[i], best_t), jp.where(closer, g4[i], best_g)), None

    (t_tri, g_best), _ = jax.lax.scan(
        scan_body, (jp.asarray(jp.inf, dt), jp.zeros((2,), dt)), jp.arange(first, first + count)
    )
    # Could a strip after these hold a hit? Only if none was found, the ray moves along p, the
    # next strip starts within range and lies inside the grid.
    nxt = first + count
    step_dir = jp.where(dp < 0.0, -1, 1)
    k = jp.floor(p0).astype(jp.int32) + step_dir * nxt
    t_next = (jp.where(dp < 0.0, k + 1, k).astype(dt) - p0) / jp.where(dp != 0.0, dp, 1.0)
    past_grid = jp.where(dp < 0.0, k < 0, k > n_p - 2)  # and moving away: never comes back
    if nxt == 0:  # nothing walked yet: strip 0 (the origin's, the only one of a vertical ray)
        return t_tri, g_best, jp.ones((), bool)
    more = ~jp.isfinite(t_tri) & (dp != 0.0) & (t_next <= max_range_m) & ~past_grid
    return t_tri, g_best, more


def _strip_hits(h_flat, ray: _Ray, s):
    """Hit parameters (4,) and (dz/dp, dz/dq) (4, 2) of the 4 triangles of the ray's strip s."""
    p0, q0, dp, dq, max_range_m = ray.p0, ray.q0, ray.dp, ray.dq, ray.max_range_m
    dt = ray.o.dtype
    step_dir = jp.where(dp < 0.0, -1, 1)
    k = jp.floor(p0).astype(jp.int32) + step_dir * s  # strip k spans p in [k, k + 1]
    moving = dp != 0.0
    dp_safe = jp.where(moving, dp, 1.0)
    t_a = (k.astype(dt) - p0) / dp_safe
    t_b = (k.astype(dt) + 1.0 - p0) / dp_safe
    t_in = jp.where(moving, jp.maximum(jp.minimum(t_a, t_b), 0.0), 0.0)
    t_out = jp.where(moving, jp.minimum(jp.maximum(t_a, t_b), max_range_m), max_range_m)
    strip_ok = (t_in <= t_out) & (moving | (s == 0))
    q_in, q_out = q0 + t_in * dq, q0 + t_out * dq
    r = jp.floor(jp.minimum(q_in, q_out)).astype(jp.int32)  # rows r and r + 1 cover the strip

    def vert(pi, qi):
        pc = jp.clip(pi, 0, ray.n_p - 1)
        qc = jp.clip(qi, 0, ray.n_q - 1)
        return h_flat[ray.base + pc * ray.s_p + qc * ray.s_q]

    # Heights H[p, q] of the 2 x 3 vertices under the strip: rows r, r + 1, r + 2.
    hk = [vert(k, r + j) for j in range(3)]
    hk1 = [vert(k + 1, r + j) for j in range(3)]
    ts = _strip_triangle_hits(ray, k, r, strip_ok, hk, hk1)
    gps = []
    for j in range(2):
        h00, h01, h10, h11 = hk[j], hk[j + 1], hk1[j], hk1[j + 1]
        gps += [(h10 - h00, h11 - h10), (h11 - h01, h01 - h00)]
    g = jp.stack([jp.stack(gg, -1) for gg in gps], -2)  # (..., 4, 2)
    return jp.stack(ts, -1), g


def _strip_triangle_hits(ray: _Ray, k, r, strip_ok, hk, hk1) -> list:
    """The 4 ray parameters (inf: no hit) of the triangles of strip k over rows r, r + 1, from
    the heights ``hk`` (p = k) and ``hk1`` (p = k + 1) of its vertices at rows r .. r + 2."""
    o, d, p0, q0, dp, dq = ray.o, ray.d, ray.p0, ray.q0, ray.dp, ray.dq
    dt, max_range_m = o.dtype, ray.max_range_m
    # Vertices V(P, Q) relative to the ray origin in (cells, cells, m), computed from their
    # indices only: a vertex shared by neighbouring cells or strips gets bit-identical
    # coordinates. Each grid edge a -> b is tested with the same canonical orientation
    # everywhere (E(a, b) = D . (a x b) = (D x a) . b, from the lower to the higher index), so
    # the inside tests of adjacent triangles are exactly complementary: watertight, no
    # tolerance needed. Strips are scanned one at a time (lax.scan): the per-strip working
    # set stays in cache, ~4x faster on CPU than materializing all strips at once.
    dz = d[2]
    dd = dp * dp + dq * dq + dz * dz
    heights = (hk, hk1)
    vx = [k.astype(dt) + x - p0 for x in range(2)]
    vy = [(r + y).astype(dt) - q0 for y in range(3)]
    vz = [[heights[x][y] - o[2] for y in range(3)] for x in range(2)]
    # cr = D x V and tv = (V . D) / (D . D) per vertex, indexed [x][y].
    cr = [
        [
            (dq * vz[x][y] - dz * vy[y], dz * vx[x] - dp * vz[x][y], dp * vy[y] - dq * vx[x])
            for y in range(3)
        ]
        for x in range(2)
    ]
    tv = [[(vx[x] * dp + vy[y] * dq + vz[x][y] * dz) / dd for y in range(3)] for x in range(2)]

    def edge(a, b):  # a = (x, y) canonical first vertex, b = (x, y) second vertex
        c = cr[a[0]][a[1]]
        return c[0] * vx[b[0]] + c[1] * vy[b[1]] + c[2] * vz[b[0]][b[1]]

    e_p = [edge((0, y), (1, y)) for y in range(3)]  # edges along p at rows r + y
    ts = []
    for j in range(2):  # cells (k, r + j): triangles A = (00, 10, 11) and B = (00, 11, 01)
        rr = r + j
        cell_ok = strip_ok & (k >= 0) & (k <= ray.n_p - 2) & (rr >= 0) & (rr <= ray.n_q - 2)
        e_left = edge((0, j), (0, j + 1))
        e_right = edge((1, j), (1, j + 1))
        e_diag = edge((0, j), (1, j + 1))
        t00, t10, t11, t01 = tv[0][j], tv[1][j], tv[1][j + 1], tv[0][j + 1]
        for (w_ab, w_bc, w_ca), (ta, tb, tc) in (
            ((e_p[j], e_right, -e_diag), (t00, t10, t11)),
            ((e_diag, -e_p[j + 1], -e_left), (t00, t11, t01)),
        ):
            pos = (w_ab >= 0) & (w_bc >= 0) & (w_ca >= 0)
            neg = (w_ab <= 0) & (w_bc <= 0) & (w_ca <= 0)
            w_sum = w_ab + w_bc + w_ca
            ok = cell_ok & (pos | neg) & (w_sum != 0.0)
            # Hit point = barycentric mix (weights w_bc, w_ca, w_ab) -> its ray parameter.
            t = (w_bc * ta + w_ca * tb + w_ab * tc) / jp.where(ok, w_sum, 1.0)
            ts.append(jp.where(ok & (t >= 0.0) & (t <= max_range_m), t, jp.inf))
    return ts


def _finish(h_flat, hf: Heightfield, o, d, t_tri, g_best, max_range_m: float, with_normal: bool):
    """Distance and outward unit normal of the first hit of one ray (inf if none), from the
    surface walk's result and MuJoCo's boxes."""
    nrow, ncol, cell = hf.nrow, hf.ncol, hf.cell_m
    rx, ry = hf.half_extents_m
    xlo, ylo = hf.x0_m, hf.y0_m
    xhi, yhi = xlo + 2.0 * rx, ylo + 2.0 * ry
    zf, ztop, zbase = hf.z_floor_m, hf.z_floor_m + hf.z_range_m, hf.z_floor_m - hf.base_m
    dt = o.dtype
    swap = jp.abs(d[1] / cell) > jp.abs(d[0] / cell)  # as in _walk: g is in its (p, q) axes
    if with_normal:
        gp, gq = g_best[0], g_best[1]
        dzdx, dzdy = jp.where(swap, gq, gp) / cell, jp.where(swap, gp, gq) / cell
        n_tri = jp.stack([-dzdx, -dzdy, jp.ones((), dt)])
        n_tri = n_tri / jp.linalg.norm(n_tri)
    else:
        n_tri = jp.zeros((3,), dt)

    # --- MuJoCo's boxes: the top box gates the surface, its sides are walls, plus the base box.
    top = _box_faces((xlo, ylo, zf), (xhi, yhi, ztop), o, d)
    base = _box_faces((xlo, ylo, zbase), (xhi, yhi, zf), o, d)
    top_hit = jp.any(jp.isfinite(top))
    t_tri = jp.where(top_hit, t_tri, jp.inf)

    walls = []
    for i in range(4):  # side walls of the top box: below the edge profile of the surface
        hp = o + jp.where(jp.isfinite(top[i]), top[i], 0.0) * d
        if i < 2:  # wall normal to x: profile along the edge column, over rows
            y = (hp[1] - ylo) / cell
            i0 = jp.clip(jp.floor(y), 0, nrow - 2)
            col = 0 if i == 0 else ncol - 1
            z0 = h_flat[i0.astype(jp.int32) * ncol + col]
            z1 = h_flat[(i0.astype(jp.int32) + 1) * ncol + col]
        else:  # wall normal to y: profile along the edge row, over columns
            y = (hp[0] - xlo) / cell
            i0 = jp.clip(jp.floor(y), 0, ncol - 2)
            row = 0 if i == 2 else nrow - 1
            z0 = h_flat[row * ncol + i0.astype(jp.int32)]
            z1 = h_flat[row * ncol + i0.astype(jp.int32) + 1]
        below = hp[2] < z0 * (i0 + 1.0 - y) + z1 * (y - i0)
        walls.append(jp.where(below, top[i], jp.inf))

    cand_t = jp.concatenate([t_tri[None], jp.stack(walls), base])  # (1 + 4 + 6,)
    normals = jp.concatenate(
        [n_tri[None], jp.asarray(_FACE_NORMALS[:4], dt), jp.asarray(_FACE_NORMALS, dt)]
    )
    i_c = jp.argmin(cand_t)
    t_hit = cand_t[i_c]
    t_hit = jp.where(t_hit <= max_range_m, t_hit, jp.inf)
    return t_hit, normals[i_c]


# Rounds of the adaptive walk: (strips, share). Every ray walks the first round's strips; each
# later round gathers the rays still unfinished, ``share`` of all rays at a time, and walks its
# strips further (``None``: all that are left). Sized from the stage-1 policy's ToF rays
# (bench/NOTES.md item 7): unfinished after 2 / 4 / 8 / 14 of the 27 strips: 40 / 20 / 9 / 4 % of
# the rays; shares with a margin over those were faster (an overflowing round takes a 2nd pass).
ROUNDS = ((2, 1.0), (2, 0.42), (4, 0.29), (6, 0.15), (None, 0.06))


def _surface_full(h_flat, meta: Heightfield, origins, unit, r: float, n_strips: int):
    """Every ray walks all ``n_strips`` strips (the reference the adaptive walk must equal)."""
    t, g, _ = jax.vmap(lambda o, d: _walk(h_flat, meta, o, d, r, 0, n_strips))(origins, unit)
    return t, g


def _geometry(hf: Heightfield) -> tuple:
    """The static (hashable) part of a heightfield: shape and placement."""
    return (hf.heights.shape, hf.x0_m, hf.y0_m, hf.cell_m, hf.z_floor_m, hf.z_range_m, hf.base_m)


def _meta(geometry: tuple) -> Heightfield:
    """A heights-free Heightfield of ``geometry`` (:func:`_geometry`): zeros broadcast to its
    shape, so it can be closed over while the heights travel traced (as ``h_flat``)."""
    shape, x0, y0, cell, z_floor, z_range, base_m = geometry
    return Heightfield(
        heights=np.broadcast_to(np.float32(0.0), shape),
        x0_m=x0,
        y0_m=y0,
        cell_m=cell,
        z_floor_m=z_floor,
        z_range_m=z_range,
        base_m=base_m,
    )


@functools.partial(jax.jit, static_argnums=(4, 5, 6, 7))
def _walk_traced_once(h_flat, o, d, base, geometry: tuple, max_range_m: float, first, count):
    """:func:`_walk` of one ray, traced once per (terrain geometry, range, strips): it is traced
    per ray (under ``vmap``), so every round and every cast of the same walk reuses the trace
    (Python tracing of the walk was ~0.55 s each, 40 times in a program with 4 ray casts)."""
    return _walk(h_flat, _meta(geometry), o, d, max_range_m, first, count, base)


def _surface_adaptive(h_flat, meta, origins, unit, r: float, n_strips: int, rounds, bases):
    """The same result as :func:`_surface_full`, with less work: every ray walks the first
    round's strips; in each later round the rays still unfinished (no hit yet, more strips within
    range and grid) are gathered ``share * N`` at a time and walk that round's strips further,
    until none of them is left; the last round walks all remaining strips.

    Most ToF rays hit within a few strips of the foot (stage-1 policy: 60 % within 2 of the 27
    strips of a 1 m ray, 87 % within 6, 95 % within 12), so this is several times fewer strip
    tests than walking all strips for every ray (bench/NOTES.md items 3 and 7). Exact: strips are
    crossed in order, so a hit found in an early strip is the first hit (see :func:`_walk`).
    ``bases`` (N,) int: where each ray's terrain starts in ``h_flat`` (0 for a single terrain).
    """
    n = origins.shape[0]
    geometry = _geometry(meta)
    walk = lambda s0, count: jax.vmap(  # noqa: E731
        lambda o, d, b: _walk_traced_once(h_flat, o, d, b, geometry, r, s0, count)
    )
    first = n_strips if rounds[0][0] is None else min(int(rounds[0][0]), n_strips)
    t, g, more = walk(0, first)(origins, unit, bases)
    done_strips = first
    for i, (strips, share) in enumerate(rounds[1:], start=1):
        last = i == len(rounds) - 1 or strips is None
        count = n_strips - done_strips if last else min(int(strips), n_strips - done_strips)
        if count <= 0 or n == 0:
            break
        m = max(1, min(n, math.ceil(float(share) * n)))
        s0 = done_strips

        def body(c, s0=s0, count=count, m=m):
            t, g, pending, more_next = c
            idx = jp.nonzero(pending, size=m, fill_value=n)[0]  # n = out of bounds: dropped
            o = jp.take(origins, idx, axis=0, mode="clip")
            d = jp.take(unit, idx, axis=0, mode="clip")
            b = jp.take(bases, idx, axis=0, mode="clip")
            t2, g2, more2 = walk(s0, count)(o, d, b)
            return (
                t.at[idx].set(t2, mode="drop"),
                g.at[idx].set(g2, mode="drop"),
                pending.at[idx].set(False, mode="drop"),
                more_next.at[idx].set(more2, mode="drop"),
            )

        t, g, _, more = jax.lax.while_loop(
            lambda c: jp.any(c[2]), body, (t, g, more, jp.zeros_like(more))
        )
        done_strips += count
        if last:
            break
    return t, g


def _surface_fn(meta: Heightfield, r: float, n_strips: int):
    """Surface hits ``(h_flat, origins (N, 3), unit (N, 3)) -> t (N,), g (N, 2)``.

    Under ``jax.vmap`` (e.g. over envs) the rays of all batch elements are walked as one set
    (``custom_vmap``), so the unfinished rays of the whole batch share the rounds of the
    adaptive walk instead of every env paying for the slowest one. A terrain per batch element
    (e.g. each env's robot-centric height scan) is laid end to end with the others, and each
    ray reads its own terrain through an offset.
    """

    @custom_vmap
    def surface(h_flat, origins, unit, bases):
        return _surface_adaptive(h_flat, meta, origins, unit, r, n_strips, ROUNDS, bases)

    @surface.def_vmap
    def _rule(axis_size, in_batched, h_flat, origins, unit, bases):
        h_b, o_b, u_b, b_b = in_batched
        n = origins.shape[1] if o_b else origins.shape[0]
        o = jp.broadcast_to(origins, (axis_size, n, 3)).reshape(-1, 3)
        d = jp.broadcast_to(unit, (axis_size, n, 3)).reshape(-1, 3)
        b = jp.broadcast_to(bases, (axis_size, n))
        if h_b:  # terrains end to end: ray i of batch element k reads terrain k
            size = h_flat.shape[-1]
            if axis_size * size >= 2**31:
                raise ValueError(
                    f"{axis_size} terrains of {size} vertices exceed int32 indexing; "
                    "batch fewer terrains per call"
                )
            b = b + (jp.arange(axis_size, dtype=b.dtype) * size)[:, None]
            h_flat = h_flat.reshape(-1)
        t, g = surface(h_flat, o, d, b.reshape(-1))  # itself: an outer vmap batches it in turn
        return (t.reshape(axis_size, n), g.reshape(axis_size, n, 2)), (True, True)

    return surface


def _cast(hfield: Heightfield, origins, directions, max_range_m, with_normal: bool, adaptive=True):
    r = _check_range(max_range_m)
    origins = jp.asarray(origins)
    directions = jp.asarray(directions)
    if origins.ndim != 2 or origins.shape[-1] != 3 or directions.shape != origins.shape:
        raise ValueError(
            f"origins and directions must both have shape (N, 3), got {origins.shape} and "
            f"{directions.shape}"
        )
    dt = jp.result_type(origins.dtype, jp.float32)
    origins = origins.astype(dt)
    directions = directions.astype(dt)
    norm = jp.linalg.norm(directions, axis=-1, keepdims=True)
    unit = directions / jp.where(norm > 0.0, norm, 1.0)
    h_flat = hfield.clipped().heights.astype(dt).reshape(-1)
    n_strips = num_strips(hfield, r)
    meta = _meta(_geometry(hfield))  # static geometry only (heights travel traced, as h_flat)
    if adaptive:
        bases = jp.zeros(origins.shape[0], jp.int32)
        t_tri, g = _surface_fn(meta, r, n_strips)(h_flat, origins, unit, bases)
    else:
        t_tri, g = _surface_full(h_flat, meta, origins, unit, r, n_strips)
    t, n = jax.vmap(lambda o, d, tt, gg: _finish(h_flat, meta, o, d, tt, gg, r, with_normal))(
        origins, unit, t_tri, g
    )
    hit = jp.isfinite(t) & (norm[:, 0] > 0.0)
    return jp.where(hit, t, MISS), jp.where(hit[:, None], n, 0.0)


def ray_heightfield(hfield: Heightfield, origins, directions, max_range_m: float) -> jax.Array:
    """Distance along each ray to MuJoCo's heightfield surface, as ``mujoco.mj_ray`` computes it.

    The heightfield solid is MuJoCo's: the triangulated surface (each cell split along the
    diagonal from vertex (i, j) to (i + 1, j + 1)), the four side walls of the "top box" below the
    edge profile, and the base box of thickness ``base_m`` under ``z_floor_m``. Triangles are
    two-sided, so a ray starting below the surface hits the surface from underneath or exits
    through a wall/the base box, exactly as mj_ray does (a ray starting inside the base box
    returns the distance to where it leaves the box). Exact: every cell whose xy-footprint the
    ray crosses within ``max_range_m`` is tested (strips of the dominant horizontal axis, at most
    2 cells per strip), so thin corners cannot be skipped. Assumes the hfield geom is not
    rotated (the ``Heightfield`` convention).

    jit- and vmap-able; ``max_range_m`` is static (it sets the number of strips,
    ``num_strips(hfield, max_range_m)``). Each ray walks the strips in order and stops at its first
    hit: every ray walks the strips of the first of the ``ROUNDS``, the unfinished ones walk on
    in gathered chunks, round by round, and under ``vmap`` the rays of all batch elements are
    walked together (``custom_vmap``), so the cost follows where the rays actually hit rather
    than ``max_range_m``.

    Args:
      hfield: terrain; heights outside the representable range are clipped like MuJoCo does.
      origins: (N, 3) ray origins in world [m].
      directions: (N, 3) ray directions in world (any non-zero length; normalized here).
      max_range_m: static Python float > 0 [m]; hits farther than this are reported as misses.

    Returns:
      (N,) distance [m] along the normalized direction to the first hit, or ``MISS`` (-1.0)
      for a miss, a hit beyond ``max_range_m`` or a zero direction.
    """
    return _cast(hfield, origins, directions, max_range_m, False)[0]


def ray_heightfield_normal(
    hfield: Heightfield, origins, directions, max_range_m: float
) -> tuple[jax.Array, jax.Array]:
    """Like :func:`ray_heightfield`, also returning the unit surface normal at the hit.

    The normal points out of the solid (up for the surface triangles, outward for the walls and
    the base box), regardless of which side the ray came from; use ``|dot(n, direction)|`` for
    the incidence angle.

    Returns:
      distance: (N,) [m] or ``MISS`` (-1.0).
      normal: (N, 3) unit world normal at the hit; zeros for a miss.
    """
    return _cast(hfield, origins, directions, max_range_m, True)
