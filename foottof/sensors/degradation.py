"""ToF degradation (offset, proportional/Gaussian/model noise, dropouts) and frame timing."""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from foottof.sensors.noise_model import NoiseModel, missing_prob, noise_std
from foottof.sensors.tof import ToFReading, ToFSpec

_FIELDS = ("offset_m", "proportional", "gaussian_m", "missing_rate", "model_scale")
_FRAME_EPS = 1e-5  # frames completing within this fraction of a period of a step count as done


@struct.dataclass
class DegradationBounds:
    """Upper bounds of the per-episode degradation levels (each level ~ U[0, bound]).

    Attributes:
      offset_m: static range offset bound [m]; per episode and sensor offset ~ U[-a, a],
        a ~ U[0, offset_m].
      proportional: bound of the std of the multiplicative noise [-] (d * (1 + s N(0, 1))).
      gaussian_m: bound of the std of the additive Gaussian noise [m].
      missing_rate: bound of the fraction of readings dropped (set to 0, invalid) [-].
      model_scale: bound of the scale applied to the characterized noise model (distance- and
        incidence-dependent std and missing rate; 1 = as characterized) [-].
      min_delay_steps, max_delay_steps: per-episode delay ~ U{min..max} [control steps].
    """

    offset_m: jax.Array
    proportional: jax.Array
    gaussian_m: jax.Array
    missing_rate: jax.Array
    model_scale: jax.Array
    min_delay_steps: jax.Array
    max_delay_steps: jax.Array


@struct.dataclass
class DegradationLevels:
    """Per-episode degradation levels of one env (drawn at reset).

    Attributes:
      offset_m: (F,) static range offset per sensor [m].
      proportional, gaussian_m, missing_rate, model_scale: () levels, see DegradationBounds.
    """

    offset_m: jax.Array
    proportional: jax.Array
    gaussian_m: jax.Array
    missing_rate: jax.Array
    model_scale: jax.Array


def bounds_from_config(noise_cfg, stage: int, spec: ToFSpec | None = None) -> DegradationBounds:
    """DegradationBounds of ``noise.stage{stage}`` (config read outside jit, validated).

    Raises:
      ValueError: unknown stage, negative bounds, missing_rate > 1, or a delay range outside
        0 <= min <= max <= spec.delay_capacity_steps.
    """
    if stage not in (1, 2):
        raise ValueError(f"stage must be 1 or 2, got {stage!r}")
    c = noise_cfg[f"stage{stage}"]
    vals = {f: float(c[f]) for f in _FIELDS}
    for f, v in vals.items():
        if not v >= 0.0:
            raise ValueError(f"noise.stage{stage}.{f} must be >= 0, got {v!r}")
    if vals["missing_rate"] > 1.0:
        raise ValueError(
            f"noise.stage{stage}.missing_rate must be in [0, 1], got {vals['missing_rate']!r}"
        )
    lo, hi = int(c.min_delay_steps), int(c.max_delay_steps)
    cap = spec.delay_capacity_steps if spec is not None else hi
    if not 0 <= lo <= hi <= cap:
        raise ValueError(
            f"noise.stage{stage} delay range [{lo}, {hi}] must satisfy 0 <= min <= max <= {cap} "
            f"(ring-buffer capacity)"
        )
    return DegradationBounds(
        **{f: jp.float32(v) for f, v in vals.items()},
        min_delay_steps=jp.int32(lo),
        max_delay_steps=jp.int32(hi),
    )


def zero_levels(num_sensors: int) -> DegradationLevels:
    """Levels that make :func:`degrade` the identity."""
    z = jp.float32(0.0)
    return DegradationLevels(jp.zeros((num_sensors,), jp.float32), z, z, z, z)


def sample_levels(key: jax.Array, bounds: DegradationBounds, num_sensors: int) -> DegradationLevels:
    """Draw one episode's levels: each level ~ U[0, bound]; offsets ~ U[-a, a] per sensor."""
    key_lv, key_off = jax.random.split(key)
    u = jax.random.uniform(key_lv, (len(_FIELDS),))  # level_i ~ U[0, bound_i]
    lv = {f: u[i] * getattr(bounds, f) for i, f in enumerate(_FIELDS)}
    # offset per sensor ~ U[-a, a], a = offset level
    lv["offset_m"] = lv["offset_m"] * jax.random.uniform(
        key_off, (num_sensors,), minval=-1.0, maxval=1.0
    )
    return DegradationLevels(**lv)


