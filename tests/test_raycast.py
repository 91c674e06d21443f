"""foottof.sensors.raycast: the exact heightfield ray cast against MuJoCo C's mj_ray."""

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import hfield_mj_model

from foottof.sensors import (
    MISS,
    ray_heightfield,
    ray_heightfield_normal,
    raycast,
)
from foottof.terrain.heightfield import Heightfield

CELL = 0.04
N_GRID = 81  # square hfield, 3.2 m x 3.2 m
X0, Y0 = -1.3, -1.7
R_ORACLE = 6.0  # longer than any chord of the hfield box: every mj_ray hit is in range


def _stones_over_pit(seed: int) -> np.ndarray:
    """Stepping stones (0.08-0.32 m squares, tops -0.1..0.15 m) and gaps over a -0.5 m pit."""
    rng = np.random.default_rng(seed)
    h = np.full((N_GRID, N_GRID), -0.5)
    for _ in range(40):
        i, j = rng.integers(0, N_GRID - 5, 2)
        a, b = rng.integers(2, 8, 2)
        h[i : i + a, j : j + b] = rng.uniform(-0.1, 0.15)
    h[:, :10] = 0.0  # start platform
    h[:, -10:] = 0.05  # goal platform
    return h


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _oracle_rays(h: np.ndarray, rng) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Ray families (origins, unit directions). Origins avoid the hfield's outer boundary lines,
    where MuJoCo's own inside/outside decision depends on the 1e-6 rounding of the MJCF pos."""
    xs = lambda n: rng.uniform(X0 - 0.2, X0 + 3.4, n)
    ys = lambda n: rng.uniform(Y0 - 0.2, Y0 + 3.4, n)
    out = {}
    n = 10_000
    out["random"] = (
        np.stack([xs(n), ys(n), rng.uniform(-1.3, 1.0, n)], -1),
        _unit(rng.normal(size=(n, 3))),
    )
    n = 1500
    o = np.stack([xs(n), ys(n), rng.uniform(-0.45, 1.0, n)], -1)
    o[:500, 0] = X0 + rng.integers(1, N_GRID - 1, 500) * CELL  # on interior grid lines
    o[500:1000, 1] = Y0 + rng.integers(1, N_GRID - 1, 500) * CELL
    out["straight_down"] = (o, np.tile([0.0, 0.0, -1.0], (n, 1)))
    # Grazing stone corners: rays through points within 0.1 mm of vertices on stone edges.
    edges = np.argwhere(np.abs(np.diff(h, axis=1)) > 0.02)
    sel = edges[rng.integers(0, len(edges), n)]
    i, j = sel[:, 0], sel[:, 1] + rng.integers(0, 2, n)
    p = np.stack([X0 + j * CELL, Y0 + i * CELL, h[i, j]], -1) + rng.uniform(-1e-4, 1e-4, (n, 3))
    dd = rng.normal(size=(n, 3))
    dd[:, 2] = -np.abs(dd[:, 2]) * rng.uniform(0.0, 2.0, n)
    dd = _unit(dd)
    out["grazing_corners"] = (p - 0.7 * dd, dd)
    # Along the (one-cell-wide, steep) stone faces: near-horizontal rays skimming grid lines.
    o = np.stack(
        [
            np.full(n, X0 - 0.05),
            Y0 + rng.integers(1, N_GRID - 1, n) * CELL,
            rng.uniform(-0.5, 0.2, n),
        ],
        -1,
    )
    o[:, 1] += rng.choice([-1.0, 1.0], n) * rng.uniform(1e-4, 1e-3, n)
    dd = _unit(np.stack([np.ones(n), rng.uniform(-1e-3, 1e-3, n), rng.uniform(-0.05, 0.05, n)], -1))
    out["along_faces_x"] = (o, dd)
    o = np.stack(
        [
            X0 + rng.integers(1, N_GRID - 1, n) * CELL,
            np.full(n, Y0 - 0.05),
            rng.uniform(-0.5, 0.2, n),
        ],
        -1,
    )
    o[:, 0] += rng.choice([-1.0, 1.0], n) * rng.uniform(1e-4, 1e-3, n)
    out["along_faces_y"] = (o, dd[:, [1, 0, 2]])
    # Starting below the surface (inside stones / the pit solid).
    o = np.stack([xs(n), ys(n), np.zeros(n)], -1)
    hz = np.array([_height_np(h, x, y) for x, y in o[:, :2]])
    o[:, 2] = hz - rng.uniform(1e-3, 0.3, n)
    out["below_surface"] = (o, _unit(rng.normal(size=(n, 3))))
    return out


