"""Renamed names (foottof.renames): what older code wrote stays readable, old flags say the new name."""

import csv
import json
from pathlib import Path

import pytest
from helpers import REPO, run_cli

from configs import load_config
from foottof import renames
from foottof.eval import paired
from foottof.lab import curves
from foottof.ppo import runner

SHIPPED_RUN_CONFIG = Path(REPO) / "policies" / "flat" / "config.json"  # written with the old names


def _leaf(d: dict, dotted: str):
    for k in dotted.split("."):
        d = d[k]
    return d


def _parent(d: dict, dotted: str) -> tuple[dict, str]:
    """The dict holding a dotted field, and the field's last name."""
    *path, leaf = dotted.split(".")
    return _leaf(d, ".".join(path)), leaf


def test_every_renamed_field_exists_under_its_new_name_only():
    cfg = load_config(str(Path(REPO) / "configs" / "stage1_cpu.py")).to_dict()
    for old, new in renames.CONFIG_FIELDS.items():
        _leaf(cfg, new)
        with pytest.raises(KeyError):
            _leaf(cfg, old)
        assert old.endswith("_ms") and new == old[:-3] + "_mps"


def test_shipped_run_config_migrates_to_the_current_field_names():
    """policies/flat's config.json was written with the old names: after the migration every
    field it holds is a field of the current config (values as saved)."""
    saved = json.loads(SHIPPED_RUN_CONFIG.read_text())
    for old in renames.CONFIG_FIELDS:
        _leaf(saved, old)  # the shipped file predates the rename
    migrated = renames.migrate_config_dict(saved)
    for old, new in renames.CONFIG_FIELDS.items():
        assert _leaf(migrated, new) == _leaf(saved, old)
        with pytest.raises(KeyError):
            _leaf(migrated, old)
    current = load_config(str(Path(REPO) / "configs" / "flat.py")).to_dict()
    for section in ("env", "reward"):  # every saved field is a field of today's config
        assert _keys(migrated[section]) <= _keys(current[section])
    assert not _keys(saved["reward"]) <= _keys(current["reward"])  # (not before the migration)
    assert _leaf(saved, "reward.stall_speed_ms") == 0.1  # the migration copied, not moved
    assert "stall_speed_mps" not in renames.migrate_config_dict({"reward": {}})["reward"]


def _keys(d, prefix=""):
    out = set()
    for k, v in d.items():
        out |= _keys(v, f"{prefix}{k}.") if isinstance(v, dict) else {prefix + k}
    return out


def test_old_metric_columns_are_read_and_rewritten_under_new_names(tmp_path):
    """A metrics.csv of an older run: the curves read 'task/speed_ms' as 'task/speed_mps', and a
    resume (trim_metrics) renames the column so the new rows continue it."""
    path = tmp_path / "metrics.csv"
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["iteration", "time/iteration_s", "task/speed_ms", "episode/speed_ms"])
        w.writerows([[1, 2.0, 0.5, 0.6], [2, 2.0, 0.7, 0.8], [3, 2.0, 0.9, 1.0]])
    cols = curves.read_metrics(str(path))
    assert list(cols["task/speed_mps"]) == [0.5, 0.7, 0.9]
    assert "task/speed_ms" not in cols
    runner.trim_metrics(str(tmp_path), 2)
    rows = list(csv.DictReader(path.open()))
    assert [r["task/speed_mps"] for r in rows] == ["0.5", "0.7"]
    assert [r["episode/speed_mps"] for r in rows] == ["0.6", "0.8"]
    assert "task/speed_ms" not in rows[0]


def test_shipped_episode_documents_of_schema_1_pair(tmp_path):
    """Per-episode documents written before the rename (schema 1, 'mean_speed_ms') load."""
    files = sorted((Path(REPO) / "results").glob("*/episodes_*.json"))
    old = [p for p in files if json.loads(p.read_text())["schema_version"] == 1]
    assert old, "expected committed episodes files written with schema 1"
    doc = paired.load_episodes(str(old[0]))
    assert all("mean_speed_mps" in c and "mean_speed_ms" not in c for c in doc["cells"])
    bad = tmp_path / "episodes_x.json"
    bad.write_text(json.dumps({"schema_version": 9, "cells": []}))
    with pytest.raises(ValueError, match="schema version 9"):
        paired.load_episodes(str(bad))


@pytest.mark.parametrize("script", ["train.py", "evaluate.py"])
def test_old_override_names_the_new_field(script):
    r = run_cli(script, "--config.reward.stall_speed_ms=0.2")
    assert r.returncode != 0
    assert "--config.reward.stall_speed_ms was renamed to --config.reward.stall_speed_mps" in (
        r.stderr
    )
    assert "Traceback" not in r.stderr
    assert renames.old_override(["--config.reward.stall_speed_mps=0.2", "--resume"]) is None


