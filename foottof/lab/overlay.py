"""Several runs on one env-step axis: a recipe of several stages (teacher, then distillation, then
fine-tuning) against an end-to-end run, at equal env steps.

``python -m foottof.lab.overlay NAME=RUN_DIR[+OFFSET] ... [--at STEPS] [--window N] --out PREFIX``
reads each run's ``metrics.csv``; a run after another stage is shifted right by ``OFFSET`` env
steps (an integer, or with a suffix ``k`` / ``M``: e.g. ``student=runs/distill_cpu+33.2M`` for a
student distilled from a teacher checkpoint at 33.2M env steps). Writes ``PREFIX.csv`` (branch,
total env steps, moving averages of ``COLUMNS``) and ``PREFIX.png`` (one panel per column), and
with ``--at`` prints each branch's moving averages at the last iteration at or before that
total.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import os

import numpy as np

from foottof.eval import paired
from foottof.lab.curves import _atomic_write, learning_curve, read_metrics

# (metrics.csv column, panel title); a distillation run logs the same episode columns as PPO.
COLUMNS = (
    ("curriculum/level", "mean curriculum level"),
    ("episode/success", "success"),
    ("episode/failed", "falls"),
    ("episode/speed_mps", "episode speed [m/s]"),
)
_SUFFIX = {"": 1.0, "k": 1e3, "M": 1e6}


def parse_steps(text: str) -> int:
    """Env steps from ``'1234'``, ``'20k'`` or ``'33.2M'``.

    Raises:
      ValueError: naming the text and the accepted forms.
    """
    unit = text[-1] if text and text[-1] in "kM" else ""
    try:
        value = float(text[: len(text) - len(unit)]) * _SUFFIX[unit]
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value < 0:
        raise ValueError(
            f"env steps {text!r}: expected a number >= 0, optionally ending in k or M (e.g. 33.2M)"
        )
    return int(round(value))


def parse_branch(arg: str) -> tuple[str, str, int]:
    """``NAME=RUN_DIR[+OFFSET]`` (or ``RUN_DIR[+OFFSET]``) -> (name, run_dir, offset env steps);
    the NAME=RUN_DIR part as the A/B tools read it (foottof.eval.paired.parse_branch)."""
    offset = 0
    head, plus, tail = arg.rpartition("+")
    if plus and head:
        offset, arg = parse_steps(tail), head
    return (*paired.parse_branch(arg), offset)


def branch_curve(run_dir: str, offset: int, window: int) -> dict[str, np.ndarray]:
    """``env_steps`` (shifted by ``offset``) and the moving average of each of COLUMNS (NaN
    where a column is missing)."""
    out = learning_curve(read_metrics(os.path.join(run_dir, "metrics.csv")), window, COLUMNS)
    out["env_steps"] = out["env_steps"] + float(offset)
    return out


def value_at(curve: dict[str, np.ndarray], steps: float) -> dict[str, float] | None:
    """The curve's row at the last iteration at or before ``steps`` total env steps (None when
    the run starts after it)."""
    idx = np.nonzero(curve["env_steps"] <= steps)[0]
    if idx.size == 0:
        return None
    i = int(idx[-1])
    return {k: float(v[i]) for k, v in curve.items()}


def overlay_png(curves: dict[str, dict[str, np.ndarray]], title: str = "") -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(COLUMNS), figsize=(4.2 * len(COLUMNS), 3.6), sharex=True)
    for ax, (key, label) in zip(axes, COLUMNS, strict=True):
        for name, c in curves.items():
            ax.plot(c["env_steps"] / 1e6, c[key], lw=1.3, label=name)
        ax.set_title(label, fontsize=9)
        ax.set_xlabel("total env steps [M]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return buf.getvalue()


def write_overlay(branches, out_prefix: str, window: int = 50) -> dict[str, dict]:
    """Writes ``out_prefix``.csv and .png for ``branches`` [(name, run_dir, offset)]; returns
    the curves by name."""
    curves = {name: branch_curve(run, off, window) for name, run, off in branches}
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["branch", "env_steps"] + [k for k, _ in COLUMNS])
    for name, c in curves.items():
        for i in range(len(c["env_steps"])):
            w.writerow([name, f"{c['env_steps'][i]:.0f}"] + [f"{c[k][i]:.6g}" for k, _ in COLUMNS])
    os.makedirs(os.path.dirname(os.path.abspath(out_prefix)), exist_ok=True)
    _atomic_write(out_prefix + ".csv", buf.getvalue().encode())
    title = f"moving average over {window} iterations; later stages shifted by their offset"
    _atomic_write(out_prefix + ".png", overlay_png(curves, title))
    return curves


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("branches", nargs="+", help="NAME=RUN_DIR[+OFFSET env steps, e.g. +33.2M]")
    p.add_argument("--out", required=True, help="output prefix: writes PREFIX.csv, PREFIX.png")
    p.add_argument("--window", type=int, default=50, help="moving-average window [iterations]")
    p.add_argument("--at", default=None, help="print each branch's values at this many env steps")
    args = p.parse_args(argv)
    try:
        branches = [parse_branch(b) for b in args.branches]
        at = None if args.at is None else parse_steps(args.at)
        curves = write_overlay(branches, args.out, args.window)
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(f"error: {e}") from None
    print(f"wrote {args.out}.csv, {args.out}.png")
    if at is not None:
        print(f"\nMoving averages ({args.window} iterations) at {at / 1e6:.1f}M total env steps:\n")
        print("| branch | at env steps | " + " | ".join(lbl for _, lbl in COLUMNS) + " |")
        print("|---|---|" + "---|" * len(COLUMNS))
        for name, c in curves.items():
            row = value_at(c, at)
            if row is None:
                print(f"| {name} | starts later | " + " | ".join("" for _ in COLUMNS) + " |")
                continue
            vals = " | ".join(f"{row[k]:.3f}" for k, _ in COLUMNS)
            print(f"| {name} | {row['env_steps'] / 1e6:.1f}M | {vals} |")


if __name__ == "__main__":
    main()
