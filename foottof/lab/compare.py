"""A/B comparison of training runs branched from one checkpoint: means over an iteration window.

``python -m foottof.lab.compare NAME=RUN_DIR ... --first N --last M [--out FILE.csv]`` reads each
run's ``metrics.csv`` and prints, per branch, the mean of the per-iteration values of
``COLUMNS`` over iterations ``N..M`` (both included; iterations missing from a run are skipped,
and the table says how many each branch had). A branch resumed from a copy of another run keeps
that run's rows before the branch point, so choose ``N`` after it. ``--out`` writes the
per-iteration rows of all branches (branch, iteration, env_steps and ``COLUMNS``) as one CSV:
what the README's A/B tables and ``results/stage1_*_ab.csv`` are made of.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import os

import numpy as np

from foottof import files
from foottof.eval.paired import parse_branch  # noqa: F401 (NAME=RUN_DIR, re-exported)
from foottof.lab.curves import read_metrics

# (metrics.csv column, table header). Per-episode columns are means over the episodes that ended
# in an iteration; the window mean weighs every iteration alike (iterations with no ended episode
# are NaN and skipped).
COLUMNS = (
    ("curriculum/level", "level"),
    ("episode/failed", "falls"),
    ("episode/success", "success"),
    ("episode/progress", "progress"),
    ("episode/speed_mps", "speed [m/s]"),
    ("train/episode_return", "return"),
    ("ppo/action_std", "action std"),
)


def window_rows(metrics: dict[str, np.ndarray], first: int, last: int) -> dict[str, np.ndarray]:
    """The columns of ``metrics`` restricted to iterations ``first..last`` (both included)."""
    if first > last:
        raise ValueError(f"first={first} is after last={last}: the window is empty")
    it = metrics["iteration"]
    keep = (it >= first) & (it <= last)
    return {k: v[keep] for k, v in metrics.items()}


def window_means(rows: dict[str, np.ndarray]) -> dict[str, float]:
    """Mean of the finite per-iteration values of each of ``COLUMNS`` (NaN: none, or no column)."""
    out = {}
    for col, _ in COLUMNS:
        v = rows.get(col, np.array([]))
        v = v[np.isfinite(v)]
        out[col] = float(np.mean(v)) if v.size else math.nan
    return out


def compare(branches: list[tuple[str, str]], first: int, last: int) -> list[dict]:
    """Per branch: name, iterations in the window, the window means and the per-iteration rows."""
    names = [n for n, _ in branches]
    if len(set(names)) != len(names):
        raise ValueError(f"branch names {names} repeat; name them NAME=RUN_DIR")
    out = []
    for name, run_dir in branches:
        rows = window_rows(read_metrics(os.path.join(run_dir, "metrics.csv")), first, last)
        n = int(rows["iteration"].size)
        if n == 0:
            raise ValueError(f"branch {name!r} ({run_dir}) has no iteration in [{first}, {last}]")
        out.append({"name": name, "n": n, "means": window_means(rows), "rows": rows})
    return out


def markdown_table(result: list[dict], first: int, last: int) -> str:
    head = ["branch", "iterations"] + [h for _, h in COLUMNS]
    lines = [
        f"Means over iterations {first}-{last}:",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for r in result:
        cells = [r["name"], str(r["n"])]
        cells += [
            f"{r['means'][c]:.3f}" if math.isfinite(r["means"][c]) else "-" for c, _ in COLUMNS
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_rows(result: list[dict], path: str) -> None:
    """One CSV with the per-iteration rows of every branch (written atomically)."""
    cols = ["iteration", "env_steps"] + [c for c, _ in COLUMNS]
    f = io.StringIO(newline="")
    w = csv.writer(f)
    w.writerow(["branch"] + cols)
    for r in result:
        n, rows = r["n"], r["rows"]
        its = rows["iteration"].astype(np.int64)
        steps = rows["env_steps"].astype(np.int64)
        vals = [rows.get(c, np.full(n, math.nan)) for c, _ in COLUMNS]
        for i in range(n):
            w.writerow([r["name"], its[i], steps[i]] + [repr(float(v[i])) for v in vals])
    files.write_atomic({path: f.getvalue().encode()})


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("branches", nargs="+", help="NAME=RUN_DIR (or RUN_DIR) of each branch")
    p.add_argument("--first", type=int, required=True, help="first iteration of the window")
    p.add_argument("--last", type=int, required=True, help="last iteration of the window")
    p.add_argument("--out", default=None, help="CSV of the per-iteration rows of all branches")
    a = p.parse_args(argv)
    try:
        result = compare([parse_branch(b) for b in a.branches], a.first, a.last)
    except (ValueError, FileNotFoundError) as e:
        p.error(str(e))
    print(markdown_table(result, a.first, a.last))
    if a.out:
        write_rows(result, a.out)
        print(f"per-iteration rows -> {a.out}")


if __name__ == "__main__":
    main()
