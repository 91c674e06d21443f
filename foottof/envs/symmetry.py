"""Left-right mirror maps of the ToF env: every observation block, the action and the feet.

The mirror is the reflection of the world in a vertical x-z plane (world y -> -y, every tile
walks along +x), which takes the robot's base frame to its mirror image (base y -> -y): the left
legs become the right ones. Each map is a signed permutation ``x -> x[..., perm] * sign`` over the
last axis, its own inverse (a reflection twice is the identity); checked when built.

How each quantity turns (S = diag(1, -1, 1)):

- polar vectors (projected gravity, base linear velocity, goal direction): ``v -> S v``;
- the base angular velocity, an axial vector: ``w -> -S w = (-wx, wy, -wz)``;
- joints (positions, velocities, actions): LF <-> RF, LH <-> RH; a rotation about an axis in the
  mirror plane changes sign, about one normal to it does not: HAA (axis +x on every leg,
  foottof.robot.model) negates, HFE and KFE (axis +y) keep their sign;
- ToF sensors: the left foot's sensor frame reflects onto the right foot's with its y axis
  reversed (site frames: foottof.robot.kinematics.tof_site_rotation, R_x(pi +- tilt)), so zone
  ``row * grid + col`` (col along the sensor's +y, foottof.sensors.tof.ToFSpec) reads as zone
  ``row * grid + (grid - 1 - col)`` of the mirrored foot's sensor; a sensor's extra tilt
  (tilt_x, tilt_y) and offset (ox, oy, oz) mirror to (-tilt_x, tilt_y) and (ox, -oy, oz), and a
  config whose sensors have no such mirror partner has no mirror (ValueError);
- terrain samples: the critic's and the teacher's base scans (rows along base x, 9 columns
  along base y, foottof.envs.observations.critic_scan_points) flip their columns; the foot
  patches (3 x 3, dx outer, dy inner, world-aligned) swap the feet and flip dy;
- scalars (distances, time left, friction, mass, contacts' values) stay.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

import jax.numpy as jp
import numpy as np

from foottof import constants
from foottof.envs import observations as obs_lib


@dataclasses.dataclass(frozen=True, eq=False)
class SignedPerm:
    """``x -> x[..., perm] * sign`` over the last axis (jit/vmap-able; a NumPy input stays NumPy).

    Attributes:
      perm: (n,) int, entry i of the image reads entry perm[i] of the input.
      sign: (n,) float of +-1.
    """

    perm: np.ndarray
    sign: np.ndarray

    def __post_init__(self):
        perm = np.asarray(self.perm, np.int64)
        sign = np.asarray(self.sign, np.float32)
        n = perm.shape[0]
        if perm.shape != (n,) or sign.shape != (n,) or sorted(perm.tolist()) != list(range(n)):
            raise ValueError(
                f"not a signed permutation: perm {perm.tolist()}, sign {sign.tolist()}"
            )
        if not np.all(np.abs(sign) == 1.0):
            raise ValueError(f"signs must be +-1, got {sign.tolist()}")
        # its own inverse: perm o perm = id and the signs of i and perm[i] agree
        if not (np.array_equal(perm[perm], np.arange(n)) and np.all(sign[perm] == sign)):
            raise ValueError("a mirror map must be its own inverse")
        object.__setattr__(self, "perm", perm)
        object.__setattr__(self, "sign", sign)

    @property
    def size(self) -> int:
        return int(self.perm.shape[0])

    def __call__(self, x):
        if x.shape[-1] != self.size:
            raise ValueError(f"mirror map of size {self.size} applied to shape {x.shape}")
        if isinstance(x, np.ndarray):
            return x[..., self.perm] * self.sign.astype(x.dtype)
        return jp.take(x, self.perm, axis=-1) * jp.asarray(self.sign, x.dtype)

    def first(self, n: int) -> SignedPerm:
        """The map of the first ``n`` entries (they must map among themselves)."""
        if not 0 <= n <= self.size or np.any(self.perm[:n] >= n):
            raise ValueError(f"the first {n} of {self.size} entries do not mirror among themselves")
        return SignedPerm(self.perm[:n], self.sign[:n])


def identity(n: int) -> SignedPerm:
    return SignedPerm(np.arange(n), np.ones(n))


def concat(*maps: SignedPerm) -> SignedPerm:
    """The map of the concatenated blocks, each mirrored by its own map."""
    perms, start = [], 0
    for m in maps:
        perms.append(m.perm + start)
        start += m.size
    return SignedPerm(np.concatenate(perms), np.concatenate([m.sign for m in maps]))


def blocks(outer: Sequence[int], inner: SignedPerm) -> SignedPerm:
    """Items of ``inner.size`` entries each (item-major), item o moving to ``outer[o]`` and each
    item's entries mirrored by ``inner``."""
    k = inner.size
    perm = np.concatenate([outer_o * k + inner.perm for outer_o in outer])
    return SignedPerm(perm, np.tile(inner.sign, len(outer)))


