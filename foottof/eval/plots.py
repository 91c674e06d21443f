"""Figures of the evaluation: the 3-panel robustness plot and the one-episode rollout analysis.

Both return PNG bytes (so callers can write them atomically) and use the Agg backend.
"""

from __future__ import annotations

import io

import numpy as np

from foottof.constants import FEET

PANELS = (
    ("joint_offset", "A  joint offset", "static joint offset [rad]"),
    ("shank_length", "B  shank length", "shank length scale [-]"),
    ("odometry", "C  odometry noise", "odometry noise [x 100 %]"),
)
FILL_COMMAND = "python evaluate.py --source all --perturbation {}"  # fills a missing panel


def _figure(*args, **kwargs):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt, plt.subplots(*args, **kwargs)


def _png(plt, fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def robustness_png(
    rows: list[dict], caption: str | None = None, left_out: tuple | list = ()
) -> bytes:
    """Success rate vs. perturbation level, one panel per perturbation, one line per source.

    Args:
      rows: result rows (keys of foottof.eval.results.RESULT_KEYS); 'none' rows are ignored.
        Error bars are the 95 % Wilson intervals; sources are drawn 1 % of the level span apart
        so that equal rates stay visible. Only panels with rows are drawn; a line under them
        names the command that fills each missing one (all three missing: that line alone).
      caption: what was evaluated (foottof.eval.results.ensemble_caption), drawn above the
        panels.
      left_out: names of results files not drawn (another ensemble), listed under the panels.
    """
    full = [(p, t, x) for p, t, x in PANELS if any(r["perturbation"] == p for r in rows)]
    missing = [(p, t) for p, t, _ in PANELS if p not in {q for q, _, _ in full}]
    note = "not run yet: " + "; ".join(
        f"{t.split(maxsplit=1)[1]} ({FILL_COMMAND.format(p)})" for p, t in missing
    )
    if left_out:
        note = (note + "\n" if missing else "") + (
            "not drawn (another ensemble): " + ", ".join(left_out)
        )
    if not full:
        plt, (fig, ax) = _figure(1, 1, figsize=(9, 2.5))
        ax.axis("off")
        ax.text(
            0.5,
            0.5,
            "no perturbation sweep in this folder\n"
            + note.replace("; ", "\n")
            + (f"\n{caption}" if caption else ""),
            ha="center",
            va="center",
            transform=ax.transAxes,
            color="0.3",
            fontsize=10,
        )
        return _png(plt, fig)
    plt, (fig, axes) = _figure(
        1, len(full), figsize=(1.0 + 4.2 * len(full), 3.8), sharey=True, squeeze=False
    )
    axes = axes[0]
    sources = sorted({r["source"] for r in rows})
    colours = {s: f"C{i}" for i, s in enumerate(sources)}
    for ax, (pert, title, xlabel) in zip(axes, full, strict=True):
        ax.set_title(title, loc="left")
        ax.set_xlabel(xlabel)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        sel = [r for r in rows if r["perturbation"] == pert]
        levels = sorted({r["level"] for r in sel})
        span = (levels[-1] - levels[0]) or 1.0
        for i, s in enumerate(sources):
            pts = sorted((r for r in sel if r["source"] == s), key=lambda r: r["level"])
            if not pts:
                continue
            # Sources side by side at each level (1 % of the span apart) so equal rates stay visible.
            dodge = (i - (len(sources) - 1) / 2) * 0.01 * span
            x = np.array([r["level"] for r in pts]) + dodge
            y = np.array([r["success_rate"] for r in pts])
            err = np.array(
                [
                    [r["success_rate"] - r["ci_low"] for r in pts],
                    [r["ci_high"] - r["success_rate"] for r in pts],
                ]
            )
            ax.errorbar(
                x, y, yerr=np.maximum(err, 0), marker="o", capsize=3, label=s, color=colours[s]
            )
        ax.legend(fontsize=8)
    axes[0].set_ylabel("success rate")
    fig.tight_layout()
    if caption:
        fig.subplots_adjust(top=0.82)
        fig.text(0.01, 0.99, caption, fontsize=8, color="0.2", ha="left", va="top", wrap=True)
    if missing or left_out:
        fig.subplots_adjust(bottom=0.24 + 0.05 * (bool(missing) and bool(left_out)))
        fig.text(0.01, 0.01, note, fontsize=8, color="0.3", ha="left", va="bottom", wrap=True)
    return _png(plt, fig)


def analysis_png(trace: dict, dt: float) -> bytes:
    """Rollout analysis of one episode (paper's deployment figure, panels C-E).

    Args:
      trace: dict of NumPy arrays over T control steps: ``tof`` (T, 4, Z) readings [m] (feet
        LF, RF, LH, RH), ``valid`` (T, 4, Z) {0, 1}, ``foot_z`` (T, 4) foot centre height [m].
      dt: control period [s].
    """
    tof = np.asarray(trace["tof"], np.float64)
    valid = np.asarray(trace["valid"], bool)
    foot_z = np.asarray(trace["foot_z"], np.float64)
    t = np.arange(tof.shape[0]) * dt
    masked = np.where(valid, tof, np.nan)
    plt, (fig, axes) = _figure(3, 1, figsize=(10, 9), sharex=True)
    ax = axes[0]
    with np.errstate(all="ignore"):
        mean = np.nanmean(masked, axis=2)  # (T, 4); NaN where no zone is valid
    for f in range(tof.shape[1]):
        ax.plot(t, mean[:, f], label=FEET[f])
    ax.set_ylabel("mean ToF reading [m]")
    ax.set_title("C  per-foot mean ToF reading (valid zones)", loc="left")
    ax.legend(ncol=4, fontsize=8)
    ax = axes[1]
    im = ax.imshow(
        masked[:, 0, :].T,
        aspect="auto",
        origin="lower",
        interpolation="nearest",
        extent=(t[0], t[-1] + dt, -0.5, tof.shape[2] - 0.5),
        cmap="viridis",
    )
    fig.colorbar(im, ax=ax, label="reading [m]", pad=0.01)
    ax.set_ylabel("LF zone index")
    ax.set_title("D  LF zone readings (blank = invalid)", loc="left")
    ax = axes[2]
    lf = np.where(valid[:, 0, :], tof[:, 0, :], np.inf)
    idx = np.argmin(lf, axis=1).astype(float)
    idx[~valid[:, 0, :].any(axis=1)] = np.nan
    ax.plot(t, foot_z[:, 0], color="0.7", lw=1)
    sc = ax.scatter(t, foot_z[:, 0], c=idx, cmap="tab20", vmin=0, vmax=tof.shape[2] - 1, s=10)
    fig.colorbar(sc, ax=ax, label="min-reading zone", pad=0.01)
    ax.set_ylabel("LF foot height [m]")
    ax.set_xlabel("time [s]")
    ax.set_title("E  LF foot height, coloured by its minimum-reading zone", loc="left")
    fig.tight_layout()
    return _png(plt, fig)
