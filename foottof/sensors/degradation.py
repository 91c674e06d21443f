"""ToF degradation: per-episode levels of offset, proportional/Gaussian/model noise and dropouts."""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from foottof import config_check
from foottof.sensors.noise_model import NoiseModel, missing_prob, noise_std
from foottof.sensors.tof import ToFReading

_FIELDS = ("offset_m", "proportional", "gaussian_m", "missing_rate", "model_scale")


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

    @classmethod
    def from_config(cls, noise_cfg, stage: int, spec=None) -> DegradationBounds:
        """DegradationBounds of ``noise.stage{stage}`` (config read outside jit, validated).

        ``spec`` is the pipeline's foottof.sensors.timing.TimingSpec (its delay capacity bounds the
        delay range), or None.

        Raises:
          ValueError: unknown stage; a field outside its range (foottof.config_check's rules for
            noise.stage*: bounds >= 0, missing_rate <= 1, 0 <= min_delay <= max_delay); a
            max_delay above spec.delay_capacity_steps (the timing ring buffer; unchecked
            without ``spec``).
        """
        if stage not in (1, 2):
            raise ValueError(f"stage must be 1 or 2, got {stage!r}")
        c = noise_cfg[f"stage{stage}"]
        names = (*_FIELDS, "min_delay_steps", "max_delay_steps")
        config_check.check_fields(f"noise.stage{stage}", {f: c[f] for f in names})
        vals = {f: float(c[f]) for f in _FIELDS}
        lo, hi = int(c.min_delay_steps), int(c.max_delay_steps)
        cap = spec.delay_capacity_steps if spec is not None else hi
        if hi > cap:
            raise ValueError(
                f"noise.stage{stage}.max_delay_steps={hi}: the delay range [{lo}, {hi}] must "
                f"end at or below the timing ring buffer's capacity, {cap} steps"
            )
        return cls(
            **{f: jp.float32(v) for f, v in vals.items()},
            min_delay_steps=jp.int32(lo),
            max_delay_steps=jp.int32(hi),
        )


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


def bounds_from_config(noise_cfg, stage: int, spec=None) -> DegradationBounds:
    """Alias of :meth:`DegradationBounds.from_config` (the name before the one adapter
    convention)."""
    return DegradationBounds.from_config(noise_cfg, stage, spec)


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