def grid_flip(rows: int, cols: int) -> SignedPerm:
    """Row-major (rows x cols) grid whose columns reverse: index r * cols + c <- r * cols +
    (cols - 1 - c)."""
    return blocks(range(rows), SignedPerm(np.arange(cols)[::-1], np.ones(cols)))


def _mirror_leg(name: str) -> str:
    """'LF' <-> 'RF', 'LH' <-> 'RH' (and the same prefix of a joint or site name)."""
    swap = {"L": "R", "R": "L"}
    return swap[name[0]] + name[1:]


# The feet (constants.FEET order) and the 12 joints (constants.JOINT_NAMES order).
FOOT_PERM = tuple(constants.FEET.index(_mirror_leg(f)) for f in constants.FEET)  # (1, 0, 3, 2)
FEET = SignedPerm(FOOT_PERM, np.ones(constants.NUM_FEET))
JOINTS = SignedPerm(
    [constants.JOINT_NAMES.index(_mirror_leg(j)) for j in constants.JOINT_NAMES],
    [-1.0 if j.endswith("_HAA") else 1.0 for j in constants.JOINT_NAMES],
)
ACTION = JOINTS  # actions are joint-target offsets from the (symmetric) default pose
POLAR_VEC = SignedPerm([0, 1, 2], [1.0, -1.0, 1.0])  # S v
AXIAL_VEC = SignedPerm([0, 1, 2], [-1.0, 1.0, -1.0])  # -S w
GOAL = SignedPerm([0, 1, 2, 3], [1.0, 1.0, -1.0, 1.0])  # distance, direction x, y, time left
FOOT_PATCHES = blocks(FOOT_PERM, grid_flip(3, 3))  # 4 feet x (dx outer, dy inner)
SCAN_COLS = 9  # columns (base y) of the critic's and the teacher's scans
CRITIC_SCAN = grid_flip(obs_lib.critic_scan_points().shape[0] // SCAN_COLS, SCAN_COLS)  # 171
ACTOR_SCAN = grid_flip(obs_lib.ACTOR_SCAN_ROWS, SCAN_COLS)  # 117


def sensor_perm(sites, tilt_deg, offset_m) -> tuple[int, ...]:
    """(F,) the sensor each sensor mirrors onto: the one on the mirrored foot's site with the
    extra tilt (-tilt_x, tilt_y) and the offset (ox, -oy, oz) (module docstring).

    Raises:
      ValueError: a sensor without such a partner (e.g. a tilt on one side only).
    """
    tilt = np.asarray(tilt_deg, np.float64).reshape(len(sites), 2)
    off = np.asarray(offset_m, np.float64).reshape(len(sites), 3)
    perm = []
    for i, site in enumerate(sites):
        want = (_mirror_leg(site), tilt[i] * [-1.0, 1.0], off[i] * [1.0, -1.0, 1.0])
        match = [
            j
            for j, s in enumerate(sites)
            if s == want[0] and np.allclose(tilt[j], want[1]) and np.allclose(off[j], want[2])
        ]
        if not match:
            raise ValueError(
                f"sensor {i} ({site}, tilt {tilt[i].tolist()} deg, offset {off[i].tolist()} m) "
                f"has no mirror partner ({want[0]}, tilt {want[1].tolist()}, offset "
                f"{want[2].tolist()}): the sensor layout is not left-right symmetric"
            )
        perm.append(match[0] if match[0] not in perm else match[-1])
    return tuple(perm)


def tof_maps(perm_sensors: Sequence[int], grid: int) -> tuple[SignedPerm, SignedPerm]:
    """(zone readings (F x grid^2, sensor-major), per-sensor values (F,))."""
    return blocks(perm_sensors, grid_flip(grid, grid)), SignedPerm(
        perm_sensors, np.ones(len(perm_sensors))
    )


def actor_map(perm_sensors: Sequence[int], grid: int) -> SignedPerm:
    """The actor's sensor-and-body blocks (foottof.envs.observations.actor_obs_layout)."""
    zones, per_sensor = tof_maps(perm_sensors, grid)
    by_block = {
        "tof_distance": zones,
        "tof_valid": zones,
        "tof_age": per_sensor,
        "joint_pos": JOINTS,
        "joint_vel": JOINTS,
        "projected_gravity": POLAR_VEC,
        "base_lin_vel": POLAR_VEC,
        "base_ang_vel": AXIAL_VEC,
        "goal": GOAL,
        "last_action": JOINTS,
    }
    layout = obs_lib.actor_obs_layout(len(perm_sensors), grid * grid)
    missing = [name for name, *_ in layout if name not in by_block]
    if missing:
        raise ValueError(f"actor observation blocks {missing} have no mirror map")
    maps = [by_block[name] for name, *_ in layout]
    for m, (name, start, stop, _) in zip(maps, layout, strict=True):
        if m.size != stop - start:
            raise ValueError(f"mirror map of {name} has size {m.size}, the block {stop - start}")
    return concat(*maps)


def actor_terrain_map(seen: bool) -> SignedPerm:
    """The teacher's terrain inputs (env.actor_terrain): foot patches (36) + base scan (117), and
    with env.actor_terrain_seen their 153 seen flags after them."""
    heights = concat(FOOT_PATCHES, ACTOR_SCAN)
    return concat(heights, heights) if seen else heights


def critic_map(perm_sensors: Sequence[int], grid: int, height_scan: bool) -> SignedPerm:
    """The critic's privileged_state: the clean actor blocks, foot patches (36), contacts (4),
    friction (1), added mass (1), and with env.critic_height_scan the base scan (171)."""
    parts = [actor_map(perm_sensors, grid), FOOT_PATCHES, FEET, identity(2)]
    if height_scan:
        parts.append(CRITIC_SCAN)
    return concat(*parts)


@dataclasses.dataclass(frozen=True, eq=False)
class Mirror:
    """The mirror of an env's observations and actions.

    Attributes:
      obs: one map per observation key (a dict observation), or one map (an array observation).
      action: the action's map.
    """

    obs: Mapping[str, SignedPerm] | SignedPerm
    action: SignedPerm

    def observation(self, obs):
        """The mirrored observation (an array, or a dict: every key mirrored by its map)."""
        if isinstance(obs, Mapping):
            if not isinstance(self.obs, Mapping):
                raise ValueError("a dict observation needs a mirror map per key")
            missing = sorted(set(obs) - set(self.obs))
            if missing:
                raise ValueError(f"observation keys {missing} have no mirror map")
            return {k: self.obs[k](v) for k, v in obs.items()}
        return self.obs(obs)

    def maps(self) -> dict[str, SignedPerm]:
        """Every map by name (the observation keys and 'action')."""
        out = dict(self.obs) if isinstance(self.obs, Mapping) else {"obs": self.obs}
        return {**out, "action": self.action}


def make_mirror(cfg) -> Mirror:
    """The mirror of the ToF env built from ``cfg`` (its sensor section, env.actor_terrain,
    env.actor_terrain_seen, env.actor_terrain_fine, env.critic_height_scan): obs keys 'state'
    and 'privileged_state'.

    Raises:
      ValueError: sensors without a mirror partner (see :func:`sensor_perm`).
    """
    from foottof.sensors.tof import ToFSpec

    spec = ToFSpec.from_config(cfg.sensor)
    perm = sensor_perm(tuple(cfg.sensor.sites), spec.tilt_deg, spec.offset_m)
    env = cfg.env
    actor = actor_map(perm, spec.grid)
    if env.actor_terrain:
        actor = concat(actor, actor_terrain_map(bool(env.actor_terrain_seen)))
    if env.actor_terrain_fine:
        from foottof.envs import fine_terrain

        actor = concat(actor, SignedPerm(*fine_terrain.mirror_perm()))
    critic = critic_map(perm, spec.grid, bool(env.critic_height_scan))
    return Mirror(obs={"state": actor, "privileged_state": critic}, action=ACTION)