def degrade(
    key: jax.Array,
    levels: DegradationLevels,
    reading: ToFReading,
    model: NoiseModel,
    max_range_m: float,
    resolution_m: float,
) -> tuple[jax.Array, jax.Array]:
    """One degraded frame of one env (fresh noise per zone; pure).

    ``d' = d (1 + p N1) + offset + g N2 + s std(d, theta) N3``, re-quantized to
    ``resolution_m``; readings pushed beyond ``max_range_m`` are clipped to it and invalid,
    negative ones clipped to 0. Each zone is then dropped (0 m, invalid) with probability
    ``1 - (1 - missing_rate)(1 - s p_miss(d, theta))``. Zones that were invalid keep their value
    (``max_range_m``) unless dropped. With all levels 0 this is the identity.

    Args:
      key: PRNG key of this frame.
      levels: this episode's levels (offset (F,)).
      reading: noise-free (F, Z) frame.
      model: characterized noise model.
      max_range_m, resolution_m: sensor clip range and quantization [m] (static).

    Returns:
      distance_m (F, Z) [m] and valid (F, Z) bool.
    """
    d, valid, theta = reading.distance_m, reading.valid, reading.incidence_rad
    k_prop, k_gauss, k_model, k_miss = jax.random.split(key, 4)
    n_prop = jax.random.normal(k_prop, d.shape)
    n_gauss = jax.random.normal(k_gauss, d.shape)
    n_model = jax.random.normal(k_model, d.shape)
    s = levels.model_scale
    std_model = jp.where(s > 0.0, s * noise_std(model, d, theta), 0.0)
    p_model = jp.where(s > 0.0, jp.clip(s * missing_prob(model, d, theta), 0.0, 1.0), 0.0)
    noisy = (
        d * (1.0 + levels.proportional * n_prop)
        + levels.offset_m[:, None]
        + levels.gaussian_m * n_gauss
        + std_model * n_model
    )
    noisy = jp.round(noisy / resolution_m) * resolution_m
    beyond = noisy > max_range_m
    noisy = jp.clip(noisy, 0.0, max_range_m)
    p_miss = 1.0 - (1.0 - levels.missing_rate) * (1.0 - p_model)
    dropped = jax.random.uniform(k_miss, d.shape) < p_miss
    dist = jp.where(valid, noisy, d)
    dist = jp.where(dropped, 0.0, dist).astype(d.dtype)
    return dist, valid & ~beyond & ~dropped


# ----------------------------------------------------------------------------- frame timing


@struct.dataclass
class ToFObs:
    """What the policy sees from the ToF sensors at one control step.

    Attributes:
      distance_m: (F, Z) delayed, held, degraded readings [m] (0 = dropped, max range = none).
      valid: (F, Z) bool validity flags.
      age_s: (F,) time since the frame's completion, hold and delay included [s].
    """

    distance_m: jax.Array
    valid: jax.Array
    age_s: jax.Array


@struct.dataclass
class ToFState:
    """Per-env sensor state: frame clock, hold buffer, delay ring buffer, episode levels.

    Times are seconds since the episode reset. Sensor f completes frames at
    ``phase_s[f] + m / rate_hz`` (integer m, also negative: the sensor ran before the reset).

    Attributes:
      levels: per-episode DegradationLevels.
      delay_steps: () int32, per-episode delay k [control steps].
      phase_s: (F,) frame clock phase in [0, 1 / rate_hz) [s].
      step: () int32, control steps since reset.
      prev: noise-free ToFReading of the previous control step (F, Z).
      held_m, held_valid: (F, Z) the most recent completed (degraded) frame.
      held_time_s: (F,) completion time of the held frame [s].
      ring_m, ring_valid: (B, F, Z) held frames of the last B steps (B = capacity + 1).
      ring_time_s: (B, F) their completion times [s].
    """

    levels: DegradationLevels
    delay_steps: jax.Array
    phase_s: jax.Array
    step: jax.Array
    prev: ToFReading
    held_m: jax.Array
    held_valid: jax.Array
    held_time_s: jax.Array
    ring_m: jax.Array
    ring_valid: jax.Array
    ring_time_s: jax.Array


def _frame_index(spec: ToFSpec, phase_s, t):
    """Index m of the latest frame completed by time t (float; frames at phase + m / rate)."""
    return jp.floor((t - phase_s) / spec.frame_period_s + _FRAME_EPS)


def _latest_frame_time(spec: ToFSpec, phase_s, t):
    return phase_s + _frame_index(spec, phase_s, t) * spec.frame_period_s


def init(spec: ToFSpec) -> ToFState:
    """All-zero state with the right shapes and dtypes (e.g. for an env's initial pytree)."""
    f, z, b = spec.num_sensors, spec.num_zones, spec.delay_capacity_steps + 1
    zf = jp.zeros((f, z), jp.float32)
    zb = jp.zeros((f, z), bool)
    return ToFState(
        levels=zero_levels(f),
        delay_steps=jp.int32(0),
        phase_s=jp.zeros((f,), jp.float32),
        step=jp.int32(0),
        prev=ToFReading(zf, zb, zf),
        held_m=zf,
        held_valid=zb,
        held_time_s=jp.zeros((f,), jp.float32),
        ring_m=jp.zeros((b, f, z), jp.float32),
        ring_valid=jp.zeros((b, f, z), bool),
        ring_time_s=jp.zeros((b, f), jp.float32),
    )


