"""Distance- and incidence-dependent ToF noise model: evaluation, JSON I/O, CSV I/O and fitting."""

from __future__ import annotations

import csv
import io
import json
import math
import os
from importlib import resources

import jax
import jax.numpy as jp
import numpy as np
from flax import struct

FORMAT = "foottof.tof_noise_model.v1"
FEATURES = ("1", "d_m", "theta_rad^2", "d_m*theta_rad^2")  # same features for both models
CSV_COLUMNS = ("nominal_distance_m", "incidence_deg", "measured_m", "valid")
DEFAULT_JSON = "tof_noise_default.json"  # in foottof/data
EXAMPLE_CSV = "tof_bench_example.csv"  # in foottof/data


@struct.dataclass
class NoiseModel:
    """Noise level and missing rate of one zone as functions of range d [m] and incidence theta.

    ``std(d, theta) = exp(log_std_coef . phi)`` [m] and ``p_miss(d, theta) = sigmoid(
    logit_missing_coef . phi)`` with features ``phi = (1, d, theta^2, d * theta^2)``, theta in
    rad (0 = perpendicular). Smooth, positive, and increasing with range and obliquity for
    positive coefficients, like the paper's Fig. 3 heatmaps.

    Attributes:
      log_std_coef: (4,) coefficients of log std [log m].
      logit_missing_coef: (4,) coefficients of the missing-rate logit.
    """

    log_std_coef: jax.Array
    logit_missing_coef: jax.Array


def _features(d, theta, xp=jp):
    d = xp.asarray(d)
    t2 = xp.asarray(theta) ** 2
    return xp.stack([xp.ones_like(d * t2), d + 0.0 * t2, t2 + 0.0 * d, d * t2], -1)


def noise_std(model: NoiseModel, d, theta):
    """Gaussian range noise std [m] at range ``d`` [m] and incidence ``theta`` [rad] (any shape)."""
    return jp.exp(_features(d, theta) @ jp.asarray(model.log_std_coef))


def missing_prob(model: NoiseModel, d, theta):
    """Probability that a zone reports no valid return, at ``d`` [m] and ``theta`` [rad]."""
    return jax.nn.sigmoid(_features(d, theta) @ jp.asarray(model.logit_missing_coef))


# ----------------------------------------------------------------------------- JSON


def model_to_dict(model: NoiseModel, **meta) -> dict:
    return {
        "format": FORMAT,
        **meta,
        "features": list(FEATURES),
        "log_std_coef": [float(v) for v in np.asarray(model.log_std_coef)],
        "logit_missing_coef": [float(v) for v in np.asarray(model.logit_missing_coef)],
    }


def model_from_dict(obj: dict) -> NoiseModel:
    if obj.get("format") != FORMAT:
        raise ValueError(f"noise model format must be {FORMAT!r}, got {obj.get('format')!r}")
    out = []
    for key in ("log_std_coef", "logit_missing_coef"):
        v = np.asarray(obj.get(key, ()), dtype=float)
        if v.shape != (len(FEATURES),) or not np.all(np.isfinite(v)):
            raise ValueError(
                f"noise model {key!r} must be {len(FEATURES)} finite numbers, got {obj.get(key)!r}"
            )
        out.append(jp.asarray(v, jp.float32))
    return NoiseModel(log_std_coef=out[0], logit_missing_coef=out[1])


def save_model(model: NoiseModel, path: str, **meta) -> None:
    """Write ``model`` (plus metadata such as ``source``/``comment``) as JSON."""
    with open(path, "w") as f:
        json.dump(model_to_dict(model, **meta), f, indent=2)
        f.write("\n")


def load_model(path: str | None = None) -> NoiseModel:
    """Load a noise-model JSON; ``None`` or "" = the packaged default (hand-set, see its source)."""
    if not path:
        text = resources.files("foottof").joinpath("data", DEFAULT_JSON).read_text()
    else:
        if not os.path.exists(path):
            raise ValueError(f"noise model file {path!r} does not exist")
        with open(path) as f:
            text = f.read()
    try:
        obj = json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(f"noise model file {path!r} is not valid JSON: {e}") from e
    return model_from_dict(obj)


