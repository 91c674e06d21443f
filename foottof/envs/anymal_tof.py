"""Goal-reaching ANYmal-D environment on discrete terrain with foot ToF sensing (Brax Env)."""

from __future__ import annotations

import jax
import jax.numpy as jp
from brax.envs.base import Env, State
from flax import struct

from foottof import constants
from foottof.envs import rewards as rw
from foottof.envs import sensing, symmetry
from foottof.envs import terminations as term
from foottof.envs.observe import Observer
from foottof.envs.randomization import EpisodeParams, sample_episode_params
from foottof.envs.seen_map import SeenGrid
from foottof.envs.sensing import select_where
from foottof.envs.step_kinematics import StepKinematics, foot_kinematics, step_kinematics
from foottof.envs.task_spec import TaskSpec
from foottof.envs.terminations import Ends
from foottof.perception import check_source
from foottof.physics import make_physics
from foottof.robot import kinematics
from foottof.robot.model import make_model
from foottof.terrain import curriculum
from foottof.terrain.terrain_map import (
    TerrainMap,
    TerrainMapSpec,
    build_terrain_map,
    sample_spawn_goal,
)

EPISODE_METRICS = (
    "episode/success",
    "episode/failed",
    "episode/foot_stuck",
    "episode/goal_dist_m",
    "episode/progress",
    "curriculum/level",
    "episode/speed_mps",
)
# averaged over all steps by the trainer
STEP_METRICS = ("task/speed_mps", "task/feet_at_edges", "task/guidance_weight")
# State.info key of each env's control steps since training began (only where the guidance bias
# decays, reward.guidance_decay_end_iteration > 0); checkpointed with the env state.
ENV_STEPS_KEY = "env_steps"
SEEN_KEY = "seen"  # State.info: (origin, grid) of the ray-hit cells (env.actor_terrain_seen)


@struct.dataclass
class TaskState:
    """Per-env task bookkeeping carried in ``State.info['task']``.

    Attributes:
      rng: PRNG key of this env.
      step: control steps since the episode started (int32).
      level, col: curriculum level and terrain column of the current tile (int32).
      spawn: (4,) spawn x, y, yaw, surface z; goal: (2,) goal x, y [m].
      last_action: (12,) previous action; last_qvel: (12,) joint velocities one step ago.
      params: per-episode randomization.
    """

    rng: jax.Array
    step: jax.Array
    level: jax.Array
    col: jax.Array
    spawn: jax.Array
    goal: jax.Array
    last_action: jax.Array
    last_qvel: jax.Array
    params: EpisodeParams


