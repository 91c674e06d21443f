"""ToF frame timing: 60 Hz sample-and-hold with per-sensor phase, frame age, k-step delay ring."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
from flax import struct

from foottof import constants
from foottof.sensors.degradation import (
    DegradationBounds,
    DegradationLevels,
    degrade,
    sample_levels,
    zero_levels,
)
from foottof.sensors.noise_model import NoiseModel
from foottof.sensors.tof import ToFReading, ToFSpec

_FRAME_EPS = 1e-5  # frames completing within this fraction of a period of a step count as done


@dataclasses.dataclass(frozen=True)
class TimingSpec:
    """Static timing of the foot sensors' frames (hashable; read from config outside jit).

    Attributes:
      sensor: the sensors' geometry and rate (frame period, zone count, range clip and
        quantization of the degraded frames).
      delay_capacity_steps: ring-buffer capacity; the per-episode delay must not exceed it.
      control_dt_s: policy period [s].
    """

    sensor: ToFSpec = ToFSpec()
    delay_capacity_steps: int = 4
    control_dt_s: float = constants.CONTROL_DT_S

    @classmethod
    def from_config(
        cls, sensor: ToFSpec, noise_cfg, control_dt_s: float = constants.CONTROL_DT_S
    ) -> TimingSpec:
        """TimingSpec whose delay capacity is the largest ``max_delay_steps`` of ``noise.stage1`` /
        ``noise.stage2`` (so one compiled pipeline serves both stages)."""
        cap = max(int(noise_cfg[s].max_delay_steps) for s in ("stage1", "stage2"))
        return cls(sensor, delay_capacity_steps=cap, control_dt_s=float(control_dt_s))

    def __post_init__(self):
        if self.delay_capacity_steps < 0:
            raise ValueError(
                f"delay_capacity_steps must be >= 0, got {self.delay_capacity_steps!r}"
            )
        if not self.control_dt_s > 0.0:
            raise ValueError(f"control_dt_s must be > 0, got {self.control_dt_s!r}")

    @property
    def num_sensors(self) -> int:
        return self.sensor.num_sensors

    @property
    def num_zones(self) -> int:
        return self.sensor.num_zones

    @property
    def frame_period_s(self) -> float:
        return self.sensor.frame_period_s

    @property
    def max_range_m(self) -> float:
        return self.sensor.max_range_m

    @property
    def resolution_m(self) -> float:
        return self.sensor.resolution_m


def make_timing_spec(
    sensor: ToFSpec, noise_cfg, control_dt_s: float = constants.CONTROL_DT_S
) -> TimingSpec:
    """Alias of :meth:`TimingSpec.from_config` (the name before the one adapter convention)."""
    return TimingSpec.from_config(sensor, noise_cfg, control_dt_s)


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


def _frame_index(spec: TimingSpec, phase_s, t):
    """Index m of the latest frame completed by time t (float; frames at phase + m / rate)."""
    return jp.floor((t - phase_s) / spec.frame_period_s + _FRAME_EPS)


def _latest_frame_time(spec: TimingSpec, phase_s, t):
    return phase_s + _frame_index(spec, phase_s, t) * spec.frame_period_s


def init(spec: TimingSpec) -> ToFState:
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


def _observe(spec: TimingSpec, state: ToFState) -> ToFObs:
    b = spec.delay_capacity_steps + 1
    idx = jp.maximum(state.step - state.delay_steps, 0) % b  # oldest available = reset frame
    t = state.step.astype(jp.float32) * spec.control_dt_s
    return ToFObs(
        distance_m=state.ring_m[idx], valid=state.ring_valid[idx], age_s=t - state.ring_time_s[idx]
    )


def reset(
    spec: TimingSpec,
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
    spec: TimingSpec, model: NoiseModel, state: ToFState, reading: ToFReading, key: jax.Array
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
