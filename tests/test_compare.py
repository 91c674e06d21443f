"""foottof.lab.compare: window means of A/B branches against hand-computed values."""

import csv
import math

import numpy as np
import pytest

from foottof.lab import compare


def _write_metrics(run_dir, rows):
    run_dir.mkdir(parents=True, exist_ok=True)
    cols = ["iteration", "env_steps", "curriculum/level", "episode/success"]
    with open(run_dir / "metrics.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for r in rows:
            w.writerow(["" if v is None else v for v in r])


def test_window_means_skip_empty_cells_and_rows_outside_the_window(tmp_path):
    # Branch a: iterations 1..5; the window 3..5 holds levels 2, 4, 6 (mean 4) and successes
    # 0.5, (empty: no episode ended), 0.1 (mean 0.3). Rows 1-2 (the base run's) are left out.
    _write_metrics(
        tmp_path / "a",
        [(1, 10, 100.0, 1.0), (2, 20, 100.0, 1.0), (3, 30, 2.0, 0.5), (4, 40, 4.0, None),
         (5, 50, 6.0, 0.1)],
    )  # fmt: skip
    # Branch b stopped at iteration 4: levels 1, 2 (mean 1.5), successes 0, 0.2 (mean 0.1).
    _write_metrics(tmp_path / "b", [(3, 30, 1.0, 0.0), (4, 40, 2.0, 0.2)])
    res = compare.compare([("a", str(tmp_path / "a")), ("b", str(tmp_path / "b"))], 3, 5)
    assert [r["n"] for r in res] == [3, 2]
    assert res[0]["means"]["curriculum/level"] == pytest.approx(4.0)
    assert res[0]["means"]["episode/success"] == pytest.approx(0.3)
    assert res[1]["means"]["curriculum/level"] == pytest.approx(1.5)
    assert res[1]["means"]["episode/success"] == pytest.approx(0.1)
    assert math.isnan(res[0]["means"]["episode/failed"])  # no such column in these files
    table = compare.markdown_table(res, 3, 5)
    assert "| a | 3 | 4.000 |" in table and "| b | 2 | 1.500 |" in table

    out = tmp_path / "ab.csv"
    compare.write_rows(res, str(out))
    with open(out, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["branch"], r["iteration"], r["env_steps"]) for r in rows] == [
        ("a", "3", "30"), ("a", "4", "40"), ("a", "5", "50"), ("b", "3", "30"), ("b", "4", "40")
    ]  # fmt: skip
    assert np.isnan(float(rows[1]["episode/success"]))


def test_bad_input_names_the_problem(tmp_path):
    _write_metrics(tmp_path / "a", [(3, 30, 2.0, 0.5)])
    with pytest.raises(ValueError, match=r"first=5 is after last=4"):
        compare.compare([("a", str(tmp_path / "a"))], 5, 4)
    with pytest.raises(ValueError, match=r"no iteration in \[10, 20\]"):
        compare.compare([("a", str(tmp_path / "a"))], 10, 20)
    with pytest.raises(ValueError, match=r"repeat"):
        compare.compare([("a", str(tmp_path / "a")), ("a", str(tmp_path / "a"))], 1, 5)
    with pytest.raises(FileNotFoundError, match=r"is this a run directory"):
        compare.compare([("x", str(tmp_path / "missing"))], 1, 5)
    assert compare.parse_branch("runs/stage1_cap25/") == ("stage1_cap25", "runs/stage1_cap25/")
    assert compare.parse_branch("cap=runs/x") == ("cap", "runs/x")
    with pytest.raises(ValueError, match=r"expected NAME=DIR"):
        compare.parse_branch("=runs/x")


def test_overlay_shifts_a_later_stage_and_reads_values_at_equal_env_steps(tmp_path, capsys):
    """foottof.lab.overlay: a student run shifted by its teacher's env steps (+1k) and an
    end-to-end run, hand-computed 2-iteration moving averages at 1.04k total env steps."""
    from foottof.lab import overlay

    _write_metrics(tmp_path / "e2e", [(i, 10 * i, float(i), 0.1 * i) for i in range(1, 121)])
    _write_metrics(tmp_path / "student", [(1, 20, 5.0, 0.5), (2, 40, 7.0, None), (3, 60, 9.0, 1.0)])
    overlay.main(
        [f"e2e={tmp_path / 'e2e'}", f"student={tmp_path / 'student'}+1k", "--window", "2",
         "--at", "1.04k", "--out", str(tmp_path / "out" / "pipeline")]
    )  # fmt: skip
    out = capsys.readouterr().out
    # e2e at 1040 steps: iteration 104, levels 103, 104 -> 103.5; successes 10.3, 10.4 -> 10.35.
    assert "| e2e | 0.0M | 103.500 | 10.350 |" in out
    # student at 1040 = 1000 + 40: iteration 2, levels 5, 7 -> 6; success 0.5 (2 is empty).
    assert "| student | 0.0M | 6.000 | 0.500 |" in out
    with open(tmp_path / "out" / "pipeline.csv") as f:
        rows = [r for r in csv.DictReader(f) if r["branch"] == "student"]
    assert [r["env_steps"] for r in rows] == ["1020", "1040", "1060"]
    assert (tmp_path / "out" / "pipeline.png").stat().st_size > 1000
    assert overlay.parse_branch("s=runs/a+b+33.2M") == ("s", "runs/a+b", 33_200_000)
    assert overlay.parse_branch("runs/x") == ("x", "runs/x", 0)
    with pytest.raises(ValueError, match=r"'-3M'.*number >= 0"):
        overlay.parse_steps("-3M")
    with pytest.raises(SystemExit, match="error: .*'12q'"):
        overlay.main([f"s={tmp_path / 'student'}+12q", "--out", str(tmp_path / "o")])
