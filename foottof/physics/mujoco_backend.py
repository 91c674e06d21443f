"""MuJoCo C physics backend: ``mujoco.batch.Batch`` through ``jax.pure_callback`` in the step.

The JAX program owns the state (:class:`PhysicsState`); each call loads it into the batch's state
rows, runs (PD torque, ``mj_step``) x num_substeps on the batch's thread pool and returns the new
state. Nothing is kept between calls but the batch objects themselves (one per batch size, made
lazily), whose rows every call overwrites, so the callback is a pure function, and
``mujoco.batch`` results are bit-identical at any thread count.
"""

from __future__ import annotations

import os
import threading

import jax
import jax.numpy as jp
import mujoco
import numpy as np
from mujoco import batch as mjbatch

from foottof import constants
from foottof.physics.base import (
    PhysicsState,
    bits_to_f64,
    f64_to_bits,
    init_state,
    num_substeps,
)
from foottof.robot import control


class MujocoPhysics:
    """Steps envs with MuJoCo C on ``nthread`` threads; per-episode foot friction and base mass.

    The same interface as :class:`foottof.physics.mjx_backend.MjxPhysics`; vmap ``step`` for many
    envs (the callback sees them as one batch: ``vmap_method="broadcast_all"``).

    A simulation that MuJoCo flags (any warning counter rises: bad qpos/qvel/qacc, after which
    MuJoCo resets its data; contact or constraint buffer full; bad control; an engine error)
    or whose state is not finite comes back with NaN qpos, qvel and warm start, which the env's
    divergence guard ends as a failure. The call itself never raises for a simulation's fault.

    Args:
      m: the compiled model (foottof.robot.make_model).
      control_kw: drive limits of :func:`foottof.robot.pd_torque`.
      nthread: MuJoCo threads; 0 = ``os.cpu_count()``.
    """

    name = "mujoco"

    def __init__(self, m: mujoco.MjModel, control_kw: dict | None = None, nthread: int = 0):
        if int(nthread) < 0:
            raise ValueError(f"env.physics_threads={nthread} must be >= 0 (0 = all CPUs)")
        self.mj_model = m
        self.num_substeps = num_substeps(m.opt.timestep)
        self.control_kw = dict(control_kw or {})
        self.nthread = int(nthread) or (os.cpu_count() or 1)
        self._foot_geom_ids = np.array([m.geom(g).id for g in constants.FOOT_GEOMS])
        self._base_body_id = m.body(constants.BASE_BODY).id
        self.base_mass_kg = float(m.body_mass[self._base_body_id])
        self._batches: dict[int, mjbatch.Batch] = {}
        self._lock = threading.Lock()

    def init(self, qpos: jax.Array) -> PhysicsState:
        """Resting state at ``qpos`` (nq,)."""
        return init_state(qpos, self.mj_model.nv, exact=True)

    def step(
        self,
        state: PhysicsState,
        q_target: jax.Array,
        kp: jax.Array,
        kd: jax.Array,
        foot_friction: jax.Array,
        added_mass_kg: jax.Array,
    ) -> tuple[PhysicsState, jax.Array]:
        """One control period: (PD torque, mj_step) x num_substeps, on the host.

        Args: as :meth:`foottof.physics.mjx_backend.MjxPhysics.step`.

        Returns:
          (new state, (num_substeps, 12) torques applied at each substep [N m]).
        """
        nq, nv, nj = self.mj_model.nq, self.mj_model.nv, constants.NUM_JOINTS
        gain = lambda g: jp.broadcast_to(jp.asarray(g, jp.float32), (nj,))  # noqa: E731
        out_shapes = (
            jax.ShapeDtypeStruct((nq,), jp.float32),
            jax.ShapeDtypeStruct((nv,), jp.float32),
            jax.ShapeDtypeStruct((nv,), jp.float32),
            jax.ShapeDtypeStruct((nq + 2 * nv, 2), jp.uint32),
            jax.ShapeDtypeStruct((self.num_substeps, nj), jp.float32),
        )
        qpos, qvel, warm, exact, taus = jax.pure_callback(
            self._host_step,
            out_shapes,
            state.qpos,
            state.qvel,
            state.qacc_warmstart,
            state.exact,
            jp.asarray(q_target, jp.float32),
            gain(kp),
            gain(kd),
            jp.asarray(foot_friction, jp.float32),
            jp.asarray(added_mass_kg, jp.float32),
            vmap_method="broadcast_all",
        )
        return PhysicsState(qpos=qpos, qvel=qvel, qacc_warmstart=warm, exact=exact), taus

    # ----------------------------------------------------------------------------------------
    # Host side
    def batch(self, nsim: int) -> mjbatch.Batch:
        """The cached batch of ``nsim`` simulations (made on first use)."""
        b = self._batches.get(nsim)
        if b is None:
            b = mjbatch.Batch(self.mj_model, nsim=nsim, nthread=min(self.nthread, nsim))
            self._batches[nsim] = b
        return b

    def _host_step(self, qpos, qvel, warm, exact, q_target, kp, kd, friction, added_mass):
        lead = np.shape(qpos)[:-1]  # () for one env, (N,) under vmap, more under nested vmaps
        n = int(np.prod(lead))
        nq, nv = self.mj_model.nq, self.mj_model.nv
        flat = lambda x: np.asarray(x).reshape((n,) + np.shape(x)[len(lead) :])  # noqa: E731
        x32 = np.concatenate([flat(qpos), flat(qvel), flat(warm)], axis=-1)
        x64 = bits_to_f64(flat(exact))
        # Continue from the float64 state where the float32 fields still equal it (untouched).
        x = np.where(x64.astype(np.float32) == x32, x64, x32.astype(np.float64))
        q_target = flat(q_target).astype(np.float64)
        kp, kd = flat(kp).astype(np.float64), flat(kd).astype(np.float64)
        friction = flat(friction).astype(np.float64)
        mass = self.base_mass_kg + flat(added_mass).astype(np.float64)
        taus = np.empty((n, self.num_substeps, constants.NUM_JOINTS))
        failed = np.zeros(n, bool)
        with self._lock:  # a batch serves one call at a time
            b = self.batch(n)
            b.bind("time")[:] = 0.0
            b.bind("qpos")[:] = x[:, :nq]
            b.bind("qvel")[:] = x[:, nq : nq + nv]
            b.bind("qacc_warmstart")[:] = x[:, nq + nv :]
            b.expand("geom_friction")[:, self._foot_geom_ids, 0] = friction[:, None]
            b.expand("body_mass")[:, self._base_body_id] = mass
            b.warning[...] = 0
            q, qd, ctrl = b.bind("qpos"), b.bind("qvel"), b.bind("ctrl")
            for k in range(self.num_substeps):
                tau = control.pd_torque(
                    q_target, q[:, 7:19], qd[:, 6:18], kp, kd, **self.control_kw
                )
                ctrl[:] = tau
                taus[:, k] = tau
                try:
                    b.step()
                except mjbatch.SimulationError as e:  # those sims kept their state: flag them
                    failed[e.ids] = True
            out = np.concatenate([q, qd, b.bind("qacc_warmstart")], axis=-1)
            failed |= b.warning[:, :, 1].any(axis=-1)
        failed |= ~np.isfinite(out).all(axis=-1)
        out[failed] = np.nan
        taus[failed] = 0.0
        out32 = out.astype(np.float32)
        return (
            out32[:, :nq].reshape(lead + (nq,)),
            out32[:, nq : nq + nv].reshape(lead + (nv,)),
            out32[:, nq + nv :].reshape(lead + (nv,)),
            f64_to_bits(out).reshape(lead + (nq + 2 * nv, 2)),
            taus.astype(np.float32).reshape(lead + (self.num_substeps, constants.NUM_JOINTS)),
        )
