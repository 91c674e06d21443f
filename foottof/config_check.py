"""Whole-config validation, run before any disk write or compile (imports no JAX)."""

import math
import numbers
import os

import ml_collections

from foottof.constants import CONTROL_DT_S  # noqa: F401 (imports no JAX)
from foottof.limits import (  # the one home of allowed values (imports no JAX)
    ACTIVATIONS,
    FOOT_RADIUS_RANGE_M,
    LEVEL_RANGES,
    LR_SCHEDULES,
    MAX_CELL_M,
    MAX_TIMESTEP_S,
    PHYSICS_BACKENDS,
    POLICIES,
    SOURCES,
    TILT_LIMIT_DEG,
    TOF_MAX_RATE_HZ,
)

SECTIONS = ("terrain", "sensor", "noise", "env", "reward", "ppo", "network", "train", "eval")


class ConfigError(ValueError):
    """An invalid config; str() is one line naming the field, its value and the valid range."""


def _fmt(lo, hi, lo_open=False, hi_open=False) -> str:
    if lo is not None and hi is not None:
        return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    return f"{'<' if hi_open else '<='} {hi:g}"


def _int(lo=None, hi=None):
    def check(v):
        want = "must be an integer" + (f" {_fmt(lo, hi)}" if (lo, hi) != (None, None) else "")
        if isinstance(v, bool) or not isinstance(v, numbers.Integral):
            return want
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            return want
        return None

    return check


def _num(lo=None, hi=None, lo_open=False, hi_open=False):
    def check(v):
        rng = _fmt(lo, hi, lo_open, hi_open) if (lo, hi) != (None, None) else "(finite)"
        if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
            return f"must be a number {rng}"
        bad_lo = lo is not None and (v <= lo if lo_open else v < lo)
        bad_hi = hi is not None and (v >= hi if hi_open else v > hi)
        return f"must be a number {rng}" if bad_lo or bad_hi else None

    return check


def _pos(v):  # a positive number
    return _num(0.0, lo_open=True)(v)


def _nonneg(v):
    return _num(0.0)(v)


def _frac(v):  # in [0, 1]
    return _num(0.0, 1.0)(v)


def _choice(*choices):
    def check(v):
        return None if v in choices else f"must be one of {list(choices)}"

    return check


def _bool(v):
    return None if isinstance(v, bool) else "must be True or False"


def _name(v):  # a non-empty file name (no path separator)
    ok = isinstance(v, str) and v.strip() and os.sep not in v and v not in (".", "..")
    return None if ok else "must be a non-empty name without '/'"


def _path(v):  # "" or a path
    return None if isinstance(v, str) else "must be a path string ('' = none)"


def _file_or_empty(v):  # "" or an existing file
    if isinstance(v, str) and (v == "" or os.path.isfile(v)):
        return None
    return "must be '' (the default) or an existing file"


def _dir(v):  # a non-empty path
    return None if isinstance(v, str) and v.strip() else "must be a non-empty path"


def _range(lo=None, hi=None):
    """A (low, high) pair with lo <= low <= high <= hi."""

    def check(v):
        both = f", both {_fmt(lo, hi)}" if (lo, hi) != (None, None) else ""
        want = f"must be a pair (low, high) with low <= high{both}"
        if not isinstance(v, (tuple, list)) or len(v) != 2 or any(_num(lo, hi)(x) for x in v):
            return want
        return None if v[0] <= v[1] else want

    return check


def _ints_pos(v):  # a non-empty tuple of positive integers (MLP widths)
    ok = isinstance(v, (tuple, list)) and len(v) > 0 and all(_int(1)(x) is None for x in v)
    return None if ok else "must be a non-empty tuple of integers >= 1"


def _levels(name):
    lo, hi = LEVEL_RANGES[name]

    def check(v):
        ok = isinstance(v, (tuple, list)) and len(v) > 0 and all(_num(lo, hi)(x) is None for x in v)
        return None if ok else f"must be a non-empty tuple of levels in [{lo:g}, {hi:g}]"

    return check


def _subset(choices):
    def check(v):
        ok = isinstance(v, (tuple, list)) and len(v) > 0 and all(x in choices for x in v)
        return None if ok else f"must be a non-empty tuple of {list(choices)}"

    return check


def _non_empty_strs(v):
    ok = isinstance(v, (tuple, list)) and len(v) > 0 and all(isinstance(x, str) for x in v)
    return None if ok else "must be a non-empty tuple of names"