# ----------------------------------------------------------------------------- CSV


def read_bench_csv(path: str) -> dict[str, np.ndarray]:
    """Bench measurements from CSV (``#`` lines are comments; header row with CSV_COLUMNS).

    Columns: ``nominal_distance_m`` [m] (sensor to target along the central ray),
    ``incidence_deg`` [deg], ``measured_m`` [m] (ignored where invalid), ``valid`` (0/1).

    Raises:
      ValueError: missing file or columns, non-numeric or out-of-range values (row given).
    """
    if not os.path.exists(path):
        raise ValueError(f"CSV file {path!r} does not exist")
    with open(path) as f:
        text = f.read()
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise ValueError("CSV has no header row")
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    header = [h.strip() for h in (reader.fieldnames or [])]
    missing = [c for c in CSV_COLUMNS if c not in header]
    if missing:
        raise ValueError(
            f"CSV is missing column(s) {missing}; required: {list(CSV_COLUMNS)}, got {header}"
        )
    cols = {c: [] for c in CSV_COLUMNS}
    for i, row in enumerate(reader, start=1):
        row = {k.strip(): v for k, v in row.items() if k is not None}
        for c in CSV_COLUMNS:
            v = (row.get(c) or "").strip()
            try:
                x = float(v)
            except ValueError:
                raise ValueError(f"CSV data row {i}: column {c!r} is not numeric: {v!r}") from None
            if not math.isfinite(x):
                raise ValueError(f"CSV data row {i}: column {c!r} is not finite: {v!r}")
            cols[c].append(x)
    out = {c: np.asarray(v, float) for c, v in cols.items()}
    if out["valid"].size == 0:
        raise ValueError("CSV has no data rows")
    if not np.all(np.isin(out["valid"], (0.0, 1.0))):
        raise ValueError("CSV column 'valid' must be 0 or 1")
    if np.any(out["nominal_distance_m"] <= 0.0):
        raise ValueError("CSV column 'nominal_distance_m' must be > 0")
    if np.any((out["incidence_deg"] < 0.0) | (out["incidence_deg"] >= 90.0)):
        raise ValueError("CSV column 'incidence_deg' must be in [0, 90)")
    return out


def write_bench_csv(path: str, data: dict[str, np.ndarray], comment: str = "") -> None:
    with open(path, "w") as f:
        for line in comment.splitlines():
            f.write(f"# {line}\n")
        f.write(",".join(CSV_COLUMNS) + "\n")
        for d, a, m, v in zip(*(data[c] for c in CSV_COLUMNS), strict=True):
            f.write(f"{d:.4f},{a:.2f},{m:.4f},{int(v)}\n")


def synthesize(model: NoiseModel, seed: int, distances_m, angles_deg, samples: int) -> dict:
    """Synthetic bench data from ``model``: ``samples`` frames at each (distance, angle) setting.

    measured = nominal + N(0, std(d, theta)); invalid with probability p_miss (measured = 0),
    rounded to 1 mm like the sensor.
    """
    rng = np.random.default_rng(seed)
    d, a = np.meshgrid(np.asarray(distances_m, float), np.asarray(angles_deg, float), indexing="ij")
    d = np.repeat(d.ravel(), samples)
    a = np.repeat(a.ravel(), samples)
    th = np.radians(a)
    std = np.asarray(noise_std(model, d, th), float)
    p = np.asarray(missing_prob(model, d, th), float)
    meas = np.round((d + std * rng.standard_normal(d.shape)) * 1000.0) / 1000.0
    valid = (rng.random(d.shape) >= p).astype(float)
    return {
        "nominal_distance_m": d,
        "incidence_deg": a,
        "measured_m": np.where(valid > 0, meas, 0.0),
        "valid": valid,
    }


# ----------------------------------------------------------------------------- fitting


