"""foottof.ppo.storage.run_dir: a new folder per run, the latest linked; errors name CLI flags."""

import json
import os

import pytest

from foottof.ppo.storage import run_dir as rd


def _fake_run(path, step=10):
    os.makedirs(os.path.join(path, rd.CHECKPOINT_SUBDIR, str(step)))
    return path


def test_each_run_gets_a_new_folder_even_within_one_second(tmp_path):
    root = str(tmp_path)
    a = rd.new_run_dir(root, "cpu", now=0.0)
    os.makedirs(a)
    b = rd.new_run_dir(root, "cpu", now=0.0)
    assert a != b and not os.path.exists(b)
    assert os.path.basename(a).startswith("cpu-") and os.path.dirname(a) == root


def test_default_run_dir_is_new_and_the_link_follows_the_latest(tmp_path):
    root = str(tmp_path)
    first, link = rd.resolve_run_dir(root, "cpu", None, resume=False)
    assert link == os.path.join(root, "cpu") and first != link
    _fake_run(first)
    assert rd.point_latest(link, first) is None
    second, _ = rd.resolve_run_dir(root, "cpu", None, resume=False)  # `make demo` again: no error
    assert second != first
    os.makedirs(second)
    assert rd.point_latest(link, second) == os.path.basename(first)
    assert os.path.realpath(link) == os.path.realpath(second)
    assert not os.path.isabs(os.readlink(link))  # relative: the runs folder can be moved
    _fake_run(second)
    resumed, no_link = rd.resolve_run_dir(root, "cpu", None, resume=True)
    assert os.path.realpath(resumed) == os.path.realpath(second) and no_link is None


def test_forget_run_restores_the_previous_latest(tmp_path):
    root = str(tmp_path)
    link = os.path.join(root, "cpu")
    good = _fake_run(os.path.join(root, "cpu-1"))
    rd.point_latest(link, good)
    failed = os.path.join(root, "cpu-2")
    os.makedirs(failed)
    previous = rd.point_latest(link, failed)
    rd.forget_run(link, previous, failed)
    assert os.path.realpath(link) == os.path.realpath(good) and not os.path.exists(failed)
    rd.forget_run(link, None, None)  # the first run ever saved nothing: no link at all
    assert not os.path.lexists(link)


def test_existing_run_in_explicit_run_dir_names_the_flags(tmp_path):
    run = _fake_run(str(tmp_path / "mine"))
    with pytest.raises(FileExistsError) as e:
        rd.resolve_run_dir(str(tmp_path), "cpu", run, resume=False)
    msg = str(e.value)
    assert "--resume" in msg and "--run_dir" in msg and "resume=True" not in msg
    assert rd.resolve_run_dir(str(tmp_path), "cpu", run, resume=True) == (run, None)


def test_resume_without_a_run_names_the_flags(tmp_path):
    with pytest.raises(FileNotFoundError, match="--resume.*--run_dir"):
        rd.resolve_run_dir(str(tmp_path), "cpu", None, resume=True)
    with pytest.raises(FileNotFoundError, match="drop --resume"):
        rd.resolve_run_dir(str(tmp_path), "cpu", str(tmp_path / "empty"), resume=True)


def test_a_real_folder_at_the_link_path_is_left_alone(tmp_path):
    """runs/<name> from before timestamped runs: resumable as is, never replaced by a link."""
    old = _fake_run(str(tmp_path / "cpu"))
    assert rd.resolve_run_dir(str(tmp_path), "cpu", None, resume=True) == (old, None)
    with pytest.raises(FileExistsError):
        rd.point_latest(old, str(tmp_path / "cpu-new"))
    assert os.path.isdir(os.path.join(old, rd.CHECKPOINT_SUBDIR, "10"))


def test_latest_checkpoint_is_the_newest_complete_one(tmp_path):
    """Orbax writes <iteration>.orbax-checkpoint-tmp-<time> and renames it when every process has
    written its part: a half-written checkpoint (a killed run's) is not a number and is not
    counted, however new."""
    assert rd.latest_checkpoint(str(tmp_path)) is None  # no checkpoints/ folder
    _fake_run(tmp_path, step=4)
    _fake_run(tmp_path, step=12)
    (tmp_path / "checkpoints" / "14.orbax-checkpoint-tmp-1765000000").mkdir()
    (tmp_path / "checkpoints" / "notes.txt").write_text("")
    assert rd.latest_checkpoint(str(tmp_path)) == 12


def _run_with_config(tmp_path, network: dict, env: dict) -> str:
    run = tmp_path / "run"
    (run / "checkpoints" / "10").mkdir(parents=True)
    (run / "config.json").write_text(json.dumps({"network": network, "env": env}))
    return str(run / "checkpoints" / "10")