_STAGE_NOISE = {
    "offset_m": _nonneg,
    "proportional": _nonneg,
    "gaussian_m": _nonneg,
    "missing_rate": _frac,
    "model_scale": _nonneg,
    "min_delay_steps": _int(0),
    "max_delay_steps": _int(0),
}

# Field -> check. '*' matches every key of a section (terrain weights, reward scales).
RULES = {
    "seed": _int(0),
    "stage": _choice(1, 2),
    # terrain
    "terrain.tile_length_m": _pos,
    "terrain.tile_width_m": _pos,
    "terrain.cell_m": _num(0.0, MAX_CELL_M, lo_open=True),
    "terrain.platform_length_m": _pos,
    "terrain.goal_length_m": _pos,
    "terrain.pit_z_m": _num(hi=-0.5),
    "terrain.z_range_m": _pos,
    "terrain.border_m": _nonneg,
    "terrain.num_levels": _int(1),
    "terrain.num_cols": _int(1),
    "terrain.stage1_weights.*": _nonneg,
    "terrain.stage2_weights.*": _nonneg,
    "terrain.stage1_difficulty.*": _range(0.0, 1.0),
    "terrain.stage2_difficulty.*": _range(0.0, 1.0),
    "terrain.spawn_x_spread_m": _nonneg,
    "terrain.spawn_y_spread_m": _nonneg,
    "terrain.spawn_yaw_spread_rad": _num(0.0, math.pi),
    "terrain.goal_x_spread_m": _nonneg,
    "terrain.goal_y_spread_m": _nonneg,
    "terrain.init_level_max": _int(0),  # the env clips it to num_levels - 1
    "terrain.down_progress_frac": _frac,
    "terrain.up_progress_frac": _frac,
    "terrain.flat": _bool,
    "terrain.stone_curriculum": _choice("size_first", "gaps_first"),  # tiles.STONE_CURRICULA
    "terrain.no_promotion_on_fall": _bool,
    # sensor, noise
    "sensor.sites": _non_empty_strs,
    "sensor.grid": _choice(*TOF_MAX_RATE_HZ),
    "sensor.fov_deg": _num(0.0, 180.0, lo_open=True, hi_open=True),
    "sensor.max_range_m": _pos,
    "sensor.resolution_m": _pos,
    "sensor.rate_hz": _pos,
    "noise.model_path": _file_or_empty,
    **{f"noise.stage{s}.{k}": c for s in (1, 2) for k, c in _STAGE_NOISE.items()},
    # env: robot model and PD control
    "env.model.shank_scale": _num(*LEVEL_RANGES["shank_length"]),
    "env.model.foot_radius_m": _num(*FOOT_RADIUS_RANGE_M),
    "env.model.armature": _nonneg,
    "env.model.joint_damping": _nonneg,
    "env.model.foot_friction": _nonneg,
    "env.model.body_friction": _nonneg,
    "env.model.body_condim": _choice(1, 3),
    "env.model.body_collision": _bool,
    "env.model.solref_timeconst": _pos,
    "env.model.solref_dampratio": _pos,
    "env.model.solver": _choice("newton", "cg"),
    "env.model.iterations": _int(1),
    "env.model.ls_iterations": _int(1),
    "env.model.cone": _choice("pyramidal", "elliptic"),
    "env.model.impratio": _nonneg,
    "env.model.eulerdamp": _bool,
    "env.model.timestep": _num(0.0, MAX_TIMESTEP_S, lo_open=True),
    "env.control.kp": _nonneg,
    "env.control.kd": _nonneg,
    "env.control.torque_limit": _pos,
    "env.control.velocity_limit": _pos,
    # env: task
    "env.physics": _choice(*PHYSICS_BACKENDS),
    "env.physics_threads": _int(0),
    "env.source": _choice(*SOURCES),
    "env.episode_length_s": _pos,
    "env.clip_actions": _pos,
    "env.clip_observations": _pos,
    "env.clip_reward": _pos,
    "env.max_joint_speed_rads": _pos,
    "env.contact_margin_m": _nonneg,
    "env.body_contact_margin_m": _num(),
    "env.knee_contact_terminates": _bool,
    "env.bootstrap_time_limit": _bool,
    "env.fall_height_above_floor_m": _nonneg,
    "env.foot_stuck_depth_m": _num(0.0, 1.0),
    "env.critic_height_scan": _bool,
    "env.actor_terrain": _bool,
    "env.actor_terrain_seen": _bool,
    "env.actor_terrain_fine": _bool,
    "env.max_tilt_deg": _num(0.0, 180.0, lo_open=True),
    "env.init_joint_noise_rad": _nonneg,
    "env.init_roll_pitch_rad": _num(0.0, math.pi / 2),
    "env.spawn_height_offset_m": _nonneg,
    "env.push_interval_s": _pos,
    "env.randomization.enabled": _bool,
    "env.randomization.nominal_friction": _nonneg,
    "env.randomization.friction_range": _range(0.0),
    "env.randomization.added_mass_kg_range": _range(),
    "env.randomization.motor_strength_range": _range(0.0),
    "env.randomization.kp_scale_range": _range(0.0),
    "env.randomization.kd_scale_range": _range(0.0),
    "env.randomization.joint_pos_noise_rad": _nonneg,
    "env.randomization.joint_vel_noise_rads": _nonneg,
    "env.randomization.push_vel_mps": _nonneg,
    "env.randomization.joint_offset_rad": _num(*LEVEL_RANGES["joint_offset"]),
    "env.randomization.odometry_level": _num(*LEVEL_RANGES["odometry"]),
    # reward
    "reward.success_radius_m": _pos,
    "reward.guidance_max_speed_mps": _pos,
    "reward.stall_speed_mps": _nonneg,
    "reward.stall_grace_s": _nonneg,
    "reward.jump_grace_s": _nonneg,
    "reward.edge_radius_m": _pos,
    "reward.edge_height_m": _pos,
    "reward.only_positive": _bool,
    "reward.guidance_goal_pay": _bool,
    "reward.guidance_decay_start_iteration": _nonneg,
    "reward.guidance_decay_end_iteration": _nonneg,
    "reward.task_window_s": _pos,
    "reward.stall_toward_goal": _bool,
    "reward.overall_scale": _pos,
    "reward.overspeed_mps": _nonneg,
    "reward.scales.*": _num(),
    # ppo, network, train
    "ppo.num_envs": _int(1),
    "ppo.num_steps": _int(1),
    "ppo.num_epochs": _int(1),
    "ppo.num_minibatches": _int(1),
    "ppo.learning_rate": _pos,
    "ppo.lr_schedule": _choice(*LR_SCHEDULES),
    "ppo.desired_kl": _pos,
    "ppo.lr_min": _pos,
    "ppo.lr_max": _pos,
    "ppo.gamma": _frac,
    "ppo.gae_lambda": _frac,
    "ppo.clip_param": _pos,
    "ppo.value_loss_coef": _nonneg,
    "ppo.reconstruction_weight": _nonneg,
    "ppo.use_clipped_value_loss": _bool,
    "ppo.entropy_coef": _nonneg,
    "ppo.max_grad_norm": _pos,
    "ppo.normalize_advantage": _bool,
    "ppo.symmetry": _bool,
    "network.policy": _choice(*POLICIES),
    "network.lstm_hidden_size": _int(1),
    "network.lstm_num_layers": _int(1),
    "network.actor_hidden": _ints_pos,
    "network.critic_hidden": _ints_pos,
    "network.activation": _choice(*ACTIVATIONS),
    "network.init_noise_std": _pos,
    "network.max_noise_std": _nonneg,
    "network.obs_skip": _bool,
    "network.reconstruct": _int(0, 153),  # observations.ACTOR_TERRAIN_INPUTS
    "network.normalize_observations": _bool,
    "network.normalizer_std_eps": _pos,
    "train.num_iterations": _int(1),
    "train.run_root": _dir,
    "train.run_name": _name,
    "train.checkpoint_every": _int(1),
    "train.max_checkpoints": _int(1),
    "train.checkpoint_env_state": _bool,
    "train.tensorboard": _bool,
    "train.log_every": _int(1),
    "train.init_from": _path,
    "train.teacher": _path,
    "train.teacher_change_ok": _bool,
    "train.student_privileged_inputs": _int(0, 153),  # observations.ACTOR_TERRAIN_INPUTS
    # eval
    "eval.episodes": _int(1),
    "eval.num_envs": _int(1),
    "eval.num_levels": _int(1),
    "eval.num_cols": _int(1),
    "eval.stone_fraction": _frac,
    "eval.stone_types": _non_empty_strs,
    "eval.gap_types": _non_empty_strs,
    "eval.difficulty_fraction": _frac,
    "eval.sources": _subset(SOURCES),
    "eval.joint_offset_levels": _levels("joint_offset"),
    "eval.shank_length_levels": _levels("shank_length"),
    "eval.odometry_levels": _levels("odometry"),
    "eval.deterministic": _bool,
    "eval.seed": _int(0),
    "eval.out_dir": _path,
}


