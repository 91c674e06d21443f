"""Robustness evaluation: foot-reading sources (tof, mock_ideal, mock_aggre) and their maps."""

from foottof.eval.cameras import CAMERAS, Camera
from foottof.eval.elevation_map import (
    ElevationMapState,
    aggre_init,
    aggre_update,
    height_scan,
    noisy_odometry,
)
from foottof.eval.sources import (
    SOURCES,
    check_source,
    mock_aggre_readings,
    mock_ideal_readings,
    readings_from_scan,
)

__all__ = [
    "CAMERAS",
    "SOURCES",
    "Camera",
    "ElevationMapState",
    "aggre_init",
    "aggre_update",
    "check_source",
    "height_scan",
    "mock_aggre_readings",
    "mock_ideal_readings",
    "noisy_odometry",
    "readings_from_scan",
]