def _height_np(h, x, y):
    u = np.clip((x - X0) / CELL, 0.0, N_GRID - 1.000001)
    v = np.clip((y - Y0) / CELL, 0.0, N_GRID - 1.000001)
    j, i = int(u), int(v)
    fu, fv = u - j, v - i
    if fu >= fv:
        return h[i, j] + fu * (h[i, j + 1] - h[i, j]) + fv * (h[i + 1, j + 1] - h[i, j + 1])
    return h[i, j] + fv * (h[i + 1, j] - h[i, j]) + fu * (h[i + 1, j + 1] - h[i + 1, j])


@pytest.fixture(scope="module")
def oracle():
    """Our distances and mj_ray's for all ray families, from one compiled call."""
    h = _stones_over_pit(0)
    hf = Heightfield(heights=jp.asarray(h, jp.float32), x0_m=X0, y0_m=Y0, cell_m=CELL)
    m, d = hfield_mj_model(hf)
    fams = _oracle_rays(h, np.random.default_rng(1))
    o = np.concatenate([v[0] for v in fams.values()])
    dd = np.concatenate([v[1] for v in fams.values()])
    ours = np.asarray(jax.jit(lambda o, d: ray_heightfield(hf, o, d, R_ORACLE))(o, dd))
    gid = np.zeros(1, np.int32)
    ref = np.array([mujoco.mj_ray(m, d, o[i], dd[i], None, 1, -1, gid) for i in range(len(o))])
    names = np.concatenate([[k] * len(v[0]) for k, v in fams.items()])
    return {"ours": ours, "ref": ref, "names": names, "hf": hf, "h": h}


def test_ray_matches_mj_ray(oracle):
    ours, ref, names = oracle["ours"], oracle["ref"], oracle["names"]
    assert len(ours) >= 10_000
    assert np.all(ref <= R_ORACLE)
    hit_o, hit_r = ours >= 0, ref >= 0
    for fam in np.unique(names):
        sel = names == fam
        assert np.array_equal(hit_o[sel], hit_r[sel]), f"hit/miss disagreement in {fam}"
        assert 0.02 < hit_r[sel].mean() or fam == "random"
    both = hit_o & hit_r
    err = np.abs(ours - ref)[both]
    assert (err <= 1e-3).mean() >= 0.999, f"only {(err <= 1e-3).mean():.5f} within 1 mm"
    assert np.all(ours[~hit_o] == MISS)
    assert hit_r.mean() > 0.3 and (~hit_r).sum() > 100  # both outcomes exercised


