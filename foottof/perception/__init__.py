"""Perception: the foot-reading sources (tof, mock_ideal, mock_aggre), their maps, odometry noise.

The env runs a source every control step (``foottof.envs.sensing``); the evaluation only picks
one. This file imports no JAX (``SOURCES`` lives in ``foottof.limits`` with the other allowed
values); the modules are imported by name: ``sources`` (mock foot readings), ``elevation_map`` (ideal
height scan, camera-aggregated map), ``cameras`` (the six depth cameras), ``odometry`` (noisy
velocity estimate).
"""

from __future__ import annotations

from foottof.limits import SOURCES  # the sources, defined once (imports no JAX)


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
