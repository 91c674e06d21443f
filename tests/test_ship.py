"""foottof.lab.ship: a run's newest intact checkpoint replaces a shipped policy folder."""

import csv
import os
import shutil

import pytest
from helpers import REPO

from foottof.lab import ship as ship_lib
from foottof.ppo.storage.integrity import integrity_problem, policy_digest

SHIPPED = os.path.join(REPO, "policies", "stage1")


def _shipped_step() -> int:
    return max(int(d) for d in os.listdir(os.path.join(SHIPPED, "checkpoints")) if d.isdigit())


def _iterations(path: str) -> list[int]:
    with open(os.path.join(path, "metrics.csv"), newline="") as f:
        return [int(r["iteration"]) for r in csv.DictReader(f)]


@pytest.fixture
def run_dir(tmp_path):
    """A run folder: the shipped stage-1 checkpoint, a newer one whose params file was truncated
    after it was written, and metrics rows logged past both."""
    run = tmp_path / "run"
    shutil.copytree(SHIPPED, run)
    step = _shipped_step()
    damaged = run / "checkpoints" / str(step + 10)
    shutil.copytree(run / "checkpoints" / str(step), damaged)
    victim = next(
        os.path.join(root, f)
        for root, _, files in os.walk(damaged / "params")
        for f in sorted(files)
        if os.path.getsize(os.path.join(root, f)) > 100
    )
    with open(victim, "r+b") as fh:
        fh.truncate(os.path.getsize(victim) // 2)
    with open(run / "metrics.csv", newline="") as f:
        reader = csv.DictReader(f)
        fields, rows = reader.fieldnames, list(reader)
    extra = [dict(rows[-1], iteration=str(step + k)) for k in (5, 10, 15)]
    with open(run / "metrics.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows + extra)
    return str(run), step


def test_ship_takes_the_newest_intact_checkpoint_and_replaces_the_folder(run_dir, tmp_path):
    run, step = run_dir
    dest = tmp_path / "policies" / "stage1"
    os.makedirs(dest / "checkpoints" / "7")  # an older shipped policy: replaced as a whole
    assert ship_lib.ship(run, str(dest)) == step
    assert sorted(os.listdir(dest / "checkpoints")) == [str(step)]
    assert integrity_problem(str(dest / "checkpoints" / str(step))) is None
    assert policy_digest(str(dest)) == policy_digest(os.path.join(run, "checkpoints", str(step)))
    assert max(_iterations(str(dest))) == step
    assert os.path.exists(dest / "config.json") and os.path.exists(dest / "config.yaml")
    assert not os.path.exists(str(dest) + ".shipping") and not os.path.exists(
        str(dest) + ".replaced"
    )


def test_ship_refuses_a_damaged_step_and_an_oversized_folder_leaving_dest_alone(run_dir, tmp_path):
    run, step = run_dir
    dest = tmp_path / "stage1"
    os.makedirs(dest / "checkpoints" / "7")
    with pytest.raises(ValueError, match=rf"--step {step + 10}: .*damaged.*bytes"):
        ship_lib.ship(run, str(dest), step=step + 10)
    with pytest.raises(FileNotFoundError, match=r"--step 3: not in"):
        ship_lib.ship(run, str(dest), step=3)
    with pytest.raises(ValueError, match=r"over --max_mb 0.5"):
        ship_lib.ship(run, str(dest), max_mb=0.5)
    assert os.listdir(dest / "checkpoints") == ["7"]
    assert not os.path.exists(str(dest) + ".shipping")


def test_ship_cli_names_a_run_without_checkpoints(tmp_path):
    with pytest.raises(SystemExit, match=r"\[ship\] no finished checkpoint in .*empty"):
        ship_lib.main([str(tmp_path / "empty"), str(tmp_path / "dest")])


def test_ship_copy_failure_names_the_step_and_leaves_dest_alone(run_dir, tmp_path, monkeypatch):
    """The running run deletes (rotates out) the step while it is being copied: the ship fails
    with a message naming that step, and neither DEST nor a half-copied folder is left changed."""
    run, step = run_dir
    dest = tmp_path / "stage1"
    os.makedirs(dest / "checkpoints" / "7")
    real_copytree = shutil.copytree

    def rotated_out(src, dst, *args, **kwargs):
        real_copytree(src, dst, *args, **kwargs)  # a part of the folder arrives, then it is gone
        raise FileNotFoundError(2, "No such file or directory", os.path.join(src, "params"))

    monkeypatch.setattr(ship_lib.shutil, "copytree", rotated_out)
    with pytest.raises(ValueError, match=rf"copying .*checkpoints/{step} failed.*run ship again"):
        ship_lib.ship(run, str(dest))
    assert os.listdir(dest / "checkpoints") == ["7"]
    assert not os.path.exists(str(dest) + ".shipping")
