"""Damaged checkpoints: resume from the newest readable one; one line naming the path and cause."""

import glob
import json
import os
import shutil

import jax
import pytest
import toy_envs
from helpers import REPO, run_cli, tiny_cfg, tree_equal

from foottof.ppo import checkpoint as ckpt
from foottof.ppo import integrity, runner

ENV = toy_envs.make_memory_env()


def _largest_data_file(step_dir: str) -> str:
    files = glob.glob(os.path.join(step_dir, "params", "**", "d", "*"), recursive=True)
    return max(files, key=os.path.getsize)


def _truncate(step_dir: str) -> str:
    path = _largest_data_file(step_dir)
    os.truncate(path, os.path.getsize(path) // 2)
    return "truncated or partial copy"


def _remove(step_dir: str) -> str:
    os.remove(_largest_data_file(step_dir))
    return "is missing"


def _garble_manifest(step_dir: str) -> str:
    path = os.path.join(step_dir, "manifest", "metadata")
    with open(path, "r+b") as f:
        f.write(b"{garbled")
    return "corrupted"


def _garble_manifest_legacy(step_dir: str) -> str:
    """A checkpoint written before the integrity record: only reading it shows the damage."""
    os.remove(os.path.join(step_dir, integrity.INTEGRITY_FILE))
    _garble_manifest(step_dir)
    return "manifest unreadable"


def _truncate_legacy(step_dir: str) -> str:
    os.remove(os.path.join(step_dir, integrity.INTEGRITY_FILE))
    _truncate(step_dir)
    return "data unreadable"


DAMAGE = {
    "truncated": _truncate,
    "removed": _remove,
    "garbled_manifest": _garble_manifest,
    "legacy_garbled_manifest": _garble_manifest_legacy,
    "legacy_truncated": _truncate_legacy,
}


@pytest.fixture(scope="module")
def run4(tmp_path_factory):
    """A run with checkpoints 2 and 4 (tiny LSTM on the memory task)."""
    path = str(tmp_path_factory.mktemp("runs") / "run4")
    runner.run(tiny_cfg(num_iterations=4, checkpoint_every=2), ENV, path)
    assert sorted(os.listdir(os.path.join(path, "checkpoints"))) == ["2", "4"]
    return path


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_damaged_newest_resumes_from_the_previous_one(run4, tmp_path, capfd, damage):
    damaged, reference = str(tmp_path / "damaged"), str(tmp_path / "reference")
    shutil.copytree(run4, damaged)
    shutil.copytree(run4, reference)
    cause = DAMAGE[damage](os.path.join(damaged, "checkpoints", "4"))
    shutil.rmtree(os.path.join(reference, "checkpoints", "4"))  # uninterrupted from 2
    capfd.readouterr()
    state = runner.run(tiny_cfg(num_iterations=6, checkpoint_every=2), ENV, damaged, resume=True)
    out, err = capfd.readouterr()
    warnings = [ln for ln in out.splitlines() if "WARNING: skipping checkpoint" in ln]
    assert len(warnings) == 1, out
    assert os.path.join(damaged, "checkpoints", "4") in warnings[0] and cause in warnings[0]
    assert "resumed from iteration 2" in out
    assert "Traceback" not in out + err, err[-3000:]
    # The skipped checkpoint is kept aside, and the run wrote its own 4 and 6.
    assert os.path.isdir(os.path.join(damaged, ckpt.DAMAGED_SUBDIR, "4"))
    assert sorted(os.listdir(os.path.join(damaged, "checkpoints")), key=int) == ["2", "4", "6"]
    expected = runner.run(
        tiny_cfg(num_iterations=6, checkpoint_every=2), ENV, reference, resume=True
    )
    assert int(state.iteration) == 6
    assert tree_equal(jax.device_get(state), jax.device_get(expected))


def test_no_readable_checkpoint_says_so_in_one_line(run4, tmp_path):
    damaged = str(tmp_path / "damaged")
    shutil.copytree(run4, damaged)
    for step in ("2", "4"):
        _truncate(os.path.join(damaged, "checkpoints", step))
    with pytest.raises(ckpt.CheckpointUnreadable) as info:
        runner.run(tiny_cfg(num_iterations=6), ENV, damaged, resume=True)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"no readable checkpoint in {damaged} (tried 4, 2;")
    # Nothing was moved: there was nothing to resume from.
    assert not os.path.exists(os.path.join(damaged, ckpt.DAMAGED_SUBDIR))


def test_unreadable_is_not_a_mismatch(run4, tmp_path):
    """init_from (stage 2, evaluate, export) tells a damaged checkpoint from one that does not
    fit the model: CheckpointUnreadable vs CheckpointMismatch, each naming the path."""
    damaged = str(tmp_path / "damaged")
    shutil.copytree(run4, damaged)
    shutil.rmtree(os.path.join(damaged, "checkpoints", "2"))
    _remove(os.path.join(damaged, "checkpoints", "4"))
    with pytest.raises(ckpt.CheckpointUnreadable, match=r"train.init_from .*is missing"):
        runner.run(tiny_cfg(num_iterations=1), ENV, str(tmp_path / "s2"), init_from=damaged)
    bigger = tiny_cfg(num_iterations=1)
    bigger.network.lstm_hidden_size = 16
    with pytest.raises(ckpt.CheckpointMismatch, match="has shape"):
        runner.run(bigger, ENV, str(tmp_path / "s2b"), init_from=run4)
    assert not issubclass(ckpt.CheckpointUnreadable, ValueError)


def test_integrity_record_lists_every_file(run4):
    step_dir = os.path.join(run4, "checkpoints", "4")
    with open(os.path.join(step_dir, integrity.INTEGRITY_FILE)) as f:
        record = json.load(f)["files"]
    on_disk = {
        os.path.relpath(os.path.join(r, n), step_dir)
        for r, _, names in os.walk(step_dir)
        for n in names
        if n != integrity.INTEGRITY_FILE
    }
    assert set(record) == on_disk and len(on_disk) > 20
    assert integrity.integrity_problem(step_dir) is None


@pytest.mark.parametrize("policy", ["flat", "stage1", "teacher", "student"])
def test_shipped_policies_carry_an_intact_record(policy):
    run = os.path.join(REPO, "policies", policy)
    steps = os.listdir(os.path.join(run, "checkpoints"))
    assert steps
    for step in steps:
        step_dir = os.path.join(run, "checkpoints", step)
        assert os.path.exists(os.path.join(step_dir, integrity.INTEGRITY_FILE))
        assert integrity.integrity_problem(step_dir) is None


def test_evaluate_on_a_damaged_checkpoint_exits_with_one_unreadable_line(tmp_path):
    damaged = str(tmp_path / "flat")
    shutil.copytree(os.path.join(REPO, "policies", "flat"), damaged)
    (step,) = os.listdir(os.path.join(damaged, "checkpoints"))
    _truncate(os.path.join(damaged, "checkpoints", step))
    p = run_cli(
        "evaluate.py",
        "--config",
        "configs/flat.py",
        "--checkpoint",
        damaged,
        "--episodes",
        "1",
        "--out",
        str(tmp_path / "out"),
    )
    assert p.returncode == 1
    errors = [ln for ln in p.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, p.stderr[-3000:]
    assert f"checkpoint '{damaged}' is unreadable" in errors[0] and "truncated" in errors[0]
    assert "does not fit" not in errors[0]
    assert "Traceback" not in p.stdout + p.stderr