def _get(cfg, path: str):
    """Value at a dotted path, or KeyError."""
    v = cfg
    for part in path.split("."):
        if not isinstance(v, (ml_collections.ConfigDict, dict)) or part not in v:
            raise KeyError(path)
        v = v[part]
    return v


def _items(cfg, pattern: str):
    """(path, value) pairs matched by a RULES key; fields absent from `cfg` are skipped."""
    if not pattern.endswith(".*"):
        try:
            return [(pattern, _get(cfg, pattern))]
        except KeyError:
            return []
    try:
        section = _get(cfg, pattern[:-2])
    except KeyError:
        return []
    return [(f"{pattern[:-2]}.{k}", v) for k, v in section.items()]


def _fail(path: str, value, why: str):
    raise ConfigError(f"{path}={value!r}: {why}")


def _leaves(cfg, prefix=""):
    for k, v in cfg.items():
        path = f"{prefix}{k}"
        if isinstance(v, (ml_collections.ConfigDict, dict)):
            yield from _leaves(v, path + ".")
        else:
            yield path, v


def _check_ppo_cross(p) -> None:
    """Checks between fields of c.ppo (divisibility, ordering)."""
    if p.num_envs % p.num_minibatches:
        _fail(
            "ppo.num_envs",
            p.num_envs,
            f"must be divisible by ppo.num_minibatches={p.num_minibatches} (each minibatch takes "
            f"whole envs)",
        )
    if not p.lr_min <= p.learning_rate <= p.lr_max:
        _fail(
            "ppo.learning_rate",
            p.learning_rate,
            f"must be in [ppo.lr_min, ppo.lr_max] = [{p.lr_min:g}, {p.lr_max:g}]",
        )