def _observe(spec: ToFSpec, state: ToFState) -> ToFObs:
    b = spec.delay_capacity_steps + 1
    idx = jp.maximum(state.step - state.delay_steps, 0) % b  # oldest available = reset frame
    t = state.step.astype(jp.float32) * spec.control_dt_s
    return ToFObs(
        distance_m=state.ring_m[idx], valid=state.ring_valid[idx], age_s=t - state.ring_time_s[idx]
    )


def reset(
    spec: ToFSpec,
    bounds: DegradationBounds,
    model: NoiseModel,
    key: jax.Array,
    reading: ToFReading,
    phase_s: jax.Array | None = None,
) -> tuple[ToFState, ToFObs]:
    """New episode: draw levels, delay and frame phases; fill hold and ring with the first frame.

    Args:
      spec: sensor spec (static).
      bounds: degradation upper bounds of the current stage.
      model: characterized noise model.
      key: PRNG key.
      reading: noise-free frame at the reset state (F, Z).
      phase_s: optional (F,) frame phases in [0, 1 / rate_hz) [s]; None = random.

    Returns:
      (state, obs) with obs = the reset frame, age = time since its (pre-reset) completion.
    """
    key_lv, key_delay, key_phase, key_noise = jax.random.split(key, 4)
    f = spec.num_sensors
    levels = sample_levels(key_lv, bounds, f)
    # delay ~ U{min_delay_steps..max_delay_steps}
    delay = jax.random.randint(key_delay, (), bounds.min_delay_steps, bounds.max_delay_steps + 1)
    # frame phase per sensor ~ U[0, 1 / rate_hz): the sensors run asynchronously
    phase = jax.random.uniform(key_phase, (f,), maxval=spec.frame_period_s)
    if phase_s is not None:
        phase = jp.broadcast_to(jp.asarray(phase_s, jp.float32), (f,))
    dist, valid = degrade(key_noise, levels, reading, model, spec.max_range_m, spec.resolution_m)
    t0 = _latest_frame_time(spec, phase, jp.float32(0.0))
    b = spec.delay_capacity_steps + 1
    state = ToFState(
        levels=levels,
        delay_steps=delay.astype(jp.int32),
        phase_s=phase,
        step=jp.int32(0),
        prev=reading,
        held_m=dist,
        held_valid=valid,
        held_time_s=t0,
        ring_m=jp.broadcast_to(dist, (b,) + dist.shape),
        ring_valid=jp.broadcast_to(valid, (b,) + valid.shape),
        ring_time_s=jp.broadcast_to(t0, (b,) + t0.shape),
    )
    return state, _observe(spec, state)


def step(
    spec: ToFSpec, model: NoiseModel, state: ToFState, reading: ToFReading, key: jax.Array
) -> tuple[ToFState, ToFObs]:
    """Advance one control step: sample-and-hold at the sensor rate, then the k-step delay.

    A sensor whose clock completed a frame since the previous control step replaces its held
    frame with a newly degraded one. The scene is only known at control steps, so the frame's
    content is the noise-free reading of the control step nearest to its completion time (this
    step's ``reading`` or the previous one, at most half a control period off); ``age_s`` uses
    the exact completion time. Several frames within one step: only the newest is kept.
    The held frames go through a ring buffer; the policy sees the one pushed ``delay_steps``
    steps ago, or the reset frame if fewer steps have passed.

    Args:
      spec: sensor spec (static).
      model: characterized noise model.
      state: current ToFState.
      reading: noise-free frame at this control step (F, Z).
      key: PRNG key for this step's noise.

    Returns:
      (new state, obs).
    """
    n = state.step + 1
    dt = spec.control_dt_s
    t_now = n.astype(jp.float32) * dt
    m_now = _frame_index(spec, state.phase_s, t_now)
    t_prev = state.step.astype(jp.float32) * dt
    new = m_now > _frame_index(spec, state.phase_s, t_prev)  # completed in (t_prev, t_now]
    tau = state.phase_s + m_now * spec.frame_period_s
    use_now = (t_now - tau) <= 0.5 * dt  # nearest control step to the completion time
    pick = lambda a, b: jp.where(use_now[:, None], a, b)
    content = ToFReading(
        distance_m=pick(reading.distance_m, state.prev.distance_m),
        valid=pick(reading.valid, state.prev.valid),
        incidence_rad=pick(reading.incidence_rad, state.prev.incidence_rad),
    )
    dist, valid = degrade(key, state.levels, content, model, spec.max_range_m, spec.resolution_m)
    held_m = jp.where(new[:, None], dist, state.held_m)
    held_valid = jp.where(new[:, None], valid, state.held_valid)
    held_time = jp.where(new, tau, state.held_time_s)
    slot = n % (spec.delay_capacity_steps + 1)
    state = state.replace(
        step=n,
        prev=reading,
        held_m=held_m,
        held_valid=held_valid,
        held_time_s=held_time,
        ring_m=state.ring_m.at[slot].set(held_m),
        ring_valid=state.ring_valid.at[slot].set(held_valid),
        ring_time_s=state.ring_time_s.at[slot].set(held_time),
    )
    return state, _observe(spec, state)
