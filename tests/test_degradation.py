"""foottof.sensors.degradation: offset, proportional and Gaussian noise, missing readings."""

import jax
import jax.numpy as jp
import numpy as np
import pytest

from configs import _sensor
from foottof.sensors import (
    ToFReading,
    bounds_from_config,
    degrade,
    sample_levels,
    zero_levels,
)
from foottof.sensors import noise_model as nm

DEGRADE = jax.jit(degrade, static_argnums=(4, 5))


def _random_reading(key, f=4, z=16):
    k1, k2, k3 = jax.random.split(key, 3)
    d = jp.round(jax.random.uniform(k1, (f, z), minval=0.02, maxval=1.0) * 1000) / 1000
    valid = jax.random.uniform(k2, (f, z)) > 0.2
    return ToFReading(jp.where(valid, d, 1.0), valid, jax.random.uniform(k3, (f, z), maxval=1.4))


def test_degradation_level_zero_is_identity():
    model = nm.load_model()
    keys = jax.random.split(jax.random.PRNGKey(3), 64)

    def one(k):
        rd = _random_reading(k)
        d, v = degrade(jax.random.fold_in(k, 1), zero_levels(4), rd, model, 1.0, 0.001)
        return rd.distance_m, rd.valid, d, v

    d0, v0, d, v = jax.jit(jax.vmap(one))(keys)
    np.testing.assert_array_equal(np.asarray(d), np.asarray(d0))
    np.testing.assert_array_equal(np.asarray(v), np.asarray(v0))


def test_degradation_levels_and_effects():
    model = nm.load_model()
    noise = _sensor.get_noise_section()
    b2 = bounds_from_config(noise, 2)
    lv = jax.jit(jax.vmap(lambda k: sample_levels(k, b2, 4)))(
        jax.random.split(jax.random.PRNGKey(0), 2000)
    )
    for f in ("proportional", "gaussian_m", "missing_rate", "model_scale"):
        x = np.asarray(getattr(lv, f))
        bound = float(getattr(b2, f))
        assert x.min() >= 0 and x.max() <= bound and abs(x.mean() - bound / 2) < 0.05 * bound
    assert np.abs(np.asarray(lv.offset_m)).max() <= float(b2.offset_m)
    # Gaussian only: residual std = level; missing only: dropped fraction = level, set to 0.
    rd = ToFReading(jp.full((4, 4096), 0.5), jp.ones((4, 4096), bool), jp.zeros((4, 4096)))
    z = zero_levels(4)
    d, v = DEGRADE(
        jax.random.PRNGKey(1), z.replace(gaussian_m=jp.float32(0.01)), rd, model, 1.0, 0.001
    )
    assert np.std(np.asarray(d) - 0.5) == pytest.approx(0.01, rel=0.05) and np.asarray(v).all()
    d, v = DEGRADE(
        jax.random.PRNGKey(2), z.replace(missing_rate=jp.float32(0.2)), rd, model, 1.0, 0.001
    )
    v = np.asarray(v)
    assert (~v).mean() == pytest.approx(0.2, abs=0.01) and np.all(np.asarray(d)[~v] == 0.0)
    off = z.replace(offset_m=jp.array([0.01, -0.02, 0.0, 0.6], jp.float32))
    d, v = DEGRADE(jax.random.PRNGKey(3), off, rd, model, 1.0, 0.001)
    np.testing.assert_allclose(np.asarray(d)[:3, 0], [0.51, 0.48, 0.5], atol=1e-6)
    assert np.all(np.asarray(d)[3] == 1.0) and not np.asarray(v)[3].any()  # pushed beyond 1 m
    # Characterized model: noisier and more often missing at range and oblique incidence.
    near = ToFReading(jp.full((4, 4096), 0.2), jp.ones((4, 4096), bool), jp.zeros((4, 4096)))
    far = ToFReading(jp.full((4, 4096), 0.9), jp.ones((4, 4096), bool), jp.full((4, 4096), 1.0))
    one = z.replace(model_scale=jp.float32(1.0))
    dn, vn = DEGRADE(jax.random.PRNGKey(4), one, near, model, 1.0, 0.001)
    df, vf = DEGRADE(jax.random.PRNGKey(5), one, far, model, 1.0, 0.001)
    assert np.std(np.asarray(df)[np.asarray(vf)]) > 3 * np.std(np.asarray(dn)[np.asarray(vn)])
    assert (~np.asarray(vf)).mean() > 5 * (~np.asarray(vn)).mean()
