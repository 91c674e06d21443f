"""Per-episode domain randomization: friction, base mass, motor strength, PD gains, noise, pushes."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
from flax import struct


@struct.dataclass
class EpisodeParams:
    """Per-env physical and observation parameters, drawn at every reset.

    Attributes:
      friction: foot sliding friction coefficient [-].
      added_mass_kg: mass added to the base [kg].
      motor_strength: multiplier of the PD torque [-].
      kp_scale, kd_scale: multipliers of the nominal PD gains [-].
      joint_pos_noise_rad: std of Gaussian noise on joint position readings [rad].
      joint_vel_noise_rads: std of Gaussian noise on joint velocity readings [rad/s].
      joint_offset_rad: (12,) static offset added to joint readings (evaluation hook, 0 in training).
      odometry_level: multiple of the 100% odometry noise (+-0.1 m/s, +-0.2 rad/s uniform per axis).
      push_step: control step of the next push (int32).
    """

    friction: jax.Array
    added_mass_kg: jax.Array
    motor_strength: jax.Array
    kp_scale: jax.Array
    kd_scale: jax.Array
    joint_pos_noise_rad: jax.Array
    joint_vel_noise_rads: jax.Array
    joint_offset_rad: jax.Array
    odometry_level: jax.Array
    push_step: jax.Array


@dataclasses.dataclass(frozen=True)
class RandomizationSpec:
    """The ``env.randomization`` section, read once (``RandomizationSpec.from_config``): ranges
    are (lo, hi) tuples; what :func:`sample_episode_params` and the env's push read."""

    enabled: bool  # per-episode domain randomization on/off
    nominal_friction: float  # foot friction when randomization is off [-]
    friction_range: tuple[float, float]  # [-]
    added_mass_kg_range: tuple[float, float]  # [kg]
    motor_strength_range: tuple[float, float]  # [-]
    kp_scale_range: tuple[float, float]  # [-]
    kd_scale_range: tuple[float, float]  # [-]
    joint_pos_noise_rad: float  # upper end of the per-episode noise std [rad]
    joint_vel_noise_rads: float  # upper end of the per-episode noise std [rad/s]
    push_vel_mps: float  # push: base velocity change ~ U(+-this) per horizontal axis [m/s]
    joint_offset_rad: float  # static offset on all joint readings (evaluation only) [rad]
    odometry_level: float  # multiple of the 100 % odometry noise [-]

    @classmethod
    def from_config(cls, rcfg) -> RandomizationSpec:
        pair = lambda v: (float(v[0]), float(v[1]))  # noqa: E731
        return cls(
            enabled=bool(rcfg.enabled),
            nominal_friction=float(rcfg.nominal_friction),
            friction_range=pair(rcfg.friction_range),
            added_mass_kg_range=pair(rcfg.added_mass_kg_range),
            motor_strength_range=pair(rcfg.motor_strength_range),
            kp_scale_range=pair(rcfg.kp_scale_range),
            kd_scale_range=pair(rcfg.kd_scale_range),
            joint_pos_noise_rad=float(rcfg.joint_pos_noise_rad),
            joint_vel_noise_rads=float(rcfg.joint_vel_noise_rads),
            push_vel_mps=float(rcfg.push_vel_mps),
            joint_offset_rad=float(rcfg.joint_offset_rad),
            odometry_level=float(rcfg.odometry_level),
        )


def _u(key, lo_hi) -> jax.Array:
    lo, hi = lo_hi
    return jax.random.uniform(key, (), minval=lo, maxval=hi)


def sample_episode_params(
    key: jax.Array, rcfg: RandomizationSpec, push_interval_steps: int
) -> EpisodeParams:
    """Draws one env's parameters.

    Args:
      key: PRNG key.
      rcfg: the ``env.randomization`` section (RandomizationSpec.from_config).
      push_interval_steps: mean control steps between pushes (static).
    """
    keys = jax.random.split(key, 9)
    enabled = rcfg.enabled

    def draw(k, rng, nominal):
        return _u(k, rng) if enabled else jp.asarray(nominal, jp.float32)

    return EpisodeParams(
        friction=draw(keys[0], rcfg.friction_range, rcfg.nominal_friction),  # ~ U(range)
        added_mass_kg=draw(keys[1], rcfg.added_mass_kg_range, 0.0),  # ~ U(range)
        motor_strength=draw(keys[2], rcfg.motor_strength_range, 1.0),  # ~ U(range)
        kp_scale=draw(keys[3], rcfg.kp_scale_range, 1.0),  # ~ U(range)
        kd_scale=draw(keys[4], rcfg.kd_scale_range, 1.0),  # ~ U(range)
        joint_pos_noise_rad=draw(keys[5], (0.0, rcfg.joint_pos_noise_rad), 0.0),  # ~ U[0, upper]
        joint_vel_noise_rads=draw(keys[6], (0.0, rcfg.joint_vel_noise_rads), 0.0),  # ~ U[0, upper]
        joint_offset_rad=jp.full((12,), rcfg.joint_offset_rad, jp.float32),  # evaluation hook
        odometry_level=jp.asarray(rcfg.odometry_level, jp.float32),  # 1.0 = paper's 100 %
        # first push ~ U{push_interval/2 .. 3 push_interval/2}
        push_step=jax.random.randint(
            keys[8], (), push_interval_steps // 2, 3 * push_interval_steps // 2 + 1
        ),
    )
