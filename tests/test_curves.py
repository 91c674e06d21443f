"""Tests of the learning-curve writer (foottof.lab.curves) on hand-made metrics.csv files."""

import csv
import math

import numpy as np
import pytest

from foottof.lab import curves


def test_moving_average_hand_computed_skips_nan():
    x = np.array([1.0, np.nan, 3.0, 5.0, np.nan, np.nan, np.nan])
    got = curves.moving_average(x, 2)
    # windows: [1] [1, nan] [nan, 3] [3, 5] [5, nan] [nan, nan] [nan, nan]
    expect = [1.0, 1.0, 3.0, 4.0, 5.0, np.nan, np.nan]
    np.testing.assert_allclose(got, expect, equal_nan=True)
    np.testing.assert_allclose(curves.moving_average(x[:4], 1), x[:4], equal_nan=True)
    with pytest.raises(ValueError, match="window=0"):
        curves.moving_average(x, 0)


def _write_metrics(path, rows):
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


def test_write_curve_files_and_missing_columns(tmp_path):
    rows = [
        {"iteration": i, "env_steps": 100 * i, "episode/success": (i % 2) if i > 2 else "nan",
         "train/episode_return": float(i)}
        for i in range(1, 11)
    ]  # fmt: skip
    _write_metrics(tmp_path / "metrics.csv", rows)
    csv_path, png_path = curves.write_curve(str(tmp_path), window=3)
    assert open(png_path, "rb").read(8) == b"\x89PNG\r\n\x1a\n"
    with open(csv_path) as f:
        out = list(csv.DictReader(f))
    assert len(out) == 10 and float(out[-1]["env_steps"]) == 1000
    # return over iterations 8, 9, 10 -> 9; success over 8, 9, 10 -> (0 + 1 + 0) / 3
    assert float(out[-1]["train/episode_return"]) == pytest.approx(9.0)
    assert float(out[-1]["episode/success"]) == pytest.approx(1 / 3, abs=1e-5)
    assert math.isnan(float(out[0]["episode/success"]))  # no episode data yet
    assert math.isnan(float(out[-1]["task/speed_mps"]))  # column not logged by this run


def test_missing_run_is_a_clear_error(tmp_path):
    with pytest.raises(SystemExit, match="metrics.csv.*not found"):
        curves.main([str(tmp_path / "nope")])
