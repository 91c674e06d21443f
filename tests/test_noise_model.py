"""foottof.sensors.noise_model / characterize: the noise-model fit, its CLI, bad input, config adapters."""

import jax.numpy as jp
import ml_collections
import numpy as np
import pytest

from configs import _sensor
from foottof.sensors import (
    ToFSpec,
    bounds_from_config,
    characterize,
    init,
    make_spec,
    make_timing_spec,
    sense,
)
from foottof.sensors import noise_model as nm
from foottof.terrain.heightfield import Heightfield

CELL = 0.04


def _flat(z=0.0):
    return Heightfield(heights=jp.full((61, 61), z, jp.float32), x0_m=-1.2, y0_m=-1.2, cell_m=CELL)


def test_fit_recovers_generating_parameters(tmp_path):
    true = nm.NoiseModel(jp.array([-6.3, 1.8, 0.7, 0.4]), jp.array([-5.5, 3.5, 1.2, 0.8]))
    data = nm.synthesize(
        true, 7, np.linspace(0.1, 1.0, 10), [0.0, 15.0, 30.0, 45.0, 60.0, 70.0], 1500
    )
    path = tmp_path / "bench.csv"
    nm.write_bench_csv(str(path), data, "synthetic")
    fit, _ = nm.fit(nm.read_bench_csv(str(path)))
    np.testing.assert_allclose(
        np.asarray(fit.log_std_coef), np.asarray(true.log_std_coef), atol=0.12
    )
    np.testing.assert_allclose(
        np.asarray(fit.logit_missing_coef), np.asarray(true.logit_missing_coef), atol=0.4
    )
    dd, aa = np.meshgrid(np.linspace(0.1, 1.0, 10), np.radians([0, 30, 60]))
    np.testing.assert_allclose(nm.noise_std(fit, dd, aa), nm.noise_std(true, dd, aa), rtol=0.06)
    np.testing.assert_allclose(
        nm.missing_prob(fit, dd, aa), nm.missing_prob(true, dd, aa), atol=0.02
    )


def test_characterize_cli_roundtrip(tmp_path):
    csv_path, js, png = tmp_path / "b.csv", tmp_path / "m.json", tmp_path / "m.png"
    assert characterize.main(["--synthesize", str(csv_path), "--seed", "1", "--samples", "40"]) == 0
    assert "SYNTHETIC" in csv_path.read_text().splitlines()[0]
    assert characterize.main([str(csv_path), "--json", str(js), "--png", str(png)]) == 0
    model = nm.load_model(str(js))
    default = nm.load_model()
    np.testing.assert_allclose(
        nm.noise_std(model, 0.5, 0.3), nm.noise_std(default, 0.5, 0.3), rtol=0.2
    )
    assert png.stat().st_size > 10_000
    # The shipped example CSV parses and fits.
    nm.fit(nm.read_bench_csv(str(nm.resources.files("foottof").joinpath("data", nm.EXAMPLE_CSV))))


def test_bad_inputs(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("nominal_distance_m,incidence_deg,valid\n0.1,0,1\n")
    with pytest.raises(ValueError, match="missing column.*measured_m"):
        nm.read_bench_csv(str(p))
    p.write_text("nominal_distance_m,incidence_deg,measured_m,valid\n0.1,0,abc,1\n")
    with pytest.raises(ValueError, match="row 1.*measured_m.*not numeric"):
        nm.read_bench_csv(str(p))
    p.write_text("nominal_distance_m,incidence_deg,measured_m,valid\n0.1,95,0.1,1\n")
    with pytest.raises(ValueError, match="incidence_deg"):
        nm.read_bench_csv(str(p))
    with pytest.raises(ValueError, match="does not exist"):
        nm.read_bench_csv(str(tmp_path / "none.csv"))
    with pytest.raises(ValueError, match="grid"):
        ToFSpec(grid=6)
    with pytest.raises(ValueError, match="rate_hz"):
        ToFSpec(grid=8, rate_hz=60.0)
    with pytest.raises(ValueError, match="tilt"):
        ToFSpec(tilt_deg=((0.0, 0.0),) * 3 + ((95.0, 0.0),))
    cfg = _sensor.get_section()
    cfg.tilt_x_deg = (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="tilt_x_deg"):
        make_spec(cfg)
    cfg = _sensor.get_section()
    cfg.grid = 5
    with pytest.raises(ValueError, match="grid"):
        make_spec(cfg)
    with pytest.raises(ValueError, match="site_pos"):
        sense(ToFSpec(), _flat(), jp.zeros((3, 3)), jp.zeros((3, 3, 3)))


def test_config_sections_build_spec_and_bounds():
    cfg = ml_collections.ConfigDict(
        {"sensor": _sensor.get_section(), "noise": _sensor.get_noise_section()}
    )
    spec = make_spec(cfg.sensor)
    tspec = make_timing_spec(spec, cfg.noise)
    assert (spec.num_sensors, spec.num_zones, spec.num_rays, tspec.delay_capacity_steps) == (
        4,
        16,
        41,
        4,
    )
    b1, b2 = bounds_from_config(cfg.noise, 1, tspec), bounds_from_config(cfg.noise, 2, tspec)
    for f in ("offset_m", "proportional", "gaussian_m", "missing_rate", "model_scale"):
        assert float(getattr(b1, f)) < float(getattr(b2, f))
    st = init(tspec)
    assert st.ring_m.shape == (5, 4, 16) and st.held_time_s.shape == (4,)
