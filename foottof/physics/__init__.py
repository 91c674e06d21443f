"""Physics backends between robot/ and envs/: MJX (on device) or MuJoCo C (host callback).

``make_physics(name, mj_model, control_kw, nthread)`` picks the backend named by ``env.physics``
("auto": MuJoCo C on a CPU JAX backend, MJX otherwise). Both implement :class:`PhysicsBackend`:
``init(qpos) -> PhysicsState`` and ``step(state, q_target, kp, kd, foot_friction, added_mass_kg)
-> (state, taus)`` for one env (vmap for many), with the same PD law (foottof.robot.pd_torque)
between substeps (MJX: ``mjx_backend.control_step``; MuJoCo C: ``mujoco_backend``) and the same
per-episode model changes.
"""

from __future__ import annotations

import mujoco

from foottof.physics.base import (
    BACKENDS,
    PhysicsBackend,
    PhysicsState,
    num_substeps,
    resolve_backend,
)
from foottof.physics.mjx_backend import MjxPhysics
from foottof.physics.mujoco_backend import MujocoPhysics


def make_physics(
    name: str, m: mujoco.MjModel, control_kw: dict | None = None, nthread: int = 0
) -> PhysicsBackend:
    """The physics backend ``name`` (one of BACKENDS) for model ``m``.

    Args:
      name: "auto", "mjx" or "mujoco" (config ``env.physics``).
      m: the compiled model.
      control_kw: drive limits of foottof.robot.pd_torque (torque_limit, velocity_limit,
        saturation_torque); the gains are passed per step.
      nthread: MuJoCo C threads (``env.physics_threads``), 0 = os.cpu_count(); unused by MJX.
    """
    name = resolve_backend(name)
    if name == "mjx":
        return MjxPhysics(m, control_kw)
    return MujocoPhysics(m, control_kw, nthread)


__all__ = [
    "BACKENDS",
    "MjxPhysics",
    "MujocoPhysics",
    "PhysicsBackend",
    "PhysicsState",
    "make_physics",
    "num_substeps",
    "resolve_backend",
]