@pytest.mark.parametrize(
    "policy, config",
    [
        ("stage1", "stage1_cpu.py"),
        ("flat", "flat.py"),
        ("teacher", "teacher_cpu.py"),
        ("teacher_stones", "experiments/teacher_stones_cpu.py"),  # the line in training
        ("teacher_fine", "experiments/teacher_fine_cpu.py"),  # its A/B arm (5 cm inputs)
    ],
    ids=["stage1", "flat", "teacher", "teacher_stones", "teacher_fine"],
)
def test_shipped_policies_fit_this_code_for_resume(policy, config):
    """Every leaf of the shipped checkpoint fits the TrainState this code builds from the run's
    config (names and shapes, as Checkpointer.restore checks them before reading; env metrics
    saved under old names are allowed). Shapes only: the TrainState is traced with
    jax.eval_shape, nothing is compiled or run."""
    import jax

    from foottof.envs import make_training_env
    from foottof.ppo import train as train_lib
    from foottof.ppo.storage import checkpoint as ckpt

    run = Path(REPO) / "policies" / policy
    cfg = load_config(str(Path(REPO) / "configs" / config))
    checkpointer = ckpt.Checkpointer(str(run))
    step = checkpointer.latest_step()
    manifest = checkpointer.manifest(step)
    checkpointer.close()
    trainer = train_lib.make_train(make_training_env(cfg), cfg)
    target = jax.eval_shape(trainer.init, jax.random.PRNGKey(0))
    for item in ckpt.ITEMS:
        if item in manifest:
            ckpt.check_compatible(item, manifest[item], ckpt._sub(target, item), policy)
    assert "rollout" in manifest  # the env state too: a resume continues the same episodes


def test_draw_fingerprint_is_kept_across_the_rename():
    """An evaluation written before the rename (results/stage1_trapfree_it1110_d01, by the code of
    2026-12-02's second round) pairs with one made now with the same config: the fingerprint this
    code computes equals the one in the committed file."""
    from foottof.eval import results

    doc = json.loads(
        (
            Path(REPO) / "results" / "stage1_trapfree_it1110_d01" / "episodes_tof_none.json"
        ).read_text()
    )
    cfg = load_config(str(Path(REPO) / "configs" / "stage1_cpu.py"))
    cfg.eval.num_envs, cfg.eval.seed, cfg.eval.episodes = 200, 4242, 200
    cfg.eval.difficulty_fraction = 0.125
    cfg.terrain.stone_curriculum = "gaps_first"  # what that run trained and evaluated on
    assert results.episode_draws(cfg) == doc["draws"]
    cfg.eval.deterministic, cfg.network.max_noise_std = False, 0.15  # sampled: the same draws
    assert results.episode_draws(cfg) == doc["draws"]
    cfg.eval.deterministic = True
    cfg.reward.scales.overspeed = -1.0  # an added field counts away from its old-behaviour default
    assert results.draws_fingerprint(cfg) != doc["draws"]["fingerprint"]
    cfg.reward.scales.overspeed = 0.0
    cfg.reward.stall_speed_mps = 0.2  # a renamed field still counts
    assert results.draws_fingerprint(cfg) != doc["draws"]["fingerprint"]
    back = renames.legacy_config_dict(
        renames.migrate_config_dict({"reward": {"stall_speed_ms": 1}})
    )
    assert back == {"reward": {"stall_speed_ms": 1}}


def test_ensemble_evaluations_pair_across_the_stone_curricula():
    """An ensemble evaluation written before terrain.stone_curriculum existed
    (results/wideedge_it5120_ens: difficulty 0.9 of the stage-1 range, d = 0.72) pairs with one
    made now on either curriculum: there every curriculum draws the same stones. Below the knot
    (difficulty 0.45) the curriculum decides the tiles and the fingerprints part."""
    from foottof.eval import results

    doc = json.loads(
        (Path(REPO) / "results" / "wideedge_it5120_ens" / "episodes_tof_none.json").read_text()
    )
    cfg = load_config(str(Path(REPO) / "configs" / "stage1_cpu.py"))
    cfg.eval.num_envs, cfg.eval.seed, cfg.eval.episodes = 200, 4242, 200
    cfg.env.actor_terrain = True  # the teacher (not a draw: the same fingerprint as a student)
    for curriculum in ("size_first", "gaps_first"):
        cfg.terrain.stone_curriculum = curriculum
        assert results.episode_draws(cfg) == doc["draws"], curriculum
    cfg.eval.difficulty_fraction = 0.45
    prints = set()
    for curriculum in ("size_first", "gaps_first"):
        cfg.terrain.stone_curriculum = curriculum
        prints.add(results.draws_fingerprint(cfg))
    assert len(prints) == 2


