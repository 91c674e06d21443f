"""Tests of the robustness evaluation (foottof/eval/robustness.py, plots.py, evaluate.py).

One env compile: the end-to-end cell (4 envs, 0.5 s episodes, untrained policy) in a module
fixture; everything else is pure NumPy or fails before any compile.
"""

import csv
import json
import math
import os
from typing import NamedTuple

import jax
import jax.numpy as jp
import numpy as np
import pytest
from helpers import REPO, run_cli

from configs import smoke
from foottof.eval import cells, harness, paired, plots, results
from foottof.eval import robustness as rb
from foottof.perception import check_source
from foottof.ppo.storage import run_dir


def tiny_cfg():
    c = smoke.get_config()
    c.env.episode_length_s = 0.5  # 25 control steps
    c.eval.episodes = 4
    c.eval.num_envs = 4
    c.eval.num_levels = 2
    c.eval.num_cols = 5
    return c


# ---------------------------------------------------------------------------------------------
# Pure functions
def test_first_episode_outcomes_hand_checked():
    # 5 steps x 4 envs. env0: fails at t=1, later auto-reset episode succeeds at t=4 (ignored).
    # env1: success at its first done t=4. env2: truncated at t=3 without success.
    # env3: never done.
    done = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 1, 0], [1, 1, 0, 0]])
    success = np.array([[0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [1, 1, 0, 0]])
    failed = np.array([[0, 0, 0, 0], [1, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]])
    speed = np.arange(20, dtype=float).reshape(5, 4)
    out = rb.first_episode_outcomes(done, success, failed, speed)
    np.testing.assert_array_equal(out["finished"], [True, True, True, False])
    np.testing.assert_array_equal(out["success"], [False, True, False, False])
    np.testing.assert_array_equal(out["failed"], [True, False, False, False])
    np.testing.assert_array_equal(out["length"], [2, 5, 4, 5])
    # env0: mean(0, 4) = 2; env1: mean(1,5,9,13,17) = 9; env2: mean(2,6,10,14) = 8
    np.testing.assert_allclose(out["mean_speed_mps"], [2.0, 9.0, 8.0, 9.0 + 2.0])
    row = results.summarize("tof", "none", 0.0, out)
    assert (row["episodes"], row["successes"], row["falls"]) == (4, 1, 1)
    assert row["success_rate"] == 0.25


def test_first_episode_outcomes_random_property():
    rng = np.random.default_rng(0)
    for _ in range(50):
        t, b = rng.integers(1, 12), rng.integers(1, 9)
        done = rng.random((t, b)) < 0.3
        success = done & (rng.random((t, b)) < 0.5)
        out = rb.first_episode_outcomes(done, success, np.zeros((t, b)), np.ones((t, b)))
        for j in range(b):
            idx = np.flatnonzero(done[:, j])
            assert out["success"][j] == (bool(success[idx[0], j]) if idx.size else False)
        np.testing.assert_allclose(out["mean_speed_mps"], 1.0)


def test_wilson_interval_hand_computed():
    # 8 / 10, z = 1.96: centre = (0.8 + 0.19208) / 1.38416 = 0.716738,
    # half = 1.96 * sqrt(0.016 + 0.009604) / 1.38416 = 0.226581 -> [0.49016, 0.94332]
    lo, hi = results.wilson_interval(8, 10)
    assert lo == pytest.approx(0.49016, abs=2e-5)
    assert hi == pytest.approx(0.94332, abs=2e-5)
    assert results.wilson_interval(0, 0) == (0.0, 1.0)
    lo, hi = results.wilson_interval(0, 20)
    assert lo == 0.0 and hi == pytest.approx(3.8415 / (20 + 3.8415), abs=1e-4)
    with pytest.raises(ValueError, match="successes=5, n=3"):
        results.wilson_interval(5, 3)


def test_mcnemar_exact_hand_computed():
    assert paired.mcnemar_exact(0, 0) == 1.0
    assert paired.mcnemar_exact(0, 5) == pytest.approx(2 / 32)  # 2 x 0.5^5
    assert paired.mcnemar_exact(9, 1) == pytest.approx(2 * (1 + 10) / 1024)
    assert paired.mcnemar_exact(3, 7) == pytest.approx(2 * (1 + 10 + 45 + 120) / 1024)
    assert paired.mcnemar_exact(5, 5) == 1.0  # the tail sum exceeds 1/2: clipped
    assert paired.mcnemar_exact(7, 3) == paired.mcnemar_exact(3, 7)
    with pytest.raises(ValueError, match="must be >= 0"):
        paired.mcnemar_exact(-1, 2)


def _episodes_doc(success, failed, seed=0, fingerprint="f"):
    n = len(success)
    cell = {"source": "tof", "perturbation": "none", "level": 0.0}
    cell |= {
        "terrain": (["grid_stones", "platform_gap"] * n)[:n],
        "success": success,
        "failed": failed,
        "finished": [1] * n,
        "length": [9] * n,
    }
    cell["mean_speed_mps"] = [0.5] * n
    draws = {"seed": seed, "num_envs": n, "episodes": n, "fingerprint": fingerprint}
    return {"schema_version": 1, "checkpoint": "x", "draws": draws, "cells": [cell]}


def test_paired_cells_hand_checked():
    a = _episodes_doc([1] * 10 + [0] * 5 + [1] * 3, [0] * 10 + [1] * 5 + [0] * 3)
    b = _episodes_doc([0] * 10 + [1] + [0] * 4 + [1] * 3, [1] * 9 + [0] * 9)
    (row,) = paired.pair_cells(a, b)
    assert (row["successes_a"], row["successes_b"], row["a_only"], row["b_only"]) == (13, 4, 10, 1)
    assert row["p_value"] == pytest.approx(2 * (1 + 11) / 2048)  # 11 discordant, 1 the other way
    assert (row["falls_a"], row["falls_b"], row["episodes"]) == (5, 9, 18)
    # b: episode 9 and 11-14 neither succeed nor fall (18 = 4 successes + 9 falls + 5)
    assert (row["timeouts_a"], row["timeouts_b"]) == (0, 5)
    assert "McNemar" in paired.format_table([row]) and "timeouts" in paired.format_table([row])
    head = paired.format_table([row], ("mean", "sampled")).splitlines()[0]
    assert "mean only sampled only" in head and "timeouts mean timeouts sampled" in head
    grid, gap = results.terrain_breakdown(a)  # even episodes grid stones, odd ones gaps
    # grid: successes at 0 2 4 6 8 16, falls at 10 12 14; gap: successes at 1 3 5 7 9 15 17
    assert (grid["terrain"], grid["episodes"], grid["successes"], grid["falls"]) == (
        "grid_stones",
        9,
        6,
        3,
    )
    assert (gap["terrain"], gap["episodes"], gap["successes"], gap["falls"]) == (
        "platform_gap",
        9,
        7,
        2,
    )
    assert "platform_gap" in results.format_terrain_breakdown([grid, gap])
    with pytest.raises(ValueError, match=r"config .* differs"):
        paired.pair_cells(a, _episodes_doc([0] * 18, [0] * 18, fingerprint="g"))


def test_draws_fingerprint_follows_what_decides_the_episodes():
    base = results.draws_fingerprint(tiny_cfg())
    same, differ = tiny_cfg(), tiny_cfg()
    same.eval.out_dir, same.eval.episodes, same.ppo.learning_rate, same.seed = "x", 9, 0.5, 7
    same.eval.odometry_levels = (0.0, 1.0)
    same.env.actor_terrain = True  # a teacher's actor inputs: the same episodes as its student's
    differ.eval.difficulty_fraction = 0.5
    assert results.draws_fingerprint(same) == base != results.draws_fingerprint(differ)
    sensor = tiny_cfg()
    sensor.env.critic_height_scan = not sensor.env.critic_height_scan  # hashed as before
    assert results.draws_fingerprint(sensor) != base


def test_paired_cli_bad_input_and_output(tmp_path, capsys):
    with pytest.raises(SystemExit, match="no such evaluation folder"):
        paired.main([str(tmp_path / "nope"), str(tmp_path)])
    with pytest.raises(SystemExit, match=r"no per-episode file \(episodes_\*.json\)"):
        paired.main([str(tmp_path), str(tmp_path)])
    for name, doc in (("a", _episodes_doc([1, 0], [0, 1])), ("b", _episodes_doc([0, 0], [1, 1]))):
        (tmp_path / name).mkdir()
        (tmp_path / name / "episodes_tof_none.json").write_text(json.dumps(doc))
    out = tmp_path / "paired.csv"
    paired.main([f"old={tmp_path / 'a'}", f"new={tmp_path / 'b'}", "--out", str(out)])
    printed = capsys.readouterr().out
    assert "old only" in printed and "actions:" not in printed  # none recorded: no line
    cfg = smoke.get_config()
    for name, det in (("a", True), ("b", False)):  # how each acted, from its results file
        cfg.eval.deterministic, cfg.network.max_noise_std = det, 0.15
        doc = results.results_document([_row("tof", "none", 0.0, 1, n=2)], None, 10.0,
                                       results.ensemble_setting(cfg))  # fmt: skip
        results.write_results(str(tmp_path / name), "tof", "none", doc)
    assert paired.actions_of(str(tmp_path / "a")) == "mean actions"
    paired.main([f"old={tmp_path / 'a'}", f"new={tmp_path / 'b'}"])
    printed = capsys.readouterr().out
    assert "actions: old mean actions, new sampled actions (std capped at 0.15)" in printed
    (row,) = list(csv.DictReader(out.open()))
    assert tuple(row) == paired.PAIRED_KEYS and (row["a_only"], row["b_only"]) == ("1", "0")


def _sweep_doc(source, perturbation, levels_success):
    """An episodes document of one sweep: {level: success list}, falls where no success."""
    doc = _episodes_doc([0], [0])
    doc["cells"] = []
    for level, success in levels_success.items():
        cell = _episodes_doc(success, [1 - x for x in success])["cells"][0]
        cell |= {"source": source, "perturbation": perturbation, "level": level}
        doc["cells"].append(cell)
    doc["draws"]["num_envs"] = doc["draws"]["episodes"] = len(success)
    return doc


def test_figure_pairs_tof_with_each_panels_mock_hand_checked(tmp_path, capsys):
    sweeps = {  # 12 episodes per cell
        ("tof", "joint_offset"): {0.0: [1] * 6 + [0] * 6, 0.1: [1] * 8 + [0] * 4},
        ("mock_ideal", "joint_offset"): {0.0: [1] * 7 + [0] * 5, 0.1: [0] * 12},
        ("tof", "odometry"): {0.0: [1] * 2 + [0] * 10, 4.0: [0] * 12},
        ("mock_aggre", "odometry"): {4.0: [0] * 10 + [1] * 2, 9.0: [1] * 12},
        ("mock_aggre", "joint_offset"): {0.0: [1] * 12},  # not a panel of the figure: unused
    }
    for (source, pert), by_level in sweeps.items():
        doc = _sweep_doc(source, pert, by_level)
        (tmp_path / f"episodes_{source}_{pert}.json").write_text(json.dumps(doc))
    rows = paired.pair_figure(str(tmp_path))
    got = [(r["source"], r["perturbation"], r["level"], r["a_only"], r["b_only"]) for r in rows]
    assert got == [  # shank length has no sweep; odometry pairs only the level both hold
        ("tof|mock_ideal", "joint_offset", 0.0, 0, 1),
        ("tof|mock_ideal", "joint_offset", 0.1, 8, 0),
        ("tof|mock_aggre", "odometry", 4.0, 0, 2),
    ]
    assert rows[1]["p_value"] == pytest.approx(2 / 2**8)  # 8 discordant, all one way
    assert (rows[1]["successes_a"], rows[1]["falls_b"], rows[1]["episodes"]) == (8, 12, 12)
    out = tmp_path / "figure_paired.csv"
    paired.main(["--figure", str(tmp_path), "--out", str(out)])
    assert "tof|mock_aggre" in capsys.readouterr().out
    assert [r["source"] for r in csv.DictReader(out.open())] == [r["source"] for r in rows]
    with pytest.raises(SystemExit, match="or --figure OUT_DIR alone"):
        paired.main(["--figure", str(tmp_path), f"a={tmp_path}", f"b={tmp_path}"])
    with pytest.raises(SystemExit, match="or --figure OUT_DIR alone"):
        paired.main([f"a={tmp_path}"])
    (tmp_path / "only_tof").mkdir()
    with pytest.raises(SystemExit, match="episodes_mock_ideal_joint_offset.json"):
        paired.main(["--figure", str(tmp_path / "only_tof")])
    other = _sweep_doc("mock_ideal", "joint_offset", {0.0: [1] * 12})
    other["draws"]["seed"] = 3
    (tmp_path / "episodes_mock_ideal_joint_offset.json").write_text(json.dumps(other))
    with pytest.raises(ValueError, match="seed differs"):
        paired.pair_figure(str(tmp_path))


def test_check_inputs():
    assert check_source("all") == ("tof", "mock_ideal", "mock_aggre")
    with pytest.raises(ValueError, match=r"unknown source 'lidar'.*mock_aggre"):
        check_source("lidar")
    with pytest.raises(ValueError, match=r"unknown perturbation 'wind'.*odometry"):
        rb.check_levels("wind", [0.0])
    with pytest.raises(ValueError, match=r"joint_offset level 0.5 outside .*\[0.0, 0.3\]"):
        rb.check_levels("joint_offset", [0.1, 0.5])
    with pytest.raises(ValueError, match=r"shank_length level 0.7 outside .*\[0.8, 1.2\]"):
        rb.check_levels("shank_length", ["0.7"])
    with pytest.raises(ValueError, match=r"odometry level 11.0 outside .*\[0.0, 10.0\]"):
        rb.check_levels("odometry", [11])
    with pytest.raises(ValueError, match=r"odometry level 'x'"):
        rb.check_levels("odometry", ["x"])
    assert rb.check_levels("odometry", ["0", "2.5"]) == (0.0, 2.5)
    assert rb.check_levels("none", []) == (0.0,)


def _row(source, perturbation, level, k, n=10):
    lo, hi = results.wilson_interval(k, n)
    return {
        "source": source, "perturbation": perturbation, "level": level, "episodes": n,
        "successes": k, "success_rate": k / n, "ci_low": lo, "ci_high": hi,
        "mean_speed_mps": 0.5, "falls": 1,
    }  # fmt: skip


def test_robustness_png_panels_without_data():
    rows = [
        _row(s, "odometry", lv, k) for s in ("tof", "mock_aggre") for lv, k in ((0.0, 9), (2.0, 5))
    ]
    png = plots.robustness_png(rows)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert png != plots.robustness_png([])


def test_ensemble_is_recorded_and_captioned():
    cfg = smoke.get_config()
    cfg.eval.difficulty_fraction = 0.125
    e = results.ensemble_setting(cfg)
    assert tuple(e) == results.ENSEMBLE_KEYS
    assert e["difficulty_fraction"] == 0.125 and e["deterministic"] is True
    assert e["fingerprint"] == results.draws_fingerprint(cfg)
    doc = results.results_document([_row("tof", "odometry", 0.0, 5)], None, 10.0, e)
    assert doc["schema_version"] == 4 and doc["ensemble"] == e
    assert e["action_std_cap"] is None  # mean actions use no std
    rows = [_row("tof", "odometry", 0.0, 5, n=200), _row("tof", "odometry", 2.0, 3, n=200)]
    assert results.ensemble_caption(e, rows) == (
        "ensemble: 80 % stepping stones + 20 % gaps at 12.5 % of the stage-1 difficulty range, "
        "mean actions, 200 episodes per cell"
    )
    assert results.ensemble_caption(e, rows, ["a", "b", "a"]).endswith("; policies: a, b")
    assert results.ensemble_caption(e, rows, ["run/x"]).endswith("per cell; policy: run/x")
    with pytest.raises(ValueError, match="ensemble keys"):
        results.results_document([], None, 10.0, {"difficulty_fraction": 0.9})


def _record_figures(monkeypatch) -> list:
    """plots.robustness_png replaced by a recorder: the list gets (rows, caption, left_out) of
    every figure drawn."""
    drawn = []
    monkeypatch.setattr(
        plots,
        "robustness_png",
        lambda rows, caption, left_out: drawn.append((rows, caption, left_out)) or b"png",
    )
    return drawn


def test_figure_draws_only_results_of_the_same_ensemble(tmp_path, monkeypatch):
    drawn = _record_figures(monkeypatch)
    cfg = smoke.get_config()
    easy = results.ensemble_setting(cfg)
    cfg.eval.difficulty_fraction = 0.125
    hard = results.ensemble_setting(cfg)
    assert easy["fingerprint"] != hard["fingerprint"]
    out = str(tmp_path)

    def write(source, pert, ensemble, checkpoint=None):
        rows = [_row(source, pert, 0.0, 4)]
        doc = results.results_document(rows, checkpoint, 10.0, ensemble)
        results.write_results(out, source, pert, doc)

    write("tof", "odometry", easy, "runs/a")
    write("mock_aggre", "odometry", easy, "runs/b")
    rows, caption, left_out = drawn[-1]
    assert sorted(r["source"] for r in rows) == ["mock_aggre", "tof"] and left_out == []
    assert "90 % of the stage-1" in caption and caption.endswith("policies: runs/b, runs/a")
    write("tof", "joint_offset", hard)  # another ensemble: the two files above are not drawn
    rows, caption, left_out = drawn[-1]
    assert [(r["source"], r["perturbation"]) for r in rows] == [("tof", "joint_offset")]
    assert left_out == ["results_mock_aggre_odometry.json", "results_tof_odometry.json"]
    assert "12.5 % of the stage-1" in caption
    old = json.loads((tmp_path / "results_tof_odometry.json").read_text())
    del old["ensemble"]  # schema 1 (no ensemble): not drawn with anything else
    (tmp_path / "results_tof_odometry.json").write_text(json.dumps(old))
    write("mock_aggre", "odometry", easy)
    rows, _, left_out = drawn[-1]
    assert [r["source"] for r in rows] == ["mock_aggre"]
    assert left_out == ["results_tof_joint_offset.json", "results_tof_odometry.json"]
    legacy = json.loads((tmp_path / "results_mock_aggre_odometry.json").read_text())
    legacy["schema_version"] = 2  # written before mean_speed_ms became mean_speed_mps: drawn
    legacy["results"] = [
        {("mean_speed_ms" if k == "mean_speed_mps" else k): v for k, v in r.items()}
        for r in legacy["results"]
    ]
    (tmp_path / "results_mock_aggre_odometry.json").write_text(json.dumps(legacy))
    write("tof", "odometry", easy)
    rows, _, _ = drawn[-1]
    assert sorted(r["source"] for r in rows) == ["mock_aggre", "tof"]
    assert all("mean_speed_mps" in r for r in rows)


def test_sampled_results_record_their_action_std_cap_and_old_files_migrate(tmp_path, monkeypatch):
    drawn = _record_figures(monkeypatch)
    cfg = smoke.get_config()
    mean = results.ensemble_setting(cfg)
    cfg.eval.deterministic = False
    cfg.network.max_noise_std = 0.25
    at_025 = results.ensemble_setting(cfg)
    cfg.network.max_noise_std = 0.4
    at_04 = results.ensemble_setting(cfg)
    assert (mean["action_std_cap"], at_025["action_std_cap"], at_04["action_std_cap"]) == (
        None,
        0.25,
        0.4,
    )
    rows = [_row("tof", "odometry", 0.0, 5, n=200)]
    assert results.ensemble_caption(at_025, rows).endswith(
        "sampled actions (std capped at 0.25), 200 episodes per cell"
    )
    out = str(tmp_path)

    def write(source, ensemble):
        doc = results.results_document([_row(source, "odometry", 0.0, 4)], None, 10.0, ensemble)
        results.write_results(out, source, "odometry", doc)

    write("tof", at_025)
    write("mock_aggre", at_04)  # sampled at another cap: not drawn with the first
    assert [r["source"] for r in drawn[-1][0]] == ["mock_aggre"]
    assert drawn[-1][2] == ["results_tof_odometry.json"]
    # Files written before schema 4: mean actions migrate (no std used); sampled ones, whose
    # cap was not recorded, are drawn with nothing new.
    for name, ens in (("tof", mean), ("mock_aggre", at_04)):
        path = tmp_path / f"results_{name}_odometry.json"
        old = json.loads(path.read_text())
        old["schema_version"] = 3
        old["ensemble"] = {k: v for k, v in ens.items() if k != "action_std_cap"}
        path.write_text(json.dumps(old))
    write("mock_ideal", mean)
    assert sorted(r["source"] for r in drawn[-1][0]) == ["mock_ideal", "tof"]
    assert drawn[-1][2] == ["results_mock_aggre_odometry.json"]
    assert results.migrate_ensemble(None) is None


def test_robustness_png_with_caption_and_left_out_files():
    rows = [_row("tof", "odometry", 0.0, 9), _row("tof", "odometry", 2.0, 5)]
    plain = plots.robustness_png(rows)
    captioned = plots.robustness_png(rows, "ensemble: test", ["results_x_odometry.json"])
    assert captioned[:8] == b"\x89PNG\r\n\x1a\n" and captioned != plain


def test_default_sweep_is_the_sources_headline_sweep():
    e = tiny_cfg().eval
    odo, joint = tuple(e.odometry_levels), tuple(e.joint_offset_levels)
    assert rb.sweep_plan(e, ("mock_aggre",), None) == [("mock_aggre", "odometry", odo)]
    assert rb.sweep_plan(e, check_source("all"), None) == [
        ("tof", "joint_offset", joint),
        ("mock_ideal", "joint_offset", joint),
        ("mock_aggre", "odometry", odo),
    ]
    assert rb.sweep_plan(e, ("tof",), None, ["0", "0.2"]) == [("tof", "joint_offset", (0.0, 0.2))]
    with pytest.raises(ValueError, match="needs --perturbation"):
        rb.sweep_plan(e, check_source("all"), None, ["1"])
    assert rb.sweep_plan(e, ("tof",), "none") == [("tof", "none", (0.0,))]


def test_write_atomic_leaves_nothing_on_error(tmp_path):
    good = str(tmp_path / "a.json")
    bad = str(tmp_path / "missing_dir_is_a_file" / "b.csv")
    (tmp_path / "missing_dir_is_a_file").write_text("x")  # a file where a folder is needed
    with pytest.raises(OSError):
        results.write_atomic({good: b"{}", bad: b"x"})
    assert sorted(os.listdir(tmp_path)) == ["missing_dir_is_a_file"]


# ---------------------------------------------------------------------------------------------
# CLI errors (no env compile: they fail on the flags)
@pytest.mark.parametrize(
    "args, message",
    [
        (["--source", "lidar"], "unknown source 'lidar'"),
        (["--perturbation", "wind"], "unknown perturbation 'wind'"),
        (["--perturbation", "joint_offset", "--levels", "0,0.4"], "joint_offset level 0.4"),
        (["--checkpoint", "/nonexistent/run"], "'/nonexistent/run' does not exist"),
        (["--perturbation", "all", "--levels", "0"], "--levels cannot be given with"),
        (["--analyze", "--source", "all"], "--analyze needs one --source"),
        (["--analyze", "--perturbation", "odometry"], "give one perturbation and one level"),
        (["--analyze", "--video_stride", "0"], "--video_stride 0: must be >= 1"),
    ],
)
def test_cli_bad_input(args, message, tmp_path):
    p = run_cli("evaluate.py", "--out", str(tmp_path), *args, timeout=300)
    assert p.returncode != 0
    err_lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error:")]
    assert len(err_lines) == 1 and message in err_lines[0], p.stderr[-2000:]


class _Task(NamedTuple):  # the part of the env's task state the rollout reads
    col: jax.Array


class _ConstantObsEnv:
    """Single env whose observation is always zero and whose episodes last 4 steps; at the last
    step 'episode/speed_mps' reads the first action component (what the rollout acted)."""

    action_size = 2
    observation_size = 3

    def reset(self, key):
        from brax.envs.base import State

        z = jp.zeros(())
        metrics = {"episode/success": z, "episode/failed": z, "episode/speed_mps": z}
        info = {"t": jp.zeros((), jp.int32), "task": _Task(jp.int32(3))}
        return State(None, jp.zeros(3), z, z, metrics, info)

    def step(self, state, action):
        t = state.info["t"] + 1
        done = t >= 4
        metrics = dict(state.metrics, **{"episode/speed_mps": jp.where(done, action[0], 0.0)})
        info = {"t": jp.where(done, 0, t), "task": state.info["task"]}
        return state.replace(done=done.astype(jp.float32), metrics=metrics, info=info)


@pytest.mark.parametrize("deterministic", [True, False])
def test_rollout_acts_with_the_mean_or_samples_at_the_capped_std(deterministic):
    # Constant observations and a policy carry reset at every episode start: the mean action at
    # the last step of an episode is the same in every env, so with eval.deterministic the acted
    # values have no spread at all, and with sampling their spread across 1024 envs is the
    # action std, init_noise_std 1.0 capped at max_noise_std 0.3.
    cfg = tiny_cfg()
    cfg.network.init_noise_std = 1.0
    cfg.network.max_noise_std = 0.3
    env = _ConstantObsEnv()
    networks, params, normalizer = harness.load_policy(
        cfg, env, jp.zeros((1, 3)), None, jax.random.PRNGKey(0)
    )
    rollout = rb.make_rollout(env, networks, 1024, 8, deterministic=deterministic)
    (done, _, _, speed), col = jax.device_get(
        rollout(params, normalizer, jax.random.PRNGKey(1), 0.0)
    )
    assert col.shape == (1024,) and (col == 3).all()
    acted = speed[done > 0.5]  # 2 episodes x 1024 envs
    assert acted.shape == (2048,)
    if deterministic:
        np.testing.assert_allclose(acted, acted[0], atol=1e-6)
    else:
        assert np.std(acted) == pytest.approx(0.3, rel=0.08)


class _DrawingEnv(_ConstantObsEnv):
    """_ConstantObsEnv whose reset draws the terrain column from its key and whose steps draw
    from an rng carried in the state (as the real env's noise): at an episode's last step
    'episode/speed_mps' reads that draw instead of the action."""

    def reset(self, key):
        state = super().reset(key)
        info = dict(state.info, task=_Task(jax.random.randint(key, (), 0, 1000)), rng=key)
        return state.replace(info=info)

    def step(self, state, action):
        rng, sub = jax.random.split(state.info["rng"])
        out = super().step(state, action)
        speed = jp.where(out.done > 0.5, jax.random.uniform(sub), 0.0)
        metrics = dict(out.metrics, **{"episode/speed_mps": speed})
        return out.replace(metrics=metrics, info=dict(out.info, rng=rng))


def test_mean_and_sampled_actions_run_the_same_draws():
    """What lets paired compare a policy's mean with its sampled actions: the rollout's reset
    and env draws do not depend on how it acts (the action keys are split off), and the draws
    fingerprint is the same for both; another key draws other episodes."""
    cfg = tiny_cfg()
    env = _DrawingEnv()
    networks, params, normalizer = harness.load_policy(
        cfg, env, jp.zeros((1, 3)), None, jax.random.PRNGKey(0)
    )
    got = {}
    for det, seed in ((True, 1), (False, 1), (True, 2)):
        rollout = rb.make_rollout(env, networks, 64, 8, deterministic=det)
        (_, _, _, speed), col = jax.device_get(
            rollout(params, normalizer, jax.random.PRNGKey(seed), 0.0)
        )
        got[det, seed] = (col, speed)
    for a, b in zip(got[True, 1], got[False, 1], strict=True):
        np.testing.assert_array_equal(a, b)
    assert (got[True, 2][0] != got[True, 1][0]).mean() > 0.9
    sampled = tiny_cfg()
    sampled.eval.deterministic, sampled.network.max_noise_std = False, 0.15
    assert results.episode_draws(sampled) == results.episode_draws(cfg)
    e_mean, e_sampled = results.ensemble_setting(cfg), results.ensemble_setting(sampled)
    assert e_mean != e_sampled  # a figure still draws only results that acted alike


# ---------------------------------------------------------------------------------------------
# End to end (one env compile)
E2E_RUN = {}  # the e2e fixture's cell store and per-episode outcomes


@pytest.fixture(scope="module")
def e2e(tmp_path_factory):
    cfg = tiny_cfg()
    cfg.eval.stone_types = ("mixed_row_stones",)  # 5 columns: 4 mixed-row stones, 1 gap
    cfg.eval.gap_types = ("platform_gap",)
    out = str(tmp_path_factory.mktemp("eval"))
    store = cells.CellStore(  # each finished cell is also kept (resume: test_cells_resume_...)
        str(tmp_path_factory.mktemp("cells")),
        cells.cell_identity("untrained", results.episode_draws(cfg), cfg.eval.deterministic),
    )
    rows, outcomes = rb.evaluate_sweep(
        cfg,
        "mock_ideal",
        "odometry",
        (0.0, 2.0),
        None,
        jax.random.PRNGKey(0),
        return_outcomes=True,
        cells=store,
    )  # one compile for both levels
    E2E_RUN.update(store=store, outcomes=outcomes)
    written = results.write_run(  # what evaluate.py writes
        out,
        "mock_ideal",
        "odometry",
        rows,
        None,
        cfg.env.episode_length_s,
        outcomes,
        results.episode_draws(cfg),
        ensemble=results.ensemble_setting(cfg),
    )
    paths = {
        "json": os.path.join(out, "results_mock_ideal_odometry.json"),
        "csv": os.path.join(out, "results_mock_ideal_odometry.csv"),
        "png": os.path.join(out, "robustness.png"),
        "episodes": os.path.join(out, "episodes_mock_ideal_odometry.json"),
    }
    assert sorted(written) == sorted(paths.values())
    return cfg, out, rows, paths


def test_end_to_end_writes_outputs(e2e):
    cfg, out, rows, paths = e2e
    assert sorted(os.listdir(out)) == [
        "episodes_mock_ideal_odometry.json",
        "results_mock_ideal_odometry.csv",
        "results_mock_ideal_odometry.json",
        "robustness.png",
    ]
    with open(paths["json"]) as f:
        doc = json.load(f)
    assert tuple(doc) == results.TOP_KEYS  # schema: exact key sets
    assert doc["schema_version"] == 4 and doc["ensemble"] == results.ensemble_setting(cfg)
    assert len(doc["results"]) == 2
    for r, level in zip(doc["results"], (0.0, 2.0), strict=True):
        assert tuple(r) == results.RESULT_KEYS
        assert (r["source"], r["perturbation"], r["level"]) == ("mock_ideal", "odometry", level)
        assert r["episodes"] == 4 and 0 <= r["successes"] <= 4 and 0 <= r["falls"] <= 4
        assert r["ci_low"] <= r["success_rate"] <= r["ci_high"]
        assert math.isfinite(r["mean_speed_mps"]) and r["mean_speed_mps"] >= 0
    with open(paths["csv"]) as f:
        csv_rows = list(csv.DictReader(f))
    assert tuple(csv_rows[0]) == results.RESULT_KEYS and [int(r["episodes"]) for r in csv_rows] == [
        4,
        4,
    ]
    with open(paths["png"], "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    assert "mock_ideal" in results.format_table(rows)


def test_per_episode_outcomes_match_the_rows_and_pair_with_themselves(e2e, tmp_path):
    cfg, out, rows, paths = e2e
    doc = paired.load_episodes(paths["episodes"])
    assert doc["draws"] == results.episode_draws(cfg)
    assert [(c["source"], c["perturbation"], c["level"]) for c in doc["cells"]] == [
        ("mock_ideal", "odometry", 0.0),
        ("mock_ideal", "odometry", 2.0),
    ]
    for cell, row in zip(doc["cells"], rows, strict=True):
        assert all(len(cell[k]) == 4 for k in results.EPISODE_KEYS)
        assert sum(cell["success"]) == row["successes"] and sum(cell["failed"]) == row["falls"]
        assert np.mean(cell["mean_speed_mps"]) == pytest.approx(row["mean_speed_mps"], abs=1e-3)
    terrains = [t for c in doc["cells"] for t in c["terrain"]]
    assert set(terrains) <= {"mixed_row_stones", "platform_gap"}
    assert doc["cells"][0]["terrain"] == doc["cells"][1]["terrain"]  # same draws at each level
    by_type = results.terrain_breakdown(doc)
    assert sum(r["episodes"] for r in by_type) == 8
    assert sum(r["successes"] for r in by_type) == sum(r["successes"] for r in rows)
    same = paired.pair_folders(out, out)
    assert [(r["a_only"], r["b_only"], r["p_value"]) for r in same] == [(0, 0, 1.0)] * 2
    assert [r["successes_a"] for r in same] == [r["successes"] for r in rows]
    other = tmp_path / "other"  # the same outcomes, evaluated with another seed: no pairing
    other.mkdir()
    doc["draws"]["seed"] += 1
    (other / os.path.basename(paths["episodes"])).write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="seed differs"):
        paired.pair_folders(out, str(other))


def test_cells_resume_an_interrupted_sweep_with_the_same_outcomes(e2e, monkeypatch):
    cfg, _, rows, _ = e2e
    store, outcomes = E2E_RUN["store"], E2E_RUN["outcomes"]
    assert sorted(os.path.basename(p) for p in store.written) == [
        "cell_mock_ideal_odometry_0.0.json",
        "cell_mock_ideal_odometry_2.0.json",
    ]

    def must_not_run(*a, **k):
        raise AssertionError("a stored cell was run again")

    monkeypatch.setattr(rb, "make_eval_env_and_policy", must_not_run)
    again = cells.CellStore(store.out_dir, store.identity)
    r2, o2 = rb.evaluate_sweep(
        cfg, "mock_ideal", "odometry", (0.0, 2.0), None, jax.random.PRNGKey(0), None, True, again
    )
    assert r2 == rows and len(again.loaded) == 2 and not again.written
    for a, b in zip(outcomes, o2, strict=True):
        assert set(a) == set(b)
        for k in a:
            if k == "mean_speed_mps":
                np.testing.assert_allclose(b[k], a[k], rtol=1e-6)
            else:
                np.testing.assert_array_equal(b[k], a[k])
    other = cells.CellStore(store.out_dir, dict(store.identity, policy="another"))
    with pytest.raises(AssertionError, match="run again"):  # another policy: the cells rerun
        rb.evaluate_sweep(
            cfg, "mock_ideal", "odometry", (0.0, 2.0), None, jax.random.PRNGKey(0), cells=other
        )
    again.clear()
    assert not os.path.exists(os.path.join(store.out_dir, cells.CELLS_SUBDIR))


def _cell(level, n=3):
    row = results.summarize(
        "tof",
        "joint_offset",
        level,
        {
            "success": np.array([1, 0, 1][:n], bool),
            "failed": np.array([0, 1, 0][:n], bool),
            "mean_speed_mps": np.array([0.5, 0.25, 0.75][:n]),
        },
    )
    outcomes = {
        "terrain": np.array(["grid_stones", "platform_gap", "grid_stones"][:n]),
        "success": np.array([1, 0, 1][:n], bool),
        "failed": np.array([0, 1, 0][:n], bool),
        "finished": np.ones(n, bool),
        "length": np.array([50, 20, 50][:n]),
        "mean_speed_mps": np.array([0.5, 0.25, 0.75][:n]),
    }
    return row, outcomes


def test_a_sampled_cell_is_reused_only_at_the_same_action_std_cap(tmp_path):
    draws = {"seed": 1, "num_envs": 3, "episodes": 3, "fingerprint": "abc"}
    cells.CellStore(str(tmp_path), cells.cell_identity("p1", draws, False, 0.4)).save(*_cell(0.1))

    def load(deterministic, cap):
        store = cells.CellStore(str(tmp_path), cells.cell_identity("p1", draws, deterministic, cap))
        return store.load("tof", "joint_offset", 0.1)

    assert load(False, 0.4) is not None
    assert load(False, 0.25) is None  # sampled at another std
    assert load(True, 0.4) is None  # mean actions
    # Mean actions do not depend on the cap: their identity is the same at any cap.
    assert cells.cell_identity("p1", draws, True, 0.4) == cells.cell_identity("p1", draws, True)


def test_cell_store_reuses_only_an_intact_cell_of_the_same_identity(tmp_path):
    draws = {"seed": 1, "num_envs": 3, "episodes": 3, "fingerprint": "abc"}
    store = cells.CellStore(str(tmp_path), cells.cell_identity("p1", draws, True))
    row, outcomes = _cell(0.1)
    path = store.save(row, outcomes)
    assert store.load("tof", "joint_offset", 0.2) is None  # another level
    assert store.load("mock_ideal", "joint_offset", 0.1) is None  # another source
    got_row, got = store.load("tof", "joint_offset", 0.1)
    assert got_row == row
    for k in results.EPISODE_KEYS:
        np.testing.assert_array_equal(got[k], outcomes[k])
    for identity in (
        cells.cell_identity("p2", draws, True),  # another policy
        cells.cell_identity("p1", dict(draws, seed=2), True),  # other draws
        cells.cell_identity("p1", draws, False),  # sampled actions
    ):
        assert cells.CellStore(str(tmp_path), identity).load("tof", "joint_offset", 0.1) is None
    text = open(path).read()
    for damaged in (
        text[: len(text) // 2],
        text.replace('"successes": 2', '"successes": "2"'),
        text.replace('"length": [50, 20, 50]', '"length": [50, 20]'),
    ):
        with open(path, "w") as f:
            f.write(damaged)
        assert store.load("tof", "joint_offset", 0.1) is None, damaged[-80:]
    store.clear()
    assert os.listdir(tmp_path) == []


def test_policy_digest_follows_the_policy_files(tmp_path):
    from foottof.ppo.storage.integrity import policy_digest

    run = tmp_path / "run"
    for step, value in ((10, b"a"), (20, b"b")):
        for item in ("params", "normalizer", "opt_state"):
            d = run / "checkpoints" / str(step) / item
            d.mkdir(parents=True)
            (d / "d").write_bytes(value + item.encode())
    latest = policy_digest(str(run))
    assert (
        latest
        == policy_digest(str(run / "checkpoints"))
        == policy_digest(str(run / "checkpoints" / "20"))
    )
    assert policy_digest(str(run / "checkpoints" / "10")) != latest
    (run / "checkpoints" / "20" / "opt_state" / "d").write_bytes(b"other")  # not the policy
    assert policy_digest(str(run)) == latest
    (run / "checkpoints" / "20" / "params" / "d").write_bytes(b"other")
    assert policy_digest(str(run)) != latest
    with pytest.raises(FileNotFoundError):
        policy_digest(str(tmp_path / "empty"))


def _save_checkpoint(run_dir, params, normalizer):
    from foottof.ppo.storage.checkpoint import Checkpointer
    from foottof.ppo.train import TrainState

    z = jp.zeros(1)
    state = TrainState(
        params=params,
        opt_state=z,
        normalizer=normalizer,
        env_state=z,
        carry=z,
        prev_done=z,
        ep_return=z,
        ep_length=z,
        key=jax.random.PRNGKey(0),
        iteration=jp.asarray(1, jp.int32),
    )
    ck = Checkpointer(run_dir, save_env_state=False)
    ck.save(state)
    ck.close()


def test_checkpoint_layout_mismatch_and_roundtrip(tmp_path):
    from foottof.envs import make_env
    from foottof.ppo.networks import make_networks

    cfg = tiny_cfg()
    c, _ = harness.eval_config(cfg, "none", 0.0)
    env = make_env(c, source="tof", terrain_map=harness.eval_terrain_map(c, jax.random.PRNGKey(0)))
    sizes = env.observation_size  # eval_shape, no compile
    obs = {k: jp.zeros((1, n)) for k, n in sizes.items()}
    nets = make_networks(env.action_size, c.network)
    key = jax.random.PRNGKey(1)
    # A checkpoint of a different observation layout (8 fewer actor inputs).
    other = {k: jp.zeros((1, n - 8)) for k, n in sizes.items()}
    _save_checkpoint(
        str(tmp_path / "other"), nets.init_params(key, other), nets.init_normalizer(other)
    )
    with pytest.raises(ValueError, match=rf"observation sizes .*{sizes['state']}.*checkpoint"):
        harness.load_policy(c, env, obs, str(tmp_path / "other"), key)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        harness.load_policy(c, env, obs, str(tmp_path / "nowhere"), key)
    # Matching layout: restored values equal the saved ones.
    params = nets.init_params(jax.random.PRNGKey(7), obs)
    _save_checkpoint(str(tmp_path / "same"), params, nets.init_normalizer(obs))
    _, restored, _ = harness.load_policy(c, env, obs, str(tmp_path / "same"), key)
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(restored), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert run_dir.find_checkpoint(str(tmp_path)) is None  # no runs/ there
    os.makedirs(tmp_path / "runs")
    os.rename(tmp_path / "same", tmp_path / "runs" / "same")
    assert run_dir.find_checkpoint(str(tmp_path)) == str(tmp_path / "runs" / "same")


@pytest.mark.slow
def test_cli_analyze_and_export_end_to_end(tmp_path):  # two env compiles in subprocesses (~3 min)
    tiny = [
        "--config",
        os.path.join(REPO, "configs", "smoke.py"),
        "--config.env.episode_length_s=0.5",
        "--config.eval.num_levels=2",
        "--config.eval.num_cols=5",
        "--untrained",
        "--out",
        str(tmp_path),
    ]
    p = run_cli(
        "evaluate.py",
        "--analyze",
        "--source",
        "mock_aggre",
        "--perturbation",
        "odometry",
        "--levels",
        "2",
        "--video",
        "gif",
        "--video_stride",
        "5",
        *tiny,
        timeout=900,
    )
    assert p.returncode == 0, p.stderr[-3000:]
    tag = "mock_aggre_odometry_2"
    assert sorted(os.listdir(tmp_path)) == sorted(
        [f"analysis_{tag}.png", f"episode_{tag}.npz", f"rollout_{tag}.gif"]
    )
    with np.load(tmp_path / f"episode_{tag}.npz") as f:
        assert f["qpos"].shape[1] == 19 and str(f["source"]) == "mock_aggre"
    out = tmp_path / "policy.npz"
    p = run_cli("evaluate.py", "--export", str(out), *tiny, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    from foottof.ppo.export import NumpyPolicy

    policy = NumpyPolicy(str(out))
    assert policy(np.zeros(policy.obs_size, np.float32)).shape == (12,)


# ---------------------------------------------------------------------------------------------
# The plan line and progress within a batch
def test_plan_line_names_cells_episodes_estimate_and_quick_form():
    """The design card's evaluation (mock_aggre, the odometry sweep, 5 x 1000): 5000 episodes in
    batches of 250, 5 x 8.5 min + one compile of 1 min = 43.5 -> ~44 min; its quick form names
    --episodes and --levels (one cell of the same sweep)."""
    cfg = smoke.get_config()
    line = rb.plan_line(rb.sweep_plan(cfg.eval, ("mock_aggre",), None), 1000, 250)
    assert line.startswith("[evaluate] 5 cell(s) x 1000 episodes = 5000 (mock_aggre odometry ")
    assert "batches of 250" in line and "~44 min" in line and "1 compile(s)" in line
    assert line.endswith("Quick look: --episodes 100 --perturbation odometry --levels 0")
    # every sweep of every source: 45 cells; shank_length compiles once per level (3 x 5), the
    # traced sweeps once each (3 x 2); the quick form is one unperturbed cell per source
    plan = rb.sweep_plan(cfg.eval, ("tof", "mock_ideal", "mock_aggre"), "all")
    line = rb.plan_line(plan, 200, 250)
    assert "45 cell(s) x 200 episodes = 9000" in line and "21 compile(s)" in line
    assert "batches of 200" in line and line.endswith("--episodes 100 --perturbation none")


class _Bar:
    def __init__(self):
        self.updates = []

    def update(self, n):
        self.updates.append(n)


@pytest.mark.integration
def test_progress_moves_within_a_batch_and_leaves_the_outcomes_alone():
    """With a progress bar the sweep advances it as the steps of each batch run (8 episodes in 2
    batches of 4 envs x 25 steps: an episode per 25 / 4 steps, not one move per batch), and its
    per-episode outcomes equal those of the same sweep without one (the rollout's callback
    reads nothing back)."""
    cfg = tiny_cfg()
    cfg.eval.episodes = 8
    key = jax.random.PRNGKey(0)
    bar = _Bar()
    rows, outcomes = rb.evaluate_sweep(cfg, "tof", "none", (0.0,), None, key, bar, True)
    assert sum(bar.updates) == 8 and len(bar.updates) > 2  # 2 batches, more moves
    rows0, outcomes0 = rb.evaluate_sweep(cfg, "tof", "none", (0.0,), None, key, None, True)
    assert rows == rows0
    for k in outcomes0[0]:
        np.testing.assert_array_equal(outcomes[0][k], outcomes0[0][k])