def _check_sensor_cross(s) -> None:
    """Checks between fields of c.sensor (rate per grid, resolution within the range)."""
    max_hz = TOF_MAX_RATE_HZ[s.grid]
    if s.rate_hz > max_hz:
        _fail(
            "sensor.rate_hz", s.rate_hz, f"must be in (0, {max_hz:g}] for a {s.grid}x{s.grid} grid"
        )
    if s.resolution_m > s.max_range_m:
        _fail(
            "sensor.resolution_m",
            s.resolution_m,
            f"must be <= sensor.max_range_m={s.max_range_m:g}",
        )


def _check_noise_stage_cross(n, prefix: str) -> None:
    """Checks between fields of c.noise.stage1 / stage2 (the delay range's order)."""
    if n.min_delay_steps > n.max_delay_steps:
        _fail(
            f"{prefix}.min_delay_steps",
            n.min_delay_steps,
            f"must be <= {prefix}.max_delay_steps={n.max_delay_steps}",
        )


def _check_tile_cross(t) -> None:
    """Checks between the tile geometry fields of c.terrain (whole cells, course length, height
    range); foottof.terrain.tiles.TileSpec runs them too."""
    for name in ("tile_length_m", "tile_width_m", "platform_length_m", "goal_length_m"):
        cells = t[name] / t.cell_m
        if abs(cells - round(cells)) > 1e-6:
            _fail(f"terrain.{name}", t[name], f"must be a multiple of terrain.cell_m={t.cell_m:g}")
    if t.platform_length_m + t.goal_length_m > t.tile_length_m - 1.0:
        _fail(
            "terrain.tile_length_m",
            t.tile_length_m,
            f"must be >= platform_length_m + goal_length_m + 1 m of course = "
            f"{t.platform_length_m + t.goal_length_m + 1.0:g}",
        )
    if t.pit_z_m + t.z_range_m < 1.0:
        _fail("terrain.z_range_m", t.z_range_m, f"must be >= 1 - pit_z_m = {1.0 - t.pit_z_m:g}")


def _check_model_cross(m) -> None:
    """Checks between fields of c.env.model (contact time constant vs the physics step);
    foottof.robot.model runs them too."""
    if m.solref_timeconst < 2 * m.timestep:
        _fail(
            "env.model.solref_timeconst",
            m.solref_timeconst,
            f"must be >= 2 * env.model.timestep = {2 * m.timestep:g}",
        )