def test_configs_saved_before_an_added_field_read_its_old_behaviour_default(tmp_path):
    """A run config saved before the ADDED_FIELDS existed (the fields deleted), read by the one
    loader (renames.read_saved_config), builds the same TaskSpec, reward terms and network as one
    holding them at their old-behaviour defaults: migrated once, when it is read."""
    import jax.numpy as jp
    import ml_collections

    from foottof.envs import rewards
    from foottof.envs.task_spec import TaskSpec

    cfg = load_config(str(Path(REPO) / "configs" / "stage1_cpu.py"))
    at_default = cfg.to_dict()
    for field, default in renames.ADDED_FIELDS.items():
        _leaf(at_default, field)  # every added field is a field of the current config
        parent, leaf = _parent(at_default, field)
        parent[leaf] = default
    saved_before = json.loads(json.dumps(at_default))
    for field in renames.ADDED_FIELDS:
        parent, leaf = _parent(saved_before, field)
        del parent[leaf]
    path = tmp_path / "config.json"
    path.write_text(json.dumps(saved_before))
    old = ml_collections.ConfigDict(renames.read_saved_config(str(path)))
    new = ml_collections.ConfigDict(at_default)
    at_default["env"]["foot_stuck_depth_m"] = 0.1  # away from the default: the specs differ
    assert TaskSpec.from_config(old) == TaskSpec.from_config(new)
    assert TaskSpec.from_config(old) != TaskSpec.from_config(ml_collections.ConfigDict(at_default))

    from foottof import constants

    pose = jp.asarray(constants.DEFAULT_POSE)
    x = rewards.RewardInputs(
        **dict(base_pos=jp.array([0.0, 0.0, 0.6]), base_lin_vel=jp.array([0.8, 0.0, 0.0])),
        **dict(goal_xy=jp.array([3.0, 0.0]), projected_gravity=jp.array([0.0, 0.0, -1.0])),
        **{k: jp.zeros(12) for k in ("torques", "qvel", "last_qvel", "action", "last_action")},
        **dict(foot_vel=jp.ones((4, 3)), foot_contact=jp.zeros(4), q=pose, default_q=pose),
        **dict(time_s=jp.asarray(5.0), failed=jp.asarray(0.0), truncated=jp.asarray(0.0)),
        **dict(knee_contact=jp.zeros(4), foot_edge=jp.zeros(4)),
        **dict(time_left_s=jp.asarray(1.0), guidance_weight=jp.asarray(1.0)),  # in the window
    )

    def terms(c):
        return rewards.compute_terms(x, rewards.RewardSpec.from_config(c.reward), 0.02)

    for name, value in terms(old).items():
        assert jp.allclose(value, terms(new)[name]), name

    # ... and scale alike: an absent added term (reward.scales.task) scales to its default, off
    def scaled(c):  # as the env scales them
        spec = rewards.RewardSpec.from_config(c.reward)
        return rewards.scaled_terms(terms(c), dict(spec.scales), 0.02, spec.overall_scale)

    for name, value in scaled(old).items():
        assert jp.allclose(value, scaled(new)[name]), name
    new.reward.scales.task = 10.0  # away from the default: paid in the window
    assert float(scaled(new)["task"]) > 0.0 == float(scaled(old)["task"])
    new.reward.task_window_s = 0.5  # away from the default: 1 s before the end is outside it
    assert not jp.allclose(terms(old)["task"], terms(new)["task"])
    from foottof.ppo.networks import make_networks

    assert make_networks(12, old.network).module == make_networks(12, new.network).module
    new.network.obs_skip = True  # away from the default: the networks differ
    assert make_networks(12, old.network).module != make_networks(12, new.network).module
    with pytest.raises(KeyError, match="not an added field"):
        renames.added_default("terrain.num_levels")


