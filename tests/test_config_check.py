"""foottof.config_check: shipped configs pass; each bad value fails with one line naming it."""

import ast
import glob
import math
import os
import subprocess
import sys

import pytest
from helpers import REPO

from configs import load_config
from foottof import config_check as cc

CONFIG_FILES = sorted(
    p
    for pattern in ("*.py", "experiments/*.py")
    for p in glob.glob(os.path.join(REPO, "configs", pattern))
    if not os.path.basename(p)[0] == "_"
)


@pytest.mark.parametrize("path", CONFIG_FILES, ids=os.path.basename)
def test_shipped_configs_pass(path):
    cc.check_config(load_config(path))


def _config_imports(path):
    """The config files ``path`` imports (``from configs import x`` / ``from configs.y import x``),
    the base and the section files (configs/base.py, configs/_*.py) left out."""
    tree = ast.parse(open(path).read())
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("configs"):
            folder = node.module.split(".")[1:]
            out += [
                os.path.join(REPO, "configs", *folder, a.name + ".py")
                for a in node.names
                if a.name != "base" and not a.name.startswith("_")
            ]
    return out


def _chain_depth(path):
    return 1 + max((_chain_depth(p) for p in _config_imports(path)), default=0)


@pytest.mark.parametrize("path", CONFIG_FILES, ids=os.path.basename)
def test_config_chains_are_at_most_three_deep(path):
    """A config imports at most two others above configs/base.py (STYLE.md: a variant changes a
    few fields of one user config; legged_gym: two levels), every one of them a file that exists."""
    for imported in _config_imports(path):
        assert os.path.exists(imported), (path, imported)
    assert _chain_depth(path) <= 3, path


def test_chain_depth_counts_imports_of_imports():
    """The depth is what the files say: experiments/teacher_stones_cpu.py -> teacher_cpu.py ->
    stage1_cpu.py (-> base, not counted) is 3; configs/cpu.py (-> base) is 1."""
    stones = os.path.join(REPO, "configs", "experiments", "teacher_stones_cpu.py")
    assert _chain_depth(stones) == 3
    assert _chain_depth(os.path.join(REPO, "configs", "cpu.py")) == 1


def _set(cfg, dotted, value):
    *parents, leaf = dotted.split(".")
    section = cfg
    for p in parents:
        section = section[p]
    with section.unlocked():
        section[leaf] = value


# (field, bad value, words the message must hold)
BAD = [
    ("ppo.num_envs", -1, ">= 1"),
    ("terrain.stone_curriculum", "dense", "['size_first', 'gaps_first']"),
    ("ppo.num_envs", 66, "divisible by ppo.num_minibatches=4"),
    ("ppo.num_minibatches", 0, ">= 1"),
    ("ppo.gamma", 1.5, "[0, 1]"),
    ("ppo.learning_rate", 0.5, "[ppo.lr_min, ppo.lr_max]"),
    ("terrain.up_progress_frac", 0.3, "[terrain.down_progress_frac, 1]"),
    ("terrain.up_progress_frac", 1.5, "[0, 1]"),
    ("ppo.lr_schedule", "cosine", "'adaptive'"),
    ("network.activation", "gelu", "'elu'"),
    ("network.actor_hidden", (64, 0), "integers >= 1"),
    ("train.num_iterations", 0, ">= 1"),
    ("train.run_name", "a/b", "without '/'"),
    ("env.source", "lidar", "'mock_aggre'"),
    ("env.model.timestep", 0.05, "(0, 0.01]"),
    ("env.model.timestep", 0.003, "whole physics steps"),
    ("env.physics", "bullet", "'mujoco'"),
    ("env.physics_threads", -1, ">= 0"),
    ("env.model.solref_timeconst", 0.005, ">= 2 * env.model.timestep"),
    ("env.randomization.friction_range", (1.2, 0.4), "low <= high"),
    ("terrain.cell_m", 0.05, "(0, 0.04]"),
    ("terrain.tile_length_m", 6.02, "multiple of terrain.cell_m"),
    ("terrain.stage1_difficulty.grid_stones", (0.0, 1.5), "[0, 1]"),
    ("sensor.rate_hz", 100.0, "(0, 60]"),
    ("sensor.tilt_x_deg", (0.0, 0.0), "one entry per sensor.sites (4)"),
    ("noise.stage1.missing_rate", 2.0, "[0, 1]"),
    ("noise.model_path", "nope.json", "existing file"),
    ("noise.stage2.min_delay_steps", 9, "<= noise.stage2.max_delay_steps=4"),
    ("reward.scales.reach", math.nan, "finite"),
    ("reward.overspeed_mps", -0.1, ">= 0"),
    ("eval.odometry_levels", (0.0, 11.0), "[0, 10]"),
    ("eval.sources", ("tof", "lidar"), "'mock_ideal'"),
    ("seed", -3, ">= 0"),
    ("stage", 3, "[1, 2]"),
]