def _check_guidance_decay_cross(r) -> None:
    """The guidance bias decay's order (c.reward); foottof.envs.rewards.RewardSpec runs it too."""
    start, end = r.guidance_decay_start_iteration, r.guidance_decay_end_iteration
    if end > 0 and not 0 <= start < end:
        _fail(
            "reward.guidance_decay_start_iteration",
            start,
            f"must be in [0, reward.guidance_decay_end_iteration={end}) when the decay is on "
            f"(end > 0)",
        )


# Cross-field checks of one section by its path, with the fields they read (check_fields runs
# them after the RULES when it is given all of those fields).
_TILE_FIELDS = (
    "tile_length_m",
    "tile_width_m",
    "cell_m",
    "platform_length_m",
    "goal_length_m",
    "pit_z_m",
    "z_range_m",
)
_SECTION_CROSS = {
    "ppo": (("num_envs", "num_minibatches", "learning_rate", "lr_min", "lr_max"), _check_ppo_cross),
    "reward": (
        ("guidance_decay_start_iteration", "guidance_decay_end_iteration"),
        _check_guidance_decay_cross,
    ),
    "terrain": (_TILE_FIELDS, _check_tile_cross),
    "env.model": (("timestep", "solref_timeconst"), _check_model_cross),
    "sensor": (("grid", "rate_hz", "max_range_m", "resolution_m"), _check_sensor_cross),
    **{
        f"noise.stage{s}": (
            ("min_delay_steps", "max_delay_steps"),
            lambda n, p=f"noise.stage{s}": _check_noise_stage_cross(n, p),
        )
        for s in (1, 2)
    },
}


# Each rule runs once a command for the same values: the rules are pure functions of the values
# they read, so one that passed is remembered (by rule and values; a failure is not) and what
# check_config passed first (train.py, evaluate.py) is not checked again by the builders that
# check what they read (make_train: ppo, make_networks: network, the specs via check_fields).
_PASSED: set[str] = set()


def _plain(value):
    return value.to_dict() if isinstance(value, ml_collections.ConfigDict) else value


def _check_rule(path: str, value, check) -> None:
    """RULES entry ``check`` on the field at ``path`` (once for the same value)."""
    key = repr(("rule", path, _plain(value)))
    if key in _PASSED:
        return
    why = check(value)
    if why:
        _fail(path, value, why)
    _PASSED.add(key)


def _check_section_cross(section: str, values) -> None:
    """The cross-field checks of ``section`` (a path of _SECTION_CROSS) on ``values`` (mapping
    or ConfigDict of that section), once for the same values; skipped where a field is absent."""
    fields, cross = _SECTION_CROSS.get(section, ((), None))
    if cross is None or not all(f in values for f in fields):
        return
    key = repr(("cross", section, tuple(_plain(values[f]) for f in fields)))
    if key in _PASSED:
        return
    cross(ml_collections.ConfigDict({f: values[f] for f in fields}))
    _PASSED.add(key)


def check_fields(section: str, values) -> None:
    """The RULES and cross-field checks of one config section for the fields in ``values`` (a
    mapping or ConfigDict of that section, e.g. section 'sensor' or 'noise.stage1').

    The specs built from a config section (foottof.sensors.tof.ToFSpec,
    foottof.sensors.degradation.DegradationBounds, foottof.terrain.tiles.TileSpec, the robot
    model of foottof.robot.model and its kinematics) check their fields with it, so each rule
    lives once, here, whether a spec comes from a config or is built in code.

    Raises:
      ConfigError (a ValueError): '<section>.<field>=<value>: <valid range>'.
    """
    values = dict(values)
    for name, value in values.items():
        check = RULES.get(f"{section}.{name}")
        if check is not None:
            _check_rule(f"{section}.{name}", value, check)
    _check_section_cross(section, values)


