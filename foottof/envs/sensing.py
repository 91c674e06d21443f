"""Foot-reading sources of the env: foot ray casters (tof) or emulated (mock_ideal, mock_aggre)."""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

from foottof import constants
from foottof.perception import check_source
from foottof.perception import elevation_map as em
from foottof.perception import sources as mock
from foottof.perception.odometry import noisy_odometry
from foottof.robot import kinematics
from foottof.sensors import degradation as deg
from foottof.sensors import timing, tof
from foottof.sensors.noise_model import load_model


@struct.dataclass
class Measurements:
    """What the robot measures of itself at a control step (what the mocks and the actor use).

    Attributes:
      q: (12,) measured joint positions [rad] (noise and any static offset included).
      lin_vel: (3,) estimated base linear velocity, base frame [m/s] (odometry noise included).
      ang_vel: (3,) estimated base angular velocity, base frame [rad/s].
    """

    q: jax.Array
    lin_vel: jax.Array
    ang_vel: jax.Array


def measure(key, d, p) -> Measurements:
    """Joint readings (Gaussian noise + static offset) and odometry (uniform noise).

    Args:
      key: PRNG key of this draw; d: the physics state; p: the episode's EpisodeParams (joint
        offset and noise, odometry level).
    """
    k1, k2 = jax.random.split(key)
    q = d.qpos[7:19] + p.joint_offset_rad
    q = q + p.joint_pos_noise_rad * jax.random.normal(k1, (12,))  # ~ N(0, std^2)
    lin_b = kinematics.quat_rotate_inv(d.qpos[3:7], d.qvel[0:3])
    # odometry noise ~ U(+-0.1 level) m/s, U(+-0.2 level) rad/s per axis (paper's 100 % = 1)
    lin, ang = noisy_odometry(k2, lin_b, d.qvel[3:6], p.odometry_level)
    return Measurements(q=q, lin_vel=lin, ang_vel=ang)


@struct.dataclass
class Sense:
    """Foot readings for the observation.

    Attributes:
      distance: (F, Z) delivered readings [m] (held at 60 Hz, delayed, degraded; 0 = dropped).
      valid: (F, Z) float validity flags of the delivered readings.
      age_s: (F,) age of the delivered frames [s].
      true_distance: (F, Z) noise-free ``tof`` readings at this step [m] (critic).
      true_valid: (F, Z) float validity of the noise-free readings.
      hit_points: (F, R, 3) world points [m] the noise-free frame's rays hit (every ray of the
        real foot sensors, true poses; env.actor_terrain_seen marks them).
      hit_valid: (F, R) bool, the ray hit the terrain within range.
    """

    distance: jax.Array
    valid: jax.Array
    age_s: jax.Array
    true_distance: jax.Array
    true_valid: jax.Array
    hit_points: jax.Array
    hit_valid: jax.Array


@struct.dataclass
class SensingState:
    """Per-env sensing state: the ToF timing/degradation pipeline and, for mock_aggre, the map
    (its ``scan`` None: rebuilt by every update, see _without_scan)."""

    tof: timing.ToFState
    emap: em.ElevationMapState | None = None


def _without_scan(emap: em.ElevationMapState | None) -> em.ElevationMapState | None:
    """The map as the env carries it: without its robot-centric scan, which every update
    rebuilds and only this step's readings use (41 KB less state per env; no measurable change
    in speed, bench/NOTES.md item 10)."""
    return None if emap is None else emap.replace(scan=None)


