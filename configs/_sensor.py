"""Sensor config sections: foot ToF geometry/timing (c.sensor) and degradation bounds (c.noise)."""

import ml_collections

from foottof import constants


def get_section() -> ml_collections.ConfigDict:
    """Returns the ``c.sensor`` section (read by foottof.sensors.make_spec)."""
    c = ml_collections.ConfigDict()
    c.sites = constants.TOF_SITES  # MuJoCo sites carrying one sensor each (repeat = 2 sensors) [-]
    c.grid = constants.TOF_GRID  # zones per side: 4 (4x4, <= 60 Hz) or 8 (8x8, <= 15 Hz) [-]
    c.fov_deg = constants.TOF_FOV_DEG  # full field of view per side [deg]
    c.max_range_m = constants.TOF_MAX_RANGE_M  # readings beyond are clipped and invalid [m]
    c.resolution_m = 0.001  # range quantization [m]
    c.rate_hz = constants.TOF_RATE_HZ  # frame rate, sample-and-hold to the 50 Hz policy [Hz]
    c.tilt_x_deg = (0.0, 0.0, 0.0, 0.0)  # extra tilt about each site's x axis, per sensor [deg]
    c.tilt_y_deg = (0.0, 0.0, 0.0, 0.0)  # extra tilt about each site's y axis, per sensor [deg]
    c.offset_m = ((0.0, 0.0, 0.0),) * 4  # sensor origin in each site frame, per sensor [m]
    return c


def _stage(offset_m, proportional, gaussian_m, missing_rate, model_scale, min_delay, max_delay):
    s = ml_collections.ConfigDict()
    s.offset_m = offset_m  # bound of the per-episode static range offset |o| [m]
    s.proportional = proportional  # bound of the multiplicative noise std [-]
    s.gaussian_m = gaussian_m  # bound of the additive Gaussian noise std [m]
    s.missing_rate = missing_rate  # bound of the random dropout fraction per reading [-]
    s.model_scale = model_scale  # bound of the scale of the characterized noise model [-]
    s.min_delay_steps = min_delay  # smallest per-episode delay [control steps of 20 ms]
    s.max_delay_steps = max_delay  # largest per-episode delay [control steps of 20 ms]
    return s


def get_noise_section() -> ml_collections.ConfigDict:
    """Returns the ``c.noise`` section: degradation upper bounds per training stage.

    Each level is drawn per episode from U[0, bound] (paper Sec. II-C). Stage 1 is kept very low;
    stage 2 mirrors real-world levels. Hand-set values (no bench data): VL53L5CX-like offsets of a
    few cm, a few percent proportional noise, 20-80 ms USB + processing delay (paper: 20-60 ms
    transport, sampled at 60 Hz).
    """
    n = ml_collections.ConfigDict()
    n.model_path = ""  # noise-model JSON from characterize; "" = foottof/data default [-]
    n.stage1 = _stage(0.005, 0.005, 0.002, 0.01, 0.25, 1, 2)  # stage-1 bounds (low)
    n.stage2 = _stage(0.02, 0.05, 0.01, 0.10, 1.0, 1, 4)  # stage-2 bounds (real-world)
    return n