@pytest.mark.parametrize("field,value,words", BAD, ids=[f"{f}={v}" for f, v, _ in BAD])
def test_bad_value_is_one_line_naming_field_value_and_range(field, value, words):
    cfg = load_config(os.path.join(REPO, "configs", "cpu.py"))
    _set(cfg, field, value)
    with pytest.raises(cc.ConfigError) as e:
        cc.check_config(cfg)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{field}={value!r}"), msg
    assert words in msg, msg


def test_missing_section_is_an_error():
    cfg = load_config(os.path.join(REPO, "configs", "cpu.py"))
    del cfg["eval"]
    with pytest.raises(cc.ConfigError, match="'eval'"):
        cc.check_config(cfg)


def test_every_rule_names_a_field_of_the_base_config():
    """A renamed or dropped field must not leave a rule that silently never runs."""
    cfg = load_config(os.path.join(REPO, "configs", "base.py"))
    dead = [p for p in cc.RULES if not cc._items(cfg, p)]
    assert not dead, dead


def test_allowed_values_live_once():
    """The modules and config_check read the same objects from foottof.limits (no copies)."""
    from foottof import limits, perception, physics
    from foottof.eval import robustness
    from foottof.ppo import networks, train
    from foottof.sensors import tof

    assert cc.SOURCES is perception.SOURCES is limits.SOURCES
    assert physics.BACKENDS is limits.PHYSICS_BACKENDS is cc.PHYSICS_BACKENDS
    assert train.LR_SCHEDULES is limits.LR_SCHEDULES is cc.LR_SCHEDULES
    assert networks.POLICIES is limits.POLICIES is cc.POLICIES
    assert tuple(networks.ACTIVATIONS) == limits.ACTIVATIONS == cc.ACTIVATIONS
    assert tof.TILT_LIMIT_DEG is limits.TILT_LIMIT_DEG is cc.TILT_LIMIT_DEG
    assert robustness.LEVEL_RANGES is limits.LEVEL_RANGES is cc.LEVEL_RANGES


@pytest.mark.parametrize(
    "field, value",
    [
        ("max_range_m", -1.0),
        ("max_range_m", 0.0),
        ("resolution_m", 2.0),
        ("fov_deg", 180.0),
        ("grid", 6),
        ("rate_hz", 61.0),
    ],
)
def test_a_tof_rule_lives_once(field, value):
    """A bad sensor value gives the same one line from the whole-config check and from a ToFSpec
    built in code: both run config_check's rule (no second copy in foottof.sensors.tof)."""
    from foottof.sensors import tof

    cfg = load_config(os.path.join(REPO, "configs", "stage1_cpu.py"))
    cfg.sensor[field] = value
    with pytest.raises(cc.ConfigError) as from_config:
        cc.check_config(cfg)
    with pytest.raises(ValueError) as from_spec:
        tof.ToFSpec(**{field: value})
    assert str(from_spec.value) == str(from_config.value)
    assert str(from_config.value).startswith(f"sensor.{field}={value!r}: must")


