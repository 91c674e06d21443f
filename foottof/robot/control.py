"""Joint PD law with drive torque limits (NumPy or JAX); the substep loops that apply it live in
foottof.physics (MJX: ``mjx_backend.control_step``; MuJoCo C: ``mujoco_backend``).

The PD law is written once for both physics backends: :func:`pd_torque` runs on NumPy arrays (the
MuJoCo C backend's host callback, float64) and on JAX arrays (MJX, inside the compiled step).
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np

from foottof import constants


def _xp(*arrays):
    """``numpy`` if every argument is a NumPy array or a Python/NumPy scalar, else ``jax.numpy``."""
    host = all(isinstance(a, (np.ndarray, np.generic, float, int)) for a in arrays)
    return np if host else jp


def torque_bounds(
    qd: jax.Array,
    torque_limit: float = constants.TORQUE_LIMIT_NM,
    velocity_limit: float = constants.VELOCITY_LIMIT_RADS,
    saturation_torque: float | None = 1.5 * constants.TORQUE_LIMIT_NM,
) -> tuple[jax.Array, jax.Array]:
    """Lower and upper joint-torque bounds [N m] at joint speed ``qd`` [rad/s].

    DC-motor model (IsaacLab ``isaaclab.actuators.DCMotor``): ``upper = clip(sat * (1 - qd / v_lim),
    0, tau_lim)``, ``lower = clip(sat * (-1 - qd / v_lim), -tau_lim, 0)``. The full ``tau_lim``
    is available while ``|qd| <= v_lim * (1 - tau_lim / sat)`` (2.83 rad/s for 80 / 120 / 8.5);
    the torque that drives the joint further in its direction of motion falls linearly to 0 at
    ``v_lim``, while braking torque stays available. With ``saturation_torque=None`` the bounds
    are the constant +-``torque_limit`` (no speed dependence; ``velocity_limit`` unused).
    NumPy in, NumPy out (the MuJoCo C backend); otherwise JAX.
    """
    xp = _xp(qd)
    if saturation_torque is None:
        lim = xp.full_like(qd, torque_limit)
        return -lim, lim
    upper = xp.clip(saturation_torque * (1.0 - qd / velocity_limit), 0.0, torque_limit)
    lower = xp.clip(saturation_torque * (-1.0 - qd / velocity_limit), -torque_limit, 0.0)
    return lower, upper


def pd_torque(
    q_target: jax.Array,
    q: jax.Array,
    qd: jax.Array,
    kp: jax.Array | float,
    kd: jax.Array | float,
    torque_limit: float = constants.TORQUE_LIMIT_NM,
    velocity_limit: float = constants.VELOCITY_LIMIT_RADS,
    saturation_torque: float | None = 1.5 * constants.TORQUE_LIMIT_NM,
) -> jax.Array:
    """Joint PD torque ``kp (q_target - q) - kd qd`` clipped to the drive limits.

    Args:
      q_target: (..., 12) joint position targets [rad].
      q: (..., 12) joint positions [rad].
      qd: (..., 12) joint velocities [rad/s].
      kp: stiffness [N m/rad], scalar or broadcastable to (..., 12).
      kd: damping [N m s/rad], scalar or broadcastable to (..., 12).
      torque_limit: continuous torque limit [N m].
      velocity_limit: speed at which no torque is left in the direction of motion [rad/s].
      saturation_torque: peak torque of the DC-motor line [N m]; None = constant clip only
        (see :func:`torque_bounds`).

    Returns:
      (..., 12) joint torques [N m]: NumPy if all array inputs are NumPy, else JAX.
    """
    tau = kp * (q_target - q) - kd * qd
    lower, upper = torque_bounds(qd, torque_limit, velocity_limit, saturation_torque)
    return _xp(tau, lower, upper).clip(tau, lower, upper)
