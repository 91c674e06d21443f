"""Learning curves of a run: success, return, length, curriculum level and speed vs env steps.

``python -m foottof.lab.curves RUN_DIR [--window N]`` reads ``RUN_DIR/metrics.csv`` (written by the
runner every iteration, also while the run goes on) and writes ``RUN_DIR/curve.csv`` and
``RUN_DIR/curve.png``: each quantity as a moving average over ``window`` iterations.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import os

import numpy as np

from foottof import files, renames

# (column in metrics.csv, label of the curve). Per-episode means are over the episodes that ended
# in the iteration; 'task/speed_mps' is the mean horizontal base speed over all steps.
CURVES = (
    ("episode/success", "success (episodes ending at the deadline within 0.5 m)"),
    ("episode/failed", "falls (failure terminations per ended episode)"),
    ("train/episode_return", "episode return"),
    ("train/episode_length", "episode length [steps]"),
    ("curriculum/level", "mean curriculum level"),
    ("task/speed_mps", "mean horizontal speed [m/s]"),
)


def read_metrics(path: str) -> dict[str, np.ndarray]:
    """Columns of a metrics.csv as float arrays (empty cells and missing columns -> NaN; renamed
    metric columns of older runs under their new names, foottof.renames.METRICS)."""
    if not os.path.exists(path):
        raise FileNotFoundError(f"{path!r} not found: is this a run directory of train.py?")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise ValueError(f"{path!r} has no iterations yet")

    def num(v):
        try:
            return float(v)
        except (TypeError, ValueError):
            return math.nan

    return {renames.METRICS.get(k, k): np.array([num(r.get(k)) for r in rows]) for k in rows[0]}


def moving_average(x: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over the last ``window`` finite values (NaN where none is finite).

    Args:
      x: (T,) values, NaN where an iteration had no data (e.g. no episode ended).
      window: number of iterations averaged, >= 1.
    """
    if int(window) != window or window < 1:
        raise ValueError(f"window={window!r} must be an integer >= 1")
    ok = np.isfinite(x)
    vals = np.cumsum(np.where(ok, x, 0.0))
    cnt = np.cumsum(ok.astype(np.float64))
    lag = lambda a: np.concatenate([np.zeros(window), a[:-window]])[: len(a)]
    s, n = vals - lag(vals), cnt - lag(cnt)
    return np.where(n > 0, s / np.maximum(n, 1), np.nan)


def learning_curve(
    metrics: dict[str, np.ndarray], window: int = 20, curves=CURVES
) -> dict[str, np.ndarray]:
    """``env_steps`` and the moving average of each of ``curves`` ((column, label) pairs;
    NaN where a column is missing)."""
    steps = metrics["env_steps"]
    out = {"env_steps": steps}
    for key, _ in curves:
        col = metrics.get(key, np.full_like(steps, np.nan))
        out[key] = moving_average(col, window)
    return out


def curve_png(curve: dict[str, np.ndarray], title: str = "") -> bytes:
    """One panel per curve vs env steps [millions]; PNG bytes (Agg backend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5), sharex=True)
    x = curve["env_steps"] / 1e6
    for ax, (key, label) in zip(axes.flat, CURVES, strict=True):
        y = curve[key]
        if np.any(np.isfinite(y)):
            ax.plot(x, y, lw=1.5)
        else:
            ax.text(0.5, 0.5, "not logged", ha="center", va="center", transform=ax.transAxes)
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("env steps [M]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()


def _atomic_write(path: str, data: bytes) -> None:
    files.write_atomic({path: data})


def write_curve(run_dir: str, window: int = 20, out_prefix: str | None = None) -> tuple[str, str]:
    """Writes ``<out_prefix>.csv`` and ``.png`` (default ``RUN_DIR/curve``); returns both paths."""
    curve = learning_curve(read_metrics(os.path.join(run_dir, "metrics.csv")), window)
    prefix = out_prefix or os.path.join(run_dir, "curve")
    buf = io.StringIO()
    w = csv.writer(buf)
    keys = list(curve)
    w.writerow(keys)
    for i in range(len(curve["env_steps"])):
        w.writerow([f"{curve[k][i]:.6g}" for k in keys])
    _atomic_write(prefix + ".csv", buf.getvalue().encode())
    title = (
        f"{os.path.basename(os.path.normpath(run_dir))}: moving average over {window} iterations"
    )
    _atomic_write(prefix + ".png", curve_png(curve, title))
    return prefix + ".csv", prefix + ".png"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run_dir", help="run directory holding metrics.csv")
    p.add_argument("--window", type=int, default=20, help="moving-average window [iterations]")
    p.add_argument("--out", default=None, help="output prefix (default RUN_DIR/curve)")
    a = p.parse_args(argv)
    try:
        for path in write_curve(a.run_dir, a.window, a.out):
            print(path)
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(f"error: {e}") from None


if __name__ == "__main__":
    main()