@pytest.mark.parametrize(
    "field, value", [("missing_rate", 1.5), ("gaussian_m", -0.1), ("min_delay_steps", 9)]
)
def test_a_noise_stage_rule_lives_once(field, value):
    """Likewise for noise.stage*: DegradationBounds.from_config runs config_check's rules."""
    from foottof.sensors.degradation import DegradationBounds

    cfg = load_config(os.path.join(REPO, "configs", "stage1_cpu.py"))
    cfg.noise.stage2[field] = value
    with pytest.raises(cc.ConfigError) as from_config:
        cc.check_config(cfg)
    with pytest.raises(ValueError) as from_bounds:
        DegradationBounds.from_config(cfg.noise, 2)
    assert str(from_bounds.value) == str(from_config.value)
    assert str(from_config.value).startswith(f"noise.stage2.{field}={value!r}: must")


def _config_error(field, value) -> str:
    """The one line check_config gives for the stage-1 CPU config with ``field`` set to ``value``."""
    cfg = load_config(os.path.join(REPO, "configs", "stage1_cpu.py"))
    _set(cfg, field, value)
    with pytest.raises(cc.ConfigError) as e:
        cc.check_config(cfg)
    assert str(e.value).startswith(f"{field}={value!r}: must"), str(e.value)
    return str(e.value)


# (TileSpec field, config field, bad value): one case per terrain rule TileSpec runs.
TILE_BAD = [
    ("length_m", "terrain.tile_length_m", 6.02),  # a multiple of cell_m
    ("width_m", "terrain.tile_width_m", 4.02),
    ("platform_length_m", "terrain.platform_length_m", 1.5),
    ("goal_length_m", "terrain.goal_length_m", 1.02),
    ("length_m", "terrain.tile_length_m", 3.2),  # >= platform + goal + 1 m of course
    ("length_m", "terrain.tile_length_m", -6.0),  # > 0
    ("cell_m", "terrain.cell_m", 0.05),  # in (0, MAX_CELL_M]
    ("pit_z_m", "terrain.pit_z_m", -0.4),  # <= -0.5
    ("z_range_m", "terrain.z_range_m", 1.6),  # pit_z_m + z_range_m >= 1
    ("foot_radius_m", "env.model.foot_radius_m", 0.019),  # limits.FOOT_RADIUS_RANGE_M
    ("foot_radius_m", "env.model.foot_radius_m", 0.051),
]


@pytest.mark.parametrize(
    "spec_field, field, value", TILE_BAD, ids=[f"{f}={v}" for f, _, v in TILE_BAD]
)
def test_a_tile_rule_lives_once(spec_field, field, value):
    """A bad tile value gives the same one line from the whole-config check and from a TileSpec
    built in code: both run config_check's rule (no second copy in foottof.terrain.tiles)."""
    from foottof.terrain.tiles import TileSpec

    cfg = load_config(os.path.join(REPO, "configs", "stage1_cpu.py"))
    assert TileSpec.from_config(cfg.terrain) == TileSpec()  # the config's tile is the default
    with pytest.raises(ValueError) as from_spec:
        TileSpec(**{spec_field: value})
    assert str(from_spec.value) == _config_error(field, value)


# (make_model keyword, bad value): one case per env.model rule the model builder runs.
MODEL_BAD = [
    ("timestep", 0.05),  # in (0, MAX_TIMESTEP_S]
    ("solref_timeconst", 0.005),  # >= 2 * timestep
    ("cone", "round"),
    ("solver", "pgs"),
    ("body_condim", 6),
    ("iterations", 0),
    ("ls_iterations", 0),
    ("armature", -0.1),
    ("impratio", -1.0),
    ("solref_dampratio", 0.0),
    ("shank_scale", 0.79),  # limits.LEVEL_RANGES["shank_length"]
    ("shank_scale", 1.21),
    ("foot_radius_m", 0.019),
]


