"""Shaded-relief PNG of every terrain type at a few difficulties (`python -m ... --out x.png`)."""

from __future__ import annotations

import argparse
import pathlib

import jax
import jax.numpy as jp
import numpy as np

from foottof.terrain.terrain_map import tile_generator
from foottof.terrain.tiles import TERRAIN_TYPES, TileSpec

# Terrain colour by height z [m] (the spawn surface is z = 0), linear between knots: pit floors
# near black, the walls of gaps and pits darkening with depth, tops at z = 0 sand, higher ones
# lighter; stone tops +-0.1 m apart get visibly different shades. Used here and by the rollout
# video (foottof.eval.video), so a frame reads like this figure.
HEIGHT_KNOTS_M = (-1.0, -0.35, -0.12, 0.0, 0.12, 0.8)
HEIGHT_RGB = (
    (0.08, 0.08, 0.10),
    (0.25, 0.23, 0.22),
    (0.45, 0.42, 0.38),
    (0.70, 0.66, 0.58),
    (0.86, 0.82, 0.72),
    (0.97, 0.95, 0.90),
)


def height_rgb(z_m) -> np.ndarray:
    """RGB in [0, 1], shape (*z.shape, 3), of heights ``z_m`` [m] (HEIGHT_KNOTS_M, HEIGHT_RGB;
    clamped outside the knots)."""
    z = np.asarray(z_m, np.float64)
    rgb = np.asarray(HEIGHT_RGB)
    return np.stack([np.interp(z, HEIGHT_KNOTS_M, rgb[:, k]) for k in range(3)], axis=-1)


def render_grid(
    out: str | pathlib.Path,
    difficulties: tuple[float, ...] = (0.0, 0.5, 1.0),
    seed: int = 0,
    spec: TileSpec | None = None,
) -> pathlib.Path:
    """Writes a PNG grid: one row per terrain type, one column per difficulty.

    Args:
      out: output PNG path (parent folders are created).
      difficulties: generator difficulties in [0, 1], one column each.
      seed: PRNG seed of the tiles.
      spec: tile geometry; ``TileSpec()`` if None.

    Returns:
      The path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LightSource

    spec = TileSpec() if spec is None else spec
    out = pathlib.Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    d = jp.asarray(difficulties, jp.float32)
    keys = jax.random.split(jax.random.key(seed), len(difficulties))
    ls = LightSource(azdeg=315, altdeg=45)
    extent = (0.0, spec.length_m, 0.0, spec.width_m)
    nrow, ncol = len(TERRAIN_TYPES), len(difficulties)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.6 * ncol, 2.55 * nrow), squeeze=False)
    lo, hi = spec.pit_z_m, 0.7
    for r, name in enumerate(TERRAIN_TYPES):
        gen = tile_generator(r, spec)  # the terrain map's per-type generator
        tiles = [np.asarray(gen(keys[c], d[c])) for c in range(ncol)]
        for c in range(ncol):
            z = tiles[c]
            rgb = ls.shade_rgb(  # coloured by height, shaded by slope
                height_rgb(z),
                np.clip(z, lo, hi),
                vert_exag=4.0,
                dx=spec.cell_m,
                dy=spec.cell_m,
                blend_mode="soft",
            )
            ax = axes[r, c]
            ax.imshow(rgb, origin="lower", extent=extent, interpolation="nearest")
            ax.set_title(
                f"{name}  d={difficulties[c]:.1f}  z[{z.min():.2f}, {z.max():.2f}] m", fontsize=8
            )
            ax.axvline(spec.course_x0_m, color="tab:red", lw=0.6, ls="--")
            ax.axvline(spec.course_x1_m, color="tab:red", lw=0.6, ls="--")
            ax.tick_params(labelsize=6)
            if c == 0:
                ax.set_ylabel("y [m]", fontsize=7)
            if r == nrow - 1:
                ax.set_xlabel("x [m] (walking direction)", fontsize=7)
    fig.suptitle(
        "foottof training terrains: rows = type, columns = difficulty "
        f"(start platform x < {spec.course_x0_m:.2f} m, goal x >= {spec.course_x1_m:.2f} m, "
        f"pit z = {spec.pit_z_m:.1f} m)",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.985))
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="docs/terrains.png", help="output PNG path")
    parser.add_argument("--seed", type=int, default=0, help="PRNG seed")
    parser.add_argument(
        "--difficulties", type=float, nargs="+", default=[0.0, 0.5, 1.0], help="in [0, 1]"
    )
    args = parser.parse_args(argv)
    path = render_grid(args.out, tuple(args.difficulties), args.seed)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