class AnymalToFEnv(Env):
    """Reach a goal across a terrain tile; Brax ``Env`` API (single env; vmap for many).

    ``reset(key) -> State`` and ``step(state, action) -> State``; the step auto-resets finished
    episodes inside the compiled step (the returned state holds the new episode's observation with
    ``done = 1`` and the finished episode's reward). ``State.info['truncation']`` is 1 at the time
    limit only if ``env.bootstrap_time_limit`` (by default the deadline is terminal),
    ``State.obs`` is ``{'state': actor obs, 'privileged_state': critic obs}``.

    Args:
      cfg: the full config (configs/base.py layout).
      source: foot-reading source, one of foottof.perception.SOURCES.
      terrain_map: a prebuilt map (default: built from ``cfg.terrain`` for ``cfg.stage``).

    The shank length scale of the *physics* model (an evaluation perturbation; the policy-side
    kinematics stay nominal) is ``cfg.env.model.shank_scale``; joint-offset and odometry levels
    are given at reset (:meth:`reset_perturbed`) and kept for the auto-reset episodes.
    """

    def __init__(
        self,
        cfg,
        source: str = "tof",
        terrain_map: TerrainMap | None = None,
    ):
        check_source(source, allow_all=False)
        self.cfg = cfg  # kept for callers; the step's phases read self.spec
        self.spec = TaskSpec.from_config(cfg)
        self.source = source
        ecfg = cfg.env
        model_kw = dict(ecfg.model)
        self.shank_scale = float(model_kw.pop("shank_scale", 1.0))
        self.foot_radius_m = float(model_kw.get("foot_radius_m", constants.FOOT_RADIUS_M))
        if terrain_map is None:
            spec = TerrainMapSpec.from_config(cfg.terrain, int(cfg.stage))
            terrain_map = build_terrain_map(jax.random.PRNGKey(int(cfg.seed)), spec)
        self.tmap = terrain_map
        self.hfield = terrain_map.hfield.clipped()
        self.mj_model = make_model(terrain_map.hfield, shank_scale=self.shank_scale, **model_kw)
        # Physics backend (env.physics: MJX or MuJoCo C); the PD gains come per step.
        drive = {k: v for k, v in dict(ecfg.control).items() if k not in ("kp", "kd")}
        self.physics = make_physics(
            str(ecfg.physics),
            self.mj_model,
            drive,
            int(ecfg.physics_threads),
        )
        self._default_q = jp.asarray(constants.DEFAULT_POSE, jp.float32)
        self._stand_height = kinematics.nominal_base_height(
            constants.DEFAULT_POSE, self.shank_scale, self.foot_radius_m
        )
        self.dt = constants.CONTROL_DT_S
        self.episode_steps = int(round(float(ecfg.episode_length_s) / self.dt))
        self._push_interval = max(int(round(float(ecfg.push_interval_s) / self.dt)), 2)
        self.sensing = sensing.Sensing(cfg, source, self.hfield, self.shank_scale)
        # env.actor_terrain_seen: the cells the foot rays have hit, spawn-anchored, over the tile
        self.seen_grid = SeenGrid(
            cell_m=float(cfg.terrain.cell_m),
            back_m=1.0,
            ahead_m=float(cfg.terrain.tile_length_m) + 1.0,
            half_width_m=float(cfg.terrain.tile_width_m) / 2.0,
        )
        self.observer = Observer(
            self.spec,
            self.hfield,
            self.seen_grid,
            self._default_q,
            self.shank_scale,
            self.foot_radius_m,
            self._stand_height,
            self.episode_steps,
        )
        self._obs_sizes = None

    # ----------------------------------------------------------------------------------------
    # Brax Env API
    @property
    def observation_size(self):
        if self._obs_sizes is None:
            st = jax.eval_shape(self.reset, jax.random.PRNGKey(0))
            self._obs_sizes = {k: v.shape[-1] for k, v in st.obs.items()}
        return dict(self._obs_sizes)

    @property
    def action_size(self) -> int:
        return constants.NUM_JOINTS

    @property
    def backend(self) -> str:
        return self.physics.name  # "mjx" | "mujoco"

    @property
    def mirror(self) -> symmetry.Mirror:
        """The left-right mirror maps of this env's observations and actions (ppo.symmetry)."""
        return symmetry.make_mirror(self.cfg)

    def reset(self, rng: jax.Array) -> State:
        """Starts an episode on a random tile at curriculum level drawn from the initial range."""
        return self._reset_first(rng, None)

    def reset_perturbed(self, rng: jax.Array, joint_offset_rad=None, odometry_level=None) -> State:
        """``reset(rng)`` with this env's evaluation perturbations given as (traced) values.

        The same draws as ``reset(rng)``; only the episode parameters ``joint_offset_rad`` (a
        static offset added to all 12 joint readings [rad]) and ``odometry_level`` (multiple of
        the 100 % odometry noise) are replaced (None: the config's value), so one compiled
        rollout serves every level of a sweep. The env keeps them: episodes that ``step``
        auto-resets carry them over.
        """
        overrides = {}
        if joint_offset_rad is not None:
            overrides["joint_offset_rad"] = jp.broadcast_to(
                jp.asarray(joint_offset_rad, jp.float32), (constants.NUM_JOINTS,)
            )
        if odometry_level is not None:
            overrides["odometry_level"] = jp.asarray(odometry_level, jp.float32)
        return self._reset_first(rng, overrides)

    def _reset_first(self, rng: jax.Array, overrides: dict | None) -> State:
        key_lvl, key_col, key_ep = jax.random.split(rng, 3)
        max_init = min(self.spec.init_level_max, self.tmap.num_levels - 1)
        level = jax.random.randint(key_lvl, (), 0, max_init + 1)  # level ~ U{0..init_level_max}
        col = jax.random.randint(key_col, (), 0, self.tmap.num_cols)  # column ~ U{0..C-1}
        return self._reset_episode(key_ep, level, col, overrides)

    def step(self, state: State, action: jax.Array) -> State:
        """One 50 Hz control step in phases: action and physics, kinematics, terminations,
        rewards, auto-reset (curriculum update on the finished episode), then sensing and
        observations of the selected state."""
        task: TaskState = state.info["task"]
        rng, key_push, key_reset, key_obs = self._step_keys(task)
        d, action, taus, diverged = self._act_and_simulate(
            state.pipeline_state, task, action, key_push
        )
        step = task.step + 1
        kin = self._step_kinematics(d)
        ends = self._terminations(d, kin, step, diverged)
        env_steps = state.info.get(ENV_STEPS_KEY)
        weight = self._guidance_weight(env_steps)
        reward, terms, success, dist = self._rewards(
            d, kin, task, action, taus, ends, step, diverged, weight
        )
        next_d, next_task = self._auto_reset(key_reset, d, task, action, step, success, ends, rng)
        # Sensing on the selected pose: one ray cast per step; buffers restart where done.
        key_meas, key_sense = jax.random.split(key_obs)
        meas = sensing.measure(key_meas, next_d, next_task.params)
        done = ends.done
        sensor_state, sense = self.sensing.step(state.info["sensor"], key_sense, next_d, meas, done)
        seen = None
        if self.spec.actor_terrain_seen:  # static: a fresh grid where done, then this step's rays
            seen = select_where(done, self._fresh_seen(next_task), state.info[SEEN_KEY])
            seen = self._mark_seen(seen, sense)
        obs = self.observer(next_d, next_task, sense, meas, seen)
        speed = jp.linalg.norm(d.qvel[0:2])
        metrics = {f"reward/{k}": v for k, v in terms.items()}
        metrics.update(
            {
                "episode/success": success,
                "episode/failed": ends.failed.astype(jp.float32),
                "episode/foot_stuck": ends.stuck.astype(jp.float32),
                "episode/goal_dist_m": dist,
                "episode/progress": self._progress(task, d.qpos[0:2]),
                "curriculum/level": task.level.astype(jp.float32),
                "episode/speed_mps": speed,
                "task/speed_mps": speed,
                "task/feet_at_edges": jp.sum(kin.foot_edge),
                "task/guidance_weight": weight,
            }
        )
        info = dict(state.info)
        if env_steps is not None:  # kept across auto-resets: it counts training, not an episode
            info[ENV_STEPS_KEY] = env_steps + 1
        # The deadline is part of this task (time left is observed, reach pays at the last step):
        # bootstrapping V there would pay the at-goal value again forever (10 / (1 - gamma)).
        bootstrap = ends.truncated & self.spec.bootstrap_time_limit
        info.update(task=next_task, sensor=sensor_state, truncation=bootstrap.astype(jp.float32))
        if seen is not None:
            info[SEEN_KEY] = seen
        return State(
            pipeline_state=next_d,
            obs=obs,
            reward=reward,
            done=done.astype(jp.float32),
            metrics=metrics,
            info=info,
        )

    def step_physics(self, state: State, action: jax.Array):
        """(physics state, diverged) that :meth:`step` reaches from ``state`` with ``action``
        before its auto-reset: the pose an ending episode ended in (``fail_reasons`` of it says
        why; the failures tool). The same push and physics as the step, so the same pose."""
        task: TaskState = state.info["task"]
        d, _, _, diverged = self._act_and_simulate(
            state.pipeline_state, task, action, self._step_keys(task)[1]
        )
        return d, diverged

    # ----------------------------------------------------------------------------------------
    # Step phases
    @staticmethod
    def _step_keys(task: TaskState):
        """(next rng, push, reset, observation) keys of one step, split off the task's rng."""
        return jax.random.split(task.rng, 4)

    def _act_and_simulate(self, d, task: TaskState, action, key_push):
        """Clipped action -> joint targets, the episode's push, the physics step; a diverged
        simulation (non-finite or absurd velocities) is flagged and sanitized so that no inf/NaN
        reaches rewards or observations before the auto-reset.

        Returns:
          (physics state, clipped action, (substeps, 12) torques, diverged).
        """
        sp, p = self.spec, task.params
        action = jp.clip(action, -sp.clip_actions, sp.clip_actions)
        q_target = self._default_q + constants.ACTION_SCALE * action
        # Push: add a random horizontal base velocity every push interval.
        push_now = (task.step == p.push_step) & sp.randomization.enabled
        push = jax.random.uniform(key_push, (2,), minval=-1.0, maxval=1.0)
        push = push * sp.randomization.push_vel_mps * push_now
        d = d.replace(qvel=d.qvel.at[0:2].add(push))
        kp = sp.kp * p.kp_scale * p.motor_strength
        kd = sp.kd * p.kd_scale * p.motor_strength
        d, taus = self.physics.step(d, q_target, kp, kd, p.friction, p.added_mass_kg)
        max_speed = sp.max_joint_speed_rads
        diverged = ~(jp.all(jp.isfinite(d.qpos)) & jp.all(jp.isfinite(d.qvel)))
        diverged = diverged | (jp.max(jp.abs(jp.nan_to_num(d.qvel))) > max_speed)
        d = d.replace(
            qpos=jp.nan_to_num(d.qpos),
            qvel=jp.clip(jp.nan_to_num(d.qvel), -max_speed, max_speed),
            qacc_warmstart=jp.nan_to_num(d.qacc_warmstart),
        )
        return d, action, jp.nan_to_num(taus), diverged

    def _step_kinematics(self, d) -> StepKinematics:
        """Foot kinematics (analytic FK on the physics model), contacts, gravity, foot edges."""
        return step_kinematics(d, self.spec, self.hfield, self.shank_scale, self.foot_radius_m)

    def _terminations(self, d, kin: StepKinematics, step, diverged) -> Ends:
        failed, knee_contact, stuck = self._failed(d, kin.gravity, kin.fk)
        return term.ends(failed, knee_contact, stuck, step, self.episode_steps, diverged)

    def _guidance_weight(self, env_steps) -> jax.Array:
        """The guidance bias weight (rewards.guidance_weight) from this env's step counter: each
        env steps ``ppo.num_steps`` times per training iteration, so counter / num_steps is the
        iterations done (1 where the decay is off)."""
        start, end = self.spec.reward.guidance_decay
        if env_steps is None:  # static: the decay is off
            return jp.ones(())
        iteration = env_steps.astype(jp.float32) / float(self.spec.steps_per_iteration)
        return rw.guidance_weight(iteration, start, end)

    def _rewards(
        self,
        d,
        kin: StepKinematics,
        task: TaskState,
        action,
        taus,
        ends: Ends,
        step,
        diverged,
        guidance_weight,
    ):
        """(reward, clipped scaled terms, success (float), distance to the goal [m])."""
        qpos, qvel = d.qpos, d.qvel
        base_pos = qpos[0:3]
        rin = rw.RewardInputs(
            base_pos=base_pos,
            base_lin_vel=qvel[0:3],
            goal_xy=task.goal,
            projected_gravity=kin.gravity,
            torques=taus[-1],
            qvel=qvel[6:18],
            last_qvel=task.last_qvel,
            action=action,
            last_action=task.last_action,
            foot_vel=kin.foot_vel,
            foot_contact=kin.contact,
            q=qpos[7:19],
            default_q=self._default_q,
            time_s=step.astype(jp.float32) * self.dt,
            time_left_s=(self.episode_steps - step).astype(jp.float32) * self.dt,
            guidance_weight=guidance_weight,
            failed=ends.failed.astype(jp.float32),
            truncated=ends.truncated.astype(jp.float32),
            knee_contact=ends.knee_contact,
            foot_edge=kin.foot_edge,
        )
        sr = self.spec.reward
        terms = rw.scaled_terms(
            rw.compute_terms(rin, sr, self.dt), dict(sr.scales), self.dt, sr.overall_scale
        )
        clip = self.spec.clip_reward
        terms = {k: jp.clip(v, -clip, clip) for k, v in terms.items()}
        valid = 1.0 - diverged.astype(jp.float32)
        reward = rw.total_reward(terms, sr.only_positive, valid)
        dist = jp.linalg.norm(task.goal - base_pos[:2])
        success = (ends.truncated & (dist < sr.success_radius_m)).astype(jp.float32)
        return reward, terms, success, dist

    def _auto_reset(self, key_reset, d, task: TaskState, action, step, success, ends: Ends, rng):
        """The next physics and task state: the continued episode, or where it ended, a fresh one
        on the tile the curriculum picks (keeping the env's evaluation perturbation)."""
        cont = task.replace(rng=rng, step=step, last_action=action, last_qvel=d.qvel[6:18])
        new_level, new_col = self._curriculum(key_reset, task, d.qpos[0:2], success, ends.failed)
        fresh_d, fresh_task = self._reset_core(key_reset, new_level, new_col)
        fresh_task = fresh_task.replace(params=_keep_perturbation(fresh_task.params, task.params))
        return select_where(ends.done, fresh_d, d), select_where(ends.done, fresh_task, cont)

    # ----------------------------------------------------------------------------------------
    # Internals
    def _foot_kinematics(self, d) -> tuple[kinematics.FootKinematics, jax.Array]:
        """World FK of the physics model and (4, 3) world foot-centre velocities (FK Jacobian)."""
        return foot_kinematics(d, self.shank_scale)

    def _failed(self, d, gravity, fk: kinematics.FootKinematics):
        """Failure (any of :meth:`fail_reasons`), (4,) knee contacts (1.0 where a knee touches)
        and whether a foot is stuck (``foot_stuck``, its own reason): terminations.failed."""
        return term.failed(self.spec, self.hfield, d, gravity, fk)

    def fail_reasons(self, d) -> dict:
        """{reason: () bool} for the physics state ``d`` after a step, keyed by FAIL_REASONS (a
        jitted call returns the keys sorted): which of the failure terminations hold there (the
        episode fails where any does; a diverged simulation fails too, flagged by the step
        itself). The rules: terminations.fail_reasons."""
        kin = self._step_kinematics(d)
        return term.fail_reasons(self.spec, self.hfield, d, kin.gravity, kin.fk)[0]

    def _progress(self, task: TaskState, base_xy) -> jax.Array:
        return curriculum.progress_fraction(task.spawn[:2], task.goal, base_xy)

    def _curriculum(self, key, task: TaskState, base_xy, success, failed):
        level = curriculum.update_levels(
            key,
            task.level,
            done=jp.ones((), bool),
            reached_goal=success > 0,
            progress=self._progress(task, base_xy),
            num_levels=self.tmap.num_levels,
            down_progress_frac=self.spec.down_progress_frac,
            up_progress_frac=self.spec.up_progress_frac,
            failed=failed if self.spec.no_promotion_on_fall else None,
        )
        return level, task.col

    def _reset_episode(self, key, level, col, overrides: dict | None = None) -> State:
        """A fresh episode on tile (level, col), with sensing and observation; ``overrides``
        replaces EpisodeParams fields (evaluation perturbations)."""
        key_core, key_sense, key_meas = jax.random.split(key, 3)
        d, task = self._reset_core(key_core, level, col)
        if overrides:
            task = task.replace(params=task.params.replace(**overrides))
        meas = sensing.measure(key_meas, d, task.params)
        sensor_state, sense = self.sensing.reset(key_sense, d, meas)
        seen = None
        if self.spec.actor_terrain_seen:  # static
            seen = self._mark_seen(self._fresh_seen(task), sense)
        obs = self.observer(d, task, sense, meas, seen)
        zero = jp.zeros(())
        metrics = {f"reward/{k}": zero for k in rw.REWARD_TERMS}
        metrics.update({k: zero for k in EPISODE_METRICS + STEP_METRICS})
        info = {"task": task, "sensor": sensor_state, "truncation": zero}
        if seen is not None:
            info[SEEN_KEY] = seen
        if self.spec.reward.guidance_decay[1] > 0:  # static: count this env's steps for the decay
            info[ENV_STEPS_KEY] = jp.zeros((), jp.int32)
        return State(
            pipeline_state=d,
            obs=obs,
            reward=zero,
            done=zero,
            metrics=metrics,
            info=info,
        )

    def _reset_core(self, key, level, col):
        """Physics state and task state of a fresh episode on tile (level, col) (no sensing)."""
        key_sg, key_par, key_pose, key_rng = jax.random.split(key, 4)
        spawn, goal = sample_spawn_goal(key_sg, self.tmap, level, col)
        params = sample_episode_params(key_par, self.spec.randomization, self._push_interval)
        # Initial pose: nominal stance, joint noise ~ U(+-init_joint_noise_rad) (wider in stage 2).
        kq, kr = jax.random.split(key_pose)
        jn = self.spec.init_joint_noise_rad
        q0 = self._default_q + jax.random.uniform(kq, (12,), minval=-jn, maxval=jn)
        rp = jax.random.uniform(kr, (2,), minval=-1.0, maxval=1.0) * self.spec.init_roll_pitch_rad
        quat = kinematics.euler_to_quat(rp[0], rp[1], spawn[2])
        z = spawn[3] + self._stand_height + self.spec.spawn_height_offset_m
        qpos = jp.concatenate([jp.array([spawn[0], spawn[1]]), z[None], quat, q0])
        # A tilted base or bent joints can put a foot below the terrain at the nominal height
        # (stage 2's 0.2 rad and 0.15 rad: up to ~0.13 m): lift the robot until no foot sphere
        # starts inside the terrain under it (a no-op for poses whose feet are all above it).
        fk = kinematics.world_foot_kinematics(qpos, self.shank_scale)
        bottom = fk.foot_pos[:, 2] - self.foot_radius_m - self.hfield.height_at(fk.foot_pos[:, :2])
        qpos = qpos.at[2].add(jp.maximum(0.0, -jp.min(bottom)))
        d = self.physics.init(qpos)  # at rest
        task = TaskState(
            rng=key_rng,
            step=jp.zeros((), jp.int32),
            level=jp.asarray(level, jp.int32),
            col=jp.asarray(col, jp.int32),
            spawn=spawn,
            goal=goal,
            last_action=jp.zeros(12),
            last_qvel=jp.zeros(12),
            params=params,
        )
        return d, task

    def _fresh_seen(self, task: TaskState) -> tuple[jax.Array, jax.Array]:
        """(origin, seen) of an episode's empty grid of ray-hit cells, anchored at its spawn."""
        return self.seen_grid.init(task.spawn[:2])

    def _mark_seen(self, seen, sense) -> tuple[jax.Array, jax.Array]:
        """``seen`` with the cells of this step's noise-free ray hits of every foot sensor."""
        origin, grid = seen
        pts = sense.hit_points.reshape(-1, 3)
        return origin, self.seen_grid.mark(origin, grid, pts, sense.hit_valid.reshape(-1))


def _keep_perturbation(fresh: EpisodeParams, old: EpisodeParams) -> EpisodeParams:
    """An auto-reset episode keeps the env's evaluation perturbation (given at reset)."""
    return fresh.replace(joint_offset_rad=old.joint_offset_rad, odometry_level=old.odometry_level)
