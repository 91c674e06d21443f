"""Foot ToF sensing: heightfield ray caster, VL53L5CX zone model, degradation and frame timing."""

from foottof.sensors.degradation import (
    DegradationBounds,
    DegradationLevels,
    bounds_from_config,
    degrade,
    sample_levels,
    zero_levels,
)
from foottof.sensors.noise_model import NoiseModel, load_model, missing_prob, noise_std
from foottof.sensors.raycast import MISS, num_strips, ray_heightfield, ray_heightfield_normal
from foottof.sensors.timing import (
    TimingSpec,
    ToFObs,
    ToFState,
    init,
    make_timing_spec,
    reset,
    step,
)
from foottof.sensors.tof import (
    ToFReading,
    ToFSpec,
    cast_rays,
    make_spec,
    sense,
    sensor_frames,
    site_ids,
)

__all__ = [
    "cast_rays",
    "MISS",
    "DegradationBounds",
    "DegradationLevels",
    "NoiseModel",
    "ToFObs",
    "ToFReading",
    "ToFSpec",
    "ToFState",
    "TimingSpec",
    "bounds_from_config",
    "degrade",
    "init",
    "load_model",
    "make_spec",
    "make_timing_spec",
    "missing_prob",
    "noise_std",
    "num_strips",
    "ray_heightfield",
    "ray_heightfield_normal",
    "reset",
    "sample_levels",
    "sense",
    "sensor_frames",
    "site_ids",
    "step",
    "zero_levels",
]
