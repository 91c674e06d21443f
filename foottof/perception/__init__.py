"""Perception: the foot-reading sources (tof, mock_ideal, mock_aggre), their maps, odometry noise.

The env runs a source every control step (``foottof.envs.sensing``); the evaluation only picks
one. This file imports no JAX, so ``foottof.config_check`` can use ``SOURCES`` before JAX loads;
the modules are imported by name: ``sources`` (mock foot readings), ``elevation_map`` (ideal
height scan, camera-aggregated map), ``cameras`` (the six depth cameras), ``odometry`` (noisy
velocity estimate).
"""

from __future__ import annotations

# tof: rays cast from the simulated foot sensor sites on the terrain (foottof.sensors.tof.sense).
# mock_ideal: the same rays cast on the ideal 5 m x 5 m, 5 cm height scan around the base, from
#   sensor poses computed from the measured joints through the nominal kinematics.
# mock_aggre: as mock_ideal, on the camera-aggregated elevation map (elevation_map.aggre_*).
SOURCES = ("tof", "mock_ideal", "mock_aggre")


def check_source(name: str, allow_all: bool = True) -> tuple[str, ...]:
    """The sources that ``name`` names: itself, or every source for 'all' (if ``allow_all``).

    Raises:
      ValueError: ``name`` is not a source (nor 'all' where allowed); the message lists them.
    """
    choices = ["all", *SOURCES] if allow_all else list(SOURCES)
    if name not in choices:
        raise ValueError(f"unknown source {name!r}; valid choices: {choices}")
    return tuple(SOURCES) if name == "all" else (name,)


__all__ = ["SOURCES", "check_source"]
