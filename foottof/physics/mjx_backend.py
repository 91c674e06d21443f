"""MJX physics backend: the control step (JAX PD + ``mjx.step`` substeps) inside the compiled step."""

from __future__ import annotations

import jax
import mujoco
import numpy as np
from mujoco import mjx

from foottof import constants
from foottof.physics.base import PhysicsState, init_state, num_substeps
from foottof.robot.control import pd_torque


def control_step(
    m: mjx.Model,
    d: mjx.Data,
    q_target: jax.Array,
    kp: jax.Array | float,
    kd: jax.Array | float,
    num_substeps: int = constants.DECIMATION,
    torque_limit: float = constants.TORQUE_LIMIT_NM,
    velocity_limit: float = constants.VELOCITY_LIMIT_RADS,
    saturation_torque: float | None = 1.5 * constants.TORQUE_LIMIT_NM,
) -> tuple[mjx.Data, jax.Array]:
    """Hold ``q_target`` for one control period: (JAX PD, ``mjx.step``) x ``num_substeps``.

    Args:
      m: MJX model (joint order of foottof.robot.make_model: qpos[7:19], qvel[6:18]).
      d: MJX data (unbatched; vmap for many envs).
      q_target: (12,) joint targets [rad], held over the substeps.
      kp, kd, torque_limit, velocity_limit, saturation_torque: see :func:`pd_torque`.
      num_substeps: physics steps per control step (static).

    Returns:
      (new data, (num_substeps, 12) torques applied at each substep [N m]).
    """

    def substep(d, _):
        tau = pd_torque(
            q_target,
            d.qpos[7:19],
            d.qvel[6:18],
            kp,
            kd,
            torque_limit,
            velocity_limit,
            saturation_torque,
        )
        d = mjx.step(m, d.replace(ctrl=tau))
        return d, tau

    return jax.lax.scan(substep, d, None, length=num_substeps)


class MjxPhysics:
    """Steps one env (vmap for many) with MJX; per-episode foot friction and base mass.

    Args:
      m: the compiled model (foottof.robot.make_model).
      control_kw: drive limits of :func:`foottof.robot.pd_torque` (torque_limit,
        velocity_limit, saturation_torque); the gains come per step.
    """

    name = "mjx"

    def __init__(self, m: mujoco.MjModel, control_kw: dict | None = None):
        self.mj_model = m
        self.num_substeps = num_substeps(m.opt.timestep)
        self.control_kw = dict(control_kw or {})
        self.mx = mjx.put_model(m)
        d0 = mujoco.MjData(m)
        mujoco.mj_resetDataKeyframe(m, d0, 0)
        mujoco.mj_forward(m, d0)
        self._d0 = mjx.put_data(m, d0)  # template: derived fields are recomputed by each step
        self._foot_geom_ids = np.array([m.geom(g).id for g in constants.FOOT_GEOMS])
        self._base_body_id = m.body(constants.BASE_BODY).id
        self.base_mass_kg = float(m.body_mass[self._base_body_id])

    def init(self, qpos: jax.Array) -> PhysicsState:
        """Resting state at ``qpos`` (nq,)."""
        return init_state(qpos, self.mj_model.nv, exact=False)

    def episode_model(self, foot_friction: jax.Array, added_mass_kg: jax.Array) -> mjx.Model:
        """The MJX model with this episode's foot friction and base mass (only these leaves vary)."""
        fr = self.mx.geom_friction.at[self._foot_geom_ids, 0].set(foot_friction)
        mass = self.mx.body_mass.at[self._base_body_id].set(self.base_mass_kg + added_mass_kg)
        return self.mx.replace(geom_friction=fr, body_mass=mass)

    def step(
        self,
        state: PhysicsState,
        q_target: jax.Array,
        kp: jax.Array,
        kd: jax.Array,
        foot_friction: jax.Array,
        added_mass_kg: jax.Array,
    ) -> tuple[PhysicsState, jax.Array]:
        """One control period: (PD torque, mjx.step) x num_substeps.

        Args:
          state: this env's physics state.
          q_target: (12,) joint targets [rad].
          kp, kd: PD gains, scalars or (12,).
          foot_friction: () sliding friction of the four feet.
          added_mass_kg: () mass added to the base [kg].

        Returns:
          (new state, (num_substeps, 12) torques applied at each substep [N m]).
        """
        mx = self.episode_model(foot_friction, added_mass_kg)
        d = self._d0.replace(qpos=state.qpos, qvel=state.qvel, qacc_warmstart=state.qacc_warmstart)
        d, taus = control_step(mx, d, q_target, kp, kd, self.num_substeps, **self.control_kw)
        new = state.replace(qpos=d.qpos, qvel=d.qvel, qacc_warmstart=d.qacc_warmstart)
        return new, taus
