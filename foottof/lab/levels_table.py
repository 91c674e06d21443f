"""Per-type, per-level table of the stage-1 curricula: nominal stone size, gap and height spread,
and what a foot meets, counted on generated tiles.

``python -m foottof.lab.levels_table [--config configs/stage1_cpu.py] [--seeds 6]`` prints a
Markdown table (docs/terrain_levels.md holds its output). Per level of each stage-1 type with a
pit: the difficulty d of the level (``terrain.stage1_difficulty``, ``terrain.num_levels``), the
nominal parameters at d (tiles.STONE_CURRICULA, the config's terrain.stone_curriculum;
platform gaps: the largest gap), and measured on
``--seeds`` tiles along straight foot lines (x direction, at the feet's lateral offsets +-0.31 m
around five centre lines within +-0.2 m of the tile's): gaps to the pit floor crossed per metre
(hazards), the narrowest and widest of them [m] (top opening: last solid vertex to the next) and
shallow cracks (narrower than the foot, drawn their sag deep) per metre.
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

from foottof.terrain.tiles import (
    DEFAULT_STONE_CURRICULUM,
    STONE_CURRICULUM_NAMES,
    STONE_TYPES,
    TileSpec,
    generate_tile,
    stone_params,
)

TABLE_TYPES = ("grid_stones", "two_row_stones", "mixed_row_stones", "platform_gap")
FOOT_OFFSETS_M = (-0.31, 0.31)  # ANYmal-D feet at +-0.31 m from the base centre line
CENTRE_LINES_M = (-0.2, -0.1, 0.0, 0.1, 0.2)


def nominal(name: str, d: float, curriculum: str = DEFAULT_STONE_CURRICULUM) -> dict:
    """Nominal stone size, gap and height spread [m] of ``name`` at difficulty ``d`` (stone
    types: on the stone ``curriculum``)."""
    if name in STONE_TYPES:
        p = {k: float(v) for k, v in stone_params(name, d, curriculum).items()}
        return {"size": p["size"], "gap": p["gap"], "dz": p["dz"]}
    # platform_gap (tiles._platform_gap): platforms 0.6-1.6 m, largest gap, spread, linear in d.
    return {"size": 1.3 - 0.5 * d, "gap": 0.05 + 0.70 * d, "dz": 0.20 * d}


def foot_line_counts(z: np.ndarray, spec: TileSpec) -> tuple[list[float], int, int, float]:
    """(widths of deep gaps crossed [m], deep gaps, shallow cracks, metres of line) on one tile."""
    course = z[:, spec.n_start - 1 : spec.nx - spec.n_goal + 1]  # with the platform edges
    length = (course.shape[1] - 1) * spec.cell_m
    widths, deep, shallow, metres = [], 0, 0, 0.0
    for yc in CENTRE_LINES_M:
        for off in FOOT_OFFSETS_M:
            row = course[spec.ny // 2 + int(round((yc + off) / spec.cell_m))]
            pit = row <= spec.pit_z_m + 1e-6
            left, right = np.r_[row[0], row[:-1]], np.r_[row[1:], row[-1]]
            crack = ~pit & (row < left - 2e-3) & (row < right - 2e-3)  # a V below both sides
            edges = np.flatnonzero(np.diff(np.r_[0, pit.astype(int), 0])).reshape(-1, 2)
            for a, b in edges:  # pit vertices a .. b - 1: top opening (b - a + 1) cells
                widths.append((b - a + 1) * spec.cell_m)
            deep += len(edges)
            shallow += int(crack.sum())
            metres += length
    return widths, deep, shallow, metres


def table(cfg_terrain, seeds: int = 6) -> list[dict]:
    spec = TileSpec.from_config(cfg_terrain)
    n = int(cfg_terrain.num_levels)
    rows = []
    for name in TABLE_TYPES:
        lo, hi = cfg_terrain.stage1_difficulty[name]
        for level in range(n):
            d = lo + (hi - lo) * level / max(n - 1, 1)
            widths, deep, shallow, metres = [], 0, 0, 0.0
            for s in range(seeds):
                z = np.asarray(generate_tile(name, jax.random.PRNGKey(1000 + s), d, spec))
                w, k, c, m = foot_line_counts(z, spec)
                widths += w
                deep, shallow, metres = deep + k, shallow + c, metres + m
            rows.append(
                {
                    "type": name,
                    "level": level,
                    "d": d,
                    **nominal(name, d, spec.stone_curriculum),
                    "hazards_per_m": deep / metres,
                    "narrowest": min(widths) if widths else float("nan"),
                    "widest": max(widths) if widths else float("nan"),
                    "cracks_per_m": shallow / metres,
                }
            )
    return rows


def format_markdown(rows: list[dict]) -> str:
    head = (
        "| type | level | d | stone size [m] | gap [m] | height spread [m] | deep gaps per m of "
        "foot line | narrowest / widest drawn [m] | shallow cracks per m |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = [
        f"| {r['type']} | {r['level']} | {r['d']:.3f} | {r['size']:.2f} | {r['gap']:.3f} | "
        f"{r['dz']:.3f} | {r['hazards_per_m']:.2f} | {r['narrowest']:.2f} / {r['widest']:.2f} | "
        f"{r['cracks_per_m']:.2f} |"
        for r in rows
    ]
    return head + "\n".join(lines) + "\n"


def main(argv=None) -> None:
    from foottof.config_file import load_config  # the repo's configs/*.py (run from the repo root)

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="configs/stage1_cpu.py")
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument(
        "--stone_curriculum",
        default=None,
        help="size_first or gaps_first (default: the config's terrain.stone_curriculum)",
    )
    args = ap.parse_args(argv)
    if args.seeds < 1:
        raise SystemExit(f"error: --seeds={args.seeds} must be >= 1")
    terrain = load_config(args.config).terrain
    if args.stone_curriculum is not None:
        if args.stone_curriculum not in STONE_CURRICULUM_NAMES:
            raise SystemExit(
                f"error: --stone_curriculum={args.stone_curriculum!r}; valid choices: "
                f"{', '.join(STONE_CURRICULUM_NAMES)}"
            )
        terrain.stone_curriculum = args.stone_curriculum
    print(format_markdown(table(terrain, args.seeds)), end="")


if __name__ == "__main__":
    main()