@pytest.mark.parametrize(
    "first, max_range",
    [
        (0, 0.3),
        # None: the shipped ROUNDS (test_ray_matches_mj_ray runs them against mj_ray too)
        pytest.param(None, 1.0, marks=pytest.mark.slow),
        pytest.param(4, R_ORACLE, marks=pytest.mark.slow),
    ],
)
def test_adaptive_walk_equals_walking_every_strip(oracle, monkeypatch, first, max_range):
    """The adaptive strip walk (most rays stop after a few strips, the rest are gathered and walk
    on) gives bit-identical distances and normals to every ray walking every strip, for one ray
    set and under vmap (whose rule walks the rays of all batch elements together), also when the
    unfinished rays need several gathering rounds and passes (tiny shares), and with the shipped
    rounds."""
    hf = oracle["hf"]
    fams = _oracle_rays(oracle["h"], np.random.default_rng(2))
    pick = np.random.default_rng(3).permutation(sum(len(v[0]) for v in fams.values()))[:4000]
    o = np.concatenate([v[0] for v in fams.values()])[pick].astype(np.float32)  # every family
    d = np.concatenate([v[1] for v in fams.values()])[pick].astype(np.float32)
    d[:7] = 0.0  # zero directions stay misses
    full = jax.jit(lambda o, d: raycast._cast(hf, o, d, max_range, True, adaptive=False))(o, d)
    if first is not None:  # else the shipped raycast.ROUNDS
        # 0 first strips: every ray is gathered; tiny shares: many passes per round
        monkeypatch.setattr(raycast, "ROUNDS", ((first, 1.0), (1, 0.01), (3, 0.02), (None, 0.01)))
    one = jax.jit(lambda o, d: raycast._cast(hf, o, d, max_range, True))(o, d)
    batched = jax.jit(
        jax.vmap(lambda o, d: raycast._cast(hf, o, d, max_range, True))  # 40 "envs"
    )(o.reshape(40, -1, 3), d.reshape(40, -1, 3))
    for got in (one, tuple(x.reshape(full[i].shape) for i, x in enumerate(batched))):
        np.testing.assert_array_equal(got[0], full[0])
        np.testing.assert_array_equal(got[1], full[1])
    assert (full[0] >= 0).mean() > 0.2 and (full[0] < 0).sum() > 100
    # A terrain per "env" (as each env's height scan): rays read their own terrain.
    shift = np.arange(40) % 7 * 3  # terrain k = the oracle's heights rolled by a few cells
    terrains = jp.stack([jp.roll(hf.heights, int(k), axis=int(k) % 2) for k in shift])

    def per_env(adaptive):
        def cast(h, o, d):
            return raycast._cast(hf.replace(heights=h), o, d, max_range, True, adaptive)

        return jax.jit(jax.vmap(cast))(terrains, o.reshape(40, -1, 3), d.reshape(40, -1, 3))

    own = per_env(False)
    for a, b in zip(per_env(True), own, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(own[0].reshape(-1), full[0])  # the terrains differ


def test_ray_max_range_and_miss(oracle):
    hf = oracle["hf"]
    o = jp.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.05]])
    d = jp.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -3.0], [0.0, 0.0, 1.0]])
    z = _height_np(oracle["h"], 0.0, 0.0)
    cast = jax.jit(lambda o, d: ray_heightfield(hf, o, d, 3.0))
    t_far = cast(o, d)
    assert t_far[0] == pytest.approx(1.0 - z, abs=1e-5)
    assert t_far[1] == MISS  # pointing up into the sky
    assert t_far[2] == pytest.approx(1.0 - z, abs=1e-5)  # direction normalized
    assert t_far[3] == pytest.approx(0.05, abs=1e-5)  # inside the base box: exits its top face
    # From 3 m + 1 mm above the surface the hit lies beyond max_range_m (3 m), from 3 m - 1 mm not.
    o_far = o.at[0, 2].set(z + 3.001).at[2, 2].set(z + 2.999)
    t_short = cast(o_far, d)  # same shapes: no recompilation
    assert t_short[0] == MISS
    assert t_short[2] == pytest.approx(2.999, abs=1e-4)
    with pytest.raises(ValueError, match="max_range_m"):
        ray_heightfield(hf, o, d, -1.0)
    with pytest.raises(ValueError, match="shape"):
        ray_heightfield(hf, o[:, :2], d[:, :2], 1.0)


def test_ray_normal_on_slope_and_wall():
    slope = 0.3  # z = 0.3 x
    xs = X0 + np.arange(N_GRID) * CELL
    h = np.tile(slope * xs, (N_GRID, 1))
    hf = Heightfield(heights=jp.asarray(h, jp.float32), x0_m=X0, y0_m=Y0, cell_m=CELL)
    rng = np.random.default_rng(0)
    n = 200
    o = np.stack([rng.uniform(-0.5, 1.0, n), rng.uniform(-1.0, 1.0, n), np.full(n, 0.9)], -1)
    d = _unit(np.stack([rng.uniform(-0.2, 0.2, n), rng.uniform(-0.2, 0.2, n), -np.ones(n)], -1))
    cast = jax.jit(lambda o, d: ray_heightfield_normal(hf, o, d, 2.0))
    t, nrm = cast(o, d)
    assert np.all(np.asarray(t) > 0)
    expect = _unit(np.array([-slope, 0.0, 1.0]))
    np.testing.assert_allclose(np.asarray(nrm), np.tile(expect, (n, 1)), atol=1e-5)
    hit = o + np.asarray(t)[:, None] * d
    np.testing.assert_allclose(hit[:, 2], slope * hit[:, 0], atol=1e-5)
    # A horizontal ray from outside at x < x0 below the edge profile hits the -x side wall.
    o_w, d_w = np.tile([[X0 - 0.5, 0.0, -0.9]], (n, 1)), np.tile([[1.0, 0.0, 0.0]], (n, 1))
    t_w, n_w = cast(o_w, d_w)  # same shapes: no recompilation
    assert float(t_w[0]) == pytest.approx(0.5, abs=1e-5)
    np.testing.assert_allclose(np.asarray(n_w[0]), [-1.0, 0.0, 0.0])