@pytest.mark.parametrize("field, value", MODEL_BAD, ids=[f"{f}={v}" for f, v in MODEL_BAD])
def test_a_model_rule_lives_once(field, value):
    """A bad env.model value gives the same one line from the whole-config check and from the
    robot model built in code (the config unpacks into make_model; the kinematics run the
    shank_scale rule): no second copy in foottof.robot."""
    from foottof.robot import kinematics, model

    cfg = load_config(os.path.join(REPO, "configs", "stage1_cpu.py"))
    line = _config_error(f"env.model.{field}", value)
    with pytest.raises(ValueError) as from_model:
        model.make_model(**{**cfg.env.model, field: value})
    assert str(from_model.value) == line
    if field == "shank_scale":
        with pytest.raises(ValueError) as from_kinematics:
            kinematics.check_shank_scale(value)
        assert str(from_kinematics.value) == line


def test_check_imports_no_jax():
    """What makes a bad value fail in about a second: no JAX import before the check."""
    code = (
        "import sys; from configs import load_config; from foottof import config_check;"
        "config_check.check_config(load_config('configs/cpu.py'));"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('jax', 'mujoco')))"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]", r.stdout


@pytest.mark.parametrize(
    "start, end, ok", [(5, 3, False), (3, 3, False), (0, 1, True), (500, 1500, True), (7, 0, True)]
)
def test_the_guidance_decay_rule_lives_once(start, end, ok):
    """reward.guidance_decay_start_iteration < _end_iteration when the decay is on (end > 0):
    the same one line from the whole-config check and from the RewardSpec the env builds."""
    from foottof.envs.rewards import RewardSpec

    cfg = load_config(os.path.join(REPO, "configs", "stage1_cpu.py"))
    cfg.reward.guidance_decay_start_iteration = start
    cfg.reward.guidance_decay_end_iteration = end
    if ok:
        cc.check_config(cfg)
        assert RewardSpec.from_config(cfg.reward).guidance_decay == (start, end)
        return
    with pytest.raises(cc.ConfigError) as from_config:
        cc.check_config(cfg)
    with pytest.raises(ValueError) as from_spec:
        RewardSpec.from_config(cfg.reward)
    assert (
        str(from_spec.value)
        == str(from_config.value)
        == (
            f"reward.guidance_decay_start_iteration={start}: must be in "
            f"[0, reward.guidance_decay_end_iteration={end}) when the decay is on (end > 0)"
        )
    )


def test_each_rule_runs_once_on_the_train_path(monkeypatch):
    """train.py checks the whole config first (check_config); make_train then checks the ppo
    section and make_networks the network section, as a library caller needs: a rule that passed
    for a value is not run again (each section is checked once a command), and one that fails
    fails every time."""
    import toy_envs

    from foottof.ppo import train as train_lib

    monkeypatch.setattr(cc, "_PASSED", set())
    calls = {}
    for name in ("ppo.num_envs", "ppo.gamma", "network.policy", "network.actor_hidden"):

        def counted(value, rule=cc.RULES[name], name=name):
            calls[name] = calls.get(name, 0) + 1
            return rule(value)

        monkeypatch.setitem(cc.RULES, name, counted)
    cfg = load_config(os.path.join(REPO, "configs", "cpu.py"))
    cc.check_config(cfg)
    train_lib.make_train(toy_envs.make_memory_env(), cfg)
    assert calls == dict.fromkeys(calls, 1) and len(calls) == 4, calls
    monkeypatch.setattr(cc, "_PASSED", set())  # a library caller, without check_config
    train_lib.make_train(toy_envs.make_memory_env(), cfg)
    assert calls == dict.fromkeys(calls, 2), calls
    cfg.network.policy = "gru"
    for _ in range(2):
        with pytest.raises(cc.ConfigError, match="network.policy='gru'"):
            train_lib.make_train(toy_envs.make_memory_env(), cfg)
