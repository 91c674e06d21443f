"""Odometry: the robot's estimate of its base velocity, the truth plus uniform per-axis noise."""

from __future__ import annotations

import jax

# Odometry (estimated base velocity) noise at the 100 % level: uniform per axis, per step (paper).
ODOM_LIN_NOISE_MS = 0.1  # linear velocity noise half-width [m/s]
ODOM_ANG_NOISE_RADS = 0.2  # angular velocity noise half-width [rad/s]


def noisy_odometry(
    key: jax.Array, lin_vel_base: jax.Array, ang_vel_base: jax.Array, level: float
) -> tuple[jax.Array, jax.Array]:
    """Estimated base velocities: truth plus uniform per-axis noise scaled by ``level``.

    Args:
      key: PRNG key for this step's noise.
      lin_vel_base: (..., 3) true linear velocity in the base frame [m/s].
      ang_vel_base: (..., 3) true angular velocity in the base frame [rad/s].
      level: noise level, 1.0 = 100 % (+-0.1 m/s, +-0.2 rad/s); >= 0.

    Returns:
      (lin_vel_est (..., 3), ang_vel_est (..., 3)).
    """
    if isinstance(level, (int, float)) and not level >= 0.0:
        raise ValueError(f"odometry noise level={level} must be >= 0 (1.0 = 100 %)")
    key_lin, key_ang = jax.random.split(key)
    # lin noise ~ U(-0.1 level, 0.1 level) m/s, ang noise ~ U(-0.2 level, 0.2 level) rad/s per axis.
    n_lin = jax.random.uniform(key_lin, lin_vel_base.shape, lin_vel_base.dtype, -1.0, 1.0)
    n_ang = jax.random.uniform(key_ang, ang_vel_base.shape, ang_vel_base.dtype, -1.0, 1.0)
    return (
        lin_vel_base + level * ODOM_LIN_NOISE_MS * n_lin,
        ang_vel_base + level * ODOM_ANG_NOISE_RADS * n_ang,
    )