class Sensing:
    """Foot readings of one env from the configured source, through the sensor pipeline.

    Every source goes through the same VL53L5CX pipeline (60 Hz sample-and-hold, k-step delay,
    per-episode degradation with the stage's bounds from ``cfg.noise``), so the policy sees the
    same observation layout; only where the noise-free frame comes from differs:
    ``tof`` casts the foot rays on the terrain from the true sensor poses (physics model, incl.
    any shank-length change); ``mock_ideal`` / ``mock_aggre`` cast the same rays into an ideal
    height scan / an aggregated elevation map from poses given by the *measured* joints through
    the *nominal* kinematics (foottof.perception.sources).
    """

    def __init__(self, cfg, source: str, hfield, shank_scale: float):
        check_source(source, allow_all=False)
        self.source = source
        self.hfield = hfield
        self.shank_scale = float(shank_scale)
        self.spec = tof.ToFSpec.from_config(cfg.sensor)
        self.timing = timing.TimingSpec.from_config(self.spec, cfg.noise, constants.CONTROL_DT_S)
        self.bounds = deg.DegradationBounds.from_config(cfg.noise, int(cfg.stage), self.timing)
        self.model = load_model(cfg.noise.model_path or None)
        sites = tuple(cfg.sensor.sites)
        bad = [s for s in sites if s not in constants.TOF_SITES]
        if bad:
            raise ValueError(
                f"sensor.sites {bad} unknown; valid sites: {list(constants.TOF_SITES)}"
            )
        self.feet = tuple(constants.TOF_SITES.index(s) for s in sites)
        self._feet_idx = np.asarray(self.feet, np.int32)
        self.dt = constants.CONTROL_DT_S

    @property
    def num_sensors(self) -> int:
        return self.spec.num_sensors

    @property
    def num_zones(self) -> int:
        return self.spec.num_zones

    def true_reading(self, d) -> tof.ToFReading:
        """Noise-free frame of the real foot sensors (true poses of the physics model)."""
        return self._true_frame(d)[0]

    def _true_frame(self, d):
        """(noise-free reading, ray hit points (F, R, 3), hit (F, R)) of the real foot sensors."""
        fk = kinematics.world_foot_kinematics(d.qpos, self.shank_scale)
        pos = fk.tof_pos[self._feet_idx]
        rot = fk.tof_rot[self._feet_idx]
        return tof.sense_and_hits(self.spec, self.hfield, pos, rot)

    def _source_reading(self, d, meas: Measurements, emap, true):
        base_pos, base_quat = d.qpos[0:3], d.qpos[3:7]
        if self.source == "tof":
            return true
        if self.source == "mock_ideal":
            return mock.mock_ideal_readings(
                self.spec, self.hfield, base_pos, base_quat, meas.q, self.feet
            )
        return mock.mock_aggre_readings(self.spec, emap, base_quat, meas.q, self.feet)

    def _sense(self, obs: timing.ToFObs, true: tof.ToFReading, points, hit) -> Sense:
        return Sense(
            distance=obs.distance_m,
            valid=obs.valid.astype(jp.float32),
            age_s=obs.age_s,
            true_distance=true.distance_m,
            true_valid=true.valid.astype(jp.float32),
            hit_points=points,
            hit_valid=hit,
        )

    def reset(self, key, d, meas: Measurements) -> tuple[SensingState, Sense]:
        """Sensing state of a fresh episode (draws degradation levels, delay, frame phases)."""
        emap = None
        if self.source == "mock_aggre":
            emap = em.aggre_init(self.hfield, d.qpos[0:3], d.qpos[3:7], with_flags=False)
        true, points, hit = self._true_frame(d)
        reading = self._source_reading(d, meas, emap, true)
        tstate, obs = timing.reset(self.timing, self.bounds, self.model, key, reading)
        sense = self._sense(obs, true, points, hit)
        return SensingState(tof=tstate, emap=_without_scan(emap)), sense

    def step(
        self, state: SensingState, key, d, meas: Measurements, done
    ) -> tuple[SensingState, Sense]:
        """Advance one control step; where ``done`` the pipeline restarts (the env auto-reset).

        ``d`` is the physics state *after* any auto-reset, so one ray cast serves both cases.
        """
        key_step, key_reset = jax.random.split(key)
        base_pos, base_quat = d.qpos[0:3], d.qpos[3:7]
        emap = state.emap
        if self.source == "mock_aggre":  # where done: a fresh map (= aggre_init), same pass
            emap = em.aggre_update(
                state.emap,
                self.hfield,
                base_pos,
                base_quat,
                meas.lin_vel,
                meas.ang_vel,
                self.dt,
                reset=done,
                with_flags=False,  # the masks are diagnostics; without them: one fused loop
            )
        true, points, hit = self._true_frame(d)
        reading = self._source_reading(d, meas, emap, true)
        t_step, o_step = timing.step(self.timing, self.model, state.tof, reading, key_step)
        t_reset, o_reset = timing.reset(self.timing, self.bounds, self.model, key_reset, reading)
        tof = select_where(done, t_reset, t_step)
        return SensingState(tof=tof, emap=_without_scan(emap)), self._sense(
            select_where(done, o_reset, o_step), true, points, hit
        )


def select_where(done: jax.Array, fresh, cont):
    """Per-leaf ``where(done, fresh, cont)``: the auto-reset's one state selection (the env and
    its sensing both use it)."""
    return jax.tree.map(lambda x, y: jp.where(done, x, y), fresh, cont)