def test_a_command_line_action_std_cap_outlives_the_runs_network(tmp_path):
    """evaluate.py --config.network.max_noise_std=X with sampled actions: the policy's network
    comes from its run, but the cap on the std its actions are sampled at is the user's (it shapes
    no parameter); any other command-line network or input field must equal the run's."""
    import jax.numpy as jp

    from configs import teacher_cpu
    from foottof.ppo.networks import make_networks

    ckpt = _run_with_config(
        tmp_path,
        {"max_noise_std": 0.4, "lstm_hidden_size": 32, "actor_hidden": [16, 8]},
        {"actor_terrain": True, "critic_height_scan": True},
    )
    cfg = teacher_cpu.get_config()
    cfg.network.max_noise_std = 0.25
    kept = rd.with_run_network(cfg, ckpt, {"network.max_noise_std"})
    assert kept.network.max_noise_std == 0.25
    assert kept.network.lstm_hidden_size == 32 and kept.network.actor_hidden == (16, 8)
    # saved before network.obs_skip existed: the run's network reads its old default (off), not
    # teacher_cpu's True (its config.json is read migrated, renames.read_saved_config)
    assert cfg.network.obs_skip and not kept.network.obs_skip
    assert rd.with_run_network(cfg, ckpt).network.max_noise_std == 0.4  # not on the command line
    assert cfg.network.max_noise_std == 0.25  # the caller's config is not changed
    # The cap reaches the sampled actions: a learned std of 1 is sampled at 0.25.
    params = {"params": {"log_std": jp.zeros(12)}}
    std = jp.exp(make_networks(12, kept.network).action_log_std(params))
    assert float(std.max()) == pytest.approx(0.25)
    cfg.network.lstm_hidden_size = 64  # differs from the run's 32
    with pytest.raises(ValueError, match=r"network.lstm_hidden_size=64 on the command line.*32"):
        rd.with_run_network(cfg, ckpt, {"network.lstm_hidden_size"})
    cfg.network.lstm_hidden_size = 32  # equal to the run's: allowed
    assert (
        rd.with_run_network(cfg, ckpt, {"network.lstm_hidden_size"}).network.lstm_hidden_size == 32
    )
    cfg.env.actor_terrain = False  # the run's actor reads the terrain
    with pytest.raises(ValueError, match=r"env.actor_terrain=False on the command line"):
        rd.with_run_network(cfg, ckpt, {"env.actor_terrain"})


def test_a_policy_evaluated_with_a_stock_config_reads_the_terrain_inputs_its_run_read(tmp_path):
    """evaluate.py --config configs/stage1_cpu.py --checkpoint policies/teacher_fine: every env
    field that shapes the actor's inputs comes from the run (the 5 cm block among them, 372 more
    inputs); a run saved before a field existed gets its old default (off)."""
    from configs import stage1_cpu

    cfg = stage1_cpu.get_config()
    assert not cfg.env.actor_terrain and not cfg.env.actor_terrain_fine
    fine = rd.with_run_network(
        cfg, _run_with_config(tmp_path, {}, {"actor_terrain": True, "actor_terrain_fine": True})
    )
    assert fine.env.actor_terrain and fine.env.actor_terrain_fine
    assert not fine.env.actor_terrain_seen and not fine.env.critic_height_scan
    old = tmp_path / "old"
    old.mkdir()
    cfg.env.actor_terrain_fine = True
    before = rd.with_run_network(cfg, _run_with_config(old, {}, {"actor_terrain": True}))
    assert before.env.actor_terrain and not before.env.actor_terrain_fine


def test_a_run_keeps_its_stone_curriculum_unless_the_command_line_sets_one(tmp_path):
    """A resumed or evaluated run takes terrain.stone_curriculum from its config.json; one saved
    before the field existed trained gaps-first; a command-line value wins; the caller's config
    is not changed."""
    from configs import stage1_cpu

    cfg = stage1_cpu.get_config()
    assert cfg.terrain.stone_curriculum == "size_first"
    old = cfg.to_dict()
    del old["terrain"]["stone_curriculum"]  # saved before 2026-12-07
    path = tmp_path / "config.json"
    path.write_text(json.dumps(old, default=list))
    kept, note = rd.with_run_curriculum(cfg, str(path))
    assert kept.terrain.stone_curriculum == "gaps_first" and "gaps_first" in note
    assert cfg.terrain.stone_curriculum == "size_first"
    same, note = rd.with_run_curriculum(cfg, str(path), {"terrain.stone_curriculum": "size_first"})
    assert same.terrain.stone_curriculum == "size_first" and note is None
    new = cfg.to_dict()  # a run saved with the field keeps its value
    path.write_text(json.dumps(new, default=list))
    cfg.terrain.stone_curriculum = "gaps_first"
    assert rd.with_run_curriculum(cfg, str(path))[0].terrain.stone_curriculum == "size_first"
    assert rd.with_run_curriculum(cfg, None)[0] is cfg  # no run: the config as given