def test_a_saved_run_config_is_migrated_once_when_read(tmp_path):
    """renames.read_saved_config, the one reader of a run's config.json: a run saved before the
    ADDED_FIELDS existed reads each at its old-behaviour default (renames.added_default); a value
    the run saved is kept; renames are applied and removed fields dropped as before; a section
    the run lacks is not created (a test's config.json of "network" and "env" gets the env.* and
    network.* added fields only)."""
    cfg = load_config(str(Path(REPO) / "configs" / "teacher_cpu.py")).to_dict()
    saved = json.loads(json.dumps(cfg, default=list))
    for field in renames.ADDED_FIELDS:
        parent, leaf = _parent(saved, field)
        del parent[leaf]
    saved["reward"]["stall_speed_ms"] = saved["reward"].pop("stall_speed_mps")  # an old name
    saved["ppo"]["low_noise_share"] = 0.0  # a removed field at its default
    path = tmp_path / "config.json"
    path.write_text(json.dumps(saved))
    out = renames.read_saved_config(str(path))
    for field, default in renames.ADDED_FIELDS.items():
        assert _leaf(out, field) == default == renames.added_default(field), field
    assert _leaf(out, "reward.stall_speed_mps") == cfg["reward"]["stall_speed_mps"]
    assert "stall_speed_ms" not in out["reward"] and "low_noise_share" not in out["ppo"]
    # every other field as saved: the migrated config is today's, its added fields at default
    for field, default in renames.ADDED_FIELDS.items():
        parent, leaf = _parent(cfg, field)
        parent[leaf] = default
    assert out == json.loads(json.dumps(cfg, default=list))
    # a value the run saved is kept, at any value
    kept = {"env.physics": "mjx", "network.obs_skip": True, "reward.scales.task": 3.0}
    for field, value in kept.items():
        parent, leaf = _parent(saved, field)
        parent[leaf] = value
    path.write_text(json.dumps(saved))
    out = renames.read_saved_config(str(path))
    for field, value in kept.items():
        assert _leaf(out, field) == value, field
    # no section is created: only the dicts the run saved get their added fields
    path.write_text(json.dumps({"network": {"lstm_hidden_size": 32}, "env": {}}))
    out = renames.read_saved_config(str(path))
    assert set(out) == {"network", "env"}
    assert out["env"] == {
        f.split(".")[1]: d for f, d in renames.ADDED_FIELDS.items() if f.startswith("env.")
    }
    assert set(out["network"]) == {"lstm_hidden_size"} | {
        f.split(".")[1] for f in renames.ADDED_FIELDS if f.startswith("network.")
    }
    no_scales = renames.migrate_config_dict({"reward": {}})["reward"]
    assert "scales" not in no_scales and no_scales["overall_scale"] == 1.0
    assert renames.HASHED_AT_DEFAULT <= set(renames.ADDED_FIELDS)


def test_removed_fields_are_dropped_at_their_default_and_refused_elsewhere():
    """renames.REMOVED_FIELDS (experiment flags removed on 2026-12-07): a saved run config holding
    one at its default migrates without it; one that read it away from the default is refused in
    one line naming the field and the commit whose code has it. A field read only when another is
    on (ppo.low_noise_scale, with ppo.low_noise_share) is dropped whatever its value while that
    one is off: policies/teacher's config.json holds low_noise_scale 0.25, share 0."""
    saved = {
        "ppo": {"low_noise_share": 0.0, "low_noise_scale": 0.5, "gamma": 0.998},
        "reward": {"guidance_peaked": False, "scales": {"timeout": 0.0, "reach": 10.0}},
        "terrain": {"stretch_prob": 0.0, "stretch_min_level": 7},
    }
    out = renames.migrate_config_dict(saved)
    for field in renames.ADDED_FIELDS:  # filled in where their section is (tested above)
        *path, leaf = field.split(".")
        node = out
        for k in path:
            node = node.get(k, {})
        node.pop(leaf, None)
    assert out == {"ppo": {"gamma": 0.998}, "reward": {"scales": {"reach": 10.0}}, "terrain": {}}
    assert saved["ppo"]["low_noise_share"] == 0.0  # a copy: the saved dict is not changed
    for field, value in (
        ("ppo.low_noise_share", 0.25),
        ("ppo.low_noise_scale", 0.5),  # read: low_noise_share is on
        ("reward.scales.timeout", -15.0),
        ("reward.scales.foot_clearance", -20.0),
        ("terrain.stretch_prob", 0.1),
        ("reward.guidance_peaked", True),
    ):
        bad = {"ppo": {"low_noise_share": 0.25}} if field == "ppo.low_noise_scale" else {}
        section, *path, leaf = field.split(".")
        node = bad.setdefault(section, {})
        for p in path:
            node = node.setdefault(p, {})
        node[leaf] = value
        with pytest.raises(ValueError) as info:
            renames.migrate_config_dict(bad)
        message = str(info.value)
        assert "\n" not in message and renames.REMOVED_AT in message, message
        assert (f"{field}={value!r}" in message) or field == "ppo.low_noise_scale", message


def test_removed_fields_are_gone_from_the_configs_and_the_shipped_policies_migrate():
    """No config file holds a removed field, none is an added one, and every shipped policy's
    config.json (written while they existed) migrates."""
    import glob

    for path in glob.glob(str(Path(REPO) / "configs" / "**" / "[!_]*.py"), recursive=True):
        flat = json.dumps(load_config(path).to_dict(), default=str)
        for field in renames.REMOVED_FIELDS:
            assert f'"{field.rsplit(".", 1)[1]}"' not in flat, (path, field)
    assert not set(renames.REMOVED_FIELDS) & set(renames.ADDED_FIELDS)
    policies = sorted(glob.glob(str(Path(REPO) / "policies" / "*" / "config.json")))
    assert len(policies) >= 4
    for path in policies:
        with open(path) as f:
            renames.migrate_config_dict(json.load(f))