def _check_cross(c) -> None:
    """Checks between fields (divisibility, ordering, lengths)."""
    _check_section_cross("ppo", c.ppo)
    _check_section_cross("sensor", c.sensor)
    t = c.terrain
    if t.up_progress_frac < t.down_progress_frac:
        _fail(
            "terrain.up_progress_frac",
            t.up_progress_frac,
            f"must be in [terrain.down_progress_frac, 1] = [{t.down_progress_frac:g}, 1]",
        )
    for s in (1, 2):
        w = dict(t[f"stage{s}_weights"])
        if not any(v > 0 for v in w.values()):
            _fail(f"terrain.stage{s}_weights", w, "needs at least one weight > 0")
        missing = sorted(k for k, v in w.items() if v > 0 and k not in t[f"stage{s}_difficulty"])
        if missing:
            _fail(
                f"terrain.stage{s}_difficulty",
                dict(t[f"stage{s}_difficulty"]),
                f"needs a (low, high) range for {missing}",
            )
        _check_section_cross(f"noise.stage{s}", c.noise[f"stage{s}"])
    _check_section_cross("terrain", t)
    e = c.get("env", {})
    if e.get("actor_terrain_seen", False) and not e.get("actor_terrain", False):
        _fail(
            "env.actor_terrain_seen",
            True,
            "needs env.actor_terrain=True (it limits the teacher's terrain inputs to the seen cells)",
        )
    if e.get("actor_terrain_fine", False) and (
        not e.get("actor_terrain", False) or e.get("actor_terrain_seen", False)
    ):
        _fail(
            "env.actor_terrain_fine",
            True,
            "needs env.actor_terrain=True and env.actor_terrain_seen=False (it adds 5 cm samples "
            "between the teacher's true 10 cm ones)",
        )
    s = c.sensor
    n_sensors = len(s.sites)
    for name, width in (("tilt_x_deg", None), ("tilt_y_deg", None), ("offset_m", 3)):
        v = s.get(name)
        if v is None:
            continue
        ok = isinstance(v, (tuple, list)) and len(v) == n_sensors
        if ok and width is None:
            ok = all(_num(-TILT_LIMIT_DEG, TILT_LIMIT_DEG, True, True)(x) is None for x in v)
        elif ok:
            ok = all(
                isinstance(x, (tuple, list))
                and len(x) == width
                and all(_num()(y) is None for y in x)
                for x in v
            )
        if not ok:
            what = (
                "(x, y, z) triples [m]"
                if width
                else f"tilts in ({-TILT_LIMIT_DEG:g}, {TILT_LIMIT_DEG:g}) deg"
            )
            _fail(
                f"sensor.{name}", v, f"must hold one entry per sensor.sites ({n_sensors}): {what}"
            )
    m = c.env.model
    ratio = CONTROL_DT_S / m.timestep  # foottof.physics.num_substeps
    if not math.isclose(ratio, round(ratio), rel_tol=1e-9, abs_tol=1e-9):
        _fail(
            "env.model.timestep",
            m.timestep,
            f"must divide the control period {CONTROL_DT_S:g} s into whole physics steps",
        )
    _check_section_cross("env.model", m)
    _check_section_cross("reward", c.reward)
    sat = c.env.control.get("saturation_torque")
    if sat is not None and _num(0.0, lo_open=True)(sat):
        _fail("env.control.saturation_torque", sat, "must be None or a number > 0")


def check_sections(cfg, sections: tuple[str, ...]) -> None:
    """The rules of ``sections`` only (e.g. ("ppo", "network") for the trainer's make_train,
    which may get a config without the env sections): the same RULES and cross-field checks as
    :func:`check_config`, one line per bad field (ConfigError)."""
    for pattern, check in RULES.items():
        if pattern.split(".")[0] not in sections:
            continue
        for path, value in _items(cfg, pattern):
            _check_rule(path, value, check)
    if "ppo" in sections:
        _check_section_cross("ppo", cfg.ppo)


def check_config(cfg: ml_collections.ConfigDict) -> None:
    """Validates a whole train/eval config (sections, every known field's range, cross-field).

    Cheap (no JAX, no disk writes): train.py and evaluate.py call it first.

    Raises:
      ConfigError (a ValueError): one line, '<field>=<value>: <valid range>', for the first bad
        field (file order of RULES).
    """
    missing = [s for s in ("seed", "stage", *SECTIONS) if s not in cfg]
    if missing:
        raise ConfigError(
            f"config has no {missing[0]!r} (a config needs {['seed', 'stage', *SECTIONS]}; "
            f"start from configs/base.py)"
        )
    for pattern, check in RULES.items():
        for path, value in _items(cfg, pattern):
            _check_rule(path, value, check)
    for path, value in _leaves(cfg):  # fields without a rule (e.g. new ones): no NaN / inf
        if isinstance(value, float) and not math.isfinite(value):
            _fail(path, value, "must be finite")
    _check_cross(cfg)
