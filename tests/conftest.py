"""Test-session setup: XLA's CPU backend compiles at LLVM optimization level 1.

The fast suite is compile-bound (most of its time is XLA compiling the env, the ray caster and
PPO iterations for a few steps each). Level 1 instead of XLA's default cuts those compiles by
about a third (the env's reset and step: 25 -> 16 s and 32 -> 22 s on a 2-core machine) and the
suite from ~1000 s to ~760 s (bench/NOTES.md item 11). All tests pass at level 1, and where we
compared values (the level-0 case below) level 1 gave the default's bit for bit. Level 0 was
faster still (~580 s) but one jitted program (``aggre_init``) then disagreed with its own stored
map, so we do not use it.
Set FOOTTOF_TEST_XLA_OPT to another level (or to "" for XLA's default) to override.
"""

import os

_level = os.environ.get("FOOTTOF_TEST_XLA_OPT", "1")
if _level and "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "") + f" --xla_backend_optimization_level={_level}"
    ).strip()


# Heaviest modules first. `make test` hands whole modules to its 2 workers (--dist loadfile) in
# collection order (--no-loadscope-reorder; xdist's default orders them by number of tests, which
# left the ~4-minute test_analysis.py for last while the other worker idled). Seconds per module,
# summed over its tests, from `pytest --durations=0` (bench/NOTES.md item 11): env 419, sensors
# 370, sources 263, analysis 227, evaluate 196, ppo 193, terrain 116; the rest < 60 each.
_HEAVY_FIRST = (
    "test_env.py",
    "test_raycast.py",
    "test_tof.py",
    "test_sources.py",
    "test_analysis.py",
    "test_evaluate.py",
    "test_ppo.py",
    "test_terrain.py",
)


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(_HEAVY_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(_HEAVY_FIRST)))  # stable sort
