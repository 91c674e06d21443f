"""Physics state shared by the backends, backend names, and the substep count."""

from __future__ import annotations

import math
import warnings
from typing import Protocol

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

from foottof import constants
from foottof.limits import PHYSICS_BACKENDS as BACKENDS  # valid env.physics values

_warned_host_roundtrip = False


@struct.dataclass
class PhysicsState:
    """The physics state the env carries per env (``State.pipeline_state``): a pure pytree.

    The env reads ``qpos``/``qvel`` and may write them (pushes, resets, sanitizing); that is
    all a backend needs to continue. The MuJoCo C backend integrates in float64 and also keeps
    the float64 values it returned, bit for bit, in ``exact``: where ``qpos``/``qvel``/
    ``qacc_warmstart`` still round-trip from ``exact`` (nothing wrote them), the next step
    continues from the float64 values, so a C-backend rollout equals one uninterrupted
    ``mj_step`` simulation. The MJX backend (float32) leaves ``exact`` empty.

    Attributes:
      qpos: (nq,) generalized positions (free joint pos, quat wxyz; 12 joints) float32.
      qvel: (nv,) generalized velocities float32.
      qacc_warmstart: (nv,) constraint-solver warm start float32.
      exact: (nq + 2 nv, 2) uint32, the float64 bits of (qpos, qvel, qacc_warmstart) as last
        returned by the MuJoCo C backend (zeros: none yet); (0, 2) for MJX.
    """

    qpos: jax.Array
    qvel: jax.Array
    qacc_warmstart: jax.Array
    exact: jax.Array


class PhysicsBackend(Protocol):
    """What the env needs of a physics backend (MjxPhysics, MujocoPhysics): one env per call,
    vmap for many; both hold the PD law (foottof.robot.pd_torque) between their substeps."""

    name: str  # "mjx" | "mujoco"
    num_substeps: int  # physics steps per control step

    def init(self, qpos: jax.Array) -> PhysicsState:
        """Resting state at ``qpos`` (nq,)."""
        ...

    def step(
        self,
        state: PhysicsState,
        q_target: jax.Array,
        kp: jax.Array,
        kd: jax.Array,
        foot_friction: jax.Array,
        added_mass_kg: jax.Array,
    ) -> tuple[PhysicsState, jax.Array]:
        """One control period holding ``q_target`` (12,) with gains ``kp``, ``kd``, this
        episode's foot friction and added base mass: (new state, (num_substeps, 12) torques)."""
        ...


def init_state(qpos: jax.Array, nv: int, exact: bool) -> PhysicsState:
    """Resting state at ``qpos`` (nq,): zero velocities and warm start."""
    qpos = jp.asarray(qpos, jp.float32)
    zeros = jp.zeros(qpos.shape[:-1] + (nv,), jp.float32)
    n_exact = qpos.shape[-1] + 2 * nv if exact else 0
    bits = jp.zeros(qpos.shape[:-1] + (n_exact, 2), jp.uint32)
    return PhysicsState(qpos=qpos, qvel=zeros, qacc_warmstart=zeros, exact=bits)


def num_substeps(timestep_s: float, control_dt_s: float = constants.CONTROL_DT_S) -> int:
    """Physics steps per control step: ``control_dt_s / timestep_s``, which must be an integer."""
    ratio = float(control_dt_s) / float(timestep_s)
    n = int(round(ratio))
    if n < 1 or not math.isclose(ratio, n, rel_tol=1e-9, abs_tol=1e-9):
        raise ValueError(
            f"env.model.timestep={timestep_s} s does not divide the control period "
            f"{control_dt_s} s into an integer number of physics steps ({ratio:.6g})"
        )
    return n


def resolve_backend(name: str) -> str:
    """``"mjx"`` or ``"mujoco"`` for ``env.physics``; "auto" is MuJoCo C on a CPU JAX backend.

    "mujoco" on a GPU/TPU JAX backend works but warns (once per process): every physics step then
    copies the state to the host and back.
    """
    global _warned_host_roundtrip
    if name not in BACKENDS:
        raise ValueError(f"env.physics={name!r} is not a physics backend; valid: {list(BACKENDS)}")
    platform = jax.default_backend()
    if name == "auto":
        return "mujoco" if platform == "cpu" else "mjx"
    if name == "mujoco" and platform != "cpu" and not _warned_host_roundtrip:
        _warned_host_roundtrip = True
        warnings.warn(
            f"env.physics='mujoco' on the {platform} JAX backend: every control step copies the "
            "physics state to the host and back (MuJoCo C runs on the CPU); 'mjx' keeps it on "
            "the device",
            stacklevel=2,
        )
    return name


def f64_to_bits(x: np.ndarray) -> np.ndarray:
    """(..., n) float64 -> (..., n, 2) uint32 holding the same bits."""
    x = np.ascontiguousarray(x, np.float64)
    return x.view(np.uint32).reshape(x.shape + (2,))


def bits_to_f64(bits: np.ndarray) -> np.ndarray:
    """(..., n, 2) uint32 -> (..., n) float64 (inverse of :func:`f64_to_bits`)."""
    bits = np.ascontiguousarray(bits, np.uint32)
    return bits.view(np.float64).reshape(bits.shape[:-1])
