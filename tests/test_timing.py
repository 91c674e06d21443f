"""foottof.sensors.timing: 60 Hz sample-and-hold, frame age and the k-step transport delay."""

import math

import jax
import jax.numpy as jp
import numpy as np
import pytest

from configs import _sensor
from foottof.sensors import (
    TimingSpec,
    ToFReading,
    ToFSpec,
    bounds_from_config,
    reset,
    step,
)
from foottof.sensors import noise_model as nm


def _reading(values, valid=True):
    v = jp.asarray(values, jp.float32)
    return ToFReading(distance_m=v, valid=jp.full(v.shape, valid), incidence_rad=jp.zeros_like(v))


def _zero_bounds(lo, hi):
    n = _sensor.get_noise_section()
    for k in ("offset_m", "proportional", "gaussian_m", "missing_rate", "model_scale"):
        n.stage1[k] = 0.0
    n.stage1.min_delay_steps, n.stage1.max_delay_steps = lo, hi
    return bounds_from_config(n, 1)


def _run(spec, bounds, phase, n_steps, key=0):
    """Feed reading value = 0.1 + 0.001 * step for n_steps; return obs distances and ages."""
    model = nm.load_model()
    f, z = spec.num_sensors, spec.num_zones
    state, obs = reset(
        spec,
        bounds,
        model,
        jax.random.PRNGKey(key),
        _reading(np.full((f, z), 0.1)),
        phase_s=jp.asarray(phase, jp.float32),
    )
    dists, delay = [obs.distance_m[:, 0]], int(state.delay_steps)

    def body(st, n):
        st, ob = step(
            spec, model, st, _reading(jp.full((f, z), 0.1) + 0.001 * n), jax.random.PRNGKey(n)
        )
        return st, (ob.distance_m[:, 0], ob.age_s)

    _, (d, a) = jax.lax.scan(body, state, jp.arange(1, n_steps + 1))
    return np.asarray(jp.concatenate([jp.stack(dists), d])), np.asarray(a), delay


@pytest.mark.parametrize("k", [0, 1, 3])
def test_delay_returns_reading_k_steps_earlier(k):
    spec = TimingSpec(
        ToFSpec(
            num_sensors=2,
            rate_hz=50.0,
            tilt_deg=((0.0, 0.0),) * 2,
            offset_m=((0.0, 0.0, 0.0),) * 2,
        ),
        delay_capacity_steps=4,
    )
    d, age, delay = _run(spec, _zero_bounds(k, k), [0.0, 0.0], 12)
    assert delay == k
    for n in range(13):  # frames at every control step (50 Hz, phase 0): value of step n - k
        np.testing.assert_allclose(d[n], 0.1 + 0.001 * max(n - k, 0), atol=1e-6)
    t = 0.02 * np.arange(1, 13)
    np.testing.assert_allclose(age[:, 0], t - 0.02 * np.maximum(np.arange(1, 13) - k, 0), atol=1e-5)


def test_delay_draw_and_capacity():
    spec = TimingSpec(ToFSpec(), delay_capacity_steps=4)
    bounds = _zero_bounds(1, 4)
    keys = jax.random.split(jax.random.PRNGKey(0), 256)
    rd = _reading(np.zeros((4, 16)))
    model = nm.load_model()
    states = jax.jit(jax.vmap(lambda k: reset(spec, bounds, model, k, rd)[0]))(keys)
    ks = np.asarray(states.delay_steps)
    assert set(ks.tolist()) == {1, 2, 3, 4}
    ph = np.asarray(states.phase_s)
    assert ph.min() >= 0.0 and ph.max() < 1 / 60 and ph.std() > 0.003  # random per sensor
    n = _sensor.get_noise_section()
    n.stage2.max_delay_steps = 5
    with pytest.raises(ValueError, match="delay range.*capacity"):
        bounds_from_config(n, 2, spec)
    with pytest.raises(ValueError, match="stage"):
        bounds_from_config(n, 3)


def test_sample_and_hold_ages_60hz_and_15hz():
    for grid, rate in ((4, 60.0), (8, 15.0)):
        spec = TimingSpec(
            ToFSpec(
                num_sensors=2,
                grid=grid,
                rate_hz=rate,
                tilt_deg=((0.0, 0.0),) * 2,
                offset_m=((0.0, 0.0, 0.0),) * 2,
            ),
            delay_capacity_steps=0,
        )
        phase = np.array([0.3, 0.7]) / rate  # no completion exactly between two steps
        d, age, _ = _run(spec, _zero_bounds(0, 0), phase, 30)
        period = 1 / rate
        for f in range(2):
            for n in range(1, 31):
                t = 0.02 * n
                m = math.floor((t - phase[f]) / period + 1e-5)
                tau = phase[f] + m * period  # completion time of the newest frame
                assert age[n - 1, f] == pytest.approx(t - tau, abs=1e-5)
                assert -1e-6 <= age[n - 1, f] < period + 1e-6
                # Content: reading of the control step nearest to tau (0.1 + 0.001 * step).
                near = round(tau / 0.02) if tau > 0 else 0
                near = max(near, 0)
                assert d[n, f] == pytest.approx(0.1 + 0.001 * near, abs=1e-6)
        if rate == 15.0:  # held over 3-4 control steps
            changes = np.count_nonzero(np.diff(d[:, 0]))
            assert 6 <= changes <= 9
