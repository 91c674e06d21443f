"""CLI: fit the ToF noise model from bench CSV data, write heatmaps (PNG) and parameters (JSON).

Fit:        python -m foottof.sensors.characterize BENCH.csv --json OUT.json --png OUT.png
Synthesize: python -m foottof.sensors.characterize --synthesize OUT.csv [--params IN.json]
            [--seed 0] [--samples 200]
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from foottof.sensors import noise_model as nm

SYNTH_DISTANCES_M = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)  # bench settings [m]
SYNTH_ANGLES_DEG = (0.0, 15.0, 30.0, 45.0, 60.0)  # bench settings [deg]


def plot_heatmaps(model: nm.NoiseModel, stats: dict | None, path: str) -> None:
    """Two heatmaps over (nominal distance, incidence angle): noise std [mm] and missing rate [%].

    The colour field is the model; circles (same colour scale) are per-setting bench statistics.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = np.linspace(0.05, 1.0, 96)
    a = np.linspace(0.0, 75.0, 76)
    dd, aa = np.meshgrid(d, a, indexing="xy")
    std_mm = 1e3 * np.asarray(nm.noise_std(model, dd, np.radians(aa)))
    miss = 1e2 * np.asarray(nm.missing_prob(model, dd, np.radians(aa)))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    panels = (
        (std_mm, "noise level (std) [mm]", "std_m", 1e3),
        (miss, "missing rate [%]", "missing_rate", 1e2),
    )
    for ax, (field, title, key, scale) in zip(axes, panels, strict=True):
        vmax = float(np.nanmax(field))
        im = ax.pcolormesh(d, a, field, shading="auto", cmap="viridis", vmin=0.0, vmax=vmax)
        if stats is not None:
            ax.scatter(
                stats["distance_m"],
                stats["incidence_deg"],
                c=scale * stats[key],
                cmap="viridis",
                vmin=0.0,
                vmax=vmax,
                edgecolors="w",
                s=40,
            )
        ax.set_xlabel("nominal distance [m]")
        ax.set_ylabel("incidence angle [deg]")
        ax.set_title(title)
        fig.colorbar(im, ax=ax)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m foottof.sensors.characterize",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "csv", nargs="?", help="bench CSV to fit (columns: " + ", ".join(nm.CSV_COLUMNS) + ")"
    )
    p.add_argument("--json", default="tof_noise_fit.json", help="output parameter JSON")
    p.add_argument("--png", default="tof_noise_heatmaps.png", help="output heatmap PNG")
    p.add_argument(
        "--synthesize", metavar="OUT_CSV", help="write a synthetic bench CSV instead of fitting"
    )
    p.add_argument(
        "--params", default="", help="noise-model JSON used by --synthesize (default: packaged)"
    )
    p.add_argument("--seed", type=int, default=0, help="--synthesize random seed")
    p.add_argument("--samples", type=int, default=200, help="--synthesize frames per setting")
    args = p.parse_args(argv)

    if args.synthesize:
        if args.samples < 3:
            raise ValueError(f"--samples must be >= 3, got {args.samples}")
        model = nm.load_model(args.params or None)
        data = nm.synthesize(model, args.seed, SYNTH_DISTANCES_M, SYNTH_ANGLES_DEG, args.samples)
        src = args.params or f"foottof/data/{nm.DEFAULT_JSON}"
        comment = (
            "SYNTHETIC example data, NOT bench measurements: generated from the hand-set noise "
            "model\n"
            f"{src} by: python -m foottof.sensors.characterize --synthesize <out.csv> "
            f"--seed {args.seed} --samples {args.samples}\n"
            f"settings: distances {list(SYNTH_DISTANCES_M)} m x angles "
            f"{list(SYNTH_ANGLES_DEG)} deg; "
            "measured = 0 where valid = 0"
        )
        nm.write_bench_csv(args.synthesize, data, comment)
        print(f"wrote {len(data['valid'])} rows to {args.synthesize}")
        return 0

    if not args.csv:
        p.error("give a bench CSV to fit, or --synthesize OUT_CSV")
    data = nm.read_bench_csv(args.csv)
    model, stats = nm.fit(data)
    nm.save_model(
        model,
        args.json,
        source=f"fit by foottof.sensors.characterize from {args.csv} ({len(data['valid'])} rows, "
        f"{len(stats['n'])} settings)",
    )
    plot_heatmaps(model, stats, args.png)
    print(f"log_std_coef       = {np.asarray(model.log_std_coef).round(4).tolist()}")
    print(f"logit_missing_coef = {np.asarray(model.logit_missing_coef).round(4).tolist()}")
    print(f"wrote {args.json} and {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