def grouped_stats(data: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-setting statistics: samples are grouped by (distance rounded to 1 mm, angle to 0.1 deg).

    Returns dict of (G,) arrays: distance_m, incidence_deg, n, n_valid, std_m (about the group
    mean of valid samples, NaN with < 2 valid), missing_rate.
    """
    key_d = np.round(data["nominal_distance_m"], 3)
    key_a = np.round(data["incidence_deg"], 1)
    keys, inv = np.unique(np.stack([key_d, key_a], -1), axis=0, return_inverse=True)
    inv = inv.ravel()
    g = len(keys)
    valid = data["valid"] > 0
    n = np.bincount(inv, minlength=g).astype(float)
    nv = np.bincount(inv, weights=valid.astype(float), minlength=g)
    m = data["measured_m"]
    s1 = np.bincount(inv, weights=np.where(valid, m, 0.0), minlength=g)
    mean = s1 / np.maximum(nv, 1.0)
    s2 = np.bincount(inv, weights=np.where(valid, (m - mean[inv]) ** 2, 0.0), minlength=g)
    std = np.where(nv >= 2, np.sqrt(s2 / np.maximum(nv - 1.0, 1.0)), np.nan)
    return {
        "distance_m": keys[:, 0],
        "incidence_deg": keys[:, 1],
        "n": n,
        "n_valid": nv,
        "std_m": std,
        "missing_rate": 1.0 - nv / n,
    }


def fit(data: dict[str, np.ndarray], quant_m: float = 0.001) -> tuple[NoiseModel, dict]:
    """Fit the NoiseModel to bench data (see :func:`read_bench_csv`).

    log std: weighted least squares on the per-setting log sample std (weights n_valid - 1),
    bias-corrected for the Gaussian log-variance (E[log s^2] = log s2 + psi(k/2) - log(k/2),
    k = n_valid - 1) and for 1 mm quantization (variance q^2 / 12 removed). Missing rate:
    binomial logistic regression on the per-setting counts (Newton / IRLS).

    Raises:
      ValueError: fewer than 4 settings with >= 3 valid samples, or degenerate designs.
    """
    st = grouped_stats(data)
    x = _features(st["distance_m"], np.radians(st["incidence_deg"]), xp=np)
    k = st["n_valid"] - 1.0
    use = (st["n_valid"] >= 3) & np.isfinite(st["std_m"])
    if use.sum() < len(FEATURES):
        raise ValueError(
            f"need >= {len(FEATURES)} (distance, angle) settings with >= 3 valid samples to fit "
            "the "
            f"noise level, got {int(use.sum())}"
        )
    var = np.maximum(st["std_m"][use] ** 2 - quant_m**2 / 12.0, (0.1 * quant_m) ** 2)
    half = k[use] / 2.0
    psi_minus_log = -1.0 / (2.0 * half) - 1.0 / (12.0 * half**2)  # psi(x) - log(x), asymptotic
    y = 0.5 * (np.log(var) - psi_minus_log)
    w = np.sqrt(k[use])
    a_std, *_ = np.linalg.lstsq(x[use] * w[:, None], y * w, rcond=None)

    # Binomial logistic regression (IRLS) on the missing counts, with a tiny ridge for stability.
    n, miss = st["n"], st["n"] - st["n_valid"]
    b = np.zeros(len(FEATURES))
    b[0] = math.log((miss.sum() + 0.5) / (n.sum() - miss.sum() + 0.5))
    for _ in range(100):
        p = 1.0 / (1.0 + np.exp(-(x @ b)))
        grad = x.T @ (miss - n * p) - 1e-6 * b
        hess = (x * (n * p * (1.0 - p))[:, None]).T @ x + 1e-6 * np.eye(len(b))
        step = np.linalg.solve(hess, grad)
        b = b + step
        if np.max(np.abs(step)) < 1e-10:
            break
    if not (np.all(np.isfinite(a_std)) and np.all(np.isfinite(b))):
        raise ValueError("noise-model fit did not converge (degenerate distance/angle design?)")
    model = NoiseModel(
        log_std_coef=jp.asarray(a_std, jp.float32), logit_missing_coef=jp.asarray(b, jp.float32)
    )
    return model, st
